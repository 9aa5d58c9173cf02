//! `study fit`: fit effects' parameters against a campaign and write the fitted model.

use super::campaign_io::{load_campaign, load_model, load_tests, report_checks, LoadedCampaign};
use super::cli::FitArgs;
use super::progress::Progress;
use super::{BadInput, RunFailed};
use crate::kernel::params::{EffectId, ModelParams, EFFECTS};
use crate::orchestration::fit::{self, Free, Problem, TestData};
use crate::orchestration::toml_fields::suggest;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

/// A campaign's measured tests as a fitting problem, with what was noticed reading them.
pub struct Loaded {
    pub campaign: LoadedCampaign,
    pub problem: Problem,
    /// The tests as aligned to the model.
    pub aligned: Vec<crate::orchestration::measured::AlignedTest>,
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
    let limit = crate::orchestration::compare::IMPLAUSIBLE_RESIDUAL;
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

/// The free parameters: each effect's defaults, then the named ones.
pub(crate) fn free_parameters(
    effects: &[String],
    named: &[String],
    model: &ModelParams,
) -> anyhow::Result<Vec<Free>> {
    let mut free: Vec<Free> = Vec::new();
    for e in effects {
        let e = check_effect(e, "--effect")?;
        free.extend(crate::orchestration::diagnose::free_of(e, model));
    }
    let all: Vec<String> = ModelParams::registry().map(|p| p.path()).collect();
    let all_refs: Vec<&str> = all.iter().map(String::as_str).collect();
    for n in named {
        let info = ModelParams::lookup(n.trim()).ok_or_else(|| {
            let hint = suggest(n.trim(), &all_refs)
                .map_or(String::new(), |s| format!(" (did you mean `{s}`?)"));
            BadInput(format!(
                "--free {n:?}: unknown parameter{hint} (`study params` lists them)"
            ))
        })?;
        if !free
            .iter()
            .any(|f| std::ptr::eq(f.info, info) || f.info.path() == info.path())
        {
            free.push(Free::new(info, (info.get)(model)));
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

pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    super::outputs::check_output(&args.out)?;
    run_to(args, &mut std::io::stdout())
}

/// The command, its report printed to `o` (the Python package keeps it as text).
pub(crate) fn run_to(args: &FitArgs, o: &mut dyn Write) -> anyhow::Result<()> {
    let engine = super::gpu::uncovered(
        args.backend,
        "a fit compares time histories at the measured samples (the CUDA kernel returns metrics only)",
    )?;
    let model = load_model(args.model.as_deref())?;
    let free = free_parameters(&args.effect, &args.free, &model)?;
    let mut loaded = load_problem(&args.campaign, &model, args.strict)?;
    let progress = with_progress(&mut loaded.problem, "fit", args.log_progress);
    let problem = &loaded.problem;
    let t0 = std::time::Instant::now();
    let pool = super::run_cmd::pool(args.threads)?;
    // Each freed stage's start and scan (a mode's mass, a resonance's frequency, a lag), as a
    // diagnosis makes them.
    let free = pool.install(|| crate::orchestration::diagnose::scan_starts(problem, &free));
    let r = pool
        .install(|| fit::fit(problem, &free, args.max_iter))
        .map_err(|e| RunFailed(format!("the fit failed: {e}")))?;
    progress.finish();
    if let Some(f) = &r.before.failure {
        return Err(RunFailed(format!("the starting model fails: {f}")).into());
    }
    let mut implausible = residual_warnings(problem, &r.before, Some(&r.after));
    implausible.extend(noise_warnings(problem, Some(&r.after)));
    if args.strict && !implausible.is_empty() {
        return Err(BadInput(format!("{} (--strict)", implausible.join("\n"))).into());
    }
    writeln!(
        o,
        "study fit {} ({} tests, {} features, {} free parameters; {} iterations, {}, {:.1} s)",
        args.campaign.display(),
        problem.tests.len(),
        r.after.r.len(),
        free.len(),
        r.iterations,
        if r.converged {
            "converged"
        } else {
            "NOT converged: raise --max-iter"
        },
        t0.elapsed().as_secs_f64()
    )?;
    writeln!(o, "  backend     {}", engine.describe())?;
    writeln!(o)?;
    print_estimates(o, &free, &r)?;
    print_residuals(o, problem, &r)?;
    let command = format!("fit {}", args.campaign.display());
    write_fitted(&args.out, &command, &model, &free, &r)?;
    writeln!(o, "\n  wrote {} (use it with --model)", args.out.display())?;
    print_checks(o, &loaded.checks, &implausible)?;
    Ok(())
}

/// The estimates with their starts and standard errors, and their correlations.
fn print_estimates(o: &mut dyn Write, free: &[Free], r: &fit::FitResult) -> std::io::Result<()> {
    writeln!(
        o,
        "  {:<30} {:>12} {:>12} {:>12}  unit",
        "parameter", "start", "estimate", "std. error"
    )?;
    for ((f, e), s) in free.iter().zip(&r.estimate).zip(&r.se) {
        writeln!(
            o,
            "  {:<30} {:>12.4e} {:>12.4e} {:>12.2e}  {}",
            f.info.path(),
            f.start,
            e,
            s,
            f.info.unit
        )?;
    }
    if free.len() > 1 {
        writeln!(o, "\n  correlations of the estimates:")?;
        for (i, f) in free.iter().enumerate() {
            let row: Vec<String> = r.corr[i].iter().map(|c| format!("{c:+.2}")).collect();
            writeln!(o, "  {:<30} {}", f.info.path(), row.join("  "))?;
        }
    }
    Ok(())
}

/// The χ² before and after, and the residual over the measured rms per test and overall.
fn print_residuals(
    o: &mut dyn Write,
    problem: &Problem,
    r: &fit::FitResult,
) -> std::io::Result<()> {
    writeln!(o, "\n  chi2 (features scaled by their noise; about n, their degrees of freedom, for a model right to the noise): {:.4e} -> {:.4e} (n = {})", r.chi2_before(), r.chi2_after(), r.n)?;
    writeln!(
        o,
        "\n  residual rms / measured rms, per test (before -> after):"
    )?;
    writeln!(
        o,
        "  {:<24} {:>24} {:>24} {:>24}",
        "test", "acceleration", "displacement", "force"
    )?;
    for (i, t) in problem.tests.iter().enumerate() {
        let cell = |c: usize| {
            let (b, a) = (r.before.rms[i][c], r.after.rms[i][c]);
            if b.is_finite() {
                format!("{b:.3e} -> {a:.3e}")
            } else {
                "-".into()
            }
        };
        writeln!(
            o,
            "  {:<24} {:>24} {:>24} {:>24}",
            t.name,
            cell(0),
            cell(1),
            cell(2)
        )?;
    }
    let (b, a) = (r.before.residual_rms(), r.after.residual_rms());
    let noise = problem.noise_rms();
    writeln!(o, "  {:<24} {:>10.3e} -> {:>10.3e} ({:+.0} %) over every test and channel; noise floor {noise:.3e} ({:.2}x after)", "campaign", b, a, 100.0 * (a / b - 1.0), a / noise)?;
    Ok(())
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
        toml::Value::Table(crate::orchestration::spec::model_table(&fitted)),
    );
    let header = format!(
        "# Fitted by `study {command}` (vshake {}): {}\n",
        env!("CARGO_PKG_VERSION"),
        free.iter()
            .zip(&r.estimate)
            .zip(&r.se)
            .map(|((f, e), s)| format!("{} = {e:?} ± {s:.3e}", f.info.path()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let out = super::tables::AtomicFile::new(out);
    std::fs::write(&out.tmp, header + &toml::to_string(&root)?)?;
    out.commit()?;
    Ok(())
}
