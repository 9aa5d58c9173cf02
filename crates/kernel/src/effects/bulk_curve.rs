//! Effect `bulk_curve`: a pressure-dependent bulk modulus of unknown form. The oil column's
//! stiffness β/V of each chamber is scaled by a gain that depends on the chamber's pressure,
//!
//! ```text
//! β_e(p) = β · b(p / P_S),   b piecewise linear through (0, b0), (0.5, b1), (1, b2),
//!                            constant outside [0, 1]
//! ```
//!
//! with p the chamber's gauge pressure and P_S the supply pressure. It covers what the fixed
//! forms of `compressibility` do not pin down: entrained air (a modulus that falls steeply at low
//! pressure, b0 ≪ b1), hose and wall compliance (a modulus below the oil's everywhere), and an
//! oil stiffening with pressure (b rising towards P_S). Its signature: a softer or stiffer oil
//! column, so amplitude ratio and phase change near the oil-column resonance, and more at large
//! amplitude when the stiffness change sits at the pressures a chamber reaches only there.
//! [chosen: three knots, half the supply apart — a chamber's pressure spans 0 … P_S, and a
//! campaign of sine tests determines a level, a slope and a bend of the curve, not more; three
//! parameters also keep a diagnosis's fit of it cheap. b ≡ 1 is the baseline.]

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "compressibility",
    summary: "a bulk modulus of unknown form: its gain against chamber pressure at three knots",
    params: Params::FIELDS,
    stages: &[Stage::free(&["b0", "b1", "b2"])],
};

/// Knots of the curve, as fractions of the supply pressure.
pub const KNOTS: [f64; 3] = [0.0, 0.5, 1.0];

params! {
    /// Effect `bulk_curve`: β_e(p) = β·b(p/P_S), b piecewise linear through three knots.
    pub struct Params {
        b0: "-", "", 1.0, Range::closed(0.01, 10.0), Chosen,
            "Bulk-modulus gain at p = 0 (gauge) relative to the oil's [chosen: 1 = the baseline].";
        b1: "-", "", 1.0, Range::closed(0.01, 10.0), Chosen,
            "Bulk-modulus gain at p = 0.5 P_S [chosen: 1].";
        b2: "-", "", 1.0, Range::closed(0.01, 10.0), Chosen,
            "Bulk-modulus gain at p = P_S and above [chosen: 1].";
    }
}

pub struct BulkCurve<const N: usize> {
    /// Gain at each knot, per lane (all 1 where the effect is off).
    b: [[f64; N]; 3],
    inv_p_s: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for BulkCurve<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let q = p.map(Params::of);
        let knot = |l: usize, k: usize| [q[l].b0, q[l].b1, q[l].b2][k];
        BulkCurve {
            b: std::array::from_fn(|k| std::array::from_fn(|l| 1.0 + on[l] * (knot(l, k) - 1.0))),
            inv_p_s: p.map(|m| 1.0 / m.servovalve().p_s),
        }
    }
}

impl<const N: usize> BulkCurve<N> {
    /// The gain b at gauge pressure `p`.
    #[inline(always)]
    fn gain(&self, l: usize, p: f64) -> f64 {
        let r = p * self.inv_p_s[l];
        let mut g = if r < 0.0 { self.b[0][l] } else { self.b[2][l] };
        for k in (0..2).rev() {
            // Linear between knots k and k+1 where r lies there (a select, no early exit).
            let w = (r - KNOTS[k]) / (KNOTS[k + 1] - KNOTS[k]);
            let inside = r >= KNOTS[k] && r < KNOTS[k + 1];
            g = if inside {
                self.b[k][l] + w * (self.b[k + 1][l] - self.b[k][l])
            } else {
                g
            };
        }
        g
    }
}

impl<const N: usize> BulkCurve<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 4] {
        [self.b[0][l], self.b[1][l], self.b[2][l], self.inv_p_s[l]]
    }
}

impl<const N: usize> Effect<N> for BulkCurve<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// β_e/V of both chambers (cap, rod): the baseline's (or an earlier effect's) β/V times b(p).
    #[inline(always)]
    fn chamber_stiffness(&self, c: hook::Chambers, _s: &Self::State) -> (f64, f64) {
        (
            c.b.0 * self.gain(c.lane, c.p1),
            c.b.1 * self.gain(c.lane, c.p2),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The curve passes through its knots, is linear between them and constant outside.
    #[test]
    fn the_gain_interpolates_the_knots() {
        let mut m = super::super::tests::Defaults::default();
        m.effects.bulk_curve = true;
        m.effect_params.bulk_curve = Params {
            b0: 0.2,
            b1: 1.0,
            b2: 1.5,
        };
        let e = BulkCurve::<1>::new([&m as &dyn ModelView]);
        let p_s = m.servovalve().p_s;
        for (r, want) in [
            (-0.1, 0.2),
            (0.0, 0.2),
            (0.25, 0.6),
            (0.5, 1.0),
            (0.75, 1.25),
            (1.0, 1.5),
            (1.3, 1.5),
        ] {
            assert!(
                (e.gain(0, r * p_s) - want).abs() < 1e-12,
                "b({r}) = {} not {want}",
                e.gain(0, r * p_s)
            );
        }
        // Off: neutral whatever its parameters.
        m.effects.bulk_curve = false;
        let off = BulkCurve::<1>::new([&m]);
        assert_eq!(
            off.chamber_stiffness(
                hook::Chambers {
                    lane: 0,
                    act: 0,
                    b: (3.0, 5.0),
                    p1: 1e6,
                    p2: 9e6
                },
                &[]
            ),
            (3.0, 5.0)
        );
    }
}
