//! The batch engine: a study's samples through the lane kernel, in parallel, streamed in order.
//!
//! - A sample's parameters depend only on (seed, sample id) ([`Plan::sample`]).
//! - A chunk of consecutive samples is one work item: its samples are run in groups of
//!   [`LANES`] through the kernel for every excitation; lanes are independent (bit for bit), so a
//!   sample's row does not depend on its neighbours, the chunk size or the thread count.
//! - Chunks are processed in waves: a wave runs in parallel on the rayon pool, and its rows go to
//!   the [`RowSink`] in sample order before the next wave starts, so memory stays flat however
//!   many samples a study has.
//! - A sample whose parameters are invalid (e.g. a normal draw giving a negative mass) or whose run
//!   fails is a row with its status, time and reason; the study goes on.

use crate::runs::spec::ExcitationSpec;
use crate::study::problem::{Method, StudySpec};
use crate::study::sampling::{saltelli_block, Design, UnitDesign};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;
use vshake_kernel::excitation::Reference;
use vshake_kernel::metrics::Metrics;
use vshake_kernel::params::{ModelParams, ParamInfo};
use vshake_kernel::simulate::{self, Failure, LaneResult, LaneStatus, SetupError};
use vshake_kernel::spectrum::SpectrumSpec;
use vshake_kernel::LANES;

/// An engine that runs any number of lanes at once, on one reference or one per lane (the CUDA
/// kernel of `shell::gpu`): set on a plan ([`Plan::engine`]), it takes the CPU lane kernel's
/// place. Only what [`Plan::engine_unsupported`] allows reaches it.
pub trait LaneEngine: Send + Sync {
    /// A result per model on `refs` (one reference for every model, or one per model), or the
    /// setup error of the whole group; `Err` is a device failure, which ends the run.
    fn run(
        &self,
        models: &[&ModelParams],
        refs: &[&Reference],
        solver: &simulate::Solver,
    ) -> anyhow::Result<Result<Vec<LaneResult>, SetupError>>;
}

/// Where the sample points come from.
#[derive(Debug, Clone)]
pub enum DesignSource {
    Generated(UnitDesign),
    /// Rows read from a design file, one value per column of `Plan::columns`.
    Table(Vec<Vec<f64>>),
}

/// Everything needed to compute any sample's row: shared read-only by every thread.
pub struct Plan {
    pub base: ModelParams,
    /// The parameters written as columns: the study's variables (fixed ones too), or a design
    /// file's columns.
    pub columns: Vec<&'static ParamInfo>,
    /// For generated designs: which design dimension drives each column (None = fixed value).
    dims: Vec<Option<usize>>,
    fixed: Vec<f64>,
    dists: Vec<crate::study::sampling::Distribution>,
    pub design: DesignSource,
    pub references: Vec<Reference>,
    /// Per excitation: its spec when its reference depends on the sample (a stochastic motion
    /// with a realisation per sample or sampled `ground.*`), made for each sample by
    /// [`crate::runs::quake::generated`] from (seed, sample id); `references[e]` is then unused.
    pub per_sample: Vec<Option<ExcitationSpec>>,
    /// The study's seed (the excitation noise's, [`crate::runs::quake`]) and response spectrum.
    pub seed: u64,
    pub spectrum: SpectrumSpec,
    pub solver: simulate::Solver,
    pub saltelli_dims: Option<usize>,
    /// The engine that runs the lanes instead of the CPU kernel (None: the CPU kernel).
    pub engine: Option<Arc<dyn LaneEngine>>,
}

/// Which excitations of `spec` need a reference per sample, given the varied parameter paths.
fn per_sample(spec: &StudySpec, varied: &[String]) -> Vec<Option<ExcitationSpec>> {
    spec.excitations
        .iter()
        .map(|e| {
            e.spec
                .per_sample(|p| varied.iter().any(|v| v == p))
                .then(|| e.spec.clone())
        })
        .collect()
}

/// Status of one row.
#[derive(Debug, Clone, PartialEq)]
pub enum RowStatus {
    Ok,
    /// The run failed (diverged, stroke or pressure limit) at a time.
    Failed {
        time_s: f64,
        failure: Failure,
    },
    /// The sample could not be run: its parameters are outside their valid ranges
    /// ([`INVALID_PARAMETERS`]), its own motion could not be made ([`INVALID_MOTION`]), or its
    /// group could not be set up ([`INVALID_SETUP`]).
    Invalid {
        category: &'static str,
        reason: String,
    },
}

/// `fail_reason` of a sample whose parameters are outside their valid ranges.
pub const INVALID_PARAMETERS: &str = "invalid_parameters";
/// `fail_reason` of a sample whose own ground motion could not be generated.
pub const INVALID_MOTION: &str = "invalid_motion";
/// `fail_reason` of a group of lanes the kernel could not set up.
pub const INVALID_SETUP: &str = "invalid_setup";

impl RowStatus {
    pub fn label(&self) -> &'static str {
        match self {
            RowStatus::Ok => "ok",
            RowStatus::Failed { .. } => "failed",
            RowStatus::Invalid { .. } => "invalid",
        }
    }
    /// A fixed category to group on: the guard that stopped the run (`diverged`,
    /// `stroke_limit`, `pressure_limit`) or why it was not run; None for a run that ended.
    pub fn category(&self) -> Option<&'static str> {
        match self {
            RowStatus::Ok => None,
            RowStatus::Failed { failure, .. } => Some(failure.category()),
            RowStatus::Invalid { category, .. } => Some(category),
        }
    }
    /// The value that left its bound, SI (see [`Failure::value`]).
    pub fn value(&self) -> Option<f64> {
        match self {
            RowStatus::Failed { failure, .. } => failure.value(),
            _ => None,
        }
    }
    /// What happened, in words.
    pub fn detail(&self) -> Option<String> {
        match self {
            RowStatus::Ok => None,
            RowStatus::Failed { failure, .. } => Some(failure.to_string()),
            RowStatus::Invalid { reason, .. } => Some(reason.clone()),
        }
    }
}

/// One row of the results: one sample × one excitation.
#[derive(Debug, Clone)]
pub struct Row {
    pub sample_id: u64,
    pub excitation: u32,
    /// Saltelli design: (base point, block 0 = A, 1 = B, 2 + i = AB_i).
    pub saltelli: Option<(u32, u32)>,
    pub values: Vec<f64>,
    pub status: RowStatus,
    pub metrics: Metrics,
}

/// A sample's parameter values and model (or why the model is invalid).
pub struct Sample {
    pub id: u64,
    pub values: Vec<f64>,
    pub model: Result<ModelParams, String>,
}

impl Plan {
    /// A plan for a study whose design is generated (not `Method::File`).
    pub fn generated(spec: &StudySpec, references: Vec<Reference>) -> Plan {
        let varied = spec.varied();
        let design = UnitDesign::new(spec.design(), varied.len(), spec.samples, spec.seed);
        let mut dims = Vec::new();
        let mut next = 0;
        for v in &spec.variables {
            if v.dist.varies() {
                dims.push(Some(next));
                next += 1;
            } else {
                dims.push(None);
            }
        }
        Plan {
            base: spec.model.clone(),
            columns: spec.variables.iter().map(|v| v.info).collect(),
            dims,
            fixed: spec
                .variables
                .iter()
                .map(|v| v.dist.quantile(0.5))
                .collect(),
            dists: spec.variables.iter().map(|v| v.dist.clone()).collect(),
            saltelli_dims: matches!(spec.method, Method::Saltelli).then_some(varied.len()),
            design: DesignSource::Generated(design),
            references,
            per_sample: per_sample(
                spec,
                &spec
                    .varied()
                    .iter()
                    .map(|v| v.info.path())
                    .collect::<Vec<_>>(),
            ),
            seed: spec.seed,
            spectrum: spec.spectrum.clone(),
            solver: spec.solver,
            engine: None,
        }
    }

    /// A plan whose samples are the rows of a design table.
    pub fn from_table(
        spec: &StudySpec,
        columns: Vec<&'static ParamInfo>,
        rows: Vec<Vec<f64>>,
        references: Vec<Reference>,
    ) -> Plan {
        Plan {
            base: spec.model.clone(),
            dims: (0..columns.len()).map(Some).collect(),
            fixed: vec![f64::NAN; columns.len()],
            dists: Vec::new(),
            per_sample: per_sample(spec, &columns.iter().map(|c| c.path()).collect::<Vec<_>>()),
            seed: spec.seed,
            spectrum: spec.spectrum.clone(),
            columns,
            design: DesignSource::Table(rows),
            references,
            solver: spec.solver,
            saltelli_dims: None,
            engine: None,
        }
    }

    /// Number of samples.
    pub fn samples(&self) -> usize {
        match &self.design {
            DesignSource::Generated(d) => d.samples,
            DesignSource::Table(rows) => rows.len(),
        }
    }

    /// Number of rows (samples × excitations).
    pub fn rows(&self) -> usize {
        self.samples() * self.references.len()
    }

    /// The parameters of sample `id`: a function of (seed, id) only.
    pub fn sample(&self, id: usize) -> Sample {
        let values: Vec<f64> = match &self.design {
            DesignSource::Table(rows) => rows[id].clone(),
            DesignSource::Generated(d) => {
                let mut vals = self.fixed.clone();
                if let Design::Grid { values } = &d.design {
                    let mut idx = vec![0; d.dims];
                    d.grid_index(id, &mut idx);
                    for (c, dim) in self.dims.iter().enumerate() {
                        if let Some(j) = dim {
                            vals[c] = values[*j][idx[*j]];
                        }
                    }
                } else {
                    let mut u = vec![0.0; d.dims];
                    d.point(id, &mut u);
                    for (c, dim) in self.dims.iter().enumerate() {
                        if let Some(j) = dim {
                            vals[c] = self.dists[c].quantile(u[*j]);
                        }
                    }
                }
                vals
            }
        };
        let mut model = self.base.clone();
        for (info, v) in self.columns.iter().zip(&values) {
            info.set(&mut model, *v);
        }
        let model = model.validate().map(|_| model).map_err(|list| {
            list.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join("; ")
        });
        Sample {
            id: id as u64,
            values,
            model,
        }
    }

    /// Why the CUDA kernel cannot run this plan (an effect, too long a spectrum), naming the
    /// excitation; `None` when it can.
    pub fn engine_unsupported(&self, names: &[String]) -> Option<String> {
        for (e, r) in self.references.iter().enumerate() {
            let name = names.get(e).map_or("?", |n| n.as_str());
            if let Some(why) = vshake_kernel::gpu_lanes::unsupported(&[&self.base], r) {
                return Some(format!("excitation `{name}`: {why}"));
            }
        }
        None
    }

    /// Runs samples `range` for every excitation: rows in (sample, excitation) order; `Err` only
    /// when the engine's device fails.
    pub(crate) fn run_chunk(&self, range: Range<usize>) -> anyhow::Result<Vec<Row>> {
        self.run_samples(range)
    }

    /// Runs the samples `ids` for every excitation: rows in (sample, excitation) order.
    pub fn run_samples(&self, ids: impl IntoIterator<Item = usize>) -> anyhow::Result<Vec<Row>> {
        let samples: Vec<Sample> = ids.into_iter().map(|i| self.sample(i)).collect();
        let n_exc = self.references.len();
        let mut rows: Vec<Option<Row>> = vec![None; samples.len() * n_exc];
        let valid: Vec<usize> = (0..samples.len())
            .filter(|&i| samples[i].model.is_ok())
            .collect();
        for (e, reference) in self.references.iter().enumerate() {
            let of_e = self.run_excitation(e, reference, &samples, &valid)?;
            for (i, row) in of_e.into_iter().enumerate() {
                rows[i * n_exc + e] = row;
            }
        }
        Ok(rows
            .into_iter()
            .map(|r| r.expect("every row filled"))
            .collect())
    }

    /// The rows of excitation `e` (its `reference`, unless the samples make their own), one per
    /// sample: the valid samples run in groups of [`LANES`], the others say why they did not.
    fn run_excitation(
        &self,
        e: usize,
        reference: &Reference,
        samples: &[Sample],
        valid: &[usize],
    ) -> anyhow::Result<Vec<Option<Row>>> {
        let mut rows: Vec<Option<Row>> = vec![None; samples.len()];
        let (own, runnable) = self.own_references(e, samples, valid, &mut rows);
        if let Some(engine) = &self.engine {
            let models: Vec<&ModelParams> = runnable
                .iter()
                .map(|&i| samples[i].model.as_ref().expect("valid"))
                .collect();
            let refs: Vec<&Reference> = match self.per_sample[e] {
                Some(_) => runnable
                    .iter()
                    .map(|&i| own[i].as_ref().expect("made"))
                    .collect(),
                None => vec![reference],
            };
            if !models.is_empty() {
                let results = engine.run(&models, &refs, &self.solver)?;
                for (lane, &i) in runnable.iter().enumerate() {
                    let (status, metrics) = lane_outcome(results.as_deref(), lane);
                    rows[i] = Some(self.row(&samples[i], e, status, metrics));
                }
            }
        }
        let on_cpu = if self.engine.is_some() {
            &[][..]
        } else {
            &runnable[..]
        };
        for group in on_cpu.chunks(LANES) {
            let models: Vec<&ModelParams> = group
                .iter()
                .map(|&i| samples[i].model.as_ref().expect("valid"))
                .collect();
            let refs: Vec<&Reference> = group
                .iter()
                .map(|&i| own[i].as_ref().unwrap_or(reference))
                .collect();
            // Lanes without effects give the same bits in the effect set (it is neutral
            // there), and a lane's reference is its own, so the kernel `run_group` chooses
            // per group does not make a row depend on its neighbours.
            let results = crate::runs::single::run_group(&models, &refs, &self.solver);
            for (lane, &i) in group.iter().enumerate() {
                let (status, metrics) = lane_outcome(results.as_deref(), lane);
                rows[i] = Some(self.row(&samples[i], e, status, metrics));
            }
        }
        for s in samples.iter().enumerate().filter(|(_, s)| s.model.is_err()) {
            let (i, s) = s;
            let reason = s.model.as_ref().err().cloned().unwrap_or_default();
            let status = RowStatus::Invalid {
                category: INVALID_PARAMETERS,
                reason,
            };
            rows[i] = Some(self.row(s, e, status, Metrics::NAN));
        }
        Ok(rows)
    }

    /// The lanes' references for excitation `e`: the excitation's (None), or each valid
    /// sample's own, and the samples that can run; a sample whose own motion cannot run gets
    /// the row that says why.
    fn own_references(
        &self,
        e: usize,
        samples: &[Sample],
        valid: &[usize],
        rows: &mut [Option<Row>],
    ) -> (Vec<Option<Reference>>, Vec<usize>) {
        let mut own: Vec<Option<Reference>> = vec![None; samples.len()];
        let Some(exc) = &self.per_sample[e] else {
            return (own, valid.to_vec());
        };
        let mut runnable = Vec::new();
        for &i in valid {
            let s = &samples[i];
            match crate::runs::quake::generated(
                exc,
                s.model.as_ref().expect("valid"),
                self.seed,
                s.id,
            ) {
                Ok(r) => {
                    own[i] = Some(r.with_spectrum(self.spectrum.clone()));
                    runnable.push(i);
                }
                Err(reason) => {
                    let status = RowStatus::Invalid {
                        category: INVALID_MOTION,
                        reason,
                    };
                    rows[i] = Some(self.row(s, e, status, Metrics::NAN));
                }
            }
        }
        (own, runnable)
    }

    /// The row of sample `s` and excitation `e`.
    fn row(&self, s: &Sample, e: usize, status: RowStatus, metrics: Metrics) -> Row {
        Row {
            sample_id: s.id,
            excitation: e as u32,
            saltelli: self.saltelli_dims.map(|d| {
                let (b, k) = saltelli_block(s.id as usize, d);
                (b as u32, k as u32)
            }),
            values: s.values.clone(),
            status,
            metrics,
        }
    }
}

/// A lane's status and metrics (NaN unless it ran to the end), or why its group could not run.
fn lane_outcome(results: Result<&[LaneResult], &SetupError>, lane: usize) -> (RowStatus, Metrics) {
    match results {
        Ok(r) => match r[lane].status {
            LaneStatus::Ok => (RowStatus::Ok, r[lane].metrics),
            LaneStatus::Failed { time_s, reason } => (
                RowStatus::Failed {
                    time_s,
                    failure: reason,
                },
                Metrics::NAN,
            ),
        },
        Err(e) => (
            RowStatus::Invalid {
                category: INVALID_SETUP,
                reason: e.to_string(),
            },
            Metrics::NAN,
        ),
    }
}

/// Receives rows in sample order.
pub trait RowSink {
    fn write(&mut self, rows: &[Row]) -> anyhow::Result<()>;
}

impl RowSink for Vec<Row> {
    fn write(&mut self, rows: &[Row]) -> anyhow::Result<()> {
        self.extend_from_slice(rows);
        Ok(())
    }
}

/// A short timed run of samples spread evenly over a range, to size a run before it starts.
#[derive(Debug, Clone)]
pub struct Timing {
    /// Samples in the timed round.
    pub samples: usize,
    /// Wall seconds of the timed round (every thread of the pool busy).
    pub secs: f64,
    /// The round's rows (e.g. to measure their size on disk).
    pub rows: Vec<Row>,
}

impl Timing {
    /// Estimated wall seconds for `samples` samples.
    pub fn wall_s(&self, samples: usize) -> f64 {
        self.secs / self.samples.max(1) as f64 * samples as f64
    }
}

/// Times rounds of samples spread evenly over `range` (each round twice the last, starting at
/// two groups of [`LANES`] per thread), until a round takes `round` or covers the range; the
/// last round is the measure (the first ones warm the threads and caches up). Failing samples end
/// early in a real run too, so spreading the samples over the design weighs them as the run will.
pub fn time_round(
    plan: &Plan,
    range: Range<usize>,
    pool: &rayon::ThreadPool,
    round: std::time::Duration,
) -> anyhow::Result<Timing> {
    let len = range.len();
    let mut n = (2 * LANES * pool.current_num_threads()).min(len).max(1);
    loop {
        // Offset by half a stride, so that a round does not start on the range's first sample only.
        let ids: Vec<usize> = (0..n)
            .map(|i| range.start + ((2 * i + 1) * len) / (2 * n))
            .collect();
        let t = std::time::Instant::now();
        let group = if plan.engine.is_some() { n } else { LANES };
        let rows: Vec<Vec<Row>> = pool.install(|| {
            ids.par_chunks(group)
                .map(|g| plan.run_samples(g.iter().copied()))
                .collect::<anyhow::Result<_>>()
        })?;
        let rows = rows.concat();
        let secs = t.elapsed().as_secs_f64();
        if secs >= round.as_secs_f64() || n >= len {
            return Ok(Timing {
                samples: n,
                secs,
                rows,
            });
        }
        n = (2 * n).min(len);
    }
}

/// Counts of a finished (or stopped) run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Summary {
    pub rows: usize,
    pub ok: usize,
    pub failed: usize,
    pub invalid: usize,
    /// The first sample not written: the range's end unless the run was stopped.
    pub next: usize,
    /// Whether `stop` ended the run before the range's end.
    pub stopped: bool,
}

impl Summary {
    fn count(&mut self, rows: &[Row]) {
        for r in rows {
            self.rows += 1;
            match r.status {
                RowStatus::Ok => self.ok += 1,
                RowStatus::Failed { .. } => self.failed += 1,
                RowStatus::Invalid { .. } => self.invalid += 1,
            }
        }
    }
}

/// Runs samples `range` of a plan on `pool` in chunks of `chunk` samples, sending rows to `sink`
/// in order. `progress(rows_done)` is called from worker threads as chunks finish.
///
/// `stop()` is asked before each chunk starts: once it says yes, chunks in flight finish, the
/// rows of every chunk before the first one not run go to the sink, and the run returns with
/// `stopped` and the first sample not written (`next`), from which a later run continues.
pub fn run_plan(
    plan: &Plan,
    range: Range<usize>,
    pool: &rayon::ThreadPool,
    chunk: usize,
    sink: &mut dyn RowSink,
    progress: &(dyn Fn(usize) + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> anyhow::Result<Summary> {
    let chunk = chunk.max(1);
    let wave = (pool.current_num_threads() * 4).max(1);
    let mut summary = Summary {
        next: range.start,
        ..Summary::default()
    };
    while summary.next < range.end {
        let starts: Vec<usize> = (summary.next..range.end)
            .step_by(chunk)
            .take(wave)
            .collect();
        let results: Vec<Option<anyhow::Result<Vec<Row>>>> = pool.install(|| {
            starts
                .par_iter()
                .map(|&s| {
                    if stop() {
                        return None;
                    }
                    let rows = plan.run_chunk(s..(s + chunk).min(range.end));
                    progress(rows.as_ref().map_or(0, |r| r.len()));
                    Some(rows)
                })
                .collect()
        });
        for (rows, &s) in results.into_iter().zip(&starts) {
            let Some(rows) = rows else {
                summary.stopped = true;
                return Ok(summary);
            };
            let rows = rows?;
            summary.count(&rows);
            sink.write(&rows)?;
            summary.next = (s + chunk).min(range.end);
        }
        if stop() && summary.next < range.end {
            summary.stopped = true;
            return Ok(summary);
        }
    }
    Ok(summary)
}
