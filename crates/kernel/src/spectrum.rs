//! Response spectra: the peak response of damped single-degree-of-freedom oscillators to a base
//! acceleration (docs/model.md §5b).
//!
//! An oscillator of period T (ω = 2π/T) and damping ratio ζ on the base acceleration a_g(t):
//!   ü + 2ζω u̇ + ω² u = −a_g(t);
//! its pseudo-spectral acceleration is PSA(T) = ω²·max_t |u(t)|.
//!
//! **Exact for piecewise-linear input** (Nigam & Jennings 1969): between two ticks the base
//! acceleration is the straight line through its samples, and (u, u̇) advance by the exact
//! solution of that interval: [u, u̇]ₖ₊₁ = A·[u, u̇]ₖ + B·[a_k, a_{k+1}]. A and B are the matrix
//! exponential of the augmented system (u, u̇, a, ȧ) over one tick, computed here with the same
//! scaled Taylor series as the reference filter ([`super::expm::expm`]); they are the
//! Nigam–Jennings coefficients without transcribing their formulas. The peak is taken at the
//! ticks. `tests` check the recursion against the closed-form response to a ramp (exact for a
//! piecewise-linear input) and to a harmonic input at resonance.
//!
//! The spectrum of the achieved acceleration is accumulated online in the lane kernel
//! ([`SpectrumAcc`]: two states and a running peak per period and lane, no stored history); the
//! target's is computed once per reference ([`psa`]).

/// Where and how a response spectrum is taken.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumSpec {
    /// Oscillator periods, s (increasing).
    pub periods: Vec<f64>,
    /// Damping ratio ζ. Default 0.05 [chosen: the 5 %-damped spectrum of earthquake engineering].
    pub damping: f64,
    /// Periods over which the spectral error is taken, s: [low, high] (inclusive).
    pub band: (f64, f64),
}

impl SpectrumSpec {
    /// `count` periods log-spaced from `t_min` to `t_max` (both included), damping `damping`,
    /// the error band every period.
    pub fn log_spaced(t_min: f64, t_max: f64, count: usize, damping: f64) -> SpectrumSpec {
        let periods: Vec<f64> = if count == 1 {
            vec![t_min]
        } else {
            (0..count)
                .map(|i| t_min * (t_max / t_min).powf(i as f64 / (count - 1) as f64))
                .collect()
        };
        SpectrumSpec {
            periods,
            damping,
            band: (t_min, t_max),
        }
    }

    /// Indices of the periods inside the error band.
    pub fn in_band(&self) -> impl Iterator<Item = usize> + '_ {
        // A relative slack of 1e-12 so that log-spaced end points computed by powf stay in.
        let (lo, hi) = self.band;
        self.periods
            .iter()
            .enumerate()
            .filter(move |(_, t)| **t >= lo * (1.0 - 1e-12) && **t <= hi * (1.0 + 1e-12))
            .map(|(i, _)| i)
    }

    /// The mean and the largest |ln(PSA_achieved / PSA_target)| over the band.
    pub fn error(&self, achieved: &[f64], target: &[f64]) -> (f64, f64) {
        let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
        for i in self.in_band() {
            let e = (achieved[i] / target[i]).ln().abs();
            sum += e;
            max = max.max(e);
            n += 1;
        }
        if n == 0 {
            (f64::NAN, f64::NAN)
        } else {
            (sum / n as f64, max)
        }
    }
}

/// One oscillator's exact one-tick map: u' = a11 u + a12 v + b11 a_k + b12 a_{k+1}, v' likewise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillator {
    pub a: [[f64; 2]; 2],
    pub b: [[f64; 2]; 2],
    /// ω², to turn a peak displacement into a pseudo-acceleration.
    pub w2: f64,
}

impl Oscillator {
    /// Period `t` s, damping ratio `zeta`, tick `dt` s.
    pub fn new(t: f64, zeta: f64, dt: f64) -> Oscillator {
        let w = 2.0 * std::f64::consts::PI / t;
        // States (u, u̇, g, s) with g the base acceleration and s its slope over the tick:
        // u̇ = u̇, ü = −ω²u − 2ζωu̇ − g, ġ = s, ṡ = 0. Times dt; the fifth row/column unused.
        let mut m = [[0.0f64; 5]; 5];
        m[0][1] = dt;
        m[1][0] = -w * w * dt;
        m[1][1] = -2.0 * zeta * w * dt;
        m[1][2] = -dt;
        m[2][3] = dt;
        let e = super::expm::expm(&m);
        // [u, v](dt) = E[0..2][0..2]·[u, v] + E[·][2]·a_k + E[·][3]·(a_{k+1} − a_k)/dt.
        let b = |r: usize| [e[r][2] - e[r][3] / dt, e[r][3] / dt];
        Oscillator {
            a: [[e[0][0], e[0][1]], [e[1][0], e[1][1]]],
            b: [b(0), b(1)],
            w2: w * w,
        }
    }

    /// One tick: (u, v) with the base acceleration going from `a0` to `a1`.
    #[inline(always)]
    pub fn step(&self, u: f64, v: f64, a0: f64, a1: f64) -> (f64, f64) {
        (
            self.a[0][0] * u + self.a[0][1] * v + self.b[0][0] * a0 + self.b[0][1] * a1,
            self.a[1][0] * u + self.a[1][1] * v + self.b[1][0] * a0 + self.b[1][1] * a1,
        )
    }
}

/// The oscillators of `spec` at tick `dt`.
pub fn oscillators(spec: &SpectrumSpec, dt: f64) -> Vec<Oscillator> {
    spec.periods
        .iter()
        .map(|&t| Oscillator::new(t, spec.damping, dt))
        .collect()
}

/// PSA at every period of `spec` for the acceleration `accel` sampled every `dt` s, starting at
/// rest (same units as `accel`).
pub fn psa(accel: &[f64], dt: f64, spec: &SpectrumSpec) -> Vec<f64> {
    oscillators(spec, dt)
        .iter()
        .map(|o| {
            let (mut u, mut v, mut peak) = (0.0, 0.0, 0.0f64);
            for w in accel.windows(2) {
                (u, v) = o.step(u, v, w[0], w[1]);
                peak = peak.max(u.abs());
            }
            o.w2 * peak
        })
        .collect()
}

/// The online spectrum of N lanes' accelerations: per period and lane the oscillator's state and
/// running peak. Allocated once per run; nothing is allocated per tick.
#[derive(Debug, Clone)]
pub struct SpectrumAcc<const N: usize> {
    osc: Vec<Oscillator>,
    u: Vec<[f64; N]>,
    v: Vec<[f64; N]>,
    peak: Vec<[f64; N]>,
    prev: [f64; N],
    started: bool,
}

impl<const N: usize> SpectrumAcc<N> {
    pub fn new(spec: &SpectrumSpec, dt: f64) -> Self {
        let p = spec.periods.len();
        SpectrumAcc {
            osc: oscillators(spec, dt),
            u: vec![[0.0; N]; p],
            v: vec![[0.0; N]; p],
            peak: vec![[0.0; N]; p],
            prev: [0.0; N],
            started: false,
        }
    }

    /// The acceleration of every lane at the next tick (the first tick only sets the start).
    #[inline(always)]
    pub fn tick(&mut self, a: &[f64; N]) {
        if self.started {
            for (i, o) in self.osc.iter().enumerate() {
                let (u, v, peak) = (&mut self.u[i], &mut self.v[i], &mut self.peak[i]);
                for l in 0..N {
                    let (un, vn) = o.step(u[l], v[l], self.prev[l], a[l]);
                    u[l] = un;
                    v[l] = vn;
                    peak[l] = peak[l].max(un.abs());
                }
            }
        }
        self.started = true;
        self.prev = *a;
    }

    /// Lane `l`'s PSA at every period.
    /// Sets lane `l`'s peak oscillator displacements (m), one per period: what another engine
    /// accumulated (the CUDA kernel), for [`SpectrumAcc::psa`].
    pub(crate) fn set_peaks(&mut self, l: usize, peaks: &[f64]) {
        for (p, &v) in self.peak.iter_mut().zip(peaks) {
            p[l] = v;
        }
    }

    pub fn psa(&self, l: usize) -> Vec<f64> {
        self.osc
            .iter()
            .zip(&self.peak)
            .map(|(o, p)| o.w2 * p[l])
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Response from rest to a_g = c·t (a ramp is piecewise linear, so the recursion must be
    /// exact up to rounding): u = −(c/ω²)(t − 2ζ/ω) + e^{−ζωt}(C₁ cos ω_d t + C₂ sin ω_d t).
    #[test]
    fn a_ramp_is_followed_exactly() {
        let (t_n, zeta, dt, c): (f64, f64, f64, f64) = (0.7, 0.05, 1.0 / 1024.0, 3.0);
        let w = 2.0 * PI / t_n;
        let wd = w * (1.0 - zeta * zeta).sqrt();
        let c1 = -2.0 * zeta * c / w.powi(3);
        // u̇(0) = 0: −c/ω² − ζω C₁ + ω_d C₂ = 0.
        let c2 = (c / (w * w) + zeta * w * c1) / wd;
        let exact = |t: f64| {
            -(c / (w * w)) * (t - 2.0 * zeta / w)
                + (-zeta * w * t).exp() * (c1 * (wd * t).cos() + c2 * (wd * t).sin())
        };
        let o = Oscillator::new(t_n, zeta, dt);
        let (mut u, mut v) = (0.0, 0.0);
        let mut worst = 0.0f64;
        for k in 0..4096 {
            (u, v) = o.step(u, v, c * k as f64 * dt, c * (k + 1) as f64 * dt);
            let t = (k + 1) as f64 * dt;
            worst = worst.max((u - exact(t)).abs() / (c / (w * w) * t));
        }
        assert!(worst < 1e-10, "relative error {worst:e}");
    }

    /// A harmonic base acceleration A sin ωt at the oscillator's own frequency, from rest:
    /// u = (A/(2ζω²))·[cos ωt − e^{−ζωt}(cos ω_d t + (ζω/ω_d) sin ω_d t)]. Sampled finely enough
    /// that the straight lines between samples differ from the sine by less than 1e-8
    /// ((ω·dt)²/12), the PSA must match ω²·max|u| of the closed form to 1e-6.
    #[test]
    fn the_spectrum_at_resonance_matches_the_closed_form() {
        for (t_n, zeta) in [(1.0f64, 0.05f64), (0.25, 0.05), (2.0, 0.02)] {
            let (w, amp, f_s) = (2.0 * PI / t_n, 2.5, 32768.0);
            let dt = 1.0 / f_s;
            let wd = w * (1.0 - zeta * zeta).sqrt();
            let big = amp / (2.0 * zeta * w * w);
            let exact = |t: f64| {
                big * ((w * t).cos()
                    - (-zeta * w * t).exp() * ((wd * t).cos() + zeta * w / wd * (wd * t).sin()))
            };
            let n = (8.0 * t_n * f_s) as usize;
            let accel: Vec<f64> = (0..=n).map(|k| amp * (w * k as f64 * dt).sin()).collect();
            let spec = SpectrumSpec {
                periods: vec![t_n],
                damping: zeta,
                band: (t_n, t_n),
            };
            let got = psa(&accel, dt, &spec)[0];
            let want = w
                * w
                * (0..=n)
                    .map(|k| exact(k as f64 * dt).abs())
                    .fold(0.0, f64::max);
            assert!(
                (got / want - 1.0).abs() < 1e-6,
                "T {t_n} s: {got} vs {want}"
            );
            // And the online accumulator gives the same bits as the offline spectrum.
            let mut acc = SpectrumAcc::<2>::new(&spec, dt);
            accel.iter().for_each(|&a| acc.tick(&[a, 0.5 * a]));
            assert_eq!(acc.psa(0)[0], got);
            assert_eq!(
                acc.psa(1)[0],
                psa(
                    &accel.iter().map(|a| 0.5 * a).collect::<Vec<_>>(),
                    dt,
                    &spec
                )[0]
            );
        }
    }

    #[test]
    fn peaks_set_from_another_engine_give_the_psa_of_their_lane() {
        let s = SpectrumSpec::log_spaced(0.1, 2.0, 5, 0.05);
        let mut acc = SpectrumAcc::<4>::new(&s, 1.0 / 1024.0);
        let peaks = [0.01, 0.02, 0.03, 0.04, 0.05];
        acc.set_peaks(2, &peaks);
        for (k, (psa, p)) in acc.psa(2).iter().zip(peaks).enumerate() {
            let w = 2.0 * std::f64::consts::PI / s.periods[k];
            assert!(
                (psa - w * w * p).abs() <= 1e-12 * psa.abs(),
                "period {k}: {psa}"
            );
        }
        assert!(
            acc.psa(1).iter().all(|&a| a == 0.0),
            "another lane is untouched"
        );
    }

    #[test]
    fn log_spacing_and_band_error() {
        let s = SpectrumSpec::log_spaced(0.05, 4.0, 20, 0.05);
        assert_eq!(s.periods.len(), 20);
        assert!((s.periods[0] - 0.05).abs() < 1e-15 && (s.periods[19] - 4.0).abs() < 1e-12);
        assert_eq!(s.in_band().count(), 20);
        // A target of its own at each period: the error is a ratio, not a product.
        let target: Vec<f64> = (0..20).map(|i| 0.3 + 0.1 * i as f64).collect();
        let mut got = target.clone();
        got[3] *= 2.0;
        got[7] *= 0.5;
        let (mean, max) = s.error(&got, &target);
        assert!((max - 2f64.ln()).abs() < 1e-15, "{max}");
        assert!((mean - 2.0 * 2f64.ln() / 20.0).abs() < 1e-15, "{mean}");
    }
}
