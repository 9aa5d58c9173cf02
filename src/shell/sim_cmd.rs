//! `study sim`: resolve a run file, build its reference, run, print, write.

use super::cli::SimArgs;
use super::tables::{self, TableError};
use super::{BadInput, RunFailed};
use crate::kernel::excitation::{Record, Reference};
use crate::kernel::params::ModelParams;
use crate::kernel::simulate::LaneStatus;
use crate::orchestration::sim::{self, CHANNELS};
use crate::orchestration::spec::{ExcitationSpec, SimSpec};
use anyhow::Context;
use std::io::Write;
use std::path::Path;

/// Builds the reference of a spec, reading a record file relative to `base`.
pub fn build_reference(spec: &SimSpec, base: &Path) -> anyhow::Result<Reference> {
    reference_for(&spec.excitation, &spec.model, base)
}

/// The reference of one excitation for `model`, reading a record file relative to `base`.
pub fn reference_for(excitation: &ExcitationSpec, model: &ModelParams, base: &Path) -> anyhow::Result<Reference> {
    let f_s = model.controller.f_s;
    match excitation {
        ExcitationSpec::Sine { sine, .. } => Ok(sine.reference(f_s)),
        ExcitationSpec::Record { file, column, time_column, f_ref_hz, scale } => {
            let path = base.join(file);
            let t = tables::read_columns(&path, &[time_column, column], &[]).map_err(input_if_user)?;
            // Rounded time is rebuilt into its uniform grid; a gap or a drift is refused.
            let grid = t.time_base(time_column).map_err(|p| BadInput(p.to_string()))?;
            let disp: Vec<f64> = t.column(column).unwrap().iter().map(|d| d * scale).collect();
            let l = model.actuator.l;
            if let Some((row, d)) = disp.iter().enumerate().find(|(_, d)| d.abs() >= l) {
                return Err(BadInput(format!(
                    "{}: column `{column}`, row {}: displacement {d} m (after scale {scale}) exceeds the stroke (half stroke actuator.l = {l} m)",
                    path.display(),
                    row + 1
                ))
                .into());
            }
            let rec = Record { time_s: (0..t.rows()).map(|i| grid.time(i as f64)).collect(), disp_m: disp, f_ref_hz: *f_ref_hz };
            Ok(rec.reference(f_s))
        }
    }
}

/// Marks a table error as bad input (exit 2) when it is the user's.
pub fn input_if_user(e: TableError) -> anyhow::Error {
    if e.is_input() { BadInput(e.to_string()).into() } else { e.into() }
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
        let cols: Vec<(&str, &[f64])> = CHANNELS.iter().map(|(n, _)| *n).zip(out.history.columns.iter().map(Vec::as_slice)).collect();
        let meta = vec![
            ("vshake.kind".to_string(), "time_history".to_string()),
            ("vshake.spec".to_string(), spec.resolved_toml()),
            ("vshake.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
            ("vshake.schema_version".to_string(), "1".to_string()),
            ("vshake.status".to_string(), status.clone()),
        ];
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
