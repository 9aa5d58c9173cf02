//! The seam for optional physical effects (spool dynamics, leakage, supply dynamics, …).
//!
//! An effect is one type implementing [`Effect`]: it may carry extra per-lane states, and it
//! contributes through hooks that the plant right-hand side calls at fixed places:
//!
//! 1. [`Effect::supply`]: the supply pressure the valves see (supply droop);
//! 2. [`Effect::spool`]: the valve opening from the held command x_c (spool dynamics, delay,
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
//! The built-in effects, one file each, are combined by [`EffectSet`], which the kernel runs
//! whenever a lane switches any effect on; an effect that is off in a lane is neutral there (zero
//! coefficients or a 0/1 lane mask), so the step still has no branch on configuration.
//!
//! # Writing a new effect
//!
//! A new effect is a type with per-lane parameters that implements [`Effect`]. For example a
//! cubic hardening of the hold-down struts, F = −k3·y³:
//!
//! ```
//! use vshake::kernel::effects::Effect;
//!
//! /// Cubic hold-down stiffness: F = −k3·y³ (N/m³), per lane.
//! struct CubicHoldDown<const N: usize> {
//!     k3: [f64; N],
//! }
//!
//! impl<const N: usize> Effect<N> for CubicHoldDown<N> {
//!     type State = [[f64; N]; 0]; // no states of its own
//!     fn initial_state(&self) -> Self::State {
//!         []
//!     }
//!     #[inline(always)]
//!     fn extra_force(&self, l: usize, y: f64, _v: f64, _s: &Self::State) -> f64 {
//!         -self.k3[l] * y * y * y
//!     }
//! }
//!
//! // Run it like any effect: simulate::run(&lane_params, &CubicHoldDown { k3: [2e9; 1] }, ...).
//! # let _ = CubicHoldDown::<1> { k3: [2e9] };
//! ```
//!
//! To make it switchable from model files, give it a parameter struct in `kernel::params`
//! (the `params!` table gives unit, default, range, source and the registry entry) and add it to
//! [`EffectSet`].

pub mod asymmetry;
pub mod compressibility;
pub mod flow_saturation;
pub mod hold_down;
pub mod leakage;
pub mod reaction_mass;
pub mod seal_friction;
pub mod spool_dynamics;
pub mod supply;
pub mod transport_delay;

use super::params::ModelParams;

/// 1.0 where effect `name` is switched on in `m`, 0.0 where it is off: the factor an effect's
/// coefficients are multiplied by, so an off lane is neutral without a branch in the step.
pub fn switch(m: &ModelParams, name: &str) -> f64 {
    if m.effects.get(name) {
        1.0
    } else {
        0.0
    }
}

/// [`switch`] for every lane.
pub fn lane_mask<const N: usize>(p: &[&ModelParams; N], name: &str) -> [f64; N] {
    std::array::from_fn(|l| switch(p[l], name))
}

/// A view of the plant quantities of one right-hand-side evaluation, for [`Effect::derivs`].
pub struct PlantView<'a, const N: usize> {
    /// Held spool command per lane, m.
    pub x_c: &'a [f64; N],
    /// Spool position per actuator (after [`Effect::spool`]), m.
    pub x: &'a [[f64; N]; super::N_ACT],
    /// Flow drawn from the supply by all valves of a lane (supply → chamber 1 for x > 0,
    /// supply → chamber 2 for x < 0), m³/s.
    pub q_supply: &'a [f64; N],
    /// Plant states (see [`crate::kernel::simulate::idx`]).
    pub state: &'a [[f64; N]; super::simulate::NP],
    /// Valve flow into chamber 1 and out of chamber 2 per actuator (all valves), m³/s.
    pub q_in1: &'a [[f64; N]; super::N_ACT],
    pub q_out2: &'a [[f64; N]; super::N_ACT],
    /// Supply pressure seen by the valves, Pa.
    pub p_s: &'a [f64; N],
    /// Total actuator force on the platen, N.
    pub f_act: &'a [f64; N],
}

/// An optional physical effect plugged into the lane kernel.
pub trait Effect<const N: usize>: Sync {
    /// Extra states per lane, as an array of lanes (`[[f64; N]; 0]` for none).
    type State: Copy + Send + AsRef<[[f64; N]]> + AsMut<[[f64; N]]>;

    /// Extra states at t = 0.
    fn initial_state(&self) -> Self::State;

    /// Supply pressure seen by the valves of lane `l`, from the nominal P_S.
    #[inline(always)]
    fn supply(&self, _l: usize, p_s: f64, _s: &Self::State) -> f64 {
        p_s
    }

    /// Valve opening (effective spool position) of actuator `act` in lane `l`, from the held
    /// command x_c.
    #[inline(always)]
    fn spool(&self, _l: usize, _act: usize, x_c: f64, _s: &Self::State) -> f64 {
        x_c
    }

    /// Spool position as a spool LVDT reads it (before any metering nonlinearity); recorded as
    /// the `spool_m` channel. The same as [`Effect::spool`] unless an effect says otherwise.
    #[inline(always)]
    fn spool_position(&self, l: usize, act: usize, x_c: f64, s: &Self::State) -> f64 {
        self.spool(l, act, x_c, s)
    }

    /// Actuator stroke and stroke rate of lane `l` from the platen's displacement `y` and
    /// velocity `v` (the chamber volumes, the piston flows and the LVDT follow the stroke).
    #[inline(always)]
    fn stroke(&self, _l: usize, y: f64, v: f64, _s: &Self::State) -> (f64, f64) {
        (y, v)
    }

    /// β/V of the cap- and rod-side chambers of actuator `act`, from the baseline's `b` = (β/V1,
    /// β/V2) at chamber pressures `p1`, `p2`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn chamber_stiffness(&self, _l: usize, _act: usize, b: (f64, f64), _p1: f64, _p2: f64, _s: &Self::State) -> (f64, f64) {
        b
    }

    /// The net flows of actuator `act` (into chamber 1, out of chamber 2), m³/s, from the valve
    /// flows `q` (all valves of the actuator).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn flows(&self, _l: usize, _act: usize, q: (f64, f64), _p1: f64, _p2: f64, _p_s: f64, _s: &Self::State) -> (f64, f64) {
        q
    }

    /// Extra force on the platen, N (positive in the direction of extension).
    #[inline(always)]
    fn extra_force(&self, _l: usize, _y: f64, _v: f64, _s: &Self::State) -> f64 {
        0.0
    }

    /// Derivatives of the extra states.
    #[inline(always)]
    fn derivs(&self, _plant: &PlantView<'_, N>, _s: &Self::State, _ds: &mut Self::State) {}
}

/// The baseline model: no extra effect.
#[derive(Debug, Clone, Copy, Default)]
pub struct Baseline;

impl<const N: usize> Effect<N> for Baseline {
    type State = [[f64; N]; 0];
    fn initial_state(&self) -> Self::State {
        []
    }
}

/// Number of states of [`EffectSet`]: spool position and velocity of each actuator (0..4), supply
/// pressure (4), the transport-delay chain (5..9), reaction-mass displacement and velocity (9, 10).
pub const SET_STATES: usize = 2 * super::N_ACT + 1 + transport_delay::STAGES + 2;

/// Every built-in effect, per lane; what is off in a lane is neutral there.
pub struct EffectSet<const N: usize> {
    pub spool: spool_dynamics::SpoolDynamics<N>,
    pub leakage: leakage::Leakage<N>,
    pub supply: supply::Supply<N>,
    pub seal: seal_friction::SealFriction<N>,
    pub saturation: flow_saturation::FlowSaturation<N>,
    pub hold_down: hold_down::HoldDown<N>,
    pub asymmetry: asymmetry::Asymmetry<N>,
    pub delay: transport_delay::TransportDelay<N>,
    pub compressibility: compressibility::Compressibility<N>,
    pub reaction: reaction_mass::ReactionMass<N>,
}

impl<const N: usize> EffectSet<N> {
    /// The effects of up to N lanes (missing lanes repeat the last).
    pub fn new(sets: &[&ModelParams]) -> Self {
        let lanes: [&ModelParams; N] = std::array::from_fn(|l| sets[l.min(sets.len() - 1)]);
        EffectSet {
            spool: spool_dynamics::SpoolDynamics::new(lanes),
            leakage: leakage::Leakage::new(lanes),
            supply: supply::Supply::new(lanes),
            seal: seal_friction::SealFriction::new(lanes),
            saturation: flow_saturation::FlowSaturation::new(lanes),
            hold_down: hold_down::HoldDown::new(lanes),
            asymmetry: asymmetry::Asymmetry::new(lanes),
            delay: transport_delay::TransportDelay::new(lanes),
            compressibility: compressibility::Compressibility::new(lanes),
            reaction: reaction_mass::ReactionMass::new(lanes),
        }
    }
}

impl<const N: usize> Effect<N> for EffectSet<N> {
    type State = [[f64; N]; SET_STATES];

    fn initial_state(&self) -> Self::State {
        let mut s = [[0.0; N]; SET_STATES];
        s[supply::PS] = self.supply.p_s0;
        s
    }
    #[inline(always)]
    fn supply(&self, l: usize, p_s: f64, s: &Self::State) -> f64 {
        self.supply.supply(l, p_s, s)
    }
    #[inline(always)]
    fn spool(&self, l: usize, act: usize, x_c: f64, s: &Self::State) -> f64 {
        // The metering area saturates with the spool position.
        self.saturation.opening(l, self.spool_position(l, act, x_c, s))
    }
    #[inline(always)]
    fn spool_position(&self, l: usize, act: usize, x_c: f64, s: &Self::State) -> f64 {
        // The command is delayed, then the spool follows it (dynamics).
        self.spool.spool(l, act, self.delay.delayed(l, x_c, s), s)
    }
    #[inline(always)]
    fn stroke(&self, l: usize, y: f64, v: f64, s: &Self::State) -> (f64, f64) {
        self.reaction.stroke(l, y, v, s)
    }
    #[inline(always)]
    fn chamber_stiffness(&self, l: usize, _act: usize, b: (f64, f64), p1: f64, p2: f64, _s: &Self::State) -> (f64, f64) {
        self.compressibility.stiffness(l, b, p1, p2)
    }
    #[inline(always)]
    fn flows(&self, l: usize, act: usize, q: (f64, f64), p1: f64, p2: f64, _p_s: f64, _s: &Self::State) -> (f64, f64) {
        // Valve flows scaled by the port asymmetry, then the leakage paths.
        self.leakage.flows(l, self.asymmetry.flows(l, act, q), p1, p2)
    }
    #[inline(always)]
    fn extra_force(&self, l: usize, y: f64, v: f64, _s: &Self::State) -> f64 {
        self.seal.force(l, v) + self.hold_down.force(l, y)
    }
    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        self.delay.derivs(plant, s, ds);
        // The spool dynamics are driven by the delayed command.
        let delayed: [f64; N] = std::array::from_fn(|l| self.delay.delayed(l, plant.x_c[l], s));
        self.spool.derivs(&PlantView { x_c: &delayed, ..*plant }, s, ds);
        self.supply.derivs(plant, s, ds);
        self.reaction.derivs(plant, s, ds);
    }
}
