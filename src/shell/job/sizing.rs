//! The size of a run before it starts: `study run --dry-run` (samples, runs, estimated wall time
//! from a short timed run, output size), and the question a run of more than a day asks first.

use crate::orchestration::study::batch::{self, RowSink, Timing};
use crate::shell::job::study_job::{Job, ResultsSink};
use crate::shell::BadInput;
use std::io::{IsTerminal, Write};
use std::ops::Range;
use std::time::Duration;

/// A run estimated above this many wall seconds asks for `--yes` first.
pub const LONG_RUN_S: f64 = 86_400.0;

/// Length of the timed round of a dry run's timing: long enough to be steady (a round of a few
/// hundred samples), short beside any run worth estimating.
const TIMING_ROUND: Duration = Duration::from_millis(600);

/// What to do with a run of an estimated wall time.
#[derive(Debug, PartialEq)]
pub enum Decision {
    Go,
    /// Start, and print this loudly (stderr is not a terminal: nobody can answer).
    Warn(String),
    /// Do not start: ask for `--yes` with this message.
    Ask(String),
}

/// A run over [`LONG_RUN_S`] asks for `--yes` at a terminal, and starts with a loud warning in
/// a batch job (where stderr is a log file).
pub(crate) fn long_run_decision(wall_s: f64, yes: bool, terminal: bool) -> Decision {
    if wall_s <= LONG_RUN_S || yes {
        return Decision::Go;
    }
    let what = format!(
        "this run is estimated at {} of wall time",
        human_time(wall_s)
    );
    if terminal {
        Decision::Ask(format!(
            "{what}; pass --yes to start it, or --dry-run to see the estimate, or fewer --samples"
        ))
    } else {
        Decision::Warn(format!("WARNING: {what}; starting anyway because stderr is not a terminal (pass --yes to silence this)"))
    }
}

/// Simulated seconds of the samples `todo` (every excitation).
fn simulated_s(job: &Job, todo: &Range<usize>) -> f64 {
    job.plan
        .references
        .iter()
        .map(|r| r.len() as f64 / r.f_s)
        .sum::<f64>()
        * todo.len() as f64
}

/// Times a few samples when the run could take more than a day even at a fast 1 000 simulated
/// seconds per wall second per thread, and asks for `--yes` if the estimate is over a day.
pub(crate) fn gate_long_run(
    job: &Job,
    todo: Range<usize>,
    pool: &rayon::ThreadPool,
    yes: bool,
) -> anyhow::Result<()> {
    if yes || simulated_s(job, &todo) < LONG_RUN_S * 1_000.0 * pool.current_num_threads() as f64 {
        return Ok(());
    }
    let c = batch::time_round(&job.plan, todo.clone(), pool, TIMING_ROUND)?;
    match long_run_decision(c.wall_s(todo.len()), yes, std::io::stderr().is_terminal()) {
        Decision::Go => Ok(()),
        Decision::Warn(w) => {
            eprintln!("{w}");
            Ok(())
        }
        Decision::Ask(a) => Err(BadInput(a).into()),
    }
}

/// Prints what a run would do and cost, without writing anything.
pub(crate) fn dry_run(
    job: &Job,
    todo: Range<usize>,
    pool: &rayon::ThreadPool,
) -> anyhow::Result<()> {
    let runs = todo.len() * job.plan.references.len();
    let c = batch::time_round(&job.plan, todo.clone(), pool, TIMING_ROUND)?;
    let wall = c.wall_s(todo.len());
    let bytes = output_bytes(job, &c, runs)?;
    let mut o = std::io::stdout().lock();
    writeln!(o, "  dry run     nothing is written")?;
    writeln!(
        o,
        "  runs        {} samples x {} excitations = {runs} runs, {:.3e} simulated s",
        todo.len(),
        job.plan.references.len(),
        simulated_s(job, &todo)
    )?;
    writeln!(
        o,
        "  estimate    {} wall ({} samples timed in {:.2} s on {} threads, spread over the design)",
        human_time(wall),
        c.samples,
        c.secs,
        pool.current_num_threads()
    )?;
    writeln!(
        o,
        "  output      {} ({})",
        human_bytes(bytes),
        job.out.display()
    )?;
    if wall > LONG_RUN_S {
        writeln!(o, "  note        over a day: the run will ask for --yes (see `study slurm` to spread it over a cluster)")?;
    }
    Ok(())
}

/// The results file's size, from the timed rows written to a scratch file: its fixed part (the
/// footer and metadata, from a file with no rows) plus the timed rows' bytes per row.
fn output_bytes(job: &Job, c: &Timing, runs: usize) -> anyhow::Result<f64> {
    let dir = std::env::temp_dir().join(format!("vshake-dry-run-{}", std::process::id()));
    let size = |rows: &[batch::Row], name: &str| -> anyhow::Result<u64> {
        let path = dir.join(name);
        let mut sink = ResultsSink::create(&path, &job.plan, &job.spec, &job.meta)?;
        sink.write(rows)?;
        sink.finish(&[])?;
        Ok(std::fs::metadata(&path)?.len())
    };
    let sized =
        (|| Ok::<_, anyhow::Error>((size(&[], "empty.parquet")?, size(&c.rows, "rows.parquet")?)))(
        );
    let _ = std::fs::remove_dir_all(&dir);
    let (empty, full) = sized?;
    let per_row = (full.saturating_sub(empty)) as f64 / c.rows.len().max(1) as f64;
    Ok(empty as f64 + per_row * runs as f64)
}

/// Seconds as s, min, h or days.
pub(crate) fn human_time(s: f64) -> String {
    match s {
        s if s < 90.0 => format!("{s:.1} s"),
        s if s < 5_400.0 => format!("{:.1} min", s / 60.0),
        s if s < 2.0 * 86_400.0 => format!("{:.1} h", s / 3_600.0),
        s => format!("{:.1} days", s / 86_400.0),
    }
}

fn human_bytes(b: f64) -> String {
    match b {
        b if b < 1e6 => format!("{:.0} kB", b / 1e3),
        b if b < 1e9 => format!("{:.1} MB", b / 1e6),
        b => format!("{:.2} GB", b / 1e9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_over_a_day_asks_at_a_terminal_and_warns_in_a_batch_job() {
        assert_eq!(long_run_decision(3_600.0, false, true), Decision::Go);
        assert_eq!(
            long_run_decision(2.0 * LONG_RUN_S, true, true),
            Decision::Go
        );
        match long_run_decision(12.0 * LONG_RUN_S, false, true) {
            Decision::Ask(m) => assert!(m.contains("12.0 days") && m.contains("--yes"), "{m}"),
            d => panic!("{d:?}"),
        }
        match long_run_decision(12.0 * LONG_RUN_S, false, false) {
            Decision::Warn(m) => {
                assert!(m.starts_with("WARNING") && m.contains("12.0 days"), "{m}")
            }
            d => panic!("{d:?}"),
        }
    }
}
