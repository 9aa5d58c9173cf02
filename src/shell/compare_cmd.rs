//! `study compare`: drive the model with each measured test's excitation and show where it
//! differs: harmonics, amplitude, part of the cycle, envelope; per test and across the campaign.

use super::campaign_io::{load_campaign, load_model, read_measured, test_reference};
use super::cli::{CompareArgs, OpenLoop};
use super::BadInput;
use crate::kernel::excitation::Drive;
use super::tables::{self, Column};
use super::RunFailed;
use crate::kernel::metrics::N_HARM;
use crate::kernel::simulate::LaneStatus;
use crate::orchestration::campaign::TestSpec;
use crate::orchestration::compare::{self, Channels, Comparison};
use crate::orchestration::sim;
use crate::orchestration::spec::{ExcitationSpec, SimSpec};
use std::io::Write;

/// One compared test, with what the report tables need.
pub struct Compared {
    pub test: TestSpec,
    pub comparison: Comparison,
    pub time: Vec<f64>,
    pub accel_measured: Vec<f64>,
    pub accel_model: Vec<f64>,
    pub window: (usize, usize),
}

fn excitation_label(e: &ExcitationSpec) -> (String, f64, f64) {
    match e {
        ExcitationSpec::Sine { sine, amp_g } => {
            let g = amp_g.unwrap_or(sine.amp_m * (2.0 * std::f64::consts::PI * sine.freq_hz).powi(2) / crate::kernel::params::G);
            (format!("sine {} Hz {:.2} g", sine.freq_hz, g), sine.freq_hz, g)
        }
        ExcitationSpec::Record { column, .. } => (format!("record {column}"), f64::NAN, f64::NAN),
    }
}

/// Compares every test of a campaign (used by `compare`, and by later diagnosis).
pub fn compare_campaign(args: &CompareArgs) -> anyhow::Result<Vec<Compared>> {
    let model = load_model(args.model.as_deref())?;
    let lc = load_campaign(&args.campaign, &model)?;
    let mut out = Vec::new();
    for test in &lc.campaign.tests {
        let path = lc.base.join(&test.data);
        let m = read_measured(&path, test.model.controller.f_s)?;
        let mut reference = test_reference(test, m.rows(), &lc.base, &path)?;
        let mut model = test.model.clone();
        if let Some(mode) = args.open_loop {
            let col = mode.column();
            let data = m.column(col).ok_or_else(|| {
                BadInput(format!("{}: column `{col}` is missing; `--open-loop {}` drives the model with it", path.display(), col.split('_').next().unwrap_or(col)))
            })?;
            reference.drive = match mode {
                OpenLoop::Valve => Drive::ValveCommand(data.to_vec()),
                OpenLoop::Spool => {
                    // A measured spool already holds the valve's delay and dynamics.
                    model.effects.transport_delay = false;
                    model.effects.spool_dynamics = false;
                    Drive::Spool(data.to_vec())
                }
            };
        }
        let spec = SimSpec { model, excitation: test.excitation.clone(), solver: Default::default() };
        let outcome = sim::run_sim(&spec, &reference)?;
        if let LaneStatus::Failed { time_s, reason } = outcome.result.status {
            return Err(RunFailed(format!("test {:?}: the model failed at t = {time_s:.4} s: {reason}", test.name)).into());
        }
        let h = &outcome.history;
        let model_ch = Channels { accel: h.channel("accel_mps2").unwrap(), disp: h.channel("disp_m").unwrap(), force: h.channel("force_n") };
        let meas_ch = Channels { accel: m.column("accel_mps2").unwrap(), disp: m.column("disp_m").unwrap(), force: m.column("force_n") };
        let comparison = compare::compare(&reference, &meas_ch, &model_ch);
        out.push(Compared {
            test: test.clone(),
            comparison,
            time: m.column("time_s").unwrap().to_vec(),
            accel_measured: meas_ch.accel.to_vec(),
            accel_model: model_ch.accel.to_vec(),
            window: reference.window,
        });
    }
    Ok(out)
}

pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    let results = compare_campaign(args)?;
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "study compare {} ({} tests, model: {}, {})",
        args.campaign.display(),
        results.len(),
        args.model.as_ref().map_or("defaults".to_string(), |p| p.display().to_string()),
        drive_label(args.open_loop)
    )?;
    writeln!(o)?;
    writeln!(
        o,
        "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10} {:>10} {:>10} {:>10} {:>15}",
        "test", "excitation", "ratio meas/mod", "phase° meas/mod", "h3 meas/mod", "resid a", "resid x", "resid F", "worst k", "drift meas/mod"
    )?;
    for r in &results {
        let c = &r.comparison;
        let (label, _, _) = excitation_label(&r.test.excitation);
        let worst = (1..N_HARM).max_by(|&a, &b| c.residual[a].0.hypot(c.residual[a].1).total_cmp(&c.residual[b].0.hypot(c.residual[b].1)));
        let worst = worst.map_or("-".to_string(), |k| format!("h{} {:.1e}", k + 1, c.residual[k].0.hypot(c.residual[k].1)));
        writeln!(
            o,
            "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10.2e} {:>10.2e} {:>10} {:>10} {:>15}",
            r.test.name,
            label,
            format!("{:.4}/{:.4}", c.amp_ratio_measured, c.amp_ratio_model),
            format!("{:+.2}/{:+.2}", c.phase_measured_deg, c.phase_model_deg),
            format!("{:.4}/{:.4}", c.h_measured[1], c.h_model[1]),
            c.rms_residual_accel_ratio,
            c.rms_residual_disp_ratio,
            c.rms_residual_force_ratio.map_or("-".to_string(), |v| format!("{v:.2e}")),
            worst,
            format!("{:+.1e}/{:+.1e}", c.drift_measured, c.drift_model),
        )?;
    }
    writeln!(o)?;
    writeln!(o, "  residual of the acceleration by part of the cycle (rms in the part / rms of the measured acceleration):")?;
    writeln!(o, "  (and the kinematic consistency |a1|/(w^2 |x1|) of the acceleration and displacement channels: 1 for one rigid body)")?;
    writeln!(o, "  {:<22} {:>18} {:>18} {:>18} {:>17}", "test", "velocity reversal", "peak velocity", "peak displacement", "a/x meas/mod")?;
    for r in &results {
        let c = &r.comparison;
        let b = &c.bins;
        writeln!(
            o,
            "  {:<22} {:>18.2e} {:>18.2e} {:>18.2e} {:>17}",
            r.test.name,
            b[0].rms_residual_ratio,
            b[1].rms_residual_ratio,
            b[2].rms_residual_ratio,
            format!("{:.4}/{:.4}", c.accel_over_disp_measured, c.accel_over_disp_model)
        )?;
    }
    // Across the campaign: error against amplitude, per frequency.
    let mut sines: Vec<(f64, f64, &Compared)> =
        results.iter().filter_map(|r| match excitation_label(&r.test.excitation) { (_, f, g) if f.is_finite() => Some((f, g, r)), _ => None }).collect();
    if !sines.is_empty() {
        sines.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        writeln!(o)?;
        writeln!(o, "  error against amplitude, per frequency (rms acceleration residual / rms measured):")?;
        let mut last = f64::NAN;
        for (f, g, r) in &sines {
            if *f != last {
                write!(o, "{}  {f:>6} Hz:", if last.is_nan() { "" } else { "\n" })?;
                last = *f;
            }
            write!(o, "  {g:.2} g -> {:.2e}", r.comparison.rms_residual_accel_ratio)?;
        }
        writeln!(o)?;
    }
    if let Some(dir) = &args.report {
        write_tables(dir, &results, args.open_loop)?;
        let page = super::report::html(&format!("vshake: model versus measurement, {} ({})", args.campaign.display(), drive_label(args.open_loop)), &results)?;
        let path = dir.join("report.html");
        let out = super::tables::AtomicFile::new(&path);
        std::fs::write(&out.tmp, page)?;
        out.commit()?;
        writeln!(o, "\n  wrote {} and its tables (tests, harmonics, bins, cycles, overlay .parquet)", path.display())?;
    }
    Ok(())
}

/// How the model was driven, in words.
pub fn drive_label(open_loop: Option<OpenLoop>) -> String {
    match open_loop {
        None => "closed loop".to_string(),
        Some(m) => format!("open loop on the measured {}", m.column()),
    }
}

/// The Parquet tables of a comparison: one per kind of thing a report plots.
pub fn write_tables(dir: &std::path::Path, results: &[Compared], open_loop: Option<OpenLoop>) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let meta = vec![
        ("vshake.kind".to_string(), "compare".to_string()),
        ("vshake.drive".to_string(), drive_label(open_loop)),
        ("vshake.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
    ];
    let s = |f: &dyn Fn(&Compared) -> String| Column::Str(results.iter().map(f).collect());
    let x = |f: &dyn Fn(&Compared) -> f64| Column::F64(results.iter().map(f).collect());
    let mut cols = vec![
        ("test".to_string(), s(&|r| r.test.name.clone())),
        ("excitation".to_string(), s(&|r| excitation_label(&r.test.excitation).0)),
        ("freq_hz".to_string(), x(&|r| excitation_label(&r.test.excitation).1)),
        ("amp_g".to_string(), x(&|r| excitation_label(&r.test.excitation).2)),
        ("amp_ratio_measured".to_string(), x(&|r| r.comparison.amp_ratio_measured)),
        ("amp_ratio_model".to_string(), x(&|r| r.comparison.amp_ratio_model)),
        ("phase_measured_deg".to_string(), x(&|r| r.comparison.phase_measured_deg)),
        ("phase_model_deg".to_string(), x(&|r| r.comparison.phase_model_deg)),
    ];
    for k in 2..=N_HARM {
        cols.push((format!("h{k}_measured_ratio"), x(&|r| r.comparison.h_measured[k - 2])));
        cols.push((format!("h{k}_model_ratio"), x(&|r| r.comparison.h_model[k - 2])));
    }
    cols.extend([
        ("rms_residual_accel_ratio".to_string(), x(&|r| r.comparison.rms_residual_accel_ratio)),
        ("rms_residual_disp_ratio".to_string(), x(&|r| r.comparison.rms_residual_disp_ratio)),
        ("rms_residual_force_ratio".to_string(), Column::OptF64(results.iter().map(|r| r.comparison.rms_residual_force_ratio).collect())),
        ("drift_measured_per_cycle".to_string(), x(&|r| r.comparison.drift_measured)),
        ("drift_model_per_cycle".to_string(), x(&|r| r.comparison.drift_model)),
        ("accel_over_disp_measured".to_string(), x(&|r| r.comparison.accel_over_disp_measured)),
        ("accel_over_disp_model".to_string(), x(&|r| r.comparison.accel_over_disp_model)),
    ]);
    tables::write_table(&dir.join("tests.parquet"), cols, &meta)?;

    let rows: Vec<(&Compared, usize)> = results.iter().flat_map(|r| (0..N_HARM).map(move |k| (r, k))).collect();
    let hx = |f: &dyn Fn(&Comparison, usize) -> f64| Column::F64(rows.iter().map(|(r, k)| f(&r.comparison, *k)).collect());
    tables::write_table(
        &dir.join("harmonics.parquet"),
        vec![
            ("test".into(), Column::Str(rows.iter().map(|(r, _)| r.test.name.clone()).collect())),
            ("k".into(), Column::U32(rows.iter().map(|(_, k)| *k as u32 + 1).collect())),
            ("model_re".into(), hx(&|c, k| c.harm_model[k].0)),
            ("model_im".into(), hx(&|c, k| c.harm_model[k].1)),
            ("measured_re".into(), hx(&|c, k| c.harm_measured[k].0)),
            ("measured_im".into(), hx(&|c, k| c.harm_measured[k].1)),
            ("residual_re".into(), hx(&|c, k| c.residual[k].0)),
            ("residual_im".into(), hx(&|c, k| c.residual[k].1)),
            ("residual_abs".into(), hx(&|c, k| c.residual[k].0.hypot(c.residual[k].1))),
        ],
        &meta,
    )?;

    let bins: Vec<(&Compared, usize)> = results.iter().flat_map(|r| (0..3).map(move |b| (r, b))).collect();
    tables::write_table(
        &dir.join("bins.parquet"),
        vec![
            ("test".into(), Column::Str(bins.iter().map(|(r, _)| r.test.name.clone()).collect())),
            ("bin".into(), Column::Str(bins.iter().map(|(r, b)| r.comparison.bins[*b].name.to_string()).collect())),
            ("fraction".into(), Column::F64(bins.iter().map(|(r, b)| r.comparison.bins[*b].fraction).collect())),
            ("rms_residual_ratio".into(), Column::F64(bins.iter().map(|(r, b)| r.comparison.bins[*b].rms_residual_ratio).collect())),
        ],
        &meta,
    )?;

    let cyc: Vec<(&Compared, usize)> = results.iter().flat_map(|r| (0..r.comparison.cycle_amp_model.len()).map(move |i| (r, i))).collect();
    tables::write_table(
        &dir.join("cycles.parquet"),
        vec![
            ("test".into(), Column::Str(cyc.iter().map(|(r, _)| r.test.name.clone()).collect())),
            ("cycle".into(), Column::U32(cyc.iter().map(|(_, i)| *i as u32).collect())),
            ("amp_measured".into(), Column::F64(cyc.iter().map(|(r, i)| r.comparison.cycle_amp_measured[*i]).collect())),
            ("amp_model".into(), Column::F64(cyc.iter().map(|(r, i)| r.comparison.cycle_amp_model[*i]).collect())),
        ],
        &meta,
    )?;

    let ov: Vec<(&Compared, usize)> = results.iter().flat_map(|r| (r.window.0..r.window.1).map(move |k| (r, k))).collect();
    tables::write_table(
        &dir.join("overlay.parquet"),
        vec![
            ("test".into(), Column::Str(ov.iter().map(|(r, _)| r.test.name.clone()).collect())),
            ("time_s".into(), Column::F64(ov.iter().map(|(r, k)| r.time[*k]).collect())),
            ("accel_measured_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.accel_measured[*k]).collect())),
            ("accel_model_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.accel_model[*k]).collect())),
            ("residual_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.accel_model[*k] - r.accel_measured[*k]).collect())),
        ],
        &meta,
    )?;
    Ok(())
}
