//! vshake: a virtual shake table. See the README and docs/guide.md for the tour.
//!
//! Three layers, dependencies pointing one way:
//! - [`kernel`]: physics, integration and metrics (pure; no I/O, no serde, no threads);
//! - [`orchestration`]: specs, validation, running configurations through the kernel;
//! - [`shell`]: the command line, files and reports.

pub mod kernel;
pub mod orchestration;
pub mod shell;
