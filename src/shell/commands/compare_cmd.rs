//! `study compare`: drive the model with each measured test's excitation and show where it
//! differs: harmonics, amplitude, part of the cycle, envelope; per test and across the campaign.

use crate::kernel::metrics::N_HARM;
use crate::orchestration::diagnosis::compare::{CompareSpec, ComparedTest, Comparison};
use crate::orchestration::diagnosis::statemap::{self, StateMap};
use crate::orchestration::measured::aligned::{self, fmt_row, Start};
use crate::orchestration::measured::timebase::fmt_rate;
use crate::shell::cli::{CompareArgs, OpenLoop};
use crate::shell::formats::campaign_io::{load_campaign, load_model, load_tests, report_checks};
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use crate::shell::job::progress::Progress;
use crate::shell::report::statemap_report;
use crate::shell::RunFailed;
use std::io::Write;
use std::path::Path;

impl From<OpenLoop> for aligned::OpenLoop {
    fn from(o: OpenLoop) -> Self {
        match o {
            OpenLoop::Valve => aligned::OpenLoop::Valve,
            OpenLoop::Spool => aligned::OpenLoop::Spool,
        }
    }
}

/// A number for a table cell: "-" for NaN.
fn cell(v: f64, f: impl Fn(f64) -> String) -> String {
    if v.is_finite() {
        f(v)
    } else {
        "-".into()
    }
}

pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    run_to(args, &mut std::io::stdout())
}

/// The command, its report printed to `o` (the Python package keeps it as text).
pub(crate) fn run_to(args: &CompareArgs, o: &mut dyn Write) -> anyhow::Result<()> {
    let model = load_model(args.model.as_deref())?;
    let lc = load_campaign(&args.campaign, &model)?;
    let open_loop = args.open_loop.map(aligned::OpenLoop::from);
    let spec = CompareSpec {
        tests: load_tests(&lc, open_loop)?,
        open_loop,
        solver: Default::default(),
    };
    let progress = Progress::new("compare", spec.tests.len(), false, args.log_progress);
    let results = crate::shell::job::study_job::pool(args.threads)?
        .install(|| spec.run_with(&|| progress.inc(1)))
        .map_err(RunFailed)?;
    progress.finish();
    let residual_warnings: Vec<String> = results
        .iter()
        .filter_map(ComparedTest::residual_warning)
        .collect();
    let state_map = statemap::map(&results);
    let model_name = args
        .model
        .as_ref()
        .map_or("defaults".to_string(), |p| p.display().to_string());
    writeln!(
        o,
        "study compare {} ({} tests, model: {model_name}, {})",
        args.campaign.display(),
        results.len(),
        spec.drive_label()
    )?;
    writeln!(o)?;
    print_tests(o, &results)?;
    print_files(o, &results)?;
    print_bins(o, &results)?;
    print_amplitudes(o, &results)?;
    statemap_report::print(o, &state_map)?;
    report_checks(
        o,
        &args.campaign,
        &spec.tests,
        &residual_warnings,
        args.strict,
    )?;
    if let Some(dir) = &args.report {
        write_tables(dir, &results, &state_map, &spec.drive_label())?;
        let title = format!(
            "vshake: model versus measurement, {} ({})",
            args.campaign.display(),
            spec.drive_label()
        );
        let path = dir.join("report.html");
        let out = parquet_write::AtomicFile::new(&path);
        std::fs::write(
            &out.tmp,
            crate::shell::report::kit::html(&title, &results, &state_map, &residual_warnings)?,
        )?;
        out.commit()?;
        writeln!(o, "\n  wrote {} and its tables (tests, harmonics, bins, cycles, overlay, statemap, stateterms .parquet)", path.display())?;
    }
    let n_warn =
        spec.tests.iter().map(|t| t.warnings.len()).sum::<usize>() + residual_warnings.len();
    if n_warn > 0 {
        eprintln!("warning: {n_warn} warning(s) about the measured data: see the WARNINGS block of the output");
    }
    Ok(())
}

fn print_tests(o: &mut dyn Write, results: &[ComparedTest]) -> std::io::Result<()> {
    writeln!(
        o,
        "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10} {:>10} {:>10} {:>10} {:>15}",
        "test",
        "excitation",
        "ratio meas/mod",
        "phase° meas/mod",
        "h3 meas/mod",
        "resid a",
        "resid x",
        "resid F",
        "worst k",
        "drift meas/mod"
    )?;
    for r in results {
        let c = &r.comparison;
        let (label, _, _) = r.test.excitation.label();
        let worst = (1..N_HARM)
            .filter(|&k| c.residual[k].0.is_finite())
            .max_by(|&a, &b| {
                c.residual[a]
                    .0
                    .hypot(c.residual[a].1)
                    .total_cmp(&c.residual[b].0.hypot(c.residual[b].1))
            });
        let worst = worst.map_or("-".to_string(), |k| {
            format!("h{} {:.1e}", k + 1, c.residual[k].0.hypot(c.residual[k].1))
        });
        writeln!(
            o,
            "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10} {:>10} {:>10} {:>10} {:>15}",
            r.test.name,
            label,
            format!(
                "{}/{}",
                cell(c.amp_ratio_measured, |v| format!("{v:.4}")),
                cell(c.amp_ratio_model, |v| format!("{v:.4}"))
            ),
            format!(
                "{}/{}",
                cell(c.phase_measured_deg, |v| format!("{v:+.2}")),
                cell(c.phase_model_deg, |v| format!("{v:+.2}"))
            ),
            format!(
                "{}/{}",
                cell(c.h_measured[1], |v| format!("{v:.4}")),
                cell(c.h_model[1], |v| format!("{v:.4}"))
            ),
            cell(c.rms_residual_accel_ratio, |v| format!("{v:.2e}")),
            cell(c.rms_residual_disp_ratio, |v| format!("{v:.2e}")),
            c.rms_residual_force_ratio
                .map_or("-".to_string(), |v| cell(v, |v| format!("{v:.2e}"))),
            worst,
            format!(
                "{}/{}",
                cell(c.drift_measured, |v| format!("{v:+.1e}")),
                cell(c.drift_model, |v| format!("{v:+.1e}"))
            ),
        )?;
    }
    Ok(())
}

/// How each file was read: its rate, where the excitation starts and ends, the window.
fn print_files(o: &mut dyn Write, results: &[ComparedTest]) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  data files (sample rate; where the excitation starts and ends in the file; the analysis window):")?;
    writeln!(
        o,
        "  {:<22} {:>10}  {:<28} {:<20} window",
        "test", "rate", "start", "end"
    )?;
    for r in results {
        let a = &r.test.alignment;
        let how = match a.start {
            Start::Detected => "found",
            Start::Given => "t0_s",
            Start::FirstRow => "first row",
        };
        let window = match a.cycles {
            Some(c) => format!("{c} cycles, {} samples", a.window.1 - a.window.0),
            None => format!("{} samples", a.window.1 - a.window.0),
        };
        writeln!(
            o,
            "  {:<22} {:>10}  {:<28} {:<20} {}",
            r.test.name,
            format!("{} Hz", fmt_rate(a.time.rate_hz)),
            format!("{:.4} s (row {}, {how})", a.start_s(), fmt_row(a.start_row)),
            format!("{:.4} s (row {})", a.end_s(), a.end_row),
            window
        )?;
    }
    Ok(())
}

fn print_bins(o: &mut dyn Write, results: &[ComparedTest]) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  residual of the acceleration by part of the cycle (rms in the part / rms of the measured acceleration):")?;
    writeln!(o, "  (and the kinematic consistency |a1|/(w^2 |x1|) of the acceleration and displacement channels: 1 for one rigid body)")?;
    writeln!(
        o,
        "  {:<22} {:>18} {:>18} {:>18} {:>17}",
        "test", "velocity reversal", "peak velocity", "peak displacement", "a/x meas/mod"
    )?;
    for r in results {
        let c = &r.comparison;
        let b = &c.bins;
        let e = |v: f64| cell(v, |v| format!("{v:.2e}"));
        writeln!(
            o,
            "  {:<22} {:>18} {:>18} {:>18} {:>17}",
            r.test.name,
            e(b[0].rms_residual_ratio),
            e(b[1].rms_residual_ratio),
            e(b[2].rms_residual_ratio),
            format!(
                "{}/{}",
                cell(c.accel_over_disp_measured, |v| format!("{v:.4}")),
                cell(c.accel_over_disp_model, |v| format!("{v:.4}"))
            )
        )?;
    }
    Ok(())
}

/// Across the campaign: error against amplitude, per frequency.
fn print_amplitudes(o: &mut dyn Write, results: &[ComparedTest]) -> std::io::Result<()> {
    let mut sines: Vec<(f64, f64, &ComparedTest)> = results
        .iter()
        .filter_map(|r| match r.test.excitation.label() {
            (_, f, g) if f.is_finite() => Some((f, g, r)),
            _ => None,
        })
        .collect();
    if sines.is_empty() {
        return Ok(());
    }
    sines.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    writeln!(o)?;
    writeln!(
        o,
        "  error against amplitude, per frequency (rms acceleration residual / rms measured):"
    )?;
    let mut last = f64::NAN;
    for (f, g, r) in &sines {
        if *f != last {
            write!(o, "{}  {f:>6} Hz:", if last.is_nan() { "" } else { "\n" })?;
            last = *f;
        }
        write!(
            o,
            "  {g:.2} g -> {}",
            cell(r.comparison.rms_residual_accel_ratio, |v| format!(
                "{v:.2e}"
            ))
        )?;
    }
    writeln!(o)
}

/// The Parquet tables of a comparison: one per kind of thing a report plots.
pub(crate) fn write_tables(
    dir: &Path,
    results: &[ComparedTest],
    map: &StateMap,
    drive: &str,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut meta = meta::header(Kind::Compare);
    meta.push(meta::pair(Key::Drive, drive));
    parquet_write::write_table(&dir.join("tests.parquet"), tests_columns(results), &meta)?;
    statemap_report::write(dir, map, &meta)?;
    parquet_write::write_table(
        &dir.join("harmonics.parquet"),
        harmonics_columns(results),
        &meta,
    )?;
    parquet_write::write_table(&dir.join("bins.parquet"), bins_columns(results), &meta)?;
    parquet_write::write_table(&dir.join("cycles.parquet"), cycles_columns(results), &meta)?;
    parquet_write::write_table(
        &dir.join("overlay.parquet"),
        overlay_columns(results),
        &meta,
    )
}

/// `tests.parquet`: one row per test.
fn tests_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let mut cols = test_alignment_columns(results);
    cols.extend(test_ratio_columns(results));
    cols.extend(test_residual_columns(results));
    cols
}

/// `tests.parquet`'s test, excitation and where it lies in the file.
fn test_alignment_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let s = |f: &dyn Fn(&ComparedTest) -> String| Column::Str(results.iter().map(f).collect());
    let x = |f: &dyn Fn(&ComparedTest) -> f64| Column::F64(results.iter().map(f).collect());
    vec![
        ("test".to_string(), s(&|r| r.test.name.clone())),
        (
            "excitation".to_string(),
            s(&|r| r.test.excitation.label().0),
        ),
        ("freq_hz".to_string(), x(&|r| r.test.excitation.label().1)),
        ("amp_g".to_string(), x(&|r| r.test.excitation.label().2)),
        ("rate_hz".to_string(), x(&|r| r.test.alignment.time.rate_hz)),
        ("start_s".to_string(), x(&|r| r.test.alignment.start_s())),
        (
            "start_row".to_string(),
            x(&|r| r.test.alignment.start_row + 1.0),
        ),
        ("end_s".to_string(), x(&|r| r.test.alignment.end_s())),
        (
            "window_samples".to_string(),
            Column::U32(
                results
                    .iter()
                    .map(|r| r.test.samples.len() as u32)
                    .collect(),
            ),
        ),
    ]
}

/// `tests.parquet`'s fundamental's amplitude ratios and phases, and the harmonic ratios.
fn test_ratio_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let x = |f: &dyn Fn(&ComparedTest) -> f64| Column::F64(results.iter().map(f).collect());
    let mut cols = vec![
        (
            "amp_ratio_measured".to_string(),
            x(&|r| r.comparison.amp_ratio_measured),
        ),
        (
            "amp_ratio_model".to_string(),
            x(&|r| r.comparison.amp_ratio_model),
        ),
        (
            "phase_measured_deg".to_string(),
            x(&|r| r.comparison.phase_measured_deg),
        ),
        (
            "phase_model_deg".to_string(),
            x(&|r| r.comparison.phase_model_deg),
        ),
    ];
    for k in 2..=N_HARM {
        cols.push((
            format!("h{k}_measured_ratio"),
            x(&|r| r.comparison.h_measured[k - 2]),
        ));
        cols.push((
            format!("h{k}_model_ratio"),
            x(&|r| r.comparison.h_model[k - 2]),
        ));
    }
    cols
}

/// `tests.parquet`'s residuals, drifts, kinematic ratios, warnings and notes.
fn test_residual_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let x = |f: &dyn Fn(&ComparedTest) -> f64| Column::F64(results.iter().map(f).collect());
    let list =
        |f: &dyn Fn(&ComparedTest) -> Vec<String>| Column::StrList(results.iter().map(f).collect());
    vec![
        (
            "rms_residual_accel_ratio".to_string(),
            x(&|r| r.comparison.rms_residual_accel_ratio),
        ),
        (
            "rms_residual_disp_ratio".to_string(),
            x(&|r| r.comparison.rms_residual_disp_ratio),
        ),
        (
            "rms_residual_force_ratio".to_string(),
            Column::OptF64(
                results
                    .iter()
                    .map(|r| r.comparison.rms_residual_force_ratio)
                    .collect(),
            ),
        ),
        (
            "drift_measured_per_cycle".to_string(),
            x(&|r| r.comparison.drift_measured),
        ),
        (
            "drift_model_per_cycle".to_string(),
            x(&|r| r.comparison.drift_model),
        ),
        (
            "accel_over_disp_measured".to_string(),
            x(&|r| r.comparison.accel_over_disp_measured),
        ),
        (
            "accel_over_disp_model".to_string(),
            x(&|r| r.comparison.accel_over_disp_model),
        ),
        (
            "warnings".to_string(),
            list(&|r| {
                r.test
                    .warnings
                    .iter()
                    .cloned()
                    .chain(r.residual_warning())
                    .collect()
            }),
        ),
        ("notes".to_string(), list(&|r| r.test.notes.clone())),
    ]
}

/// `harmonics.parquet`: per test and harmonic, the model's, the measurement's and the residual's
/// complex amplitude.
fn harmonics_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let rows: Vec<(&ComparedTest, usize)> = results
        .iter()
        .flat_map(|r| (0..N_HARM).map(move |k| (r, k)))
        .collect();
    let hx = |f: &dyn Fn(&Comparison, usize) -> f64| {
        Column::F64(rows.iter().map(|(r, k)| f(&r.comparison, *k)).collect())
    };
    vec![
        (
            "test".into(),
            Column::Str(rows.iter().map(|(r, _)| r.test.name.clone()).collect()),
        ),
        (
            "k".into(),
            Column::U32(rows.iter().map(|(_, k)| *k as u32 + 1).collect()),
        ),
        ("model_re".into(), hx(&|c, k| c.harm_model[k].0)),
        ("model_im".into(), hx(&|c, k| c.harm_model[k].1)),
        ("measured_re".into(), hx(&|c, k| c.harm_measured[k].0)),
        ("measured_im".into(), hx(&|c, k| c.harm_measured[k].1)),
        ("residual_re".into(), hx(&|c, k| c.residual[k].0)),
        ("residual_im".into(), hx(&|c, k| c.residual[k].1)),
        (
            "residual_abs".into(),
            hx(&|c, k| c.residual[k].0.hypot(c.residual[k].1)),
        ),
    ]
}

/// `bins.parquet`: per test and part of the cycle, the residual.
fn bins_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let bins: Vec<(&ComparedTest, usize)> = results
        .iter()
        .flat_map(|r| (0..3).map(move |b| (r, b)))
        .collect();
    vec![
        (
            "test".into(),
            Column::Str(bins.iter().map(|(r, _)| r.test.name.clone()).collect()),
        ),
        (
            "bin".into(),
            Column::Str(
                bins.iter()
                    .map(|(r, b)| r.comparison.bins[*b].name.to_string())
                    .collect(),
            ),
        ),
        (
            "fraction".into(),
            Column::F64(
                bins.iter()
                    .map(|(r, b)| r.comparison.bins[*b].fraction)
                    .collect(),
            ),
        ),
        (
            "rms_residual_ratio".into(),
            Column::F64(
                bins.iter()
                    .map(|(r, b)| r.comparison.bins[*b].rms_residual_ratio)
                    .collect(),
            ),
        ),
    ]
}

/// `cycles.parquet`: per test and cycle, the measured and the model's amplitude.
fn cycles_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let cyc: Vec<(&ComparedTest, usize)> = results
        .iter()
        .flat_map(|r| (0..r.comparison.cycle_amp_model.len()).map(move |i| (r, i)))
        .collect();
    vec![
        (
            "test".into(),
            Column::Str(cyc.iter().map(|(r, _)| r.test.name.clone()).collect()),
        ),
        (
            "cycle".into(),
            Column::U32(cyc.iter().map(|(_, i)| *i as u32).collect()),
        ),
        (
            "amp_measured".into(),
            Column::F64(
                cyc.iter()
                    .map(|(r, i)| r.comparison.cycle_amp_measured[*i])
                    .collect(),
            ),
        ),
        (
            "amp_model".into(),
            Column::F64(
                cyc.iter()
                    .map(|(r, i)| r.comparison.cycle_amp_model[*i])
                    .collect(),
            ),
        ),
    ]
}

/// `overlay.parquet`: per test and sample of the window, the measured and the model's
/// acceleration.
fn overlay_columns(results: &[ComparedTest]) -> Vec<(String, Column)> {
    let ov: Vec<(&ComparedTest, usize)> = results
        .iter()
        .flat_map(|r| (0..r.test.samples.len()).map(move |k| (r, k)))
        .collect();
    vec![
        (
            "test".into(),
            Column::Str(ov.iter().map(|(r, _)| r.test.name.clone()).collect()),
        ),
        (
            "time_s".into(),
            Column::F64(ov.iter().map(|(r, k)| r.test.samples.time[*k]).collect()),
        ),
        (
            "accel_measured_mps2".into(),
            Column::F64(ov.iter().map(|(r, k)| r.test.measured.accel[*k]).collect()),
        ),
        (
            "accel_model_mps2".into(),
            Column::F64(ov.iter().map(|(r, k)| r.accel_model[*k]).collect()),
        ),
        (
            "residual_mps2".into(),
            Column::F64(
                ov.iter()
                    .map(|(r, k)| r.accel_model[*k] - r.test.measured.accel[*k])
                    .collect(),
            ),
        ),
    ]
}
