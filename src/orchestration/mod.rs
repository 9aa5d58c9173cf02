//! Orchestration: run specifications, validation, and running configurations through the kernel.
//! No terminal or file I/O here (the shell reads files and hands over their contents).

pub mod sim;
pub mod spec;
pub mod toml_fields;
