//! Effect `asymmetry`: port/valve asymmetry. The valve flows of extension (flow into the cap
//! side, x > 0) are scaled by `extend_gain` against those of retraction, and actuator 2's valves
//! by `act2_gain` against actuator 1's. Its signature: even harmonics (h2) and a shifted
//! displacement, from a table that extends and retracts differently.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "asymmetry",
    summary: "the valve flows of extension and retraction, or of the two actuators, differ",
    params: Params::FIELDS,
    // Both gains: a table whose actuators' valves differ (act2_gain 0.8) was named a flow-gain
    // curve of 0.9 with act2_gain held at 1, leaving the total force 69x its noise (issue 51);
    // freed, it is fitted to 1e-6. The split pressures it makes are its own signature.
    stages: &[Stage::free(&["extend_gain", "act2_gain"])],
};

params! {
    /// Effect `asymmetry`: port/valve asymmetry. The flow gain for extension (x > 0) differs from
    /// that for retraction, and actuator 2's valves differ from actuator 1's.
    pub struct Params {
        extend_gain: "-", "", 1.05, Range::gt(0.0), Chosen,
            "Flow gain for x > 0 relative to x < 0 [chosen: a 5 % port mismatch].";
        act2_gain: "-", "", 1.0, Range::gt(0.0), Chosen,
            "Flow gain of actuator 2's valves relative to actuator 1's [chosen: equal].";
    }
}

pub struct Asymmetry<const N: usize> {
    extend: [f64; N],
    act2: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for Asymmetry<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        // Off: both gains exactly 1.
        Asymmetry {
            extend: std::array::from_fn(|l| 1.0 + on[l] * (Params::of(p[l]).extend_gain - 1.0)),
            act2: std::array::from_fn(|l| 1.0 + on[l] * (Params::of(p[l]).act2_gain - 1.0)),
        }
    }
}

impl<const N: usize> Asymmetry<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 2] {
        [self.extend[l], self.act2[l]]
    }
}

impl<const N: usize> Effect<N> for Asymmetry<N> {
    type State = [[f64; N]; 0];
    const SPLITS: bool = true;

    fn initial_state(&self) -> Self::State {
        []
    }

    /// The actuators differ only where actuator 2's gain is not 1.
    fn symmetric(&self) -> bool {
        self.act2.iter().all(|&g| g == 1.0)
    }

    /// Valve flows of actuator `act`, scaled.
    #[inline(always)]
    fn flows(&self, c: hook::Flows, _s: &Self::State) -> (f64, f64) {
        let (l, q) = (c.lane, c.q);
        let g = (if q.0 > 0.0 { self.extend[l] } else { 1.0 })
            * (if c.act == 1 { self.act2[l] } else { 1.0 });
        (g * q.0, g * q.1)
    }
}
