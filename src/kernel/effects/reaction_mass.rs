//! Effect `reaction_mass`: the actuators push against a reaction mass m_r that sits on a
//! compliant foundation (natural frequency f_r, damping ratio ζ_r):
//!
//! ```text
//! m_r ÿ_r = −F − k_r y_r − c_r ẏ_r,   k_r = m_r (2π f_r)²,   c_r = 2 ζ_r m_r (2π f_r)
//! ```
//!
//! The actuator stroke, the chamber volumes and the LVDT (the displacement feedback) follow
//! y − y_r; the accelerometer sees the platen's absolute acceleration. The platen's own stiffness,
//! damping and friction still act to fixed ground (a choice: they are small, and the bearings'
//! reaction path is not in docs/model.md). Its signature: the measured acceleration and displacement
//! stop being one body's (a₁ ≠ −ω²·x₁), increasingly with frequency, as (m/m_r)·(f/f_r)²/(1 − (f/f_r)²).

use super::PlantView;
use crate::kernel::params::ModelParams;

/// State indices in [`super::EffectSet`]: reaction-mass displacement and velocity.
pub const YR: usize = 9;
pub const VR: usize = 10;

pub struct ReactionMass<const N: usize> {
    /// 1/m_r where on, 0 where off (the states then stay at rest).
    inv_m: [f64; N],
    k: [f64; N],
    c: [f64; N],
}

impl<const N: usize> ReactionMass<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let w = p.map(|m| 2.0 * std::f64::consts::PI * m.reaction_mass.f_r);
        ReactionMass {
            inv_m: p.map(|m| if m.effects.reaction_mass { 1.0 / m.reaction_mass.m_r } else { 0.0 }),
            k: std::array::from_fn(|l| p[l].reaction_mass.m_r * w[l] * w[l]),
            c: std::array::from_fn(|l| 2.0 * p[l].reaction_mass.zeta_r * p[l].reaction_mass.m_r * w[l]),
        }
    }

    /// Actuator stroke and stroke rate, from the platen's absolute displacement and velocity.
    #[inline(always)]
    pub fn stroke<const S: usize>(&self, l: usize, y: f64, v: f64, s: &[[f64; N]; S]) -> (f64, f64) {
        (y - s[YR][l], v - s[VR][l])
    }

    #[inline(always)]
    pub fn derivs<const S: usize>(&self, plant: &PlantView<'_, N>, s: &[[f64; N]; S], ds: &mut [[f64; N]; S]) {
        for l in 0..N {
            ds[YR][l] = s[VR][l];
            ds[VR][l] = self.inv_m[l] * (-plant.f_act[l] - self.k[l] * s[YR][l] - self.c[l] * s[VR][l]);
        }
    }
}
