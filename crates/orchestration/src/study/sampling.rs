//! Designs of experiments: unit-hypercube points and the distributions that map them to
//! parameter values (inverse CDF), for Monte Carlo, Latin hypercube, scrambled Sobol', full-factorial
//! grids and the Saltelli design for Sobol' indices.
//!
//! Determinism: every point depends only on (seed, sample index) — Monte Carlo draws come from a
//! ChaCha8 stream per sample (`seed_from_u64(seed)`, `set_stream(sample)`); a Latin hypercube's
//! per-dimension permutations from streams reserved for them; Sobol' points from the Owen-scrambled
//! sequence of `sobol_burley` (seeded; f32 resolution 2⁻²⁴, at most 65 536 points and 256
//! dimensions). No point depends on the thread or chunk that computes it.

use chacha20::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

/// A parameter distribution.
#[derive(Debug, Clone, PartialEq)]
pub enum Distribution {
    Fixed {
        value: f64,
    },
    Uniform {
        low: f64,
        high: f64,
    },
    LogUniform {
        low: f64,
        high: f64,
    },
    /// Normal, optionally truncated to [low, high].
    Normal {
        mean: f64,
        std: f64,
        low: Option<f64>,
        high: Option<f64>,
    },
    /// ln x ~ Normal(mu, sigma).
    LogNormal {
        mu: f64,
        sigma: f64,
    },
    Triangular {
        low: f64,
        mode: f64,
        high: f64,
    },
    /// One of the listed values, equally likely (a grid takes each in turn).
    List {
        values: Vec<f64>,
    },
}

impl Distribution {
    /// True when the distribution varies (everything but `Fixed`).
    pub fn varies(&self) -> bool {
        !matches!(self, Distribution::Fixed { .. })
    }

    /// Maps u ∈ [0, 1) to a value (inverse CDF).
    pub fn quantile(&self, u: f64) -> f64 {
        match self {
            Distribution::Fixed { value } => *value,
            Distribution::Uniform { low, high } => low + u * (high - low),
            Distribution::LogUniform { low, high } => (low.ln() + u * (high.ln() - low.ln())).exp(),
            Distribution::Normal {
                mean,
                std,
                low,
                high,
            } => {
                let a = low.map_or(0.0, |l| normal_cdf((l - mean) / std));
                let b = high.map_or(1.0, |h| normal_cdf((h - mean) / std));
                let p = (a + u * (b - a)).clamp(1e-300, 1.0 - 1e-16);
                let x = mean + std * normal_quantile(p);
                // Rounding in the CDF must not step outside the truncation.
                x.clamp(
                    low.unwrap_or(f64::NEG_INFINITY),
                    high.unwrap_or(f64::INFINITY),
                )
            }
            Distribution::LogNormal { mu, sigma } => {
                (mu + sigma * normal_quantile(u.clamp(1e-300, 1.0 - 1e-16))).exp()
            }
            Distribution::Triangular { low, mode, high } => {
                let (a, c, b) = (*low, *mode, *high);
                let fc = (c - a) / (b - a);
                if u < fc {
                    a + (u * (b - a) * (c - a)).sqrt()
                } else {
                    b - ((1.0 - u) * (b - a) * (b - c)).sqrt()
                }
            }
            Distribution::List { values } => {
                values[((u * values.len() as f64) as usize).min(values.len() - 1)]
            }
        }
    }

    /// The `levels` values a full-factorial grid takes: the listed values; a uniform range split
    /// evenly including its ends (log-evenly for log-uniform); the mid-quantiles (i + ½)/levels
    /// otherwise; a fixed value once.
    pub fn grid(&self, levels: usize) -> Vec<f64> {
        match self {
            Distribution::Fixed { value } => vec![*value],
            Distribution::List { values } => values.clone(),
            Distribution::Uniform { low, high } => linspace(*low, *high, levels),
            Distribution::LogUniform { low, high } => linspace(low.ln(), high.ln(), levels)
                .into_iter()
                .map(f64::exp)
                .collect(),
            _ => (0..levels)
                .map(|i| self.quantile((i as f64 + 0.5) / levels as f64))
                .collect(),
        }
    }
}

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![0.5 * (a + b)];
    }
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// Standard normal quantile Φ⁻¹(p), Acklam's rational approximation (relative error < 1.2e-9).
#[allow(clippy::excessive_precision)] // the coefficients as published
pub(crate) fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    const P_LOW: f64 = 0.02425;
    if p < P_LOW {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - P_LOW {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

/// Standard normal CDF Φ(x) = ½ erfc(−x/√2), with erfc from `libm` (the Rust port of musl's
/// libm, accurate to about an ulp; used to map truncation bounds).
pub(crate) fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// How unit points are made.
#[derive(Debug, Clone, PartialEq)]
pub enum Design {
    MonteCarlo,
    LatinHypercube,
    Sobol,
    /// Full factorial over the given value lists (one per varied dimension).
    Grid {
        values: Vec<Vec<f64>>,
    },
    /// Saltelli's design for Sobol' indices: `base` points of A and B, each followed by the d
    /// points AB_i (A with column i from B): N·(d + 2) runs.
    Saltelli {
        base: usize,
    },
}

/// Largest number of points of a Sobol' sequence (sobol_burley).
pub const SOBOL_MAX_POINTS: usize = 1 << 16;
/// Largest number of Sobol' dimensions.
pub const SOBOL_MAX_DIMS: usize = sobol_burley::NUM_DIMENSIONS as usize;

/// Block of a Saltelli design row: 0 = A, 1 = B, 2 + i = AB_i.
pub(crate) fn saltelli_block(sample: usize, d: usize) -> (usize, usize) {
    (sample / (d + 2), sample % (d + 2))
}

/// A design with its dimension and size; `point` fills the unit point of one sample.
#[derive(Debug, Clone)]
pub struct UnitDesign {
    pub design: Design,
    pub dims: usize,
    pub samples: usize,
    pub seed: u64,
    /// Latin hypercube: one permutation of 0..samples per dimension.
    lhs_perm: Vec<Vec<u32>>,
}

impl UnitDesign {
    /// `samples` is the number of runs (for Saltelli: base points; the runs are base·(d + 2)).
    pub fn new(design: Design, dims: usize, samples: usize, seed: u64) -> Self {
        let runs = match &design {
            Design::Grid { values } => values.iter().map(Vec::len).product(),
            Design::Saltelli { base } => base * (dims + 2),
            _ => samples,
        };
        let lhs_perm = if design == Design::LatinHypercube {
            (0..dims)
                .map(|j| {
                    // Streams from 2⁶³ on are reserved for the permutations (sample streams are < 2⁶³).
                    let mut rng = ChaCha8Rng::seed_from_u64(seed);
                    rng.set_stream((1u64 << 63) + j as u64);
                    let mut p: Vec<u32> = (0..samples as u32).collect();
                    for i in (1..p.len()).rev() {
                        let k = rng.random_range(0..=i);
                        p.swap(i, k);
                    }
                    p
                })
                .collect()
        } else {
            Vec::new()
        };
        UnitDesign {
            design,
            dims,
            samples: runs,
            seed,
            lhs_perm,
        }
    }

    /// The unit point of `sample` (for a grid: the level indices as u = index, see [`Self::grid_index`]).
    pub fn point(&self, sample: usize, out: &mut [f64]) {
        debug_assert_eq!(out.len(), self.dims);
        let rng = || {
            let mut r = ChaCha8Rng::seed_from_u64(self.seed);
            r.set_stream(sample as u64);
            r
        };
        match &self.design {
            Design::MonteCarlo => {
                let mut r = rng();
                for u in out.iter_mut() {
                    *u = r.random::<f64>();
                }
            }
            Design::LatinHypercube => {
                let mut r = rng();
                let n = self.samples as f64;
                for (j, u) in out.iter_mut().enumerate() {
                    *u = (self.lhs_perm[j][sample] as f64 + r.random::<f64>()) / n;
                }
            }
            Design::Sobol => {
                for (j, u) in out.iter_mut().enumerate() {
                    *u = sobol(sample, j, self.seed);
                }
            }
            Design::Grid { .. } => unreachable!("grid points are indices, see grid_index"),
            Design::Saltelli { .. } => {
                let d = self.dims;
                let (base, block) = saltelli_block(sample, d);
                for (j, u) in out.iter_mut().enumerate() {
                    // A = dimensions 0..d of the Sobol' sequence, B = dimensions d..2d.
                    let from_b = block == 1 || block == 2 + j;
                    *u = sobol(base, if from_b { d + j } else { j }, self.seed);
                }
            }
        }
    }

    /// Grid design: the level index of each dimension for `sample` (last dimension fastest).
    pub fn grid_index(&self, sample: usize, out: &mut [usize]) {
        let Design::Grid { values } = &self.design else {
            panic!("not a grid")
        };
        let mut rest = sample;
        for j in (0..values.len()).rev() {
            out[j] = rest % values[j].len();
            rest /= values[j].len();
        }
    }
}

fn sobol(index: usize, dim: usize, seed: u64) -> f64 {
    let s = (seed ^ (seed >> 32)) as u32;
    // Centre of the f32 cell, so that no point sits exactly on 0.
    sobol_burley::sample(index as u32, dim as u32, s) as f64 + 0.5 / (1u64 << 24) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantile_matches_known_values() {
        assert!((normal_quantile(0.975) - 1.959963984540054).abs() < 1e-8);
        assert!((normal_quantile(0.001) + 3.090232306167813).abs() < 1e-8);
        assert!((normal_quantile(0.841344746068543) - 1.0).abs() < 1e-8);
        assert_eq!(normal_quantile(0.5), 0.0);
        for p in [0.01, 0.2, 0.5, 0.77, 0.999] {
            assert!((normal_cdf(normal_quantile(p)) - p).abs() < 2e-7, "{p}");
        }
    }

    #[test]
    fn distributions_map_the_unit_interval() {
        let t = Distribution::Triangular {
            low: 0.0,
            mode: 1.0,
            high: 4.0,
        };
        assert!((t.quantile(0.25) - 1.0).abs() < 1e-12);
        let n = Distribution::Normal {
            mean: 1.0,
            std: 1.0,
            low: Some(0.0),
            high: Some(2.0),
        };
        assert!((n.quantile(0.5) - 1.0).abs() < 1e-6);
        assert!(n.quantile(0.0) >= 0.0 && n.quantile(0.999999) <= 2.0);
        let lu = Distribution::LogUniform {
            low: 1.0,
            high: 100.0,
        };
        assert!((lu.quantile(0.5) - 10.0).abs() < 1e-9);
        assert_eq!(
            Distribution::List {
                values: vec![1.0, 2.0, 3.0]
            }
            .quantile(0.99),
            3.0
        );
        assert_eq!(
            Distribution::Uniform {
                low: 1.0,
                high: 2.0
            }
            .grid(3),
            vec![1.0, 1.5, 2.0]
        );
    }

    #[test]
    fn latin_hypercube_has_one_point_per_stratum() {
        let d = UnitDesign::new(Design::LatinHypercube, 3, 50, 7);
        let mut seen = vec![vec![false; 50]; 3];
        let mut u = [0.0; 3];
        for s in 0..50 {
            d.point(s, &mut u);
            for j in 0..3 {
                let k = (u[j] * 50.0) as usize;
                assert!(!seen[j][k]);
                seen[j][k] = true;
            }
        }
    }

    #[test]
    fn points_depend_only_on_seed_and_index() {
        for design in [
            Design::MonteCarlo,
            Design::Sobol,
            Design::Saltelli { base: 16 },
        ] {
            let a = UnitDesign::new(design.clone(), 4, 16, 99);
            let b = UnitDesign::new(design, 4, 16, 99);
            let (mut x, mut y) = ([0.0; 4], [0.0; 4]);
            a.point(13, &mut x);
            b.point(13, &mut y);
            assert_eq!(x, y);
            a.point(12, &mut y);
            assert_ne!(x, y);
        }
    }

    #[test]
    fn saltelli_rows_share_columns_as_designed() {
        let d = UnitDesign::new(Design::Saltelli { base: 8 }, 3, 8, 1);
        assert_eq!(d.samples, 8 * 5);
        let row = |s: usize| {
            let mut u = [0.0; 3];
            d.point(s, &mut u);
            u
        };
        let (a, b, ab1) = (row(5 * 2), row(5 * 2 + 1), row(5 * 2 + 3));
        assert_eq!(ab1[0], a[0]);
        assert_eq!(ab1[1], b[1]);
        assert_eq!(ab1[2], a[2]);
        assert_ne!(a[1], b[1]);
    }
}
