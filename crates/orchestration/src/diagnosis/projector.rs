//! The harmonics of a sampled channel over a window: H_k by least squares on the harmonics below
//! the Nyquist frequency (compare, the state map and the terms with memory share it).

use faer::prelude::*;
use faer::{Mat, Side};
use std::f64::consts::PI;
use vshake_kernel::metrics::N_HARM;

/// A complex number (re, im).
pub type C64 = (f64, f64);

/// H_k (k = 1…9) of `x` at model times `tau`, by least squares on the harmonics below the
/// Nyquist frequency (see [`Projector`]).
pub fn project(x: &[f64], tau: &[f64], f: f64, n_harm: usize) -> [C64; N_HARM] {
    Projector::new(tau, f, n_harm).apply(x)
}

/// The harmonics H_k of a channel over a window of samples, by least squares: x ≈ c +
/// Σₖ (Re Hₖ cos θₖ − Im Hₖ sin θₖ), θₖ = 2π k f τ, for k = 1 … n_harm (those below the file's
/// Nyquist frequency).
///
/// [chosen] On a window of whole cycles sampled at a whole number of samples per cycle this is
/// the discrete Fourier sum (2/n) Σ x·e^{−jθₖ} exactly (the basis is orthogonal there). At a
/// sample rate that is not a whole multiple of f (500 Hz for a 3 Hz test: 166.7 samples per
/// cycle) the window holds whole cycles only to within a sample, and the plain sum leaks the
/// other harmonics and the mean into each Hₖ by O(1/n) — 3e-4 of the fundamental at 500 Hz.
/// Least squares removes that leakage, so a file's rate does not move its harmonics. The
/// pseudo-inverse depends only on the sample times, so it is built once per window and each
/// projection is one pass over the samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Projector {
    n_harm: usize,
    /// Rows of the pseudo-inverse (XᵀX)⁻¹Xᵀ: the mean, then (cos, sin) of each harmonic.
    rows: Vec<Vec<f64>>,
    /// The basis X at the samples, one row per function (same order as `rows`).
    basis: Vec<Vec<f64>>,
}

impl Projector {
    /// The projector of the window `tau` (model times, s) for fundamental `f` (Hz) and
    /// harmonics 1 … `n_harm` (fewer when the window has too few samples for them).
    pub fn new(tau: &[f64], f: f64, n_harm: usize) -> Self {
        let n_harm = n_harm.min(N_HARM).min(tau.len().saturating_sub(1) / 2);
        // Drop the highest harmonic while the window cannot tell the functions apart (XᵀX is
        // then not positive definite: e.g. samples at a multiple of a harmonic's phase); the
        // mean alone always can.
        (0..=n_harm)
            .rev()
            .find_map(|h| Self::with_harmonics(tau, f, h))
            .expect("the mean alone is resolved by any window")
    }

    /// The projector with exactly `n_harm` harmonics, or None when XᵀX has no Cholesky factor.
    fn with_harmonics(tau: &[f64], f: f64, n_harm: usize) -> Option<Self> {
        let p = 1 + 2 * n_harm;
        // The basis X at the samples, one row per function.
        let x = Mat::<f64>::from_fn(p, tau.len(), |i, m| {
            let k = i.div_ceil(2);
            let c = f * tau[m] * k as f64;
            let (s, co) = (2.0 * PI * (c - c.floor())).sin_cos();
            match i {
                0 => 1.0,
                _ if i % 2 == 1 => co,
                _ => s,
            }
        });
        // Rows of (XᵀX)⁻¹Xᵀ (X is n × p: here its transpose is stored) by faer's Cholesky.
        let gram = &x * x.transpose();
        let rows = gram.llt(Side::Lower).ok()?.solve(&x);
        let to_rows = |a: &Mat<f64>| -> Vec<Vec<f64>> {
            (0..p)
                .map(|i| (0..tau.len()).map(|m| a[(i, m)]).collect())
                .collect()
        };
        Some(Projector {
            n_harm,
            rows: to_rows(&rows),
            basis: to_rows(&x),
        })
    }

    /// Harmonics the projector resolves.
    pub fn n_harm(&self) -> usize {
        self.n_harm
    }

    /// The mean of `x` over the window (the constant of the least-squares fit).
    pub fn mean(&self, x: &[f64]) -> f64 {
        self.rows[0].iter().zip(x).map(|(a, b)| a * b).sum()
    }

    /// x − P x at each sample: what of `x` the mean and the resolved harmonics do not hold (other
    /// frequencies, higher harmonics, a trend, noise).
    pub(crate) fn remainder(&self, x: &[f64]) -> Vec<f64> {
        let c: Vec<f64> = self
            .rows
            .iter()
            .map(|r| r.iter().zip(x).map(|(a, b)| a * b).sum())
            .collect();
        x.iter()
            .enumerate()
            .map(|(m, &v)| {
                v - self
                    .basis
                    .iter()
                    .zip(&c)
                    .map(|(b, c)| b[m] * c)
                    .sum::<f64>()
            })
            .collect()
    }

    /// The basis at the samples, one row per function: the constant, then cos and sin of each
    /// resolved harmonic.
    pub fn basis(&self) -> &[Vec<f64>] {
        &self.basis
    }

    /// Functions fitted: the mean and two per resolved harmonic.
    pub(crate) fn n_functions(&self) -> usize {
        self.rows.len()
    }

    /// H_1 … H_9 of `x` (one value per sample of the window); those beyond `n_harm` are 0.
    pub fn apply(&self, x: &[f64]) -> [C64; N_HARM] {
        let dot = |r: &[f64]| r.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
        let mut out = [(0.0, 0.0); N_HARM];
        for (k, o) in out.iter_mut().enumerate().take(self.n_harm) {
            *o = (dot(&self.rows[2 * k + 1]), -dot(&self.rows[2 * k + 2]));
        }
        out
    }
}
