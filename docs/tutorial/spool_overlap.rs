//! Effect `spool_overlap`: lands that overlap their ports by δ, a dead band around null:
//! no flow while |x| ≤ δ, then x_eff = sign(x)·(|x| − δ).
use super::{Effect, EffectInfo, LibraryEffect, Stage};
use crate::kernel::params::{params, Component, ModelParams, Range};

pub const INFO: EffectInfo = EffectInfo {
    name: "spool_overlap",
    family: "valve flow nonlinearity",
    summary: "spool lands that overlap their ports: a dead band around null",
    params: Params::PARAMS,
    stages: &[Stage::free(&["delta"])],
    moves_spool: false,
};
params! {
    pub struct Params in effect_params.spool_overlap as (Component::Effect(super::EffectId::SpoolOverlap)) {
        delta: "m", "m", 0.2e-3, Range::closed(0.0, 5e-3), Chosen, "Overlap δ [chosen: 0.2 mm].";
    }
}

pub struct SpoolOverlap<const N: usize> {
    delta: [f64; N], // 0 where the effect is off
}
impl<const N: usize> LibraryEffect<N> for SpoolOverlap<N> {
    fn new(p: [&ModelParams; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        SpoolOverlap { delta: std::array::from_fn(|l| on[l] * Params::of(p[l]).delta) }
    }
}
impl<const N: usize> Effect<N> for SpoolOverlap<N> {
    type State = [[f64; N]; 0];
    fn initial_state(&self) -> Self::State {
        []
    }
    fn opening(&self, l: usize, _act: usize, x: f64, _s: &Self::State) -> f64 {
        x.signum() * (x.abs() - self.delta[l]).max(0.0)
    }
    fn spool_position(&self, _l: usize, _act: usize, x: f64, _s: &Self::State) -> f64 {
        x // a spool LVDT reads the spool, not the opening
    }
}
