//! `study run`: a study file through the batch engine into a Parquet table.

use super::cli::RunArgs;
use super::meta::{self, Key, Kind};
use super::outputs::{check_output, check_replaceable, OutputLock};
use super::progress::Progress;
use super::tables::{self, input_if_user, load_reference, Column, ParquetStream};
use super::{interrupt, BadInput};
use crate::kernel::params::{ModelParams, ParamInfo};
use crate::kernel::simulate::Isa;
use crate::kernel::LANES;
use crate::orchestration::batch::{self, Plan, Row, RowSink, RowStatus};
use crate::orchestration::sim;
use crate::orchestration::spec::SimSpec;
use crate::orchestration::study::{cannot_vary, Method, StudySpec};
use anyhow::Context;
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Version of the results table layout (docs/formats.md "Results"). 2: a metric of a run that did
/// not end is null (was NaN); `fail_reason` is a fixed category, with `fail_value` and
/// `fail_detail` beside it.
pub const SCHEMA_VERSION: &str = "2";

/// Reads and validates a study file.
pub fn load_study(file: &Path) -> anyhow::Result<StudySpec> {
    load_study_on(file, None)
}

/// Reads and validates a study file on the model file `model` (`--model`; None: the defaults).
pub(crate) fn load_study_on(file: &Path, model: Option<&Path>) -> anyhow::Result<StudySpec> {
    let base = super::campaign_io::load_model(model)?;
    let text = tables::read_input_text(file)
        .map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    Ok(StudySpec::from_toml_on(
        &text,
        &file.display().to_string(),
        base,
    )?)
}

/// Builds the plan of a study: references of its excitations and its design.
pub fn plan_for(spec: &StudySpec, base: &Path) -> anyhow::Result<Plan> {
    match &spec.method {
        Method::File { path } => {
            let path = base.join(path);
            let infos = design_columns(&path)?;
            let wanted: Vec<String> = infos.iter().map(|i| i.path()).collect();
            let references = references(spec, base, &wanted)?;
            let names = tables::column_names(&path).map_err(input_if_user)?;
            let wanted: Vec<&str> = names.iter().map(String::as_str).collect();
            let t = tables::read_columns(&path, &wanted, &[]).map_err(input_if_user)?;
            let rows: Vec<Vec<f64>> = (0..t.rows())
                .map(|r| t.columns.iter().map(|c| c[r]).collect())
                .collect();
            Ok(Plan::from_table(spec, infos, rows, references))
        }
        _ => {
            let varied: Vec<String> = spec.varied().iter().map(|v| v.info.path()).collect();
            Ok(Plan::generated(spec, references(spec, base, &varied)?))
        }
    }
}

/// The excitations' references: each made once, with the study's spectrum where it is not a
/// sine; one that depends on the sample (`varied` paths) is made per sample by the plan, and
/// gets an empty placeholder here.
pub fn references(
    spec: &StudySpec,
    base: &Path,
    varied: &[String],
) -> anyhow::Result<Vec<crate::kernel::excitation::Reference>> {
    let f_s = spec.model.controller.f_s;
    spec.excitations
        .iter()
        .map(|e| {
            if e.spec.per_sample(|p| varied.iter().any(|v| v == p)) {
                return Ok(crate::kernel::excitation::Reference::from_states(f_s, &[]));
            }
            let r = load_reference(&e.spec, &spec.model, base, spec.seed)
                .with_context(|| format!("excitation {:?}", e.name))?;
            Ok(if e.spec.is_sine() {
                r
            } else {
                r.with_spectrum(spec.spectrum.clone())
            })
        })
        .collect()
}

/// The parameters of a design file's columns (each a path such as controller.g_d or a column
/// name such as g_d), refused when unknown or not variable.
fn design_columns(path: &Path) -> anyhow::Result<Vec<&'static ParamInfo>> {
    let names = tables::column_names(path).map_err(input_if_user)?;
    parameters_of_columns(&names, &path.display().to_string())
}

/// The parameters that columns name (a path such as controller.g_d, a qualified column name, or
/// a column name such as g_d), refused when unknown or not variable; `source` names the columns'
/// file in errors.
pub(crate) fn parameters_of_columns(
    names: &[String],
    source: &str,
) -> anyhow::Result<Vec<&'static ParamInfo>> {
    let mut infos: Vec<&'static ParamInfo> = Vec::new();
    for n in names {
        // A name is quoted short in a message (a header line may be megabytes long).
        let n_ = tables::clip(n, 60);
        let info = ModelParams::lookup(n)
            .or_else(|| ModelParams::registry().find(|p| p.qualified_column_name() == *n))
            .or_else(|| ModelParams::registry().find(|p| p.column_name() == *n || p.name == n));
        match info.map(|i| (i, cannot_vary(i))) {
            Some((_, Some(why))) => return Err(BadInput(format!("{source}: column `{n_}`: {why}")).into()),
            Some((i, None)) if infos.iter().any(|j| j.path() == i.path()) => {
                return Err(BadInput(format!("{source}: column `{n_}` names {}, which another column names too; give each parameter once", i.path())).into())
            }
            Some((i, None)) => infos.push(i),
            None => {
                return Err(BadInput(format!(
                    "{source}: column `{n_}` is not a model parameter (use a path such as controller.g_d, or a column name such as g_d; `study params` lists them)"
                ))
                .into())
            }
        }
    }
    Ok(infos)
}

/// Writes rows to a results file.
pub struct ResultsSink {
    stream: ParquetStream,
    exc_names: Vec<String>,
    metrics: Vec<&'static str>,
    saltelli: bool,
    columns: Vec<String>,
}

impl ResultsSink {
    /// Column layout: sample_id, excitation_id, excitation, [design_base, design_block],
    /// one column per parameter, one per metric (null where the run did not end), status,
    /// fail_time_s, fail_reason (a fixed category), fail_value (SI), fail_detail (in words).
    pub fn create(
        path: &Path,
        plan: &Plan,
        spec: &StudySpec,
        metadata: &[(String, String)],
    ) -> anyhow::Result<Self> {
        let saltelli = plan.saltelli_dims.is_some();
        let columns: Vec<String> = crate::kernel::params::column_names(&plan.columns);
        let template = Self::template(saltelli, &columns, &spec.metrics);
        Ok(ResultsSink {
            stream: ParquetStream::create(path, &template, metadata)?,
            exc_names: spec.excitations.iter().map(|e| e.name.clone()).collect(),
            metrics: spec.metrics.clone(),
            saltelli,
            columns,
        })
    }

    fn template(saltelli: bool, columns: &[String], metrics: &[&str]) -> Vec<(String, Column)> {
        let mut t = vec![
            ("sample_id".to_string(), Column::U64(vec![])),
            ("excitation_id".to_string(), Column::U32(vec![])),
            ("excitation".to_string(), Column::Str(vec![])),
        ];
        if saltelli {
            t.push(("design_base".into(), Column::U32(vec![])));
            t.push(("design_block".into(), Column::U32(vec![])));
        }
        t.extend(columns.iter().map(|c| (c.clone(), Column::F64(vec![]))));
        t.extend(
            metrics
                .iter()
                .map(|m| (m.to_string(), Column::OptF64(vec![]))),
        );
        t.push(("status".into(), Column::Str(vec![])));
        t.push(("fail_time_s".into(), Column::OptF64(vec![])));
        t.push(("fail_reason".into(), Column::OptStr(vec![])));
        t.push(("fail_value".into(), Column::OptF64(vec![])));
        t.push(("fail_detail".into(), Column::OptStr(vec![])));
        t
    }

    /// Makes the rows survive a hard kill (see [`ParquetStream::checkpoints`]).
    pub fn checkpoints(mut self, every: Duration) -> Self {
        self.stream = self.stream.checkpoints(every);
        self
    }

    /// Appends rows copied from another results file with the same columns.
    pub(crate) fn write_batch(&mut self, batch: &arrow_array::RecordBatch) -> anyhow::Result<()> {
        self.stream.write_batch(batch)
    }

    /// Rows written so far.
    pub fn rows(&self) -> usize {
        self.stream.rows()
    }

    /// Closes the file with its completion keys ([`completion`]).
    pub fn finish(self, completion: &[(String, String)]) -> anyhow::Result<()> {
        self.stream.finish_with(completion)
    }
}

impl RowSink for ResultsSink {
    fn write(&mut self, rows: &[Row]) -> anyhow::Result<()> {
        let mut cols = vec![
            Column::U64(rows.iter().map(|r| r.sample_id).collect()),
            Column::U32(rows.iter().map(|r| r.excitation).collect()),
            Column::Str(
                rows.iter()
                    .map(|r| self.exc_names[r.excitation as usize].clone())
                    .collect(),
            ),
        ];
        if self.saltelli {
            cols.push(Column::U32(
                rows.iter().map(|r| r.saltelli.map_or(0, |s| s.0)).collect(),
            ));
            cols.push(Column::U32(
                rows.iter().map(|r| r.saltelli.map_or(0, |s| s.1)).collect(),
            ));
        }
        for c in 0..self.columns.len() {
            cols.push(Column::F64(rows.iter().map(|r| r.values[c]).collect()));
        }
        // Metric values in table order, once per row; then the chosen ones as columns.
        let names: Vec<&str> = crate::kernel::metrics::Metrics::NAN
            .columns()
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        let values: Vec<Vec<(&str, f64)>> = rows.iter().map(|r| r.metrics.columns()).collect();
        for m in &self.metrics {
            let k = names
                .iter()
                .position(|n| n == m)
                .expect("metric names are validated");
            // A metric of a run that did not end, or one the run does not define, is null.
            let cell = |v: f64| v.is_finite().then_some(v);
            cols.push(Column::OptF64(
                values.iter().map(|v| cell(v[k].1)).collect(),
            ));
        }
        cols.push(Column::Str(
            rows.iter().map(|r| r.status.label().to_string()).collect(),
        ));
        cols.push(Column::OptF64(
            rows.iter()
                .map(|r| {
                    if let RowStatus::Failed { time_s, .. } = r.status {
                        Some(time_s)
                    } else {
                        None
                    }
                })
                .collect(),
        ));
        cols.push(Column::OptStr(
            (rows.iter())
                .map(|r| r.status.category().map(str::to_string))
                .collect(),
        ));
        cols.push(Column::OptF64(
            rows.iter().map(|r| r.status.value()).collect(),
        ));
        cols.push(Column::OptStr(
            rows.iter().map(|r| r.status.detail()).collect(),
        ));
        self.stream.write(cols)
    }
}

/// The metadata every results file carries.
pub(crate) fn results_metadata(
    spec: &StudySpec,
    plan: &Plan,
    extra: &[(String, String)],
) -> Vec<(String, String)> {
    let mut m = meta::header(Kind::StudyResults);
    m.extend([
        meta::pair(Key::Study, spec.resolved_toml()),
        meta::pair(Key::Seed, spec.seed),
        meta::pair(Key::SchemaVersion, SCHEMA_VERSION),
        meta::pair(Key::Design, spec.method.name()),
        meta::pair(Key::Samples, plan.samples()),
        meta::pair(
            Key::Excitations,
            meta::list(spec.excitations.iter().map(|e| &e.name)),
        ),
        meta::pair(
            Key::Parameters,
            meta::list(plan.columns.iter().map(|c| c.path())),
        ),
        meta::pair(
            Key::ParameterColumns,
            meta::list(crate::kernel::params::column_names(&plan.columns)),
        ),
        meta::pair(Key::Metrics, meta::list(&spec.metrics)),
        meta::pair(
            Key::DesignParameters,
            meta::list(design_parameters(spec, plan)),
        ),
    ]);
    m.extend_from_slice(extra);
    m
}

fn design_parameters(spec: &StudySpec, plan: &Plan) -> Vec<String> {
    match spec.method {
        Method::File { .. } => plan.columns.iter().map(|c| c.path()).collect(),
        _ => spec.varied().iter().map(|v| v.path()).collect(),
    }
}

/// Builds the rayon pool for `--threads` (0 = all cores).
pub fn pool(threads: usize) -> anyhow::Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if threads > 0 {
        b = b.num_threads(threads);
    }
    Ok(b.build()?)
}

/// A run to do: the study, its plan, the slice of samples the file covers, the output file and
/// its metadata, and the rows an interrupted run already wrote.
pub struct Job {
    pub spec: StudySpec,
    pub plan: Plan,
    pub shard: Option<Shard>,
    pub range: Range<usize>,
    pub out: PathBuf,
    pub meta: Vec<(String, String)>,
    pub kept: Option<super::resume::Kept>,
    /// The table's lock, held until the job is dropped: one writer at a time (none for a dry
    /// run).
    #[allow(dead_code)] // held, never read
    pub(crate) lock: Option<OutputLock>,
}

impl Job {
    /// A new run of `args.file`: everything it needs is read and checked here, before any work.
    fn fresh(args: &RunArgs, file: &Path) -> anyhow::Result<Job> {
        let spec = load_study_on(file, args.model.as_deref())?;
        let study_file = std::fs::canonicalize(file).unwrap_or_else(|_| file.to_path_buf());
        let base = file.parent().unwrap_or(Path::new("."));
        Job::of_spec(args, spec, base, &study_file.display().to_string())
    }

    /// A new run of a read study: `base` is the folder its relative paths start from,
    /// `study_file` the file (or the words) the metadata names it by.
    pub(crate) fn of_spec(
        args: &RunArgs,
        mut spec: StudySpec,
        base: &Path,
        study_file: &str,
    ) -> anyhow::Result<Job> {
        if let Some(n) = args.samples {
            if n == 0 {
                return Err(BadInput("--samples must be at least 1".into()).into());
            }
            spec.samples = n;
            spec.check_design_size()
                .map_err(|why| BadInput(format!("--samples {n}: {why}")))?;
        }
        let plan = plan_for(&spec, base)?;
        Job::of_plan(args, spec, plan, study_file)
    }

    /// A new run of a study's plan (its design made or given), named `study_file` in the metadata.
    pub(crate) fn of_plan(
        args: &RunArgs,
        spec: StudySpec,
        plan: Plan,
        study_file: &str,
    ) -> anyhow::Result<Job> {
        let shard = args
            .shard
            .as_deref()
            .map(|s| Shard::parse(s, plan.samples()))
            .transpose()?;
        let range = shard
            .as_ref()
            .map_or(0..plan.samples(), |s| s.range.clone());
        for (i, &id) in spec.histories.iter().enumerate() {
            if id as usize >= plan.samples() {
                return Err(BadInput(format!("{study_file}: output.histories[{i}]: sample {id} does not exist (the study has samples 0 to {})", plan.samples() - 1)).into());
            }
        }
        let (out, lock) = output_path(args.out.as_deref(), &spec, shard.as_ref(), !args.dry_run)?;
        let mut extra = vec![meta::pair(Key::StudyFile, study_file)];
        extra.extend(shard.as_ref().map_or_else(Vec::new, |s| s.metadata()));
        let meta = results_metadata(&spec, &plan, &extra);
        Ok(Job {
            spec,
            plan,
            shard,
            range,
            out,
            meta,
            kept: None,
            lock,
        })
    }

    fn samples_kept(&self) -> usize {
        self.kept.as_ref().map_or(0, |k| k.samples)
    }

    fn rows_total(&self) -> usize {
        self.range.len() * self.plan.references.len()
    }
}

/// The results file: `--out` (inside it as `<name>.parquet` when it is a folder), else the
/// study's `[output] file` (with `.shard-I-of-N` for a shard), and its lock where `lock` (a dry
/// run writes nothing, and takes none). Refused when it is a folder or another file that is not a
/// regular one, when its folder cannot be written, or when another process writes it: before any
/// work.
fn output_path(
    out: Option<&Path>,
    spec: &StudySpec,
    shard: Option<&Shard>,
    lock: bool,
) -> anyhow::Result<(PathBuf, Option<OutputLock>)> {
    let default = match shard {
        None => spec.output.clone(),
        Some(s) => {
            let stem = spec
                .output
                .file_stem()
                .map(|x| x.to_string_lossy().to_string())
                .unwrap_or_else(|| "results".into());
            spec.output
                .with_file_name(format!("{stem}.shard-{}-of-{}.parquet", s.index, s.count))
        }
    };
    // A folder, or a path ending in a separator (a folder to make), takes the default name.
    let folder = |o: &Path| {
        let last = o.as_os_str().to_string_lossy().chars().last();
        o.is_dir() || last.is_some_and(std::path::is_separator)
    };
    let out = match out {
        Some(o) if folder(o) => o.join(
            default
                .file_name()
                .unwrap_or_else(|| std::ffi::OsStr::new("results.parquet")),
        ),
        Some(o) => o.to_path_buf(),
        None => default,
    };
    if out.is_dir() {
        return Err(BadInput(format!(
            "{}: is a folder; name the results file (e.g. --out {}.parquet)",
            out.display(),
            spec.name
        ))
        .into());
    }
    check_output(&out)?;
    check_output(&tables::partial_path(&out))?;
    check_writable(&out)?;
    let lock = lock.then(|| OutputLock::acquire(&out)).transpose()?;
    check_no_interrupted_run(&out)?;
    check_replaceable(&out)?;
    Ok((out, lock))
}

/// A new run may replace a table vshake wrote ([`check_replaceable`]), never the rows of an
/// interrupted run of it (those are `--resume`'s).
fn check_no_interrupted_run(out: &Path) -> anyhow::Result<()> {
    let partial = tables::partial_path(out);
    let left: Vec<String> = [
        partial.clone(),
        tables::killed_path(&partial),
        tables::tmp_path(&partial),
        tables::checkpoint_path(&partial),
    ]
    .iter()
    .filter(|p| p.exists())
    .map(|p| p.display().to_string())
    .collect();
    if !left.is_empty() {
        return Err(BadInput(format!(
            "{}: an interrupted run of this table left its rows in {}; continue it with: study run --resume {}, or remove {} to start again",
            out.display(),
            left.join(" and "),
            partial.display(),
            if left.len() > 1 { "those files" } else { "that file" }
        ))
        .into());
    }
    Ok(())
}

/// Checks that the results file's folder (or the nearest existing ancestor of it, which the run
/// will create the rest of) takes a new file.
fn check_writable(out: &Path) -> anyhow::Result<()> {
    let mut dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    while !dir.exists() {
        match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => dir = p.to_path_buf(),
            _ => dir = PathBuf::from("."),
        }
    }
    if !dir.is_dir() {
        return Err(BadInput(format!(
            "{}: cannot write the results file: {} is not a folder",
            out.display(),
            dir.display()
        ))
        .into());
    }
    let probe = dir.join(format!(".vshake-probe-{}", std::process::id()));
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(BadInput(format!(
            "{}: cannot write the results file in {}: {e}",
            out.display(),
            dir.display()
        ))
        .into()),
    }
}

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
    let engine = super::gpu::choose(args.backend)?;
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
        return super::sizing::dry_run(&job, todo, &pool);
    }
    super::sizing::gate_long_run(&job, todo.clone(), &pool, args.yes)?;
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
    let partial = tables::partial_path(&job.out);
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
        .find_map(|c| c.downcast_ref::<tables::WriteFailed>())
    else {
        return e;
    };
    let partial = tables::partial_path(&job.out);
    let (tmp, side) = (
        tables::tmp_path(&partial),
        tables::checkpoint_path(&partial),
    );
    let fix = if w.no_space {
        "make room (free disk space, or lift the file-size limit or quota)"
    } else {
        "mend the cause"
    };
    let resume = format!("study run --resume {}", partial.display());
    let kept = match (tables::checkpoint_rows(&side), &job.kept) {
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
        (Some(f), _) => super::resume::job(f),
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
    let partial = tables::partial_path(&job.out);
    sink.finish(&meta::completion(done, total))?;
    if let Some(k) = &job.kept {
        k.discard();
    }
    if !stopped {
        // Complete: the table takes its name (never a device's, or another special file's).
        super::outputs::regular_output(&job.out)
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
            };
            // A per-sample motion is this sample's realisation; one that cannot run has no history.
            let own = match &plan.per_sample[e] {
                Some(x) => match crate::orchestration::quake::generated(x, &model, plan.seed, id) {
                    Ok(r) => Some(r.with_spectrum(plan.spectrum.clone())),
                    Err(_) => continue,
                },
                None => None,
            };
            let outcome = sim::run_sim(&sim_spec, own.as_ref().unwrap_or(&plan.references[e]))?;
            let path = dir.join(format!("sample{id}_{}.parquet", exc.name));
            let cols = outcome.history.named_columns();
            let mut meta = meta::header(Kind::TimeHistory);
            meta.extend([
                meta::pair(Key::Spec, sim_spec.resolved_toml()),
                meta::pair(Key::SampleId, id),
                meta::pair(Key::SchemaVersion, SCHEMA_VERSION),
            ]);
            tables::write_parquet(&path, &cols, &meta)?;
            writeln!(o, "  history     {}", path.display())?;
        }
    }
    Ok(())
}

/// A deterministic slice of a study's design: shard `index` of `count` runs the contiguous
/// samples [⌊index·S/count⌋, ⌊(index+1)·S/count⌋), so the shards in order are the whole run.
#[derive(Debug, Clone, PartialEq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
    pub range: std::ops::Range<usize>,
}

impl Shard {
    /// Parses `I/N` for a design of `samples` samples.
    pub fn parse(text: &str, samples: usize) -> anyhow::Result<Shard> {
        let bad =
            |why: String| -> anyhow::Error { BadInput(format!("--shard {text:?}: {why}")).into() };
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| bad("expected I/N, e.g. 0/4 (I from 0 to N-1)".into()))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| bad(format!("{i:?} is not a shard index")))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| bad(format!("{n:?} is not a shard count")))?;
        if count == 0 || index >= count {
            return Err(bad(format!(
                "the index must be in 0..{} (0 to N-1)",
                count.saturating_sub(1)
            )));
        }
        if count > samples {
            return Err(bad(format!(
                "{count} shards for a design of {samples} samples; at most {samples}"
            )));
        }
        Ok(Shard {
            index,
            count,
            range: (index * samples / count)..((index + 1) * samples / count),
        })
    }

    pub fn metadata(&self) -> Vec<(String, String)> {
        vec![
            meta::pair(Key::ShardIndex, self.index),
            meta::pair(Key::ShardCount, self.count),
            meta::pair(
                Key::ShardSamples,
                format!("{}..{}", self.range.start, self.range.end),
            ),
        ]
    }
}

/// Folder of the full histories requested by a study: `<out stem>_histories/`.
pub(crate) fn history_dir(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "results".into());
    out.with_file_name(format!("{stem}_histories"))
}
