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

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "reaction mass",
    summary: "the actuators push against a reaction mass on a compliant foundation",
    params: Params::FIELDS,
    stages: &[Stage {
        label: "",
        // The damping shapes the resonance with the mass and the frequency (issue 51).
        free: &["m_r", "f_r", "zeta_r"],
        // [chosen] Starts a fit scans for `f_r` (a resonance).
        scan: Some(("f_r", &[3.0, 6.0, 12.0, 25.0, 50.0, 100.0])),
        size: None,
        shape: None,
        start: &[],
    }],
};

params! {
    /// Effect `reaction_mass`: the actuators push against a reaction mass on a compliant
    /// foundation, m_r ÿ_r = −F − k_r y_r − c_r ẏ_r. The actuator stroke (and the LVDT) is y − y_r;
    /// the accelerometer sees the platen's absolute acceleration.
    pub struct Params {
        m_r: "kg", "kg", 2.0e6, Range::gt(0.0), Chosen,
            "Reaction mass [chosen: order of a large table's foundation block].";
        f_r: "Hz", "hz", 12.0, Range::closed(0.5, 200.0), Chosen,
            "Natural frequency of the reaction mass on its foundation [chosen].";
        zeta_r: "-", "", 0.1, Range::closed(0.0, 2.0), Chosen,
            "Damping ratio of the reaction mass on its foundation [chosen: soil radiation damping].";
    }
}

/// State indices: reaction-mass displacement and velocity.
pub const YR: usize = 0;
pub const VR: usize = 1;

pub struct ReactionMass<const N: usize> {
    /// 1/m_r where on, 0 where off (the states then stay at rest).
    inv_m: [f64; N],
    k: [f64; N],
    c: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for ReactionMass<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let q = p.map(Params::of);
        let w = q.map(|q| 2.0 * std::f64::consts::PI * q.f_r);
        ReactionMass {
            inv_m: std::array::from_fn(|l| if on[l] > 0.0 { 1.0 / q[l].m_r } else { 0.0 }),
            k: std::array::from_fn(|l| q[l].m_r * w[l] * w[l]),
            c: std::array::from_fn(|l| 2.0 * q[l].zeta_r * q[l].m_r * w[l]),
        }
    }
}

impl<const N: usize> ReactionMass<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 3] {
        [self.inv_m[l], self.k[l], self.c[l]]
    }
}

impl<const N: usize> Effect<N> for ReactionMass<N> {
    type State = [[f64; N]; 2];

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; 2]
    }

    /// Actuator stroke and stroke rate, from the platen's absolute displacement and velocity.
    #[inline(always)]
    fn stroke(&self, c: hook::Motion, s: &Self::State) -> (f64, f64) {
        (c.y - s[YR][c.lane], c.v - s[VR][c.lane])
    }

    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        for l in 0..N {
            ds[YR][l] = s[VR][l];
            ds[VR][l] =
                self.inv_m[l] * (-plant.f_act[l] - self.k[l] * s[YR][l] - self.c[l] * s[VR][l]);
        }
    }
}
