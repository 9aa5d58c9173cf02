//! `study tune`: the controller gains that give the best fidelity on a test plan, chosen by
//! CMA-ES ([`crate::preparation::cmaes`]) on the virtual table.
//!
//! A candidate (one set of gains) runs every excitation of the plan on every uncertain draw: all
//! candidates × draws of a generation are the samples of one batch ([`Plan`]), run on every core;
//! lanes are independent, so a candidate's objective does not depend on the thread count, and the
//! search (seeded) gives the same gains bit for bit on any number of threads.
//!
//! - The objective of a candidate on one draw is Σ_e w_e Σ_m w_m e_m, where e_m is the metric as
//!   an error ([`error_term`]): |ln r| for a ratio whose ideal is 1, |φ| for a phase error, the
//!   value itself for the others (errors, distortion, spectral error). A metric that an
//!   excitation does not measure (NaN: a spectrum on a sine, a harmonic above Nyquist) is left
//!   out of its sum.
//! - Constraints: every run ends (the §3 guard: finite state, |y| < L, pressures in range) and
//!   max |u| ≤ `valve_cmd_fraction`·u_lim. A candidate that breaks one on any draw is infeasible:
//!   its objective is NaN, and it ranks after every feasible one, by how far it is off.
//! - Robustness: the objective over the draws (a Latin hypercube of the uncertain parameters) is
//!   their mean or a quantile ([`Statistic`]); the mean and the 90th percentile (or the chosen
//!   quantile) are reported for every candidate.

use crate::preparation::cmaes::Cmaes;
use crate::preparation::tune_journal::Stored;
use crate::preparation::tune_spec::{Statistic, TuneSpec};
use crate::study::batch::{DesignSource, Plan, Row, RowStatus};
use crate::study::problem::{Method, StudySpec, Variable};
use crate::study::sampling::{Design, Distribution, UnitDesign};
use rayon::prelude::*;
use std::ops::ControlFlow;
use vshake_kernel::excitation::Reference;
use vshake_kernel::params::ParamInfo;
use vshake_kernel::LANES;

/// Ratios whose ideal value is 1: their error is |ln r|.
pub const RATIOS_TO_ONE: [&str; 5] = [
    "amp_ratio",
    "disp_amp_ratio",
    "pga_ratio",
    "pgv_ratio",
    "pgd_ratio",
];
/// Phase errors (degrees): their error is |φ|.
pub const PHASES: [&str; 2] = ["phase_err_deg", "disp_phase_err_deg"];
/// Rank of an infeasible candidate: after every feasible objective, plus how far it is off.
const INFEASIBLE: f64 = 1e9;

/// A metric's value as an error to minimise (see the module doc).
pub fn error_term(metric: &str, value: f64) -> f64 {
    if RATIOS_TO_ONE.contains(&metric) {
        value.ln().abs()
    } else if PHASES.contains(&metric) {
        value.abs()
    } else {
        value
    }
}

/// The quantile q of `values` (linear between order statistics; NaN when any is NaN).
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() || values.iter().any(|v| v.is_nan()) {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let h = (v.len() - 1) as f64 * q;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(v.len() - 1);
    v[lo] + (h - lo as f64) * (v[hi] - v[lo])
}

/// One candidate's evaluation.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// 0 for the starting (published) gains, then the CMA-ES generation from 1.
    pub generation: usize,
    pub candidate: usize,
    pub gains: Vec<f64>,
    /// The objective on each draw (NaN where a constraint broke).
    pub per_draw: Vec<f64>,
    /// The tuning's statistic over the draws (NaN when infeasible).
    pub objective: f64,
    pub mean: f64,
    /// The reported quantile over the draws (the statistic's, or 0.9).
    pub quantile: f64,
    /// The key CMA-ES ranks by: the objective, or [`INFEASIBLE`] + the violation.
    pub rank: f64,
    /// The largest max |u| / u_lim over its runs.
    pub valve_fraction: f64,
    /// The first broken constraint; None when feasible.
    pub infeasible: Option<String>,
    /// Its runs: draw-major, excitation-minor.
    pub rows: Vec<Row>,
}

/// One generation in a line.
#[derive(Debug, Clone, Copy)]
pub struct GenerationSummary {
    pub generation: usize,
    pub evaluated: usize,
    pub feasible: usize,
    /// The best objective of this generation and of the run so far (NaN: none feasible).
    pub best: f64,
    pub best_so_far: f64,
    pub sigma: f64,
    pub spread: f64,
}

/// A finished tuning.
#[derive(Debug, Clone)]
pub struct Tuned {
    /// The starting gains' evaluation (generation 0).
    pub start: Evaluation,
    /// The best feasible evaluation (the start when nothing beat it).
    pub best: Evaluation,
    pub generations: Vec<GenerationSummary>,
    /// Every evaluation, in order.
    pub evaluations: Vec<Evaluation>,
    /// Why the search stopped.
    pub stopped: String,
    /// Whether `each` stopped it before its end (a signal): the search is not finished.
    pub interrupted: bool,
}

/// The study a tuning's runs are: its model, plan, spectrum and solver, the gains and the
/// uncertain parameters as its variables (the shell builds the references from it).
pub fn study_of(spec: &TuneSpec) -> StudySpec {
    let gains = spec.gains.iter().map(|g| Variable {
        info: g.info,
        dist: Distribution::Uniform {
            low: g.low,
            high: g.high,
        },
    });
    StudySpec {
        name: spec.name.clone(),
        description: spec.description.clone(),
        seed: spec.seed,
        samples: 0,
        method: Method::MonteCarlo,
        model: spec.model.clone(),
        variables: gains.chain(spec.uncertain.iter().cloned()).collect(),
        excitations: spec.excitations.clone(),
        metrics: crate::study::problem::all_metric_names(),
        spectrum: spec.spectrum.clone(),
        output: spec.output.join("evaluations.parquet"),
        histories: Vec::new(),
        solver: spec.solver,
        chunk: LANES,
        notes: Vec::new(),
    }
}

/// The uncertain parameters' values of each draw: a Latin hypercube of the seed (one empty draw
/// without uncertain parameters).
pub fn draws(spec: &TuneSpec) -> Vec<Vec<f64>> {
    if spec.uncertain.is_empty() {
        return vec![Vec::new()];
    }
    let d = UnitDesign::new(
        Design::LatinHypercube,
        spec.uncertain.len(),
        spec.draws,
        spec.seed,
    );
    let mut u = vec![0.0; spec.uncertain.len()];
    (0..spec.draws)
        .map(|k| {
            d.point(k, &mut u);
            spec.uncertain
                .iter()
                .zip(&u)
                .map(|(v, x)| v.dist.quantile(*x))
                .collect()
        })
        .collect()
}

/// A journal whose generation's candidates are not those the search asks for: another tuning's
/// (the tuning file, the model or the build changed, or the journal was edited).
#[derive(Debug, thiserror::Error)]
#[error("generation {generation} is not this tuning's: its candidates differ from the search's (the tuning file, the model or the build changed since it was written)")]
pub struct NotThisTuning {
    pub generation: usize,
}

/// Runs a tuning: the plan's batches and the search.
pub struct Tuner {
    pub spec: TuneSpec,
    plan: Plan,
    pub draws: Vec<Vec<f64>>,
    /// Generations of an interrupted tuning ([`Tuner::resume`]), taken instead of running them.
    replay: std::collections::VecDeque<Vec<Stored>>,
}

impl Tuner {
    /// A tuner on the references of [`study_of`]'s excitations.
    pub fn new(spec: TuneSpec, references: Vec<Reference>) -> Self {
        let study = study_of(&spec);
        let columns: Vec<&'static ParamInfo> = study.variables.iter().map(|v| v.info).collect();
        let plan = Plan::from_table(&study, columns, Vec::new(), references);
        Tuner {
            draws: draws(&spec),
            spec,
            plan,
            replay: Default::default(),
        }
    }

    /// Continue an interrupted tuning: its journal's generations are judged again from their
    /// stored runs (checked against the candidates the search asks for), not run.
    pub fn resume(&mut self, generations: Vec<Vec<Stored>>) {
        self.replay = generations.into();
    }

    /// The stored generation `generation`'s evaluations, when it is the next to replay; `Err`
    /// when its candidates are not `candidates` (the journal is another tuning's).
    fn replayed(
        &mut self,
        generation: usize,
        candidates: &[Vec<f64>],
    ) -> anyhow::Result<Option<Vec<Evaluation>>> {
        let Some(stored) = self.replay.pop_front() else {
            return Ok(None);
        };
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let same = stored.len() == candidates.len()
            && stored.iter().zip(candidates).all(|(s, c)| {
                s.generation == generation
                    && bits(&s.gains) == bits(c)
                    && s.rows.len() == self.draws.len() * self.spec.excitations.len()
            });
        if !same {
            return Err(NotThisTuning { generation }.into());
        }
        Ok(Some(
            stored
                .into_iter()
                .map(|s| self.judge(generation, s.candidate, s.gains, s.rows))
                .collect(),
        ))
    }

    /// Whether the runs may carry a building (then the specimen's metrics are written).
    pub fn carries_building(&self) -> bool {
        crate::study::problem::carries_building(&self.spec.model, &self.spec.uncertain)
    }

    /// The parameters written beside each run: the gains, then the uncertain ones.
    pub fn columns(&self) -> &[&'static ParamInfo] {
        &self.plan.columns
    }

    /// The quantile reported for every candidate.
    pub fn reported_quantile(&self) -> f64 {
        match self.spec.statistic {
            Statistic::Quantile(q) => q,
            Statistic::Mean => 0.9,
        }
    }

    /// Evaluates `candidates` (gain vectors) on every draw and excitation, as one batch on the
    /// current rayon pool; `Err` only when the engine fails.
    pub fn evaluate(
        &mut self,
        generation: usize,
        candidates: &[Vec<f64>],
    ) -> anyhow::Result<Vec<Evaluation>> {
        if let Some(done) = self.replayed(generation, candidates)? {
            return Ok(done);
        }
        let n_d = self.draws.len();
        let rows: Vec<Vec<f64>> = candidates
            .iter()
            .flat_map(|c| {
                self.draws
                    .iter()
                    .map(move |d| c.iter().chain(d).copied().collect())
            })
            .collect();
        self.plan.design = DesignSource::Table(rows);
        let ids: Vec<usize> = (0..candidates.len() * n_d).collect();
        let plan = &self.plan;
        // Groups of at most LANES, small enough to keep every thread busy (lanes are independent,
        // so the grouping does not change a result).
        let group = ids
            .len()
            .div_ceil(rayon::current_num_threads())
            .clamp(1, LANES);
        let chunks: Vec<anyhow::Result<Vec<Row>>> = ids
            .par_chunks(group)
            .map(|c| plan.run_samples(c.iter().copied()))
            .collect();
        let mut all: Vec<Row> = Vec::with_capacity(ids.len() * self.spec.excitations.len());
        for c in chunks {
            all.extend(c?);
        }
        let per = n_d * self.spec.excitations.len();
        Ok(candidates
            .iter()
            .enumerate()
            .map(|(i, g)| {
                let rows = all[i * per..(i + 1) * per].to_vec();
                self.judge(generation, i, g.clone(), rows)
            })
            .collect())
    }

    /// A candidate's objective per draw, its statistic and its constraints, from its runs.
    fn judge(
        &self,
        generation: usize,
        candidate: usize,
        gains: Vec<f64>,
        rows: Vec<Row>,
    ) -> Evaluation {
        let spec = &self.spec;
        let n_e = spec.excitations.len();
        let u_lim = spec.model.servovalve.u_lim;
        let (mut violation, mut valve, mut why) = (0.0, 0.0f64, None::<String>);
        let mut per_draw = Vec::with_capacity(self.draws.len());
        for (d, runs) in rows.chunks(n_e).enumerate() {
            let (mut j, mut ok) = (0.0, true);
            for (e, r) in runs.iter().enumerate() {
                let name = &spec.excitations[e].name;
                let frac = r.metrics.max_abs_u_v / u_lim;
                valve = valve.max(frac);
                if r.status != RowStatus::Ok {
                    ok = false;
                    violation += 1.0;
                    let detail = r.status.detail().unwrap_or_default();
                    why.get_or_insert(format!(
                        "{} on {name}, draw {d}: {detail}",
                        r.status.label()
                    ));
                } else if frac > spec.valve_cmd_fraction {
                    ok = false;
                    violation += frac - spec.valve_cmd_fraction;
                    why.get_or_insert(format!(
                        "valve command {:.1} % of u_lim on {name}, draw {d} (limit {:.1} %)",
                        100.0 * frac,
                        100.0 * spec.valve_cmd_fraction
                    ));
                }
                j += spec.weights[e] * weighted_errors(&spec.objective, r);
            }
            per_draw.push(if ok { j } else { f64::NAN });
        }
        let mean = per_draw.iter().sum::<f64>() / per_draw.len() as f64;
        let q = quantile(&per_draw, self.reported_quantile());
        let objective = match spec.statistic {
            Statistic::Mean => mean,
            Statistic::Quantile(_) => q,
        };
        let rank = match &why {
            None if objective.is_finite() => objective,
            _ => INFEASIBLE + violation,
        };
        Evaluation {
            generation,
            candidate,
            gains,
            per_draw,
            objective: if why.is_none() { objective } else { f64::NAN },
            mean,
            quantile: q,
            rank,
            valve_fraction: valve,
            infeasible: why,
            rows,
        }
    }

    /// The search from the starting gains: generation 0 is the start, then CMA-ES until the
    /// spread falls below the tolerance or the generation limit; `each` sees every generation
    /// (replayed ones included) and may stop the search after it ([`Tuned::interrupted`]).
    pub fn run(
        &mut self,
        mut each: impl FnMut(&GenerationSummary, &[Evaluation]) -> ControlFlow<()>,
    ) -> anyhow::Result<Tuned> {
        let s = self.spec.search;
        let (lo, hi): (Vec<f64>, Vec<f64>) =
            self.spec.gains.iter().map(|g| (g.low, g.high)).unzip();
        let mut es = Cmaes::new(
            &self.spec.start(),
            &lo,
            &hi,
            s.sigma0,
            s.population,
            self.spec.seed,
        )?;
        let start = self.evaluate(0, &[self.spec.start()])?.remove(0);
        let mut best = start.clone();
        let mut evaluations = vec![start.clone()];
        let mut generations = Vec::new();
        let summary0 = summary(0, std::slice::from_ref(&start), &best, &es);
        let mut flow = each(&summary0, std::slice::from_ref(&start));
        generations.push(summary0);
        while flow.is_continue() && es.generation() < s.generations && es.spread() > s.tolerance {
            let x = es.ask();
            let evals = self.evaluate(es.generation() + 1, &x)?;
            es.tell(&x, &evals.iter().map(|e| e.rank).collect::<Vec<_>>());
            for e in &evals {
                if e.rank < best.rank {
                    best = e.clone();
                }
            }
            let line = summary(es.generation(), &evals, &best, &es);
            flow = each(&line, &evals);
            generations.push(line);
            evaluations.extend(evals);
        }
        let interrupted = flow.is_break();
        let stopped = if interrupted {
            format!("stopped after generation {}", es.generation())
        } else if es.spread() <= s.tolerance {
            format!("the search spread fell below {} of the ranges", s.tolerance)
        } else {
            format!("the generation limit ({})", s.generations)
        };
        Ok(Tuned {
            start,
            best,
            generations,
            evaluations,
            stopped,
            interrupted,
        })
    }
}

/// Σ_m w_m e_m of one run (metrics it does not measure left out).
fn weighted_errors(objective: &[(&'static str, f64)], r: &Row) -> f64 {
    let cols = r.metrics.columns();
    objective
        .iter()
        .filter_map(|(m, w)| {
            let v = cols.iter().find(|(n, _)| n == m)?.1;
            (!v.is_nan()).then(|| w * error_term(m, v))
        })
        .sum()
}

fn summary(
    generation: usize,
    evals: &[Evaluation],
    best: &Evaluation,
    es: &Cmaes,
) -> GenerationSummary {
    let feasible: Vec<f64> = evals
        .iter()
        .map(|e| e.objective)
        .filter(|v| v.is_finite())
        .collect();
    GenerationSummary {
        generation,
        evaluated: evals.len(),
        feasible: feasible.len(),
        best: feasible.iter().copied().fold(f64::NAN, f64::min),
        best_so_far: best.objective,
        sigma: es.sigma(),
        spread: es.spread(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_interpolates_between_order_statistics() {
        let v = [4.0, 1.0, 3.0, 2.0, 5.0];
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 0.9), 4.6);
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert!(quantile(&[1.0, f64::NAN], 0.5).is_nan());
    }

    #[test]
    fn error_terms_measure_distance_from_ideal() {
        assert!((error_term("pga_ratio", 0.5) - 2f64.ln()).abs() < 1e-15);
        assert_eq!(error_term("pga_ratio", 2.0), error_term("pga_ratio", 0.5));
        assert_eq!(error_term("phase_err_deg", -3.0), 3.0);
        assert_eq!(error_term("spectral_err_mean", 0.25), 0.25);
    }
}
