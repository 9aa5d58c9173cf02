//! The seam for optional physical effects (spool dynamics, leakage, supply dynamics, …).
//!
//! An effect is one type implementing [`Effect`]: it may carry extra per-lane states, and it
//! contributes through hooks that the plant right-hand side calls at fixed places:
//!
//! 1. [`Effect::supply`]: the supply pressure the valves see (supply droop);
//! 2. [`Effect::spool`]: the spool position from the held command x_c (spool dynamics, delay);
//! 3. [`Effect::extra_flows`]: flows added to chamber 1 / taken from chamber 2 (leakage);
//! 4. [`Effect::extra_force`]: a force on the platen (seal friction, reaction-mass compliance);
//! 5. [`Effect::derivs`]: the derivatives of its own states, given a view of the plant.
//!
//! Every hook has a no-op default and is `#[inline(always)]`, so the baseline ([`Baseline`]) costs
//! nothing, and an effect is compiled into the same lane kernel (monomorphised, no dynamic dispatch
//! in the step). Effects keep their parameters as `[f64; N]` per lane.

/// A view of the plant quantities of one right-hand-side evaluation, for [`Effect::derivs`].
pub struct PlantView<'a, const N: usize> {
    /// Held spool command per lane, m.
    pub x_c: &'a [f64; N],
    /// Plant states (see [`crate::kernel::simulate::idx`]).
    pub state: &'a [[f64; N]; super::simulate::NP],
    /// Valve flow into chamber 1 and out of chamber 2 per actuator (all valves), m³/s.
    pub q_in1: &'a [[f64; N]; super::N_ACT],
    pub q_out2: &'a [[f64; N]; super::N_ACT],
    /// Supply pressure seen by the valves, Pa.
    pub p_s: &'a [f64; N],
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

    /// Spool position of actuator `act` in lane `l`, from the held command x_c.
    #[inline(always)]
    fn spool(&self, _l: usize, _act: usize, x_c: f64, _s: &Self::State) -> f64 {
        x_c
    }

    /// Extra flow (into chamber 1, out of chamber 2) of actuator `act`, m³/s.
    #[inline(always)]
    fn extra_flows(&self, _l: usize, _act: usize, _p1: f64, _p2: f64, _p_s: f64, _s: &Self::State) -> (f64, f64) {
        (0.0, 0.0)
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
