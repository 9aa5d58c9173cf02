//! Effect `spool_overlap`: lands that overlap their ports by δ, a dead band around null:
//! no flow while |x| ≤ δ, then x_eff = sign(x)·(|x| − δ).
use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()), // its registry line names it
    family: "valve flow nonlinearity",
    summary: "spool lands that overlap their ports: a dead band around null",
    params: Params::FIELDS,
    stages: &[Stage::free(&["delta"])],
};
params! {
    pub struct Params {
        delta: "m", "m", 0.2e-3, Range::closed(0.0, 5e-3), Chosen, "Overlap δ [chosen: 0.2 mm].";
    }
}

pub struct SpoolOverlap<const N: usize> {
    delta: [f64; N], // 0 where the effect is off
}
impl<const N: usize> LibraryEffect<N> for SpoolOverlap<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        SpoolOverlap { delta: std::array::from_fn(|l| on[l] * Params::of(p[l]).delta) }
    }
}
impl<const N: usize> Effect<N> for SpoolOverlap<N> {
    type State = [[f64; N]; 0];
    // MOVES_SPOOL stays false: the lands meter the flow; a spool LVDT reads the spool itself.
    fn initial_state(&self) -> Self::State {
        []
    }
    fn opening(&self, c: hook::Opening, _s: &Self::State) -> f64 {
        c.x.signum() * (c.x.abs() - self.delta[c.lane]).max(0.0)
    }
}
