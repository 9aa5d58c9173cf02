//! Effect `flow_saturation`: spool-to-flow nonlinearity. The metering area saturates toward large
//! openings, x_eff = x_sat·tanh(x/x_sat). Its signature: lost flow where the tests demand the most
//! velocity, so a lower amplitude ratio and more odd distortion at large amplitude, nothing at
//! small amplitude.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "valve flow nonlinearity",
    summary: "the metering area of the valves saturates toward large openings",
    params: Params::FIELDS,
    stages: &[Stage::free(&["x_sat"])],
};

params! {
    /// Effect `flow_saturation`: spool-to-flow nonlinearity; the metering area saturates,
    /// x_eff = x_sat·tanh(x/x_sat).
    pub struct Params {
        x_sat: "m", "m", 0.012, Range::gt(0.0), Chosen,
            "Spool opening scale of the saturation x_eff = x_sat·tanh(x/x_sat) [chosen: 12 mm of the 19.05 mm stroke].";
    }
}

pub struct FlowSaturation<const N: usize> {
    on: [f64; N],
    x_sat: [f64; N],
    inv_x_sat: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for FlowSaturation<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        FlowSaturation {
            on: super::lane_mask::<N, Self>(&p),
            x_sat: p.map(|m| Params::of(m).x_sat),
            inv_x_sat: p.map(|m| 1.0 / Params::of(m).x_sat),
        }
    }
}

impl<const N: usize> FlowSaturation<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 3] {
        [self.on[l], self.x_sat[l], self.inv_x_sat[l]]
    }
}

impl<const N: usize> Effect<N> for FlowSaturation<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// Effective opening of spool position `x`.
    #[inline(always)]
    fn opening(&self, c: hook::Opening, _s: &Self::State) -> f64 {
        let (l, x) = (c.lane, c.x);
        x + self.on[l] * (self.x_sat[l] * (x * self.inv_x_sat[l]).tanh() - x)
    }
}
