//! Terms with memory: a residual that follows a state through a linear second-order filter
//! rather than at the same instant.
//!
//! A flexible specimen, a mode of the table or of its foundation, a payload on a spring: such a
//! load is not a function of any one state at the same instant. Below its resonance it moves with
//! the table (a mass: a force against the acceleration), above it it stays behind (little force),
//! and near it the force is large and in quadrature. Likewise a spool that lags its command: the
//! opening it misses is in quadrature with the opening. A regression on the static terms of the
//! states ([`crate::diagnosis::statemap`]) finds little; the terms must have memory. Two families, each one
//! filter of natural frequency f_n and damping ratio ζ on one measured state ([`Kind`]):
//! - [`Kind::Carried`], on the platen's balance: the force m·z̈ of an oscillator (mass m) whose
//!   base moves as the measured platen displacement y: z̈ = −2ζω_n·u̇ − ω_n²·u with
//!   ü + 2ζω_n·u̇ + ω_n²·u = −ÿ, u = z − y; per harmonic, z̈_k = −Ω²·T(Ω)·Y_k with
//!   T(Ω) = (ω_n² + 2iζω_nΩ)/(ω_n² − Ω² + 2iζω_nΩ). The oscillator pulls on the platen with
//!   −m·z̈, so the balance's residual F − M·a − (the platen's own forces) is m·z̈: the slope is m.
//! - [`Kind::Lag`], on the missing valve opening: x_f − x, x_f the opening x (as the command asks
//!   for it) through the low-pass ω_n²/(ω_n² − Ω² + 2iζω_nΩ); the slope is the share of the
//!   opening that lags (1 for a spool that follows its command through that filter).
//!
//! Over a grid of (f_n, ζ), then a finer one around the best, then a pattern search, the residual
//! is regressed on the filter's output (with a constant); the pair of largest R² is named. For a
//! sine test the filter's steady state is exact per harmonic of the state (the compare's
//! projection); for a record it is integrated from rest at the first sample (exactly, the input
//! linear between samples).
//!
//! [chosen: one filter per family; grid f_n 0.2–100 Hz (60 log-spaced values), ζ 1–50 % (6
//! values), refined to ±1 grid step in 21 × 11 values, then polished within f_n 0.2–100 Hz and
//! ζ 0.2–200 %.]

use crate::diagnosis::projector::Projector;
use std::f64::consts::PI;
use vshake_kernel::spectrum::Oscillator;

/// Natural frequencies of the coarse grid: 0.2 … 100 Hz, log-spaced.
const F_LO: f64 = 0.2;
/// The top of that grid: a fit there says only "fast" (a rigid mass, a short delay).
pub(crate) const F_HI: f64 = 100.0;
const N_F: usize = 60;
/// Damping ratios of the coarse grid.
const ZETAS: [f64; 6] = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5];
/// The damping ratios the polish may reach. [chosen]
const ZETA_MIN: f64 = 0.002;
const ZETA_MAX: f64 = 2.0;

/// A family of terms with memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The force per unit mass of an oscillator carried by the platen (input: displacement).
    Carried,
    /// The part of the opening a second-order low-pass holds back (input: the opening).
    Lag,
}

impl Kind {
    /// The filter's output per unit input at angular frequency `w`, as a complex number.
    fn transfer(self, wn: f64, zeta: f64, w: f64) -> (f64, f64) {
        let (dr, di) = (wn * wn - w * w, 2.0 * zeta * wn * w);
        let d2 = dr * dr + di * di;
        match self {
            Kind::Carried => {
                // −w²·(ω_n² + i·di)/(dr + i·di)
                let (nr, ni) = (wn * wn, di);
                let (tr, ti) = ((nr * dr + ni * di) / d2, (ni * dr - nr * di) / d2);
                (-w * w * tr, -w * w * ti)
            }
            // ω_n²/(dr + i·di) − 1
            Kind::Lag => (wn * wn * dr / d2 - 1.0, -wn * wn * di / d2),
        }
    }

    /// The state it filters.
    pub fn state(self) -> crate::diagnosis::states::State {
        match self {
            Kind::Carried => crate::diagnosis::states::State::Displacement,
            Kind::Lag => crate::diagnosis::states::State::SpoolOpening,
        }
    }

    /// In words, as the map lists it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Carried => "an oscillator on the platen",
            Kind::Lag => "a lag of the opening",
        }
    }
}

/// One test's input state, in the form a filter needs.
pub enum Input {
    /// Mean and harmonics of the state, with the projector's basis at the samples.
    Sine {
        f: f64,
        h: Vec<(f64, f64)>,
        cos: Vec<Vec<f64>>,
        sin: Vec<Vec<f64>>,
    },
    /// The state at the samples (for [`Kind::Carried`]: the base acceleration), and the interval.
    Record { x: Vec<f64>, dt: f64 },
}

impl Input {
    /// A sine test's state from its projector.
    pub fn sine(p: &Projector, f: f64, x: &[f64]) -> Input {
        let h: Vec<(f64, f64)> = p.apply(x).into_iter().take(p.n_harm()).collect();
        let basis = p.basis();
        let cos = (0..h.len()).map(|k| basis[2 * k + 1].clone()).collect();
        let sin = (0..h.len()).map(|k| basis[2 * k + 2].clone()).collect();
        Input::Sine { f, h, cos, sin }
    }

    /// The filter's output (family `kind`, f_n Hz, damping ratio ζ) at each sample, appended to `out`.
    pub fn filtered(&self, kind: Kind, f_n: f64, zeta: f64, out: &mut Vec<f64>) {
        let wn = 2.0 * PI * f_n;
        match self {
            Input::Sine { f, h, cos, sin } => {
                // P_k = G(kω)·H_k; the output is Σ Re P_k cos − Im P_k sin.
                let p: Vec<(f64, f64)> = h
                    .iter()
                    .enumerate()
                    .map(|(k, &(hr, hi))| {
                        let (gr, gi) = kind.transfer(wn, zeta, 2.0 * PI * f * (k + 1) as f64);
                        (gr * hr - gi * hi, gr * hi + gi * hr)
                    })
                    .collect();
                let n = cos.first().map_or(0, Vec::len);
                out.extend((0..n).map(|i| {
                    p.iter()
                        .enumerate()
                        .map(|(k, &(pr, pi))| pr * cos[k][i] - pi * sin[k][i])
                        .sum::<f64>()
                }));
            }
            Input::Record { x, dt } => {
                let (c, k) = (2.0 * zeta * wn, wn * wn);
                // u'' + c u' + k u = g·s: for the oscillator s = ÿ, g = −1 and the output −c u' − k u;
                // for the lag s = x, g = k and the output u − x.
                let g = if kind == Kind::Carried { -1.0 } else { k };
                let output = |u: f64, w: f64, s: f64| match kind {
                    Kind::Carried => -c * w - k * u,
                    Kind::Lag => u - s,
                };
                // The response-spectrum oscillator's exact step (input linear between samples),
                // whose base acceleration is −g·s.
                let step = Oscillator::new(1.0 / f_n, zeta, *dt);
                // The lag starts at rest at the first value (no step at t = 0).
                let mut u = match kind {
                    Kind::Lag => x.first().copied().unwrap_or(0.0),
                    Kind::Carried => 0.0,
                };
                let mut w = 0.0f64;
                for i in 0..x.len() {
                    out.push(output(u, w, x[i]));
                    let (a0, a1) = (x[i], *x.get(i + 1).unwrap_or(&x[i]));
                    (u, w) = step.step(u, w, -g * a0, -g * a1);
                }
            }
        }
    }
}

/// The filter of one family the residual follows best.
#[derive(Debug, Clone, PartialEq)]
pub struct MemoryFit {
    pub kind: Kind,
    /// Natural frequency, Hz.
    pub f_n: f64,
    /// Damping ratio.
    pub zeta: f64,
    /// The residual's slope on the filter's output: for [`Kind::Carried`] the moving mass, kg,
    /// positive for a body the platen carries (NaN when the residual is not the platen's force
    /// balance: the mass means nothing there); for [`Kind::Lag`] the share of the opening that lags.
    pub gain: f64,
    /// Share of the residual's variance it explains (with a constant).
    pub r2: f64,
}

/// Beyond this factor above the highest (below the lowest) test frequency an oscillator reads as a
/// rigid mass (as a spring to the ground). [chosen]
pub const OUT_OF_BAND: f64 = 2.0;

impl MemoryFit {
    /// Its parameters in words: "f_n 5.02 Hz, ζ 5.1 %, 20.3 t moving" ("f_n ≥ 100 Hz, 15.9 t
    /// moving" at the top of the range searched, "ζ ≥ 200 %: no resonance" at the top of the
    /// damping's; a negative mass said as a slope).
    pub fn describe(&self) -> String {
        let g = match (self.kind, self.gain) {
            (_, g) if !g.is_finite() => String::new(),
            // A negative mass is no body's: the slope is said as what it is.
            (Kind::Carried, m) if m < 0.0 => {
                format!(", slope {}: a negative mass, no body moving", mass(m))
            }
            (Kind::Carried, m) => format!(", {} moving", mass(m)),
            // (L − 1) ≈ −2iζΩ/ω_n well below ω_n: a delay of gain·2ζ/ω_n.
            (Kind::Lag, g) => {
                let ms = 1e3 * g * 2.0 * self.zeta / (2.0 * PI * self.f_n);
                let side = if ms < 0.0 { "ahead of" } else { "behind" };
                format!(
                    ", gain {g:.2}: {:.2} ms {side} the command at low frequency",
                    ms.abs()
                )
            }
        };
        // At the grid's top the data say only "fast": a rigid mass, a short delay; its damping
        // is not seen.
        if self.f_n >= F_HI {
            return format!("f_n ≥ {F_HI:.0} Hz{g}");
        }
        // At the polish's bounds of ζ the data say only "no resonance" (a lag of another form)
        // or "undamped".
        let z = match self.zeta {
            z if z >= ZETA_MAX * (1.0 - 1e-9) => {
                format!("ζ ≥ {:.0} %: no resonance", 100.0 * ZETA_MAX)
            }
            z if z <= ZETA_MIN * (1.0 + 1e-9) => format!("ζ ≤ {:.1} %", 100.0 * ZETA_MIN),
            z => format!("ζ {:.1} %", 100.0 * z),
        };
        format!("f_n {:.2} Hz, {z}{g}", self.f_n)
    }

    /// What it suggests physically, given the tests' band of fundamentals (Hz).
    pub fn reading(&self, band: Option<(f64, f64)>) -> &'static str {
        match self.kind {
            // In closed loop the opening the data ask for is the loop's answer too: a slower
            // valve whose lag the controller over-corrects reads as a lead (a 60 Hz spool at
            // ζ 0.55 beside seal friction read as a lead at f_n ≥ 100 Hz, R² 0.96).
            Kind::Lag if self.gain < 0.0 => "an opening ahead of the model's: a lead in the valve's driver, a valve faster than the model's, or a slower one whose lag the loop over-corrects (the candidates' fits tell which)",
            Kind::Lag => "an opening that lags its command: spool dynamics (of another order or bandwidth than the model's), a slow valve driver or pilot stage",
            Kind::Carried if self.gain < 0.0 => "a dynamic load that no carried body makes (its mass comes out negative): a load with memory of another form",
            Kind::Carried => match band {
                Some((_, hi)) if self.f_n > OUT_OF_BAND * hi => "a mass moving rigidly with the table (a specimen or payload; its resonance lies above the tests)",
                Some((lo, _)) if self.f_n < lo / OUT_OF_BAND => "a spring and damper to the ground (an oscillator tuned below the tests)",
                _ => "a resonance within the tests' band: a flexible specimen, or a mode of the table or its foundation",
            },
        }
    }
}

/// "20.3 t", "350 kg".
fn mass(m: f64) -> String {
    match m.abs() >= 1000.0 {
        true => format!("{:.1} t", m / 1000.0),
        false => format!("{m:.0} kg"),
    }
}

/// R² and slope of `y` on `x` with a constant.
fn simple_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        let (da, db) = (a - mx, b - my);
        sxx += da * da;
        sxy += da * db;
        syy += db * db;
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return (0.0, 0.0);
    }
    (sxy * sxy / (sxx * syy), sxy / sxx)
}

/// The filter of family `kind` whose output on the inputs best explains `y` (the residual, pooled
/// over the tests in the order of `inputs`), or None without samples.
pub fn fit(kind: Kind, inputs: &[Input], y: &[f64]) -> Option<MemoryFit> {
    if y.len() < 8 || inputs.is_empty() {
        return None;
    }
    let mut col = Vec::with_capacity(y.len());
    let mut eval = |f_n: f64, zeta: f64| {
        col.clear();
        for x in inputs {
            x.filtered(kind, f_n, zeta, &mut col);
        }
        let (r2, gain) = if col.len() == y.len() && col.iter().all(|v| v.is_finite()) {
            simple_fit(&col, y)
        } else {
            (0.0, 0.0)
        };
        MemoryFit {
            kind,
            f_n,
            zeta,
            gain,
            r2,
        }
    };
    let ratio = (F_HI / F_LO).powf(1.0 / (N_F - 1) as f64);
    let mut best = MemoryFit {
        kind,
        f_n: F_LO,
        zeta: ZETAS[0],
        gain: 0.0,
        r2: -1.0,
    };
    let mut at = (0, 0);
    for i in 0..N_F {
        for (j, &z) in ZETAS.iter().enumerate() {
            let r = eval(F_LO * ratio.powi(i as i32), z);
            if r.r2 > best.r2 {
                (best, at) = (r, (i, j));
            }
        }
    }
    // Refine: ±1 step in f_n (21 values), between the neighbouring ζ (11 values, log-spaced).
    let f0 = F_LO * ratio.powi(at.0 as i32);
    let (z_lo, z_hi) = (
        ZETAS[at.1.saturating_sub(1)],
        ZETAS[(at.1 + 1).min(ZETAS.len() - 1)],
    );
    for i in 0..21 {
        let f = (f0 * ratio.powf(-1.0 + i as f64 / 10.0)).clamp(F_LO, F_HI);
        for j in 0..11 {
            let z = z_lo * (z_hi / z_lo).powf(j as f64 / 10.0);
            let r = eval(f, z);
            if r.r2 > best.r2 {
                best = r;
            }
        }
    }
    // Polish: a pattern search in (ln f_n, ln ζ) from the fine grid's step, halved when no move
    // improves, down to 1e-4.
    let (mut step_f, mut step_z) = (ratio.ln() / 10.0, (z_hi / z_lo).ln().max(0.1) / 10.0);
    while step_f > 1e-4 || step_z > 1e-4 {
        let moves = [(step_f, 0.0), (-step_f, 0.0), (0.0, step_z), (0.0, -step_z)];
        let tried = moves.map(|(df, dz)| {
            eval(
                (best.f_n * df.exp()).clamp(F_LO, F_HI),
                (best.zeta * dz.exp()).clamp(ZETA_MIN, ZETA_MAX),
            )
        });
        match tried
            .into_iter()
            .filter(|r| r.r2 > best.r2)
            .max_by(|a, b| a.r2.total_cmp(&b.r2))
        {
            Some(r) => best = r,
            None => (step_f, step_z) = (step_f / 2.0, step_z / 2.0),
        }
    }
    (best.r2 >= 0.0).then_some(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steady state per harmonic is the filter's: integrating a long record of the same sine
    /// in time ends on the same output, for both families.
    #[test]
    fn sine_and_record_agree_in_steady_state() {
        let (f, rate) = (3.0, 2048.0);
        let (f_n, zeta, y0) = (5.0, 0.05, 0.01);
        let w = 2.0 * PI * f;
        // 20 s, long enough for the transient (time constant 1/(ζω_n) ≈ 0.64 s) to die.
        let n = (20.0 * rate) as usize;
        let tau: Vec<f64> = (0..n).map(|k| k as f64 / rate).collect();
        let tail = &tau[n - 2048..];
        let disp: Vec<f64> = tail.iter().map(|t| y0 * (w * t).sin()).collect();
        let p = Projector::new(tail, f, 3);
        let wn = 2.0 * PI * f_n;
        let d = ((wn * wn - w * w).powi(2) + (2.0 * zeta * wn * w).powi(2)).sqrt();
        for (kind, input, gain) in [
            // |z̈| = ω²·|T|·y0 in closed form.
            (
                Kind::Carried,
                tau.iter()
                    .map(|t| -w * w * y0 * (w * t).sin())
                    .collect::<Vec<f64>>(),
                w * w * (wn.powi(4) + (2.0 * zeta * wn * w).powi(2)).sqrt() / d,
            ),
            // |ω_n²/D − 1|.
            (
                Kind::Lag,
                tau.iter().map(|t| y0 * (w * t).sin()).collect(),
                ((wn * wn * (wn * wn - w * w) / (d * d) - 1.0).powi(2)
                    + (wn * wn * 2.0 * zeta * wn * w / (d * d)).powi(2))
                .sqrt(),
            ),
        ] {
            let mut rec = Vec::new();
            Input::Record {
                x: input,
                dt: 1.0 / rate,
            }
            .filtered(kind, f_n, zeta, &mut rec);
            let mut sine = Vec::new();
            Input::sine(&p, f, &disp).filtered(kind, f_n, zeta, &mut sine);
            let peak = sine.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                (peak / (gain * y0) - 1.0).abs() < 1e-3,
                "{kind:?}: {peak} vs {}",
                gain * y0
            );
            for (a, b) in rec[n - 2048..].iter().zip(&sine) {
                assert!((a - b).abs() < 1e-4 * peak, "{kind:?}: {a} vs {b}");
            }
        }
    }

    /// A residual made by a filter on sines of several frequencies is attributed to it: its
    /// frequency, damping and gain, for both families.
    #[test]
    fn fit_finds_the_filter_it_was_made_of() {
        let rate = 1024.0;
        let tau: Vec<f64> = (0..2048).map(|k| k as f64 / rate).collect();
        let mut inputs = Vec::new();
        for &(f, y0) in &[
            (1.0, 0.05),
            (2.0, 0.02),
            (4.0, 0.01),
            (6.0, 0.005),
            (8.0, 0.003),
        ] {
            let w = 2.0 * PI * f;
            let disp: Vec<f64> = tau
                .iter()
                .map(|t| y0 * (w * t).sin() + 0.1 * y0 * (3.0 * w * t).cos())
                .collect();
            inputs.push(Input::sine(&Projector::new(&tau, f, 9), f, &disp));
        }
        for (kind, f_n, zeta, gain) in [
            (Kind::Carried, 4.7, 0.07, 12_000.0),
            (Kind::Lag, 31.0, 0.6, 0.8),
        ] {
            let mut y = Vec::new();
            for x in &inputs {
                x.filtered(kind, f_n, zeta, &mut y);
            }
            y.iter_mut().for_each(|v| *v *= gain);
            let r = fit(kind, &inputs, &y).unwrap();
            assert!(r.r2 > 1.0 - 1e-6, "{r:?}");
            assert!(
                (r.f_n / f_n - 1.0).abs() < 1e-3
                    && (r.zeta / zeta - 1.0).abs() < 1e-2
                    && (r.gain / gain - 1.0).abs() < 1e-3,
                "{r:?}"
            );
        }
    }
}
