//! `study tune`: CMA-ES over the controller's gains on a test plan; the tuned model file, every
//! evaluation in Parquet and an HTML report.

use crate::kernel::excitation::Reference;
use crate::kernel::metrics::Metrics;
use crate::kernel::params::ModelParams;
use crate::orchestration::preparation::tune::{self, Evaluation, GenerationSummary, Tuned, Tuner};
use crate::orchestration::preparation::tune_journal;
use crate::orchestration::preparation::tune_spec::{Statistic, TuneSpec};
use crate::orchestration::runs::single::{self, SimOutcome};
use crate::orchestration::runs::spec::SimSpec;
use crate::orchestration::study::batch::{Row, RowStatus};
use crate::shell::cli::TuneArgs;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use crate::shell::job::interrupt;
use crate::shell::job::outputs::output_paths;
use crate::shell::job::study_job;
use crate::shell::job::tune_journal_file::{JournalFile, JOURNAL};
use crate::shell::report::tune_report;
use crate::shell::report::tune_report::Nominal;
use crate::shell::BadInput;
use crate::shell::RunFailed;
use anyhow::Context;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

/// The files the output folder receives.
const OUTPUTS: [&str; 5] = [
    "tuned.toml",
    "gains.toml",
    "evaluations.parquet",
    "generations.parquet",
    "report.html",
];

/// The interrupted tuning's evaluations, in the output folder until it is resumed.
const PARTIAL: &str = "evaluations.partial.parquet";

pub fn run(args: &TuneArgs) -> anyhow::Result<()> {
    let read = |p: &Path| {
        crate::shell::formats::input::read_input_text(p)
            .map_err(|e| BadInput(format!("{}: cannot read: {e}", p.display())))
    };
    let text = read(&args.file)?;
    let model_text = args.model.as_deref().map(read).transpose()?;
    let base_model = crate::shell::formats::campaign_io::load_model(args.model.as_deref())?;
    let spec = TuneSpec::from_toml_on(&text, &args.file.display().to_string(), base_model)?;
    let dir = args.out.clone().unwrap_or_else(|| spec.output.clone());
    let paths = outputs(args, &dir)?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let references = study_job::references(&tune::study_of(&spec), base, &[])?;
    let pool = study_job::pool(args.threads)?;
    std::fs::create_dir_all(&dir).map_err(|e| {
        BadInput(format!(
            "{}: cannot create the output folder: {e}",
            dir.display()
        ))
    })?;
    let mut tuner = Tuner::new(spec, references.clone());
    let (journal, replayed) = open_journal(args, &dir, &text, model_text.as_deref(), &mut tuner)?;
    // stdout is not held while the search runs: its lines are printed from a pool thread.
    let threads = pool.current_num_threads();
    header(
        &mut std::io::stdout().lock(),
        args,
        &tuner.spec,
        threads,
        replayed,
    )?;
    interrupt::install().context("installing the signal handlers")?;
    let t0 = Instant::now();
    let (tuned, journal) = pool.install(|| search(&mut tuner, journal, replayed, args.quiet))?;
    let wall = t0.elapsed().as_secs_f64();
    let command = command_line(args);
    if tuned.interrupted {
        return Err(stopped(args, &dir, &tuner, &tuned, &text, &command));
    }
    let mut o = std::io::stdout().lock();
    result(&mut o, &tuner, &tuned, wall)?;
    let nominal = nominal_runs(&tuner, &tuned, &references)?;
    write_evaluations(&paths[2], &tuner, &tuned, &text, &command)?;
    write_generations(&paths[3], &tuned.generations)?;
    let page = tune_report::html(&tuner, &tuned, &nominal, &references, wall)?;
    crate::shell::job::outputs::write_whole(&paths[4], page.as_bytes())?;
    journal.remove()?;
    remove_stale(&[dir.join(PARTIAL)])?;
    if let Some(why) = &tuned.best.infeasible {
        // A model left by an earlier run (--force) would pass for this one's.
        remove_stale(&paths[..2])?;
        return Err(RunFailed(format!(
            "no candidate met the constraints (the start: {why}); nothing tuned is written: {} says why each failed; loosen [constraints], the gains' bounds or the uncertain parameters",
            paths[2].display()
        ))
        .into());
    }
    write_model(&paths[0], &command, &tuner, &tuned, false)?;
    write_model(&paths[1], &command, &tuner, &tuned, true)?;
    let list: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    writeln!(o, "\n  wrote       {}", list.join(", "))?;
    writeln!(
        o,
        "  use it      study run STUDY.toml --model {} (the model tuned on, with the tuned gains), or --model {} (the gains alone, on the defaults)",
        paths[0].display(),
        paths[1].display()
    )?;
    Ok(())
}

/// The tuning's output files in `dir`, refused where they stand (unless `--force`); a fresh
/// start also refuses an interrupted tuning's files, and `--resume` needs its journal.
fn outputs(args: &TuneArgs, dir: &Path) -> anyhow::Result<Vec<std::path::PathBuf>> {
    if args.resume && !dir.join(JOURNAL).exists() {
        let done = dir.join(OUTPUTS[0]).exists();
        return Err(BadInput(format!(
            "{}: no interrupted tuning to resume (no {JOURNAL}){}",
            dir.display(),
            if done {
                "; the tuning there is complete"
            } else {
                ""
            }
        ))
        .into());
    }
    // A fresh start refuses an interrupted tuning's files too (--resume continues it).
    if !args.resume && !args.force && dir.join(JOURNAL).exists() {
        return Err(BadInput(format!(
            "{}: holds an interrupted tuning ({JOURNAL}): continue it with --resume, or start over with --force",
            dir.display()
        ))
        .into());
    }
    let guarded = match args.resume {
        true => OUTPUTS.to_vec(),
        false => [&OUTPUTS[..], &[JOURNAL, PARTIAL]].concat(),
    };
    let mut paths = output_paths(dir, &guarded, args.force)?;
    paths.truncate(OUTPUTS.len());
    Ok(paths)
}

/// A new journal, or with `--resume` the interrupted tuning's, its generations handed to the
/// tuner to replay: the journal and how many generations it holds.
fn open_journal(
    args: &TuneArgs,
    dir: &Path,
    text: &str,
    model_text: Option<&str>,
    tuner: &mut Tuner,
) -> anyhow::Result<(JournalFile, usize)> {
    if !args.resume {
        return Ok((JournalFile::start(dir, text, model_text)?, 0));
    }
    let (journal, done) = JournalFile::resume(dir, text, model_text)?;
    let n = done.len();
    tuner.resume(done);
    Ok((journal, n))
}

/// The search, each generation printed and journaled (those replayed from the journal are not
/// written again), stopped after the generation in which a signal came.
fn search(
    tuner: &mut Tuner,
    mut journal: JournalFile,
    replayed: usize,
    quiet: bool,
) -> anyhow::Result<(Tuned, JournalFile)> {
    let mut failed = None;
    let journal_path = journal.path().to_path_buf();
    let tuned = tuner.run(|g, evals| {
        if !quiet {
            print_generation(g);
        }
        if g.generation >= replayed {
            let runs = evals
                .iter()
                .map(|e| (e.candidate, &e.gains[..], &e.rows[..]));
            if let Err(e) = journal.append(&tune_journal::generation(g.generation, runs)) {
                failed = Some(e);
                return ControlFlow::Break(());
            }
        }
        match interrupt::requested() {
            Some(_) => ControlFlow::Break(()),
            None => ControlFlow::Continue(()),
        }
    });
    let tuned = tuned.map_err(|e| match e.downcast_ref::<tune::NotThisTuning>() {
        Some(n) => BadInput(format!(
            "{}: {n}; start over with --force",
            journal_path.display()
        ))
        .into(),
        None => e,
    })?;
    match failed {
        Some(e) => Err(e),
        None => Ok((tuned, journal)),
    }
}

/// A tuning stopped by a signal: every evaluation so far in evaluations.partial.parquet, the
/// journal kept for `--resume`, and the error that exits with 128 + the signal.
fn stopped(
    args: &TuneArgs,
    dir: &Path,
    tuner: &Tuner,
    t: &Tuned,
    text: &str,
    command: &str,
) -> anyhow::Error {
    let partial = dir.join(PARTIAL);
    if let Err(e) = write_evaluations(&partial, tuner, t, text, command) {
        return e;
    }
    let signal = interrupt::requested().unwrap_or(signal_hook::consts::SIGTERM);
    let last = t.generations.last().map_or(0, |g| g.generation);
    let out = format!("--out {}", dir.display());
    interrupt::Interrupted {
        signal,
        message: format!(
            "stopped by {} after generation {last} of at most {}: {} candidates ({} runs) kept in {} and {}; continue with: study {} {out} --resume",
            interrupt::name(signal),
            tuner.spec.search.generations,
            t.evaluations.len(),
            t.evaluations.iter().map(|e| e.rows.len()).sum::<usize>(),
            partial.display(),
            dir.join(JOURNAL).display(),
            command_line(args),
        ),
    }
    .into()
}

/// The command as the files record it: `tune FILE [--model M]`.
fn command_line(args: &TuneArgs) -> String {
    match &args.model {
        Some(m) => format!("tune {} --model {}", args.file.display(), m.display()),
        None => format!("tune {}", args.file.display()),
    }
}

/// Files of an earlier run that would pass for this one's, removed.
fn remove_stale(paths: &[std::path::PathBuf]) -> anyhow::Result<()> {
    for stale in paths.iter().filter(|p| p.exists()) {
        std::fs::remove_file(stale).with_context(|| format!("removing {}", stale.display()))?;
    }
    Ok(())
}

fn header(
    o: &mut impl Write,
    args: &TuneArgs,
    spec: &TuneSpec,
    threads: usize,
    replayed: usize,
) -> anyhow::Result<()> {
    writeln!(o, "study tune {}", args.file.display())?;
    if args.resume {
        writeln!(
            o,
            "  resumed     {replayed} generation{} from the journal, not run again",
            if replayed == 1 { "" } else { "s" }
        )?;
    }
    if let Some(m) = &args.model {
        writeln!(
            o,
            "  model       {} (the tuning file's [model.*] on top)",
            m.display()
        )?;
    }
    let gains: Vec<String> = spec
        .gains
        .iter()
        .map(|g| {
            format!(
                "{} in [{}, {}] from {}",
                g.info.path(),
                g.low,
                g.high,
                g.start
            )
        })
        .collect();
    writeln!(o, "  gains       {}", gains.join("; "))?;
    for (e, w) in spec.excitations.iter().zip(&spec.weights) {
        writeln!(
            o,
            "  plan        {} (weight {w}): {}",
            e.name,
            e.spec.describe()
        )?;
    }
    let terms: Vec<String> = spec
        .objective
        .iter()
        .map(|(m, w)| format!("{w} x {m}"))
        .collect();
    writeln!(o, "  objective   {}", terms.join(" + "))?;
    writeln!(o, "  constraints every run ends (stroke, pressure, divergence guard); max |u| <= {:.0} % of u_lim", 100.0 * spec.valve_cmd_fraction)?;
    if !spec.uncertain.is_empty() {
        let names: Vec<String> = spec.uncertain.iter().map(|v| v.path()).collect();
        let statistic = match spec.statistic {
            Statistic::Mean => "the mean".to_string(),
            Statistic::Quantile(q) => format!("the {:.0}th percentile", 100.0 * q),
        };
        writeln!(
            o,
            "  robust      {statistic} of the objective over {} draws of {}",
            spec.draws,
            names.join(", ")
        )?;
    }
    let s = spec.search;
    let lambda = s.population.unwrap_or_else(|| {
        crate::orchestration::preparation::cmaes::default_population(spec.gains.len())
    });
    writeln!(o, "  search      CMA-ES, population {lambda}, sigma0 {}, at most {} generations, seed {}, {threads} thread{}", s.sigma0, s.generations, spec.seed, if threads == 1 { "" } else { "s" })?;
    if !args.quiet {
        writeln!(
            o,
            "\n  {:>10} {:>5} {:>8} {:>12} {:>12} {:>8}",
            "generation", "candidates", "feasible", "best", "best so far", "sigma"
        )?;
    }
    Ok(())
}

fn print_generation(g: &GenerationSummary) {
    let v = |x: f64| {
        if x.is_nan() {
            "-".to_string()
        } else {
            format!("{x:.5}")
        }
    };
    println!(
        "  {:>10} {:>10} {:>8} {:>12} {:>12} {:>8.4}",
        g.generation,
        g.evaluated,
        g.feasible,
        v(g.best),
        v(g.best_so_far),
        g.sigma
    );
}

/// The tuned gains against the start, and the objective's fall.
fn result(o: &mut impl Write, tuner: &Tuner, t: &Tuned, wall: f64) -> anyhow::Result<()> {
    let runs: usize = t.evaluations.iter().map(|e| e.rows.len()).sum();
    writeln!(
        o,
        "\n  stopped     {} after {:.1} s ({} runs)",
        t.stopped, wall, runs
    )?;
    // The names' column: 22 wide, wider for a compensator's longer names.
    let w = (tuner.spec.gains.iter())
        .map(|g| g.info.path().len())
        .fold(22, usize::max);
    writeln!(o, "\n  {:<w$} {:>12} {:>12}", "gain", "start", "tuned")?;
    for (i, g) in tuner.spec.gains.iter().enumerate() {
        writeln!(
            o,
            "  {:<w$} {:>12.6} {:>12.6}",
            g.info.path(),
            t.start.gains[i],
            t.best.gains[i]
        )?;
    }
    let q = tuner.reported_quantile();
    let row = |o: &mut dyn Write, name: &str, a: f64, b: f64| {
        let v = |x: f64| {
            if x.is_finite() {
                format!("{x:.5}")
            } else {
                "infeasible".into()
            }
        };
        let change = if a.is_finite() && b.is_finite() && a != 0.0 {
            format!(" {:>+8.1} %", 100.0 * (b / a - 1.0))
        } else {
            String::new()
        };
        writeln!(o, "  {:<w$} {:>12} {:>12}{change}", name, v(a), v(b))
    };
    row(o, "objective", t.start.objective, t.best.objective)?;
    if tuner.draws.len() > 1 {
        row(o, "mean over draws", t.start.mean, t.best.mean)?;
        row(
            o,
            &format!("{:.0}th percentile", 100.0 * q),
            t.start.quantile,
            t.best.quantile,
        )?;
    }
    row(
        o,
        "max |u| / u_lim",
        t.start.valve_fraction,
        t.best.valve_fraction,
    )?;
    if let Some(why) = &t.start.infeasible {
        writeln!(o, "  the start is infeasible: {why}")?;
    }
    Ok(())
}

fn nominal_runs(tuner: &Tuner, t: &Tuned, refs: &[Reference]) -> anyhow::Result<Nominal> {
    let run = |gains: &[f64]| -> anyhow::Result<Vec<SimOutcome>> {
        let model = with_gains(tuner, gains);
        tuner
            .spec
            .excitations
            .iter()
            .zip(refs)
            .map(|(e, r)| {
                let spec = SimSpec {
                    model: model.clone(),
                    excitation: e.spec.clone(),
                    solver: tuner.spec.solver,
                    spectrum: tuner.spec.spectrum.clone(),
                };
                single::run_sim(&spec, r)
                    .map_err(|err| anyhow::anyhow!("excitation {}: {err}", e.name))
            })
            .collect()
    };
    let (start, tuned) = rayon::join(|| run(&t.start.gains), || run(&t.best.gains));
    Ok(Nominal {
        start: start?,
        tuned: tuned?,
    })
}

/// The tuning's model with `gains` set.
pub(crate) fn with_gains(tuner: &Tuner, gains: &[f64]) -> ModelParams {
    let mut m = tuner.spec.model.clone();
    for (g, v) in tuner.spec.gains.iter().zip(gains) {
        g.info.set(&mut m, *v);
    }
    m
}

/// tuned.toml: the model tuned on (the defaults, `--model`, the tuning file's `[model.*]`) with
/// the tuned gains; gains.toml (`gains_only`): the tuned gains alone, to put on any other model.
fn write_model(
    path: &Path,
    command: &str,
    tuner: &Tuner,
    t: &Tuned,
    gains_only: bool,
) -> anyhow::Result<()> {
    let model = with_gains(tuner, &t.best.gains);
    let table = if gains_only {
        // [model.controller] and each tuned compensator's table (which switches it on).
        let mut m = toml::Table::new();
        for (g, v) in tuner.spec.gains.iter().zip(&t.best.gains) {
            let c = m
                .entry(g.info.component.name())
                .or_insert_with(|| toml::Table::new().into());
            if let toml::Value::Table(c) = c {
                c.insert(g.info.name.into(), (*v).into());
            }
        }
        m
    } else {
        crate::orchestration::runs::spec::model_table(&model)
    };
    let mut root = toml::Table::new();
    root.insert("model".into(), toml::Value::Table(table));
    let gains: Vec<String> = tuner
        .spec
        .gains
        .iter()
        .zip(&t.best.gains)
        .map(|(g, v)| format!("# {} = {v:?}", g.info.path()))
        .collect();
    let what = if gains_only {
        "the tuned gains alone (every other parameter: the defaults, or the --model it is given with)"
    } else {
        "the model tuned on, every [model.*] table of the tuning file and its --model included, with the tuned gains"
    };
    let head = format!(
        "# Tuned by `study {command}` (vshake {}): objective {:.6} -> {:.6} ({:+.1} %)\n# This file: {what}.\n{}\n",
        env!("CARGO_PKG_VERSION"),
        t.start.objective,
        t.best.objective,
        100.0 * (t.best.objective / t.start.objective - 1.0),
        gains.join("\n")
    );
    let text = head + &toml::to_string(&root)?;
    crate::shell::job::outputs::write_whole(path, text.as_bytes())
}

/// evaluations.parquet: a row per run (generation, candidate, draw, excitation).
fn write_evaluations(
    path: &Path,
    tuner: &Tuner,
    t: &Tuned,
    text: &str,
    command: &str,
) -> anyhow::Result<()> {
    let mut cols = run_columns(tuner, t);
    let runs: Vec<(&Evaluation, usize)> = t
        .evaluations
        .iter()
        .flat_map(|e| (0..e.rows.len()).map(move |i| (e, i)))
        .collect();
    let specimen = tuner.carries_building();
    let metrics: Vec<&str> = Metrics::NAN
        .columns_for(specimen)
        .iter()
        .map(|c| c.0)
        .collect();
    for (k, m) in metrics.iter().enumerate() {
        // A metric of a run that did not end, or one the run does not define, is null.
        let v = runs
            .iter()
            .map(|(e, i)| e.rows[*i].metrics.columns_for(specimen)[k].1);
        cols.push((m.to_string(), Column::OptF64(v.map(finite).collect())));
    }
    let n_e = tuner.spec.excitations.len();
    let draw_objective = runs.iter().map(|(e, i)| finite(e.per_draw[i / n_e]));
    let draw_objective = Column::OptF64(draw_objective.collect());
    cols.push(("draw_objective".into(), draw_objective));
    let objective = runs.iter().map(|(e, _)| finite(e.objective));
    cols.push(("objective".into(), Column::OptF64(objective.collect())));
    let feasible = runs.iter().map(|(e, _)| e.infeasible.is_none());
    cols.push(("feasible".into(), Column::Bool(feasible.collect())));
    let why = runs.iter().map(|(e, _)| e.infeasible.clone());
    cols.push(("infeasible_reason".into(), Column::OptStr(why.collect())));
    let mut m = meta::header(Kind::TuneEvaluations);
    m.push(meta::pair(Key::Spec, text));
    m.push(meta::pair(Key::Seed, tuner.spec.seed));
    m.push(meta::pair(Key::Command, command));
    parquet_write::write_table(path, cols, &m)
        .with_context(|| format!("writing {}", path.display()))
}

/// A value, or null where it is not finite.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// The columns that say which run a row is: generation, candidate, draw, the gains and the
/// uncertain parameters, the excitation, the status.
fn run_columns(tuner: &Tuner, t: &Tuned) -> Vec<(String, Column)> {
    let n_e = tuner.spec.excitations.len();
    let runs: Vec<(&Evaluation, usize, &Row)> = t
        .evaluations
        .iter()
        .flat_map(|e| e.rows.iter().enumerate().map(move |(i, r)| (e, i, r)))
        .collect();
    let int = |f: &dyn Fn(&(&Evaluation, usize, &Row)) -> usize| {
        Column::U32(runs.iter().map(|x| f(x) as u32).collect())
    };
    let mut cols = vec![
        ("generation".to_string(), int(&|x| x.0.generation)),
        ("candidate".into(), int(&|x| x.0.candidate)),
        ("draw".into(), int(&|x| x.1 / n_e)),
    ];
    let names = crate::kernel::params::column_names(tuner.columns());
    for (c, name) in names.into_iter().enumerate() {
        let v = runs.iter().map(|x| x.2.values[c]);
        cols.push((name, Column::F64(v.collect())));
    }
    let names = &tuner.spec.excitations;
    let name = runs
        .iter()
        .map(|x| names[x.2.excitation as usize].name.clone());
    cols.push(("excitation".into(), Column::Str(name.collect())));
    let status = runs.iter().map(|x| x.2.status.label().to_string());
    cols.push(("status".into(), Column::Str(status.collect())));
    let time = runs.iter().map(|x| match x.2.status {
        RowStatus::Failed { time_s, .. } => Some(time_s),
        _ => None,
    });
    cols.push(("fail_time_s".into(), Column::OptF64(time.collect())));
    let reason = runs
        .iter()
        .map(|x| x.2.status.category().map(str::to_string));
    cols.push(("fail_reason".into(), Column::OptStr(reason.collect())));
    let value = runs.iter().map(|x| x.2.status.value());
    cols.push(("fail_value".into(), Column::OptF64(value.collect())));
    let detail = runs.iter().map(|x| x.2.status.detail());
    cols.push(("fail_detail".into(), Column::OptStr(detail.collect())));
    cols
}

/// generations.parquet: a row per generation.
fn write_generations(path: &Path, gens: &[GenerationSummary]) -> anyhow::Result<()> {
    let int = |f: &dyn Fn(&GenerationSummary) -> usize| {
        Column::U32(gens.iter().map(|g| f(g) as u32).collect())
    };
    let num = |f: &dyn Fn(&GenerationSummary) -> f64| Column::F64(gens.iter().map(f).collect());
    let cols = vec![
        ("generation".to_string(), int(&|g| g.generation)),
        ("candidates".into(), int(&|g| g.evaluated)),
        ("feasible".into(), int(&|g| g.feasible)),
        ("best_objective".into(), num(&|g| g.best)),
        ("best_so_far".into(), num(&|g| g.best_so_far)),
        ("sigma".into(), num(&|g| g.sigma)),
        ("spread".into(), num(&|g| g.spread)),
    ];
    let m = meta::header(Kind::TuneGenerations);
    parquet_write::write_table(path, cols, &m)
        .with_context(|| format!("writing {}", path.display()))
}
