//! Global sensitivity analysis of study results.
//!
//! **Sobol' indices** from a Saltelli design (base matrices A and B of N points, and AB_i = A with
//! column i from B), with V the variance of f over A ∪ B:
//!
//! ```text
//! S_i  = (1/N) Σ_j (f_B,j − f̄) (f_ABi,j − f_A,j) / V             (first order, Saltelli 2010)
//! ST_i = (1/2N) Σ_j (f_A,j − f_ABi,j)² / V                        (total, Jansen 1999)
//! ```
//!
//! with f̄ the mean over A ∪ B (centring leaves the expectation unchanged and removes the variance
//! that grows with f̄²/V), and percentile bootstrap confidence intervals (base points resampled
//! with replacement).
//!
//! **Regression measures** for any design: standardised regression coefficients (SRC, least
//! squares on standardised inputs and output, with the R² that says how linear the response is)
//! and partial rank correlation coefficients (PRCC: correlation of the residuals of rank(x_i) and
//! rank(y) after regressing each on the other ranks). Least squares by QR in faer, sequential
//! (the caller parallelises across metrics).

use chacha20::ChaCha8Rng;
use faer::prelude::*;
use faer::Mat;
use rand::{RngExt, SeedableRng};

/// An estimate with a confidence interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub value: f64,
    pub ci_low: f64,
    pub ci_high: f64,
}

/// Sobol' indices of one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SobolIndex {
    pub first: Estimate,
    pub total: Estimate,
}

fn variance(xs: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = xs.clone().count() as f64;
    let mean = xs.clone().sum::<f64>() / n;
    xs.map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
}

fn point_indices(fa: &[f64], fb: &[f64], fab: &[Vec<f64>], idx: &[usize]) -> Vec<(f64, f64)> {
    let n = idx.len() as f64;
    let v = variance(idx.iter().map(|&j| fa[j]).chain(idx.iter().map(|&j| fb[j])));
    // f is centred on the mean over A ∪ B: the estimator's expectation is unchanged, but its
    // variance no longer grows with mean²/V (large for responses like an amplitude ratio ≈ 1).
    let mean = idx.iter().map(|&j| fa[j] + fb[j]).sum::<f64>() / (2.0 * n);
    fab.iter()
        .map(|fi| {
            let s1 = idx
                .iter()
                .map(|&j| (fb[j] - mean) * (fi[j] - fa[j]))
                .sum::<f64>()
                / n
                / v;
            let st = idx.iter().map(|&j| (fa[j] - fi[j]).powi(2)).sum::<f64>() / (2.0 * n) / v;
            (s1, st)
        })
        .collect()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let pos = p * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (pos - lo as f64) * (sorted[hi] - sorted[lo])
}

/// First-order and total Sobol' indices with `bootstrap` resamples (95 % percentile intervals).
/// `fa`, `fb` hold f at the N base points of A and B; `fab[i]` at AB_i.
pub fn sobol(
    fa: &[f64],
    fb: &[f64],
    fab: &[Vec<f64>],
    bootstrap: usize,
    seed: u64,
) -> Vec<SobolIndex> {
    let n = fa.len();
    let all: Vec<usize> = (0..n).collect();
    let point = point_indices(fa, fb, fab, &all);
    let d = fab.len();
    let mut boots: Vec<(Vec<f64>, Vec<f64>)> =
        vec![(Vec::with_capacity(bootstrap), Vec::with_capacity(bootstrap)); d];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut idx = vec![0; n];
    for _ in 0..bootstrap {
        for x in idx.iter_mut() {
            *x = rng.random_range(0..n);
        }
        for (i, (s1, st)) in point_indices(fa, fb, fab, &idx).into_iter().enumerate() {
            boots[i].0.push(s1);
            boots[i].1.push(st);
        }
    }
    point
        .into_iter()
        .zip(boots)
        .map(|((s1, st), (mut b1, mut bt))| {
            let ci = |b: &mut Vec<f64>, v: f64| {
                if b.is_empty() {
                    return Estimate {
                        value: v,
                        ci_low: f64::NAN,
                        ci_high: f64::NAN,
                    };
                }
                b.sort_by(f64::total_cmp);
                Estimate {
                    value: v,
                    ci_low: percentile(b, 0.025),
                    ci_high: percentile(b, 0.975),
                }
            };
            SobolIndex {
                first: ci(&mut b1, s1),
                total: ci(&mut bt, st),
            }
        })
        .collect()
}

fn standardise(v: &[f64]) -> Vec<f64> {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    v.iter()
        .map(|x| if sd > 0.0 { (x - mean) / sd } else { 0.0 })
        .collect()
}

/// Least squares with an intercept: returns (coefficients without the intercept, residuals).
fn lstsq(x: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (n, d) = (y.len(), x.len());
    let a = Mat::<f64>::from_fn(n, d + 1, |i, j| if j == 0 { 1.0 } else { x[j - 1][i] });
    let b = Mat::<f64>::from_fn(n, 1, |i, _| y[i]);
    let sol = a.qr().solve_lstsq(&b);
    let coef: Vec<f64> = (0..=d).map(|j| sol[(j, 0)]).collect();
    let resid = (0..n)
        .map(|i| y[i] - (0..=d).map(|j| a[(i, j)] * coef[j]).sum::<f64>())
        .collect();
    (coef[1..].to_vec(), resid)
}

/// Standardised regression coefficients and R². `x[i]` is input i over the samples.
pub fn src(x: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, f64) {
    let xs: Vec<Vec<f64>> = x.iter().map(|c| standardise(c)).collect();
    let ys = standardise(y);
    let (coef, resid) = lstsq(&xs, &ys);
    let ss_tot: f64 = ys.iter().map(|v| v * v).sum();
    let ss_res: f64 = resid.iter().map(|r| r * r).sum();
    (
        coef,
        if ss_tot > 0.0 {
            1.0 - ss_res / ss_tot
        } else {
            f64::NAN
        },
    )
}

/// Ranks 1…n, ties sharing their average rank.
pub fn ranks(v: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && v[order[j + 1]] == v[order[i]] {
            j += 1;
        }
        let avg = (i + j) as f64 / 2.0 + 1.0;
        for k in i..=j {
            r[order[k]] = avg;
        }
        i = j + 1;
    }
    r
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let (sa, sb) = (standardise(a), standardise(b));
    sa.iter().zip(&sb).map(|(x, y)| x * y).sum::<f64>() / (a.len() as f64 - 1.0)
}

/// Partial rank correlation coefficient of each input with the output.
pub fn prcc(x: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let rx: Vec<Vec<f64>> = x.iter().map(|c| ranks(c)).collect();
    let ry = ranks(y);
    (0..x.len())
        .map(|i| {
            let others: Vec<Vec<f64>> = rx
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, c)| c.clone())
                .collect();
            let (_, res_x) = lstsq(&others, &rx[i]);
            let (_, res_y) = lstsq(&others, &ry);
            correlation(&res_x, &res_y)
        })
        .collect()
}

/// A study's results as the analysis reads them: columns of one results table, row by row.
pub struct Results<'a> {
    /// The excitation of each row (its index).
    pub excitation: &'a [f64],
    /// For a Saltelli design, each row's base point and block (0 = A, 1 = B, 2 + i = AB_i).
    pub saltelli: Option<(&'a [f64], &'a [f64])>,
    /// The varied parameters' columns, in design order.
    pub inputs: Vec<&'a [f64]>,
}

/// The indices of one output (one metric at one excitation), per varied parameter in design
/// order.
#[derive(Debug, Clone, PartialEq)]
pub struct Indices {
    /// Sobol' indices (a Saltelli design with at least two complete base points).
    pub sobol: Option<Vec<SobolIndex>>,
    pub src: Vec<f64>,
    pub prcc: Vec<f64>,
    /// R² of the linear fit behind the SRCs.
    pub r2: f64,
    /// Runs the regression measures used.
    pub n: usize,
    /// Failed runs left out: base points (Saltelli) or rows.
    pub dropped: usize,
}

/// The outputs of a Saltelli design regrouped by base point: one row `[f_A, f_B, f_AB_1, …,
/// f_AB_d]` per base point whose every block finished, and the number of base points dropped
/// because one of their runs failed (NaN) or is absent.
pub(crate) fn saltelli_blocks(
    rows: &[usize],
    base: &[f64],
    block: &[f64],
    y: &[f64],
    d: usize,
) -> (Vec<Vec<f64>>, usize) {
    let n_base = rows
        .iter()
        .map(|&r| base[r] as usize + 1)
        .max()
        .unwrap_or(0);
    let mut table = vec![vec![f64::NAN; d + 2]; n_base];
    for &r in rows {
        let (b, k) = (base[r] as usize, block[r] as usize);
        if k < d + 2 {
            table[b][k] = y[r];
        }
    }
    let complete: Vec<Vec<f64>> = table
        .into_iter()
        .filter(|v| v.iter().all(|x| x.is_finite()))
        .collect();
    let dropped = n_base - complete.len();
    (complete, dropped)
}

/// Sobol' indices (Saltelli designs), SRC and PRCC of output `y` at excitation `e`. The
/// bootstrap's seed depends only on `e`, so the result does not depend on the order outputs are
/// analysed in.
pub fn analyse(results: &Results<'_>, e: usize, y: &[f64], bootstrap: usize) -> Indices {
    let d = results.inputs.len();
    let rows: Vec<usize> = (0..y.len())
        .filter(|&r| results.excitation[r] as usize == e)
        .collect();
    let (sobol_idx, dropped, used) = match results.saltelli {
        Some((base, block)) => {
            let (complete, dropped) = saltelli_blocks(&rows, base, block, y, d);
            let sobol_idx = (complete.len() >= 2).then(|| {
                let fa: Vec<f64> = complete.iter().map(|v| v[0]).collect();
                let fb: Vec<f64> = complete.iter().map(|v| v[1]).collect();
                let fab: Vec<Vec<f64>> = (0..d)
                    .map(|i| complete.iter().map(|v| v[2 + i]).collect())
                    .collect();
                sobol(&fa, &fb, &fab, bootstrap, 0x5eed ^ ((e as u64) << 8))
            });
            // The regression measures use the A and B points: independent samples of the design.
            (
                sobol_idx,
                dropped,
                rows.iter()
                    .copied()
                    .filter(|&r| block[r] < 2.0 && y[r].is_finite())
                    .collect::<Vec<_>>(),
            )
        }
        None => {
            let used: Vec<usize> = rows.iter().copied().filter(|&r| y[r].is_finite()).collect();
            (None, rows.len() - used.len(), used)
        }
    };
    let n = used.len();
    let (src_v, r2, prcc_v) = if n > d + 2 && used.iter().any(|&r| y[r] != y[used[0]]) {
        let x: Vec<Vec<f64>> = results
            .inputs
            .iter()
            .map(|c| used.iter().map(|&r| c[r]).collect())
            .collect();
        let yy: Vec<f64> = used.iter().map(|&r| y[r]).collect();
        let (s, r2) = src(&x, &yy);
        (s, r2, prcc(&x, &yy))
    } else {
        (vec![f64::NAN; d], f64::NAN, vec![f64::NAN; d])
    };
    Indices {
        sobol: sobol_idx,
        src: src_v,
        prcc: prcc_v,
        r2,
        n,
        dropped,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::sampling::{Design, Distribution, UnitDesign};

    /// Ishigami function with a = 7, b = 0.1 on [−π, π]³: S = (0.3139, 0.4424, 0),
    /// ST = (0.5576, 0.4424, 0.2437).
    fn ishigami(x: &[f64]) -> f64 {
        x[0].sin() + 7.0 * x[1].sin().powi(2) + 0.1 * x[2].powi(4) * x[0].sin()
    }

    #[test]
    fn sobol_indices_of_the_ishigami_function() {
        let base = 8192;
        let design = UnitDesign::new(Design::Saltelli { base }, 3, base, 42);
        let u_to_x = Distribution::Uniform {
            low: -std::f64::consts::PI,
            high: std::f64::consts::PI,
        };
        let (mut fa, mut fb, mut fab) =
            (vec![0.0; base], vec![0.0; base], vec![vec![0.0; base]; 3]);
        let mut u = [0.0; 3];
        for s in 0..design.samples {
            design.point(s, &mut u);
            let x: Vec<f64> = u.iter().map(|&v| u_to_x.quantile(v)).collect();
            let (j, block) = (s / 5, s % 5);
            let f = ishigami(&x);
            match block {
                0 => fa[j] = f,
                1 => fb[j] = f,
                k => fab[k - 2][j] = f,
            }
        }
        let idx = sobol(&fa, &fb, &fab, 200, 7);
        let exact_s1 = [0.3139, 0.4424, 0.0];
        let exact_st = [0.5576, 0.4424, 0.2437];
        for i in 0..3 {
            assert!(
                (idx[i].first.value - exact_s1[i]).abs() < 0.02,
                "S{} = {:?}",
                i + 1,
                idx[i].first
            );
            assert!(
                (idx[i].total.value - exact_st[i]).abs() < 0.02,
                "ST{} = {:?}",
                i + 1,
                idx[i].total
            );
            // The interval is a real interval around the estimate, and covers the exact value.
            assert!(
                idx[i].first.ci_low < idx[i].first.value
                    && idx[i].first.value < idx[i].first.ci_high
            );
            assert!(
                idx[i].first.ci_low <= exact_s1[i] && exact_s1[i] <= idx[i].first.ci_high,
                "S{}: {:?}",
                i + 1,
                idx[i].first
            );
            assert!(
                idx[i].total.ci_low <= exact_st[i] && exact_st[i] <= idx[i].total.ci_high,
                "ST{}: {:?}",
                i + 1,
                idx[i].total
            );
        }
    }

    #[test]
    fn regression_measures_of_a_linear_model() {
        // y = 3 x0 − x1 + 0·x2 + noise independent of the inputs: SRC ∝ coefficient × sd,
        // R² near 1; the PRCC of x2 is the correlation of noise with x2, ≈ 0 (|ρ| < 4/√n).
        let n = 400;
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let x: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..n).map(|_| rng.random::<f64>()).collect())
            .collect();
        let noise: Vec<f64> = (0..n).map(|_| rng.random::<f64>() - 0.5).collect();
        let y: Vec<f64> = (0..n)
            .map(|i| 3.0 * x[0][i] - x[1][i] + 0.05 * noise[i])
            .collect();
        let (coef, r2) = src(&x, &y);
        assert!(r2 > 0.999, "{r2}");
        // SRC_k = b_k·sd(x_k)/sd(y), with the sample's standard deviations.
        let sd = |v: &[f64]| variance(v.iter().copied()).sqrt();
        for (k, b) in [3.0, -1.0].into_iter().enumerate() {
            assert!(
                (coef[k] - b * sd(&x[k]) / sd(&y)).abs() < 0.01,
                "SRC{k}: {coef:?}"
            );
        }
        assert!(coef[2].abs() < 0.01, "{coef:?}");
        let p = prcc(&x, &y);
        assert!(p[0] > 0.99 && p[1] < -0.95, "{p:?}");
        assert!(p[2].abs() < 4.0 / (n as f64).sqrt(), "PRCC(x2) = {}", p[2]);
        assert_eq!(ranks(&[3.0, 1.0, 3.0, 2.0]), vec![3.5, 1.0, 3.5, 2.0]);
    }
}
