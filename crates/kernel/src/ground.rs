//! Earthquake-type excitations (docs/model.md §4b): ground accelerations made into displacement
//! references, stochastic ground motions, sine sweeps and band-limited random motions.
//!
//! - **From acceleration to displacement** ([`to_displacement`]): a recorded or generated ground
//!   acceleration becomes the table's displacement by (1) removing its mean, (2) a half-cosine
//!   taper over the first and last `taper_s`, (3) zero pads of 2/f_hp at each end (Boore 2005
//!   asks an acausal filter for pads of 1.5·n/f_c in all, 1.5/f_hp a side for n = 2 per pass;
//!   [chosen] 2/f_hp keeps the filter's tail beyond the pads near 1e-4 of the peak), (4) a 2nd-order
//!   Butterworth high-pass at f_hp run forward and backward (zero phase, 4th-order magnitude), and
//!   (5) the trapezoid rule twice from rest. The pads stay: the table starts and ends at rest,
//!   the motion itself starts 2/f_hp after the reference's start. A 4th-order zero-phase
//!   high-pass leaves no mean and no first moments, so the displacement returns to zero up to
//!   the filter's tail beyond the pads: the residual drift |d_end| is reported, and bounded by
//!   the tests (≤ 1e-3 of the peak displacement).
//! - **Stochastic ground motion** ([`GroundParams`], [`filtered_noise`]): white noise through a
//!   Kanai–Tajimi filter (ground frequency f_g, damping ζ_g) and a Clough–Penzien high-pass
//!   (f_f, ζ_f), discretised exactly for a held input, times the Jennings–Housner–Tsai (1968)
//!   envelope (a quadratic rise to t_rise, a plateau of t_strong, then exp(−decay·t)), scaled to
//!   the peak ground acceleration pga_g. The noise comes from the caller (orchestration draws it
//!   from a stream of (seed, sample)).
//! - **Sweep** ([`Sweep`]) and **band-limited random** ([`Multisine`]): closed-form displacements
//!   whose velocity, acceleration and jerk are their exact derivatives, computed by third-order
//!   Taylor arithmetic ([`Jet`]) — no filter, no lag.

use super::channels::G;
use super::param_table::{params, Range};
use std::f64::consts::PI;
use std::ops::{Add, Mul};

params! {
    /// A stochastic ground motion's parameters (docs/model.md §4b). The plant never reads them:
    /// they sit in the model so that studies sample them like any other parameter (`ground.*`).
    pub struct GroundParams {
        pga_g: "g", "g", 0.5, Range::gt(0.0), Chosen,
            "Peak ground acceleration the realisation is scaled to.";
        f_g_hz: "Hz", "hz", 2.5, Range::gt(0.0), Literature,
            "Kanai–Tajimi ground frequency f_g (ω_g = 15.6 rad/s for firm soil, Kanai 1957 / Tajimi 1960).";
        zeta_g: "-", "", 0.6, Range::gt(0.0), Literature,
            "Kanai–Tajimi ground damping ζ_g (0.6, Tajimi 1960).";
        f_f_hz: "Hz", "hz", 0.25, Range::gt(0.0), Literature,
            "Clough–Penzien high-pass frequency f_f (f_g/10, Clough & Penzien 1975).";
        zeta_f: "-", "", 0.6, Range::gt(0.0), Literature,
            "Clough–Penzien damping ζ_f (= ζ_g, Clough & Penzien 1975).";
        t_rise_s: "s", "s", 2.0, Range::ge(0.0), Literature,
            "Envelope rise time t_rise: (t/t_rise)² before it (Jennings, Housner & Tsai 1968).";
        t_strong_s: "s", "s", 6.0, Range::ge(0.0), Chosen,
            "Envelope plateau (strong-motion duration) after the rise.";
        decay_per_s: "1/s", "per_s", 0.4, Range::gt(0.0), Chosen,
            "Envelope decay rate after the plateau: exp(−decay·(t − t_rise − t_strong)).";
    }
}

/// How an acceleration becomes a displacement ([`to_displacement`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Processing {
    /// High-pass corner f_hp, Hz. Default 0.2 Hz [chosen: the LHPOST's ±0.75 m stroke; shake
    /// tables filter records below 0.1–0.25 Hz].
    pub highpass_hz: f64,
    /// Half-cosine taper at each end of the acceleration, s. Default 0.5 s [chosen].
    pub taper_s: f64,
}

impl Default for Processing {
    fn default() -> Self {
        Processing {
            highpass_hz: 0.2,
            taper_s: 0.5,
        }
    }
}

impl Processing {
    /// Zero pad at each end, s: 2/f_hp (see the module docs).
    pub(crate) fn pad_s(&self) -> f64 {
        2.0 / self.highpass_hz
    }
}

/// A displacement made from an acceleration ([`to_displacement`]), sampled every `dt`.
#[derive(Debug, Clone, PartialEq)]
pub struct Processed {
    pub dt: f64,
    pub disp_m: Vec<f64>,
    /// The filtered, padded acceleration, m/s².
    pub accel_mps2: Vec<f64>,
    /// Samples of zero pad before the motion.
    pub pad: usize,
    /// |displacement| at the end (the residual drift), m.
    pub drift_m: f64,
    /// |velocity| at the end, m/s.
    pub end_velocity_mps: f64,
}

/// The displacement of acceleration `accel` (m/s², every `dt` s) — see the module docs.
pub fn to_displacement(accel: &[f64], dt: f64, p: &Processing) -> Processed {
    let n = accel.len();
    let mean = accel.iter().sum::<f64>() / n.max(1) as f64;
    let nt = ((p.taper_s / dt).round() as usize).min(n / 2);
    let pad = (p.pad_s() / dt).ceil() as usize;
    let mut a = vec![0.0; n + 2 * pad];
    for (i, v) in accel.iter().enumerate() {
        a[pad + i] = (v - mean) * edge_weight(i, n, nt);
    }
    let bq = Biquad::highpass(p.highpass_hz, dt);
    bq.filter(&mut a);
    a.reverse();
    bq.filter(&mut a);
    a.reverse();
    let (mut v, mut d) = (0.0, 0.0);
    let mut disp = Vec::with_capacity(a.len());
    disp.push(0.0);
    for w in a.windows(2) {
        let v1 = v + 0.5 * dt * (w[0] + w[1]);
        d += 0.5 * dt * (v + v1);
        v = v1;
        disp.push(d);
    }
    Processed {
        dt,
        drift_m: d.abs(),
        end_velocity_mps: v.abs(),
        disp_m: disp,
        accel_mps2: a,
        pad,
    }
}

/// The half-cosine taper's weight of sample `i` of `n`, over `nt` samples at each end: 0 at
/// the first and last sample, 1 between the tapers, the end the mirror of the start.
fn edge_weight(i: usize, n: usize, nt: usize) -> f64 {
    if i < nt {
        0.5 * (1.0 - (PI * i as f64 / nt as f64).cos())
    } else if i + nt >= n {
        0.5 * (1.0 - (PI * (n - 1 - i) as f64 / nt as f64).cos())
    } else {
        1.0
    }
}

/// A 2nd-order Butterworth section (bilinear transform with a prewarped corner).
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

impl Biquad {
    fn highpass(fc: f64, dt: f64) -> Biquad {
        let k = (PI * fc * dt).tan();
        let q = std::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        Biquad {
            b: [norm, -2.0 * norm, norm],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
        }
    }

    /// In place, from rest (direct form II transposed).
    fn filter(&self, x: &mut [f64]) {
        let (mut z1, mut z2) = (0.0, 0.0);
        for v in x.iter_mut() {
            let y = self.b[0] * *v + z1;
            z1 = self.b[1] * *v - self.a[0] * y + z2;
            z2 = self.b[2] * *v - self.a[1] * y;
            *v = y;
        }
    }
}

/// Scales `accel` so that its peak is `pga_mps2`; returns the factor.
pub fn scale_to_pga(accel: &mut [f64], pga_mps2: f64) -> f64 {
    let peak = accel.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let factor = if peak > 0.0 { pga_mps2 / peak } else { 1.0 };
    accel.iter_mut().for_each(|v| *v *= factor);
    factor
}

/// The envelope of [`GroundParams`] at time t.
pub fn envelope(g: &GroundParams, t: f64) -> f64 {
    if t < g.t_rise_s {
        (t / g.t_rise_s).powi(2)
    } else if t <= g.t_rise_s + g.t_strong_s {
        1.0
    } else {
        (-g.decay_per_s * (t - g.t_rise_s - g.t_strong_s)).exp()
    }
}

/// A stochastic ground acceleration, m/s², one value per sample of `white` (unit-variance
/// noise every `dt` s): Kanai–Tajimi then Clough–Penzien filtering from rest, the envelope, and
/// the scaling to `g.pga_g`.
pub fn filtered_noise(g: &GroundParams, white: &[f64], dt: f64) -> Vec<f64> {
    let (wg, zg, wf, zf) = (2.0 * PI * g.f_g_hz, g.zeta_g, 2.0 * PI * g.f_f_hz, g.zeta_f);
    // States (z, ż, y, ẏ): z̈ = −2ζ_g ω_g ż − ω_g² z + w; a₁ = ω_g² z + 2ζ_g ω_g ż (Kanai–Tajimi);
    // ÿ = a₁ − 2ζ_f ω_f ẏ − ω_f² y, output ÿ (Clough–Penzien). Input w in column 4.
    let mut m = [[0.0f64; 5]; 5];
    m[0][1] = dt;
    m[1][0] = -wg * wg * dt;
    m[1][1] = -2.0 * zg * wg * dt;
    m[1][4] = dt;
    m[2][3] = dt;
    m[3][0] = wg * wg * dt;
    m[3][1] = 2.0 * zg * wg * dt;
    m[3][2] = -wf * wf * dt;
    m[3][3] = -2.0 * zf * wf * dt;
    let e = super::expm::expm(&m);
    let mut s = [0.0f64; 4];
    let mut out: Vec<f64> = white
        .iter()
        .enumerate()
        .map(|(k, &w)| {
            let y = wg * wg * s[0] + 2.0 * zg * wg * s[1] - wf * wf * s[2] - 2.0 * zf * wf * s[3];
            let next: [f64; 4] =
                std::array::from_fn(|r| (0..4).map(|c| e[r][c] * s[c]).sum::<f64>() + e[r][4] * w);
            s = next;
            y * envelope(g, k as f64 * dt)
        })
        .collect();
    scale_to_pga(&mut out, g.pga_g * G);
    out
}

/// A value and its first three time derivatives, with the arithmetic that carries them (Taylor
/// arithmetic of order 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jet(pub [f64; 4]);

impl std::ops::Add for Jet {
    type Output = Jet;
    fn add(self, o: Jet) -> Jet {
        Jet(std::array::from_fn(|i| self.0[i] + o.0[i]))
    }
}

impl std::ops::Mul for Jet {
    type Output = Jet;
    /// Leibniz's rule.
    fn mul(self, o: Jet) -> Jet {
        let (a, b) = (self.0, o.0);
        Jet([
            a[0] * b[0],
            a[1] * b[0] + a[0] * b[1],
            a[2] * b[0] + 2.0 * a[1] * b[1] + a[0] * b[2],
            a[3] * b[0] + 3.0 * a[2] * b[1] + 3.0 * a[1] * b[2] + a[0] * b[3],
        ])
    }
}

impl Jet {
    /// Time itself.
    pub fn t(t: f64) -> Jet {
        Jet([t, 1.0, 0.0, 0.0])
    }
    pub fn constant(c: f64) -> Jet {
        Jet([c, 0.0, 0.0, 0.0])
    }
    pub fn scale(self, c: f64) -> Jet {
        Jet(self.0.map(|v| v * c))
    }
    /// f∘self for f with derivatives `f` = (f, f′, f″, f‴) at self's value (Faà di Bruno).
    fn compose(self, f: [f64; 4]) -> Jet {
        let u = self.0;
        Jet([
            f[0],
            f[1] * u[1],
            f[2] * u[1] * u[1] + f[1] * u[2],
            f[3] * u[1].powi(3) + 3.0 * f[2] * u[1] * u[2] + f[1] * u[3],
        ])
    }
    pub fn sin(self) -> Jet {
        let (s, c) = self.0[0].sin_cos();
        self.compose([s, c, -s, -c])
    }
    pub fn cos(self) -> Jet {
        let (s, c) = self.0[0].sin_cos();
        self.compose([c, -s, -c, s])
    }
    pub fn exp(self) -> Jet {
        let e = self.0[0].exp();
        self.compose([e; 4])
    }
    pub(crate) fn recip(self) -> Jet {
        let u = self.0[0];
        self.compose([1.0 / u, -1.0 / (u * u), 2.0 / u.powi(3), -6.0 / u.powi(4)])
    }
}

/// The half-cosine taper in over `taper` s and out over the last `taper` s of `duration`.
fn taper(t: f64, taper: f64, duration: f64) -> Jet {
    if taper <= 0.0 {
        return Jet::constant(1.0);
    }
    let p = PI / taper;
    if t < taper {
        Jet::constant(0.5).add(Jet::t(t).scale(p).cos().scale(-0.5))
    } else if t > duration - taper {
        // h(duration − t): the derivatives in t are h's with the odd orders negated.
        Jet::constant(0.5)
            .add(Jet::t(duration - t).scale(p).cos().scale(-0.5))
            .flip_odd()
    } else {
        Jet::constant(1.0)
    }
}

impl Jet {
    /// g(−t)'s derivatives from g(t)'s: odd orders change sign.
    fn flip_odd(self) -> Jet {
        Jet([self.0[0], -self.0[1], self.0[2], -self.0[3]])
    }
}

/// How a sweep's frequency moves from f0 to f1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SweepLaw {
    Linear,
    /// Exponential in time (equal time per octave).
    Log,
}

/// A sine sweep: x = e(t)·X(t)·sin φ(t), φ' = 2π f(t), with the half-cosine taper e and either a
/// constant displacement amplitude or a constant acceleration amplitude (X = a/(2πf(t))²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    pub f0_hz: f64,
    pub f1_hz: f64,
    pub duration_s: f64,
    pub taper_s: f64,
    pub law: SweepLaw,
    /// Constant displacement amplitude, m (`None`: constant acceleration `accel_mps2`).
    pub amp_m: Option<f64>,
    pub accel_mps2: f64,
}

impl Sweep {
    /// (x, v, a, j) at time t.
    pub fn states(&self, t: f64) -> [f64; 4] {
        let tt = Jet::t(t);
        let (f0, f1, d) = (self.f0_hz, self.f1_hz, self.duration_s);
        let (phase, freq) = match self.law {
            SweepLaw::Linear => {
                let k = (f1 - f0) / d;
                (
                    tt.scale(f0).add(tt.mul(tt).scale(0.5 * k)).scale(2.0 * PI),
                    tt.scale(k).add(Jet::constant(f0)),
                )
            }
            SweepLaw::Log => {
                let r = (f1 / f0).ln() / d;
                let grow = tt.scale(r).exp();
                (
                    grow.add(Jet::constant(-1.0)).scale(2.0 * PI * f0 / r),
                    grow.scale(f0),
                )
            }
        };
        let amp = match self.amp_m {
            Some(x) => Jet::constant(x),
            None => freq
                .mul(freq)
                .scale(4.0 * PI * PI)
                .recip()
                .scale(self.accel_mps2),
        };
        taper(t, self.taper_s, d).mul(amp).mul(phase.sin()).0
    }
}

/// A band-limited random motion: a sum of sines of equal acceleration amplitude at every
/// multiple of 1/duration in [f_lo, f_hi] with random phases (a random-phase multisine, whose
/// acceleration spectrum is flat in the band), tapered in and out. The displacement is the
/// closed-form double integral of each sine, so v, a, j are exact.
#[derive(Debug, Clone, PartialEq)]
pub struct Multisine {
    pub freqs_hz: Vec<f64>,
    /// Acceleration amplitude of each sine, m/s².
    pub accel_amp: f64,
    pub phases: Vec<f64>,
    pub duration_s: f64,
    pub taper_s: f64,
}

impl Multisine {
    /// The components in [f_lo, f_hi] at multiples of 1/duration, each of acceleration amplitude
    /// giving an rms acceleration `rms_mps2` (before the taper); `phases` gives one phase per
    /// component (drawn by the caller), cycled if short.
    pub fn new(
        f_lo: f64,
        f_hi: f64,
        duration_s: f64,
        taper_s: f64,
        rms_mps2: f64,
        phases: impl Fn(usize) -> f64,
    ) -> Multisine {
        let df = 1.0 / duration_s;
        let first = (f_lo / df).ceil().max(1.0) as usize;
        let last = (f_hi / df).floor() as usize;
        let freqs_hz: Vec<f64> = (first..=last.max(first)).map(|k| k as f64 * df).collect();
        let accel_amp = rms_mps2 * (2.0 / freqs_hz.len() as f64).sqrt();
        let phases = (0..freqs_hz.len()).map(phases).collect();
        Multisine {
            freqs_hz,
            accel_amp,
            phases,
            duration_s,
            taper_s,
        }
    }

    /// (x, v, a, j) at time t.
    pub fn states(&self, t: f64) -> [f64; 4] {
        let mut s = [0.0; 4];
        for (f, ph) in self.freqs_hz.iter().zip(&self.phases) {
            let w = 2.0 * PI * f;
            let (sn, cs) = (w * t + ph).sin_cos();
            let x = -self.accel_amp / (w * w);
            s[0] += x * sn;
            s[1] += x * w * cs;
            s[2] -= x * w * w * sn;
            s[3] -= x * w * w * w * cs;
        }
        taper(t, self.taper_s, self.duration_s).mul(Jet(s)).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The taper rises over its first `taper` s, holds 1 between, and falls over the last
    /// `taper` s as the mirror image of its rise (odd derivatives negated); none where it is 0.
    #[test]
    fn the_taper_falls_at_the_end_as_it_rose_at_the_start() {
        let (tp, d) = (1.5, 10.0);
        for t in [0.0, 0.3, 0.75, 1.2, 1.5] {
            let (rise, fall) = (taper(t, tp, d).0, taper(d - t, tp, d).0);
            for k in 0..4 {
                let sign = if k % 2 == 1 { -1.0 } else { 1.0 };
                assert!(
                    (fall[k] - sign * rise[k]).abs() <= 1e-12,
                    "t {t}, order {k}"
                );
            }
        }
        assert!((taper(0.75, tp, d).0[0] - 0.5).abs() <= 1e-15);
        for t in [1.6, 5.0, 8.4] {
            assert_eq!(taper(t, tp, d).0, [1.0, 0.0, 0.0, 0.0], "t {t}");
        }
        assert_eq!(taper(9.5, 0.0, d).0, [1.0, 0.0, 0.0, 0.0]);
    }

    fn fd_check(f: impl Fn(f64) -> [f64; 4], ts: &[f64]) {
        for &t in ts {
            let h = 1e-6;
            let (p, m, c) = (f(t + h), f(t - h), f(t));
            for d in 0..3 {
                let fd = (p[d] - m[d]) / (2.0 * h);
                assert!(
                    (fd - c[d + 1]).abs() <= 1e-5 * (1.0 + c[d + 1].abs()),
                    "t={t} d={d}: {fd} vs {}",
                    c[d + 1]
                );
            }
        }
    }

    /// The displacement is the trapezoidal double integral of the processed acceleration, from
    /// rest: d[k+1] − 2 d[k] + d[k−1] = dt²/4 (a[k−1] + 2 a[k] + a[k+1]) at every tick, and the
    /// drift is the last displacement's magnitude.
    #[test]
    fn the_displacement_is_the_double_integral_of_the_processed_acceleration() {
        let dt = 0.01;
        let accel: Vec<f64> = (0..1500)
            .map(|k| {
                let t = k as f64 * dt;
                3.0 * (2.0 * PI * 1.3 * t).sin() + 1.5 * (2.0 * PI * 0.4 * t).cos() + 0.2
            })
            .collect();
        let p = to_displacement(&accel, dt, &Processing::default());
        let (a, d) = (&p.accel_mps2, &p.disp_m);
        assert_eq!(a.len(), d.len());
        assert_eq!(d[0], 0.0);
        let scale = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.1, "{scale}");
        for k in 1..d.len() - 1 {
            let lhs = d[k + 1] - 2.0 * d[k] + d[k - 1];
            let rhs = dt * dt / 4.0 * (a[k - 1] + 2.0 * a[k] + a[k + 1]);
            assert!(
                (lhs - rhs).abs() < 1e-12 * scale,
                "tick {k}: {lhs} against {rhs}"
            );
        }
        assert_eq!(p.drift_m, d[d.len() - 1].abs());
    }

    /// A record's taper falls at its end as it rose at its start: each weight is its mirror's,
    /// 0 at both ends, 1 between the tapers, and the taper's half-cosine at its own points.
    #[test]
    fn a_records_taper_at_its_end_is_the_mirror_of_its_start() {
        let (n, nt) = (40, 7);
        for i in 0..n {
            assert_eq!(
                edge_weight(i, n, nt),
                edge_weight(n - 1 - i, n, nt),
                "sample {i}"
            );
        }
        assert_eq!(
            (edge_weight(0, n, nt), edge_weight(n - 1, n, nt)),
            (0.0, 0.0)
        );
        assert!((nt..n - nt).all(|i| edge_weight(i, n, nt) == 1.0));
        let half = 0.5 * (1.0 - (PI * 3.0 / 7.0).cos());
        assert_eq!(
            (edge_weight(3, n, nt), edge_weight(n - 4, n, nt)),
            (half, half)
        );
    }

    /// [`filtered_noise`] against the Kanai–Tajimi and Clough–Penzien equations integrated
    /// apart (RK4, 200 substeps per sample, the input held over each sample), away from the
    /// defaults, with the envelope's plateau from t = 0: the two agree to 1e-9 of the peak.
    #[test]
    fn stochastic_motion_is_the_filters_output() {
        let g = GroundParams {
            pga_g: 0.7,
            f_g_hz: 3.1,
            zeta_g: 0.35,
            f_f_hz: 0.6,
            zeta_f: 0.9,
            t_rise_s: 0.0,
            t_strong_s: 100.0,
            decay_per_s: 0.4,
        };
        let (dt, n) = (0.01, 600);
        let white: Vec<f64> = (0..n).map(|k| (k as f64 * 12.9898).sin() * 1.7).collect();
        let got = filtered_noise(&g, &white, dt);
        let (wg, wf) = (2.0 * PI * g.f_g_hz, 2.0 * PI * g.f_f_hz);
        // (z, ż, y, ẏ): z̈ = w − 2ζ_g ω_g ż − ω_g² z; ÿ = ω_g² z + 2ζ_g ω_g ż − 2ζ_f ω_f ẏ − ω_f² y.
        let ground = |s: [f64; 4]| wg * wg * s[0] + 2.0 * g.zeta_g * wg * s[1];
        let accel = |s: [f64; 4]| ground(s) - wf * wf * s[2] - 2.0 * g.zeta_f * wf * s[3];
        let rhs = |s: [f64; 4], w: f64| {
            let zdd = w - 2.0 * g.zeta_g * wg * s[1] - wg * wg * s[0];
            [s[1], zdd, s[3], accel(s)]
        };
        let add = |s: [f64; 4], k: [f64; 4], h: f64| std::array::from_fn(|i| s[i] + h * k[i]);
        let (mut s, sub) = ([0.0f64; 4], 200);
        let h = dt / sub as f64;
        let mut want: Vec<f64> = Vec::with_capacity(n);
        for &w in &white {
            want.push(accel(s));
            for _ in 0..sub {
                let k1 = rhs(s, w);
                let k2 = rhs(add(s, k1, h / 2.0), w);
                let k3 = rhs(add(s, k2, h / 2.0), w);
                let k4 = rhs(add(s, k3, h), w);
                s = std::array::from_fn(|i| {
                    s[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
                });
            }
        }
        scale_to_pga(&mut want, g.pga_g * G);
        assert_eq!(got.len(), n);
        let peak = g.pga_g * G;
        for (k, (a, b)) in got.iter().zip(&want).enumerate() {
            assert!((a - b).abs() <= 1e-9 * peak, "sample {k}: {a} against {b}");
        }
    }

    #[test]
    fn sweep_and_multisine_derivatives_are_exact() {
        for law in [SweepLaw::Linear, SweepLaw::Log] {
            for amp_m in [Some(0.01), None] {
                let s = Sweep {
                    f0_hz: 0.5,
                    f1_hz: 20.0,
                    duration_s: 30.0,
                    taper_s: 2.0,
                    law,
                    amp_m,
                    accel_mps2: 2.0,
                };
                fd_check(|t| s.states(t), &[0.3, 1.99, 2.01, 10.0, 27.5, 29.9]);
            }
        }
        let m = Multisine::new(0.5, 10.0, 8.0, 1.0, 1.0, |k| k as f64 * 0.7);
        assert_eq!(m.freqs_hz.len(), 77);
        fd_check(|t| m.states(t), &[0.2, 3.0, 7.5]);
    }

    #[test]
    fn a_sweep_makes_as_many_cycles_as_its_frequency_law() {
        // ∫f dt over the run: log f0·T·(r − 1)/ln r, linear (f0 + f1)/2·T; x crosses zero twice
        // a cycle.
        for (law, cycles) in [
            (SweepLaw::Log, 15.0 * 8.0 / 16f64.ln()),
            (SweepLaw::Linear, 8.5 * 8.0),
        ] {
            let s = Sweep {
                f0_hz: 1.0,
                f1_hz: 16.0,
                duration_s: 8.0,
                taper_s: 0.0,
                law,
                amp_m: Some(0.01),
                accel_mps2: 0.0,
            };
            let x: Vec<f64> = (1..80_000).map(|i| s.states(i as f64 * 1e-4)[0]).collect();
            let crossings = x
                .windows(2)
                .filter(|w| (w[0] < 0.0) != (w[1] < 0.0))
                .count() as f64;
            assert!(
                (crossings - 2.0 * cycles).abs() <= 1.0,
                "{law:?}: {crossings} crossings for {cycles} cycles"
            );
        }
    }
}
