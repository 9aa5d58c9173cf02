//! Effect `hold_down`: hold-down strut stiffness nonlinearity, F = −k3·y³ on top of the linear
//! −K·y of the baseline. Its signature: odd harmonics and a changed amplitude ratio where the
//! displacement is large (low frequency, large amplitude), nothing at small displacement.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "hold-down stiffness",
    summary: "a cubic hardening of the hold-down struts",
    params: Params::FIELDS,
    stages: &[Stage::free(&["k3"])],
};

params! {
    /// Effect `hold_down`: hold-down strut stiffness nonlinearity, F = −k3·y³ on top of −K·y.
    pub struct Params {
        k3: "N/m³", "n_per_m3", 1.0e8, Range::any(), Chosen,
            "Cubic stiffness of the hold-down struts, positive = hardening [chosen: k3·y³ equals K·y at y = 11 cm].";
    }
}

pub struct HoldDown<const N: usize> {
    k3: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for HoldDown<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        HoldDown {
            k3: std::array::from_fn(|l| {
                if on[l] > 0.0 {
                    Params::of(p[l]).k3
                } else {
                    0.0
                }
            }),
        }
    }
}

impl<const N: usize> HoldDown<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 1] {
        [self.k3[l]]
    }
}

impl<const N: usize> Effect<N> for HoldDown<N> {
    type State = [[f64; N]; 0];
    const HYDRAULIC: bool = false; // a force on the platen alone

    fn initial_state(&self) -> Self::State {
        []
    }

    /// Force of the cubic term on the platen, N.
    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, _s: &Self::State) -> f64 {
        -self.k3[c.lane] * c.y * c.y * c.y
    }
}
