//! Effect `flow_saturation`: spool-to-flow nonlinearity. The metering area saturates toward large
//! openings, x_eff = x_sat·tanh(x/x_sat). Its signature: lost flow where the tests demand the most
//! velocity, so a lower amplitude ratio and more odd distortion at large amplitude, nothing at
//! small amplitude.

use crate::kernel::params::ModelParams;

pub struct FlowSaturation<const N: usize> {
    on: [f64; N],
    x_sat: [f64; N],
    inv_x_sat: [f64; N],
}

impl<const N: usize> FlowSaturation<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        FlowSaturation {
            on: super::lane_mask(&p, "flow_saturation"),
            x_sat: p.map(|m| m.flow_saturation.x_sat),
            inv_x_sat: p.map(|m| 1.0 / m.flow_saturation.x_sat),
        }
    }

    /// Effective opening of spool position `x`.
    #[inline(always)]
    pub fn opening(&self, l: usize, x: f64) -> f64 {
        x + self.on[l] * (self.x_sat[l] * (x * self.inv_x_sat[l]).tanh() - x)
    }
}
