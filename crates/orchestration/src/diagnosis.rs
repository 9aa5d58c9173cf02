//! Model versus measurement and the missing physics: the comparison, the harmonic projector, the
//! residual on the plant's states, terms with memory, fitting and diagnosis.

pub mod compare;
pub mod diagnose;
pub mod fit;
pub mod projector;
pub mod residual_memory;
pub mod seeds;
pub mod signals;
pub mod statemap;
pub mod states;
pub mod terms;
