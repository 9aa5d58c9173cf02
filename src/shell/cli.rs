//! Command-line arguments (what the user typed), before they are resolved into specs.

use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Parser)]
#[command(name = "study", version, about = "vshake: the virtual shake table (UCSD-NEES LHPOST servo-hydraulic model)",
    long_about = "vshake: the virtual shake table. A nonlinear servo-hydraulic model of the UCSD-NEES LHPOST \
(three-variable controller, four-port orifice servo-valves, single-ended actuators, rigid platen with friction).\n\n\
Exit codes: 0 success; 1 a run failed (diverged, stroke or pressure limit) or a system error; 2 bad input.")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run one configuration (model overrides + one excitation); print the metrics, optionally write the time history.
    #[command(long_about = SIM_HELP)]
    Sim(SimArgs),
    /// List every model parameter: name, unit, default, valid range, source and meaning.
    Params(ParamsArgs),
}

#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// The run file (TOML): [model.<component>] overrides, [excitation], optional [solver].
    pub file: PathBuf,
    /// Write the time history of every channel to this Parquet file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print only the metrics table (no header lines).
    #[arg(long, short)]
    pub quiet: bool,
}

#[derive(Debug, clap::Args)]
pub struct ParamsArgs {
    /// Only this component (servovalve, actuator, platen, friction, controller).
    pub component: Option<String>,
}

const SIM_HELP: &str = "Run one configuration of the virtual shake table and print the metrics of MODEL.md §5 \
(amplitude ratio, phase error, harmonics h2..h9, THD, tracking errors, max |u|).

The run file is TOML:

  [model.servovalve]        # overrides, [model.<component>] <name> = value; see `study params`
  kv = 0.018551
  law = \"orifice\"           # or \"linear\": the published linear-valve counter-example

  [excitation]
  kind = \"sine\"
  freq_hz = 3.0
  amp_g = 1.73              # or amp_m = displacement amplitude in metres
  taper_s = 1.0             # half-cosine taper-in (default 1 s)
  duration_s = 3.0          # default taper_s + 2 s
  window_cycles = 4         # analysis window: last N whole cycles (default: all after taper_s + 1 s)

  [solver]
  substeps = 8              # RK4 steps per controller tick (default 8: h = 122 µs at 1024 Hz)

A record excitation drives the table with a sampled displacement:

  [excitation]
  kind = \"record\"
  file = \"quake.csv\"        # CSV or Parquet, relative to the run file
  column = \"ref_disp_m\"     # default ref_disp_m
  time_column = \"time_s\"    # default time_s; uniform, increasing
  f_ref_hz = 50.0           # state-variable filter corner (default 50 Hz)
  scale = 1.0

With --out, the time history (time_s, ref_disp_m, ref_accel_mps2, disp_m, accel_mps2, valve_cmd_v, force_n, \
p1_pa, p2_pa, p1_act2_pa, p2_act2_pa, spool_m, ref_vel_mps) is written as Parquet, readable as a measured test.

Example: study sim studies/sim_3hz_1p73g.toml --out run.parquet";
