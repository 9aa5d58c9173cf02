//! What the adaptive compensators of the controller share (docs/model.md §8): the phase of the
//! reference, read from its four states, and one harmonic's canceller, an LMS on the sine and
//! cosine of a correction at k times the reference's frequency. Amplitude/phase control
//! (`amplitude_phase`, k = 1) and adaptive harmonic cancellation (`harmonic_cancellation`, k = 3,
//! 5, 7, 9) are each a few of these cancellers; this file is not an effect.
//!
//! **The phase.** For a sine x_r = A sin θ (its amplitude slow against θ) the four reference
//! states give, with no clock and no knowledge of the excitation,
//!
//! ```text
//! ω² = (a_r² − v_r·j_r) / (v_r² − x_r·a_r),   (cos θ, sin θ) = (v_r, ω·x_r) / |(v_r, ω·x_r)|,
//! A = |(v_r, ω·x_r)| / ω
//! ```
//!
//! exact for a sine, the instantaneous frequency of a slow sweep. Where the states are not a
//! sine's (ω² ≤ 0 or undefined: the table at rest, a broadband record) there is no phase, and the
//! cancellers neither adapt nor act.
//!
//! **One canceller** (harmonic k, Ω = kω). A signal at Ω is written Re{Z·e^{jkθ}}, Z its phasor.
//! At each tick, with the displacement error e = x_r − x and T = 1/f_s:
//!
//! ```text
//! E ← E + λ·(2e·e^{−jkθ} − E)                 the error's k-th harmonic (a band filter at Ω:
//!                                              demodulation, then a low-pass, λ = 1 − e^{−2π B T})
//! D ← D + μ·e^{jΩτ}·E,  |D| ≤ authority·A      the correction's LMS step (μ = g·T) through the
//!                                              plant model e^{−jΩτ}, unless frozen (t ≥ t_freeze > 0)
//! u ← u + Re{F(jΩ)·D·e^{jkθ}}                  the correction, entered as the TVC enters a reference
//! ```
//!
//! where F(s) = c_fb + c_d + c_v·s + c_a·s² + c_j·s³ is the TVC's reference path (docs/model.md
//! §2): the correction acts as a displacement D·e^{jkθ} added to the reference, so the plant it
//! adapts through is the closed loop from reference to feedback, near 1 in the band the TVC
//! tracks. Its phase is modelled as a delay τ (the closed loop's lag); the LMS converges while
//! the model's phase is within 90° of the loop's, at the rate g·|T(jΩ)|·cos(phase error) (the
//! tests below check that rate on a known linear plant). At convergence the k-th harmonic of the
//! error is zero: for k = 1 the fundamental's amplitude ratio is 1 and its phase 0.

use crate::baseline_params::ControllerParams;

/// The reference's phase at a tick: frequency ω (rad/s), amplitude A (m) and the unit phasor
/// (cos θ, sin θ) with x_r = A sin θ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phase {
    pub omega: f64,
    pub amp: f64,
    pub cos: f64,
    pub sin: f64,
}

impl Phase {
    /// The phase of the reference states `r` = [x, v, a, j], or `None` where they are not a
    /// sine's (see the module's note).
    #[inline(always)]
    pub fn of(r: [f64; 4]) -> Option<Phase> {
        let [x, v, a, j] = r;
        let w2 = (a * a - v * j) / (v * v - x * a);
        if !(w2 > 0.0 && w2.is_finite()) {
            return None;
        }
        let omega = w2.sqrt();
        let wx = omega * x;
        let n = (v * v + wx * wx).sqrt();
        if !(n > 0.0) {
            return None;
        }
        Some(Phase {
            omega,
            amp: n / omega,
            cos: v / n,
            sin: wx / n,
        })
    }

    /// (cos kθ, sin kθ), by k − 1 complex products.
    #[inline(always)]
    pub fn harmonic(&self, k: usize) -> (f64, f64) {
        let (mut c, mut s) = (self.cos, self.sin);
        for _ in 1..k {
            (c, s) = (c * self.cos - s * self.sin, s * self.cos + c * self.sin);
        }
        (c, s)
    }
}

/// A canceller's settings, one lane's (from the compensator's parameters and the controller's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// 1 where the compensator is on in the lane, 0 where off.
    pub on: f64,
    /// LMS step μ = g/f_s.
    pub mu: f64,
    /// Band filter's low-pass λ = 1 − exp(−2π·B/f_s).
    pub lambda: f64,
    /// The plant model's delay τ, s.
    pub tau: f64,
    /// Largest |D| as a fraction of the reference's amplitude.
    pub authority: f64,
    /// Time from which D is held (0: adapts to the end), s.
    pub freeze_s: f64,
    /// The TVC's reference path: c_fb + c_d, c_v, c_a, c_j (V/m, V/(m/s), V/(m/s²), V/(m/s³)).
    pub f: [f64; 4],
}

impl Settings {
    /// Settings from the rate g (1/s), the band B (Hz), the delay τ (s), the authority, the freeze
    /// time (s) and the controller `c`.
    pub fn new(
        on: bool,
        [g, band, tau, authority, freeze_s]: [f64; 5],
        c: &ControllerParams,
    ) -> Self {
        let [c_fb, c_d, c_v, c_a, c_j, _] = c.gains();
        Settings {
            on: if on { 1.0 } else { 0.0 },
            mu: g / c.f_s,
            lambda: 1.0 - (-2.0 * std::f64::consts::PI * band / c.f_s).exp(),
            tau,
            authority,
            freeze_s,
            f: [c_fb + c_d, c_v, c_a, c_j],
        }
    }

    /// The record the CUDA kernel reads (`crates/kernel/src/cuda/lane.cu`: on, μ, λ, τ,
    /// authority, freeze time; F's coefficients are the controller's own fields there).
    pub fn lane(&self) -> [f64; 6] {
        [
            self.on,
            self.mu,
            self.lambda,
            self.tau,
            self.authority,
            self.freeze_s,
        ]
    }

    /// F(jΩ) = (c_fb + c_d − c_a·Ω²) + j·(c_v·Ω − c_j·Ω³).
    #[inline(always)]
    pub fn reference_path(&self, big_omega: f64) -> (f64, f64) {
        let w2 = big_omega * big_omega;
        (
            self.f[0] - self.f[2] * w2,
            big_omega * (self.f[1] - self.f[3] * w2),
        )
    }
}

/// One tick of the canceller of harmonic `k` whose states are `st` = [D_re, D_im, E_re, E_im]:
/// the band filter and the LMS step (unless frozen at `t`), then the correction to the command
/// (V), from the error `e` (m) and the reference's phase `ph`.
#[inline(always)]
pub fn cancel(set: &Settings, k: usize, ph: &Phase, e: f64, t: f64, st: [&mut f64; 4]) -> f64 {
    let [d_re, d_im, e_re, e_im] = st;
    let (c, s) = ph.harmonic(k);
    let big_omega = k as f64 * ph.omega;
    *e_re += set.lambda * (2.0 * e * c - *e_re);
    *e_im += set.lambda * (-2.0 * e * s - *e_im);
    if !(set.freeze_s > 0.0 && t >= set.freeze_s) {
        let phi = big_omega * set.tau;
        let (pc, ps) = (phi.cos(), phi.sin());
        *d_re += set.mu * (pc * *e_re - ps * *e_im);
        *d_im += set.mu * (ps * *e_re + pc * *e_im);
        let cap = set.authority * ph.amp;
        let size = (*d_re * *d_re + *d_im * *d_im).sqrt();
        if size > cap {
            *d_re *= cap / size;
            *d_im *= cap / size;
        }
    }
    let (f_re, f_im) = set.reference_path(big_omega);
    let (z_re, z_im) = (f_re * *d_re - f_im * *d_im, f_re * *d_im + f_im * *d_re);
    z_re * c - z_im * s
}

/// A controller at `f_s` Hz whose reference path is F(s) = 1 (c_fb = 1 V/m, no feedforward), so
/// that a command's volts are metres: the known plants of the compensators' unit tests.
#[cfg(test)]
pub(crate) fn unit_reference_path(f_s: f64) -> ControllerParams {
    ControllerParams {
        f_s,
        g_d: 0.1,
        d_max: 1.0,
        l_d: 0.0,
        l_v: 0.0,
        l_a: 0.0,
        l_j: 0.0,
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The states of A·sin(ωt + φ) at t.
    fn sine(amp: f64, w: f64, phi: f64, t: f64) -> [f64; 4] {
        let th = w * t + phi;
        [
            amp * th.sin(),
            amp * w * th.cos(),
            -amp * w * w * th.sin(),
            -amp * w * w * w * th.cos(),
        ]
    }

    #[test]
    fn a_sines_phase_is_read_from_its_states() {
        for (amp, f, phi) in [(0.1, 3.0, 0.3), (2e-3, 9.5, -2.0), (0.4, 0.7, 4.0)] {
            let w = 2.0 * std::f64::consts::PI * f;
            let p = Phase::of(sine(amp, w, phi, 0.37)).unwrap();
            let th: f64 = w * 0.37 + phi;
            assert!((p.omega / w - 1.0).abs() < 1e-12, "{f}");
            assert!((p.amp / amp - 1.0).abs() < 1e-12, "{f}");
            assert!((p.cos - th.cos()).abs() < 1e-12 && (p.sin - th.sin()).abs() < 1e-12);
            let (c5, s5) = p.harmonic(5);
            assert!((c5 - (5.0 * th).cos()).abs() < 1e-11 && (s5 - (5.0 * th).sin()).abs() < 1e-11);
        }
        assert_eq!(Phase::of([0.0; 4]), None, "at rest");
        assert_eq!(
            Phase::of([1.0, 1.0, 5.0, 0.0]),
            None,
            "a = +5x: not a sine (ω² < 0)"
        );
    }

    /// A known linear plant, y(t) = g_p·(r + d)(t − τ_p) + w(t): a gain and a delay of whole
    /// ticks on the reference and the correction d (F(s) = 1, so the correction's volts are
    /// metres), plus a disturbance w. Returns the error's phasor at harmonic `k` over each second
    /// (by a DFT over whole periods) and the final states.
    struct Plant {
        g_p: f64,
        lag: usize,
        w: f64,
        w_phase: f64,
    }

    const FS: f64 = 1024.0;
    const F0: f64 = 2.0;

    fn settings(g: f64, tau: f64, authority: f64, freeze_s: f64) -> Settings {
        let c = unit_reference_path(FS);
        Settings::new(true, [g, 10.0, tau, authority, freeze_s], &c)
    }

    fn run(plant: &Plant, set: &Settings, k: usize, seconds: usize) -> (Vec<f64>, [f64; 4]) {
        let w = 2.0 * std::f64::consts::PI * F0;
        let n = seconds * FS as usize;
        let mut sent = vec![0.0; n];
        let mut st = [0.0; 4];
        let mut sizes = Vec::new();
        let (mut re, mut im) = (0.0, 0.0);
        for i in 0..n {
            let t = i as f64 / FS;
            let r = sine(0.1, w, 0.0, t);
            let past = if i >= plant.lag {
                sent[i - plant.lag]
            } else {
                0.0
            };
            let y = plant.g_p * past + plant.w * (k as f64 * w * t + plant.w_phase).sin();
            let e = r[0] - y;
            let ph = Phase::of(r).unwrap();
            let [a, b, c, d] = &mut st;
            let u = cancel(set, k, &ph, e, t, [a, b, c, d]) / set.f[0];
            sent[i] = r[0] + u;
            let th = k as f64 * w * t;
            re += e * th.cos();
            im += e * th.sin();
            if (i + 1) % FS as usize == 0 {
                sizes.push(2.0 * (re * re + im * im).sqrt() / FS);
                (re, im) = (0.0, 0.0);
            }
        }
        (sizes, st)
    }

    /// The fundamental (k = 1, amplitude/phase control) through a plant of gain 0.9 and 9.8 ms
    /// of lag, modelled exactly: the error's fundamental falls as e^{−g·g_p·t} (the LMS's
    /// theory), to nothing: amplitude ratio 1, phase 0.
    #[test]
    fn the_fundamental_converges_at_the_rate_theory_gives() {
        let plant = Plant {
            g_p: 0.9,
            lag: 10,
            w: 0.0,
            w_phase: 0.0,
        };
        let (g, tau) = (1.5, 10.0 / FS);
        let (sizes, _) = run(&plant, &settings(g, tau, 1.0, 0.0), 1, 12);
        // Seconds 2 to 5: the decay rate against g·g_p (the band filter's lag adds a few %).
        let rate = (sizes[1] / sizes[4]).ln() / 3.0;
        assert!(
            (rate / (g * plant.g_p) - 1.0).abs() < 0.1,
            "rate {rate} vs {}",
            g * plant.g_p
        );
        assert!(sizes[11] < 1e-6 * 0.1, "{sizes:?}");
    }

    /// A model phase 40° off the plant's slows the decay by cos 40° (the LMS's theory).
    #[test]
    fn a_wrong_phase_model_slows_it_by_its_cosine() {
        let plant = Plant {
            g_p: 1.0,
            lag: 10,
            w: 0.0,
            w_phase: 0.0,
        };
        let w = 2.0 * std::f64::consts::PI * F0;
        let off = 40f64.to_radians();
        let tau = 10.0 / FS + off / w;
        let (sizes, _) = run(&plant, &settings(1.5, tau, 1.0, 0.0), 1, 12);
        let rate = (sizes[1] / sizes[4]).ln() / 3.0;
        let theory = 1.5 * off.cos();
        assert!((rate / theory - 1.0).abs() < 0.1, "rate {rate} vs {theory}");
    }

    /// A 3rd harmonic disturbance at the output is cancelled by the canceller at k = 3: the
    /// correction converges to −w/g_p at the plant's phase; with a freeze at 1 s it stops where
    /// it was, and an authority below |w|/g_p leaves it at the cap.
    #[test]
    fn a_harmonic_disturbance_is_cancelled_frozen_and_capped() {
        let plant = Plant {
            g_p: 0.8,
            lag: 6,
            w: 4e-3,
            w_phase: 0.7,
        };
        let tau = 6.0 / FS;
        let (sizes, st) = run(&plant, &settings(3.0, tau, 1.0, 0.0), 3, 10);
        let rate = (sizes[1] / sizes[4]).ln() / 3.0;
        assert!(
            (rate / (3.0 * plant.g_p) - 1.0).abs() < 0.1,
            "rate {rate}: {sizes:?}"
        );
        assert!(sizes[9] < 1e-9 * plant.w, "{sizes:?}");
        let size = (st[0] * st[0] + st[1] * st[1]).sqrt();
        // |D| = w/g_p, give or take the ripple the fundamental's error (not cancelled here)
        // leaves after demodulation at 3θ (at 2ω and 4ω, which the band filter only halves).
        assert!((size / (plant.w / plant.g_p) - 1.0).abs() < 0.1, "{size}");
        let (frozen, _) = run(&plant, &settings(3.0, tau, 1.0, 1.0), 3, 6);
        assert!((frozen[5] / frozen[2] - 1.0).abs() < 1e-6, "{frozen:?}");
        assert!(
            frozen[5] < 0.9 * plant.w && frozen[5] > 10.0 * sizes[9],
            "{frozen:?}"
        );
        let (_, capped) = run(&plant, &settings(3.0, tau, 0.02, 0.0), 3, 10);
        let size = (capped[0] * capped[0] + capped[1] * capped[1]).sqrt();
        // At the cap, or just inside it where the last step's ripple pointed inward.
        let cap = 0.02 * 0.1;
        assert!(size <= cap * (1.0 + 1e-12) && size > 0.98 * cap, "{size}");
    }
}
