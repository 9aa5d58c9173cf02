//! `study fit`: fit effects' parameters against a campaign and write the fitted model.

use crate::orchestration::diagnosis::fit::{self, Free, Problem};
use crate::shell::cli::FitArgs;
use crate::shell::formats::campaign_io::load_model;
use crate::shell::BadInput;
use crate::shell::RunFailed;
use std::io::Write;

use crate::shell::fit_problem::{
    free_parameters, load_problem, noise_warnings, print_checks, residual_warnings, with_progress,
    write_fitted,
};

pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    crate::shell::fit_problem::check_fitted_model(&args.out)?;
    run_to(args, &mut std::io::stdout())
}

/// The command, its report printed to `o` (the Python package keeps it as text).
pub(crate) fn run_to(args: &FitArgs, o: &mut dyn Write) -> anyhow::Result<()> {
    let engine = crate::shell::gpu::uncovered(
        args.backend,
        "a fit compares time histories at the measured samples (the CUDA kernel returns metrics only)",
    )?;
    let model = load_model(args.model.as_deref())?;
    let free = free_parameters(&args.effect, &args.free, &model)?;
    let mut loaded = load_problem(&args.campaign, &model, args.strict)?;
    let progress = with_progress(&mut loaded.problem, "fit", args.log_progress);
    let problem = &loaded.problem;
    let free = fit::as_switched(problem, &free).map_err(BadInput)?;
    let t0 = std::time::Instant::now();
    let pool = crate::shell::job::study_job::pool(args.threads)?;
    // Each freed stage's start and scan (a mode's mass, a resonance's frequency, a lag), as a
    // diagnosis makes them.
    let free =
        pool.install(|| crate::orchestration::diagnosis::diagnose::scan_starts(problem, &free));
    let r = pool
        .install(|| fit::fit(problem, &free, args.max_iter))
        .map_err(|e| RunFailed(format!("the fit failed: {e}")))?;
    progress.finish();
    if let Some(f) = &r.before.failure {
        return Err(RunFailed(format!("the starting model fails: {f}")).into());
    }
    let mut implausible = residual_warnings(problem, &r.before, Some(&r.after));
    implausible.extend(noise_warnings(problem, Some(&r.after)));
    implausible.extend(undetermined(&free, &r));
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
    print_switched(o, problem, &free)?;
    print_residuals(o, problem, &r)?;
    let command = format!("fit {}", args.campaign.display());
    write_fitted(&args.out, &command, &model, &free, &r)?;
    writeln!(o, "\n  wrote {} (use it with --model)", args.out.display())?;
    print_checks(o, &loaded.checks, &implausible)?;
    Ok(())
}

/// A line for each effect fitted in some tests only (the campaign switches it off in others).
fn print_switched(o: &mut dyn Write, problem: &Problem, free: &[Free]) -> std::io::Result<()> {
    let mut said = Vec::new();
    for f in free.iter().filter(|f| f.tests != fit::ALL_TESTS) {
        let Some(e) = f.info.component.effect().filter(|e| !said.contains(e)) else {
            continue;
        };
        said.push(e);
        let names: Vec<&str> = (0..problem.tests.len())
            .filter(|&t| f.applies(t))
            .map(|t| problem.tests[t].name.as_str())
            .collect();
        writeln!(o, "  {} fitted in {} only (the campaign switches it off in its other tests, as it still does with the fitted model)", e.name(), names.join(", "))?;
    }
    Ok(())
}

/// A warning for each free parameter the campaign's features do not determine (an infinite
/// or undefined standard error: the misfit does not change with it, or only with others).
fn undetermined(free: &[Free], r: &fit::FitResult) -> Vec<String> {
    (free.iter().zip(&r.se))
        .filter(|(_, se)| !se.is_finite())
        .map(|(f, _)| format!("{}: the campaign's features do not determine it (its standard error is infinite), so its value is not an estimate; fix it, or give tests that it changes (the features are what `study compare` lists per test)", f.info.path()))
        .collect()
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
