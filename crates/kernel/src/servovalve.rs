//! Four-port servo-valve: spool position to chamber flows (docs/model.md §3).
//!
//! Per valve, with x⁺ = max(x, 0), x⁻ = max(−x, 0) and the regularised orifice law
//! sq(Δp) = Δp / (Δp² + p_tr²)^¼ (≈ sign(Δp)·√|Δp|):
//!
//! ```text
//! q_in1  = K_v [ w1 x⁺ sq(P_S − P1) − w3 x⁻ sq(P1 − P_R) ]   (into chamber 1)
//! q_out2 = K_v [ w2 x⁺ sq(P2 − P_R) − w4 x⁻ sq(P_S − P2) ]   (out of chamber 2)
//! ```
//!
//! Only one of x⁺, x⁻ is non-zero, so each flow needs one orifice evaluation: the land is
//! selected first (a branch-free select) and `sq` is evaluated once. This is exact, not an
//! approximation, and halves the square roots per evaluation.
//!
//! The linear valve of docs/model.md §5 (the published counter-example) is the other [`FlowLaw`]:
//! q_in1 = K_q x, q_out2 = K_q (A2/A1) x with K_q = K_v w1 √(P_S − P1₀).
//! The law is a type parameter of the kernel, chosen once per batch.

use super::lanes::{inv_fourth_root, Pack, Simd};
use super::params::{ModelParams, ValveLaw};

/// Regularised orifice law sq(Δp) = Δp / (Δp² + p_tr²)^¼, with `p_tr2` = p_tr².
#[inline(always)]
pub fn sq(dp: f64, p_tr2: f64) -> f64 {
    dp * inv_fourth_root(dp * dp + p_tr2)
}

/// Per-lane valve coefficients, with the number of valves per actuator folded in.
#[derive(Debug, Clone, Copy)]
pub struct ValveLane {
    /// n_val·K_v·w_i for the four ports, m²/(s·√Pa).
    pub kw1: f64,
    pub kw2: f64,
    pub kw3: f64,
    pub kw4: f64,
    pub p_r: f64,
    pub p_tr2: f64,
    /// Linear valve: n_val·K_q (m²/s) and n_val·K_q·A2/A1.
    pub kq1: f64,
    pub kq2: f64,
    /// 1 where the set's valves follow the linear law, 0 for the orifice law: read by
    /// [`EitherLaw`] (a batch shares one law).
    pub linear: f64,
}

crate::lanes::soa!(ValveLane => ValveSoa { kw1, kw2, kw3, kw4, p_r, p_tr2, kq1, kq2, linear });

impl ValveLane {
    /// The coefficients of one parameter set (docs/model.md §3; the linear valve's K_q at the
    /// no-load cap pressure, §5).
    pub fn of(m: &ModelParams) -> Self {
        let sv = &m.servovalve;
        let k = sv.n_val * sv.kv * sv.w3;
        let (p1_0, _) = m.no_load_pressures();
        let kq = sv.n_val * sv.kv * sv.r1 * sv.w3 * (sv.p_s - p1_0).sqrt();
        ValveLane {
            kw1: k * sv.r1,
            kw2: k * sv.r2,
            kw3: k,
            kw4: k * sv.r4,
            p_r: sv.p_r,
            p_tr2: sv.p_tr * sv.p_tr,
            kq1: kq,
            kq2: kq * m.actuator.a2 / m.actuator.a1,
            linear: f64::from(u8::from(m.valve_law == ValveLaw::Linear)),
        }
    }
}

/// One parameter set's valves under its `valve_law`, evaluated at single states outside the time
/// loop (the state map of a diagnosis): the kernel's own flow laws, not a copy.
#[derive(Debug, Clone, Copy)]
pub struct Valves {
    lane: ValveLane,
    p_s: f64,
    law: ValveLaw,
}

impl Valves {
    pub fn of(m: &ModelParams) -> Self {
        Valves {
            lane: ValveLane::of(m),
            p_s: m.servovalve.p_s,
            law: m.valve_law,
        }
    }

    /// (n_val·q_in1, n_val·q_out2) at spool position `x` (m) and chamber pressures (Pa), m³/s.
    pub fn flows(&self, x: f64, p1: f64, p2: f64) -> (f64, f64) {
        match self.law {
            ValveLaw::Orifice => Orifice::flows(&self.lane, x, p1, p2, self.p_s),
            ValveLaw::Linear => Linear::flows(&self.lane, x, p1, p2, self.p_s),
        }
    }

    /// ∂(flows)/∂x on the side of `x` (x ≤ 0 counts as the closing side), m²/s: both laws are
    /// linear in x on each side, so it is the flow at a unit opening on that side.
    pub fn gains(&self, x: f64, p1: f64, p2: f64) -> (f64, f64) {
        let side = if x > 0.0 { 1.0 } else { -1.0 };
        let (g1, g2) = self.flows(side, p1, p2);
        (side * g1, side * g2)
    }
}

/// A servo-valve flow law: (spool x, P1, P2, supply P_S) → (n_val·q_in1, n_val·q_out2) in m³/s.
pub trait FlowLaw: Copy + Send + Sync + 'static {
    const NAME: &'static str;
    /// The published law (the orifice's): the kernel's vector builds are made for it, for the
    /// other only on the bare plant's full batches (`crate::builds`).
    const USUAL: bool = false;
    fn flows(c: &ValveLane, x: f64, p1: f64, p2: f64, p_s: f64) -> (f64, f64);

    /// [`FlowLaw::flows`] in lanes `l0 .. l0 + W` of a batch at once, with the same operations
    /// lane by lane (the default takes the lanes one at a time).
    #[inline(always)]
    fn flows_lanes<const N: usize, S: Simd, const G: usize>(
        c: &ValveSoa<N>,
        l0: usize,
        [x, p1, p2, p_s]: [Pack<S, G>; 4],
    ) -> (Pack<S, G>, Pack<S, G>) {
        let mut lanes = [[0.0; 16]; 2];
        let (mut q1, mut q2) = (Pack::splat(0.0), Pack::splat(0.0));
        let mut v = [[0.0; 16]; 4];
        for g in 0..G {
            for (v, p) in v.iter_mut().zip([x, p1, p2, p_s]) {
                p.0[g].store(v);
            }
            for i in 0..S::LANES {
                let lane = c.lane(l0 + S::LANES * g + i);
                (lanes[0][i], lanes[1][i]) = Self::flows(&lane, v[0][i], v[1][i], v[2][i], v[3][i]);
            }
            (q1.0[g], q2.0[g]) = (S::load(&lanes[0]), S::load(&lanes[1]));
        }
        (q1, q2)
    }
}

/// Square-root orifice law (baseline).
#[derive(Debug, Clone, Copy, Default)]
pub struct Orifice;

impl FlowLaw for Orifice {
    const NAME: &'static str = "orifice";
    const USUAL: bool = true;
    #[inline(always)]
    fn flows(c: &ValveLane, x: f64, p1: f64, p2: f64, p_s: f64) -> (f64, f64) {
        let pos = x > 0.0;
        // x > 0: supply → chamber 1 through w1, chamber 2 → return through w2.
        // x ≤ 0: chamber 1 → return through w3, supply → chamber 2 through w4 (x carries the sign).
        let dp1 = if pos { p_s - p1 } else { p1 - c.p_r };
        let k1 = if pos { c.kw1 } else { c.kw3 };
        let dp2 = if pos { p2 - c.p_r } else { p_s - p2 };
        let k2 = if pos { c.kw2 } else { c.kw4 };
        (k1 * x * sq(dp1, c.p_tr2), k2 * x * sq(dp2, c.p_tr2))
    }

    /// [`Orifice::flows`] across the lanes: the lands selected lane by lane, one root per flow.
    #[inline(always)]
    fn flows_lanes<const N: usize, S: Simd, const G: usize>(
        c: &ValveSoa<N>,
        l0: usize,
        [x, p1, p2, p_s]: [Pack<S, G>; 4],
    ) -> (Pack<S, G>, Pack<S, G>) {
        let ld = |a: &[f64; N]| Pack::<S, G>::load(a, l0);
        let (p_r, p_tr2) = (ld(&c.p_r), ld(&c.p_tr2));
        let pos = x.gt(Pack::splat(0.0));
        let dp1 = pos.select(p_s - p1, p1 - p_r);
        let k1 = pos.select(ld(&c.kw1), ld(&c.kw3));
        let dp2 = pos.select(p2 - p_r, p_s - p2);
        let k2 = pos.select(ld(&c.kw2), ld(&c.kw4));
        let (r1, r2) = Pack::inv_fourth_roots(dp1 * dp1 + p_tr2, dp2 * dp2 + p_tr2);
        (k1 * x * (dp1 * r1), k2 * x * (dp2 * r2))
    }
}

/// Linear valve (docs/model.md §5 counter-example): flow proportional to spool, no pressure dependence.
#[derive(Debug, Clone, Copy, Default)]
pub struct Linear;

impl FlowLaw for Linear {
    const NAME: &'static str = "linear";
    #[inline(always)]
    fn flows(c: &ValveLane, x: f64, _p1: f64, _p2: f64, _p_s: f64) -> (f64, f64) {
        (c.kq1 * x, c.kq2 * x)
    }
}

/// Either law, as each lane's [`ValveLane::linear`] says (a batch shares one law): the same
/// operations as [`Orifice`] or [`Linear`], bit for bit, behind a branch that every evaluation of
/// a batch takes the same way. The kernel's builds for the rarer configurations take it, so that
/// one build serves both laws (`crate::builds`).
#[derive(Debug, Clone, Copy, Default)]
pub struct EitherLaw;

impl FlowLaw for EitherLaw {
    const NAME: &'static str = "either";
    #[inline(always)]
    fn flows(c: &ValveLane, x: f64, p1: f64, p2: f64, p_s: f64) -> (f64, f64) {
        if c.linear != 0.0 {
            Linear::flows(c, x, p1, p2, p_s)
        } else {
            Orifice::flows(c, x, p1, p2, p_s)
        }
    }

    #[inline(always)]
    fn flows_lanes<const N: usize, S: Simd, const G: usize>(
        c: &ValveSoa<N>,
        l0: usize,
        xs: [Pack<S, G>; 4],
    ) -> (Pack<S, G>, Pack<S, G>) {
        if c.linear[l0] != 0.0 {
            Linear::flows_lanes(c, l0, xs)
        } else {
            Orifice::flows_lanes(c, l0, xs)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sq_tends_to_signed_sqrt() {
        let p_tr2 = 1e10;
        for dp in [1e7, -1e7, 2.5e6] {
            let exact = f64::signum(dp) * f64::abs(dp).sqrt();
            assert!((sq(dp, p_tr2) - exact).abs() / exact.abs() < 1e-3);
        }
        assert_eq!(sq(0.0, p_tr2), 0.0);
        // Slope at the origin is 1/√p_tr.
        let h = 1.0;
        let slope = (sq(h, p_tr2) - sq(-h, p_tr2)) / (2.0 * h);
        assert!((slope - 1.0 / 1e5f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn inv_fourth_root_is_accurate_to_two_ulp() {
        // Four octaves of mantissa (the seed's period) at several scales, and the kernel's range.
        let mut worst = 0.0f64;
        let mut s = 1e-300;
        while s < 1e300 {
            for k in 0..997 {
                let x = s * (1.0 + 15.0 * k as f64 / 997.0);
                let exact = x.powf(-0.25);
                let y = inv_fourth_root(x);
                worst = worst.max(((y - exact) / exact).abs());
            }
            s *= 1e7;
        }
        assert!(
            worst < 2.0 * f64::EPSILON,
            "largest relative error {worst:e}"
        );
    }

    #[test]
    fn orifice_selects_the_right_lands() {
        let c = ValveLane {
            kw1: 1.0,
            kw2: 2.0,
            kw3: 3.0,
            kw4: 4.0,
            p_r: 1e5,
            p_tr2: 1e-6,
            kq1: 0.0,
            kq2: 0.0,
            linear: 0.0,
        };
        let (p1, p2, ps) = (8e6, 12e6, 20e6);
        let (q1, q2) = Orifice::flows(&c, 0.01, p1, p2, ps);
        assert!((q1 - 0.01 * (ps - p1).sqrt()).abs() < 1e-9);
        assert!((q2 - 2.0 * 0.01 * (p2 - 1e5).sqrt()).abs() < 1e-9);
        let (q1, q2) = Orifice::flows(&c, -0.01, p1, p2, ps);
        assert!((q1 + 3.0 * 0.01 * (p1 - 1e5).sqrt()).abs() < 1e-9);
        assert!((q2 + 4.0 * 0.01 * (ps - p2).sqrt()).abs() < 1e-9);
    }
}
