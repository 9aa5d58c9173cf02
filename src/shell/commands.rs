//! The commands of `study`, one file each: each a leaf that parses its arguments, calls the
//! services and the orchestration, and prints; no command imports another (`tests/layout.rs`).

pub mod bench_cmd;
pub mod compare_cmd;
pub mod diagnose_cmd;
pub mod fit_cmd;
pub mod iterate_cmd;
pub mod merge_cmd;
pub mod params_cmd;
pub mod plot_cmd;
pub mod run_cmd;
pub mod sensitivity_cmd;
pub mod sim_cmd;
pub mod slurm_cmd;
pub mod synth_cmd;
pub mod tune_cmd;
