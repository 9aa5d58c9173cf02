//! Single-ended actuator with stroke-dependent chamber volumes (docs/model.md §3):
//!
//! ```text
//! V1 = A1 (L + y) + V_d1,   V2 = A2 (L − y) + V_d2
//! dP1/dt = β/V1 · (n_val q_in1 − A1 v),   dP2/dt = β/V2 · (A2 v − n_val q_out2)
//! F = Σ over actuators (P1 A1 − P2 A2)
//! ```
//!
//! Chamber 1 is the cap side, chamber 2 the rod side; positive y is extension.

use super::params::ActuatorParams;

/// Per-lane actuator coefficients.
#[derive(Debug, Clone, Copy)]
pub struct ActuatorLane {
    pub beta: f64,
    pub a1: f64,
    pub a2: f64,
    pub l: f64,
    pub vd1: f64,
    pub vd2: f64,
}

crate::lanes::soa!(ActuatorLane => ActuatorSoa { beta, a1, a2, l, vd1, vd2 });

impl ActuatorLane {
    /// The coefficients of one parameter set's actuators.
    pub fn of(a: &ActuatorParams) -> Self {
        ActuatorLane {
            beta: a.beta,
            a1: a.a1,
            a2: a.a2,
            l: a.l,
            vd1: a.vd1,
            vd2: a.vd2,
        }
    }
}

/// β/V1 and β/V2 at displacement y (shared by all actuators of a lane).
#[inline(always)]
pub fn stiffness_factors(c: &ActuatorLane, y: f64) -> (f64, f64) {
    let v1 = c.a1 * (c.l + y) + c.vd1;
    let v2 = c.a2 * (c.l - y) + c.vd2;
    (c.beta / v1, c.beta / v2)
}

/// (dP1/dt, dP2/dt) from the net flows into chamber 1 and out of chamber 2 (all valves).
#[inline(always)]
pub fn pressure_rates(
    c: &ActuatorLane,
    b1: f64,
    b2: f64,
    q_in1: f64,
    q_out2: f64,
    v: f64,
) -> (f64, f64) {
    (b1 * (q_in1 - c.a1 * v), b2 * (c.a2 * v - q_out2))
}

/// Rate of the force of one actuator, dP1/dt·A1 − dP2/dt·A2, from [`pressure_rates`].
#[inline(always)]
pub fn force_rate(c: &ActuatorLane, dp1: f64, dp2: f64) -> f64 {
    dp1 * c.a1 - dp2 * c.a2
}

/// Force of one actuator, P1 A1 − P2 A2.
#[inline(always)]
pub fn force(c: &ActuatorLane, p1: f64, p2: f64) -> f64 {
    p1 * c.a1 - p2 * c.a2
}
