//! Effect `leakage`: internal leakage across the piston q_i = c_int (P1 − P2) (from chamber 1
//! into chamber 2) and external leakage q_e = c_ext·P from each chamber to drain. Its signature:
//! a flow loss proportional to the load pressure, so a lower amplitude ratio and a phase lead
//! that are largest where the force is (low frequency, large amplitude); neutral when off
//! (both coefficients 0).

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "leakage",
    summary: "internal leakage across the piston and external leakage to drain",
    params: Params::FIELDS,
    // External leakage is a second stage: to first order it acts on the load pressure as an
    // internal leakage would (for a symmetric actuator, one of c_ext/2: Merritt, Hydraulic
    // Control Systems, 1967, §5.4, the total leakage coefficient C_ip + C_ep/2; these actuators
    // are single-ended), which the first stage fits; what is left, the drained mean pressure and
    // the steady offset it leaves, forward selection adds where it pays (a leakage of c_ext 6e-11
    // alone was fitted as c_int 1.7e-11, leaving 2.4x the noise; issue 51).
    stages: &[
        Stage::free(&["c_int"]),
        Stage {
            label: "external leakage",
            free: &["c_ext"],
            scan: None,
            size: None,
            shape: None,
            // [chosen] c_ext, 0 by default, starts at 1e-11 m³/(s·Pa) (half the default
            // internal leakage): from 0 its step is on the scale of 1 m³/(s·Pa).
            start: &[("c_ext", 1.0e-11)],
        },
    ],
};

params! {
    /// Effect `leakage`: internal leakage across the piston, q = c_int (P1 − P2), and external
    /// leakage from each chamber to drain, q = c_ext·P.
    pub struct Params {
        c_int: "m³/(s·Pa)", "m3_per_s_pa", 2.0e-11, Range::ge(0.0), Chosen,
            "Internal (cross-piston) leakage coefficient [chosen: 12 L/min at 10 MPa across the piston].";
        c_ext: "m³/(s·Pa)", "m3_per_s_pa", 0.0, Range::ge(0.0), Chosen,
            "External leakage coefficient of each chamber to drain [chosen: none by default].";
    }
}

pub struct Leakage<const N: usize> {
    c_int: [f64; N],
    c_ext: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for Leakage<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        Leakage {
            c_int: std::array::from_fn(|l| on[l] * Params::of(p[l]).c_int),
            c_ext: std::array::from_fn(|l| on[l] * Params::of(p[l]).c_ext),
        }
    }
}

impl<const N: usize> Leakage<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 2] {
        [self.c_int[l], self.c_ext[l]]
    }
}

impl<const N: usize> Effect<N> for Leakage<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// Net (into chamber 1, out of chamber 2) from the valve flows `q`.
    #[inline(always)]
    fn flows(&self, c: hook::Flows, _s: &Self::State) -> (f64, f64) {
        let (l, q, p1, p2) = (c.lane, c.q, c.p1, c.p2);
        let cross = self.c_int[l] * (p1 - p2);
        (
            q.0 - cross - self.c_ext[l] * p1,
            q.1 - cross + self.c_ext[l] * p2,
        )
    }
}
