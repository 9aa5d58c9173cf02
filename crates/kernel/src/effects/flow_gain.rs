//! Effect `flow_gain`: a flow-gain curve of unknown form. The valve's effective opening is the
//! spool position times a gain that depends on the opening,
//!
//! ```text
//! x_eff = x · g(|x| / x_ref),   g piecewise linear through (0, g0), (0.05, g1), (0.15, g2),
//!                               (0.35, g3), (0.7, g4), constant beyond 0.7
//! ```
//!
//! with x_ref the full spool stroke. It covers the shapes a metering edge can have without naming
//! one: a gain that falls with opening (saturation), one that grows (expansion: ports that widen),
//! and a gain near null unlike the rest (g0 < g1: overlap, a dead band; g0 > g1: underlap). The
//! knots sit where the tests put the spool (a few per cent of the stroke for small tests, about
//! half for the largest). Its signature: odd distortion and an amplitude ratio that change with the
//! velocity demand, in the direction and at the openings the curve says. [chosen: five knots,
//! linear between them — enough for a monotone or a null-region shape, few enough for a campaign
//! of eight tests to determine; g ≡ 1 is the baseline.]

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "valve flow nonlinearity",
    summary: "a flow-gain curve of unknown form: gain against spool opening at five knots",
    params: Params::FIELDS,
    stages: &[Stage::free(&["g0", "g1", "g2", "g3", "g4"])],
};

/// Knots of the curve, as fractions of x_ref.
pub const KNOTS: [f64; 5] = [0.0, 0.05, 0.15, 0.35, 0.7];

params! {
    /// Effect `flow_gain`: x_eff = x·g(|x|/x_ref), g piecewise linear through the knots.
    pub struct Params {
        g0: "-", "", 1.0, Range::closed(0.0, 10.0), Chosen,
            "Flow gain at null (|x| = 0) relative to the baseline [chosen: 1 = the baseline].";
        g1: "-", "", 1.0, Range::closed(0.0, 10.0), Chosen,
            "Flow gain at |x| = 0.05 x_ref [chosen: 1].";
        g2: "-", "", 1.0, Range::closed(0.0, 10.0), Chosen,
            "Flow gain at |x| = 0.15 x_ref [chosen: 1].";
        g3: "-", "", 1.0, Range::closed(0.0, 10.0), Chosen,
            "Flow gain at |x| = 0.35 x_ref [chosen: 1].";
        g4: "-", "", 1.0, Range::closed(0.0, 10.0), Chosen,
            "Flow gain at |x| = 0.7 x_ref and beyond [chosen: 1].";
        x_ref: "m", "m", 19.05e-3, Range::gt(0.0), Chosen,
            "Full spool stroke the knots are fractions of [chosen: 19.05 mm, the rated stroke of docs/model.md §1].";
    }
}

pub struct FlowGain<const N: usize> {
    /// Gain at each knot, per lane (all 1 where the effect is off).
    g: [[f64; N]; 5],
    inv_x_ref: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for FlowGain<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let q = p.map(Params::of);
        let knot = |l: usize, k: usize| [q[l].g0, q[l].g1, q[l].g2, q[l].g3, q[l].g4][k];
        FlowGain {
            g: std::array::from_fn(|k| std::array::from_fn(|l| 1.0 + on[l] * (knot(l, k) - 1.0))),
            inv_x_ref: q.map(|q| 1.0 / q.x_ref),
        }
    }
}

impl<const N: usize> FlowGain<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 6] {
        [
            self.g[0][l],
            self.g[1][l],
            self.g[2][l],
            self.g[3][l],
            self.g[4][l],
            self.inv_x_ref[l],
        ]
    }
}

impl<const N: usize> Effect<N> for FlowGain<N> {
    type State = [[f64; N]; 0];

    fn initial_state(&self) -> Self::State {
        []
    }

    /// Effective opening of spool position `x`.
    #[inline(always)]
    fn opening(&self, c: hook::Opening, _s: &Self::State) -> f64 {
        let (l, x) = (c.lane, c.x);
        let r = x.abs() * self.inv_x_ref[l];
        let mut g = self.g[4][l];
        for k in (0..4).rev() {
            // Linear between knots k and k+1 where r lies there (a select, no early exit).
            let w = (r - KNOTS[k]) / (KNOTS[k + 1] - KNOTS[k]);
            let inside = r < KNOTS[k + 1];
            g = if inside {
                self.g[k][l] + w * (self.g[k + 1][l] - self.g[k][l])
            } else {
                g
            };
        }
        x * g
    }
}
