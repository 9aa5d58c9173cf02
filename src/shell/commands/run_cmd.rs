//! `study run`: a study file through the batch engine into a Parquet table.

use crate::kernel::simulate::Isa;
use crate::kernel::LANES;
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::SimSpec;
use crate::orchestration::study::batch::{self};
use crate::orchestration::study::problem::Method;
use crate::shell::cli::RunArgs;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::job::interrupt;
use crate::shell::job::progress::Progress;
use crate::shell::BadInput;
use anyhow::Context;
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::shell::job::study_job::*;

/// Samples per chunk on a GPU (one kernel launch each): about twice the lanes an H100 holds at
/// once (132 SMs; float64 lanes use many registers), while the next chunk's samples are drawn.
const GPU_CHUNK: usize = 1 << 17;

pub fn run(args: &RunArgs) -> anyhow::Result<()> {
    check_checkpoint_secs(args.checkpoint_secs)?;
    let Some(job) = job_of(args)? else {
        return Ok(());
    };
    execute(args, job, &mut std::io::stdout(), true)
}

/// Runs a job as `args` say (engine, threads, chunk, dry run, progress), printing its header and
/// summary to `o`; with `signals`, SIGINT and SIGTERM stop it cleanly ([`interrupt`]; an embedding
/// program, the Python package, keeps its own handlers).
pub(crate) fn execute(
    args: &RunArgs,
    mut job: Job,
    o: &mut dyn Write,
    signals: bool,
) -> anyhow::Result<()> {
    let engine = crate::shell::gpu::choose(args.backend)?;
    let names: Vec<String> = job
        .spec
        .excitations
        .iter()
        .map(|e| e.name.clone())
        .collect();
    let (engine, lanes) = engine.for_plan(job.plan.engine_unsupported(&names))?;
    // Chunk size and threads are how the run is scheduled, not what it computes: they stay out of
    // the resolved study in the metadata, so shards (and resumed runs) with other ones still merge.
    // A GPU takes big chunks: one launch of up to GPU_CHUNK lanes per chunk.
    let chunk = match (args.chunk, &lanes) {
        (Some(c), _) => c.max(1),
        (None, Some(_)) => GPU_CHUNK,
        (None, None) => job.spec.chunk,
    };
    job.plan.engine = lanes;
    meta::add_item(&mut job.meta, Key::Backend, engine.tag());
    let pool = pool(args.threads)?;
    let todo = (job.range.start + job.samples_kept())..job.range.end;
    print_header(o, &job, args, &pool, chunk)?;
    writeln!(o, "  backend     {}", engine.describe())?;
    if let Some(b) = meta::get(&job.meta, Key::Backend).filter(|b| b.contains(meta::LIST_SEPARATOR))
    {
        writeln!(o, "  note        the kept rows and the new ones come from different backends ({b}): they differ by rounding (at most about 4e-11 relative)")?;
    }
    if args.dry_run {
        return crate::shell::job::sizing::dry_run(&job, todo, &pool);
    }
    crate::shell::job::sizing::gate_long_run(&job, todo.clone(), &pool, args.yes)?;
    let made = create_history_dir(&job)?;
    if signals {
        interrupt::install().context("catching SIGINT and SIGTERM")?;
    }
    let (summary, progress) = match write_rows(args, &job, todo.clone(), &pool, chunk) {
        Ok(done) => done,
        Err(e) => {
            // An empty histories folder made for this run goes with it (a kept one stays).
            if let Some(dir) = made {
                let _ = std::fs::remove_dir(dir);
            }
            return Err(failed_write(e, &job, args.checkpoint_secs));
        }
    };
    print_done(o, &job, &summary, &progress, todo.len())?;
    write_histories(o, &job)
}

/// Writes the job's rows (the kept ones, then the computed ones) to its partial file, and closes
/// it: renamed to the results file when complete.
fn write_rows(
    args: &RunArgs,
    job: &Job,
    todo: Range<usize>,
    pool: &rayon::ThreadPool,
    chunk: usize,
) -> anyhow::Result<(batch::Summary, Progress)> {
    let partial = parquet_write::partial_path(&job.out);
    let mut sink = ResultsSink::create(&partial, &job.plan, &job.spec, &job.meta)?
        .checkpoints(Duration::from_secs_f64(args.checkpoint_secs));
    if let Some(k) = &job.kept {
        k.copy_into(&mut sink, job)?;
    }
    let progress = Progress::new(
        &job.spec.name,
        todo.len() * job.plan.references.len(),
        args.quiet,
        args.log_progress,
    );
    let summary = batch::run_plan(
        &job.plan,
        todo,
        pool,
        chunk,
        &mut sink,
        &|n| progress.inc(n),
        &|| interrupt::requested().is_some(),
    )?;
    progress.finish();
    finish_results(job, sink, summary.stopped)?;
    Ok((summary, progress))
}

/// A failed write (a full disk, a file-size limit) as one message: the file and the cause once,
/// then what is kept and how to continue. Other errors as they are.
fn failed_write(e: anyhow::Error, job: &Job, secs: f64) -> anyhow::Error {
    let Some(w) = e
        .chain()
        .find_map(|c| c.downcast_ref::<parquet_write::WriteFailed>())
    else {
        return e;
    };
    let partial = parquet_write::partial_path(&job.out);
    let (tmp, side) = (
        parquet_write::tmp_path(&partial),
        parquet_write::checkpoint_path(&partial),
    );
    let fix = if w.no_space {
        "make room (free disk space, or lift the file-size limit or quota)"
    } else {
        "mend the cause"
    };
    let resume = format!("study run --resume {}", partial.display());
    let kept = match (parquet_write::checkpoint_rows(&side), &job.kept) {
        (Some(rows), _) if tmp.exists() => format!(
            "the {rows} of {} rows written by its last checkpoint are kept in {} (and {}); {fix}, then continue with: {resume}",
            job.rows_total(),
            tmp.display(),
            side.display()
        ),
        (_, Some(k)) => format!(
            "no new checkpoint was written; the rows of the interrupted run are still in {}; {fix}, then continue with: {resume}",
            k.source.display()
        ),
        _ => format!(
            "no rows were kept (the run had not reached its first checkpoint, --checkpoint-secs {secs}); {fix}, then start it again"
        ),
    };
    anyhow::anyhow!("{w}; {kept}")
}

/// `--checkpoint-secs` is a positive number of seconds.
fn check_checkpoint_secs(secs: f64) -> anyhow::Result<()> {
    if !(secs.is_finite() && secs > 0.0) {
        return Err(BadInput(format!(
            "--checkpoint-secs {secs}: must be a positive number of seconds"
        ))
        .into());
    }
    Ok(())
}

/// The job to run: a resumed one (none where there is nothing left to resume) or a fresh one.
fn job_of(args: &RunArgs) -> anyhow::Result<Option<Job>> {
    match (&args.resume, &args.file) {
        (Some(f), _) => crate::shell::job::resume::job(f),
        (None, Some(file)) => Job::fresh(args, file).map(Some),
        (None, None) => Err(BadInput(
            "give a study file (study run STUDY.toml) or --resume RESULTS.parquet".into(),
        )
        .into()),
    }
}

/// Creates the histories folder of a study that records histories; the folder where this made
/// it (it was not there).
fn create_history_dir(job: &Job) -> anyhow::Result<Option<PathBuf>> {
    if job.spec.histories.is_empty() {
        return Ok(None);
    }
    let dir = history_dir(&job.out);
    let made = !dir.exists();
    std::fs::create_dir_all(&dir).map_err(|e| {
        BadInput(format!(
            "{}: cannot create the histories folder: {e}",
            dir.display()
        ))
    })?;
    Ok(made.then_some(dir))
}

/// Closes the results file (marked complete or not), drops the kept rows of a resumed run, and
/// turns a stopped run into the error that says how to continue it.
fn finish_results(job: &Job, sink: ResultsSink, stopped: bool) -> anyhow::Result<()> {
    let (done, total) = (sink.rows(), job.rows_total());
    let partial = parquet_write::partial_path(&job.out);
    sink.finish(&meta::completion(done, total))?;
    if let Some(k) = &job.kept {
        k.discard();
    }
    if !stopped {
        // Complete: the table takes its name (never a device's, or another special file's).
        crate::shell::formats::input::regular_output(&job.out)
            .and_then(|_| std::fs::rename(&partial, &job.out))
            .with_context(|| format!("renaming {} to {}", partial.display(), job.out.display()))?;
    }
    if stopped {
        let signal = interrupt::requested().unwrap_or(signal_hook::consts::SIGTERM);
        return Err(interrupt::Interrupted {
            signal,
            message: format!(
                "stopped by {}: {done} of {total} rows written to {}, marked incomplete; continue with: study run --resume {}",
                interrupt::name(signal),
                partial.display(),
                partial.display()
            ),
        }
        .into());
    }
    Ok(())
}

fn print_header(
    o: &mut dyn Write,
    job: &Job,
    args: &RunArgs,
    pool: &rayon::ThreadPool,
    chunk: usize,
) -> anyhow::Result<()> {
    let (spec, plan) = (&job.spec, &job.plan);
    let varied = if matches!(spec.method, Method::File { .. }) {
        plan.columns.len()
    } else {
        spec.varied().len()
    };
    match &args.resume {
        Some(f) => writeln!(o, "study run --resume {}", f.display())?,
        None => writeln!(
            o,
            "study run {}",
            args.file.as_deref().unwrap_or(Path::new("?")).display()
        )?,
    }
    if let Some(m) = &args.model {
        writeln!(
            o,
            "  model       {} (the study's [model.*] on top)",
            m.display()
        )?;
    }
    writeln!(
        o,
        "  design      {}, {} samples x {} excitations = {} runs, {} varied parameters, seed {}",
        spec.method.name(),
        plan.samples(),
        plan.references.len(),
        plan.rows(),
        varied,
        spec.seed
    )?;
    writeln!(
        o,
        "  engine      {} threads, chunks of {} samples, {} kernel ({} lanes), RK4 {} substeps",
        pool.current_num_threads(),
        chunk,
        Isa::detected(),
        LANES,
        spec.solver.substeps
    )?;
    if let Some(s) = &job.shard {
        writeln!(
            o,
            "  shard       {}/{}: samples {}..{} ({} of {})",
            s.index,
            s.count,
            s.range.start,
            s.range.end,
            s.range.len(),
            plan.samples()
        )?;
    }
    if let Some(k) = &job.kept {
        writeln!(
            o,
            "  resume      {} samples ({} rows) kept from {}; {} samples to go",
            k.samples,
            k.samples * plan.references.len(),
            k.source.display(),
            job.range.len() - k.samples
        )?;
    }
    for n in &spec.notes {
        writeln!(o, "  note        {n}")?;
    }
    o.flush()?;
    Ok(())
}

fn print_done(
    o: &mut dyn Write,
    job: &Job,
    summary: &batch::Summary,
    progress: &Progress,
    samples: usize,
) -> anyhow::Result<()> {
    let secs = progress.elapsed().as_secs_f64();
    let sim_s: f64 = job
        .plan
        .references
        .iter()
        .map(|r| r.len() as f64 / r.f_s)
        .sum::<f64>()
        * samples as f64;
    writeln!(
        o,
        "  done        {} rows in {secs:.1} s ({:.0} simulated s per wall s): {} ok, {} failed, {} invalid",
        summary.rows,
        sim_s / secs,
        summary.ok,
        summary.failed,
        summary.invalid
    )?;
    writeln!(o, "  wrote       {}", job.out.display())?;
    Ok(())
}

/// The full histories the study asks for (`[output] histories`) that fall in this file's slice.
fn write_histories(o: &mut dyn Write, job: &Job) -> anyhow::Result<()> {
    let (spec, plan) = (&job.spec, &job.plan);
    let dir = history_dir(&job.out);
    for &id in spec
        .histories
        .iter()
        .filter(|&&id| job.range.contains(&(id as usize)))
    {
        let sample = plan.sample(id as usize);
        let Ok(model) = sample.model else { continue };
        for (e, exc) in spec.excitations.iter().enumerate() {
            let sim_spec = SimSpec {
                model: model.clone(),
                excitation: exc.spec.clone(),
                solver: spec.solver,
                spectrum: spec.spectrum.clone(),
            };
            // A per-sample motion is this sample's realisation; one that cannot run has no history.
            let own = match &plan.per_sample[e] {
                Some(x) => {
                    match crate::orchestration::runs::quake::generated(x, &model, plan.seed, id) {
                        Ok(r) => Some(r.with_spectrum(plan.spectrum.clone())),
                        Err(_) => continue,
                    }
                }
                None => None,
            };
            let outcome = single::run_sim(&sim_spec, own.as_ref().unwrap_or(&plan.references[e]))?;
            let path = dir.join(format!("sample{id}_{}.parquet", exc.name));
            let cols = outcome.history.named_columns();
            let mut meta = meta::header(Kind::TimeHistory);
            meta.extend([
                meta::pair(Key::Spec, sim_spec.resolved_toml()),
                meta::pair(Key::SampleId, id),
                meta::pair(Key::SchemaVersion, SCHEMA_VERSION),
            ]);
            parquet_write::write_parquet(&path, &cols, &meta)?;
            writeln!(o, "  history     {}", path.display())?;
        }
    }
    Ok(())
}
