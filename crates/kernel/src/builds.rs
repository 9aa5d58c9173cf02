//! The lane integrators the rest of vshake runs, compiled here, once.
//!
//! [`crate::simulate`]'s integrator is generic over the lane count, the effect and the observer,
//! and a generic function is compiled in the crate that names its types. The functions here name
//! them all, so that the orchestration and the shell, which call only these, compile none of the
//! kernel's time loops: a change above the kernel does not rebuild them. Every observer of one
//! lane count shares one build (`dyn Observer<N>`: one call per controller tick, against the
//! substeps' right-hand sides of every lane).
//!
//! Each build is compiled at a site of its own ([`crate::simulate::Site`]: a module, so a codegen
//! unit, so an LLVM module optimised on its own core), so that the builds are compiled in
//! parallel. What is built, for the published laws (orifice flow, α = ½) and, once more, for
//! every other pair of valve law and damping law (one build that reads the law from the lanes:
//! `servovalve::EitherLaw` and `platen::PowDamping`, the same bits as a build for each pair):
//! - one lane ([`run_lane`]: a single run, its history or its probes): the bare plant and the
//!   effect set, portable and AVX2 (the AVX2 build of one lane is about 20 % faster: wider
//!   moves of the state, `study bench`'s scalar path);
//! - [`EFFECT_LANES`] lanes with an observer ([`run_effect_lanes`]: batches with effects, a fit's
//!   trials): the bare plant and the effect set, portable and AVX2;
//! - [`LANES`] lanes of the bare plant ([`run_bare_lanes`]: design exploration): portable, AVX2
//!   and AVX-512;
//! - [`EFFECT_LANES`] lanes with one library effect alone ([`run_single_effect`], a diagnosis's
//!   screening): the usual configuration, AVX2;
//! - [`LANES`] lanes with one library effect alone that leaves the hydraulics alone
//!   ([`run_wide_single_effect`]: a study or a tuning with a specimen): the usual configuration,
//!   AVX2.
//!
//! The portable build is the law-reading one for every configuration (a CPU without AVX2, or a
//! caller that asks for it); the AVX2 builds are made for the published laws only, outside the
//! bare plant's full batches, where the law-reading pair has its vector builds too
//! (`simulate`'s `dispatch`). 36 copies of the integrator in all (`cargo llvm-lines`), where
//! a build per law pair made 59, before the wide batches of one effect added one for each of the
//! seven effects that leave the hydraulics alone.

use crate::effects::{effect_set, with_single, Baseline, Effect, EffectFn, EffectId};
use crate::excitation::Reference;
use crate::params::ModelParams;
use crate::simulate::{
    self, site, Isa, LaneParams, LaneResult, NoObserver, Observer, SetupError, Site, Solver,
};
use crate::{EFFECT_LANES, LANES};

site! {
    /// One lane, the bare plant.
    one_bare
}
site! {
    /// One lane, the effect set.
    one_set
}
site! {
    /// [`EFFECT_LANES`] lanes, the bare plant.
    effect_lanes_bare
}
site! {
    /// [`EFFECT_LANES`] lanes, the effect set.
    effect_lanes_set
}
site! {
    /// [`LANES`] lanes of the bare plant.
    bare_lanes
}
site! {
    /// One library effect alone.
    single
}
site! {
    /// [`LANES`] lanes with one library effect alone, one that leaves the hydraulics alone.
    wide_single
}

/// The lanes of `lp` (made from `models`; `refs[l]` is lane l's reference) through the effect
/// set when any model switches an effect on, else through the bare plant.
fn run_models<const N: usize, Bare: Site, Set: Site>(
    isa: Isa,
    lp: &LaneParams<N>,
    models: &[&ModelParams],
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut dyn Observer<N>,
) -> Result<[LaneResult; N], SetupError> {
    if models.iter().any(|m| m.effects.any()) {
        let set = effect_set::<N>(models);
        simulate::run_each_on::<N, _, _, Set>(isa, lp, &set, refs, solver, obs)
    } else {
        simulate::run_each_on::<N, _, _, Bare>(isa, lp, &Baseline, refs, solver, obs)
    }
}

/// One run of `model` against `reference`, every tick to `obs`.
pub fn run_lane(
    model: &ModelParams,
    reference: &Reference,
    solver: &Solver,
    obs: &mut dyn Observer<1>,
) -> Result<LaneResult, SetupError> {
    let lp = LaneParams::<1>::new(&[model])?;
    let [r] = run_models::<1, one_bare::Here, one_set::Here>(
        Isa::detected(),
        &lp,
        &[model],
        &[reference],
        solver,
        obs,
    )?;
    Ok(r)
}

/// Up to [`EFFECT_LANES`] models as the lanes of one batch (`refs[l]` for lane l; lanes beyond
/// the models repeat the last model, as [`LaneParams::new`] does).
pub fn run_effect_lanes(
    models: &[&ModelParams],
    refs: &[&Reference; EFFECT_LANES],
    solver: &Solver,
    obs: &mut dyn Observer<EFFECT_LANES>,
) -> Result<[LaneResult; EFFECT_LANES], SetupError> {
    let lp = LaneParams::<EFFECT_LANES>::new(models)?;
    run_models::<EFFECT_LANES, effect_lanes_bare::Here, effect_lanes_set::Here>(
        Isa::detected(),
        &lp,
        models,
        refs,
        solver,
        obs,
    )
}

/// [`LANES`] lanes of the bare plant (no effect), without an observer.
pub fn run_bare_lanes(
    lp: &LaneParams<LANES>,
    refs: &[&Reference; LANES],
    solver: &Solver,
) -> Result<[LaneResult; LANES], SetupError> {
    let obs = &mut NoObserver;
    simulate::run_each_on::<LANES, _, _, bare_lanes::Here>(
        Isa::detected(),
        lp,
        &Baseline,
        refs,
        solver,
        obs,
    )
}

/// Up to [`LANES`] models that switch on library effect `id` alone, an effect that leaves the
/// hydraulics alone (a specimen, a building, a measurement chain:
/// [`crate::effects::Effect::HYDRAULIC`]), as the lanes of one batch with the plant in the bare
/// plant's AVX2 registers, in the usual configuration ([`simulate::run_platen_forces`]);
/// `None` elsewhere (the caller then runs batches of [`EFFECT_LANES`], the same numbers bit for
/// bit). `refs[l]` is lane l's reference.
pub fn run_wide_single_effect(
    id: EffectId,
    models: &[&ModelParams],
    refs: &[&Reference; LANES],
    solver: &Solver,
) -> Option<Result<[LaneResult; LANES], SetupError>> {
    let lp = match LaneParams::<LANES>::new(models) {
        Ok(lp) => lp,
        Err(e) => return Some(Err(e)),
    };
    let lanes: [&ModelParams; LANES] = std::array::from_fn(|l| models[l.min(models.len() - 1)]);
    with_single(
        id,
        lanes,
        WideSingle {
            lp: &lp,
            refs,
            solver,
        },
    )
}

/// [`run_wide_single_effect`]'s call, generic over the effect.
struct WideSingle<'a> {
    lp: &'a LaneParams<LANES>,
    refs: &'a [&'a Reference; LANES],
    solver: &'a Solver,
}

impl EffectFn<LANES> for WideSingle<'_> {
    type Output = Option<Result<[LaneResult; LANES], SetupError>>;
    fn call<E: Effect<LANES>>(self, effect: &E) -> Self::Output {
        // Built for the effects that leave the hydraulics alone only.
        if const { E::HYDRAULIC } {
            return None;
        }
        let (lp, refs, solver, obs) = (self.lp, self.refs, self.solver, &mut NoObserver);
        simulate::run_platen_forces::<LANES, E, _, wide_single::Here>(lp, effect, refs, solver, obs)
    }
}

/// Up to [`EFFECT_LANES`] models that switch on library effect `id` alone, with a kernel made
/// for that effect, in the usual configuration ([`simulate::run_usual`]); `None` elsewhere (the
/// caller then runs [`run_effect_lanes`], the same numbers bit for bit).
pub fn run_single_effect(
    id: EffectId,
    models: &[&ModelParams],
    reference: &Reference,
    solver: &Solver,
    obs: &mut dyn Observer<EFFECT_LANES>,
) -> Option<Result<[LaneResult; EFFECT_LANES], SetupError>> {
    let lp = match LaneParams::<EFFECT_LANES>::new(models) {
        Ok(lp) => lp,
        Err(e) => return Some(Err(e)),
    };
    let lanes: [&ModelParams; EFFECT_LANES] =
        std::array::from_fn(|l| models[l.min(models.len() - 1)]);
    let single = Single {
        lp: &lp,
        reference,
        solver,
        obs,
    };
    with_single(id, lanes, single)
}

/// [`run_single_effect`]'s call, generic over the effect.
struct Single<'a, 'o> {
    lp: &'a LaneParams<EFFECT_LANES>,
    reference: &'a Reference,
    solver: &'a Solver,
    obs: &'a mut (dyn Observer<EFFECT_LANES> + 'o),
}

impl EffectFn<EFFECT_LANES> for Single<'_, '_> {
    type Output = Option<Result<[LaneResult; EFFECT_LANES], SetupError>>;
    fn call<E: Effect<EFFECT_LANES>>(self, effect: &E) -> Self::Output {
        let (lp, reference, solver) = (self.lp, self.reference, self.solver);
        simulate::run_usual::<EFFECT_LANES, E, _, single::Here>(
            lp, effect, reference, solver, self.obs,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::Sine;
    use crate::params::ValveLaw;

    /// The wide build of one effect on the platen is made for the usual configuration alone
    /// (orifice valves, α = ½) on a CPU with AVX2: elsewhere it declines, and the caller runs the
    /// general build (a linear valve run through it would be given the orifice law).
    #[test]
    fn the_wide_single_effect_build_declines_the_laws_it_was_not_made_for() {
        let r = Sine {
            freq_hz: 3.0,
            amp_m: Sine::amp_from_g(0.5, 3.0),
            taper_s: 0.1,
            duration_s: 0.3,
            window_cycles: None,
        }
        .reference(1024.0);
        let refs: [&Reference; LANES] = [&r; LANES];
        let avx2 = cfg!(target_arch = "x86_64") && Isa::detected() >= Isa::Avx2;
        for (law, alpha, usual) in [
            (ValveLaw::Orifice, 0.5, true),
            (ValveLaw::Linear, 0.5, false),
            (ValveLaw::Orifice, 0.6, false),
        ] {
            let mut p = ModelParams {
                valve_law: law,
                ..ModelParams::default()
            };
            p.platen.alpha = alpha;
            *p.effects.get_mut(EffectId::Specimen) = true;
            let models = vec![&p; LANES];
            let out =
                run_wide_single_effect(EffectId::Specimen, &models, &refs, &Solver::default());
            assert_eq!(out.is_some(), usual && avx2, "{law:?}, α {alpha}");
        }
    }
}
