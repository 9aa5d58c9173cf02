//! `study sim`: resolve a run file, build its reference, run, print, write.

use super::cli::SimArgs;
use super::meta::{self, Key, Kind};
use super::tables;
use super::{BadInput, RunFailed};
use crate::kernel::excitation::Reference;
use crate::kernel::simulate::LaneStatus;
use crate::orchestration::sim::{self, CHANNELS};
use crate::orchestration::spec::SimSpec;
use anyhow::Context;
use std::io::Write;
use std::path::Path;

/// Builds the reference of a spec, reading a record file relative to `base`.
pub fn build_reference(spec: &SimSpec, base: &Path) -> anyhow::Result<Reference> {
    tables::load_reference(&spec.excitation, &spec.model, base)
}

/// Reads and validates a run file.
pub fn load_spec(file: &Path) -> anyhow::Result<SimSpec> {
    let text = std::fs::read_to_string(file).map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    Ok(SimSpec::from_toml(&text, &file.display().to_string())?)
}

pub fn run(args: &SimArgs) -> anyhow::Result<()> {
    let spec = load_spec(&args.file)?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let reference = build_reference(&spec, base)?;
    let out = sim::run_sim(&spec, &reference)?;
    let mut stdout = std::io::stdout().lock();
    let h = 1.0 / (spec.model.controller.f_s * spec.solver.substeps as f64);
    if !args.quiet {
        writeln!(stdout, "study sim {}", args.file.display())?;
        writeln!(stdout, "  excitation  {}", spec.excitation.describe())?;
        writeln!(
            stdout,
            "  solver      RK4, {} substeps per tick (h = {:.2} µs), controller {} Hz, valve law {:?}",
            spec.solver.substeps,
            h * 1e6,
            spec.model.controller.f_s,
            spec.model.valve_law
        )?;
    }
    let status = match out.result.status {
        LaneStatus::Ok => "ok".to_string(),
        LaneStatus::Failed { time_s, reason } => format!("failed at t = {time_s:.4} s: {reason}"),
    };
    writeln!(stdout, "  status      {status}")?;
    writeln!(stdout)?;
    writeln!(stdout, "  {:<22} {:>12}", "metric", "value")?;
    for (name, v) in out.result.metrics.columns() {
        writeln!(stdout, "  {name:<22} {:>12}", fmt_value(v))?;
    }
    if let Some(path) = &args.out {
        let cols = out.history.named_columns();
        let meta = {
            let mut m = meta::header(Kind::TimeHistory);
            m.extend([meta::pair(Key::Spec, spec.resolved_toml()), meta::pair(Key::SchemaVersion, super::run_cmd::SCHEMA_VERSION), meta::pair(Key::Status, &status)]);
            m
        };
        tables::write_parquet(path, &cols, &meta).with_context(|| format!("writing {}", path.display()))?;
        writeln!(stdout, "\nwrote {} ({} rows x {} channels)", path.display(), out.history.len(), CHANNELS.len())?;
    }
    match out.result.status {
        LaneStatus::Ok => Ok(()),
        LaneStatus::Failed { .. } => Err(RunFailed(format!("{}: run {status}", args.file.display())).into()),
    }
}

fn fmt_value(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
        format!("{v:.4e}")
    } else {
        format!("{v:.5}")
    }
}
