//! Orchestration: run specifications, validation, and running configurations through the kernel.
//! No terminal or file I/O here (the shell reads files and hands over their contents).

pub mod batch;
pub mod campaign;
pub mod cmaes;
pub mod columns;
pub mod compare;
pub mod diagnose;
pub mod drive_iteration;
pub mod fit;
pub mod fourier;
pub mod measured;
pub mod memory;
pub mod quake;
pub mod sampling;
pub mod sensitivity;
pub mod sim;
pub mod spec;
pub mod spec_quake;
pub mod statemap;
pub mod study;
pub mod timebase;
pub mod toml_fields;
pub mod tune;
pub mod tune_spec;
