//! The seam for optional physical effects (spool dynamics, leakage, supply dynamics, …).
//!
//! An effect is one type implementing [`Effect`]: it may carry extra per-lane states, and it
//! contributes through hooks that the plant right-hand side calls at fixed places:
//!
//! 1. [`Effect::supply`]: the supply pressure the valves see (supply droop);
//! 2. [`Effect::opening`]: the valve opening from the held command x_c (spool dynamics, delay,
//!    saturation);
//! 3. [`Effect::flows`]: the valve flows of an actuator, changed (leakage, asymmetry);
//! 4. [`Effect::stroke`]: the actuator stroke from the platen's motion (reaction-mass compliance);
//!    the chamber volumes and the displacement feedback follow it;
//! 5. [`Effect::chamber_stiffness`]: β/V of the chambers (effective bulk modulus, dead volume);
//! 6. [`Effect::extra_force`]: a force on the platen (seal friction, hold-down nonlinearity);
//! 7. [`Effect::derivs`]: the derivatives of its own states, given a view of the plant.
//!
//! Every hook has a no-op default and is `#[inline(always)]`, so the baseline ([`Baseline`]) costs
//! nothing, and an effect is compiled into the same lane kernel (monomorphised, no dynamic dispatch
//! in the step). Effects keep their parameters as `[f64; N]` per lane.
//!
//! Each library effect is one file in this directory: its `Params` table (unit, default, range,
//! source of every parameter), its [`EffectInfo`] (name, family, the parameters a diagnosis frees)
//! and its type, which implements [`Effect`] with its own state type and [`LibraryEffect`]. The
//! registry (`library!` below, one line per effect) composes them by type into [`EffectSet`]
//! (nested [`Both`]), whose state is the effects' states side by side ([`Pair`]): no state index
//! is assigned by hand. The kernel runs the set whenever a lane switches any effect on; an effect
//! that is off in a lane is neutral there (zero coefficients or a 0/1 lane mask), so the lanes of
//! a batch share one step. An effect that no lane of the batch switches on is skipped altogether
//! ([`Gated`]: one branch per hook whose outcome is fixed for the whole run), so a batch pays
//! only for the effects it uses.
//!
//! # Writing a new effect
//!
//! Copy the smallest file here (`hold_down.rs`) to `my_effect.rs`, change its `INFO`, its `Params`
//! table and its hooks, and add the line `my_effect::MyEffect,` to the registry: the name is
//! spelt there alone (the file's `INFO.name` is `module_name(module_path!())`, its parameters'
//! component and model-file table come from the registry line). `study params`, model files
//! (`[model.my_effect]`), `synth --effect`, `fit --effect` and `diagnose` then know it; the
//! registry's test checks it is complete. docs/tutorial/spool_overlap.rs is such a file,
//! whole (CI adds it to the library, fits it and diagnoses with it).
//!
//! The hooks themselves need nothing of the registry: any type implementing [`Effect`] runs in
//! the kernel. For example, a cubic hardening of the hold-down struts, F = −k3·y³, run against
//! the baseline on a 0.1 m, 1 Hz sine (this example is compiled and run by `cargo test`):
//!
//! ```
//! use vshake_kernel::effects::{hook, Effect};
//! use vshake_kernel::excitation::Sine;
//! use vshake_kernel::params::ModelParams;
//! use vshake_kernel::simulate::{self, LaneParams, LaneStatus, NoObserver, Solver};
//!
//! /// F = −k3·y³ on the platen, k3 in N/m³ per lane (0 where the effect is off).
//! struct HoldDown<const N: usize> {
//!     k3: [f64; N],
//! }
//!
//! impl<const N: usize> Effect<N> for HoldDown<N> {
//!     type State = [[f64; N]; 0]; // no states of its own
//!     fn initial_state(&self) -> Self::State {
//!         []
//!     }
//!     #[inline(always)]
//!     fn extra_force(&self, c: hook::Motion, _s: &Self::State) -> f64 {
//!         -self.k3[c.lane] * c.y * c.y * c.y
//!     }
//! }
//!
//! let model = ModelParams::default();
//! let lanes = LaneParams::<1>::new(&[&model]).unwrap();
//! let sine = Sine { freq_hz: 1.0, amp_m: 0.1, taper_s: 1.0, duration_s: 4.0, window_cycles: Some(2) };
//! let run = |k3: f64| {
//!     let effect = HoldDown { k3: [k3] };
//!     let reference = sine.reference(model.controller.f_s);
//!     let [r] = simulate::run(&lanes, &effect, &reference, &Solver::default(), &mut NoObserver)
//!         .unwrap();
//!     assert_eq!(r.status, LaneStatus::Ok);
//!     r.metrics
//! };
//! let (baseline, hardened) = (run(0.0), run(1.0e8));
//! // The odd force (1e5 N at the peak) adds odd harmonics to the acceleration.
//! assert!(hardened.h(3) > baseline.h(3) + 1e-3, "{} {}", hardened.h(3), baseline.h(3));
//! ```
//!
//! An effect with states of its own declares them as `type State = [[f64; N]; K]` and gives
//! their derivatives in [`Effect::derivs`]. A throwaway effect (a test's specimen) needs only
//! [`Effect`]: `simulate::run` takes any.

use super::baseline_params::{
    ActuatorParams, ControllerParams, FrictionParams, PlatenParams, ValveParams,
};
use super::metrics::SpecimenAcc;
use super::param_table::{FieldInfo, Fields};

/// The family of the compensators: effects in the controller (docs/model.md §8), which change
/// the valve command at the ticks ([`Effect::command`]), not the plant.
pub const COMPENSATION: &str = "controller compensation";

/// What the rest of the tool knows about a library effect: its name (the model-file table and
/// the parameter paths `name.param`), its family, its parameters and the ones a diagnosis frees.
/// Each effect's file defines its `INFO`.
#[derive(Debug, Clone, Copy)]
pub struct EffectInfo {
    /// The effect's name: its model-file table, `--effect` name and parameter prefix.
    pub name: &'static str,
    /// The family of physics it belongs to. Effects whose signatures a campaign of sine tests
    /// cannot tell apart (a spool lag and a delay both add a lag ∝ frequency below the spool's
    /// bandwidth) share a family, and a diagnosis is judged by family.
    pub family: &'static str,
    /// One line: what it adds to the model.
    pub summary: &'static str,
    /// Its parameters (unit, default, range, source), from its `params!` table.
    pub params: &'static [FieldInfo],
    /// What a fit or a diagnosis frees, in stages: the first stage is the effect itself (a fit's
    /// default `--free`), each further one a part a diagnosis may add on top once the effect is
    /// chosen (a specimen's second mode). Each frees the parameters its signature determines;
    /// parameters that only shape it (a smoothing velocity, a damping ratio that trades off
    /// against a frequency) stay fixed unless `--free` names them.
    pub stages: &'static [Stage],
}

/// A set of an effect's parameters fitted together ([`EffectInfo::stages`]).
#[derive(Debug, Clone, Copy)]
pub struct Stage {
    /// What the stage adds, in words ("mode 2"); empty for an effect of one stage.
    pub label: &'static str,
    /// The parameters it frees.
    pub free: &'static [&'static str],
    /// A parameter whose start a fit scans over these values, keeping the best, before it
    /// iterates: one that makes the misfit non-convex (a resonance's frequency).
    pub scan: Option<(&'static str, &'static [f64])>,
    /// A parameter the stage's signature grows in proportion to (a mode's mass): at each scanned
    /// value the scan also takes it at the size that fits best, to first order, and starts it
    /// there (a specimen of 12 t scanned at the default 20 t lands in another valley).
    pub size: Option<&'static str>,
    /// A parameter of the signature's shape (a mode's damping, a spool's) the scan also tries at
    /// these values besides its start: above a resonance, mass and frequency trade off and the
    /// damping decides the valley; below a lag's corner, frequency and damping trade off along
    /// a ridge that a start at the wrong damping follows to a bound.
    pub shape: Option<(&'static str, &'static [f64])>,
    /// Values a diagnosis starts this stage's parameters from where the model has them at 0
    /// (a second mode's mass: at 0 the mode is absent and its frequency has no effect to scan).
    pub start: &'static [(&'static str, f64)],
}

impl Stage {
    /// A stage that frees `free`, without a scan.
    pub const fn free(free: &'static [&'static str]) -> Stage {
        Stage {
            label: "",
            free,
            scan: None,
            size: None,
            shape: None,
            start: &[],
        }
    }
}

impl EffectInfo {
    /// The parameters a fit frees by default: the first stage's.
    pub fn free(&self) -> &'static [&'static str] {
        self.stages[0].free
    }
}

/// The name of an effect's module, from its `module_path!()`: the last segment. An effect's
/// [`EffectInfo::name`] is its module's name, spelt once, in its registry line (and so its file).
pub const fn module_name(path: &'static str) -> &'static str {
    let bytes = path.as_bytes();
    let mut start = bytes.len();
    while start > 0 && bytes[start - 1] != b':' {
        start -= 1;
    }
    match std::str::from_utf8(bytes.split_at(start).1) {
        Ok(name) => name,
        Err(_) => panic!("a module path is UTF-8"),
    }
}

/// The recorded channels an effect's [`Effect::sensed`] may change, by index: acceleration,
/// displacement (the LVDT's stroke), total actuator force.
pub const SENSED: [&str; 3] = ["accel", "disp", "force"];

/// An effect of the library: built per batch from the lanes' parameter sets.
pub trait LibraryEffect<const N: usize>: Effect<N> + Sized {
    /// The effect for N lanes; neutral in the lanes that do not switch it on.
    fn new(lanes: [&dyn ModelView; N]) -> Self;
}

/// What an effect reads of a lane's parameter set when it is built ([`LibraryEffect::new`]): the
/// baseline's tables, which effects are on and the effects' tables. `params::ModelParams`, the
/// model's parameter set, is the one that vshake runs; the library sees it through this view so
/// that it stays below the model, whose registry names every effect.
pub trait ModelView {
    fn servovalve(&self) -> &ValveParams;
    fn actuator(&self) -> &ActuatorParams;
    fn platen(&self) -> &PlatenParams;
    fn friction(&self) -> &FrictionParams;
    fn controller(&self) -> &ControllerParams;
    /// Which library effects are on.
    fn switches(&self) -> &EffectSwitches;
    /// The library effects' parameters.
    fn effect_params(&self) -> &EffectParams;
    /// The expressions of the `expression` effect.
    fn expressions(&self) -> &expression::Expressions;
}

/// The registry: one line per effect, `module::Type`, the one place its name is spelt. It declares
/// the module (one file in this directory), lists its `INFO` in [`LIBRARY`], adds its switch to
/// [`EffectSwitches`] and its parameters to [`EffectParams`] (with their accessor `Params::of`
/// and [`EffectParams::table`], from which `params` makes the effect's registry rows, so `study
/// params`, model files, `synth --effect`, `fit --effect` and `diagnose` know it), and composes
/// it into [`EffectSet`].
///
/// **The order is the order of composition** where effects act on the same quantity: the
/// command passes through the effects in list order on its way to the valve opening (a delay,
/// then the spool's dynamics, then the metering nonlinearities), and the valve flows through the
/// flow effects in list order (port asymmetry before leakage).
macro_rules! library {
    ($($module:ident :: $Type:ident),* $(,)?) => {
        $(pub mod $module;)*

        /// Every effect of the library, in registry order.
        pub const LIBRARY: &[&EffectInfo] = &[$(&$module::INFO),*];

        /// Names of the library's effects, in registry order.
        pub const EFFECTS: [&str; [$($module::INFO.name),*].len()] = [$($module::INFO.name),*];

        /// A library effect, by identity: one variant per registry line. A name becomes an
        /// `EffectId` once, where it is read ([`EffectId::parse`]); everything after matches the
        /// enum, so adding an effect is a compile error wherever it must be handled.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum EffectId {
            $($Type,)*
        }

        impl EffectId {
            /// Every library effect, in registry order.
            pub const ALL: [EffectId; [$($module::INFO.name),*].len()] = [$(EffectId::$Type),*];

            /// The effect's [`EffectInfo`] (its file's `INFO`).
            pub fn info(self) -> &'static EffectInfo {
                match self {
                    $(EffectId::$Type => &$module::INFO,)*
                }
            }

            /// The name of the effect's module (its registry line); equal to its `INFO.name`
            /// (the registry's test checks it).
            pub fn module(self) -> &'static str {
                match self {
                    $(EffectId::$Type => stringify!($module),)*
                }
            }

            /// Whether the effect moves the spool a spool LVDT reads ([`Effect::MOVES_SPOOL`]);
            /// such effects are switched off when the plant is driven by a measured spool.
            pub fn moves_spool(self) -> bool {
                match self {
                    $(EffectId::$Type => <$module::$Type<1> as Effect<1>>::MOVES_SPOOL,)*
                }
            }
        }

        $(impl $module::Params {
            /// This effect's parameters in `m`.
            pub fn of(m: &dyn ModelView) -> &Self {
                &m.effect_params().$module
            }
        })*

        /// Which library effects a parameter set switches on (all off by default).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
        pub struct EffectSwitches {
            $(pub $module: bool,)*
        }

        impl EffectSwitches {
            /// The switch of effect `id`.
            pub fn get_mut(&mut self, id: EffectId) -> &mut bool {
                match id {
                    $(EffectId::$Type => &mut self.$module,)*
                }
            }
            /// Whether effect `id` is on.
            pub fn get(&self, id: EffectId) -> bool {
                match id {
                    $(EffectId::$Type => self.$module,)*
                }
            }
            /// Whether any effect is on.
            pub fn any(&self) -> bool {
                false $(|| self.$module)*
            }
            /// The effects that are on, in registry order.
            pub fn on(&self) -> impl Iterator<Item = EffectId> + '_ {
                EffectId::ALL.into_iter().filter(|&e| self.get(e))
            }
        }

        /// The parameters of every library effect (used where the effect is switched on).
        #[derive(Debug, Clone, PartialEq, Default)]
        pub struct EffectParams {
            $(pub $module: $module::Params,)*
        }

        impl EffectParams {
            /// The table of effect `id`.
            pub fn table(&self, id: EffectId) -> &dyn Fields {
                match id {
                    $(EffectId::$Type => &self.$module,)*
                }
            }
            /// The table of effect `id`, to change.
            pub fn table_mut(&mut self, id: EffectId) -> &mut dyn Fields {
                match id {
                    $(EffectId::$Type => &mut self.$module,)*
                }
            }
        }

        $(impl<const N: usize> Named for $module::$Type<N> {
            const ID: EffectId = EffectId::$Type;
        })*

        /// Every library effect composed, per lane; what is off in a lane is neutral there.
        pub type EffectSet<const N: usize> = library!(@nest N; $($module::$Type),*);

        /// Calls `f` with library effect `id` alone, built for `lanes` (see [`EffectFn`]).
        pub fn with_single<const N: usize, M: ModelView, F: EffectFn<N>>(id: EffectId, lanes: [&M; N], f: F) -> F::Output {
            let lanes = lanes.map(|m| m as &dyn ModelView);
            match id {
                $(EffectId::$Type => f.call(&<$module::$Type<N> as LibraryEffect<N>>::new(lanes)),)*
            }
        }
    };
    (@nest $n:ident; ) => { Baseline };
    (@nest $n:ident; $module:ident :: $Type:ident $(, $rm:ident :: $rt:ident)*) => {
        Both<Gated<$module::$Type<$n>>, library!(@nest $n; $($rm::$rt),*)>
    };
}

library! {
    transport_delay::TransportDelay,
    spool_dynamics::SpoolDynamics,
    flow_saturation::FlowSaturation,
    flow_gain::FlowGain,
    asymmetry::Asymmetry,
    leakage::Leakage,
    supply::Supply,
    seal_friction::SealFriction,
    compressibility::Compressibility,
    bulk_curve::BulkCurve,
    reaction_mass::ReactionMass,
    hold_down::HoldDown,
    specimen::Specimen,
    accel_sensor::AccelSensor,
    disp_sensor::DispSensor,
    force_sensor::ForceSensor,
    building::Building,
    expression::Expression,
    valve_compensator::ValveCompensator,
    amplitude_phase::AmplitudePhase,
    harmonic_cancellation::HarmonicCancellation,
    adaptive_inverse::AdaptiveInverse,
}

/// The measurement chain shared by the sensor effects.
mod sensor_chain;

/// The canceller shared by the adaptive compensators.
mod adaptive;

pub mod hook;

impl EffectId {
    /// The effect called `name` (its model-file table, `--effect` name and parameter prefix);
    /// `None` for a name the library does not have. The one place a name becomes an effect.
    pub fn parse(name: &str) -> Option<EffectId> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The effect's name.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Whether a diagnosis tries the effect when it is given no candidates: every effect but the
    /// building, a specimen the user describes storey by storey (a screening's `specimen`, of the
    /// same family, finds its modes; `study fit --effect building` then fits its storeys), and
    /// the expressions, which are a candidate where a model file writes some.
    pub fn screened(self) -> bool {
        !matches!(self, EffectId::Building | EffectId::Expression) && !self.compensates()
    }

    /// Whether the effect is a compensator in the controller ([`COMPENSATION`]), which a lab adds
    /// to improve a test, not physics a diagnosis looks for.
    pub fn compensates(self) -> bool {
        self.info().family == COMPENSATION
    }
}

impl std::fmt::Display for EffectId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The library's effects for up to N lanes (missing lanes repeat the last parameter set).
pub fn effect_set<const N: usize>(sets: &[&impl ModelView]) -> EffectSet<N> {
    EffectSet::<N>::new(std::array::from_fn(|l| {
        sets[l.min(sets.len() - 1)] as &dyn ModelView
    }))
}

/// 1.0 where effect `id` is switched on in `m`, 0.0 where it is off: the factor an effect's
/// coefficients are multiplied by, so an off lane is neutral without a branch in the step.
pub fn switch(m: &dyn ModelView, id: EffectId) -> f64 {
    if m.switches().get(id) {
        1.0
    } else {
        0.0
    }
}

/// [`switch`] of effect `E` for every lane (an effect's constructor calls it with `Self`).
pub(crate) fn lane_mask<const N: usize, E: Named>(p: &[&dyn ModelView; N]) -> [f64; N] {
    std::array::from_fn(|l| switch(p[l], E::ID))
}

/// Per-lane states of an effect: `[[f64; N]; M]`, or a [`Pair`] of such, viewed as a slice of
/// lanes (the integrator's arithmetic runs over that slice).
pub trait LaneStates<const N: usize>:
    OnlyF64 + bytemuck::Pod + Send + Sync + AsRef<[[f64; N]]> + AsMut<[[f64; N]]>
{
}

impl<const N: usize, const M: usize> LaneStates<N> for [[f64; N]; M] {}

impl<const N: usize, A: LaneStates<N>, B: LaneStates<N>> LaneStates<N> for Pair<A, B> {}

/// The states of two effects side by side: the state of a [`Both`].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair<A, B>(pub A, pub B);

/// A type made of `f64`s alone, laid out without padding: `[[f64; N]; M]` and [`Pair`]s of such.
///
/// # Safety
/// An implementor's bytes are exactly a sequence of `f64` (size a multiple of 8, alignment 8, no
/// padding), so that it is [`bytemuck::Pod`] and a [`Pair`] of two of them is too.
pub unsafe trait OnlyF64: Copy + 'static {}

// SAFETY: an array of `[f64; N]` is a sequence of f64.
unsafe impl<const N: usize, const M: usize> OnlyF64 for [[f64; N]; M] {}
// SAFETY: `repr(C)` lays out A then B; each is a sequence of f64 (alignment 8 where not empty,
// size a multiple of 8), so there is no padding between or after them.
unsafe impl<A: OnlyF64, B: OnlyF64> OnlyF64 for Pair<A, B> {}
// SAFETY: all-zero bytes are 0.0s; see `OnlyF64`.
unsafe impl<A: OnlyF64, B: OnlyF64> bytemuck::Zeroable for Pair<A, B> {}
// SAFETY: every bit pattern of a sequence of f64 is valid and there is no padding (`OnlyF64`).
unsafe impl<A: OnlyF64 + bytemuck::Pod, B: OnlyF64 + bytemuck::Pod> bytemuck::Pod for Pair<A, B> {}

impl<const N: usize, A: LaneStates<N>, B: LaneStates<N>> AsRef<[[f64; N]]> for Pair<A, B> {
    #[inline(always)]
    fn as_ref(&self) -> &[[f64; N]] {
        bytemuck::cast_slice(std::slice::from_ref(self))
    }
}

impl<const N: usize, A: LaneStates<N>, B: LaneStates<N>> AsMut<[[f64; N]]> for Pair<A, B> {
    #[inline(always)]
    fn as_mut(&mut self) -> &mut [[f64; N]] {
        bytemuck::cast_slice_mut(std::slice::from_mut(self))
    }
}

/// A view of the plant quantities of one right-hand-side evaluation, for [`Effect::derivs`].
pub struct PlantView<'a, const N: usize> {
    /// Held spool command per lane, m.
    pub x_c: &'a [f64; N],
    /// Valve opening (effective spool position) per actuator, after [`Effect::opening`], m.
    pub opening: &'a [[f64; N]; super::N_ACT],
    /// Flow drawn from the supply by all valves of a lane (supply → chamber 1 for x > 0,
    /// supply → chamber 2 for x < 0), m³/s.
    pub q_supply: &'a [f64; N],
    /// Plant states (see [`crate::state::idx`]).
    pub state: &'a [[f64; N]; super::state::NP],
    /// Valve flow into chamber 1 and out of chamber 2 per actuator (all valves), m³/s.
    pub q_in1: &'a [[f64; N]; super::N_ACT],
    pub q_out2: &'a [[f64; N]; super::N_ACT],
    /// Supply pressure seen by the valves, Pa.
    pub p_s: &'a [f64; N],
    /// Total actuator force on the platen, N.
    pub f_act: &'a [f64; N],
    /// Platen acceleration dv/dt, m/s² (with every effect's force).
    pub accel: &'a [f64; N],
    /// Actuator stroke (what the LVDT reads, after [`Effect::stroke`]), m.
    pub stroke: &'a [f64; N],
}

/// An optional physical effect plugged into the lane kernel.
///
/// Each hook is given one [`hook`] struct (where: the lane, the actuator; what: the quantity it
/// changes and the plant values it may depend on) and the effect's own states `s`.
pub trait Effect<const N: usize>: Sync {
    /// Extra states per lane, as an array of lanes (`[[f64; N]; 0]` for none).
    type State: LaneStates<N>;

    /// Whether [`Effect::opening`] moves the spool itself (a delay, the spool's own dynamics), so
    /// that a spool LVDT reads the opening, rather than changing only the flow an opening passes
    /// (a metering nonlinearity: the spool is where the command puts it). The one declaration of
    /// what an effect moves: the recorded `spool_m` channel follows it, and such effects are
    /// switched off when the plant is driven by a measured spool ([`EffectInfo::moves_spool`]).
    const MOVES_SPOOL: bool = false;

    /// Whether every hook of the plant is its identity and there are no extra states (the
    /// baseline alone): the kernel then takes its vector path for the bare plant.
    const BARE: bool = false;

    /// Whether the effect can tell the two actuators apart, so that [`Effect::symmetric`] may
    /// say `false`. The kernel is built with both actuators only for effects that declare it
    /// (the build of the many effect kernels halves), and refuses to run one whose `symmetric`
    /// says `false` without it.
    const SPLITS: bool = false;

    /// Whether the effect may change the hydraulics: the supply pressure, the opening, the
    /// stroke, the chamber stiffness or the flows (any hook but [`Effect::extra_force`],
    /// [`Effect::derivs`] and the recording's). One that does not (a force on the platen, a
    /// measurement chain) declares `false`, and its batches run the plant in the bare plant's
    /// vector registers (the same bits; the kernel's tests check every hook of such an effect is
    /// its identity).
    const HYDRAULIC: bool = true;

    /// [`Effect::HYDRAULIC`] for this batch: a composition is hydraulic where any effect that
    /// some lane switches on is.
    #[inline(always)]
    fn hydraulic(&self) -> bool {
        Self::HYDRAULIC
    }

    /// Extra states at t = 0.
    fn initial_state(&self) -> Self::State;

    /// How many of the extra states (arrays of lanes, from the start of `State`) move in this
    /// batch: the integrator advances those alone, the others keeping their values at t = 0. All
    /// of them, unless the effect knows that fewer move (a building lower than its most storeys;
    /// an effect no lane switches on).
    #[inline(always)]
    fn live_states(&self) -> usize {
        state_len::<N, Self::State>()
    }

    /// Whether the two actuators stay identical in every lane under this effect (it treats them
    /// alike). Then the kernel integrates one equivalent actuator and doubles its force and its
    /// supply flow: the same numbers, bit for bit, at half the valve and chamber work. An effect
    /// that gives the actuators different laws (`asymmetry.act2_gain ≠ 1`) says `false`, and
    /// declares [`Effect::SPLITS`].
    #[inline(always)]
    fn symmetric(&self) -> bool {
        true
    }

    /// Supply pressure seen by the valves, Pa, from `c.p_s`.
    #[inline(always)]
    fn supply(&self, c: hook::Supply, _s: &Self::State) -> f64 {
        c.p_s
    }

    /// Valve opening (effective spool position) of actuator `c.act`, m, from the command `c.x`.
    #[inline(always)]
    fn opening(&self, c: hook::Opening, _s: &Self::State) -> f64 {
        c.x
    }

    /// Spool position as a spool LVDT reads it, recorded as the `spool_m` channel: the opening
    /// where the effect moves the spool ([`Effect::MOVES_SPOOL`]), the command otherwise. Only
    /// the compositions ([`Both`], [`Gated`]) define it; an effect declares `MOVES_SPOOL`.
    #[inline(always)]
    fn spool_position(&self, c: hook::Opening, s: &Self::State) -> f64 {
        if Self::MOVES_SPOOL {
            self.opening(c, s)
        } else {
            c.x
        }
    }

    /// [`Effect::spool_position`] of actuator `act` in every lane at once, from the commands `x`.
    #[inline(always)]
    fn spool_positions(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        std::array::from_fn(|lane| {
            self.spool_position(
                hook::Opening {
                    lane,
                    act,
                    x: x[lane],
                },
                s,
            )
        })
    }

    /// Actuator stroke and stroke rate (m, m/s) from the platen's motion `c.y`, `c.v` (the
    /// chamber volumes, the piston flows and the LVDT follow the stroke).
    #[inline(always)]
    fn stroke(&self, c: hook::Motion, _s: &Self::State) -> (f64, f64) {
        (c.y, c.v)
    }

    /// β/V of the cap- and rod-side chambers of actuator `c.act`, Pa/m³, from `c.b`.
    #[inline(always)]
    fn chamber_stiffness(&self, c: hook::Chambers, _s: &Self::State) -> (f64, f64) {
        c.b
    }

    /// The net flows of actuator `c.act` (into chamber 1, out of chamber 2), m³/s, from the
    /// valve flows `c.q` (all valves of the actuator).
    #[inline(always)]
    fn flows(&self, c: hook::Flows, _s: &Self::State) -> (f64, f64) {
        c.q
    }

    /// Extra force on the platen, N (positive in the direction of extension), at the platen's
    /// motion `c`.
    #[inline(always)]
    fn extra_force(&self, _c: hook::Motion, _s: &Self::State) -> f64 {
        0.0
    }

    /// [`Effect::extra_force`] of every lane at once, at displacements `y` and velocities `v`
    /// (the bare plant's vector path calls it): lane by lane unless an effect can do better over
    /// the lanes (an interpreted expression), with the same numbers.
    #[inline(always)]
    fn extra_forces(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [f64; N] {
        std::array::from_fn(|lane| {
            self.extra_force(
                hook::Motion {
                    lane,
                    y: y[lane],
                    v: v[lane],
                },
                s,
            )
        })
    }

    /// [`Effect::supply`] of every lane at once, from `p_s`. The general right-hand side calls
    /// this and the array hooks below, one hook of every lane before the next: a composition
    /// ([`Both`], [`Gated`]) then decides once per batch, not once per lane, whether an effect
    /// acts, and each effect's loop over the lanes is its own (vectorised where its law allows).
    /// Lane by lane as the scalar hook, the same numbers.
    #[inline(always)]
    fn supplies(&self, p_s: &[f64; N], s: &Self::State) -> [f64; N] {
        std::array::from_fn(|lane| {
            self.supply(
                hook::Supply {
                    lane,
                    p_s: p_s[lane],
                },
                s,
            )
        })
    }

    /// [`Effect::opening`] of actuator `act` in every lane at once, from the commands `x`.
    #[inline(always)]
    fn openings(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        std::array::from_fn(|lane| {
            self.opening(
                hook::Opening {
                    lane,
                    act,
                    x: x[lane],
                },
                s,
            )
        })
    }

    /// [`Effect::stroke`] of every lane at once, from the platen's `y` and `v`: [stroke, rate].
    #[inline(always)]
    fn strokes(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [[f64; N]; 2] {
        lane_pairs(|lane| {
            let (y, v) = (y[lane], v[lane]);
            self.stroke(hook::Motion { lane, y, v }, s)
        })
    }

    /// [`Effect::chamber_stiffness`] of actuator `act` in every lane at once, from `b`
    /// ([cap side, rod side]) at the chamber pressures `p`.
    #[inline(always)]
    fn stiffnesses(
        &self,
        act: usize,
        b: [[f64; N]; 2],
        p: [&[f64; N]; 2],
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        lane_pairs(|lane| {
            let b = (b[0][lane], b[1][lane]);
            let (p1, p2) = (p[0][lane], p[1][lane]);
            self.chamber_stiffness(
                hook::Chambers {
                    lane,
                    act,
                    b,
                    p1,
                    p2,
                },
                s,
            )
        })
    }

    /// [`Effect::flows`] of actuator `act` in every lane at once, from the valve flows `q`
    /// ([into chamber 1, out of chamber 2]) at the chamber pressures `p` and the supply `p_s`.
    #[inline(always)]
    fn all_flows(
        &self,
        act: usize,
        q: [[f64; N]; 2],
        (p, p_s): ([&[f64; N]; 2], &[f64; N]),
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        lane_pairs(|lane| {
            let q = (q[0][lane], q[1][lane]);
            let (p1, p2, p_s) = (p[0][lane], p[1][lane], p_s[lane]);
            self.flows(
                hook::Flows {
                    lane,
                    act,
                    q,
                    p1,
                    p2,
                    p_s,
                },
                s,
            )
        })
    }

    /// Derivatives of the extra states, written to `ds`. The kernel's `ds` hold zeros before
    /// the first call and what the effect wrote after: an effect whose states stand still in a
    /// batch (one no lane switches on) may leave them.
    #[inline(always)]
    fn derivs(&self, _plant: &PlantView<'_, N>, _s: &Self::State, _ds: &mut Self::State) {}

    /// The channels as recorded ([`SENSED`]: acceleration, displacement, force), from `c.raw`: a
    /// measurement chain changes what is recorded (the histories, the samples compared with a
    /// measurement, the metrics), not the plant (the controller's feedback is the plant's).
    #[inline(always)]
    fn sensed(&self, c: hook::Sensed, _s: &Self::State) -> [f64; 3] {
        c.raw
    }

    /// The valve command at a controller tick (volts), from `c.u`, the TVC's sum as the effects
    /// before this one leave it: a compensator's hook (docs/model.md §8). It runs once per tick,
    /// after the sum and before the notches and the clamp, in closed loop only (an open-loop
    /// drive is the command itself). A compensator that adapts keeps what it learns in its own
    /// states, which it may change here (their derivatives are 0 between ticks).
    #[inline(always)]
    fn command(&self, c: hook::Command, _s: &mut Self::State) -> f64 {
        c.u
    }

    /// What the effect's own states say of lane `lane`, each channel given to `out` by name and
    /// value in SI units (a building's storey drifts, floor accelerations and base shear): what a
    /// specimen experiences, for the time histories. Observers call it; the step does not.
    fn responses(&self, _lane: usize, _s: &Self::State, _out: &mut dyn FnMut(&'static str, f64)) {}

    /// Once per controller tick, over the whole run: what the specimen in the effect's states
    /// experiences, kept in `acc` (peaks, dissipated energy) for the metrics of
    /// [`crate::metrics::Metrics::SPECIMEN`]. Lanes the effect leaves alone stay NaN there.
    #[inline(always)]
    fn watch(&self, _s: &Self::State, _acc: &mut SpecimenAcc<N>) {}
}

/// `f` of every lane, its pairs as two arrays of lanes (the array hooks' default, lane by lane).
#[inline(always)]
fn lane_pairs<const N: usize>(f: impl Fn(usize) -> (f64, f64)) -> [[f64; N]; 2] {
    let mut out = [[0.0; N]; 2];
    for lane in 0..N {
        (out[0][lane], out[1][lane]) = f(lane);
    }
    out
}

/// The number of arrays of lanes in a state type `S` of N lanes.
pub const fn state_len<const N: usize, S>() -> usize {
    std::mem::size_of::<S>() / (8 * N)
}

/// The baseline model: no extra effect.
#[derive(Debug, Clone, Copy, Default)]
pub struct Baseline;

impl<const N: usize> Effect<N> for Baseline {
    type State = [[f64; N]; 0];
    const BARE: bool = true;
    const HYDRAULIC: bool = false;
    fn initial_state(&self) -> Self::State {
        []
    }
}

impl<const N: usize> LibraryEffect<N> for Baseline {
    fn new(_lanes: [&dyn ModelView; N]) -> Self {
        Baseline
    }
}

/// Two effects composed: A acts first where both act on the same quantity (the command, the
/// flows, the supply pressure, the chamber stiffness, the stroke), their forces add, and B's
/// states are driven by the command as A leaves it (a spool lag after a delay follows the
/// delayed command). The state layout follows from the types: `Pair<A::State, B::State>`.
pub struct Both<A, B>(pub A, pub B);

impl<const N: usize, A: LibraryEffect<N>, B: LibraryEffect<N>> LibraryEffect<N> for Both<A, B> {
    fn new(lanes: [&dyn ModelView; N]) -> Self {
        Both(A::new(lanes), B::new(lanes))
    }
}

impl<const N: usize, A: Effect<N>, B: Effect<N>> Effect<N> for Both<A, B> {
    type State = Pair<A::State, B::State>;
    const MOVES_SPOOL: bool = A::MOVES_SPOOL || B::MOVES_SPOOL;
    const SPLITS: bool = A::SPLITS || B::SPLITS;
    const HYDRAULIC: bool = A::HYDRAULIC || B::HYDRAULIC;

    fn initial_state(&self) -> Self::State {
        Pair(self.0.initial_state(), self.1.initial_state())
    }
    #[inline(always)]
    fn hydraulic(&self) -> bool {
        self.0.hydraulic() || self.1.hydraulic()
    }
    /// A's states, then B's that move; A's that move where none of B's does (B's type may hold
    /// states that stand still in this batch: the library's set ends with a building of 40 and
    /// an expression's state, which no effect before them should drag along).
    #[inline(always)]
    fn live_states(&self) -> usize {
        match self.1.live_states() {
            0 => self.0.live_states(),
            b => state_len::<N, A::State>() + b,
        }
    }
    fn symmetric(&self) -> bool {
        self.0.symmetric() && self.1.symmetric()
    }
    #[inline(always)]
    fn supply(&self, c: hook::Supply, s: &Self::State) -> f64 {
        let p_s = self.0.supply(c, &s.0);
        self.1.supply(hook::Supply { p_s, ..c }, &s.1)
    }
    #[inline(always)]
    fn opening(&self, c: hook::Opening, s: &Self::State) -> f64 {
        let x = self.0.opening(c, &s.0);
        self.1.opening(hook::Opening { x, ..c }, &s.1)
    }
    #[inline(always)]
    fn spool_position(&self, c: hook::Opening, s: &Self::State) -> f64 {
        let x = self.0.spool_position(c, &s.0);
        self.1.spool_position(hook::Opening { x, ..c }, &s.1)
    }
    #[inline(always)]
    fn stroke(&self, c: hook::Motion, s: &Self::State) -> (f64, f64) {
        let (y, v) = self.0.stroke(c, &s.0);
        self.1.stroke(hook::Motion { y, v, ..c }, &s.1)
    }
    #[inline(always)]
    fn chamber_stiffness(&self, c: hook::Chambers, s: &Self::State) -> (f64, f64) {
        let b = self.0.chamber_stiffness(c, &s.0);
        self.1.chamber_stiffness(hook::Chambers { b, ..c }, &s.1)
    }
    #[inline(always)]
    fn flows(&self, c: hook::Flows, s: &Self::State) -> (f64, f64) {
        let q = self.0.flows(c, &s.0);
        self.1.flows(hook::Flows { q, ..c }, &s.1)
    }
    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
        self.0.extra_force(c, &s.0) + self.1.extra_force(c, &s.1)
    }
    #[inline(always)]
    fn extra_forces(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [f64; N] {
        let (a, b) = (
            self.0.extra_forces(y, v, &s.0),
            self.1.extra_forces(y, v, &s.1),
        );
        std::array::from_fn(|l| a[l] + b[l])
    }
    #[inline(always)]
    fn supplies(&self, p_s: &[f64; N], s: &Self::State) -> [f64; N] {
        self.1.supplies(&self.0.supplies(p_s, &s.0), &s.1)
    }
    #[inline(always)]
    fn spool_positions(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        self.1
            .spool_positions(act, &self.0.spool_positions(act, x, &s.0), &s.1)
    }
    #[inline(always)]
    fn openings(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        self.1.openings(act, &self.0.openings(act, x, &s.0), &s.1)
    }
    #[inline(always)]
    fn strokes(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [[f64; N]; 2] {
        let [y, v] = self.0.strokes(y, v, &s.0);
        self.1.strokes(&y, &v, &s.1)
    }
    #[inline(always)]
    fn stiffnesses(
        &self,
        act: usize,
        b: [[f64; N]; 2],
        p: [&[f64; N]; 2],
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        let b = self.0.stiffnesses(act, b, p, &s.0);
        self.1.stiffnesses(act, b, p, &s.1)
    }
    #[inline(always)]
    fn all_flows(
        &self,
        act: usize,
        q: [[f64; N]; 2],
        at: ([&[f64; N]; 2], &[f64; N]),
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        let q = self.0.all_flows(act, q, at, &s.0);
        self.1.all_flows(act, q, at, &s.1)
    }
    #[inline(always)]
    fn sensed(&self, c: hook::Sensed, s: &Self::State) -> [f64; 3] {
        let raw = self.0.sensed(c, &s.0);
        self.1.sensed(hook::Sensed { raw, ..c }, &s.1)
    }
    #[inline(always)]
    fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
        let u = self.0.command(c, &mut s.0);
        self.1.command(hook::Command { u, ..c }, &mut s.1)
    }
    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        self.0.responses(lane, &s.0, out);
        self.1.responses(lane, &s.1, out);
    }
    #[inline(always)]
    fn watch(&self, s: &Self::State, acc: &mut SpecimenAcc<N>) {
        self.0.watch(&s.0, acc);
        self.1.watch(&s.1, acc);
    }
    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        self.0.derivs(plant, &s.0, &mut ds.0);
        // B sees the command as A leaves it (actuator 0's: a command effect acts on all alike).
        let x_c = self.0.spool_positions(0, plant.x_c, &s.0);
        self.1.derivs(
            &PlantView {
                x_c: &x_c,
                ..*plant
            },
            &s.1,
            &mut ds.1,
        );
    }
}

/// Code generic over the effect type, to run with the type [`with_single`] picks (a closure
/// cannot be generic).
///
/// [`EffectSet`] runs every library effect's hooks in every lane, with a branch per effect and
/// hook that keeps the compiler from vectorising the lane loop; a kernel made for one effect
/// runs at the baseline's speed plus the effect's own work (a diagnosis screens the library one
/// effect at a time). Both give the same numbers, bit for bit (`tests/effects.rs`).
pub trait EffectFn<const N: usize> {
    type Output;
    fn call<E: Effect<N>>(self, effect: &E) -> Self::Output;
}

/// A library effect's identity, known to its type (the registry implements it).
pub trait Named {
    const ID: EffectId;
}

/// A library effect that is skipped when no lane of the batch switches it on: every hook passes
/// its input through, the extra force is 0 and the extra states stand still. The same numbers as
/// the effect's own neutral lanes (an off lane's mask multiplies its contribution by 0), without
/// evaluating it (a seal friction's tanh and exp, a saturation's tanh, for every lane of every
/// evaluation).
pub struct Gated<E> {
    on: bool,
    effect: E,
}

impl<const N: usize, E: LibraryEffect<N> + Named> LibraryEffect<N> for Gated<E> {
    fn new(lanes: [&dyn ModelView; N]) -> Self {
        Gated {
            on: lanes.iter().any(|p| p.switches().get(E::ID)),
            effect: E::new(lanes),
        }
    }
}

impl<const N: usize, E: Effect<N>> Effect<N> for Gated<E> {
    type State = E::State;
    const MOVES_SPOOL: bool = E::MOVES_SPOOL;
    const SPLITS: bool = E::SPLITS;
    const HYDRAULIC: bool = E::HYDRAULIC;

    fn initial_state(&self) -> Self::State {
        self.effect.initial_state()
    }
    #[inline(always)]
    fn hydraulic(&self) -> bool {
        self.on && self.effect.hydraulic()
    }
    #[inline(always)]
    fn live_states(&self) -> usize {
        if self.on {
            self.effect.live_states()
        } else {
            0
        }
    }
    fn symmetric(&self) -> bool {
        !self.on || self.effect.symmetric()
    }
    #[inline(always)]
    fn supply(&self, c: hook::Supply, s: &Self::State) -> f64 {
        if self.on {
            self.effect.supply(c, s)
        } else {
            c.p_s
        }
    }
    #[inline(always)]
    fn opening(&self, c: hook::Opening, s: &Self::State) -> f64 {
        if self.on {
            self.effect.opening(c, s)
        } else {
            c.x
        }
    }
    #[inline(always)]
    fn spool_position(&self, c: hook::Opening, s: &Self::State) -> f64 {
        if self.on {
            self.effect.spool_position(c, s)
        } else {
            c.x
        }
    }
    #[inline(always)]
    fn stroke(&self, c: hook::Motion, s: &Self::State) -> (f64, f64) {
        if self.on {
            self.effect.stroke(c, s)
        } else {
            (c.y, c.v)
        }
    }
    #[inline(always)]
    fn chamber_stiffness(&self, c: hook::Chambers, s: &Self::State) -> (f64, f64) {
        if self.on {
            self.effect.chamber_stiffness(c, s)
        } else {
            c.b
        }
    }
    #[inline(always)]
    fn flows(&self, c: hook::Flows, s: &Self::State) -> (f64, f64) {
        if self.on {
            self.effect.flows(c, s)
        } else {
            c.q
        }
    }
    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
        if self.on {
            self.effect.extra_force(c, s)
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn extra_forces(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [f64; N] {
        if self.on {
            self.effect.extra_forces(y, v, s)
        } else {
            [0.0; N]
        }
    }
    #[inline(always)]
    fn supplies(&self, p_s: &[f64; N], s: &Self::State) -> [f64; N] {
        if self.on {
            self.effect.supplies(p_s, s)
        } else {
            *p_s
        }
    }
    #[inline(always)]
    fn spool_positions(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        if self.on {
            self.effect.spool_positions(act, x, s)
        } else {
            *x
        }
    }
    #[inline(always)]
    fn openings(&self, act: usize, x: &[f64; N], s: &Self::State) -> [f64; N] {
        if self.on {
            self.effect.openings(act, x, s)
        } else {
            *x
        }
    }
    #[inline(always)]
    fn strokes(&self, y: &[f64; N], v: &[f64; N], s: &Self::State) -> [[f64; N]; 2] {
        if self.on {
            self.effect.strokes(y, v, s)
        } else {
            [*y, *v]
        }
    }
    #[inline(always)]
    fn stiffnesses(
        &self,
        act: usize,
        b: [[f64; N]; 2],
        p: [&[f64; N]; 2],
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        if self.on {
            self.effect.stiffnesses(act, b, p, s)
        } else {
            b
        }
    }
    #[inline(always)]
    fn all_flows(
        &self,
        act: usize,
        q: [[f64; N]; 2],
        at: ([&[f64; N]; 2], &[f64; N]),
        s: &Self::State,
    ) -> [[f64; N]; 2] {
        if self.on {
            self.effect.all_flows(act, q, at, s)
        } else {
            q
        }
    }
    #[inline(always)]
    fn sensed(&self, c: hook::Sensed, s: &Self::State) -> [f64; 3] {
        if self.on {
            self.effect.sensed(c, s)
        } else {
            c.raw
        }
    }
    #[inline(always)]
    fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
        if self.on {
            self.effect.command(c, s)
        } else {
            c.u
        }
    }
    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        if self.on {
            self.effect.responses(lane, s, out);
        }
    }
    #[inline(always)]
    fn watch(&self, s: &Self::State, acc: &mut SpecimenAcc<N>) {
        if self.on {
            self.effect.watch(s, acc);
        }
    }
    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        // Off: its derivatives stay the zeros they start at ([`Effect::derivs`]).
        if self.on {
            self.effect.derivs(plant, s, ds);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter set of defaults, as the library sees one.
    #[derive(Default)]
    pub(crate) struct Defaults {
        pub servovalve: ValveParams,
        pub actuator: ActuatorParams,
        pub platen: PlatenParams,
        pub friction: FrictionParams,
        pub controller: ControllerParams,
        pub effects: EffectSwitches,
        pub effect_params: EffectParams,
        pub expressions: expression::Expressions,
    }

    impl ModelView for Defaults {
        fn servovalve(&self) -> &ValveParams {
            &self.servovalve
        }
        fn actuator(&self) -> &ActuatorParams {
            &self.actuator
        }
        fn platen(&self) -> &PlatenParams {
            &self.platen
        }
        fn friction(&self) -> &FrictionParams {
            &self.friction
        }
        fn controller(&self) -> &ControllerParams {
            &self.controller
        }
        fn switches(&self) -> &EffectSwitches {
            &self.effects
        }
        fn effect_params(&self) -> &EffectParams {
            &self.effect_params
        }
        fn expressions(&self) -> &expression::Expressions {
            &self.expressions
        }
    }

    /// A composition declares itself hydraulic where any of its parts is ([`Effect::HYDRAULIC`]):
    /// the effect set is; a specimen with a hold-down is not; a specimen with a leakage is.
    #[test]
    fn a_composition_is_hydraulic_where_any_part_is() {
        type Spec = specimen::Specimen<1>;
        type Hold = hold_down::HoldDown<1>;
        type Leak = leakage::Leakage<1>;
        let declared = [
            <EffectSet<1> as Effect<1>>::HYDRAULIC,
            <Both<Spec, Hold> as Effect<1>>::HYDRAULIC,
            <Both<Spec, Leak> as Effect<1>>::HYDRAULIC,
            <Both<Leak, Spec> as Effect<1>>::HYDRAULIC,
        ];
        assert_eq!(declared, [true, false, true, true]);
    }

    /// Every registered effect is complete: a family, free parameters that it has, a name that is
    /// its switch, its parameter table and its module (so a misspelt or half-registered effect
    /// fails here, not silently in a diagnosis).
    #[test]
    fn every_registered_effect_is_complete() {
        assert_eq!(LIBRARY.len(), EFFECTS.len());
        assert_eq!(EffectId::ALL.len(), LIBRARY.len());
        let mut sw = EffectSwitches::default();
        for (id, e) in EffectId::ALL.into_iter().zip(LIBRARY) {
            // By name, not by address: two uses of one `const` need not share an address (they
            // did not at opt-level 1 with incremental builds, tried for benches/mutants.sh).
            assert_eq!(id.info().name, e.name, "registry order");
            assert!(!e.family.trim().is_empty(), "{}: no family", e.name);
            assert!(!e.summary.trim().is_empty(), "{}: no summary", e.name);
            // The expressions' free parameters are the ones a model file names.
            assert!(
                !e.free().is_empty() || id == EffectId::Expression,
                "{}: no parameter a diagnosis frees",
                e.name
            );
            assert!(!e.params.is_empty(), "{}: no parameters", e.name);
            for f in e.stages.iter().flat_map(|st| st.free) {
                assert!(
                    e.params.iter().any(|p| p.name == *f),
                    "{}: frees `{f}`, which it does not have",
                    e.name
                );
            }
            assert_eq!(
                id.module(),
                e.name,
                "{}: its module (and so its switch and model-file field) has another name",
                e.name
            );
            assert!(!sw.get(id));
            *sw.get_mut(id) = true;
            assert!(sw.get(id));
            assert_eq!(sw.on().last(), Some(id));
            assert_eq!(EffectId::parse(e.name), Some(id));
        }
        assert!(sw.any());
        assert_eq!(sw.on().count(), LIBRARY.len());
        assert_eq!(
            EffectId::parse("seal_fricton"),
            None,
            "a misspelt name is not an effect"
        );
    }

    /// What an effect moves is declared once (`Effect::MOVES_SPOOL`) and read from there: the
    /// delay and the spool's dynamics move the spool; the metering nonlinearities and the rest
    /// do not, and the set moves it because some of its effects do.
    #[test]
    fn what_moves_the_spool_is_the_effects_declaration() {
        let moving: Vec<&str> = EffectId::ALL
            .into_iter()
            .filter(|e| e.moves_spool())
            .map(|e| e.name())
            .collect();
        assert_eq!(moving, ["transport_delay", "spool_dynamics"]);
        const { assert!(<EffectSet<4> as Effect<4>>::MOVES_SPOOL) };
        const { assert!(!<Baseline as Effect<4>>::MOVES_SPOOL) };
        // Only the asymmetry tells the actuators apart, and the set does because it holds it.
        const { assert!(<EffectSet<4> as Effect<4>>::SPLITS) };
        const { assert!(<asymmetry::Asymmetry<4> as Effect<4>>::SPLITS) };
        const { assert!(!<Baseline as Effect<4>>::SPLITS) };
        const { assert!(!<seal_friction::SealFriction<4> as Effect<4>>::SPLITS) };
        assert_eq!(
            EffectId::FlowGain.name(),
            "flow_gain",
            "INFO.name is the module's"
        );
    }

    /// The composed states are the effects' states side by side: the layout follows the types.
    #[test]
    fn composed_states_are_contiguous() {
        let p = Defaults::default();
        let set = effect_set::<4>(&[&p]);
        let s = set.initial_state();
        let n = s.as_ref().len();
        assert_eq!(std::mem::size_of_val(s.as_ref()), std::mem::size_of_val(&s));
        assert_eq!(
            n,
            transport_delay::STAGES
                + 2 * crate::N_ACT
                + 1
                + 2
                + 2 * specimen::MODES
                + 3 * 4
                + 4 * building::MAX_STOREYS
                + 1
                + 4
                + 4 * harmonic_cancellation::HARMONICS.len()
                + adaptive_inverse::STATES,
            "delay, spool, supply, reaction mass, specimen, three sensor chains, building, \
             the expressions' time, the adaptive compensators' D and E, the inverse's weights \
             and networks"
        );
        // The supply pressure starts at P_S, the inverse at its starting taps (w_0 = 1, in the
        // fit and in use) and its least squares' P at P0·I, every other state at 0.
        let ps = p.servovalve.p_s;
        let mut w = [0.0; adaptive_inverse::TAPS];
        w[0] = 1.0;
        let inverse = adaptive_inverse::initial(&w);
        assert_eq!(inverse.iter().filter(|&&v| v == 1.0).count(), 2);
        assert_eq!(
            inverse
                .iter()
                .filter(|&&v| v == adaptive_inverse::P0)
                .count(),
            adaptive_inverse::TAPS
        );
        let started = inverse.iter().filter(|&&v| v != 0.0).count();
        assert_eq!(
            s.as_ref()
                .iter()
                .filter(|lanes| lanes.iter().all(|&v| v == ps))
                .count(),
            1
        );
        assert_eq!(
            s.as_ref()
                .iter()
                .filter(|lanes| lanes.iter().all(|&v| v == 0.0))
                .count(),
            n - 1 - started
        );
    }

    /// Eight lanes, two for each of four sets of effects: every hook changed by some effect, the
    /// opening, the flows, the chamber stiffness and the supply by two in one lane (each passes
    /// the first's result on; the supply's second is an expression), an effect on in some lanes
    /// of the batch and off in others. The stroke has one library effect.
    fn mixed_lanes() -> (Vec<Defaults>, [f64; 8]) {
        use EffectId::*;
        let on = [
            &[TransportDelay, SpoolDynamics, Leakage][..],
            &[FlowSaturation, FlowGain, Supply, Expression],
            &[
                Asymmetry,
                Compressibility,
                BulkCurve,
                ReactionMass,
                SealFriction,
                Leakage,
            ],
            &[BulkCurve, SpoolDynamics, Specimen, TransportDelay],
        ];
        let lanes = (0..8)
            .map(|l| {
                let mut p = Defaults::default();
                for &id in on.get(l / 2).copied().unwrap_or_default() {
                    *p.effects.get_mut(id) = true;
                }
                // After the library's supply, a drop of 5 %.
                let drop = expression::Hook::Supply;
                p.expressions.set(drop, "0.95 * ps").expect("compiles");
                p
            })
            .collect();
        (lanes, std::array::from_fn(|l| 1.0 + 0.1 * l as f64))
    }

    /// What the hooks are given in the test below, lane by lane from the weights `w`.
    struct HookInputs {
        x: [f64; 8],
        p: [[f64; 8]; 2],
        ps: [f64; 8],
        y: [f64; 8],
        v: [f64; 8],
        b: [[f64; 8]; 2],
        q: [[f64; 8]; 2],
    }

    fn hook_inputs(w: [f64; 8]) -> HookInputs {
        HookInputs {
            x: w.map(|v| 2e-3 * (v - 1.4)),
            p: [w.map(|v| 9e6 * v), w.map(|v| 4e6 * v)],
            ps: w.map(|v| 2e7 * v),
            y: w.map(|v| 0.05 * (v - 1.3)),
            v: w.map(|v| 0.4 * (1.5 - v)),
            b: [w.map(|v| 3e12 * v), w.map(|v| 5e12 * v)],
            q: [w.map(|v| 1e-3 * (v - 1.2)), w.map(|v| 2e-3 * (1.35 - v))],
        }
    }

    /// A hook's name, its array hook's result, its scalar hook's lane by lane, and its input.
    type HookRow = (&'static str, [f64; 8], [f64; 8], [f64; 8]);
    type SetState = <EffectSet<8> as Effect<8>>::State;

    fn per_lane(f: impl Fn(usize) -> f64) -> [f64; 8] {
        std::array::from_fn(f)
    }

    /// The hooks of actuator `act`: the opening, the spool, the flows, the chamber stiffness.
    fn actuator_rows(
        set: &EffectSet<8>,
        es: &SetState,
        act: usize,
        i: &HookInputs,
    ) -> Vec<HookRow> {
        let at = |lane| hook::Opening {
            lane,
            act,
            x: i.x[lane],
        };
        let (p1, p2) = (i.p[0], i.p[1]);
        let flows = |lane: usize| {
            let q = (i.q[0][lane], i.q[1][lane]);
            let p_s = i.ps[lane];
            let c = hook::Flows {
                lane,
                act,
                q,
                p1: p1[lane],
                p2: p2[lane],
                p_s,
            };
            set.flows(c, es)
        };
        let chambers = |lane: usize| {
            let b = (i.b[0][lane], i.b[1][lane]);
            let c = hook::Chambers {
                lane,
                act,
                b,
                p1: p1[lane],
                p2: p2[lane],
            };
            set.chamber_stiffness(c, es)
        };
        let [f1, f2] = set.all_flows(act, i.q, ([&p1, &p2], &i.ps), es);
        let [b1, b2] = set.stiffnesses(act, i.b, [&p1, &p2], es);
        let spool = set.spool_positions(act, &i.x, es);
        vec![
            (
                "openings",
                set.openings(act, &i.x, es),
                per_lane(|l| set.opening(at(l), es)),
                i.x,
            ),
            (
                "spool",
                spool,
                per_lane(|l| set.spool_position(at(l), es)),
                i.x,
            ),
            ("flows in", f1, per_lane(|l| flows(l).0), i.q[0]),
            ("flows out", f2, per_lane(|l| flows(l).1), i.q[1]),
            ("stiffness 1", b1, per_lane(|l| chambers(l).0), i.b[0]),
            ("stiffness 2", b2, per_lane(|l| chambers(l).1), i.b[1]),
        ]
    }

    /// The supply's, the stroke's and the platen force's hooks.
    fn platen_rows(set: &EffectSet<8>, es: &SetState, i: &HookInputs) -> Vec<HookRow> {
        let motion = |lane| hook::Motion {
            lane,
            y: i.y[lane],
            v: i.v[lane],
        };
        let supply = |lane| {
            set.supply(
                hook::Supply {
                    lane,
                    p_s: i.ps[lane],
                },
                es,
            )
        };
        let [ys, vs] = set.strokes(&i.y, &i.v, es);
        let forces = set.extra_forces(&i.y, &i.v, es);
        vec![
            ("supplies", set.supplies(&i.ps, es), per_lane(supply), i.ps),
            (
                "strokes",
                ys,
                per_lane(|l| set.stroke(motion(l), es).0),
                i.y,
            ),
            (
                "stroke rates",
                vs,
                per_lane(|l| set.stroke(motion(l), es).1),
                i.v,
            ),
            (
                "forces",
                forces,
                per_lane(|l| set.extra_force(motion(l), es)),
                [0.0; 8],
            ),
        ]
    }

    /// The array hooks of a composition ([`Effect::supplies`] and the others) give, lane by lane,
    /// the bits of its scalar hooks: the kernel's right-hand side calls the array hooks, a single
    /// lane's callers the scalar ones, and both must compose the effects alike.
    #[test]
    fn a_compositions_array_hooks_are_its_scalar_hooks_lane_by_lane() {
        let (lanes, w) = mixed_lanes();
        let refs: Vec<&Defaults> = lanes.iter().collect();
        let set = effect_set::<8>(&refs);
        let mut es = set.initial_state();
        for (j, row) in es.as_mut().iter_mut().enumerate() {
            for l in 0..8 {
                row[l] += 1e-4 * w[l] * (j as f64 + 1.0);
            }
        }
        let i = hook_inputs(w);
        let mut rows = platen_rows(&set, &es, &i);
        for act in 0..crate::N_ACT {
            rows.extend(actuator_rows(&set, &es, act, &i));
        }
        let bits = |a: &[f64; 8]| a.map(f64::to_bits);
        for (what, array, scalar, _) in &rows {
            assert_eq!(bits(array), bits(scalar), "{what}: {array:?} != {scalar:?}");
        }
        // Every hook changes its input in some lane: the comparisons are not of inputs.
        let changed: Vec<&str> = (rows.iter())
            .filter(|r| bits(&r.1) != bits(&r.3))
            .map(|r| r.0)
            .collect();
        assert_eq!(changed.len(), 16, "{changed:?}");
    }

    /// The set integrates the states up to the last one that moves in the batch: those of the
    /// effects some lane switches on, and of the effects before them; none for the bare plant.
    #[test]
    fn the_set_integrates_the_states_of_what_is_on_and_no_further() {
        let mut p = Defaults::default();
        assert_eq!(effect_set::<4>(&[&p]).live_states(), 0);
        *p.effects.get_mut(EffectId::SpoolDynamics) = true;
        let spool = transport_delay::STAGES + 2 * crate::N_ACT;
        assert_eq!(effect_set::<4>(&[&p]).live_states(), spool);
        *p.effects.get_mut(EffectId::SealFriction) = true;
        assert_eq!(
            effect_set::<4>(&[&p]).live_states(),
            spool,
            "friction has no states"
        );
        *p.effects.get_mut(EffectId::Supply) = true;
        assert_eq!(effect_set::<4>(&[&p]).live_states(), spool + 1);
    }

    /// In a composition, an effect's states follow the command as the effects before it leave
    /// it: spool dynamics after a transport delay lags the delayed command.
    #[test]
    fn a_later_effects_states_follow_the_command_an_earlier_one_leaves() {
        let mut p = Defaults::default();
        *p.effects.get_mut(EffectId::TransportDelay) = true;
        *p.effects.get_mut(EffectId::SpoolDynamics) = true;
        let lanes = [&p as &dyn ModelView];
        let set = effect_set::<1>(&[&p]);
        let mut es = set.initial_state();
        for (j, row) in es.as_mut().iter_mut().enumerate() {
            row[0] = 1e-4 * (j as f64 + 1.0);
        }
        let zeros = (
            [[0.0; 1]; crate::N_ACT],
            [0.0; 1],
            [[0.0; 1]; crate::state::NP],
        );
        let view = |x_c| PlantView {
            x_c,
            opening: &zeros.0,
            q_supply: &zeros.1,
            state: &zeros.2,
            q_in1: &zeros.0,
            q_out2: &zeros.0,
            p_s: &zeros.1,
            f_act: &zeros.1,
            accel: &zeros.1,
            stroke: &zeros.1,
        };
        let x_c = [2e-3];
        let mut ds = es;
        set.derivs(&view(&x_c), &es, &mut ds);
        let stages = transport_delay::STAGES;
        let delay = transport_delay::TransportDelay::<1>::new(lanes);
        let mut delay_s = [[0.0; 1]; transport_delay::STAGES];
        delay_s.copy_from_slice(&es.as_ref()[..stages]);
        let delayed = delay.spool_positions(0, &x_c, &delay_s);
        let spool = spool_dynamics::SpoolDynamics::<1>::new(lanes);
        let mut spool_s = [[0.0; 1]; 2 * crate::N_ACT];
        spool_s.copy_from_slice(&es.as_ref()[stages..stages + 2 * crate::N_ACT]);
        let (mut after, mut undelayed) = (spool_s, spool_s);
        spool.derivs(&view(&delayed), &spool_s, &mut after);
        spool.derivs(&view(&x_c), &spool_s, &mut undelayed);
        assert_eq!(&ds.as_ref()[stages..stages + 2 * crate::N_ACT], &after[..]);
        assert_ne!(after, undelayed, "the delay changes what the spool follows");
    }

    /// The flow gain's coefficients as the CUDA kernel reads them (`FlowGain::lane`, lane.cu's
    /// order): its five knots, neutral (1) in a lane that switches it off, then 1/x_ref.
    #[test]
    fn the_flow_gains_lane_record_is_its_knots_then_the_inverse_stroke() {
        let mut on = Defaults::default();
        *on.effects.get_mut(EffectId::FlowGain) = true;
        let knots = [0.6, 0.8, 1.1, 1.3, 1.25];
        // Rows 0 to 4 of its table are the knots g0 to g4.
        for (k, g) in knots.iter().enumerate() {
            (on.effect_params.table_mut(EffectId::FlowGain)).set_field(k, *g);
        }
        let off = Defaults::default();
        let lanes = [&on as &dyn ModelView, &off];
        let g = flow_gain::FlowGain::<2>::new(lanes);
        let inv = 1.0 / 19.05e-3;
        assert_eq!(g.lane(0), [0.6, 0.8, 1.1, 1.3, 1.25, inv]);
        assert_eq!(g.lane(1), [1.0, 1.0, 1.0, 1.0, 1.0, inv]);
    }

    /// The supply's record for the CUDA kernel: its switch, the nominal supply pressure, the
    /// pump's flow, the inverse accumulator capacity and the inverse pump band, in that order.
    #[test]
    fn the_supplys_lane_record_is_its_switch_pressure_pump_and_inverses() {
        let mut on = Defaults::default();
        *on.effects.get_mut(EffectId::Supply) = true;
        // Rows 0 to 2 of its table: q_pump, c_acc, dp_band.
        for (k, v) in [0.3, 4.0e-8, 2.0e6].into_iter().enumerate() {
            (on.effect_params.table_mut(EffectId::Supply)).set_field(k, v);
        }
        let off = Defaults::default();
        let s = supply::Supply::<2>::new([&on as &dyn ModelView, &off]);
        let p_s = on.servovalve().p_s;
        assert_eq!(s.lane(0), [1.0, p_s, 0.3, 1.0 / 4.0e-8, 1.0 / 2.0e6]);
        assert_eq!(s.lane(1)[0], 0.0, "the switch of a lane without it");
    }
}
