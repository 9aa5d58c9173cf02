//! Effect `overlap_compensator`: a compensator of the spool's overlap (`spool_overlap`, a dead
//! band of δ around null): the command jumps the band, u' = u + (δ/k_sp)·clamp(u/u_r, −1, 1),
//! ramped over ±u_r so that it stays continuous through null.
use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()), // its registry line names it
    family: super::COMPENSATION,
    summary: "the command pushed across a spool overlap's dead band",
    params: Params::FIELDS,
    stages: &[Stage::free(&["delta"])],
};
params! {
    pub struct Params {
        delta: "m", "m", 0.2e-3, Range::closed(0.0, 5e-3), Chosen, "Overlap jumped, as spool travel [chosen: the tutorial's 0.2 mm].";
        ramp_v: "V", "v", 0.05, Range::open_closed(0.0, 1.0), Chosen, "Command u_r over which the jump ramps in [chosen].";
    }
}

pub struct OverlapCompensator<const N: usize> {
    jump: [f64; N], // δ/k_sp, V; 0 where the compensator is off
    ramp: [f64; N],
}
impl<const N: usize> LibraryEffect<N> for OverlapCompensator<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        OverlapCompensator {
            jump: std::array::from_fn(|l| on[l] * Params::of(p[l]).delta / p[l].servovalve().k_sp),
            ramp: std::array::from_fn(|l| Params::of(p[l]).ramp_v),
        }
    }
}
impl<const N: usize> Effect<N> for OverlapCompensator<N> {
    type State = [[f64; N]; 0];
    fn initial_state(&self) -> Self::State {
        []
    }
    fn command(&self, c: hook::Command, _s: &mut Self::State) -> f64 {
        c.u + self.jump[c.lane] * (c.u / self.ramp[c.lane]).clamp(-1.0, 1.0)
    }
}
