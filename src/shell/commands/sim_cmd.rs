//! `study sim`: resolve a run file, build its reference, run, print, write.

use crate::kernel::effects::EffectId;
use crate::kernel::excitation::Reference;
use crate::kernel::params::G;
use crate::kernel::simulate::{LaneResult, LaneStatus};
use crate::kernel::spectrum::SpectrumSpec;
use crate::orchestration::runs::adaptation::cycles;
use crate::orchestration::runs::authority::{authority_used, Authority};
use crate::orchestration::runs::building_response::building_response;
use crate::orchestration::runs::passes;
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::SimSpec;
use crate::shell::cli::SimArgs;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::run_spec::{build_reference, load_spec};
use crate::shell::RunFailed;
use anyhow::Context;
use std::io::Write;
use std::path::Path;

pub fn run(args: &SimArgs) -> anyhow::Result<()> {
    crate::shell::job::outputs::check_parquet_outputs([args.out.as_ref(), args.spectrum.as_ref()])?;
    let spec = load_spec(&args.file, args.model.as_deref())?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let reference = build_reference(&spec, base)?;
    let target = match &args.target {
        Some(t) => {
            let ts = load_spec(t, args.model.as_deref())?;
            Some(build_reference(&ts, t.parent().unwrap_or(Path::new(".")))?)
        }
        None => None,
    };
    check_passes(args, &spec)?;
    let mut stdout = std::io::stdout().lock();
    let out = run_passes(&mut stdout, args, &spec, &reference)?;
    if !args.quiet {
        header(&mut stdout, args, &spec)?;
    }
    let status = status_text(&out.result.status);
    writeln!(stdout, "  status      {status}")?;
    let alone = without_compensators(&spec, &reference)?;
    if let Some((names, _)) = &alone {
        writeln!(
            stdout,
            "  compensated {} (the last column: the TVC alone)",
            names.join(", ")
        )?;
    }
    writeln!(stdout)?;
    let alone_result = alone.as_ref().map(|a| &a.1.result);
    metrics_table(&mut stdout, &spec, &out.result, alone_result)?;
    if let Some((_, a)) = &alone {
        adaptation_table(&mut stdout, &reference, &out.history, &a.history)?;
        let rows = authority_used(&spec.model, &out.history, Some(&a.history));
        authority_table(&mut stdout, &rows)?;
    }
    let ran = matches!(out.result.status, LaneStatus::Ok);
    let compared = target.as_ref().unwrap_or(&reference);
    if let (Some(t), true) = (&target, ran) {
        against_target(&mut stdout, args, &out.history, t)?;
    }
    // A failed run's spectrum would be of part of the motion: not printed, not written.
    if let (Some((spectrum, psa)), true) = (&compared.spectrum, ran) {
        write_spectrum(&mut stdout, args, &out.history, compared, spectrum, psa)?;
    }
    if let Some(b) = building_response(&spec.model, &out.history) {
        write!(stdout, "\n{b}")?;
    }
    if let Some(path) = &args.out {
        write_history(path, &spec, &out, &status)?;
        writeln!(
            stdout,
            "\nwrote {} ({} rows x {} channels)",
            path.display(),
            out.history.len(),
            out.history.named_columns().len()
        )?;
    }
    match out.result.status {
        LaneStatus::Ok => Ok(()),
        LaneStatus::Failed { .. } => {
            Err(RunFailed(format!("{}: run {status}", args.file.display())).into())
        }
    }
}

/// The run, or with `--passes`/`--learned` its passes (their table printed, the learned model
/// written): the last pass's outcome.
fn run_passes(
    stdout: &mut dyn Write,
    args: &SimArgs,
    spec: &SimSpec,
    reference: &Reference,
) -> anyhow::Result<single::SimOutcome> {
    if args.passes <= 1 && args.learned.is_none() {
        return Ok(single::run_sim(spec, reference)?);
    }
    let p = passes::passes(spec, reference, args.passes as usize)?;
    passes_table(stdout, spec, &p)?;
    if let Some(path) = &args.learned {
        let Some(best) = p.best() else {
            return Err(RunFailed(format!(
                "{}: no pass ran to the end; {} was not written",
                args.file.display(),
                path.display()
            ))
            .into());
        };
        write_learned(path, &args.file, &p.used[best], best + 1)?;
        writeln!(
            stdout,
            "  wrote {} (the inverse pass {} used, the lowest error; use it with --model)\n",
            path.display(),
            best + 1
        )?;
    }
    Ok(p.runs.into_iter().last().expect("one pass at least"))
}

/// The run's heading: its file, model, excitation and solver.
fn header(stdout: &mut dyn Write, args: &SimArgs, spec: &SimSpec) -> std::io::Result<()> {
    let h = 1.0 / (spec.model.controller.f_s * spec.solver.substeps as f64);
    writeln!(stdout, "study sim {}", args.file.display())?;
    if let Some(m) = &args.model {
        writeln!(
            stdout,
            "  model       {} (the run file's [model.*] on top)",
            m.display()
        )?;
    }
    writeln!(stdout, "  excitation  {}", spec.excitation.describe())?;
    writeln!(
        stdout,
        "  solver      RK4, {} substeps per tick (h = {:.2} µs), controller {} Hz, valve law {:?}",
        spec.solver.substeps,
        h * 1e6,
        spec.model.controller.f_s,
        spec.model.valve_law
    )
}

/// `--passes` and `--learned` need a compensator that learns across passes; `--learned` does not
/// replace a file it did not write.
fn check_passes(args: &SimArgs, spec: &SimSpec) -> anyhow::Result<()> {
    if let Some(path) = &args.learned {
        let what = "a model `study sim --learned` wrote";
        crate::shell::fit_problem::replaced_only_if_ours(path, LEARNED_HEAD, what)?;
        let folder = path.parent().filter(|f| !f.as_os_str().is_empty());
        if folder.is_some_and(|f| !f.is_dir()) {
            return Err(crate::shell::BadInput(format!(
                "{}: its folder does not exist; nothing was run (create it, or choose another file)",
                path.display()
            ))
            .into());
        }
    }
    let asked = args.passes > 1 || args.learned.is_some();
    if asked && !spec.model.effects.get(EffectId::AdaptiveInverse) {
        return Err(crate::shell::BadInput(format!(
            "{}: --passes and --learned carry adaptive_inverse's learned inverse from pass to pass, and the run has it off (add [model.adaptive_inverse], e.g. --model studies/compensation/adaptive_inverse.toml)",
            args.file.display()
        ))
        .into());
    }
    Ok(())
}

/// The first line of a model `--learned` writes.
const LEARNED_HEAD: &str = "# The inverse learned by `study sim";

/// The passes' errors, one row each (a failed pass: its status).
fn passes_table(o: &mut dyn Write, spec: &SimSpec, p: &passes::Passes) -> std::io::Result<()> {
    writeln!(
        o,
        "  passes: each from the inverse the last one learned (adaptive_inverse)"
    )?;
    let cols = [
        "rms_err_accel_ratio",
        "rms_err_disp_ratio",
        "amp_ratio",
        "thd_odd_ratio",
    ];
    write!(o, "  {:>4}", "pass")?;
    for c in cols {
        write!(o, " {c:>20}")?;
    }
    writeln!(o)?;
    let building = spec.model.effects.building;
    for (i, run) in p.runs.iter().enumerate() {
        write!(o, "  {:>4}", i + 1)?;
        if run.result.status != LaneStatus::Ok {
            writeln!(o, " {}", status_text(&run.result.status))?;
            continue;
        }
        let m = run.result.metrics.columns_for(building);
        for c in cols {
            let v = m.iter().find(|(n, _)| *n == c).map(|(_, v)| *v);
            write!(o, " {:>20}", v.map_or("-".to_string(), fmt_value))?;
        }
        writeln!(o)?;
    }
    writeln!(o)
}

/// The model of the best pass: the run's model with the taps pass `pass` used, every table.
fn write_learned(path: &Path, file: &Path, used: &SimSpec, pass: usize) -> anyhow::Result<()> {
    let mut root = toml::Table::new();
    let table = crate::orchestration::runs::spec::model_table(&used.model);
    root.insert("model".into(), toml::Value::Table(table));
    let head = format!(
        "{LEARNED_HEAD} {} --passes` (vshake {}): the run's model, [model.adaptive_inverse]'s taps w_i those pass {pass} used (the lowest rms acceleration error of the passes).\n",
        file.display(),
        env!("CARGO_PKG_VERSION")
    );
    let text = head + &toml::to_string(&root)?;
    crate::shell::job::outputs::write_whole(path, text.as_bytes())
}

/// Where the run has a compensator on (docs/model.md §7, `controller compensation`): their names
/// and the same run with every one of them off, the TVC alone.
fn without_compensators(
    spec: &SimSpec,
    reference: &Reference,
) -> anyhow::Result<Option<(Vec<&'static str>, single::SimOutcome)>> {
    let on: Vec<EffectId> = (EffectId::ALL.into_iter())
        .filter(|&e| e.compensates() && spec.model.effects.get(e))
        .collect();
    if on.is_empty() {
        return Ok(None);
    }
    let mut alone = spec.clone();
    for &e in &on {
        *alone.model.effects.get_mut(e) = false;
    }
    let names = on.iter().map(|e| e.name()).collect();
    Ok(Some((names, single::run_sim(&alone, reference)?)))
}

/// A sine run's cycles, about one a second, compensated and the TVC alone (issue 52: the
/// adaptation's history): the fundamental's amplitude ratio and THD_odd of each.
fn adaptation_table(
    o: &mut dyn Write,
    reference: &Reference,
    with: &single::History,
    alone: &single::History,
) -> std::io::Result<()> {
    let (c, a) = (cycles(with, reference), cycles(alone, reference));
    let Some(f0) = reference.fundamental_hz.filter(|_| !c.is_empty()) else {
        return Ok(());
    };
    writeln!(
        o,
        "\n  adaptation: each cycle's acceleration, compensated and the TVC alone"
    )?;
    writeln!(
        o,
        "  {:>8} {:>10} {:>10}   {:>10} {:>10}",
        "cycle to", "amp_ratio", "thd_odd", "amp_ratio", "thd_odd"
    )?;
    let every = (f0.round() as usize).max(1);
    let fmt = |x: Option<f64>| x.map_or("-".to_string(), fmt_value);
    for (i, w) in c.iter().enumerate() {
        if (i + 1) % every != 0 && i + 1 != c.len() {
            continue;
        }
        let b = a.get(i);
        writeln!(
            o,
            "  {:>7.2}s {:>10} {:>10}   {:>10} {:>10}",
            w.end_s,
            fmt_value(w.amp_ratio),
            fmt_value(w.thd_odd),
            fmt(b.map(|b| b.amp_ratio)),
            fmt(b.map(|b| b.thd_odd))
        )?;
    }
    Ok(())
}

/// The authority the compensated run used: the most of each limited quantity, its limit and the
/// share of it (the TVC alone's valve command beside).
fn authority_table(o: &mut dyn Write, rows: &[Authority]) -> std::io::Result<()> {
    writeln!(o, "\n  authority used (the most over the run; its limit)")?;
    writeln!(
        o,
        "  {:<36} {:>10} {:>10} {:>8} {:>10}",
        "", "used", "limit", "share", "TVC alone"
    )?;
    for r in rows {
        let alone = r.alone.map_or(String::new(), fmt_value);
        let row = format!(
            "  {:<36} {:>10} {:>10} {:>7.1}% {:>10}",
            format!("{} ({})", r.what, r.unit),
            fmt_value(r.used),
            fmt_value(r.limit),
            100.0 * r.used / r.limit,
            alone
        );
        writeln!(o, "{}", row.trim_end())?;
    }
    Ok(())
}

/// The metrics, with the TVC alone's beside them where `alone` is given (a failed run's: `-`).
fn metrics_table(
    o: &mut dyn Write,
    spec: &SimSpec,
    run: &LaneResult,
    alone: Option<&LaneResult>,
) -> std::io::Result<()> {
    let building = spec.model.effects.building;
    let other: Vec<f64> = match alone {
        Some(a) if a.status == LaneStatus::Ok => {
            let cols = a.metrics.columns_for(building);
            cols.into_iter().map(|(_, v)| v).collect()
        }
        _ => Vec::new(),
    };
    match alone {
        Some(_) => writeln!(o, "  {:<22} {:>12} {:>12}", "metric", "value", "TVC alone")?,
        None => writeln!(o, "  {:<22} {:>12}", "metric", "value")?,
    }
    for (i, (name, v)) in run.metrics.columns_for(building).into_iter().enumerate() {
        match alone {
            Some(_) => {
                let w = other.get(i).map_or("-".to_string(), |&x| fmt_value(x));
                writeln!(o, "  {name:<22} {:>12} {w:>12}", fmt_value(v))?
            }
            None => writeln!(o, "  {name:<22} {:>12}", fmt_value(v))?,
        }
    }
    Ok(())
}

/// A run's status in words: `ok`, or where and why it failed.
pub(crate) fn status_text(status: &LaneStatus) -> String {
    match *status {
        LaneStatus::Ok => "ok".to_string(),
        LaneStatus::Failed { time_s, reason } => format!("failed at t = {time_s:.4} s: {reason}"),
    }
}

/// Writes a run's time history (every channel) with the resolved run and its status as metadata.
pub(crate) fn write_history(
    path: &Path,
    spec: &SimSpec,
    out: &single::SimOutcome,
    status: &str,
) -> anyhow::Result<()> {
    let cols = out.history.named_columns();
    let mut meta = meta::header(Kind::TimeHistory);
    meta.extend([
        meta::pair(Key::Spec, spec.resolved_toml()),
        meta::pair(
            Key::SchemaVersion,
            crate::shell::job::study_job::SCHEMA_VERSION,
        ),
        meta::pair(Key::Status, status),
    ]);
    parquet_write::write_parquet(path, &cols, &meta)
        .with_context(|| format!("writing {}", path.display()))
}

/// The achieved acceleration against `--target`'s over the target's window (clipped to the
/// run): the rms error and the peak ratio.
fn against_target(
    o: &mut impl Write,
    args: &SimArgs,
    history: &single::History,
    target: &Reference,
) -> anyhow::Result<()> {
    let accel = history
        .channel("accel_mps2")
        .expect("a history has accel_mps2");
    let end = target.window.1.min(accel.len()).min(target.a.len());
    let start = target.window.0.min(end);
    let (got, want) = (&accel[start..end], &target.a[start..end]);
    let sq = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>();
    let err =
        (sq(&mut got.iter().zip(want).map(|(a, b)| a - b)) / sq(&mut want.iter().copied())).sqrt();
    let peak = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let path = args.target.as_ref().expect("a target was given");
    writeln!(o, "\n  against the target {}", path.display())?;
    writeln!(o, "  {:<22} {:>12}", "rms_err_accel_ratio", fmt_value(err))?;
    writeln!(
        o,
        "  {:<22} {:>12}",
        "pga_ratio",
        fmt_value(peak(got) / peak(want))
    )?;
    Ok(())
}

/// The response spectra of the achieved and the target acceleration, printed and (with
/// `--spectrum`) written: the achieved one from the history's `accel_mps2` over the window, as
/// the kernel's online spectrum takes it.
fn write_spectrum(
    o: &mut impl Write,
    args: &SimArgs,
    history: &single::History,
    reference: &Reference,
    spectrum: &SpectrumSpec,
    target: &[f64],
) -> anyhow::Result<()> {
    let got = history.accel_psa(reference, spectrum);
    writeln!(
        o,
        "
  response spectrum ({:.0} % damping), PSA in g",
        100.0 * spectrum.damping
    )?;
    writeln!(
        o,
        "  {:>9} {:>10} {:>10} {:>8}",
        "period s", "target", "achieved", "ratio"
    )?;
    for ((t, want), have) in spectrum.periods.iter().zip(target).zip(&got) {
        writeln!(
            o,
            "  {t:>9.3} {:>10.4} {:>10.4} {:>8.3}",
            want / G,
            have / G,
            have / want
        )?;
    }
    if let Some(path) = &args.spectrum {
        let ratio: Vec<f64> = got.iter().zip(target).map(|(a, b)| a / b).collect();
        let (t_g, a_g): (Vec<f64>, Vec<f64>) = (
            target.iter().map(|v| v / G).collect(),
            got.iter().map(|v| v / G).collect(),
        );
        let cols: [(&str, &[f64]); 4] = [
            ("period_s", &spectrum.periods),
            ("psa_target_g", &t_g),
            ("psa_g", &a_g),
            ("ratio", &ratio),
        ];
        let mut m = meta::header(Kind::Spectrum);
        m.push(meta::pair(Key::Damping, spectrum.damping));
        parquet_write::write_parquet(path, &cols, &m)
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(o, "  wrote {}", path.display())?;
    }
    Ok(())
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
