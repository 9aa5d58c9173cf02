//! The shell: command line, files, printing. Errors are `anyhow` chains here; [`exit_code`]
//! maps them to the documented exit codes.

pub mod api;
pub mod cli;
pub mod commands;
pub mod fit_problem;
pub mod formats;
pub mod gpu;
pub mod job;
pub mod machine_rates;
pub mod report;
pub mod run_spec;

use crate::orchestration::toml_fields::InputError;
use commands::*;

/// Bad input that is not a TOML file (a missing file, a bad record row): exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// A run that failed (diverged, stroke or pressure limit): exit code 1.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RunFailed(pub String);

/// 2 for bad input (a damaged checkpoint too), 1 for everything else.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    if e.downcast_ref::<InputError>().is_some()
        || e.downcast_ref::<BadInput>().is_some()
        || e.downcast_ref::<formats::parquet_write::BadCheckpoint>()
            .is_some()
    {
        2
    } else {
        1
    }
}

/// Runs a parsed command line.
pub fn dispatch(cli: cli::Cli) -> anyhow::Result<()> {
    match cli.command {
        cli::Command::Sim(a) => sim_cmd::run(&a),
        cli::Command::Params(a) => params_cmd::run(&a),
        cli::Command::Run(a) => run_cmd::run(&a),
        cli::Command::Sensitivity(a) => sensitivity_cmd::run(&a),
        cli::Command::Plot(a) => plot_cmd::run(&a),
        cli::Command::Bench(a) => bench_cmd::run(&a),
        cli::Command::Compare(a) => compare_cmd::run(&a),
        cli::Command::Synth(a) => synth_cmd::run(&a),
        cli::Command::Fit(a) => fit_cmd::run(&a),
        cli::Command::Diagnose(a) => diagnose_cmd::run(&a),
        cli::Command::Merge(a) => merge_cmd::run(&a),
        cli::Command::Slurm(a) => slurm_cmd::run(&a),
        cli::Command::Iterate(a) => iterate_cmd::run(&a),
        cli::Command::Tune(a) => tune_cmd::run(&a),
    }
}
