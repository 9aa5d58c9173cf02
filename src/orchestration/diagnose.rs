//! Diagnosis: which physical effect is most likely missing from the model.
//!
//! Every candidate effect of the library is fitted to the campaign (its default free parameters,
//! [`super::fit::default_free`]; the candidates in parallel) and ranked by the Bayesian
//! information criterion: ΔBIC = χ²_baseline − χ²_candidate − p·ln n (n features, p parameters
//! added). With the features scaled by their noise, χ² of a right model is ≈ n − p, so:
//! - a candidate is *significant* when ΔBIC > [`SIGNIFICANT_BIC`] (Kass & Raftery's "very strong"
//!   evidence; fitting p parameters to noise alone lowers χ² by about p, far below p·ln n);
//! - the share of the residual it *explains* is 1 − (R_c² − N²)/(R_b² − N²), with R the residual
//!   rms over every test and channel (what a user sees fall) of the baseline and the candidate and
//!   N the noise floor of that rms: the part of the baseline's residual beyond noise that the
//!   candidate removes. (A χ² share would overstate a candidate that mimics the few features of
//!   largest signal-to-noise ratio while leaving the residual as it was.) A significant best
//!   candidate that explains less than [`EXPLAINS_ENOUGH`] is reported as such: the missing effect
//!   is probably not in the library (or several are missing).

use super::fit::{self, FeatureInfo, Free, Problem};
use crate::kernel::params::ModelParams;
use rayon::prelude::*;

/// ΔBIC above which a candidate counts as significant.
pub const SIGNIFICANT_BIC: f64 = 10.0;
/// Share of the residual beyond noise a candidate must explain to be named the missing effect.
pub const EXPLAINS_ENOUGH: f64 = 0.5;
/// Iterations of each candidate's fit.
pub const MAX_ITER: usize = 25;

/// One fitted candidate.
pub struct Candidate {
    pub effect: &'static str,
    pub family: &'static str,
    pub free: Vec<Free>,
    pub fit: Result<fit::FitResult, String>,
    pub delta_bic: f64,
    pub explained: f64,
}

impl Candidate {
    pub fn significant(&self) -> bool {
        self.delta_bic > SIGNIFICANT_BIC
    }
    pub fn chi2(&self) -> f64 {
        self.fit.as_ref().map_or(f64::INFINITY, |f| f.chi2_after())
    }
}

/// The outcome of a diagnosis.
pub struct Diagnosis {
    pub baseline: fit::Eval,
    pub n: usize,
    /// Noise floor of the residual rms.
    pub noise_rms: f64,
    /// Candidates, best first.
    pub candidates: Vec<Candidate>,
    pub features: Vec<FeatureInfo>,
}

/// What the diagnosis concludes.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The baseline already fits to the noise, or no candidate lowers the misfit significantly.
    NothingSignificant,
    /// The best candidate is significant and explains most of the residual.
    Missing { effect: &'static str, explained: f64 },
    /// The best candidate is significant but explains little of the residual.
    Unexplained { effect: &'static str, explained: f64 },
}

impl Diagnosis {
    pub fn verdict(&self) -> Verdict {
        match self.candidates.first() {
            Some(c) if c.significant() && c.explained >= EXPLAINS_ENOUGH => Verdict::Missing { effect: c.effect, explained: c.explained },
            Some(c) if c.significant() => Verdict::Unexplained { effect: c.effect, explained: c.explained },
            _ => Verdict::NothingSignificant,
        }
    }

    /// The verdict in plain words.
    pub fn summary(&self) -> String {
        let best = self.candidates.first();
        match self.verdict() {
            Verdict::NothingSignificant => format!(
                "no candidate explains the residual significantly (best: {}, dBIC = {:.1} <= {SIGNIFICANT_BIC}); no significant missing effect",
                best.map_or("-", |c| c.effect),
                best.map_or(f64::NAN, |c| c.delta_bic)
            ),
            Verdict::Missing { effect, explained } => format!(
                "most likely missing: {effect} ({}); it explains {:.0} % of the residual beyond noise (dBIC = {:.0})",
                fit::family(effect),
                100.0 * explained,
                best.map_or(f64::NAN, |c| c.delta_bic)
            ),
            Verdict::Unexplained { effect, explained } => format!(
                "the best candidate, {effect}, explains only {:.0} % of the residual beyond noise: the missing effect is probably not in the library (or several are missing)",
                100.0 * explained
            ),
        }
    }
}

/// The free parameters of `effect` at their values in `model`.
pub fn free_of(effect: &str, model: &ModelParams) -> Vec<Free> {
    fit::default_free(effect)
        .iter()
        .map(|n| {
            let info = ModelParams::lookup(&format!("{effect}.{n}")).expect("default free parameters are registered");
            Free::new(info, (info.get)(model))
        })
        .collect()
}

/// Fits every candidate and ranks them.
pub fn diagnose(problem: &Problem, candidates: &[&'static str]) -> Diagnosis {
    let baseline = problem.evaluate(1, &|_, m| m.clone()).remove(0);
    let n = baseline.r.len();
    let chi2_b = baseline.chi2();
    let noise = problem.noise_rms();
    let (rb, n2) = (baseline.residual_rms(), noise * noise);
    let model0 = &problem.tests[0].model;
    let mut out: Vec<Candidate> = candidates
        .par_iter()
        .map(|&effect| {
            let free = free_of(effect, model0);
            let fit = fit::fit_from(problem, &free, MAX_ITER, baseline.clone());
            let p = free.len() as f64;
            let (delta_bic, explained) = match &fit {
                Ok(f) => {
                    let rc = f.after.residual_rms();
                    let excess = rb * rb - n2;
                    // A candidate that fits the features worse than the baseline explains nothing.
                    let e = if excess > 0.0 && f.chi2_after() < chi2_b { (1.0 - (rc * rc - n2) / excess).clamp(0.0, 1.0) } else { 0.0 };
                    (chi2_b - f.chi2_after() - p * (n as f64).ln(), e)
                }
                Err(_) => (f64::NEG_INFINITY, 0.0),
            };
            Candidate { effect, family: fit::family(effect), free, fit, delta_bic, explained }
        })
        .collect();
    out.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
    Diagnosis { baseline, n, noise_rms: noise, candidates: out, features: problem.features() }
}

/// The feature groups (test, harmonic) whose χ² a candidate lowers most: (test, harmonic, χ²
/// baseline, χ² candidate), largest reduction first.
pub fn evidence(d: &Diagnosis, c: &Candidate, top: usize) -> Vec<(usize, usize, f64, f64)> {
    let Ok(f) = &c.fit else { return Vec::new() };
    let b = fit::grouped(&d.features, &d.baseline.r);
    let a = fit::grouped(&d.features, &f.after.r);
    let mut v: Vec<(usize, usize, f64, f64)> = b.iter().map(|(&(t, k), &x)| (t, k, x, a.get(&(t, k)).copied().unwrap_or(f64::NAN))).collect();
    v.sort_by(|x, y| (y.2 - y.3).total_cmp(&(x.2 - x.3)));
    v.truncate(top);
    v
}
