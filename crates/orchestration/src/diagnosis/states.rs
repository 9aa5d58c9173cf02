//! The plant's states a residual is mapped on (spool opening, velocity, pressure difference,
//! displacement, valve flow) and their values in one compared test.

use vshake_kernel::params::ModelParams;
use vshake_kernel::servovalve::Valves;

/// The plant's states the residual is mapped on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    SpoolOpening,
    Velocity,
    PressureDifference,
    Displacement,
    ValveFlow,
}

impl State {
    pub const ALL: [State; 5] = [
        State::SpoolOpening,
        State::Velocity,
        State::PressureDifference,
        State::Displacement,
        State::ValveFlow,
    ];

    /// Column name in tables.
    pub fn name(self) -> &'static str {
        match self {
            State::SpoolOpening => "spool_opening",
            State::Velocity => "velocity",
            State::PressureDifference => "pressure_difference",
            State::Displacement => "displacement",
            State::ValveFlow => "valve_flow",
        }
    }

    /// In words.
    pub fn label(self) -> &'static str {
        match self {
            State::SpoolOpening => "spool opening",
            State::Velocity => "platen velocity",
            State::PressureDifference => "chamber pressure difference",
            State::Displacement => "platen displacement",
            State::ValveFlow => "valve flow",
        }
    }

    /// Its symbol in a term.
    pub fn symbol(self) -> &'static str {
        match self {
            State::SpoolOpening => "x",
            State::Velocity => "v",
            State::PressureDifference => "Δp",
            State::Displacement => "y",
            State::ValveFlow => "q",
        }
    }

    /// The unit of the scale the map divides it by.
    pub fn scale_unit(self) -> &'static str {
        match self {
            State::SpoolOpening => "full stroke",
            State::Velocity => "m/s",
            State::PressureDifference => "Pa",
            State::Displacement => "m",
            State::ValveFlow => "m³/s",
        }
    }
}

/// The plant's states of one test at its compared samples (physical units; the spool opening as
/// a fraction of the full stroke), in the order of [`State::ALL`].
pub fn test_states(
    model: &ModelParams,
    spool_m: &[f64],
    vel: &[f64],
    p1: &[f64],
    p2: &[f64],
    disp: &[f64],
) -> [Vec<f64>; 5] {
    let stroke = model.servovalve.k_sp * model.servovalve.u_lim;
    let valves = Valves::of(model);
    [
        spool_m.iter().map(|x| x / stroke).collect(),
        vel.to_vec(),
        p1.iter().zip(p2).map(|(a, b)| a - b).collect(),
        disp.to_vec(),
        spool_m
            .iter()
            .zip(p1.iter().zip(p2))
            .map(|(&x, (&a, &b))| valves.flows(x, a, b).0)
            .collect(),
    ]
}
