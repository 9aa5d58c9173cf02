//! A study as a job: the study file read and planned, where its table goes (and what may stand
//! there already), the sink that streams its rows to Parquet with checkpoints, the thread pool,
//! shards of its design and the folder of its histories. Used by `study run`, `study slurm`,
//! `--resume`, `--dry-run`, and the commands that run work on a pool.

use crate::kernel::params::{ModelParams, ParamInfo};
use crate::orchestration::study::batch::{Plan, Row, RowSink, RowStatus};
use crate::orchestration::study::problem::{cannot_vary, Method, StudySpec};
use crate::shell::cli::RunArgs;
use crate::shell::formats::input;
use crate::shell::formats::measured_files;
use crate::shell::formats::measured_files::input_if_user;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_read;
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::{Column, ParquetStream};
use crate::shell::job::outputs::{check_output, check_replaceable, OutputLock};
use crate::shell::run_spec::load_reference;
use crate::shell::BadInput;
use anyhow::Context;
use arrow_array::{Array, UInt64Array};
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
    let base = crate::shell::formats::campaign_io::load_model(model)?;
    let text = input::read_input_text(file)
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
            let names = measured_files::column_names(&path).map_err(input_if_user)?;
            let wanted: Vec<&str> = names.iter().map(String::as_str).collect();
            let t = measured_files::read_columns(&path, &wanted, &[]).map_err(input_if_user)?;
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
    let names = measured_files::column_names(path).map_err(input_if_user)?;
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
        let n_ = measured_files::clip(n, 60);
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
    pub kept: Option<Kept>,
    /// The table's lock, held until the job is dropped: one writer at a time (none for a dry
    /// run).
    #[allow(dead_code)] // held, never read
    pub(crate) lock: Option<OutputLock>,
}

impl Job {
    /// A new run of `args.file`: everything it needs is read and checked here, before any work.
    pub(crate) fn fresh(args: &RunArgs, file: &Path) -> anyhow::Result<Job> {
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

    pub(crate) fn samples_kept(&self) -> usize {
        self.kept.as_ref().map_or(0, |k| k.samples)
    }

    pub(crate) fn rows_total(&self) -> usize {
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
    check_output(&parquet_write::partial_path(&out))?;
    check_writable(&out)?;
    let lock = lock.then(|| OutputLock::acquire(&out)).transpose()?;
    check_no_interrupted_run(&out)?;
    check_replaceable(&out)?;
    Ok((out, lock))
}

/// A new run may replace a table vshake wrote ([`check_replaceable`]), never the rows of an
/// interrupted run of it (those are `--resume`'s).
fn check_no_interrupted_run(out: &Path) -> anyhow::Result<()> {
    let partial = parquet_write::partial_path(out);
    let left: Vec<String> = [
        partial.clone(),
        parquet_write::killed_path(&partial),
        parquet_write::tmp_path(&partial),
        parquet_write::checkpoint_path(&partial),
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

/// Rows of an interrupted run carried into the resumed one: its first `samples` samples.
pub struct Kept {
    pub source: PathBuf,
    pub samples: usize,
    /// The source is a file recovered from a killed run (`FILE.killed`), removed once its rows
    /// are safe in the new file.
    pub(crate) temporary: bool,
}

impl Kept {
    /// Copies the kept rows into `sink`, checking that they are the slice's first samples.
    pub(crate) fn copy_into(&self, sink: &mut ResultsSink, job: &Job) -> anyhow::Result<()> {
        let n_exc = job.plan.references.len();
        let mut left = self.samples * n_exc;
        let (_, reader) = parquet_read::parquet_batches(&self.source).map_err(input_if_user)?;
        let mut expect = job.range.start as u64;
        let mut in_sample = 0;
        for batch in reader {
            let batch = batch.with_context(|| format!("reading {}", self.source.display()))?;
            let batch = batch.slice(0, batch.num_rows().min(left));
            let ids = batch
                .column_by_name("sample_id")
                .and_then(|c| c.as_any().downcast_ref::<UInt64Array>())
                .ok_or_else(|| {
                    BadInput(format!("{}: no sample_id column", self.source.display()))
                })?;
            for id in ids.values().iter() {
                if *id != expect {
                    return Err(BadInput(format!("{}: row of sample {id} where sample {expect} was expected: not the rows of this study's run", self.source.display())).into());
                }
                in_sample += 1;
                if in_sample == n_exc {
                    (expect, in_sample) = (expect + 1, 0);
                }
            }
            left -= batch.num_rows();
            sink.write_batch(&batch)?;
            if left == 0 {
                break;
            }
        }
        Ok(())
    }

    /// Removes a recovered file once the new file holds its rows.
    pub(crate) fn discard(&self) {
        if self.temporary {
            let _ = std::fs::remove_file(&self.source);
        }
    }
}
