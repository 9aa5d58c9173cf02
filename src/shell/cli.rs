//! Command-line arguments (what the user typed), before they are resolved into specs.

use crate::shell::gpu::Backend;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Parser)]
#[command(
    name = "study",
    version,
    about = "vshake: the virtual shake table (UCSD-NEES LHPOST servo-hydraulic model)",
    long_about = "vshake: the virtual shake table. A nonlinear servo-hydraulic model of the UCSD-NEES LHPOST \
(three-variable controller, four-port orifice servo-valves, single-ended actuators, rigid platen with friction).\n\n\
Exit codes: 0 success; 1 a run failed (diverged, stroke or pressure limit) or a system error; 2 bad input.\n\n\
Documentation: README.md (set-up and examples), docs/guide.md (tour and tutorials), \
docs/model.md (the physics contract: every equation, default and source), docs/formats.md (measured-test files, campaigns, study files and results tables)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run one configuration (model overrides + one excitation); print the metrics, optionally write the time history.
    #[command(long_about = SIM_HELP)]
    Sim(SimArgs),
    /// Run a study: thousands of sampled parameter sets in parallel, one Parquet row per sample x excitation.
    #[command(long_about = RUN_HELP)]
    Run(RunArgs),
    /// Sensitivity of each metric to each parameter: Sobol' indices (Saltelli designs), SRC and PRCC.
    Sensitivity(SensitivityArgs),
    /// Draw a study's results (Sobol' indices with their intervals, each metric against each parameter, failed runs), or a time history channel by channel.
    Plot(PlotArgs),
    /// Compare the model with a campaign of measured tests: harmonics, amplitude, part of the cycle, envelope.
    #[command(long_about = COMPARE_HELP)]
    Compare(CompareArgs),
    /// Write measurement files (docs/formats.md) made by the model, with hidden parameter changes and sensor noise.
    Synth(SynthArgs),
    /// Fit effects' (and named baseline) parameters to a campaign (Levenberg-Marquardt).
    Fit(FitArgs),
    /// Fit every candidate effect of the library and say which one is most likely missing.
    Diagnose(DiagnoseArgs),
    /// Merge the shard files of a sharded study (`study run --shard I/N`) into one table.
    Merge(MergeArgs),
    /// Write a Slurm job array (one task per shard) and a dependent merge job for a study.
    Slurm(SlurmArgs),
    /// Iterate the drive of an earthquake test on the virtual table until it reproduces the target acceleration.
    #[command(long_about = ITERATE_HELP)]
    Iterate(IterateArgs),
    /// Choose the controller's gains that give the best fidelity on a test plan (CMA-ES on the virtual table).
    #[command(long_about = TUNE_HELP)]
    Tune(TuneArgs),
    /// Benchmark the kernel (simulated seconds per wall second) and optionally gate on a baseline.
    Bench(BenchArgs),
    /// List every model parameter: name, unit, default, valid range, source and meaning.
    Params(ParamsArgs),
}

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The study file (TOML); not needed with --resume.
    #[arg(required_unless_present = "resume")]
    pub file: Option<PathBuf>,
    /// Continue a results file that a stop (Ctrl-C, SIGTERM) left incomplete, or that a kill left
    /// as FILE.tmp with a checkpoint; the study, shard and seed come from the file. The result
    /// equals an uninterrupted run's. A complete file is left as it is.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["file", "samples", "shard", "out", "model"])]
    pub resume: Option<PathBuf>,
    /// A model file ([model.<component>] tables, e.g. `study fit`'s output) the study starts
    /// from instead of the defaults; the study's own [model.*] tables and variables change it.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Print the samples, the runs, the estimated wall time (from a short timed run) and the
    /// output size, and stop; nothing is written.
    #[arg(long)]
    pub dry_run: bool,
    /// Start a run estimated to take more than a day without asking.
    #[arg(long)]
    pub yes: bool,
    /// Seconds between checkpoints, which keep the rows written so far readable after a kill
    /// (see --resume).
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    pub checkpoint_secs: f64,
    /// Results file (default: [output] file of the study, else <name>.parquet); a folder, or a
    /// path ending in `/` (made where missing), holds it under that default name.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (0 = every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Samples per work item (overrides [solver] chunk; results do not depend on it).
    #[arg(long)]
    pub chunk: Option<usize>,
    /// Override [study] samples (e.g. a quick look at a big study).
    #[arg(long)]
    pub samples: Option<usize>,
    /// No progress output.
    #[arg(long, short)]
    pub quiet: bool,
    /// Progress as a plain line every 5 s on stderr (for batch-job logs) instead of a bar.
    #[arg(long)]
    pub log_progress: bool,
    /// Run only shard I of N (I from 0 to N-1, as SLURM_ARRAY_TASK_ID): a deterministic,
    /// contiguous slice of the design. `study merge` joins the shards.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<String>,
    /// Engine: `auto` (a GPU when one is found and the work is covered, else the CPU, saying
    /// why), `cpu`, or `cuda` (refused with the cause where no GPU can run it).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Folder holding the shard files (`study run --shard I/N`), one per shard.
    pub dir: PathBuf,
    /// The merged table (default: the folder's name with .parquet, beside it).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    /// The study file (TOML).
    pub file: PathBuf,
    /// Number of shards (array tasks).
    #[arg(long)]
    pub shards: usize,
    /// Slurm partition (default: the cluster's default partition).
    #[arg(long)]
    pub partition: Option<String>,
    /// Time limit of each array task, as Slurm takes it (e.g. 01:00:00).
    #[arg(long, default_value = "01:00:00")]
    pub time: String,
    /// CPUs per array task (the worker threads of each shard).
    #[arg(long, default_value_t = 2)]
    pub cpus: usize,
    /// GPUs per array task: 1 asks Slurm for a GPU and runs each shard with `--backend cuda`
    /// (a task that lands without a usable GPU fails, never crawling on its CPUs); 0 (the
    /// default) runs on the CPUs. vshake uses one GPU per task: for more, use more shards.
    #[arg(long, default_value_t = 0)]
    pub gpus_per_task: usize,
    /// Slurm account to charge (default: the user's default).
    #[arg(long)]
    pub account: Option<String>,
    /// Folder for the scripts, the logs, the shards and the merged table (default: slurm_<study name>).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// The `study` executable the jobs run (default: this one).
    #[arg(long)]
    pub bin: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct SensitivityArgs {
    /// A results file written by `study run`.
    pub file: PathBuf,
    /// Output table (default <results stem>_sensitivity.parquet).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Only these metrics (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub metrics: Option<Vec<String>>,
    /// Bootstrap resamples for the Sobol' confidence intervals.
    #[arg(long, default_value_t = 500)]
    pub bootstrap: usize,
    /// Worker threads (0 = every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

#[derive(Debug, clap::Args)]
pub struct PlotArgs {
    /// The results file of `study run` (or `study merge`), or a time history (`study sim --out`,
    /// `study iterate`'s history.parquet), drawn channel by channel against time.
    pub file: PathBuf,
    /// Folder for the plots (SVG) and index.html (default: RESULTS_plots beside the file). A
    /// folder holding other files is refused.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Metrics to draw (comma-separated; default: every metric of the file); for a time
    /// history, the channels.
    #[arg(long, value_delimiter = ',')]
    pub metrics: Option<Vec<String>>,
    /// Bootstrap resamples for the Sobol' indices' 95 % intervals (as `study sensitivity`).
    #[arg(long, default_value_t = 200)]
    pub bootstrap: usize,
}

#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The campaign file (TOML, docs/formats.md): [campaign] and [[test]] entries.
    pub campaign: PathBuf,
    /// Model file ([model.<component>] tables) to compare instead of the defaults.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Folder for the report tables (Parquet: tests, harmonics, bins, cycles, overlay).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Open loop: drive the plant with a measured column instead of the controller, to separate
    /// the plant's error from the controller's: `valve` (valve_cmd_v, through the model's valve
    /// effects) or `spool` (spool_m; the model's transport delay and spool dynamics are bypassed).
    #[arg(long, value_enum)]
    pub open_loop: Option<OpenLoop>,
    /// Treat every warning about the data (a file that does not match its test, units, a flipped
    /// sign, a residual above half the signal) as an error (exit code 2).
    #[arg(long)]
    pub strict: bool,
    /// Worker threads (0 = every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Progress as a plain line every 5 s on stderr (for batch-job logs) instead of the
    /// terminal's progress line.
    #[arg(long)]
    pub log_progress: bool,
}

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// The campaign file (TOML, docs/formats.md).
    pub campaign: PathBuf,
    /// Effects to add and fit (comma-separated; each frees its default parameters).
    #[arg(long, value_delimiter = ',')]
    pub effect: Vec<String>,
    /// More parameters to fit, as component.name (comma-separated), baseline ones included.
    #[arg(long, value_delimiter = ',')]
    pub free: Vec<String>,
    /// Model file to start from ([model.<component>] tables; default: the defaults).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Where to write the fitted model (a model file the other commands accept with --model).
    #[arg(long, default_value = "fitted.toml")]
    pub out: PathBuf,
    /// Iterations of Levenberg-Marquardt at most (it stops where it converges; six correlated
    /// parameters, two modes of a specimen, may need over a hundred).
    #[arg(long, default_value_t = 200)]
    pub max_iter: usize,
    /// Treat every warning about the data as an error (exit code 2).
    #[arg(long)]
    pub strict: bool,
    /// Worker threads (0 = every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Engine: the CPU always (a fit or diagnosis compares time histories, which the CUDA kernel
    /// does not return): `auto` and `cpu` run on the CPU, `cuda` is refused (exit 2).
    #[arg(long, value_enum, default_value_t = Backend::Auto, hide_possible_values = true)]
    pub backend: Backend,
    /// Progress as a plain line every 5 s on stderr (for batch-job logs) instead of the
    /// terminal's progress line.
    #[arg(long)]
    pub log_progress: bool,
}

#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    /// The campaign file (TOML, docs/formats.md).
    pub campaign: PathBuf,
    /// Model file to start from (default: the defaults).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Candidate effects (comma-separated; default: every effect of the library not already on).
    #[arg(long, value_delimiter = ',')]
    pub candidates: Vec<String>,
    /// Folder for the report (report.html and Parquet tables: candidates, tests, evidence).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write the model of the named effects' fit (the starting model with their fitted
    /// parameters, every stage the verdict names, e.g. a specimen's second mode) to this file,
    /// for --model of the other commands. Nothing is written when the verdict names nothing.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Treat every warning about the data as an error (exit code 2).
    #[arg(long)]
    pub strict: bool,
    /// Worker threads (0 = every core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Engine: the CPU always (a fit or diagnosis compares time histories, which the CUDA kernel
    /// does not return): `auto` and `cpu` run on the CPU, `cuda` is refused (exit 2).
    #[arg(long, value_enum, default_value_t = Backend::Auto, hide_possible_values = true)]
    pub backend: Backend,
    /// Progress as a plain line every 5 s on stderr (for batch-job logs) instead of the
    /// terminal's progress line.
    #[arg(long)]
    pub log_progress: bool,
}

/// The measured column an open-loop comparison drives the plant with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OpenLoop {
    /// The valve command `valve_cmd_v`, V.
    Valve,
    /// The spool position `spool_m`, m.
    Spool,
}

#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// The campaign whose tests to synthesise (its data files are written, not read).
    pub campaign: PathBuf,
    /// Output folder: one data file per test, named as in the campaign, and the campaign file.
    #[arg(long)]
    pub out: PathBuf,
    /// Model file to start from ([model.<component>] tables).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Hidden effect(s) to switch on, any of the library (`study params` lists them); repeatable.
    #[arg(long = "effect", value_delimiter = ',')]
    pub effect: Vec<String>,
    /// Hidden parameter change, component.name=value (repeatable), e.g. seal_friction.f_c=8000.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Sensor noise, standard deviations in SI units (accel=0.05,disp=1e-5,force=2000,p1=1e4,
    /// p2=1e4) or in percent of each test's rms of that channel (accel=1%).
    #[arg(long)]
    pub noise: Option<String>,
    /// Seed of the noise (one stream per test and channel).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Blind data: leave the model (and so any hidden effect) out of the files' metadata, as for
    /// a tutorial or a blind test; only the noise, seed and version are recorded.
    #[arg(long)]
    pub blind: bool,
    /// Sample rate of the written files, Hz (default: the controller's, one row per tick). At
    /// another rate the model is sampled between its ticks, from a run at 64 substeps.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Seconds of recording at rest before the excitation starts (a pre-trigger).
    #[arg(long, default_value_t = 0.0)]
    pub pre_trigger: f64,
    /// Write every test that is not a sine (a stochastic motion, a sweep, random) as a record
    /// test of its file's `ref_disp_m` (`signal = "reference"`), as a lab's campaign has it: the
    /// files, not the generator that made them. The truth tracks that reference as read back.
    #[arg(long)]
    pub as_records: bool,
    /// Replace existing files in --out (without it, synth refuses and writes nothing).
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Approximate measuring time in seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Fail (exit 1) when a ratio falls more than 25 % below this baseline (TOML).
    #[arg(long)]
    pub gate: Option<PathBuf>,
    /// Write the measured ratios as a new baseline.
    #[arg(long)]
    pub write_baseline: Option<PathBuf>,
    /// Instead of the kernel, time a whole diagnosis (every candidate of the library) of this
    /// campaign; with --max-seconds, fail when it takes longer.
    #[arg(long)]
    pub diagnose: Option<PathBuf>,
    /// Wall-time limit of the diagnosis benchmark, s.
    #[arg(long, requires = "diagnose")]
    pub max_seconds: Option<f64>,
    /// Engine: `auto` (a GPU when one is found and the work is covered, else the CPU, saying
    /// why), `cpu`, or `cuda` (refused with the cause where no GPU can run it).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// The run file (TOML): [model.<component>] overrides, [excitation], optional [solver] and
    /// [spectrum].
    pub file: PathBuf,
    /// A model file ([model.<component>] tables, e.g. `study fit`'s output) to run instead of
    /// the defaults; the run file's [model.*] tables change it further.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Write the time history of every channel to this Parquet file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// For an earthquake-type excitation: write the response spectra (period_s, psa_target_g,
    /// psa_g, ratio) to this Parquet file.
    #[arg(long)]
    pub spectrum: Option<PathBuf>,
    /// Print only the metrics table (no header lines).
    #[arg(long, short)]
    pub quiet: bool,
    /// A run file whose [excitation] is the motion the table should reproduce (e.g. the run file
    /// `study iterate` took, when this run replays its drive.csv): the achieved acceleration is
    /// also compared with it (rms error, peak ratio over its window), and the response spectra
    /// are the target's against the achieved.
    #[arg(long)]
    pub target: Option<PathBuf>,
    /// Run the test this many times, each pass given the inverse the last one learned
    /// (`adaptive_inverse`, offline passes before the real test): a table of each pass's
    /// errors; the other outputs are the last pass's.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub passes: u32,
    /// Write the model of the best pass (the lowest rms acceleration error: the
    /// `[model.adaptive_inverse]` taps that pass used) to this TOML file, to run the test with.
    #[arg(long)]
    pub learned: Option<PathBuf>,
}

const ITERATE_HELP: &str = "Iterate the drive of an earthquake test on the virtual table (offline iteration, as a \
shake-table controller's transfer-function iteration does before the real test).

The run file is the one `study sim` takes: [model.<component>] overrides (a fitted model, a specimen), the \
target [excitation] (a record, a stochastic motion, a sweep) and [solver]. The target is the acceleration of \
the excitation's reference. From the target itself as the drive, each iteration runs the drive and corrects \
it, d <- d + step * H^-1 (target - achieved), H the table's frequency response estimated from the iteration's \
own runs (H1 over the runs so far, at the record's resolution) and inverted with Tikhonov regularisation \
(--epsilon). A drive outside the table's limits (stroke, velocity, force) is never run: the step is halved \
until it fits; an update that raises the error is not kept and the next step is halved. It stops at --goal, \
after --iterations, when the step falls below a sixteenth of --gain, or when the drive the target needs would \
leave the limits; the outcome line says which, with the error left and the band it lies in. Each iteration \
is printed; --out writes iterations.parquet (the error of each), frf.parquet (H), history.parquet (per tick: \
the target and the achieved acceleration, the drive), iteration.svg (the error per iteration, target against \
achieved) and drive.csv (the final drive's displacement at the controller rate, a \
record a controller can take: kind = \"record\", column = \"drive_disp_m\", signal = \"reference\"). \
With --out, each run is journaled in iterate.journal as it ends: SIGINT or SIGTERM stops the iteration \
before its next run (exit 130 or 143, the journal kept) and --resume continues it to the uninterrupted \
result, bit for bit.";

#[derive(Debug, clap::Args)]
pub struct IterateArgs {
    /// The run file (TOML), as `study sim` takes it.
    pub file: PathBuf,
    /// A model file (e.g. `study fit`'s output, a specimen included) to iterate on instead of
    /// the defaults; the run file's [model.*] tables change it further.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Folder for iterations.parquet, frf.parquet, history.parquet, iteration.svg and drive.csv
    /// (created; files already there are refused unless --force).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Most iterations (updates of the drive).
    #[arg(long, default_value_t = 6)]
    pub iterations: usize,
    /// Gain of each update, in (0, 1].
    #[arg(long, default_value_t = 0.8)]
    pub gain: f64,
    /// Stop when the rms acceleration error is below this fraction of the target's rms.
    #[arg(long, default_value_t = 0.01)]
    pub goal: f64,
    /// Regularisation of the inverse FRF, a fraction of max |H|² (smaller: bolder steps where
    /// the table barely responds, e.g. at a specimen's anti-resonance).
    #[arg(long, default_value_t = 1e-4)]
    pub epsilon: f64,
    /// Overwrite outputs already in --out.
    #[arg(long)]
    pub force: bool,
    /// Continue an iteration stopped by a signal (Ctrl-C, SIGTERM) or killed, from the journal in
    /// --out (iterate.journal): the same run file, --model and settings; the runs done are not
    /// made again, and the result is the uninterrupted iteration's, bit for bit.
    #[arg(long, requires = "out", conflicts_with = "force")]
    pub resume: bool,
}

const TUNE_HELP: &str = "Choose the controller's gains (the TVC gains and leads, optionally the notches) that give \
the best fidelity on a test plan, at full scale, on the virtual table: CMA-ES (Hansen 2016) over the gains' \
box, each generation's candidates x uncertain draws x motions run as one batch on every core.

The tuning file (TOML; docs/formats.md \"Tuning files\"): [tune] name, seed, generations; [[gains]] name, \
low, high (start: the model's value); [objective] metric = weight (any result metric as an error: |ln r| for \
a ratio whose ideal is 1, |phase| for a phase error); [constraints] valve_cmd_fraction (max |u| / u_lim, \
default 0.9; every run must also end: the stroke and pressure guard); [[excitations]] as a study's, with a \
weight; [[uncertain]] as a study's variables and [robust] draws, statistic = \"mean\" | \"quantile\", \
quantile; [model.*], [spectrum], [solver] as a study's; [output] dir.

The same seed gives the same gains bit for bit on any --threads. Writes, into the output folder: tuned.toml \
(the model with the tuned gains: `--model` of run, sim, iterate, tune), evaluations.parquet (every run of \
every candidate: generation, candidate, draw, gains, uncertain values, excitation, metrics, objective), \
generations.parquet (a row per generation) and report.html (the objective per generation, published \
against tuned gains per motion: response spectra overlaid, errors, the margin to valve saturation).

  study tune studies/tune_record.toml
  study tune studies/tune_record.toml --model fitted.toml --out tuned_fitted";

#[derive(Debug, clap::Args)]
pub struct TuneArgs {
    /// The tuning file (TOML).
    pub file: PathBuf,
    /// A model file (e.g. `study fit`'s output, a specimen included) to tune on instead of the
    /// defaults; the tuning file's [model.*] tables change it further.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output folder (default: the file's [output] dir, else the tuning's name); files already
    /// there are refused unless --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (0 = all cores); the result does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Overwrite outputs already in the output folder.
    #[arg(long)]
    pub force: bool,
    /// Print only the result (no line per generation).
    #[arg(long, short)]
    pub quiet: bool,
    /// Continue a tuning stopped by a signal (Ctrl-C, SIGTERM) or killed, from the journal in
    /// its output folder (tune.journal): the same tuning file and --model, the generations done
    /// are not run again, and the result is the uninterrupted run's, bit for bit.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
}

#[derive(Debug, clap::Args)]
pub struct ParamsArgs {
    /// Only this component (servovalve, actuator, platen, friction, controller, or an effect).
    pub component: Option<String>,
    /// List the effect library instead: each effect's name, family, the parameters a diagnosis
    /// frees, and what it adds (docs/model.md §7).
    #[arg(long)]
    pub effects: bool,
}

const COMPARE_HELP: &str = "Compare the model with a campaign of measured tests: harmonics, amplitude, part of the cycle, envelope.

The campaign (TOML) lists the tests; each names its data file (CSV or Parquet; columns time_s, ref_disp_m, \
disp_m, accel_mps2 and optionally valve_cmd_v, force_n, p1_pa, p2_pa, spool_m, in SI units) and how it was driven:

  [campaign]
  name = \"bare_table\"
  [[test]]
  name = \"sine_3hz_1p73g\"
  data = \"sine_3hz_1p73g.csv\"
  excitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.73, taper_s = 1.0 }
  t0_s = 0.5                  # optional: where the excitation starts (default: found from ref_disp_m)
  weights = { force = 0.0 }   # optional: channel weights of fits
  model = { platen = { m = 150000.0 } }   # optional: per-test model overrides

Files may be at any sample rate, with rounded time, a pre-trigger and extra length: the time base is rebuilt, \
the excitation is found in the file, and the model (at its own controller rate) is sampled at the file's samples. \
Every problem of every file is reported at once (exit code 2); warnings (a file that does not match its test, \
units, a flipped sign) are printed, and are errors with --strict. The formats: docs/formats.md.

The output ends with where in state space the model fails: the platen's force balance and the chambers' flow \
balance, evaluated at the measured motion, regressed on static terms of each state (spool opening, velocity, \
pressure difference, displacement, valve flow) and on terms with memory (an oscillator the platen carries; \
a lag of the opening), and one sentence naming the state and term they follow (docs/model.md §8; the tables \
statemap.parquet and stateterms.parquet beside the report).

Example: study compare studies/tutorial/campaign.toml --report /tmp/report";

const RUN_HELP: &str = "Run a study file through the batch engine and write one Parquet row per sample x excitation: \
sample_id, excitation_id, excitation, every parameter, every metric, status, fail_time_s, fail_reason \
(plus design_base, design_block for Saltelli designs). The resolved study, seed, version and schema version \
are in the file's key-value metadata. Results are bit-identical for any --threads and --chunk on one backend \
(the GPU's differ from the CPU's by rounding, at most about 4e-11 relative: see --backend).

The study file (TOML), SALib-style variables in Dakota-style blocks:

  [study]
  name = \"gains_sweep\"
  seed = 20261122
  samples = 4096              # runs; for saltelli the base points N (runs = N x (d + 2))

  [method]
  sampling = \"sobol\"        # monte_carlo | lhs | sobol | grid | saltelli | file
  # levels = 5                # grid: levels per continuous variable
  # file = \"design.csv\"     # file: columns named by parameter, one row per sample

  [model.servovalve]          # fixed overrides, as in `study sim`
  law = \"orifice\"

  [[variables]]               # any parameter of `study params`
  name = \"controller.g_d\"
  distribution = \"uniform\"  # fixed(value) uniform/log_uniform(low, high) normal(mean, std[, low, high])
  low = 1.0                   # log_normal(mu, sigma) triangular(low, mode, high) list(values)
  high = 2.0

  [[excitations]]             # every sample runs every excitation
  name = \"3hz_1p73g\"
  kind = \"sine\"             # sine | record (CSV, Parquet, PEER .AT2) | stochastic | sweep | random
  freq_hz = 3.0
  amp_g = 1.73

  [[excitations]]             # a Kanai-Tajimi / Clough-Penzien ground motion (docs/model.md 4b)
  name = \"firm_0p5g\"
  kind = \"stochastic\"
  duration_s = 15
  pga_g = 0.5                 # any ground.* parameter; realisation = 0 (or \"per_sample\")

  [spectrum]                  # response spectrum of non-sine runs (spectral_err_mean, _max)
  damping = 0.05
  t_min_s = 0.05
  t_max_s = 4.0
  count = 20

  [responses]
  metrics = [\"amp_ratio\", \"thd_odd_ratio\"]   # default: every metric

  [output]
  file = \"gains_sweep.parquet\"
  histories = [0]             # full time histories of these samples

  [solver]
  substeps = 4
  chunk = 64

Before any work, the study, its files, the results path and the design's size are checked (exit 2 \
naming the key). --dry-run prints the runs, an estimated wall time and the output size. Ctrl-C or \
SIGTERM stops after the chunks in flight, closes the file marked incomplete (exit 130 or 143) and \
`study run --resume FILE` finishes it, equal to an uninterrupted run; a killed run resumes from its \
last checkpoint. docs/formats.md (\"Study files\", \"Results\", \"Interrupted and resumed runs\").

Examples:
  study run studies/gains_sweep.toml
  study run studies/gains_sweep.toml --dry-run
  study run --resume gains_sweep.parquet";

const SIM_HELP: &str = "Run one configuration of the virtual shake table and print the metrics of docs/model.md §5 \
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
  substeps = 4              # RK4 steps per controller tick (default 4: h = 244 µs at 1024 Hz)

  [spectrum]                # an earthquake-type motion's response spectrum, as a study's:
  damping = 0.05            # periods_s = [...] or t_min_s, t_max_s, count; band_s = [lo, hi]

A record excitation drives the table with a sampled displacement:

  [excitation]
  kind = \"record\"
  file = \"quake.csv\"        # CSV or Parquet, relative to the run file
  column = \"ref_disp_m\"     # default ref_disp_m
  time_column = \"time_s\"    # default time_s; uniform, increasing
  signal = \"command\"        # default: the command into the reference generator (causal, lagged);
                            # \"reference\": the reference the controller tracked (no lag)
  f_ref_hz = 50.0           # the generator's corner, or the reference's derivative filter's
  scale = 1.0

With --out, the time history (time_s, ref_disp_m, ref_accel_mps2, disp_m, accel_mps2, valve_cmd_v, force_n, \
p1_pa, p2_pa, p1_act2_pa, p2_act2_pa, spool_m, ref_vel_mps) is written as Parquet, readable as a measured test.

Example: study sim studies/sim_3hz_1p73g.toml --out run.parquet";
