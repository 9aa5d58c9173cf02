//! Excitations: the reference states (x_r, v_r, a_r, j_r) at every controller tick (docs/model.md §4).
//!
//! They are computed once, before a run, into a [`Reference`] that every lane of a batch shares,
//! so the tick loop reads arrays and never branches on the excitation kind.
//!
//! - **sine**: x_r = X·e(t)·sin(2πft), e = ½(1 − cos(πt/T_taper)) for t < T_taper, else 1;
//!   v_r, a_r, j_r are the exact derivatives (product rule with e's derivatives).
//! - **record**: a sampled displacement record, linearly interpolated to the ticks, then a discrete
//!   4th-order critically damped state-variable filter H(s) = ω⁴/(s+ω)⁴, ω = 2π f_ref, whose four
//!   states are (x_r, v_r, a_r, j_r) [chosen: all four reference states come from the filter so
//!   they are mutually consistent; the filter is discretised exactly for a zero-order-held input
//!   (matrix exponential), and starts at rest at the first record value].

use super::spectrum::SpectrumSpec;
use std::f64::consts::PI;

/// Reference states at every tick, plus what the metrics need to know about them.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Controller rate, Hz.
    pub f_s: f64,
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    pub j: Vec<f64>,
    /// The reference displacement command before any filter (a sine: x_r itself; a record: the
    /// record interpolated to the ticks), m — what a controller log calls the reference.
    pub command: Vec<f64>,
    /// Ticks of the analysis window, [start, end).
    pub window: (usize, usize),
    /// Fundamental frequency for the harmonic metrics, Hz (`None` for records).
    pub fundamental_hz: Option<f64>,
    /// What moves the spool: the controller (the default) or a measured column (open loop).
    pub drive: Drive,
    /// The response spectrum the metrics take, with the target's PSA (of `a` over the window),
    /// m/s² ([`Reference::with_spectrum`]); `None`: no spectral metrics.
    pub spectrum: Option<(SpectrumSpec, Vec<f64>)>,
}

/// What moves the spool.
///
/// Open loop drives the plant with a measured column instead of the controller, to separate
/// the plant's error from the controller's. The reference still gives the analysis window and
/// the phase reference of the metrics.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum Drive {
    /// The three-variable controller closes the loop (docs/model.md §3).
    #[default]
    ClosedLoop,
    /// A valve command per tick, V: clamped to ±u_lim like the controller's output, then
    /// x_c = k_sp·u goes through the valve effects (delay, spool dynamics) as usual.
    ValveCommand(Vec<f64>),
    /// A spool position per tick, m; the spool command held over [t_k, t_{k+1}) is the mean of
    /// the samples at t_k and t_{k+1} (the measured spool moves continuously). A measured spool already
    /// contains the valve's own dynamics, so the caller switches the delay and spool-dynamics
    /// effects off for this drive.
    Spool(Vec<f64>),
}

impl Reference {
    /// An empty reference with room for `n` ticks; the window is every tick until set.
    fn with_capacity(f_s: f64, n: usize, fundamental_hz: Option<f64>) -> Self {
        Reference {
            f_s,
            x: Vec::with_capacity(n),
            v: Vec::with_capacity(n),
            a: Vec::with_capacity(n),
            j: Vec::with_capacity(n),
            command: Vec::with_capacity(n),
            window: (0, n),
            fundamental_hz,
            drive: Drive::ClosedLoop,
            spectrum: None,
        }
    }

    /// A reference from its states (x, v, a, j) at every tick (the command is x); the window is
    /// every tick, no fundamental.
    pub fn from_states(f_s: f64, states: &[[f64; 4]]) -> Self {
        let mut r = Reference::with_capacity(f_s, states.len(), None);
        states.iter().for_each(|s| r.push(*s, s[0]));
        r
    }

    /// Appends one tick: the states (x, v, a, j) and the command.
    fn push(&mut self, s: [f64; 4], command: f64) {
        self.x.push(s[0]);
        self.v.push(s[1]);
        self.a.push(s[2]);
        self.j.push(s[3]);
        self.command.push(command);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// Time of tick k, s.
    pub fn time(&self, k: usize) -> f64 {
        k as f64 / self.f_s
    }

    /// The same reference with a response spectrum: the target's PSA is the spectrum of `a` over
    /// the window.
    pub fn with_spectrum(mut self, spec: SpectrumSpec) -> Self {
        let (w0, w1) = self.window;
        let target = super::spectrum::psa(&self.a[w0..w1], 1.0 / self.f_s, &spec);
        self.spectrum = Some((spec, target));
        self
    }

    /// Peaks over the window: (max |x_r|, max |v_r|, max |a_r|).
    pub fn peaks(&self) -> (f64, f64, f64) {
        let (w0, w1) = self.window;
        let peak = |v: &[f64]| v[w0..w1].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        (peak(&self.x), peak(&self.v), peak(&self.a))
    }

    /// Keeps the first `n` ticks (the window is clipped to them).
    pub fn truncate(&mut self, n: usize) {
        for v in [
            &mut self.x,
            &mut self.v,
            &mut self.a,
            &mut self.j,
            &mut self.command,
        ] {
            v.truncate(n);
        }
        self.window = (self.window.0.min(n), self.window.1.min(n));
    }

    /// Lengthens the reference to `n` ticks by holding its last tick (states and command). A
    /// run needs a tick beyond the last time it is sampled at ([`super::resample::Resampler`]);
    /// a held tick at the end changes nothing before it.
    pub fn hold_to(&mut self, n: usize) {
        while !self.is_empty() && self.len() < n {
            let k = self.len() - 1;
            let (s, c) = (
                [self.x[k], self.v[k], self.a[k], self.j[k]],
                self.command[k],
            );
            self.push(s, c);
        }
    }

    /// Channel `values` (one per tick) at time `t`, by the cubic through the four nearest ticks
    /// (held beyond the ends).
    pub fn at_time(&self, values: &[f64], t: f64) -> f64 {
        let p = t * self.f_s;
        let n = values.len();
        if n == 0 {
            return f64::NAN;
        }
        let k = p.floor();
        if p == k && (k as usize) < n {
            return values[k as usize];
        }
        if n < 4 || p <= 0.0 || p >= (n - 1) as f64 {
            return values[(p.round().max(0.0) as usize).min(n - 1)];
        }
        let j0 = (k as usize).saturating_sub(1).min(n - 4);
        (0..4)
            .map(|i| {
                let xi = (j0 + i) as f64;
                let w: f64 = (0..4)
                    .filter(|&q| q != i)
                    .map(|q| (p - (j0 + q) as f64) / (xi - (j0 + q) as f64))
                    .product();
                w * values[j0 + i]
            })
            .sum()
    }
}

/// Sine excitation (docs/model.md §4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sine {
    /// Frequency f, Hz.
    pub freq_hz: f64,
    /// Displacement amplitude X, m (from g: X = a·g/(2πf)²).
    pub amp_m: f64,
    /// Half-cosine taper-in time, s (0 = none). Default 1 s.
    pub taper_s: f64,
    /// Run length, s: ticks k = 0 … round(duration·f_s) − 1.
    pub duration_s: f64,
    /// Whole cycles in the analysis window (ending at the last tick); `None` = every whole cycle
    /// after T_taper + 1 s.
    pub window_cycles: Option<u32>,
}

impl Sine {
    /// Displacement amplitude for an acceleration amplitude in g.
    pub fn amp_from_g(amp_g: f64, freq_hz: f64) -> f64 {
        amp_g * super::params::G / (2.0 * PI * freq_hz).powi(2)
    }

    /// Number of whole cycles in the default window.
    pub fn default_cycles(&self) -> u32 {
        ((self.duration_s - self.taper_s - 1.0) * self.freq_hz)
            .floor()
            .max(0.0) as u32
    }

    /// Reference states at time t.
    pub fn states(&self, t: f64) -> [f64; 4] {
        let w = 2.0 * PI * self.freq_hz;
        let (s, c) = (w * t).sin_cos();
        let sd = [s, w * c, -w * w * s, -w * w * w * c];
        let ed = if t < self.taper_s {
            let p = PI / self.taper_s;
            let (ps, pc) = (p * t).sin_cos();
            [
                0.5 * (1.0 - pc),
                0.5 * p * ps,
                0.5 * p * p * pc,
                -0.5 * p * p * p * ps,
            ]
        } else {
            [1.0, 0.0, 0.0, 0.0]
        };
        let x = self.amp_m;
        [
            x * ed[0] * sd[0],
            x * (ed[1] * sd[0] + ed[0] * sd[1]),
            x * (ed[2] * sd[0] + 2.0 * ed[1] * sd[1] + ed[0] * sd[2]),
            x * (ed[3] * sd[0] + 3.0 * ed[2] * sd[1] + 3.0 * ed[1] * sd[2] + ed[0] * sd[3]),
        ]
    }

    /// Reference displacement x_r at time t (0 before the start, t < 0), m.
    pub fn displacement(&self, t: f64) -> f64 {
        if t < 0.0 {
            return 0.0;
        }
        let e = if t < self.taper_s {
            0.5 * (1.0 - (PI * t / self.taper_s).cos())
        } else {
            1.0
        };
        self.amp_m * e * (2.0 * PI * self.freq_hz * t).sin()
    }

    /// The reference at controller rate f_s.
    pub fn reference(&self, f_s: f64) -> Reference {
        let n = (self.duration_s * f_s).round() as usize;
        let mut r = Reference::with_capacity(f_s, n, Some(self.freq_hz));
        for k in 0..n {
            let s = self.states(k as f64 / f_s);
            r.push(s, s[0]);
        }
        let cycles = self.window_cycles.unwrap_or_else(|| self.default_cycles());
        let len = ((cycles as f64) * f_s / self.freq_hz).round() as usize;
        r.window = (n.saturating_sub(len), n);
        r
    }
}

/// Sampled displacement record (docs/model.md §4).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Sample times, s (strictly increasing).
    pub time_s: Vec<f64>,
    /// Displacement, m.
    pub disp_m: Vec<f64>,
    /// Corner of the state-variable filter, Hz. Default 50 Hz.
    pub f_ref_hz: f64,
}

impl Record {
    /// The reference at controller rate f_s, ticks from the first to the last record time.
    ///
    /// Panics if the record has fewer than two samples or times that do not increase; the
    /// orchestration layer validates records (with file, column and row) before they get here.
    pub fn reference(&self, f_s: f64) -> Reference {
        assert!(self.time_s.len() >= 2 && self.time_s.len() == self.disp_m.len());
        let t0 = self.time_s[0];
        let span = self.time_s[self.time_s.len() - 1] - t0;
        let n = (span * f_s).floor() as usize + 1;
        let (phi, gam) = svf_discrete(2.0 * PI * self.f_ref_hz, 1.0 / f_s);
        let mut r = Reference::with_capacity(f_s, n, None);
        let mut s = [self.disp_m[0], 0.0, 0.0, 0.0];
        let mut i = 0;
        for k in 0..n {
            let t = t0 + k as f64 / f_s;
            while i + 2 < self.time_s.len() && self.time_s[i + 1] <= t {
                i += 1;
            }
            let (ta, tb) = (self.time_s[i], self.time_s[i + 1]);
            let w = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
            let u = self.disp_m[i] + w * (self.disp_m[i + 1] - self.disp_m[i]);
            r.push(s, u);
            let mut next = [0.0; 4];
            for (row, out) in next.iter_mut().enumerate() {
                *out = (0..4).map(|c| phi[row][c] * s[c]).sum::<f64>() + gam[row] * u;
            }
            s = next;
        }
        r
    }
}

/// Exact zero-order-hold discretisation of the critically damped 4th-order filter ω⁴/(s+ω)⁴ in
/// the states (x, ẋ, ẍ, x⃛): returns (Φ, Γ) with s[k+1] = Φ s[k] + Γ u[k].
///
/// Computed in the scaled states ξ_i = x⁽ⁱ⁾/ωⁱ (entries O(ω)) by a Taylor series with scaling and
/// squaring of the augmented matrix [[A, B], [0, 0]]·T, then unscaled.
pub fn svf_discrete(w: f64, dt: f64) -> ([[f64; 4]; 4], [f64; 4]) {
    // ξ' = ω·(companion of (s+1)⁴) ξ + ω·e4·u.
    let mut m = [[0.0f64; 5]; 5];
    for i in 0..3 {
        m[i][i + 1] = w * dt;
    }
    let coef = [1.0, 4.0, 6.0, 4.0];
    for c in 0..4 {
        m[3][c] = -coef[c] * w * dt;
    }
    m[3][4] = w * dt;
    let e = expm5(&m);
    let mut phi = [[0.0; 4]; 4];
    let mut gam = [0.0; 4];
    for r in 0..4 {
        for c in 0..4 {
            phi[r][c] = e[r][c] * w.powi(r as i32) / w.powi(c as i32);
        }
        gam[r] = e[r][4] * w.powi(r as i32);
    }
    (phi, gam)
}

fn matmul5(a: &[[f64; 5]; 5], b: &[[f64; 5]; 5]) -> [[f64; 5]; 5] {
    let mut c = [[0.0; 5]; 5];
    for i in 0..5 {
        for k in 0..5 {
            for j in 0..5 {
                c[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    c
}

/// exp(m) by a 20-term Taylor series after scaling m to norm ≤ ¼, then squaring back.
pub(crate) fn expm5(m: &[[f64; 5]; 5]) -> [[f64; 5]; 5] {
    let norm = m
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let squarings = if norm > 0.25 {
        (norm / 0.25).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(squarings);
    let mut a = *m;
    a.iter_mut().flatten().for_each(|v| *v *= scale);
    let mut result = [[0.0; 5]; 5];
    let mut term = [[0.0; 5]; 5];
    for i in 0..5 {
        result[i][i] = 1.0;
        term[i][i] = 1.0;
    }
    for n in 1..=20 {
        term = matmul5(&term, &a);
        term.iter_mut().flatten().for_each(|v| *v /= n as f64);
        for i in 0..5 {
            for j in 0..5 {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        result = matmul5(&result, &result);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_derivatives_are_consistent() {
        let s = Sine {
            freq_hz: 3.0,
            amp_m: 0.05,
            taper_s: 1.0,
            duration_s: 3.0,
            window_cycles: Some(4),
        };
        for &t in &[0.1, 0.5, 0.999, 1.5, 2.2] {
            let h = 1e-6;
            let (p, m) = (s.states(t + h), s.states(t - h));
            let c = s.states(t);
            for d in 0..3 {
                let fd = (p[d] - m[d]) / (2.0 * h);
                assert!(
                    (fd - c[d + 1]).abs() <= 1e-5 * (1.0 + c[d + 1].abs()),
                    "t={t} d={d}: {fd} vs {}",
                    c[d + 1]
                );
            }
        }
        let r = s.reference(1024.0);
        assert_eq!(r.len(), 3072);
        assert_eq!(r.window, (3072 - 1365, 3072));
        assert_eq!(s.default_cycles(), 3);
        assert!((Sine::amp_from_g(1.73, 3.0) - 0.047749).abs() < 1e-6);
    }

    #[test]
    fn svf_tracks_a_ramp_with_exact_derivatives() {
        // A ramp of 0.1 m/s: after the transient, v_r = 0.1, a_r = j_r = 0, x_r lags by 4/ω.
        let f_s = 1024.0;
        let t: Vec<f64> = (0..=2048).map(|k| k as f64 / f_s).collect();
        let d: Vec<f64> = t.iter().map(|t| 0.1 * t).collect();
        let rec = Record {
            time_s: t,
            disp_m: d,
            f_ref_hz: 50.0,
        };
        let r = rec.reference(f_s);
        assert_eq!(r.len(), 2049);
        let k = 2000;
        // The held (staircase) input leaves a ripple at the tick rate: its sawtooth harmonics
        // 0.1·T/(πn) at n·1024 Hz, differentiated and attenuated by |H|, bound the velocity
        // ripple by 1.22e-6 m/s.
        assert!((r.v[k] - 0.1).abs() < 2e-6, "{}", r.v[k]);
        // Same argument with one and two more factors of 2πn·1024: bounds 8.8e-3 m/s², 77 m/s³.
        assert!(
            r.a[k].abs() < 8.8e-3 && r.j[k].abs() < 77.0,
            "a {} j {}",
            r.a[k],
            r.j[k]
        );
        let lag = 4.0 / (2.0 * PI * 50.0);
        // Held input: half a tick of extra lag.
        let expected = 0.1 * (k as f64 / f_s - lag - 0.5 / f_s);
        assert!((r.x[k] - expected).abs() < 1e-6, "{} vs {expected}", r.x[k]);
    }

    #[test]
    fn svf_dc_gain_is_one() {
        let (phi, gam) = svf_discrete(2.0 * PI * 50.0, 1.0 / 1024.0);
        // Fixed point for u = 1 is x = 1, other states 0.
        let s = [1.0, 0.0, 0.0, 0.0];
        for r in 0..4 {
            let next = (0..4).map(|c| phi[r][c] * s[c]).sum::<f64>() + gam[r];
            assert!((next - s[r]).abs() < 1e-9, "row {r}: {next}");
        }
    }
}
