//! Effect `adaptive_inverse`: adaptive inverse control (AIC) in the controller (docs/model.md §8),
//! not a physical effect of the plant. The TVC alone follows a broadband motion with an error
//! that depends on frequency: the published model's loop passes 71 % of the reference at 0 Hz,
//! 61 % at 1 Hz, 95 % at 2 Hz, and leads or lags by up to 20° below 20 Hz (a 20 s stochastic
//! record at 0.5 g: 0.24 of the acceleration left as error, 59 % of it at 1–2 Hz). AIC learns an
//! inverse C of the loop while the test runs and gives the TVC the reference through it, read
//! ahead: r' = C·r(t + Δ), so that the feedback x = P·r' follows r (Widrow and Walach, Adaptive
//! Inverse Control, 1996; the MTS 469D's: "an FIR inverse adapted toward a delayed target").
//!
//! **The inverse** is a generalised FIR of [`TAPS`] taps: tap 0 is its input, tap i ≥ 1 its input
//! through L_i(z) = √(1−a²)·z⁻¹/(1 − a z⁻¹) · ((z⁻¹ − a)/(1 − a z⁻¹))^(i−1), a Laguerre network of
//! pole a = exp(−2π·f_p/f_s). At a = 0 (`corner_hz` ≥ f_s) it is the plain FIR of unit delays;
//! the default pole spreads the taps' memory over the table's band (the i-th tap remembers about
//! i/(π·f_p) s), which a plain FIR at 1024 Hz would need hundreds of taps to span.
//!
//! **Learning it** (direct inverse modelling): the inverse is fitted from the loop's own output
//! to its input D ticks earlier, the delayed target: with ψ the network's taps on the measured
//! displacement x and y the reference sent D ticks ago (D = round(Δ·f_s), the loop's lag), both
//! weighted through the same two high-pass stages of corner f_w (the fit then weighs the motion as
//! its acceleration below f_w, as it is above), the weights w minimise the exponentially
//! forgotten Σ λ^(n−i)·(y_i − w·ψ_i)² by recursive least squares (memory 1/(1−λ) ticks = T_m):
//!
//! ```text
//! k = Pψ / (λ + ψᵀPψ),   w ← w + k·(y − w·ψ),   P ← (P − k·(Pψ)ᵀ)/λ     unless frozen
//! v ← v + β·(w − v)                                                    the inverse in use
//! r'_x = Σ vᵢ·Lᵢ·x̂_r,    u ← u + Σ vᵢ·Lᵢ·(F·r̂) − F·r
//! ```
//!
//! where r̂ are the reference's four states read D/f_s ahead by their Taylor series and F(s) =
//! c_fb + c_d + c_v·s + c_a·s² + c_j·s³ the TVC's reference path (docs/model.md §2): the TVC is
//! given r' in place of r. The fit needs no model of the loop: it is a regression on measured
//! signals, stable while the inverse in use holds (β = 0, the default: `copy_s` = 0), and it
//! converges in all directions at once, where an LMS step on these correlated taps jitters, its
//! weights following the motion and modulating it (measured on a 20 s stochastic record at
//! 0.5 g, normalised LMS through a delay model of the loop left 0.18–0.76 of the acceleration as
//! error, or made the chambers cavitate). Used as the run goes (β > 0), the copy closes a loop
//! through the fit, whose weights then modulate the large, slow taps of the reference: stable
//! with a copy of 2 s (0.167 of that record's acceleration as error), unstable at 0.5 s. The
//! default is offline: a pass learns, the next uses what it learned (`study sim --passes`, which
//! starts each pass's taps w_i, the inverse in use, from the last pass's fit); one learning pass
//! leaves that record's acceleration error at 0.044, from 0.238 with the TVC alone
//! (tests/compensation.rs). P starts as [`P0`]·I: a prior on the taps it starts from. The states
//! change at the ticks only.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::baseline_params::ControllerParams;
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: super::COMPENSATION,
    summary: "adaptive inverse control: an FIR inverse of the loop, learned as the test runs",
    params: Params::FIELDS,
    stages: &[Stage::free(&["memory_s"])],
};

/// Taps of the inverse.
pub const TAPS: usize = 16;

/// The longest anticipation, ticks (the delay line of the sent reference).
pub const MAX_AHEAD: usize = 16;

/// P's start, P0·I (1/m²): a prior of weight 1/P0 = 1e-6 m² per tap on the identity, a few ticks
/// of a millimetre's weighted motion, so that the fit follows the data within a fraction of a
/// second and stays defined before the table moves.
pub const P0: f64 = 1e6;

params! {
    /// Effect `adaptive_inverse`: an inverse of the loop learned by recursive least squares from
    /// the loop's output to its delayed input, the TVC given the reference through it, read
    /// ahead (docs/model.md §8).
    pub struct Params {
        memory_s: "s", "s", 30.0, Range::closed(0.05, 1e6), Chosen,
            "The fit's memory T_m: data older than T_m weigh e⁻¹ of the newest (λ = 1 − 1/(T_m·f_s)) [chosen: a record's length, so that a pass's fit is its whole record's least squares].";
        corner_hz: "Hz", "hz", 2.0, Range::open_closed(0.0, 1e6), Chosen,
            "Corner f_p of the Laguerre pole a = exp(−2π·f_p/f_s) [chosen: the inverse learned in one pass of a 20 s stochastic record at 0.5 g leaves 0.044 of the acceleration as error at 1 and 2 Hz, 0.047 at 4 Hz (tests/compensation.rs); at f_p ≥ f_s the inverse is the plain FIR of unit delays].";
        anticipation_s: "s", "s", 2.8e-3, Range::closed(0.0, 0.0156), Chosen,
            "Anticipation Δ, rounded to D ticks (1 to 16): the inverse is fitted toward the input D ticks before the output, and the reference is read D ticks ahead [chosen: the loop's lag, 2.6–2.9 ms at 12–40 Hz, measured as for amplitude_phase].";
        weight_hz: "Hz", "hz", 5.0, Range::closed(0.0, 1000.0), Chosen,
            "Corner f_w of the two high-pass stages that weight the fit: below it the motion counts as its acceleration (0: as its displacement) [chosen: one pass's inverse leaves 0.044 of the acceleration as error, 0.090 unweighted].";
        copy_s: "s", "s", 0.0, Range::ge(0.0), Chosen,
            "Time constant with which the inverse in use follows the one learned (0: it holds the taps w_i through the run, and `study sim --passes` carries the learned ones to the next pass) [chosen: 0; a copy inside the run closes a loop through the fit: on a 20 s stochastic record at 0.5 g, 0.167 of the acceleration left as error at 2 s, 0.215 at 1 s (0.238 with the TVC alone), the chambers out of their band at 0.5 s].";
        freeze_s: "s", "s", 0.0, Range::ge(0.0), Chosen,
            "Time from which the fit is held, learned no more (0: learns to the end) [chosen].";
        w_0: "1", "ratio", 1.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 0 [chosen: 1, with the other taps 0 the identity: the TVC alone, given the reference D ticks early; a pass of `study sim --passes` writes the learned taps here].";
        w_1: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 1 [chosen: 0].";
        w_2: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 2 [chosen: 0].";
        w_3: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 3 [chosen: 0].";
        w_4: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 4 [chosen: 0].";
        w_5: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 5 [chosen: 0].";
        w_6: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 6 [chosen: 0].";
        w_7: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 7 [chosen: 0].";
        w_8: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 8 [chosen: 0].";
        w_9: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 9 [chosen: 0].";
        w_10: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 10 [chosen: 0].";
        w_11: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 11 [chosen: 0].";
        w_12: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 12 [chosen: 0].";
        w_13: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 13 [chosen: 0].";
        w_14: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 14 [chosen: 0].";
        w_15: "1", "ratio", 0.0, Range::closed(-1e3, 1e3), Chosen,
            "The inverse in use at the start, tap 15 [chosen: 0].";
    }
}

impl Params {
    /// The taps w_0 … w_15.
    pub fn taps(&self) -> [f64; TAPS] {
        [
            self.w_0, self.w_1, self.w_2, self.w_3, self.w_4, self.w_5, self.w_6, self.w_7,
            self.w_8, self.w_9, self.w_10, self.w_11, self.w_12, self.w_13, self.w_14, self.w_15,
        ]
    }
}

/// The taps' names as a run's channels: the inverse learned so far, each tick.
pub const LEARNED: [&str; TAPS] = [
    "aic_w_0", "aic_w_1", "aic_w_2", "aic_w_3", "aic_w_4", "aic_w_5", "aic_w_6", "aic_w_7",
    "aic_w_8", "aic_w_9", "aic_w_10", "aic_w_11", "aic_w_12", "aic_w_13", "aic_w_14", "aic_w_15",
];

/// Fields of a lane's record for the CUDA kernel.
pub const LANE: usize = 9 + TAPS;

/// One lane's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// 1 where the compensator is on in the lane, 0 where off.
    pub on: f64,
    /// The forgetting factor λ.
    pub lambda: f64,
    /// The Laguerre pole a and √(1 − a²).
    pub a: f64,
    pub s: f64,
    /// The anticipation D (ticks) and D/f_s.
    pub ticks: usize,
    pub ahead: f64,
    /// The weighting high-passes' y ← α·(y + x − x_prev); α = 1: none.
    pub alpha: f64,
    pub freeze_s: f64,
    /// The copy's step per tick, 1/(copy_s·f_s) (0: none).
    pub beta: f64,
    /// The inverse in use at the start.
    pub w: [f64; TAPS],
    /// The TVC's reference path: c_fb + c_d, c_v, c_a, c_j.
    pub f: [f64; 4],
}

impl Settings {
    pub fn new(on: bool, q: &Params, c: &ControllerParams) -> Self {
        let [c_fb, c_d, c_v, c_a, c_j, _] = c.gains();
        let a = (-2.0 * std::f64::consts::PI * q.corner_hz / c.f_s).exp();
        let ticks = ((q.anticipation_s * c.f_s).round() as usize).clamp(1, MAX_AHEAD);
        Settings {
            on: if on { 1.0 } else { 0.0 },
            lambda: 1.0 - 1.0 / (q.memory_s * c.f_s),
            a,
            s: (1.0 - a * a).sqrt(),
            ticks,
            ahead: ticks as f64 / c.f_s,
            alpha: 1.0 / (1.0 + 2.0 * std::f64::consts::PI * q.weight_hz / c.f_s),
            freeze_s: q.freeze_s,
            beta: if q.copy_s > 0.0 {
                1.0 / (q.copy_s * c.f_s)
            } else {
                0.0
            },
            w: q.taps(),
            f: [c_fb + c_d, c_v, c_a, c_j],
        }
    }

    /// The record the CUDA kernel reads (`crates/kernel/src/cuda/lane.cu`; F's coefficients are
    /// the controller's own fields there): on, λ, a, √(1−a²), D, D/f_s, α, freeze time, the
    /// copy's step, then the taps at the start.
    pub fn lane(&self) -> [f64; LANE] {
        let head = [
            self.on,
            self.lambda,
            self.a,
            self.s,
            self.ticks as f64,
            self.ahead,
            self.alpha,
            self.freeze_s,
            self.beta,
        ];
        std::array::from_fn(|i| if i < 9 { head[i] } else { self.w[i - 9] })
    }

    /// F·r: the TVC's reference path on the states `r`, V.
    #[inline(always)]
    fn path(&self, r: [f64; 4]) -> f64 {
        self.f[0] * r[0] + self.f[1] * r[1] + self.f[2] * r[2] + self.f[3] * r[3]
    }
}

/// The reference's four states `r` read `d` seconds ahead by their Taylor series (the jerk held).
#[inline(always)]
pub fn ahead(r: [f64; 4], d: f64) -> [f64; 4] {
    let [x, v, a, j] = r;
    [
        x + d * (v + 0.5 * d * (a + d * j / 3.0)),
        v + d * (a + 0.5 * d * j),
        a + d * j,
        j,
    ]
}

/// One tick of a Laguerre network whose states are `st` = [input at n−1, L₁ … L_{TAPS−1} at n−1],
/// given the input `u` at n; returns its taps at n (tap 0 the input itself).
#[inline(always)]
pub fn network(a: f64, s: f64, u: f64, st: &mut [f64]) -> [f64; TAPS] {
    let mut taps = [0.0; TAPS];
    taps[0] = u;
    let (mut old, mut new) = (st[0], u);
    st[0] = u;
    for i in 1..TAPS {
        let before = st[i];
        st[i] = if i == 1 {
            a * before + s * old
        } else {
            a * before + old - a * new
        };
        (old, new) = (before, st[i]);
        taps[i] = st[i];
    }
    taps
}

/// The two weighting high-passes at this tick, from the input `x`; `st` = each stage's input and
/// output at n−1 (the input itself where α = 1).
#[inline(always)]
pub fn weigh(alpha: f64, mut x: f64, st: &mut [f64]) -> f64 {
    if alpha == 1.0 {
        return x;
    }
    for stage in st.chunks_exact_mut(2) {
        stage[1] = alpha * (stage[1] + x - stage[0]);
        stage[0] = x;
        x = stage[1];
    }
    x
}

/// Where each part of a lane's states starts.
const W: usize = 0;
const P: usize = W + TAPS;
const NET_X: usize = P + TAPS * TAPS;
const NET_R: usize = NET_X + TAPS;
const NET_G: usize = NET_R + TAPS;
const SENT: usize = NET_G + TAPS;
const WEIGH_X: usize = SENT + MAX_AHEAD;
const WEIGH_Y: usize = WEIGH_X + 4;
const WOUT: usize = WEIGH_Y + 4;
/// States per lane: the weights learned, P, the networks on the measured displacement, on the
/// reference read ahead and on its reference path, the sent reference's last D ticks, the
/// weightings' states, the weights in use.
pub const STATES: usize = WOUT + TAPS;

/// A lane's states at t = 0: the taps learned and in use both `w`, P = P0·I, the rest 0.
pub fn initial(w: &[f64; TAPS]) -> [f64; STATES] {
    let mut st = [0.0; STATES];
    st[W..P].copy_from_slice(w);
    st[WOUT..STATES].copy_from_slice(w);
    for i in 0..TAPS {
        st[P + i * (TAPS + 1)] = P0;
    }
    st
}

/// One step of recursive least squares: the weights `w` and `p` (row-major) updated toward `y`
/// from the regressors `psi`, forgetting by λ.
#[inline(always)]
pub fn rls(lambda: f64, psi: &[f64; TAPS], y: f64, w: &mut [f64], p: &mut [f64]) {
    let mut pp = [0.0; TAPS];
    for (i, row) in p.chunks_exact(TAPS).enumerate() {
        pp[i] = row.iter().zip(psi).map(|(a, b)| a * b).sum();
    }
    let den = lambda + psi.iter().zip(&pp).map(|(a, b)| a * b).sum::<f64>();
    let err = y - w.iter().zip(psi).map(|(a, b)| a * b).sum::<f64>();
    for (i, row) in p.chunks_exact_mut(TAPS).enumerate() {
        let k = pp[i] / den;
        w[i] += k * err;
        for (pij, ppj) in row.iter_mut().zip(&pp) {
            *pij = (*pij - k * ppj) / lambda;
        }
    }
}

/// One tick of the compensator on a lane's states `st`: the fit's step, then the correction to
/// the command (V), from the reference states `r` and the measured displacement `x` at time `t`.
#[inline(always)]
pub fn tick(set: &Settings, r: [f64; 4], x: f64, t: f64, st: &mut [f64; STATES]) -> f64 {
    let psi = network(
        set.a,
        set.s,
        weigh(set.alpha, x, &mut st[WEIGH_X..WEIGH_Y]),
        &mut st[NET_X..NET_R],
    );
    let y = weigh(set.alpha, st[SENT + set.ticks - 1], &mut st[WEIGH_Y..WOUT]);
    if !(set.freeze_s > 0.0 && t >= set.freeze_s) {
        let (w, p) = st[W..NET_X].split_at_mut(TAPS);
        rls(set.lambda, &psi, y, w, p);
    }
    for i in 0..TAPS {
        st[WOUT + i] += set.beta * (st[W + i] - st[WOUT + i]);
    }
    let r_hat = ahead(r, set.ahead);
    let rho = network(set.a, set.s, r_hat[0], &mut st[NET_R..NET_G]);
    let phi = network(set.a, set.s, set.path(r_hat), &mut st[NET_G..SENT]);
    let w = &st[WOUT..WOUT + TAPS];
    let sent: f64 = w.iter().zip(&rho).map(|(a, b)| a * b).sum();
    let u: f64 = w.iter().zip(&phi).map(|(a, b)| a * b).sum();
    st.copy_within(SENT..SENT + MAX_AHEAD - 1, SENT + 1);
    st[SENT] = sent;
    u - set.path(r)
}

pub struct AdaptiveInverse<const N: usize> {
    set: [Settings; N],
}

impl<const N: usize> LibraryEffect<N> for AdaptiveInverse<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        AdaptiveInverse {
            set: std::array::from_fn(|l| {
                Settings::new(on[l] != 0.0, Params::of(p[l]), p[l].controller())
            }),
        }
    }
}

impl<const N: usize> AdaptiveInverse<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; LANE] {
        self.set[l].lane()
    }
}

impl<const N: usize> Effect<N> for AdaptiveInverse<N> {
    /// Per lane, [`STATES`] of them: the weights learned, P, the three networks, the sent
    /// reference, the weightings' states, the weights in use (the constants above `STATES` say
    /// where each starts).
    type State = [[f64; N]; STATES];

    fn initial_state(&self) -> Self::State {
        let lanes = self.set.map(|s| initial(&s.w));
        std::array::from_fn(|i| std::array::from_fn(|l| lanes[l][i]))
    }

    /// Its states change at the ticks only: none is integrated.
    #[inline(always)]
    fn live_states(&self) -> usize {
        0
    }

    /// The inverse learned so far (its taps, [`LEARNED`]), where the lane has it on.
    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        if self.set[lane].on != 0.0 {
            for (i, name) in LEARNED.iter().enumerate() {
                out(name, s[W + i][lane]);
            }
        }
    }

    /// The TVC's command given the reference through the inverse, learned at this tick.
    #[inline(always)]
    fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
        let (l, set) = (c.lane, &self.set[c.lane]);
        // An off lane passes the command untouched.
        if set.on == 0.0 {
            return c.u;
        }
        let mut st: [f64; STATES] = std::array::from_fn(|i| s[i][l]);
        let u = c.u + tick(set, c.r, c.x, c.t, &mut st);
        for (row, v) in s.iter_mut().zip(st) {
            row[l] = v;
        }
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FS: f64 = 1024.0;

    /// A broadband reference from rest: sines of 0.3 to 12 Hz under an envelope rising over
    /// 2 s as (1 − cos)/2, their states at t.
    fn reference(t: f64) -> [f64; 4] {
        let mut q = [0.0; 4];
        for (i, (f, amp)) in [
            (0.3, 0.05),
            (0.9, 0.02),
            (2.2, 8e-3),
            (5.1, 2e-3),
            (11.7, 4e-4),
        ]
        .into_iter()
        .enumerate()
        {
            let w = 2.0 * std::f64::consts::PI * f;
            let th = w * t + i as f64;
            q[0] += amp * th.sin();
            q[1] += amp * w * th.cos();
            q[2] -= amp * w * w * th.sin();
            q[3] -= amp * w * w * w * th.cos();
        }
        // An envelope sin²(πt/4), rising over 2 s, and its derivatives.
        let h = std::f64::consts::FRAC_PI_4;
        let s = if t < 2.0 {
            let (sn, c) = (2.0 * h * t).sin_cos();
            [
                0.5 * (1.0 - c),
                h * sn,
                2.0 * h * h * c,
                -4.0 * h * h * h * sn,
            ]
        } else {
            [1.0, 0.0, 0.0, 0.0]
        };
        [
            s[0] * q[0],
            s[0] * q[1] + s[1] * q[0],
            s[0] * q[2] + 2.0 * s[1] * q[1] + s[2] * q[0],
            s[0] * q[3] + 3.0 * s[1] * q[2] + 3.0 * s[2] * q[1] + s[3] * q[0],
        ]
    }

    fn settings(corner_hz: f64, lag: usize, weight_hz: f64, freeze_s: f64) -> Settings {
        let q = Params {
            memory_s: 4.0,
            corner_hz,
            anticipation_s: lag as f64 / FS,
            weight_hz,
            freeze_s,
            copy_s: 0.25,
            ..Default::default()
        };
        // F(s) = 1: the command's volts are metres.
        let c = super::super::adaptive::unit_reference_path(FS);
        Settings::new(true, &q, &c)
    }

    /// A known linear loop: x = g_p·(1 − `dip`·(first-order low-pass at 1 Hz))·u, delayed by
    /// `lag` ticks (a loop that passes less of the low band, as the published model's does), u
    /// the TVC's command (F = 1: the reference it is given). With `adapt` false the TVC alone.
    /// Returns the rms error of each second, and the final states.
    fn run(
        set: &Settings,
        loop_: (f64, f64, usize),
        adapt: bool,
        seconds: usize,
    ) -> (Vec<f64>, [f64; STATES]) {
        let (g_p, dip, lag) = loop_;
        let n = seconds * FS as usize;
        let pole = (-2.0 * std::f64::consts::PI / FS).exp();
        let mut sent = vec![0.0; n];
        let (mut lp, mut st, mut errs, mut sum) = (0.0, initial(&set.w), Vec::new(), 0.0);
        for i in 0..n {
            let t = i as f64 / FS;
            let r = reference(t);
            let past = if i >= lag { sent[i - lag] } else { 0.0 };
            lp = pole * lp + (1.0 - pole) * past;
            let x = g_p * (past - dip * lp);
            sent[i] = r[0]
                + if adapt {
                    tick(set, r, x, t, &mut st)
                } else {
                    0.0
                };
            sum += (r[0] - x) * (r[0] - x);
            if (i + 1) % FS as usize == 0 {
                errs.push((sum / FS).sqrt());
                sum = 0.0;
            }
        }
        (errs, st)
    }

    /// The plain FIR (a = 0) behind a gain of 0.7 and 3 ticks of delay, read 3 ticks ahead: least
    /// squares finds the inverse, a response of 1/0.7 at each of the reference's frequencies
    /// (16 taps a tick apart are nearly collinear on them: the taps themselves are not unique),
    /// within 0.35 % (the weakest, 11.7 Hz at 4e-4 m, least), weighted or not, and the error
    /// falls by three orders of magnitude within 5 s (unweighted: 5e-5 of the TVC alone's;
    /// weighted, which counts the 0.3 Hz content least, 7.5e-4).
    #[test]
    fn a_plain_fir_learns_the_inverse_of_a_gain_and_a_delay() {
        for weight_hz in [0.0, 5.0] {
            let set = settings(1e7, 3, weight_hz, 0.0);
            assert_eq!(set.a, 0.0);
            let alone = run(&set, (0.7, 0.0, 3), false, 5).0;
            let (errs, st) = run(&set, (0.7, 0.0, 3), true, 5);
            println!(
                "weight_hz {weight_hz}: alone {:.3e}, adapted {:?}",
                alone[4], errs
            );
            assert!(errs[4] < 1e-3 * alone[4], "{weight_hz}: {errs:?}");
            for f in [0.3, 0.9, 2.2, 5.1, 11.7] {
                let th = 2.0 * std::f64::consts::PI * f / FS;
                let (re, im) =
                    (st[W..P].iter().enumerate()).fold((0.0, 0.0), |(re, im), (i, w)| {
                        (
                            re + w * (i as f64 * th).cos(),
                            im - w * (i as f64 * th).sin(),
                        )
                    });
                let gap = (re - 1.0 / 0.7).hypot(im);
                assert!(gap < 5e-3, "{weight_hz}: {f} Hz: {re} {im}");
            }
        }
    }

    /// The Laguerre network (the default corner) inverts a loop whose gain changes over the
    /// reference's band, 0.6 at 0 Hz rising to 1 above a few Hz, with 3 ticks of delay: the
    /// error falls at least 100× within 10 s, weighted or not.
    #[test]
    fn the_laguerre_network_inverts_a_loop_that_varies_with_frequency() {
        for weight_hz in [0.0, 5.0] {
            let set = settings(2.0, 3, weight_hz, 0.0);
            let alone = run(&set, (1.0, 0.4, 3), false, 10).0;
            let (errs, _) = run(&set, (1.0, 0.4, 3), true, 10);
            println!(
                "weight_hz {weight_hz}: alone {:.3e}, adapted {:?}",
                alone[9], errs
            );
            assert!(errs[9] < alone[9] / 100.0, "{weight_hz}: {errs:?}");
        }
    }

    /// Offline (no copy within the run): the inverse in use holds, the first pass follows as the
    /// TVC given the reference early, and the second pass, given the taps the first learned,
    /// leaves at most 1/50 of the first pass's error.
    #[test]
    fn a_pass_learns_and_the_next_uses_it() {
        let set = Settings {
            beta: 0.0,
            ..settings(2.0, 3, 5.0, 0.0)
        };
        let (first, st) = run(&set, (1.0, 0.4, 3), true, 10);
        let w: [f64; TAPS] = std::array::from_fn(|i| st[W + i]);
        assert_eq!(st[WOUT..STATES], set.w[..], "held");
        let (second, _) = run(&Settings { w, ..set }, (1.0, 0.4, 3), true, 10);
        println!("first pass {first:?}, second {second:?}");
        assert!(second[9] < first[9] / 50.0, "{first:?} {second:?}");
    }

    /// A freeze holds the inverse where it was.
    #[test]
    fn a_frozen_inverse_stands_still() {
        let set = settings(2.0, 3, 5.0, 2.0);
        let (_, s10) = run(&set, (1.0, 0.4, 3), true, 10);
        let (_, s3) = run(&set, (1.0, 0.4, 3), true, 3);
        assert_eq!(s10[W..NET_X], s3[W..NET_X]);
        assert!((s3[W] - 1.0).abs() > 1e-3, "{:?}", &s3[W..P]);
    }

    /// The network at a = 0 is a delay line; at a > 0 its taps' energy for an impulse is 1 each
    /// (the Laguerre functions are orthonormal).
    #[test]
    fn the_network_is_a_delay_line_or_orthonormal() {
        let mut st = [0.0; TAPS];
        for n in 0..20 {
            let taps = network(0.0, 1.0, n as f64, &mut st);
            for (i, x) in taps.iter().enumerate() {
                assert_eq!(*x, (n as f64 - i as f64).max(0.0), "{n} {i}");
            }
        }
        let a: f64 = 0.9;
        let mut st = [0.0; TAPS];
        let mut energy = [0.0; TAPS];
        for n in 0..20000 {
            let taps = network(
                a,
                (1.0 - a * a).sqrt(),
                if n == 0 { 1.0 } else { 0.0 },
                &mut st,
            );
            for (e, x) in energy.iter_mut().zip(taps) {
                *e += x * x;
            }
        }
        for (i, e) in energy.iter().enumerate() {
            assert!((e - 1.0).abs() < 1e-9, "tap {i}: {e}");
        }
    }
}
