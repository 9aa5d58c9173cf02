//! Design exploration: study files (a SALib-style problem), designs of experiments, the parallel
//! batch engine, sensitivity analysis.

pub mod batch;
pub mod problem;
pub mod sampling;
pub mod sensitivity;
