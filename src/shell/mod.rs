//! The shell: command line, files, printing. Errors are `anyhow` chains here; [`exit_code`]
//! maps them to the documented exit codes.

pub mod api;
pub mod at2;
pub mod bench_cmd;
pub mod campaign_io;
pub mod cli;
pub mod compare_cmd;
pub mod diagnose_cmd;
pub mod fit_cmd;
pub mod fit_problem;
pub mod gpu;
pub(crate) mod integrity;
pub mod interrupt;
pub mod iterate_cmd;
pub mod job;
pub mod machine_rates;
pub mod matlab;
pub mod merge_cmd;
pub mod meta;
pub(crate) mod outputs;
pub mod params_cmd;
pub mod plot_cmd;
pub mod progress;
pub mod report;
pub mod results_reader;
pub mod resume;
pub mod run_cmd;
pub mod run_spec;
pub mod sensitivity_cmd;
pub mod sim_cmd;
pub mod sizing;
pub mod slurm_cmd;
pub mod statemap_report;
pub mod synth_cmd;
pub mod tables;
pub mod tune_cmd;
pub mod tune_report;

use crate::orchestration::toml_fields::InputError;

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
        || e.downcast_ref::<tables::BadCheckpoint>().is_some()
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
