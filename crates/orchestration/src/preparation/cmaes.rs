//! CMA-ES, the covariance matrix adaptation evolution strategy, for `study tune`: a derivative-free
//! minimiser of a few bounded parameters (controller gains) whose objective is a batch of
//! simulations. Each generation's whole population is asked for at once ([`Cmaes::ask`]) so that
//! the caller evaluates it as lanes of one batch, then told the objectives ([`Cmaes::tell`]).
//!
//! The algorithm and every default are those of N. Hansen, "The CMA Evolution Strategy: A
//! Tutorial", arXiv:1604.00772 (2016), Table 1 and Fig. 7 ("(μ/μ_w, λ)-CMA-ES", positive
//! recombination weights only):
//!
//! - population λ = 4 + ⌊3 ln n⌋, parents μ = ⌊λ/2⌋, weights w_i ∝ ln((λ+1)/2) − ln i;
//! - step-size control by the cumulative path p_σ (c_σ, d_σ), covariance by the rank-one path p_c
//!   (c_c, c_1) and the rank-μ update (c_μ), with the h_σ stall of p_c;
//! - C = B D² Bᵀ by a cyclic Jacobi eigendecomposition every generation (n is small: a few gains).
//!
//! Bounds: the search runs in coordinates normalised to the box, [0, 1] per parameter, and a
//! candidate outside it is folded back by reflection at the walls (period 2), so every point
//! evaluated is inside the box and no penalty scale is needed; the distribution itself is not
//! bounded. A failed evaluation (NaN) ranks last.
//!
//! Deterministic: the draws come from one ChaCha8 stream of the seed, in order, and ranking breaks
//! ties by candidate index, so the run depends only on the seed and the objective values, not on
//! how (or on how many threads) the population was evaluated.

use chacha20::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

/// The strategy's constants for n dimensions (Hansen 2016, Table 1).
#[derive(Debug, Clone)]
struct Constants {
    lambda: usize,
    weights: Vec<f64>,
    mu_eff: f64,
    c_sigma: f64,
    d_sigma: f64,
    c_c: f64,
    c_1: f64,
    c_mu: f64,
    /// E‖N(0, I)‖ ≈ √n (1 − 1/(4n) + 1/(21n²)).
    chi_n: f64,
}

impl Constants {
    fn new(n: usize, lambda: usize) -> Self {
        let nf = n as f64;
        let mu = lambda / 2;
        let raw: Vec<f64> = (1..=mu)
            .map(|i| ((lambda as f64 + 1.0) / 2.0).ln() - (i as f64).ln())
            .collect();
        let sum: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / sum).collect();
        let mu_eff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let c_sigma = (mu_eff + 2.0) / (nf + mu_eff + 5.0);
        let d_sigma = 1.0 + 2.0 * (((mu_eff - 1.0) / (nf + 1.0)).sqrt() - 1.0).max(0.0) + c_sigma;
        let c_c = (4.0 + mu_eff / nf) / (nf + 4.0 + 2.0 * mu_eff / nf);
        let c_1 = 2.0 / ((nf + 1.3).powi(2) + mu_eff);
        let c_mu =
            (1.0 - c_1).min(2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((nf + 2.0).powi(2) + mu_eff));
        Constants {
            lambda,
            weights,
            mu_eff,
            c_sigma,
            d_sigma,
            c_c,
            c_1,
            c_mu,
            chi_n: nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf)),
        }
    }
}

/// The default population size for n dimensions: 4 + ⌊3 ln n⌋.
pub fn default_population(n: usize) -> usize {
    4 + (3.0 * (n as f64).ln()).floor() as usize
}

/// A CMA-ES run over the box [`lower`, `upper`] (see the module docs).
#[derive(Debug)]
pub struct Cmaes {
    k: Constants,
    lower: Vec<f64>,
    upper: Vec<f64>,
    /// Mean, paths and covariance, in normalised coordinates.
    mean: Vec<f64>,
    sigma: f64,
    p_sigma: Vec<f64>,
    p_c: Vec<f64>,
    c: Vec<Vec<f64>>,
    /// C = B diag(d²) Bᵀ: eigenvectors as columns, and the square roots of the eigenvalues.
    b: Vec<Vec<f64>>,
    d: Vec<f64>,
    generation: usize,
    rng: ChaCha8Rng,
    /// The last population asked for: the steps y = B D z (normalised, before reflection).
    steps: Vec<Vec<f64>>,
    /// Whether h_σ stalled the last p_c update (‖p_σ‖ large: σ is growing).
    stalled: bool,
    best: Option<(Vec<f64>, f64)>,
}

/// Why a run's settings cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CmaesError {
    #[error("parameter {0}: the lower bound {1} is not below the upper bound {2}")]
    Bounds(usize, f64, f64),
    #[error("parameter {0}: the start {1} is outside [{2}, {3}]")]
    Start(usize, f64, f64, f64),
    #[error("no parameters to optimise")]
    Empty,
    #[error("the initial step {0} is not in (0, 1] (a fraction of each parameter's range)")]
    Sigma(f64),
    #[error("a population of {0} is too small (at least 4)")]
    Population(usize),
}

impl Cmaes {
    /// A run from `start` inside the box, with initial step `sigma0` as a fraction of each
    /// parameter's range (0.3 is usual), `population` candidates per generation (None: the
    /// default) and the draws of `seed`.
    pub fn new(
        start: &[f64],
        lower: &[f64],
        upper: &[f64],
        sigma0: f64,
        population: Option<usize>,
        seed: u64,
    ) -> Result<Self, CmaesError> {
        let n = start.len();
        assert!(
            lower.len() == n && upper.len() == n,
            "a bound per parameter"
        );
        if n == 0 {
            return Err(CmaesError::Empty);
        }
        for i in 0..n {
            if !(lower[i] < upper[i]) {
                return Err(CmaesError::Bounds(i, lower[i], upper[i]));
            }
            if !(lower[i]..=upper[i]).contains(&start[i]) {
                return Err(CmaesError::Start(i, start[i], lower[i], upper[i]));
            }
        }
        if !(sigma0 > 0.0 && sigma0 <= 1.0) {
            return Err(CmaesError::Sigma(sigma0));
        }
        let lambda = population.unwrap_or_else(|| default_population(n));
        if lambda < 4 {
            return Err(CmaesError::Population(lambda));
        }
        let identity = |i: usize| (0..n).map(|j| f64::from(u8::from(i == j))).collect();
        Ok(Cmaes {
            k: Constants::new(n, lambda),
            mean: (0..n)
                .map(|i| (start[i] - lower[i]) / (upper[i] - lower[i]))
                .collect(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            sigma: sigma0,
            p_sigma: vec![0.0; n],
            p_c: vec![0.0; n],
            c: (0..n).map(identity).collect(),
            b: (0..n).map(identity).collect(),
            d: vec![1.0; n],
            generation: 0,
            rng: ChaCha8Rng::seed_from_u64(seed),
            steps: Vec::new(),
            stalled: false,
            best: None,
        })
    }

    /// Candidates per generation (λ).
    pub fn population(&self) -> usize {
        self.k.lambda
    }

    /// Generations told so far.
    pub fn generation(&self) -> usize {
        self.generation
    }

    /// The step size σ, as a fraction of the parameters' ranges.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The largest standard deviation of the search distribution along any parameter, as a
    /// fraction of its range: a run has converged when this is small.
    pub fn spread(&self) -> f64 {
        let n = self.mean.len();
        (0..n)
            .map(|i| self.sigma * self.c[i][i].sqrt())
            .fold(0.0, f64::max)
    }

    /// The best candidate told so far and its objective (None before the first `tell`).
    pub fn best(&self) -> Option<(&[f64], f64)> {
        self.best.as_ref().map(|(x, f)| (x.as_slice(), *f))
    }

    /// The mean of the search distribution, in the parameters' units (inside the box).
    pub fn mean(&self) -> Vec<f64> {
        self.to_box(&self.mean)
    }

    /// The next generation's λ candidates, each inside the box, to be evaluated and told.
    pub fn ask(&mut self) -> Vec<Vec<f64>> {
        let n = self.mean.len();
        self.steps = (0..self.k.lambda)
            .map(|_| {
                let z: Vec<f64> = (0..n)
                    .map(|_| self.rng.sample::<f64, _>(StandardNormal))
                    .collect();
                (0..n)
                    .map(|i| (0..n).map(|j| self.b[i][j] * self.d[j] * z[j]).sum())
                    .collect()
            })
            .collect();
        self.steps
            .iter()
            .map(|y| {
                let x: Vec<f64> = (0..n).map(|i| self.mean[i] + self.sigma * y[i]).collect();
                self.to_box(&x)
            })
            .collect()
    }

    /// Tells the objectives of the candidates of the last [`Cmaes::ask`], in its order (NaN: a
    /// failed evaluation, ranked last), and updates the distribution.
    pub fn tell(&mut self, candidates: &[Vec<f64>], objective: &[f64]) {
        assert_eq!(
            objective.len(),
            self.steps.len(),
            "one objective per candidate"
        );
        let rank = |f: f64| if f.is_nan() { f64::INFINITY } else { f };
        let mut order: Vec<usize> = (0..objective.len()).collect();
        order.sort_by(|&a, &b| {
            rank(objective[a])
                .total_cmp(&rank(objective[b]))
                .then(a.cmp(&b))
        });
        let top = order[0];
        if self
            .best
            .as_ref()
            .is_none_or(|(_, f)| rank(objective[top]) < *f)
        {
            self.best = Some((candidates[top].clone(), rank(objective[top])));
        }
        let n = self.mean.len();
        let y_w: Vec<f64> = (0..n)
            .map(|i| {
                order
                    .iter()
                    .zip(&self.k.weights)
                    .map(|(&r, w)| w * self.steps[r][i])
                    .sum()
            })
            .collect();
        for i in 0..n {
            self.mean[i] += self.sigma * y_w[i];
        }
        self.update_paths(&y_w);
        self.update_covariance(&order);
        let norm = self.p_sigma.iter().map(|p| p * p).sum::<f64>().sqrt();
        let k = &self.k;
        self.sigma *= ((k.c_sigma / k.d_sigma) * (norm / k.chi_n - 1.0)).exp();
        self.generation += 1;
        (self.b, self.d) = eigen(&self.c);
    }

    /// The evolution paths p_σ (through C^(−½) = B D⁻¹ Bᵀ) and p_c (stalled by h_σ).
    fn update_paths(&mut self, y_w: &[f64]) {
        let n = y_w.len();
        let k = &self.k;
        let bt_y: Vec<f64> = (0..n)
            .map(|j| (0..n).map(|i| self.b[i][j] * y_w[i]).sum::<f64>() / self.d[j])
            .collect();
        let cs = (k.c_sigma * (2.0 - k.c_sigma) * k.mu_eff).sqrt();
        for i in 0..n {
            let c_inv_half: f64 = (0..n).map(|j| self.b[i][j] * bt_y[j]).sum();
            self.p_sigma[i] = (1.0 - k.c_sigma) * self.p_sigma[i] + cs * c_inv_half;
        }
        let norm = self.p_sigma.iter().map(|p| p * p).sum::<f64>().sqrt();
        let g = (self.generation + 1) as f64;
        let stall = norm / (1.0 - (1.0 - k.c_sigma).powf(2.0 * g)).sqrt()
            >= (1.4 + 2.0 / (n as f64 + 1.0)) * k.chi_n;
        let cc = (k.c_c * (2.0 - k.c_c) * k.mu_eff).sqrt();
        for i in 0..n {
            self.p_c[i] = (1.0 - k.c_c) * self.p_c[i] + if stall { 0.0 } else { cc * y_w[i] };
        }
        self.stalled = stall;
    }

    /// C ← (1 − c_1 − c_μ + δ) C + c_1 p_c p_cᵀ + c_μ Σ w_i y_i y_iᵀ.
    fn update_covariance(&mut self, order: &[usize]) {
        let n = self.mean.len();
        let k = &self.k;
        let delta = if self.stalled {
            k.c_1 * k.c_c * (2.0 - k.c_c)
        } else {
            0.0
        };
        for i in 0..n {
            for j in 0..n {
                let rank_mu: f64 = order
                    .iter()
                    .zip(&k.weights)
                    .map(|(&r, w)| w * self.steps[r][i] * self.steps[r][j])
                    .sum();
                self.c[i][j] = (1.0 - k.c_1 - k.c_mu + delta) * self.c[i][j]
                    + k.c_1 * self.p_c[i] * self.p_c[j]
                    + k.c_mu * rank_mu;
            }
        }
    }

    /// A normalised point folded into [0, 1] by reflection, in the parameters' units.
    fn to_box(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .enumerate()
            .map(|(i, &u)| {
                let t = u.rem_euclid(2.0);
                let t = if t > 1.0 { 2.0 - t } else { t };
                self.lower[i] + t * (self.upper[i] - self.lower[i])
            })
            .collect()
    }
}

/// The eigendecomposition of a symmetric matrix by cyclic Jacobi rotations: (B, d) with
/// C = B diag(d²) Bᵀ, eigenvectors as B's columns, d the square roots of the eigenvalues (a
/// negative one from rounding is taken as 0, floored at 1e-300 so that D⁻¹ stays finite).
fn eigen(c: &[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = c.len();
    let a: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| 0.5 * (c[i][j] + c[j][i])).collect())
        .collect();
    let (lambda, v) = vshake_kernel::linalg::symmetric_eigen(a);
    let d = lambda
        .iter()
        .map(|l| l.max(0.0).sqrt().max(1e-300))
        .collect();
    (v, d)
}

/// Minimises `f` (a whole population at once: candidates in, objectives out, in order) from
/// `start` in the box until the spread falls below `tol` (a fraction of the ranges) or after
/// `max_generations`; the best candidate and its objective (the tests' driver; `tune` runs its
/// own loop, with progress and a stop).
#[cfg(test)]
fn minimize(
    mut es: Cmaes,
    tol: f64,
    max_generations: usize,
    mut f: impl FnMut(&[Vec<f64>]) -> Vec<f64>,
) -> (Vec<f64>, f64, Cmaes) {
    while es.generation() < max_generations && es.spread() > tol {
        let x = es.ask();
        let y = f(&x);
        es.tell(&x, &y);
    }
    let (x, y) = es
        .best()
        .map(|(x, y)| (x.to_vec(), y))
        .unwrap_or((es.mean(), f64::NAN));
    (x, y, es)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(x: &[f64]) -> f64 {
        x.iter().map(|v| (v - 0.3) * (v - 0.3)).sum()
    }

    fn rosenbrock(x: &[f64]) -> f64 {
        x.windows(2)
            .map(|w| 100.0 * (w[1] - w[0] * w[0]).powi(2) + (1.0 - w[0]).powi(2))
            .sum()
    }

    fn run(n: usize, lo: f64, hi: f64, seed: u64, obj: fn(&[f64]) -> f64) -> (Vec<f64>, f64) {
        let es = Cmaes::new(
            &vec![lo + 0.2 * (hi - lo); n],
            &vec![lo; n],
            &vec![hi; n],
            0.3,
            None,
            seed,
        )
        .unwrap();
        let (x, y, _) = minimize(es, 1e-12, 5000, |xs| xs.iter().map(|x| obj(x)).collect());
        (x, y)
    }

    #[test]
    fn the_sphere_reaches_1e_8() {
        for n in [2, 4, 10] {
            let (x, y) = run(n, -1.0, 2.0, 7, sphere);
            assert!(y < 1e-8, "n = {n}: {y:e} at {x:?}");
        }
    }

    #[test]
    fn rosenbrock_reaches_1e_8() {
        for (n, seed) in [(2, 1), (4, 2), (6, 3)] {
            let (x, y) = run(n, -2.0, 2.0, seed, rosenbrock);
            assert!(y < 1e-8, "n = {n}: {y:e} at {x:?}");
            assert!(x.iter().all(|v| (v - 1.0).abs() < 1e-3), "{x:?}");
        }
    }

    /// The optimum outside the box: the run ends on the wall, every candidate inside.
    #[test]
    fn a_bound_holds_the_optimum_on_the_wall() {
        let es = Cmaes::new(&[0.5, 0.1], &[0.0, 0.0], &[1.0, 0.2], 0.3, None, 5).unwrap();
        let (x, _, _) = minimize(es, 1e-10, 2000, |xs| {
            xs.iter()
                .map(|x| {
                    assert!(
                        x[0] >= 0.0 && x[0] <= 1.0 && x[1] >= 0.0 && x[1] <= 0.2,
                        "{x:?}"
                    );
                    (x[0] - 0.6).powi(2) + (x[1] - 0.7).powi(2)
                })
                .collect()
        });
        assert!(
            (x[0] - 0.6).abs() < 1e-6 && (x[1] - 0.2).abs() < 1e-6,
            "{x:?}"
        );
    }

    /// The same seed gives the same run bit for bit; failed evaluations rank last.
    #[test]
    fn a_seed_gives_the_same_run_and_nan_ranks_last() {
        let a = run(4, -2.0, 2.0, 11, rosenbrock);
        let b = run(4, -2.0, 2.0, 11, rosenbrock);
        assert_eq!(
            a.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        let es = Cmaes::new(&[0.0; 3], &[-1.0; 3], &[1.0; 3], 0.3, None, 3).unwrap();
        let (x, y, _) = minimize(es, 1e-9, 3000, |xs| {
            xs.iter()
                .map(|x| if x[0] < -0.5 { f64::NAN } else { sphere(x) })
                .collect()
        });
        assert!(y < 1e-8 && y.is_finite(), "{y} at {x:?}");
    }

    #[test]
    fn bad_settings_are_refused() {
        let e = |s: &[f64], lo: &[f64], hi: &[f64], sigma: f64| {
            Cmaes::new(s, lo, hi, sigma, None, 0).unwrap_err()
        };
        assert_eq!(
            e(&[0.5], &[1.0], &[0.0], 0.3),
            CmaesError::Bounds(0, 1.0, 0.0)
        );
        assert_eq!(
            e(&[2.0], &[0.0], &[1.0], 0.3),
            CmaesError::Start(0, 2.0, 0.0, 1.0)
        );
        assert_eq!(e(&[], &[], &[], 0.3), CmaesError::Empty);
        assert_eq!(e(&[0.5], &[0.0], &[1.0], 0.0), CmaesError::Sigma(0.0));
    }

    #[test]
    fn jacobi_recovers_a_known_decomposition() {
        let c = vec![
            vec![4.0, 1.0, 0.0],
            vec![1.0, 3.0, 1.0],
            vec![0.0, 1.0, 2.0],
        ];
        let (b, d) = eigen(&c);
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3).map(|k| b[i][k] * d[k] * d[k] * b[j][k]).sum();
                assert!((r - c[i][j]).abs() < 1e-12, "{i} {j}: {r}");
            }
        }
    }
}
