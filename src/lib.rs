//! vshake: a virtual shake table. See the README and docs/guide.md for the tour.
//!
//! Three crates, dependencies pointing one way, re-exported here under their layer's name:
//! - [`kernel`] (the `vshake-kernel` crate): physics, integration and metrics (pure; no I/O,
//!   no serde, no threads);
//! - [`orchestration`] (`vshake-orchestration`): specs, validation, running configurations
//!   through the kernel;
//! - [`shell`] (this crate): the command line, files and reports.

pub use vshake_kernel as kernel;
pub use vshake_orchestration as orchestration;
pub mod shell;
