//! Orchestration: run specifications, validation, and running configurations through the kernel.
//! No terminal or file I/O here (the shell reads files and hands over their contents).

pub mod diagnosis;
pub mod fourier;
pub mod measured;
pub mod preparation;
pub mod runs;
pub mod study;
pub mod toml_fields;
