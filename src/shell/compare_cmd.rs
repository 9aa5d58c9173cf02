//! `study compare`: drive the model with each measured test's excitation and show where it
//! differs: harmonics, amplitude, part of the cycle, envelope; per test and across the campaign.

use super::campaign_io::{load_campaign, load_model, load_tests, report_checks};
use super::cli::{CompareArgs, OpenLoop};
use super::tables::{self, Column};
use super::RunFailed;
use crate::kernel::metrics::N_HARM;
use crate::orchestration::compare::{self, Compared, Comparison};
use crate::orchestration::statemap::{self, StateMap};
use crate::orchestration::measured::{self, fmt_row, AlignedTest, Start};
use crate::orchestration::spec::ExcitationSpec;
use crate::orchestration::timebase::fmt_rate;
use rayon::prelude::*;
use std::io::Write;

/// A test's excitation in words, with its frequency and amplitude in g (NaN for a record).
pub fn excitation_label(e: &ExcitationSpec) -> (String, f64, f64) {
    match e {
        ExcitationSpec::Sine { sine, amp_g } => {
            let g = amp_g.unwrap_or(sine.amp_m * (2.0 * std::f64::consts::PI * sine.freq_hz).powi(2) / crate::kernel::params::G);
            (format!("sine {} Hz {:.2} g", sine.freq_hz, g), sine.freq_hz, g)
        }
        ExcitationSpec::Record { column, .. } => (format!("record {column}"), f64::NAN, f64::NAN),
    }
}

impl From<OpenLoop> for measured::OpenLoop {
    fn from(o: OpenLoop) -> Self {
        match o {
            OpenLoop::Valve => measured::OpenLoop::Valve,
            OpenLoop::Spool => measured::OpenLoop::Spool,
        }
    }
}

/// Compares every test (in parallel); a model failure stops with its test and reason.
fn compare_all(tests: &[AlignedTest]) -> anyhow::Result<Vec<Compared>> {
    let solver = Default::default();
    let out: Vec<Result<Compared, String>> = tests.par_iter().map(|t| compare::compare_test(t, &solver)).collect();
    out.into_iter().map(|r| r.map_err(|e| RunFailed(e).into())).collect()
}

/// A number for a table cell: "-" for NaN.
fn cell(v: f64, f: impl Fn(f64) -> String) -> String {
    if v.is_finite() { f(v) } else { "-".into() }
}

pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    let model = load_model(args.model.as_deref())?;
    let lc = load_campaign(&args.campaign, &model)?;
    let tests = load_tests(&lc, args.open_loop.map(Into::into))?;
    let results = compare_all(&tests)?;
    let residual_warnings: Vec<String> = results.iter().filter_map(Compared::residual_warning).collect();
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
    print_tests(&mut o, &results)?;
    print_files(&mut o, &results)?;
    print_bins(&mut o, &results)?;
    print_amplitudes(&mut o, &results)?;
    let state_map = statemap::map(&results);
    print_state_map(&mut o, &state_map)?;
    report_checks(&mut o, &args.campaign, &tests, &residual_warnings, args.strict)?;
    let n_warn = tests.iter().map(|t| t.warnings.len()).sum::<usize>() + residual_warnings.len();
    if let Some(dir) = &args.report {
        write_tables(dir, &results, &state_map, args.open_loop)?;
        let page = super::report::html(&format!("vshake: model versus measurement, {} ({})", args.campaign.display(), drive_label(args.open_loop)), &results, &state_map, &residual_warnings)?;
        let path = dir.join("report.html");
        let out = tables::AtomicFile::new(&path);
        std::fs::write(&out.tmp, page)?;
        out.commit()?;
        writeln!(o, "\n  wrote {} and its tables (tests, harmonics, bins, cycles, overlay, statemap, stateterms .parquet)", path.display())?;
    }
    if n_warn > 0 {
        eprintln!("warning: {n_warn} warning(s) about the measured data: see the WARNINGS block of the output");
    }
    Ok(())
}

fn print_tests(o: &mut dyn Write, results: &[Compared]) -> std::io::Result<()> {
    writeln!(
        o,
        "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10} {:>10} {:>10} {:>10} {:>15}",
        "test", "excitation", "ratio meas/mod", "phase° meas/mod", "h3 meas/mod", "resid a", "resid x", "resid F", "worst k", "drift meas/mod"
    )?;
    for r in results {
        let c = &r.comparison;
        let (label, _, _) = excitation_label(&r.test.excitation);
        let worst = (1..N_HARM).filter(|&k| c.residual[k].0.is_finite()).max_by(|&a, &b| c.residual[a].0.hypot(c.residual[a].1).total_cmp(&c.residual[b].0.hypot(c.residual[b].1)));
        let worst = worst.map_or("-".to_string(), |k| format!("h{} {:.1e}", k + 1, c.residual[k].0.hypot(c.residual[k].1)));
        writeln!(
            o,
            "  {:<22} {:<20} {:>15} {:>17} {:>15} {:>10} {:>10} {:>10} {:>10} {:>15}",
            r.test.name,
            label,
            format!("{}/{}", cell(c.amp_ratio_measured, |v| format!("{v:.4}")), cell(c.amp_ratio_model, |v| format!("{v:.4}"))),
            format!("{}/{}", cell(c.phase_measured_deg, |v| format!("{v:+.2}")), cell(c.phase_model_deg, |v| format!("{v:+.2}"))),
            format!("{}/{}", cell(c.h_measured[1], |v| format!("{v:.4}")), cell(c.h_model[1], |v| format!("{v:.4}"))),
            cell(c.rms_residual_accel_ratio, |v| format!("{v:.2e}")),
            cell(c.rms_residual_disp_ratio, |v| format!("{v:.2e}")),
            c.rms_residual_force_ratio.map_or("-".to_string(), |v| cell(v, |v| format!("{v:.2e}"))),
            worst,
            format!("{}/{}", cell(c.drift_measured, |v| format!("{v:+.1e}")), cell(c.drift_model, |v| format!("{v:+.1e}"))),
        )?;
    }
    Ok(())
}

/// How each file was read: its rate, where the excitation starts and ends, the window.
fn print_files(o: &mut dyn Write, results: &[Compared]) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  data files (sample rate; where the excitation starts and ends in the file; the analysis window):")?;
    writeln!(o, "  {:<22} {:>10}  {:<28} {:<20} {}", "test", "rate", "start", "end", "window")?;
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


fn print_bins(o: &mut dyn Write, results: &[Compared]) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  residual of the acceleration by part of the cycle (rms in the part / rms of the measured acceleration):")?;
    writeln!(o, "  (and the kinematic consistency |a1|/(w^2 |x1|) of the acceleration and displacement channels: 1 for one rigid body)")?;
    writeln!(o, "  {:<22} {:>18} {:>18} {:>18} {:>17}", "test", "velocity reversal", "peak velocity", "peak displacement", "a/x meas/mod")?;
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
            format!("{}/{}", cell(c.accel_over_disp_measured, |v| format!("{v:.4}")), cell(c.accel_over_disp_model, |v| format!("{v:.4}")))
        )?;
    }
    Ok(())
}

/// Across the campaign: error against amplitude, per frequency.
fn print_amplitudes(o: &mut dyn Write, results: &[Compared]) -> std::io::Result<()> {
    let mut sines: Vec<(f64, f64, &Compared)> =
        results.iter().filter_map(|r| match excitation_label(&r.test.excitation) { (_, f, g) if f.is_finite() => Some((f, g, r)), _ => None }).collect();
    if sines.is_empty() {
        return Ok(());
    }
    sines.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    writeln!(o)?;
    writeln!(o, "  error against amplitude, per frequency (rms acceleration residual / rms measured):")?;
    let mut last = f64::NAN;
    for (f, g, r) in &sines {
        if *f != last {
            write!(o, "{}  {f:>6} Hz:", if last.is_nan() { "" } else { "\n" })?;
            last = *f;
        }
        write!(o, "  {g:.2} g -> {}", cell(r.comparison.rms_residual_accel_ratio, |v| format!("{v:.2e}")))?;
    }
    writeln!(o)
}

/// Where in state space the residual lies: per residual, the share each state's terms explain
/// and their strongest terms, then the one sentence.
pub fn print_state_map(o: &mut dyn Write, map: &StateMap) -> std::io::Result<()> {
    writeln!(o)?;
    writeln!(o, "  where in state space ({} samples; R^2 of a sparse regression on each state's terms, then its terms with their R^2 alone; docs/model.md §8):", map.samples)?;
    for r in statemap::REGRESSED {
        if map.by_state(r).is_empty() {
            continue;
        }
        writeln!(o, "  {}:", r.label())?;
        for reg in map.by_state(r) {
            let terms: Vec<String> = reg.terms.iter().take(3).map(|t| format!("{} ({:.2})", t.formula(), t.alone)).collect();
            let st = reg.state.map_or("all states", |s| s.label());
            writeln!(o, "    {:<28} R^2 {:>5.2}  {}", st, reg.r2, if terms.is_empty() { "-".to_string() } else { terms.join(", ") })?;
        }
        for (_, m) in map.memory.iter().filter(|(res, _)| *res == r) {
            writeln!(o, "    {:<28} R^2 {:>5.2}  {}", m.kind.name(), m.r2, m.describe())?;
        }
    }
    match map.sentence() {
        Some(s) => writeln!(o, "  -> {s}")?,
        None => writeln!(o, "  -> no state's terms explain the residual (R^2 < {}): noise, or an effect neither a static term nor an oscillator holds", statemap::MIN_R2)?,
    }
    Ok(())
}

/// The state map's tables: `statemap.parquet` (per state and bin, each residual's mean and rms)
/// and `stateterms.parquet` (per regression, its R² and the terms kept).
pub fn write_state_map(dir: &std::path::Path, map: &StateMap, meta: &[(String, String)]) -> anyhow::Result<()> {
    use statemap::Residual;
    let b = &map.bins;
    let f = |g: &dyn Fn(&statemap::MapBin) -> f64| Column::F64(b.iter().map(g).collect());
    let mut cols = vec![
        ("state".to_string(), Column::Str(b.iter().map(|x| x.state.name().to_string()).collect())),
        ("bin_lo".to_string(), f(&|x| x.lo)),
        ("bin_hi".to_string(), f(&|x| x.hi)),
        ("scale".to_string(), f(&|x| x.scale)),
        ("scale_unit".to_string(), Column::Str(b.iter().map(|x| x.state.scale_unit().to_string()).collect())),
        ("samples".to_string(), Column::U32(b.iter().map(|x| x.samples as u32).collect())),
    ];
    for (i, r) in Residual::ALL.iter().enumerate() {
        cols.push((format!("mean_{}", r.name()), f(&|x| x.mean[i])));
        cols.push((format!("rms_{}", r.name()), f(&|x| x.rms[i])));
    }
    tables::write_table(&dir.join("statemap.parquet"), cols, meta)?;
    tables::write_table(&dir.join("stateterms.parquet"), state_term_rows(map).into_columns(), meta)
}

/// The rows of `stateterms.parquet`: every regression's terms (one row without a term when it
/// kept none), then the terms with memory (the filter's `f_n_hz` and `zeta`; its gain in `coef`:
/// for the oscillator the mass, kg); `named` marks the row the map's sentence names.
#[derive(Default)]
struct StateTermRows {
    residual: Vec<String>,
    states: Vec<String>,
    r2: Vec<f64>,
    term_state: Vec<String>,
    term: Vec<String>,
    coef: Vec<f64>,
    r2_alone: Vec<f64>,
    named: Vec<bool>,
    /// A term with memory's natural frequency (Hz) and damping ratio; NaN for a static term.
    f_n_hz: Vec<f64>,
    zeta: Vec<f64>,
}

impl StateTermRows {
    #[allow(clippy::too_many_arguments)]
    fn push(&mut self, residual: statemap::Residual, states: &str, r2: f64, term_state: &str, term: String, coef: f64, alone: f64, named: bool) {
        self.residual.push(residual.name().into());
        self.states.push(states.into());
        self.r2.push(r2);
        self.term_state.push(term_state.into());
        self.term.push(term);
        self.coef.push(coef);
        self.r2_alone.push(alone);
        self.named.push(named);
        self.f_n_hz.push(f64::NAN);
        self.zeta.push(f64::NAN);
    }

    fn into_columns(self) -> Vec<(String, Column)> {
        vec![
            ("residual".into(), Column::Str(self.residual)),
            ("states".into(), Column::Str(self.states)),
            ("r2".into(), Column::F64(self.r2)),
            ("term_state".into(), Column::Str(self.term_state)),
            ("term".into(), Column::Str(self.term)),
            ("coef".into(), Column::F64(self.coef)),
            ("r2_alone".into(), Column::F64(self.r2_alone)),
            ("named".into(), Column::Bool(self.named)),
            ("f_n_hz".into(), Column::F64(self.f_n_hz)),
            ("zeta".into(), Column::F64(self.zeta)),
        ]
    }
}

fn state_term_rows(map: &StateMap) -> StateTermRows {
    use statemap::Named;
    let named = map.named();
    let mut rows = StateTermRows::default();
    for g in map.per_state.iter().flatten().chain(&map.joint) {
        let states = g.state.map_or("all", |s| s.name());
        if g.terms.is_empty() {
            rows.push(g.residual, states, g.r2, "", String::new(), f64::NAN, f64::NAN, false);
        }
        for t in &g.terms {
            let is = matches!(named, Some(Named::Static(ng, nt)) if std::ptr::eq(ng, g) && std::ptr::eq(nt, t));
            rows.push(g.residual, states, g.r2, t.state.name(), t.formula(), t.coef, t.alone, is);
        }
    }
    for (r, m) in &map.memory {
        let st = m.kind.state().name();
        let term = format!("{} (f_n {:.3} Hz, ζ {:.4})", m.kind.name(), m.f_n, m.zeta);
        rows.push(*r, st, m.r2, st, term, m.gain, m.r2, matches!(named, Some(Named::Memory(_, n)) if std::ptr::eq(n, m)));
        (rows.f_n_hz[rows.r2.len() - 1], rows.zeta[rows.r2.len() - 1]) = (m.f_n, m.zeta);
    }
    rows
}

/// How the model was driven, in words.
pub fn drive_label(open_loop: Option<OpenLoop>) -> String {
    match open_loop {
        None => "closed loop".to_string(),
        Some(m) => format!("open loop on the measured {}", measured::OpenLoop::from(m).column()),
    }
}

/// The Parquet tables of a comparison: one per kind of thing a report plots.
pub fn write_tables(dir: &std::path::Path, results: &[Compared], map: &StateMap, open_loop: Option<OpenLoop>) -> anyhow::Result<()> {
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
        ("rate_hz".to_string(), x(&|r| r.test.alignment.time.rate_hz)),
        ("start_s".to_string(), x(&|r| r.test.alignment.start_s())),
        ("start_row".to_string(), x(&|r| r.test.alignment.start_row + 1.0)),
        ("end_s".to_string(), x(&|r| r.test.alignment.end_s())),
        ("window_samples".to_string(), Column::U32(results.iter().map(|r| r.test.samples.len() as u32).collect())),
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
        ("warnings".to_string(), s(&|r| r.test.warnings.iter().cloned().chain(r.residual_warning()).collect::<Vec<_>>().join("\n"))),
        ("notes".to_string(), s(&|r| r.test.notes.join("\n"))),
    ]);
    tables::write_table(&dir.join("tests.parquet"), cols, &meta)?;
    write_state_map(dir, map, &meta)?;

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

    let ov: Vec<(&Compared, usize)> = results.iter().flat_map(|r| (0..r.test.samples.len()).map(move |k| (r, k))).collect();
    tables::write_table(
        &dir.join("overlay.parquet"),
        vec![
            ("test".into(), Column::Str(ov.iter().map(|(r, _)| r.test.name.clone()).collect())),
            ("time_s".into(), Column::F64(ov.iter().map(|(r, k)| r.test.samples.time[*k]).collect())),
            ("accel_measured_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.test.measured.accel[*k]).collect())),
            ("accel_model_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.accel_model[*k]).collect())),
            ("residual_mps2".into(), Column::F64(ov.iter().map(|(r, k)| r.accel_model[*k] - r.test.measured.accel[*k]).collect())),
        ],
        &meta,
    )?;
    Ok(())
}
