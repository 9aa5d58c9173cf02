//! `study diagnose`: fit every candidate effect and say which one is most likely missing.

use crate::kernel::params::EffectId;
use crate::orchestration::diagnosis::diagnose::{
    self, Candidate, Diagnosis, Verdict, EXPLAINS_TOGETHER,
};
use crate::orchestration::diagnosis::fit::{FitResult, Free, Problem};
use crate::shell::cli::DiagnoseArgs;
use crate::shell::fit_problem::{
    self, check_effect, load_problem, print_checks, residual_warnings,
};
use crate::shell::formats::campaign_io::{self, load_model};
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use crate::shell::gpu;
use crate::shell::job::study_job::pool;
use crate::shell::report::kit::{esc, legend};
use crate::shell::BadInput;
use crate::shell::RunFailed;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::io::Write;

/// What a feature group is: a sine's harmonic, mean or remainder, or a record's frequency band
/// (`rate_hz`: the test's sample rate).
fn harmonic_label(k: usize, rate_hz: f64) -> String {
    use crate::orchestration::{diagnosis::fit, fourier};
    match k {
        fit::MEAN => "mean".into(),
        fit::REMAINDER => "beyond h1-h9".into(),
        k if k >= fit::BAND => {
            let e = fourier::octave_edges(rate_hz);
            let b = (k - fit::BAND).min(e.len() - 2);
            format!("{}-{} Hz", e[b], e[b + 1])
        }
        k => format!("h{k}"),
    }
}

pub fn run(args: &DiagnoseArgs) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        crate::shell::fit_problem::check_fitted_model(out)?;
        check_fitted_campaign(&fitted_campaign_path(out))?;
    }
    run_to(args, &mut std::io::stdout())
}

/// The command, its report printed to `o` (the Python package keeps it as text).
pub(crate) fn run_to(args: &DiagnoseArgs, o: &mut dyn Write) -> anyhow::Result<()> {
    let engine = gpu::uncovered(
        args.backend,
        "a diagnosis compares time histories (the CUDA kernel returns metrics only)",
    )?;
    let model = load_model(args.model.as_deref())?;
    let candidates: Vec<EffectId> = if args.candidates.is_empty() {
        // The expressions, switched off: the model file's, or else the state map's term (the
        // diagnosis drops the candidate where there is neither).
        let written = |e: EffectId| e == EffectId::Expression;
        EffectId::ALL
            .into_iter()
            .filter(|&e| (e.screened() || written(e)) && !model.effects.get(e))
            .collect()
    } else {
        args.candidates
            .iter()
            .map(|c| check_effect(c, "--candidates"))
            .collect::<anyhow::Result<_>>()?
    };
    let mut loaded = load_problem(&args.campaign, &model, args.strict)?;
    let progress = fit_problem::with_progress(&mut loaded.problem, "diagnose", args.log_progress);
    let mut problem = loaded.problem;
    let t0 = std::time::Instant::now();
    let d = pool(args.threads)?
        .install(|| diagnose::diagnose_campaign(&mut problem, &candidates, &loaded.aligned));
    progress.finish();
    let secs = t0.elapsed().as_secs_f64();
    if let Some(f) = &d.baseline.failure {
        return Err(RunFailed(format!("the starting model fails: {f}")).into());
    }
    let best = (d.named_fit().map(|(_, f)| &f.after)).or_else(|| {
        d.candidates
            .first()
            .and_then(|c| c.fit.as_ref().ok().map(|f| &f.after))
    });
    let mut implausible = residual_warnings(&problem, &d.baseline, best);
    implausible.extend(fit_problem::noise_warnings(&problem, best));
    if args.strict && !implausible.is_empty() {
        return Err(BadInput(format!("{} (--strict)", implausible.join("\n"))).into());
    }
    writeln!(
        o,
        "study diagnose {} ({} tests, {} features, {} candidates, {:.1} s)",
        args.campaign.display(),
        problem.tests.len(),
        d.features.len(),
        d.candidates.len(),
        secs
    )?;
    writeln!(o, "  backend     {}", engine.describe())?;
    print_candidates(o, &d)?;
    print_evidence(o, &problem, &d)?;
    print_selection(o, &d)?;
    print_misfit(o, &problem, &d)?;
    print_signals(o, &d)?;
    if let Some(map) = &d.state_map {
        writeln!(o, "\n  the starting model's residual:")?;
        crate::shell::report::statemap_report::print(o, map)?;
    }
    if let (Some(map), Some(true)) = (
        &d.state_map_after,
        d.named_fit().map(|(_, f)| d.above_noise(&f.after)),
    ) {
        writeln!(o, "\n  the residual the named effects leave:")?;
        crate::shell::report::statemap_report::print(o, map)?;
    }
    writeln!(o, "\n  verdict: {}", d.summary())?;
    if let Some(dir) = &args.report {
        write_report(dir, &args.campaign.display().to_string(), &problem, &d)?;
        writeln!(o, "\n  wrote {} and its tables (candidates, selection, tests, evidence, statemap, stateterms .parquet)", dir.join("report.html").display())?;
    }
    if let Some(out) = &args.out {
        write_named(o, out, &args.campaign, model, &d)?;
    }
    print_checks(o, &loaded.checks, &implausible)?;
    Ok(())
}

/// `--out`: the named effects' fitted model (with the state map's term where the diagnosis gave
/// it to the model), or a line saying there is none.
fn write_named(
    o: &mut dyn Write,
    out: &std::path::Path,
    campaign: &std::path::Path,
    mut model: crate::kernel::params::ModelParams,
    d: &Diagnosis,
) -> anyhow::Result<()> {
    let Some((free, fit)) = d.named_fit() else {
        let earlier = match out.exists() {
            true => " (the file there is an earlier run's, left as it was)",
            false => "",
        };
        writeln!(
            o,
            "\n  {} not written: the verdict names no effect{earlier}",
            out.display()
        )?;
        return remove_stale_campaign(o, out);
    };
    // The expression's notes where the verdict names it (a term tried and not named is not in
    // the model written).
    if let Some(t) = d.named_term() {
        t.install_one(&mut model, 0).map_err(RunFailed)?;
        let tests = d.signals.list(t.tests().into_iter());
        if d.names_a_group() {
            writeln!(o, "\n  note: the expression was fitted to {tests} only; the model written applies it to every test, the campaign written beside it keeps it off in the others")?;
        }
        if t.per_test() {
            let first = d.signals.list(t.tests().into_iter().take(1));
            writeln!(o, "\n  note: the expression has parameters per test ({}); the model written holds {first}'s form, the campaign written beside it each test's own", t.written())?;
        }
    }
    let model = &model;
    let command = format!("diagnose {}", campaign.display());
    // A stage the verdict says was fitted to 0 is written at 0.
    let mut fit = fit.clone();
    for k in d.void_params() {
        fit.estimate[k] = 0.0;
    }
    crate::shell::fit_problem::write_fitted(out, &command, model, free, &fit)?;
    let what = match d.verdict() {
        Verdict::Unexplained { explained, .. } => format!("the best candidates fitted, though they explain only {:.0} % of the residual: the missing effect is probably not among them", 100.0 * explained),
        _ => "the named effects fitted".into(),
    };
    let params: Vec<_> = free.iter().map(|f| f.info.path()).collect();
    writeln!(
        o,
        "\n  wrote {} ({what}: {}; use it with --model)",
        out.display(),
        params.join(", ")
    )?;
    let term = (d.named_term()).filter(|t| t.per_test() || d.names_a_group());
    let group = d.named_group().zip(d.candidates.first().map(|c| c.effect));
    if let Some((g, e)) = &group {
        let tests = d.signals.list(g.iter().copied());
        writeln!(o, "\n  note: {e} was fitted to {tests} only; the model written applies it to every test, the campaign written beside it keeps it off in the others")?;
    }
    if term.is_none() && group.is_none() {
        return remove_stale_campaign(o, out);
    }
    let path = fitted_campaign_path(out);
    let off = group.as_ref().map(|(g, e)| (*e, g.as_slice()));
    write_fitted_campaign(&path, campaign, term, off)?;
    let what = match (term, &group) {
        (Some(_), _) => "each test's own form of the expression, and the expression off in the tests it was not fitted to".to_string(),
        (None, Some((_, e))) => format!("{e} off in the tests it was not fitted to"),
        (None, None) => unreachable!("returned above"),
    };
    writeln!(
        o,
        "\n  wrote {} (the campaign with {what}: `study compare {} --model {}`)",
        path.display(),
        path.display(),
        out.display()
    )?;
    Ok(())
}

/// Removes the campaign an earlier diagnosis wrote beside `out` ([`fitted_campaign_path`]; the run
/// checked before any work that a file there is one), where this one writes none: it would pair
/// an earlier verdict's forms with this run's model.
fn remove_stale_campaign(o: &mut dyn Write, out: &std::path::Path) -> anyhow::Result<()> {
    let path = fitted_campaign_path(out);
    if path.exists() {
        std::fs::remove_file(&path)?;
        writeln!(
            o,
            "\n  removed {} (an earlier diagnosis's campaign; this verdict needs none)",
            path.display()
        )?;
    }
    Ok(())
}

/// The campaign `--out` writes beside the model where the expression's form differs between
/// tests or applies to some of them: `fitted.toml` → `fitted.campaign.toml`.
fn fitted_campaign_path(out: &std::path::Path) -> std::path::PathBuf {
    out.with_extension("campaign.toml")
}

/// The first line of a campaign [`write_fitted_campaign`] writes.
const FITTED_CAMPAIGN_HEAD: &str = "# Written by `study diagnose --out`";

/// Refuses, before any work, to replace a file at `path` that [`write_fitted_campaign`] did not
/// write (bad input, exit 2).
fn check_fitted_campaign(path: &std::path::Path) -> anyhow::Result<()> {
    let what = "a campaign `study diagnose --out` wrote (where the expression differs between tests it writes one there)";
    crate::shell::fit_problem::replaced_only_if_ours(path, FITTED_CAMPAIGN_HEAD, what)
}

/// Writes to `path` a copy of `campaign` in which each test the term `t` (if any) is given to has
/// its own form (`model = { expression = { <hook> = "<form>" } }`) and every other test has the
/// expression off (`enabled = false`), and the effect of `off` (if any) is off in the tests
/// outside its group; the data and record paths made absolute, since the copy may lie elsewhere.
fn write_fitted_campaign(
    path: &std::path::Path,
    campaign: &std::path::Path,
    t: Option<&crate::orchestration::diagnosis::terms::Term>,
    off: Option<(EffectId, &[usize])>,
) -> anyhow::Result<()> {
    let base = std::fs::canonicalize(campaign)?
        .parent()
        .map(|p| p.to_path_buf())
        .unwrap_or_default();
    let mut what = Vec::new();
    if t.is_some() {
        what.push(
            "each test's own form of the expression fitted, off in the tests it was not fitted to"
                .to_string(),
        );
    }
    if let Some((e, _)) = off {
        what.push(format!("{e} off in the tests it was not fitted to"));
    }
    let head = format!(
        "{FITTED_CAMPAIGN_HEAD} from {}:\n# {} (the model file --out wrote holds the fitted parameters).\n",
        campaign.display(),
        what.join("; ")
    );
    campaign_io::rewrite_tests(campaign, path, &head, &mut |i, test| {
        absolute(test, "data", &base);
        if let Some(e) = test
            .get_mut("excitation")
            .and_then(toml::Value::as_table_mut)
        {
            absolute(e, "file", &base);
        }
        let model = sub_table(test, "model")?;
        if let Some(t) = t {
            let expression = sub_table(model, "expression")?;
            for (hook, form) in
                (t.parts()).filter_map(|p| Some((p.hook, &p.forms.iter().find(|f| f.0 == i)?.1)))
            {
                expression.insert(hook.key().into(), form.clone().into());
            }
            if !t.tests().contains(&i) {
                expression.insert("enabled".into(), false.into());
            }
        }
        if let Some((e, _)) = off.filter(|(_, g)| !g.contains(&i)) {
            sub_table(model, e.name())?.insert("enabled".into(), false.into());
        }
        Ok(())
    })
}

/// `table[name]`, a table, made where it is missing.
fn sub_table<'a>(table: &'a mut toml::Table, name: &str) -> anyhow::Result<&'a mut toml::Table> {
    use anyhow::Context;
    (table.entry(name))
        .or_insert_with(|| toml::Table::new().into())
        .as_table_mut()
        .with_context(|| format!("a test's {name}"))
}

/// `table[key]`, a path relative to `base`, made absolute.
fn absolute(table: &mut toml::Table, key: &str, base: &std::path::Path) {
    if let Some(toml::Value::String(p)) = table.get_mut(key) {
        *p = base.join(&*p).display().to_string();
    }
}

/// The baseline, then the candidates ranked.
fn print_candidates(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    writeln!(
        o,
        "\n  baseline: chi2 = {:.4e} (about {} for a model right to the noise), residual rms {:.3e} (residual / measured, rms over tests and channels: acceleration, displacement, force; noise floor {:.3e})",
        d.baseline.chi2(),
        d.n,
        d.baseline.residual_rms(),
        d.noise_rms
    )?;
    // The candidate column as wide as its longest label (a group's: `specimen[1,3,5,7]`).
    let w = (d.candidates.iter().map(|c| c.label().len()))
        .max()
        .unwrap_or(0)
        .max(17);
    writeln!(
        o,
        "\n  {:<4} {:<w$} {:<24} {:>3} {:>4} {:>11} {:>11} {:>9} {:>11}  significant",
        "rank", "candidate", "family", "p", "iter", "chi2", "dBIC", "explains", "rms resid."
    )?;
    let at_noise = d.verdict() == diagnose::Verdict::NothingSignificant && d.starts_at_noise();
    for (i, c) in d.candidates.iter().enumerate() {
        let rms = c.fit.as_ref().map_or(f64::NAN, |f| f.after.residual_rms());
        writeln!(
            o,
            "  {:<4} {:<w$} {:<24} {:>3} {:>4} {:>11.4e} {:>11.4e} {:>8.1}% {:>11.3e}  {}",
            i + 1,
            c.label(),
            c.family,
            c.free.len(),
            c.fit.as_ref().map_or("-".to_string(), |f| format!(
                "{}{}",
                f.iterations,
                if f.converged { "" } else { "!" }
            )),
            c.chi2(),
            c.delta_bic,
            100.0 * c.explained,
            rms,
            match &c.fit {
                Err(e) => format!("fit failed: {e}"),
                Ok(_) if c.significant() && at_noise => "yes*".into(),
                Ok(_) if c.significant() => "yes".into(),
                Ok(_) => "no".into(),
            }
        )?;
    }
    if at_noise && d.candidates.iter().any(|c| c.significant()) {
        writeln!(
            o,
            "  * significant in BIC over the features, but the starting model is already at the noise: nothing is named"
        )?;
    }
    for c in &d.candidates {
        if let Some(finding) = &c.origin {
            writeln!(
                o,
                "  {}: fitted from {finding} ends better than from the library's start",
                c.effect
            )?;
        }
    }
    print_terms_tried(o, d)
}

/// The expression terms the diagnosis fitted to choose its `expression` candidate, if several.
fn print_terms_tried(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    if d.terms_tried.is_empty() {
        return Ok(());
    }
    writeln!(
        o,
        "\n  expression terms tried (the candidate is the one of lowest BIC = chi2 + p ln n, or a term read off the signals that adds to the named effects):"
    )?;
    for t in &d.terms_tried {
        let chosen = d.term.as_ref() == Some(&t.term);
        writeln!(
            o,
            "  {} p {:>2}  chi2 {:.4e}  {}",
            if chosen { "->" } else { "  " },
            t.k,
            t.chi2,
            t.term.described(d.test_misfit.len(), &d.signals)
        )?;
    }
    Ok(())
}

/// For the top three candidates: their estimates and the residual features each explains.
fn print_evidence(o: &mut dyn Write, problem: &Problem, d: &Diagnosis) -> std::io::Result<()> {
    writeln!(o, "\n  evidence for the top candidates (the residual features each explains; chi2 baseline -> candidate):")?;
    for c in d.candidates.iter().take(3) {
        let Ok(f) = &c.fit else { continue };
        let params: Vec<String> = c
            .free
            .iter()
            .zip(&f.estimate)
            .zip(&f.se)
            .map(|((p, e), s)| estimate_text(p.info.name, *e, *s, p.info.unit))
            .collect();
        writeln!(o, "  {} ({})", c.effect, params.join(", "))?;
        for (t, k, b, a) in diagnose::evidence(d, c, 3) {
            writeln!(
                o,
                "      {} of {:<16} {:>11.4e} -> {:.4e}",
                harmonic_label(k, problem.tests[t].samples.rate_hz),
                problem.tests[t].name,
                b,
                a
            )?;
        }
        let per: Vec<String> = (0..problem.tests.len())
            .map(|t| {
                format!(
                    "{:.1e}->{:.1e}",
                    d.baseline.test_rms(t),
                    f.after.test_rms(t)
                )
            })
            .collect();
        writeln!(o, "      residual rms per test: {}", per.join("  "))?;
        let (pb, pa) = (
            problem.fundamental_phase_error(&d.baseline),
            problem.fundamental_phase_error(&f.after),
        );
        // Record tests have no fundamental: where some are left out, each value is named.
        let sines: Vec<usize> = (0..problem.tests.len())
            .filter(|&t| pb[t].is_finite())
            .collect();
        let named = sines.len() < problem.tests.len();
        let ph: Vec<String> = (sines.iter())
            .map(|&t| match named {
                true => format!("{} {:+.2}->{:+.2}", problem.tests[t].name, pb[t], pa[t]),
                false => format!("{:+.2}->{:+.2}", pb[t], pa[t]),
            })
            .collect();
        if !ph.is_empty() {
            writeln!(
                o,
                "      phase error of the fundamental per test (model - measured, deg): {}",
                ph.join("  ")
            )?;
        }
    }
    Ok(())
}

/// Why selection starts from a candidate ranked behind one that fits better alone (in ΔBIC, the
/// ranking's measure), where it does: the two tied, and the effects added fit better with it
/// (`diagnose::settle_leader`).
fn print_swap(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    let [lead, next, ..] = &d.candidates[..] else {
        return Ok(());
    };
    let library = |c: &Candidate| c.effect != EffectId::Expression;
    if !(library(lead) && library(next) && next.delta_bic > lead.delta_bic) {
        return Ok(());
    }
    if lead.effect == next.effect {
        // `diagnose::narrow_group`: the group narrowed in the joint fit.
        return writeln!(
            o,
            "  (from {}, not {}: the named set fits as well without it in the tests dropped, and the set found from there fits better)",
            lead.label(),
            next.label()
        );
    }
    writeln!(
        o,
        "  (from {}, not {}: alone they tie, and with the effects added {} fits better)",
        lead.effect, next.effect, lead.effect
    )
}

/// The forward selection's steps, each with its joint fit, after the candidate they start
/// from (its own fit; its dBIC and share against the baseline, each step's dBIC against the
/// step before it).
fn print_selection(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    let Some(first) = d.candidates.first().filter(|_| !d.more.is_empty()) else {
        return Ok(());
    };
    writeln!(o, "\n  forward selection (each effect fitted on top of those before it, their parameters refitted with it):")?;
    print_swap(o, d)?;
    let names: Vec<String> = std::iter::once(first.label())
        .chain(d.more.iter().map(|s| format!("+ {}", s.part())))
        .collect();
    let w = names
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(0)
        .max(22);
    writeln!(
        o,
        "  {:<w$} {:>4} {:>11} {:>11} {:>9} {:>11}  parameters (joint fit)",
        "effect", "iter", "chi2", "dBIC", "explains", "rms resid."
    )?;
    if let Ok(f) = &first.fit {
        let row = (f, first.delta_bic, first.explained);
        selection_row(o, (&names[0], w), &first.free, row)?;
    }
    for (s, name) in d.more.iter().zip(&names[1..]) {
        selection_row(o, (name, w), &s.free, (&s.fit, s.delta_bic, s.explained))?;
    }
    print_first_only(o, d)
}

/// One row of the forward selection's table: `name` padded to `w`, the fit of `free`, its dBIC
/// and the share it explains.
fn selection_row(
    o: &mut dyn Write,
    (name, w): (&str, usize),
    free: &[Free],
    (fit, delta_bic, explained): (&FitResult, f64, f64),
) -> std::io::Result<()> {
    let params: Vec<String> = (free.iter().zip(&fit.estimate).zip(&fit.se))
        .map(|((p, e), se)| estimate_text(&p.info.path(), *e, *se, p.info.unit))
        .collect();
    let iter = format!("{}{}", fit.iterations, if fit.converged { "" } else { "!" });
    writeln!(
        o,
        "  {name:<w$} {iter:>4} {:>11.4e} {:>11.4e} {:>8.1}% {:>11.3e}  {}",
        fit.chi2_after(),
        delta_bic,
        100.0 * explained,
        fit.after.residual_rms(),
        params.join(", ")
    )
}

/// Why the verdict names the first effect only where the steps above do not close the gap to
/// the noise.
fn print_first_only(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    let (Verdict::Missing { effects, .. }, Some(last)) = (d.verdict(), d.more.last()) else {
        return Ok(());
    };
    if effects.len() > d.more.len() {
        return Ok(());
    }
    writeln!(
        o,
        "  (the verdict names {} only: the effects added explain {:.1} % together, short of {:.0} %, so what they add is not taken for the plant's)",
        effects[0],
        100.0 * last.explained,
        100.0 * EXPLAINS_TOGETHER
    )
}

/// The weighted misfit the fit minimises, per test and channel: the baseline's, and the named
/// effects' where the verdict names any.
fn print_misfit(o: &mut dyn Write, problem: &Problem, d: &Diagnosis) -> std::io::Result<()> {
    let before = problem.chi2_table(&d.baseline);
    let after = d.named_fit().map(|(_, f)| problem.chi2_table(&f.after));
    let what = if after.is_some() {
        "the baseline -> the named effects"
    } else {
        "the baseline"
    };
    writeln!(
        o,
        "\n  misfit per test and channel (chi2 / its degrees of freedom, about 1 at the noise; {what}):"
    )?;
    writeln!(
        o,
        "  {:<16} {:>19} {:>19} {:>19}",
        "test", "acceleration", "displacement", "force"
    )?;
    for (t, test) in problem.tests.iter().enumerate() {
        let cell = |c: usize| match &after {
            _ if before[t][c].is_nan() => "-".to_string(),
            Some(a) => format!("{:.3e} -> {:.2e}", before[t][c], a[t][c]),
            None => format!("{:.3e}", before[t][c]),
        };
        writeln!(
            o,
            "  {:<16} {:>19} {:>19} {:>19}",
            test.name,
            cell(0),
            cell(1),
            cell(2)
        )?;
    }
    match after {
        Some(a) => print_below_noise(o, problem, &a),
        None => Ok(()),
    }
}

/// A channel's χ²/dof after the fit under this is far below its noise: the noise it was weighed
/// with is larger than the channel's (a channel recorded without noise, a `noise` given too
/// large). [chosen: at the noise χ²/dof is 1 within a few per cent over thousands of degrees
/// of freedom; 0.1 is a residual under a third of the noise assumed.]
const BELOW_NOISE: f64 = 0.1;

/// Says which channels the named effects fit far below their noise (χ²/dof under
/// [`BELOW_NOISE`]), from the table `after` of [`Problem::chi2_table`].
fn print_below_noise(
    o: &mut dyn Write,
    problem: &Problem,
    after: &[[f64; 3]],
) -> std::io::Result<()> {
    for (c, channel) in ["acceleration", "displacement", "force"].iter().enumerate() {
        let low: Vec<(&str, f64)> = (problem.tests.iter().zip(after))
            .filter(|(_, a)| a[c] < BELOW_NOISE)
            .map(|(t, a)| (t.name.as_str(), a[c]))
            .collect();
        if low.is_empty() {
            continue;
        }
        let lo = low.iter().map(|l| l.1).fold(f64::INFINITY, f64::min);
        let hi = low.iter().map(|l| l.1).fold(0.0, f64::max);
        let range = match lo == hi {
            true => format!("{lo:.1e}"),
            false => format!("{lo:.1e} to {hi:.1e}"),
        };
        let names: Vec<&str> = low.iter().map(|l| l.0).collect();
        writeln!(
            o,
            "  (the {channel} of {} is fitted to a chi2/dof of {range}, far below 1: the noise it is weighed with is larger than its own (recorded without noise, or a `noise` given too large), so it counts for less in the fit than it could, and the standard errors are larger than they need be)",
            match names.len() {
                n if n == problem.tests.len() && n > 1 => "every test".to_string(),
                1 => format!("test {}", names[0]),
                _ => format!("tests {}", names.join(", ")),
            }
        )?;
    }
    Ok(())
}

/// What the signals show in the starting model's residual, one finding a line.
fn print_signals(o: &mut dyn Write, d: &Diagnosis) -> std::io::Result<()> {
    let s = d.signals.sentences();
    if s.is_empty() {
        return Ok(());
    }
    writeln!(
        o,
        "\n  what the signals show (the starting model's residual, measured - model):"
    )?;
    for line in s {
        writeln!(o, "  - {line}")?;
    }
    Ok(())
}

/// The Parquet tables and the HTML page of a diagnosis.
pub(crate) fn write_report(
    dir: &std::path::Path,
    campaign: &str,
    problem: &Problem,
    d: &Diagnosis,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut meta = meta::header(Kind::Diagnose);
    meta.extend([
        meta::pair(Key::Campaign, campaign),
        meta::pair(Key::Verdict, d.summary()),
    ]);
    if let Some(map) = &d.state_map {
        crate::shell::report::statemap_report::write(dir, map, &meta)?;
    }
    parquet_write::write_table(
        &dir.join("candidates.parquet"),
        candidates_columns(d),
        &meta,
    )?;
    parquet_write::write_table(&dir.join("selection.parquet"), selection_columns(d), &meta)?;
    parquet_write::write_table(&dir.join("tests.parquet"), tests_columns(problem, d), &meta)?;
    parquet_write::write_table(
        &dir.join("evidence.parquet"),
        evidence_columns(problem, d),
        &meta,
    )?;
    let page = html(campaign, problem, d)?;
    let path = dir.join("report.html");
    let out = parquet_write::AtomicFile::new(&path);
    std::fs::write(&out.tmp, page)?;
    out.commit()?;
    Ok(())
}

/// `candidates.parquet`: one row per candidate, ranked.
fn candidates_columns(d: &Diagnosis) -> Vec<(String, Column)> {
    let cs = &d.candidates;
    vec![
        ("rank".into(), Column::U32((1..=cs.len() as u32).collect())),
        (
            "effect".into(),
            Column::Str(cs.iter().map(|c| c.label()).collect()),
        ),
        (
            "family".into(),
            Column::Str(cs.iter().map(|c| c.family.to_string()).collect()),
        ),
        (
            "n_params".into(),
            Column::U32(cs.iter().map(|c| c.free.len() as u32).collect()),
        ),
        (
            "params".into(),
            Column::StrList(
                cs.iter()
                    .map(|c| c.free.iter().map(|f| f.info.path()).collect())
                    .collect(),
            ),
        ),
        (
            "estimates".into(),
            Column::F64List(
                cs.iter()
                    .map(|c| c.fit.as_ref().map_or(Vec::new(), |f| f.estimate.clone()))
                    .collect(),
            ),
        ),
        (
            "std_errors".into(),
            Column::F64List(
                cs.iter()
                    .map(|c| c.fit.as_ref().map_or(Vec::new(), |f| f.se.clone()))
                    .collect(),
            ),
        ),
        (
            "chi2".into(),
            Column::F64(cs.iter().map(|c| c.chi2()).collect()),
        ),
        (
            "chi2_baseline".into(),
            Column::F64(vec![d.baseline.chi2(); cs.len()]),
        ),
        ("n_features".into(), Column::U32(vec![d.n as u32; cs.len()])),
        (
            "delta_bic".into(),
            Column::F64(cs.iter().map(|c| c.delta_bic).collect()),
        ),
        (
            "explained".into(),
            Column::F64(cs.iter().map(|c| c.explained).collect()),
        ),
        (
            "significant".into(),
            Column::Bool(cs.iter().map(|c| c.significant()).collect()),
        ),
        (
            "failure".into(),
            Column::Str(
                cs.iter()
                    .map(|c| {
                        c.fit
                            .as_ref()
                            .err()
                            .map(ToString::to_string)
                            .unwrap_or_default()
                    })
                    .collect(),
            ),
        ),
    ]
}

/// `selection.parquet`: the chosen effects, the best candidate then each forward-selection step
/// (its joint fit).
fn selection_columns(d: &Diagnosis) -> Vec<(String, Column)> {
    let cs = &d.candidates;
    let mut steps: Vec<(
        String,
        &[Free],
        &crate::orchestration::diagnosis::fit::FitResult,
        f64,
        f64,
    )> = Vec::new();
    if let Some(c) = cs.first().filter(|c| c.significant()) {
        if let Ok(f) = &c.fit {
            steps.push((c.label(), &c.free, f, c.delta_bic, c.explained));
        }
    }
    for st in &d.more {
        steps.push((
            st.part().to_string(),
            &st.free,
            &st.fit,
            st.delta_bic,
            st.explained,
        ));
    }
    vec![
        (
            "step".into(),
            Column::U32((1..=steps.len() as u32).collect()),
        ),
        (
            "effect".into(),
            Column::Str(steps.iter().map(|s| s.0.clone()).collect()),
        ),
        (
            "params".into(),
            Column::StrList(
                steps
                    .iter()
                    .map(|s| s.1.iter().map(|f| f.info.path()).collect())
                    .collect(),
            ),
        ),
        (
            "estimates".into(),
            Column::F64List(steps.iter().map(|s| s.2.estimate.clone()).collect()),
        ),
        (
            "std_errors".into(),
            Column::F64List(steps.iter().map(|s| s.2.se.clone()).collect()),
        ),
        (
            "chi2".into(),
            Column::F64(steps.iter().map(|s| s.2.chi2_after()).collect()),
        ),
        (
            "delta_bic".into(),
            Column::F64(steps.iter().map(|s| s.3).collect()),
        ),
        (
            "explained".into(),
            Column::F64(steps.iter().map(|s| s.4).collect()),
        ),
        (
            "own_share".into(),
            Column::F64(
                (0..steps.len())
                    .map(|i| d.own.get(i).copied().unwrap_or(f64::NAN))
                    .collect(),
            ),
        ),
        (
            "residual_rms".into(),
            Column::F64(steps.iter().map(|s| s.2.after.residual_rms()).collect()),
        ),
        (
            "noise_rms".into(),
            Column::F64(vec![d.noise_rms; steps.len()]),
        ),
    ]
}

/// `tests.parquet`: the residual per test, baseline and each candidate (the "error falls" table).
fn tests_columns(problem: &Problem, d: &Diagnosis) -> Vec<(String, Column)> {
    let cs = &d.candidates;
    let mut rows: Vec<(String, String, f64, f64)> = Vec::new();
    let phase_b = problem.fundamental_phase_error(&d.baseline);
    let phase_c: Vec<Vec<f64>> = cs
        .iter()
        .map(|c| {
            c.fit
                .as_ref()
                .map_or(vec![f64::NAN; problem.tests.len()], |f| {
                    problem.fundamental_phase_error(&f.after)
                })
        })
        .collect();
    for (t, test) in problem.tests.iter().enumerate() {
        rows.push((
            test.name.clone(),
            "baseline".to_string(),
            d.baseline.test_rms(t),
            phase_b[t],
        ));
        for (i, c) in cs.iter().enumerate() {
            rows.push((
                test.name.clone(),
                c.label(),
                c.fit.as_ref().map_or(f64::NAN, |f| f.after.test_rms(t)),
                phase_c[i][t],
            ));
        }
    }
    vec![
        (
            "test".into(),
            Column::Str(rows.iter().map(|r| r.0.clone()).collect()),
        ),
        (
            "model".into(),
            Column::Str(rows.iter().map(|r| r.1.to_string()).collect()),
        ),
        (
            "rms_residual_ratio".into(),
            Column::F64(rows.iter().map(|r| r.2).collect()),
        ),
        (
            "phase_err_fundamental_deg".into(),
            Column::F64(rows.iter().map(|r| r.3).collect()),
        ),
    ]
}

/// `evidence.parquet`: per candidate, the residual features it explains.
fn evidence_columns(problem: &Problem, d: &Diagnosis) -> Vec<(String, Column)> {
    let mut ev: Vec<(&str, usize, usize, f64, f64)> = Vec::new();
    for c in &d.candidates {
        for (t, k, b, a) in diagnose::evidence(d, c, usize::MAX) {
            ev.push((c.effect.name(), t, k, b, a));
        }
    }
    vec![
        (
            "effect".into(),
            Column::Str(ev.iter().map(|e| e.0.to_string()).collect()),
        ),
        (
            "test".into(),
            Column::Str(ev.iter().map(|e| problem.tests[e.1].name.clone()).collect()),
        ),
        (
            "harmonic".into(),
            Column::U32(ev.iter().map(|e| e.2 as u32).collect()),
        ),
        (
            "feature".into(),
            Column::Str(
                ev.iter()
                    .map(|e| harmonic_label(e.2, problem.tests[e.1].samples.rate_hz))
                    .collect(),
            ),
        ),
        (
            "chi2_baseline".into(),
            Column::F64(ev.iter().map(|e| e.3).collect()),
        ),
        (
            "chi2_candidate".into(),
            Column::F64(ev.iter().map(|e| e.4).collect()),
        ),
    ]
}

/// "The error falls": rms acceleration residual per test, baseline and the top candidates.
fn error_falls_svg(problem: &Problem, d: &Diagnosis) -> Result<String, Box<dyn std::error::Error>> {
    let n = problem.tests.len();
    let per = |e: &crate::orchestration::diagnosis::fit::Eval| {
        (0..n).map(|t| e.test_rms(t)).collect::<Vec<f64>>()
    };
    let mut series: Vec<(String, Vec<f64>)> = vec![("baseline".into(), per(&d.baseline))];
    for c in d.candidates.iter().take(4) {
        if let Ok(f) = &c.fit {
            series.push((c.label(), per(&f.after)));
        }
    }
    let y1 = series
        .iter()
        .flat_map(|s| s.1.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(1e-12);
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (900, 380)).into_drawing_area();
        root.fill(&WHITE)?;
        let names: Vec<String> = problem.tests.iter().map(|t| t.name.clone()).collect();
        let mut c = ChartBuilder::on(&root)
            .caption("the error falls: residual rms per test (acceleration, displacement, force), baseline and candidates", ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..1.08 * y1)?;
        c.configure_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                    names[i as usize].clone()
                } else {
                    String::new()
                }
            })
            .y_desc("rms residual / rms measured")
            .draw()?;
        for (i, (name, v)) in series.iter().enumerate() {
            let color = if i == 0 {
                BLACK.to_rgba()
            } else {
                Palette99::pick(i - 1).to_rgba()
            };
            let pts: Vec<(f64, f64)> = v
                .iter()
                .enumerate()
                .filter(|(_, y)| y.is_finite())
                .map(|(t, y)| (t as f64, *y))
                .collect();
            c.draw_series(LineSeries::new(
                pts.clone(),
                color.stroke_width(if i == 0 { 3 } else { 2 }),
            ))?
            .label(name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(3))
            });
            c.draw_series(pts.into_iter().map(|p| Circle::new(p, 4, color.filled())))?;
        }
        legend(&mut c)?;
        root.present()?;
    }
    Ok(s)
}

fn html(campaign: &str, problem: &Problem, d: &Diagnosis) -> anyhow::Result<String> {
    let mut h = String::new();
    let title = format!("vshake: diagnosis of {campaign}");
    write!(
        h,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
body{{font-family:sans-serif;margin:24px;color:#222}} table{{border-collapse:collapse;font-size:13px}}\
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}} th{{background:#f2f2f2}} td:first-child,td:nth-child(2){{text-align:left}}\
</style></head><body>\n<h1>{t}</h1>\n<p id=\"verdict\"><b>Verdict:</b> {v}</p>\n",
        t = esc(&title),
        v = esc(&d.summary())
    )?;
    let svg = error_falls_svg(problem, d).map_err(|e| anyhow::anyhow!("drawing a plot: {e}"))?;
    writeln!(
        h,
        "<figure class=\"plot\" id=\"error-falls\">{svg}</figure>"
    )?;
    h.push_str("<h2>Candidates</h2>\n<table id=\"candidates\"><tr><th>rank</th><th>effect</th><th>family</th><th>fitted parameters</th><th>chi2</th><th>dBIC</th><th>explains</th><th>significant</th></tr>\n");
    for (i, c) in d.candidates.iter().enumerate() {
        let params = match &c.fit {
            Ok(f) => c
                .free
                .iter()
                .zip(&f.estimate)
                .zip(&f.se)
                .map(|((p, e), s)| estimate_text(p.info.name, *e, *s, p.info.unit))
                .collect::<Vec<_>>()
                .join("; "),
            Err(e) => format!("fit failed: {e}"),
        };
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.4e}</td><td>{:.4e}</td><td>{:.1} %</td><td>{}</td></tr>",
            i + 1,
            c.label(),
            c.family,
            esc(&params),
            c.chi2(),
            c.delta_bic,
            100.0 * c.explained,
            if c.significant() { "yes" } else { "no" }
        )?;
    }
    writeln!(h, "</table>\n<p>Baseline chi2 = {:.4e}; about {} for a model right to the noise (the features' degrees of freedom).</p>", d.baseline.chi2(), d.n)?;
    h.push_str("<h2>Evidence</h2>\n");
    for c in d.candidates.iter().take(3) {
        writeln!(h, "<h3>{}</h3>\n<table><tr><th>feature</th><th>test</th><th>chi2 baseline</th><th>chi2 with it</th></tr>", c.effect)?;
        for (t, k, b, a) in diagnose::evidence(d, c, 5) {
            writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{b:.4e}</td><td>{a:.4e}</td></tr>",
                harmonic_label(k, problem.tests[t].samples.rate_hz),
                esc(&problem.tests[t].name)
            )?;
        }
        h.push_str("</table>\n");
    }
    if let Some(map) = &d.state_map {
        h.push_str(&crate::shell::report::kit::state_map_section(map)?);
    }
    h.push_str("<p>The numbers are in the Parquet tables beside this page (candidates, selection, tests, evidence, statemap, stateterms).</p>\n</body></html>\n");
    Ok(h)
}

/// "c_int = 1.700e-11 ± 2.0e-15 m³/(s·Pa)": an estimate with its standard error and its unit
/// (none for a dimensionless one).
fn estimate_text(name: &str, e: f64, se: f64, unit: &str) -> String {
    let unit = crate::kernel::params::unit_after(unit);
    format!("{name} = {e:.3e} ± {se:.1e}{unit}")
}
