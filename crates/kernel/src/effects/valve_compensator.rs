//! Effect `valve_compensator`: a physics-based valve compensator in the controller (docs/model.md
//! §8), not a physical effect of the plant. The servo-valve's orifice law makes a port's flow
//! x·√Δp, so the same command moves the table faster or slower as the load changes the chamber
//! pressures: the odd harmonics of the seed paper. The compensator divides the TVC's command by
//! the orifice law's factor measured at the tick (feedback linearisation of the flow):
//!
//! ```text
//! u ≥ 0:  g₁ = √((P_S − P1)/(P_S − P1₀)),  g₂ = √((P2 − P_R)/(P2₀ − P_R))
//! u < 0:  g₁ = √((P1 − P_R)/(P1₀ − P_R)),  g₂ = √((P_S − P2)/(P_S − P2₀))
//! g = mean of g₁, g₂ over the actuators,   u ← u / max(g, g_min)
//! ```
//!
//! with the chamber pressures P1, P2 of each actuator at the tick, the nominal supply P_S and
//! return P_R, and the no-load pressures P1₀, P2₀ (docs/model.md §3), so that g = 1 at no load
//! and the compensator then passes the command unchanged. A negative drop counts as 0. Near a
//! port's zero pressure drop g → 0 and the division would demand an unbounded opening: g_min caps
//! the command's gain at 1/g_min (the authority). It enters after the TVC's sum and before the
//! notches; it has no state and needs no adaptation.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: super::COMPENSATION,
    summary: "a valve compensator: the command divided by the orifice law's √(Δp/Δp₀)",
    params: Params::FIELDS,
    stages: &[Stage::free(&["g_min"])],
};

params! {
    /// Effect `valve_compensator`: the command divided by the orifice law's factor
    /// g = √(Δp/Δp₀) of the ports the command opens, from the chamber pressures at the tick.
    pub struct Params {
        g_min: "1", "ratio", 0.2, Range::open_closed(0.0, 1.0), Chosen,
            "Least factor g the command is divided by: the compensator's authority is 1/g_min [chosen: at most 5× the TVC's command, so that a port near zero pressure drop does not ask the valve for its full opening].";
    }
}

pub struct ValveCompensator<const N: usize> {
    on: [f64; N],
    /// Nominal supply and return pressures, Pa.
    p_s: [f64; N],
    p_r: [f64; N],
    /// 1/Δp₀ of the four port drops, in the order u ≥ 0 (P_S − P1₀, P2₀ − P_R) then u < 0
    /// (P1₀ − P_R, P_S − P2₀), 1/Pa.
    inv_dp0: [[f64; 4]; N],
    g_min: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for ValveCompensator<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        ValveCompensator {
            on: super::lane_mask::<N, Self>(&p),
            p_s: p.map(|m| m.servovalve().p_s),
            p_r: p.map(|m| m.servovalve().p_r),
            inv_dp0: p.map(|m| {
                let sv = m.servovalve();
                let (p1, p2) = m.actuator().no_load_pressures(sv.p_s, sv.p_r);
                [sv.p_s - p1, p2 - sv.p_r, p1 - sv.p_r, sv.p_s - p2].map(|d| 1.0 / d)
            }),
            g_min: p.map(|m| Params::of(m).g_min),
        }
    }
}

impl<const N: usize> ValveCompensator<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 8] {
        let d = self.inv_dp0[l];
        [
            self.on[l],
            self.p_s[l],
            self.p_r[l],
            d[0],
            d[1],
            d[2],
            d[3],
            self.g_min[l],
        ]
    }

    /// The orifice law's factor g of lane `l` for a command of sign `u` at pressures `p`.
    #[inline(always)]
    pub fn factor(&self, l: usize, u: f64, p: &[(f64, f64)]) -> f64 {
        let (p_s, p_r, d) = (self.p_s[l], self.p_r[l], &self.inv_dp0[l]);
        let root = |dp: f64, inv: f64| (dp * inv).max(0.0).sqrt();
        let sum: f64 = p
            .iter()
            .map(|&(p1, p2)| {
                if u >= 0.0 {
                    root(p_s - p1, d[0]) + root(p2 - p_r, d[1])
                } else {
                    root(p1 - p_r, d[2]) + root(p_s - p2, d[3])
                }
            })
            .sum();
        sum / (2 * p.len()) as f64
    }
}

impl<const N: usize> Effect<N> for ValveCompensator<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// The TVC's command divided by the orifice law's factor, its gain capped at 1/g_min.
    #[inline(always)]
    fn command(&self, c: hook::Command, _s: &mut Self::State) -> f64 {
        let l = c.lane;
        // An off lane passes the command untouched, without the four ports' roots (lane.cu
        // multiplies by the switch instead: u + 0·(…) is u for a finite command).
        if self.on[l] == 0.0 {
            return c.u;
        }
        let g = self.factor(l, c.u, &c.p).max(self.g_min[l]);
        c.u + (c.u / g - c.u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compensator and its model, on (g_min as given) or off.
    fn compensator(on: bool, g_min: f64) -> (ValveCompensator<1>, (f64, f64), (f64, f64)) {
        let mut m = super::super::tests::Defaults::default();
        m.effects.valve_compensator = on;
        m.effect_params.valve_compensator = Params { g_min };
        let e = ValveCompensator::<1>::new([&m as &dyn ModelView]);
        let (sv, act) = (m.servovalve(), m.actuator());
        let p1 = (sv.p_s + sv.p_r) / (1.0 + act.a1 / act.a2);
        ((e), (sv.p_s, sv.p_r), (p1, p1 * act.a1 / act.a2))
    }

    fn command(e: &ValveCompensator<1>, u: f64, p: (f64, f64)) -> f64 {
        e.command(
            hook::Command {
                lane: 0,
                u,
                p: [p; 2],
                t: 0.0,
                r: [0.0; 4],
                x: 0.0,
            },
            &mut [],
        )
    }

    /// At the no-load pressures g = 1 for either sign: the command passes unchanged.
    #[test]
    fn at_no_load_the_command_passes() {
        let (e, _, p0) = compensator(true, 0.2);
        for u in [2.5, -2.5] {
            assert!((command(&e, u, p0) - u).abs() < 1e-12 * u.abs(), "{u}");
        }
    }

    /// Each port's drop at a quarter of its no-load drop halves the flow of a command, so the
    /// command is doubled (u ≥ 0: P→A and B→T); at 0.64 of it, divided by 0.8 (u < 0: A→T, P→B).
    #[test]
    fn the_command_is_divided_by_the_root_of_the_drops_ratio() {
        let (e, (p_s, p_r), (p1, p2)) = compensator(true, 0.2);
        let opening = (p_s - 0.25 * (p_s - p1), p_r + 0.25 * (p2 - p_r));
        assert!((command(&e, 1.5, opening) - 3.0).abs() < 1e-9);
        let closing = (p_r + 0.64 * (p1 - p_r), p_s - 0.64 * (p_s - p2));
        assert!((command(&e, -1.6, closing) + 2.0).abs() < 1e-9);
    }

    /// Where the ports' drops vanish the command's gain is capped at 1/g_min; off, the command
    /// passes bit for bit whatever the pressures.
    #[test]
    fn the_authority_is_capped_and_off_passes() {
        let (e, (p_s, p_r), _) = compensator(true, 0.25);
        assert!((command(&e, 1.0, (p_s, p_r)) - 4.0).abs() < 1e-12);
        let (off, (p_s, p_r), _) = compensator(false, 0.25);
        assert_eq!(command(&off, 1.0, (p_s, p_r)).to_bits(), 1.0f64.to_bits());
    }
}
