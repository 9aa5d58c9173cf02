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

/// Regularised orifice law sq(Δp) = Δp / (Δp² + p_tr²)^¼, with `p_tr2` = p_tr².
#[inline(always)]
pub fn sq(dp: f64, p_tr2: f64) -> f64 {
    dp / (dp * dp + p_tr2).sqrt().sqrt()
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
}

/// A servo-valve flow law: (spool x, P1, P2, supply P_S) → (n_val·q_in1, n_val·q_out2) in m³/s.
pub trait FlowLaw: Copy + Send + Sync + 'static {
    const NAME: &'static str;
    fn flows(c: &ValveLane, x: f64, p1: f64, p2: f64, p_s: f64) -> (f64, f64);
}

/// Square-root orifice law (baseline).
#[derive(Debug, Clone, Copy, Default)]
pub struct Orifice;

impl FlowLaw for Orifice {
    const NAME: &'static str = "orifice";
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
    fn orifice_selects_the_right_lands() {
        let c = ValveLane { kw1: 1.0, kw2: 2.0, kw3: 3.0, kw4: 4.0, p_r: 1e5, p_tr2: 1e-6, kq1: 0.0, kq2: 0.0 };
        let (p1, p2, ps) = (8e6, 12e6, 20e6);
        let (q1, q2) = Orifice::flows(&c, 0.01, p1, p2, ps);
        assert!((q1 - 0.01 * (ps - p1).sqrt()).abs() < 1e-9);
        assert!((q2 - 2.0 * 0.01 * (p2 - 1e5).sqrt()).abs() < 1e-9);
        let (q1, q2) = Orifice::flows(&c, -0.01, p1, p2, ps);
        assert!((q1 + 3.0 * 0.01 * (p1 - 1e5).sqrt()).abs() < 1e-9);
        assert!((q2 + 4.0 * 0.01 * (ps - p2).sqrt()).abs() < 1e-9);
    }
}
