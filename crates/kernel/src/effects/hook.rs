//! What each hook of [`super::Effect`] is given: one small `Copy` struct per hook, its fields
//! named, so that a hook reads `c.p1` rather than the fifth of eight positional arguments. The
//! effect's own states come beside it (`s: &Self::State`); the quantity a hook changes is a field
//! of its struct (`c.q` for [`Flows`]), so that effects composed in a chain ([`super::Both`])
//! pass the struct on with that one field replaced: `Flows { q: first.flows(c, s0), ..c }`.
//!
//! Units are SI throughout. `lane` is the lane (parameter set) of the batch, `act` the actuator
//! (0 or 1).

/// For [`super::Effect::supply`]: the supply pressure the valves see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Supply {
    pub lane: usize,
    /// The supply pressure as the effects before this one leave it (the nominal P_S first), Pa.
    pub p_s: f64,
}

/// For [`super::Effect::opening`]: the valve opening of one actuator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    pub lane: usize,
    pub act: usize,
    /// The spool command as the effects before this one leave it (the held x_c first), m.
    pub x: f64,
}

/// For [`super::Effect::stroke`] and [`super::Effect::extra_force`]: the platen's motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    pub lane: usize,
    /// Displacement, m: for `stroke`, as the effects before this one leave it (the platen's
    /// first); for `extra_force`, the platen's.
    pub y: f64,
    /// Velocity, m/s (likewise).
    pub v: f64,
}

/// For [`super::Effect::chamber_stiffness`]: β/V of the two chambers of one actuator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chambers {
    pub lane: usize,
    pub act: usize,
    /// β/V of the cap- and rod-side chambers as the effects before this one leave them (the
    /// baseline's first), Pa/m³.
    pub b: (f64, f64),
    /// Cap- and rod-side chamber pressures, Pa.
    pub p1: f64,
    pub p2: f64,
}

/// For [`super::Effect::flows`]: the net flows of one actuator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flows {
    pub lane: usize,
    pub act: usize,
    /// Flows into chamber 1 and out of chamber 2 as the effects before this one leave them (the
    /// valves' first), m³/s.
    pub q: (f64, f64),
    /// Cap- and rod-side chamber pressures, Pa.
    pub p1: f64,
    pub p2: f64,
    /// Supply pressure the valves see, Pa.
    pub p_s: f64,
}

/// For [`super::Effect::sensed`]: the recorded channels ([`super::SENSED`] order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensed {
    pub lane: usize,
    /// Acceleration (m/s²), displacement (m), force (N) as the effects before this one leave them
    /// (the plant's first).
    pub raw: [f64; 3],
}

/// For [`super::Effect::command`]: the controller's valve command at a tick, after the TVC's sum
/// and before its notches (docs/model.md §8: where a compensator enters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    pub lane: usize,
    /// The command as the effects before this one leave it (the TVC's sum first), V.
    pub u: f64,
    /// Cap- and rod-side chamber pressures of each actuator as the controller measures them at
    /// the tick, Pa.
    pub p: [(f64, f64); crate::N_ACT],
    /// The tick's time, s.
    pub t: f64,
    /// The reference states the TVC tracks at the tick: displacement (m), velocity (m/s),
    /// acceleration (m/s²), jerk (m/s³).
    pub r: [f64; 4],
    /// The displacement feedback the TVC reads at the tick (the LVDT's stroke), m.
    pub x: f64,
}
