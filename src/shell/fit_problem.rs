//! A campaign as a fitting problem, shared by `study fit`, `study diagnose`, `study synth` and
//! `study bench --diagnose`: the campaign and its tests read into a [`Problem`], the checks and
//! warnings about the data, the effects and parameters named on the command line, the progress
//! of a long fit, and the fitted model written.

use crate::kernel::params::{EffectId, ModelParams, EFFECTS};
use crate::orchestration::diagnosis::fit::{self, Free, Problem, TestData};
use crate::orchestration::toml_fields::suggest;
use crate::shell::formats::campaign_io::{
    load_campaign, load_tests, report_checks, LoadedCampaign,
};
use crate::shell::job::progress::Progress;
use crate::shell::BadInput;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

/// A campaign's measured tests as a fitting problem, with what was noticed reading them.
pub struct Loaded {
    pub campaign: LoadedCampaign,
    pub problem: Problem,
    /// The tests as aligned to the model.
    pub aligned: Vec<crate::orchestration::measured::aligned::AlignedTest>,
    /// The notes and warnings about the data files, as printed.
    pub checks: String,
}

/// Reads a campaign and its measured tests into a fitting problem. The data's warnings are an
/// error under `strict`.
pub(crate) fn load_problem(
    campaign: &Path,
    model: &ModelParams,
    strict: bool,
) -> anyhow::Result<Loaded> {
    let lc = load_campaign(campaign, model)?;
    let aligned = load_tests(&lc, None)?;
    if aligned.is_empty() {
        return Err(BadInput(format!("{}: the campaign has no tests", campaign.display())).into());
    }
    let mut checks = Vec::new();
    report_checks(&mut checks, campaign, &aligned, &[], strict)?;
    let tests = aligned.iter().map(TestData::new).collect();
    Ok(Loaded {
        campaign: lc,
        problem: Problem::new(tests),
        aligned,
        checks: String::from_utf8_lossy(&checks).into_owned(),
    })
}

/// Warnings for tests whose acceleration residual is above half the signal both in the starting
/// model `start` and in the best model the command found (`best`: a fit's result; none where it
/// found nothing). A specimen or a missing effect the fit explains is not a wrong file.
pub(crate) fn residual_warnings(
    problem: &Problem,
    start: &fit::Eval,
    best: Option<&fit::Eval>,
) -> Vec<String> {
    let limit = crate::orchestration::diagnosis::compare::IMPLAUSIBLE_RESIDUAL;
    let accel = |e: &fit::Eval, t: usize| e.rms.get(t).map_or(0.0, |r| r[0]);
    (problem.tests.iter().enumerate())
        .filter(|(t, _)| accel(start, *t) > limit && best.is_none_or(|b| accel(b, *t) > limit))
        .map(|(t, test)| {
            let after = best.map_or(String::new(), |b| format!(", {:.0} % after the fit", 100.0 * accel(b, t)));
            format!("test {:?}: the starting model's residual is {:.0} % of the measured acceleration{after}: the file of another test, a channel in other units, or a test that did not run as the campaign says?", test.name, 100.0 * accel(start, t))
        })
        .collect()
}

/// χ²/n of a test above which, where the whole campaign is within [`NOISE_MISMATCH`] / 2 of its
/// noise, the test's noise is taken to be misjudged [chosen: a χ² of n degrees of freedom stays
/// within a few √(2n) of n; 4 n is far beyond for any test of more than a few features].
pub const NOISE_MISMATCH: f64 = 4.0;

/// Warnings for tests whose residual after the best model found (`best`) is far above the noise
/// their features were scaled by (χ²/n > [`NOISE_MISMATCH`]) while the campaign as a whole is near
/// its noise: that test's noise is underestimated (a sensor noisier than its quiet rows show, a
/// filter), or something is missing there only. Its standard errors are then too small.
pub(crate) fn noise_warnings(problem: &Problem, best: Option<&fit::Eval>) -> Vec<String> {
    let Some(b) = best else { return Vec::new() };
    let mut chi2 = vec![0.0; problem.tests.len()];
    for (f, r) in problem.features().iter().zip(&b.r) {
        chi2[f.test] += r * r;
    }
    if b.chi2() > 0.5 * NOISE_MISMATCH * problem.dof() {
        return Vec::new();
    }
    (problem.tests.iter().enumerate())
        .filter(|(t, test)| chi2[*t] > NOISE_MISMATCH * test.dof().max(1.0))
        .map(|(t, test)| format!("test {:?}: after the fit its chi2 is {:.1}x its degrees of freedom, while the campaign's is {:.2}x: its noise is larger than estimated from the file, or something is missing in this test only; its share of the standard errors is too small (weights = {{ ... }} can lower a channel)", test.name, chi2[t] / test.dof().max(1.0), b.chi2() / problem.dof()))
        .collect()
}

/// The library effect a command-line name means.
pub(crate) fn check_effect(e: &str, flag: &str) -> anyhow::Result<EffectId> {
    EffectId::parse(e.trim()).ok_or_else(|| {
        let hint = suggest(e.trim(), &EFFECTS)
            .map_or(String::new(), |s| format!(" (did you mean `{s}`?)"));
        BadInput(format!(
            "{flag} {e:?}: unknown effect{hint}; the library has {}",
            EFFECTS.join(", ")
        ))
        .into()
    })
}

/// For the `expression` effect, that the model writes an expression, and where `to_fit`, one
/// that reads a named parameter; every other effect passes.
pub(crate) fn check_written(e: EffectId, model: &ModelParams, to_fit: bool) -> anyhow::Result<()> {
    let x = &model.expression;
    let why = match () {
        _ if e != EffectId::Expression => return Ok(()),
        _ if x.hooks.is_empty() => "the model writes no expression: give --model a file with a [model.expression] table (docs/formats.md, \"Expressions\")",
        _ if to_fit && x.slots_read().is_empty() => "the model's expressions read no named parameter, so there is nothing to fit: name one (`c = 1.0`) and write it in an expression",
        _ => return Ok(()),
    };
    Err(BadInput(format!("--effect expression: {why}")).into())
}

/// The free parameters: each effect's defaults, then the named ones.
pub(crate) fn free_parameters(
    effects: &[String],
    named: &[String],
    model: &ModelParams,
) -> anyhow::Result<Vec<Free>> {
    let mut free: Vec<Free> = Vec::new();
    for e in effects {
        let e = check_effect(e, "--effect")?;
        check_written(e, model, true)?;
        free.extend(crate::orchestration::diagnosis::diagnose::free_of(e, model));
    }
    let named_expr = model.expression.names.iter().filter(|n| !n.is_empty());
    let all: Vec<String> = (ModelParams::registry().map(|p| p.path()))
        .chain(named_expr.map(|n| format!("expression.{n}")))
        .collect();
    let all_refs: Vec<&str> = all.iter().map(String::as_str).collect();
    for n in named {
        let info = ModelParams::lookup(n.trim()).ok_or_else(|| {
            let hint = suggest(n.trim(), &all_refs)
                .map_or(String::new(), |s| format!(" (did you mean `{s}`?)"));
            BadInput(format!(
                "--free {n:?}: unknown parameter{hint} (`study params` lists them)"
            ))
        })?;
        let info = named_slot(info, model);
        if !free
            .iter()
            .any(|f| std::ptr::eq(f.info, info) || f.info.path() == info.path())
        {
            free.push(Free::new(info, info.get(model)));
        }
    }
    if free.is_empty() {
        return Err(BadInput(
            "nothing to fit: name effects with --effect and/or parameters with --free".into(),
        )
        .into());
    }
    if free.len() >= 8 {
        return Err(BadInput(format!(
            "{} free parameters; at most 7 (one batch of lanes per Jacobian)",
            free.len()
        ))
        .into());
    }
    Ok(free)
}

/// A slot of the expressions' parameters (`expression.p1`) as the parameter the model names on
/// it (`expression.c_opening`, with its unit and range); any other row as it is.
fn named_slot(
    info: &'static crate::kernel::params::ParamInfo,
    model: &ModelParams,
) -> &'static crate::kernel::params::ParamInfo {
    let slot = info.index();
    let name = model.expression.names.get(slot).filter(|n| !n.is_empty());
    match (info.component.effect(), name) {
        (Some(EffectId::Expression), Some(n)) if n != info.name => {
            ModelParams::lookup(&format!("expression.{n}")).unwrap_or(info)
        }
        _ => info,
    }
}

/// The data notes and warnings after a fit's or a diagnosis's results (a one-line pointer on
/// stderr when there are warnings).
pub(crate) fn print_checks(
    o: &mut dyn Write,
    checks: &str,
    implausible: &[String],
) -> std::io::Result<()> {
    write!(o, "{checks}")?;
    if !implausible.is_empty() {
        if !checks.contains("WARNINGS") {
            writeln!(
                o,
                "\n  WARNINGS (results above may be wrong science; --strict makes these errors):"
            )?;
        }
        for w in implausible {
            writeln!(o, "    {w}")?;
        }
    }
    if checks.contains("WARNINGS") || !implausible.is_empty() {
        eprintln!("warning: there are warnings about the measured data: see the WARNINGS block of the output");
    }
    Ok(())
}

/// A progress display counting `problem`'s model runs (on a terminal's stderr, or a line every
/// 5 s with `log_lines`); finish it when the work is done.
pub(crate) fn with_progress(problem: &mut Problem, label: &str, log_lines: bool) -> Arc<Progress> {
    let progress = Arc::new(Progress::new(label, 0, false, log_lines));
    let p = progress.clone();
    problem.progress = Some(Arc::new(move |n| p.inc(n)));
    progress
}

/// The first line of a model [`write_fitted`] writes.
const FITTED_HEAD: &str = "# Fitted by `study ";

/// Refuses, before any work, to replace a file at `out` that [`write_fitted`] did not write (a
/// model file of the user's, a campaign): bad input, exit 2, nothing replaced. An earlier fit's
/// or diagnosis's model is replaced.
pub(crate) fn check_fitted_model(out: &Path) -> anyhow::Result<()> {
    let what = "a model `study fit` or `study diagnose --out` wrote";
    replaced_only_if_ours(out, FITTED_HEAD, what)
}

/// Refuses, before any work, to replace a file at `path` whose first line does not start with
/// `head` (a file study wrote; `what` names it in the error): bad input, exit 2.
pub(crate) fn replaced_only_if_ours(path: &Path, head: &str, what: &str) -> anyhow::Result<()> {
    crate::shell::job::outputs::check_output(path)?;
    match std::fs::read_to_string(path) {
        Ok(text) if !text.starts_with(head) => Err(crate::shell::BadInput(format!(
            "{}: exists and is not {what}; nothing was replaced: choose another file, or remove it",
            path.display()
        ))
        .into()),
        _ => Ok(()),
    }
}

/// Writes the fitted model (the starting model with the fitted parameters, their effects on),
/// headed by the command (`fit CAMPAIGN`) and the estimates, to `out`.
pub(crate) fn write_fitted(
    out: &Path,
    command: &str,
    model: &ModelParams,
    free: &[Free],
    r: &fit::FitResult,
) -> anyhow::Result<()> {
    let fitted = fit::apply_estimates(model, free, &r.estimate);
    let mut root = toml::Table::new();
    root.insert(
        "model".into(),
        toml::Value::Table(crate::orchestration::runs::spec::model_table(&fitted)),
    );
    let header = format!(
        "{FITTED_HEAD}{command}` (vshake {}): {}\n",
        env!("CARGO_PKG_VERSION"),
        free.iter()
            .zip(&r.estimate)
            .zip(&r.se)
            .map(|((f, e), s)| format!("{} = {e:?} ± {s:.3e}", f.info.path()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let out = crate::shell::formats::parquet_write::AtomicFile::new(out);
    std::fs::write(&out.tmp, header + &toml::to_string(&root)?)?;
    out.commit()?;
    Ok(())
}
