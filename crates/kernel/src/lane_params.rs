//! The per-lane coefficients of a batch ([`LaneParams`]), derived once from the parameter sets,
//! and why a batch could not be set up.

use super::actuator::{ActuatorLane, ActuatorSoa};
use super::controller::ControllerLane;
use super::friction::{FrictionLane, FrictionSoa};
use super::params::{ModelParams, ValveLaw};
use super::platen::{PlatenLane, PlatenSoa};
use super::servovalve::{ValveLane, ValveSoa};

/// Per-lane coefficients of a batch, derived once from [`ModelParams`].
#[derive(Debug, Clone)]
pub struct LaneParams<const N: usize> {
    pub valve: ValveSoa<N>,
    pub p_s: [f64; N],
    pub act: ActuatorSoa<N>,
    pub platen: PlatenSoa<N>,
    pub friction: FrictionSoa<N>,
    pub ctrl: [ControllerLane; N],
    /// Initial (no-load) pressures.
    pub p0: [(f64, f64); N],
    pub f_s: f64,
    pub valve_law: ValveLaw,
    pub alpha_half: bool,
}

/// Why a batch could not be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SetupError {
    #[error("a batch takes 1 to {max} parameter sets, got {got}")]
    LaneCount { got: usize, max: usize },
    #[error("every lane of a batch must share the controller rate and the valve law (lane {lane} differs)")]
    NotUniform { lane: usize },
    #[error("the reference was made at {reference} Hz but the controller runs at {controller} Hz")]
    RateMismatch { reference: f64, controller: f64 },
    #[error(
        "the lanes' references differ in rate, length, window, fundamental, spectrum or drive"
    )]
    LaneReferences,
    #[error("substeps must be at least 1")]
    Substeps,
    #[error("the open-loop drive has {got} values but the run has {expected} ticks")]
    DriveLength { got: usize, expected: usize },
}

impl<const N: usize> LaneParams<N> {
    /// Coefficients for up to N parameter sets; missing lanes repeat the last set.
    pub fn new(sets: &[&ModelParams]) -> Result<Self, SetupError> {
        if sets.is_empty() || sets.len() > N {
            return Err(SetupError::LaneCount {
                got: sets.len(),
                max: N,
            });
        }
        let p = |l: usize| sets[l.min(sets.len() - 1)];
        for (l, s) in sets.iter().enumerate() {
            if s.controller.f_s != sets[0].controller.f_s || s.valve_law != sets[0].valve_law {
                return Err(SetupError::NotUniform { lane: l });
            }
        }
        let valve: [ValveLane; N] = std::array::from_fn(|l| ValveLane::of(p(l)));
        let act: [ActuatorLane; N] = std::array::from_fn(|l| ActuatorLane::of(&p(l).actuator));
        let platen: [PlatenLane; N] = std::array::from_fn(|l| {
            let m = p(l);
            PlatenLane {
                inv_m: 1.0 / m.platen.m,
                k: m.platen.k,
                c: m.platen.c,
                alpha: m.platen.alpha,
                mu: m.mu(),
            }
        });
        let friction: [FrictionLane; N] = std::array::from_fn(|l| {
            let f = &p(l).friction;
            FrictionLane {
                inv_y: 1.0 / f.y_yield,
                kappa: f.kappa,
                kappa_neg: 2.0 * f.kappa - 1.0,
            }
        });
        Ok(LaneParams {
            valve: ValveSoa::from_lanes(&valve),
            p_s: std::array::from_fn(|l| p(l).servovalve.p_s),
            act: ActuatorSoa::from_lanes(&act),
            platen: PlatenSoa::from_lanes(&platen),
            friction: FrictionSoa::from_lanes(&friction),
            ctrl: std::array::from_fn(|l| {
                let m = p(l);
                ControllerLane::new(&m.controller, m.servovalve.u_lim, m.servovalve.k_sp)
            }),
            p0: std::array::from_fn(|l| p(l).no_load_pressures()),
            f_s: sets[0].controller.f_s,
            valve_law: sets[0].valve_law,
            alpha_half: (0..N).all(|l| p(l).platen.alpha == 0.5),
        })
    }
}
