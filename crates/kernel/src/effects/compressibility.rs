//! Effect `compressibility`: effective bulk modulus and dead volume. Every chamber gains a dead
//! volume V_x (hoses, manifold, valve block), and its oil a wall/hose compliance and an
//! entrained-air fraction ε (isothermal, at atmospheric pressure p_atm):
//!
//! ```text
//! dP/dt = β_e(p)/(V + V_x) · (flows),   1/β_e(p) = 1/(beta_ratio·β) + ε·p_atm/p²
//! ```
//!
//! with p the absolute chamber pressure (gauge + p_atm, floored at p_atm/10 so the air term stays
//! finite near cavitation). Its signature: a softer oil column, so the closed-loop amplitude ratio
//! and phase change more at higher frequency (nearer the oil-column resonance, ≈ 10 Hz for the
//! default table); with air, more at large amplitude, where one chamber's pressure falls.
//! Isothermal air (polytropic exponent 1) is a choice: bubbles in oil exchange heat quickly, and
//! it avoids a `powf` in the step.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "compressibility",
    summary: "a softer oil column: dead volume, entrained air, hose compliance",
    params: Params::FIELDS,
    stages: &[Stage::free(&["dead_volume", "air_fraction"])],
};

params! {
    /// Effect `compressibility`: effective bulk modulus and dead volume. Each chamber gains a dead
    /// volume (hoses, manifold) and its oil an entrained-air fraction and a wall compliance:
    /// 1/β_e = 1/(beta_ratio·β) + air_fraction·p_atm/p², with p the absolute chamber pressure.
    pub struct Params {
        dead_volume: "m³", "m3", 0.02, Range::closed(0.0, 1.0), Chosen,
            "Dead volume added to every chamber (hoses, manifold, valve block) [chosen: 20 L].";
        beta_ratio: "-", "", 1.0, Range::closed(0.05, 1.0), Chosen,
            "Effective over nominal bulk modulus at high pressure (hose and wall compliance) [chosen: 1 = none].";
        air_fraction: "-", "", 0.01, Range::closed(0.0, 0.2), Chosen,
            "Entrained-air volume fraction at atmospheric pressure, isothermal [chosen: 1 %].";
    }
}

/// Atmospheric pressure, Pa (ISO 2533 standard atmosphere).
pub const P_ATM: f64 = 101_325.0;

pub struct Compressibility<const N: usize> {
    on: [f64; N],
    /// Nominal oil bulk modulus β, Pa.
    beta: [f64; N],
    /// 1/(beta_ratio·β), 1/Pa.
    inv_beta_e: [f64; N],
    /// ε·p_atm, Pa.
    air: [f64; N],
    /// Dead volume per chamber, m³.
    v_x: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for Compressibility<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        Compressibility {
            on: super::lane_mask::<N, Self>(&p),
            beta: p.map(|m| m.actuator().beta),
            inv_beta_e: p.map(|m| 1.0 / (Params::of(m).beta_ratio * m.actuator().beta)),
            air: p.map(|m| Params::of(m).air_fraction * P_ATM),
            v_x: p.map(|m| Params::of(m).dead_volume),
        }
    }
}

impl<const N: usize> Compressibility<N> {
    /// β_e/V of one chamber at gauge pressure `p`, from the baseline's β/V (`b`).
    #[inline(always)]
    fn one(&self, l: usize, b: f64, p: f64) -> f64 {
        let pa = (p + P_ATM).max(0.1 * P_ATM);
        let beta_e = 1.0 / (self.inv_beta_e[l] + self.air[l] / (pa * pa));
        let volume = self.beta[l] / b + self.v_x[l];
        b + self.on[l] * (beta_e / volume - b)
    }
}

impl<const N: usize> Compressibility<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 5] {
        [
            self.on[l],
            self.beta[l],
            self.inv_beta_e[l],
            self.air[l],
            self.v_x[l],
        ]
    }
}

impl<const N: usize> Effect<N> for Compressibility<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// β_e/V of both chambers (cap, rod) of an actuator, from the baseline's β/V1, β/V2.
    #[inline(always)]
    fn chamber_stiffness(&self, c: hook::Chambers, _s: &Self::State) -> (f64, f64) {
        (self.one(c.lane, c.b.0, c.p1), self.one(c.lane, c.b.1, c.p2))
    }
}
