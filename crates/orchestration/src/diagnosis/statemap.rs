//! Where in state space the model fails: the residual mapped onto the plant's states, and a
//! sparse regression of it on a library of candidate terms of those states (in the spirit of
//! SINDy, Brunton, Proctor & Kutz, PNAS 2016: sequentially thresholded least squares).
//!
//! # The states
//! At every compared sample of every test: the spool opening (as a fraction of the full spool
//! stroke k_sp·u_lim), the platen velocity, the chamber pressure difference P1 − P2 of actuator 1,
//! the platen displacement and the valve flow into the cap chamber (the orifice law at the spool
//! opening and chamber pressure). They are the measured channels where the file has them
//! (displacement always; `p1_pa`, `p2_pa`, `spool_m`, else the opening `valve_cmd_v` asks for)
//! and the model's, run as the test was driven, otherwise. Without measured pressures but with
//! the force, the model's pressures are moved by the force residual (split so that
//! A1·δP1 = −A2·δP2), so a load the model lacks does not show as a flow error. [chosen: the
//! model's states stand in for unmeasured ones; where the model is close enough to need a
//! diagnosis, they are close to the plant's.]
//!
//! # The residuals
//! A residual in closed loop is what the controller left of a missing effect, spread over the
//! cycle; a regression of it on the states finds little. Each balance of the plant is therefore
//! evaluated at the measured motion (an equation error, as SINDy regresses derivatives):
//! - r_a = a_measured − a_model and r_F = F_measured − F_model (M·r_a without a force channel);
//! - the *missing platen force* r_F − M·r_a: what the platen's balance M a = F − (platen forces)
//!   lacks at the measured motion (friction, a spring, a specimen); it needs the force channel;
//! - the *missing valve flow* A1·(ṙ_F/K_h + v_measured − v_model) − [q(x_measured, P1) − q(x_model, P1_model)],
//!   K_h = n_act·β·(A1²/V1 + A2²/V2): what the chambers' balance dF/dt = K_h·(q/A1 − v) lacks
//!   (a metering nonlinearity, leakage); the bracket removes what the model's own valve law
//!   explains at the measured opening (`spool_m` or `valve_cmd_v`, else the model's) and
//!   pressure, against its flow at the model's;
//! - the *missing valve opening*: that flow over ∂q/∂x at the sample, as a fraction of the full
//!   stroke; a metering effect is a function of the opening alone there (a dead band δ is a step
//!   of δ/stroke with the opening's sign).
//!
//! For a sine the residuals are first reduced to their mean and harmonics 1 … 9 (the compare's
//! least-squares projection), which removes the sensor noise, and rates are the projection's
//! exact derivative; for a record a rate is a central difference after a 10 ms moving average.
//! [chosen]
//!
//! # The map
//! Each state, scaled to [−1, 1] by its largest magnitude over the campaign (the spool by its full
//! stroke), is cut into [`N_BINS`] equal bins; per bin, the samples, the mean and the rms of each
//! residual over the campaign's rms of the measured quantity (the opening: of the full stroke).
//!
//! # The regression
//! Each balance's residual y is regressed on a library of terms of every state ξ ([`TERMS`]): ξ,
//! ξ|ξ|, ξ³, sign(ξ)√|ξ|, sign(ξ), sign(ξ)·min(|ξ|, 0.05), |ξ|, and a constant. The columns are scaled to
//! unit rms and y to unit rms; least squares (faer, QR), then every term whose coefficient is
//! below [`THRESHOLD`] is dropped and the rest refitted, until the set no longer changes. The
//! states are strongly correlated in closed loop (the spool opening follows the velocity), so the
//! regression is run once per state, on that state's terms alone (the platen's balance on the
//! velocity and displacement, the chambers' on the opening, pressure difference and flow: a force
//! on the platen depends on its motion, a flow on the valve's), and the state whose terms
//! explain the largest share of the residual (R²) is the one the residual follows; of the terms
//! kept, the one that alone explains most is named. A regression on all states together is kept
//! as the sparse model.
//!
//! A load or a valve with dynamics of its own follows no state at the same instant; the platen's
//! balance and the missing opening are also regressed on terms with memory ([`crate::diagnosis::residual_memory`]),
//! named instead when they explain [`MEMORY_MARGIN`] more.

use crate::diagnosis::compare::ComparedTest;
use crate::diagnosis::projector::Projector;
use crate::diagnosis::residual_memory::{self, Input, Kind, MemoryFit};
use crate::diagnosis::states::State;
use faer::prelude::*;
use faer::Mat;
use std::f64::consts::PI;
use vshake_kernel::actuator::{self, ActuatorLane};
use vshake_kernel::effects::expression::Hook;
use vshake_kernel::params::ModelParams;
use vshake_kernel::servovalve::Valves;

/// Bins per state in the map.
pub const N_BINS: usize = 10;

/// A term is dropped when its coefficient (columns and residual at unit rms) is below this.
/// [chosen: a term must carry a tenth of the residual's rms to stay.]
pub const THRESHOLD: f64 = 0.1;

/// A term with memory's parameters in words ([`MemoryFit::describe`]), or "-" where it carries
/// under [`THRESHOLD`] of the residual's rms (R² below its square): its fit then reads noise,
/// and its gain and lag mean nothing (a gain of −4e7 at R² 0.00 on real records).
pub fn memory_text(m: &MemoryFit) -> String {
    match m.r2 >= THRESHOLD * THRESHOLD {
        true => m.describe(),
        false => "-".to_string(),
    }
}

/// A state is named only when its terms explain at least this share of the residual.
/// [chosen: half; below it the residual is noise, or a dynamic effect no static term of one
/// state holds.]
pub const MIN_R2: f64 = 0.5;

/// Width of the near-null term sign(ξ)·min(|ξ|, NULL_WIDTH), in scaled units (for the spool, a
/// fraction of the full stroke). [chosen: 5 %: the small tests put the spool a few per cent open.]
pub const NULL_WIDTH: f64 = 0.05;

/// The library of terms of one scaled state ξ.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Term {
    Linear,
    SignedSquare,
    Cube,
    SignedSqrt,
    Sign,
    NearNull,
    Abs,
}

/// Every term of the library, in the order of the regression's columns.
pub const TERMS: [Term; 7] = [
    Term::Linear,
    Term::SignedSquare,
    Term::Cube,
    Term::SignedSqrt,
    Term::Sign,
    Term::NearNull,
    Term::Abs,
];

impl Term {
    pub(crate) fn eval(self, x: f64) -> f64 {
        match self {
            Term::Linear => x,
            Term::SignedSquare => x * x.abs(),
            Term::Cube => x * x * x,
            Term::SignedSqrt => x.signum() * x.abs().sqrt(),
            // A step smoothed over 1 % of the range, so a sample at exactly 0 is not special.
            Term::Sign => (x / 0.01).tanh(),
            Term::NearNull => x.signum() * x.abs().min(NULL_WIDTH),
            Term::Abs => x.abs(),
        }
    }

    /// The term in the language of expressions (docs/formats.md), of `s` in SI units where the
    /// near-null width is `width` in those units, and its degree (the power of the state's
    /// scale it carries: a written term is the scaled one times scale^degree).
    pub(crate) fn expression(self, s: &str, width: f64) -> (String, f64) {
        match self {
            Term::Linear => (s.to_string(), 1.0),
            Term::SignedSquare => (format!("{s} * abs({s})"), 2.0),
            Term::Cube => (format!("{s}^3"), 3.0),
            Term::SignedSqrt => (format!("sign({s}) * sqrt(abs({s}))"), 0.5),
            Term::Sign => (format!("sign({s})"), 0.0),
            Term::NearNull => (format!("sign({s}) * min(abs({s}), {width:.3e})"), 1.0),
            Term::Abs => (format!("abs({s})"), 1.0),
        }
    }

    /// The term written in the state's symbol.
    pub(crate) fn formula(self, s: &str) -> String {
        match self {
            Term::Linear => s.to_string(),
            Term::SignedSquare => format!("sign({s})·|{s}|²"),
            Term::Cube => format!("{s}³"),
            Term::SignedSqrt => format!("sign({s})·√|{s}|"),
            Term::Sign => format!("sign({s})"),
            Term::NearNull => format!("sign({s})·min(|{s}|, {NULL_WIDTH})"),
            Term::Abs => format!("|{s}|"),
        }
    }
}

/// What a term of a state suggests, physically: the phrase after the colon of a verdict.
pub fn reading(state: State, term: Term) -> &'static str {
    use State::*;
    use Term::*;
    match (state, term) {
        (SpoolOpening, Linear) => "a flow gain off by a constant factor",
        (SpoolOpening, SignedSquare | Cube) => {
            "a flow-gain nonlinearity (a gain that grows with opening)"
        }
        (SpoolOpening, SignedSqrt) => "a flow-gain nonlinearity (a gain that falls with opening)",
        (SpoolOpening, Sign | NearNull) => {
            "a flow change at small spool openings (overlap, dead band or underlap near null)"
        }
        (SpoolOpening, Abs) => "a flow that differs between the two directions of the spool",
        (Velocity, Linear) => "a viscous force",
        (Velocity, Sign | NearNull) => "a friction force that changes sign with the velocity",
        (Velocity, SignedSqrt) => "a dissipative force growing like √|v|",
        (Velocity, SignedSquare | Cube) => "a drag growing faster than the velocity",
        (Velocity, Abs) => "a force that does not reverse with the velocity",
        (PressureDifference, Linear | SignedSqrt) => {
            "a flow or a force proportional to the load pressure (leakage, compliance)"
        }
        (PressureDifference, _) => "a load-pressure nonlinearity",
        (Displacement, Linear) => {
            "a spring or a mass moving with the table (a specimen, the hold-down)"
        }
        (Displacement, SignedSquare | Cube) => "a hardening or softening spring",
        (Displacement, _) => "a force that depends on the table's position",
        (ValveFlow, Linear) => "a flow loss proportional to the flow",
        (ValveFlow, SignedSquare | Cube | Abs) => {
            "a loss growing with the flow (supply droop, line losses)"
        }
        (ValveFlow, _) => "a flow change at small flows",
    }
}

/// The residuals a map and a regression are made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Residual {
    /// a_measured − a_model.
    Accel,
    /// F_measured − F_model (M·r_a where the file has no force).
    Force,
    /// The platen's force balance at the measured motion: r_F − M·r_a (needs the force).
    PlatenForce,
    /// The chambers' flow balance at the measured motion and command.
    ValveFlow,
    /// The missing valve flow as the opening that would pass it (over ∂q/∂x at the sample), as a
    /// fraction of the full stroke: a metering effect is a function of the opening alone there.
    ValveOpening,
}

impl Residual {
    /// The states the residual is regressed on: the platen's balance on the platen's states, the
    /// chambers' on the valve's (a force on the platen depends on its motion, a flow on the
    /// opening and the pressures; the missing opening on the opening and the pressures alone);
    /// the residual force, a mix of both, on all.
    pub fn states(self) -> &'static [State] {
        match self {
            Residual::PlatenForce => &[State::Velocity, State::Displacement],
            Residual::ValveFlow => &[
                State::SpoolOpening,
                State::PressureDifference,
                State::ValveFlow,
            ],
            // The flow read as an opening: the opening's own coordinates (the flow is made of them).
            Residual::ValveOpening => &[State::SpoolOpening, State::PressureDifference],
            Residual::Accel | Residual::Force => &State::ALL,
        }
    }

    pub const ALL: [Residual; 5] = [
        Residual::Accel,
        Residual::Force,
        Residual::PlatenForce,
        Residual::ValveFlow,
        Residual::ValveOpening,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Residual::Accel => "accel",
            Residual::Force => "force",
            Residual::PlatenForce => "platen_force",
            Residual::ValveFlow => "valve_flow",
            Residual::ValveOpening => "valve_opening",
        }
    }
    pub fn label(self) -> &'static str {
        match self {
            Residual::Accel => "residual acceleration",
            Residual::Force => "residual force",
            Residual::PlatenForce => "missing platen force",
            Residual::ValveFlow => "missing valve flow",
            Residual::ValveOpening => "missing valve opening",
        }
    }
}

/// The actuators' force rate dF/dt the model's valves and chambers give at spool position `x`,
/// chamber pressures `p1`, `p2`, velocity `v` and displacement `y` (the kernel's flow law, under
/// the model's `valve_law`, and chamber balance; docs/model.md §3).
fn force_rate(plant: &(Valves, ActuatorLane), x: f64, p1: f64, p2: f64, v: f64, y: f64) -> f64 {
    let (valves, act) = plant;
    let (q1, q2) = valves.flows(x, p1, p2);
    let (b1, b2) = actuator::stiffness_factors(act, y);
    let (dp1, dp2) = actuator::pressure_rates(act, b1, b2, q1, q2, v);
    vshake_kernel::N_ACT as f64 * actuator::force_rate(act, dp1, dp2)
}

/// One test's residuals at its samples, in the order of [`Residual::ALL`] (the platen force is
/// None when the file has no force), and the scale each is divided by in the map: the rms of the
/// measured acceleration; of the force (or M·acceleration), twice; of the valve flow; and 1 for
/// the opening (a fraction of the full stroke).
pub fn test_residuals(c: &ComparedTest) -> ([Option<Vec<f64>>; 5], [f64; 5]) {
    let m = &c.test.measured;
    let s = &c.test.samples;
    let model = &c.test.model;
    let n = s.len();
    let mass = model.platen.m;
    // Noise-free parts (mean and harmonics for a sine) and rates.
    let proj = s
        .fundamental_hz
        .map(|f| (Projector::new(&s.tau, f, s.n_harm), f));
    let smooth = |x: &[f64]| match &proj {
        Some((p, f)) => harmonic_and_rate(p, &s.tau, *f, x),
        None => (x.to_vec(), rate_of(x, s.rate_hz)),
    };
    let ra: Vec<f64> = (0..n).map(|k| m.accel[k] - c.accel_model[k]).collect();
    let (rf, f_meas): (Vec<f64>, Vec<f64>) = match &m.force {
        Some(f) => ((0..n).map(|k| f[k] - c.force_model[k]).collect(), f.clone()),
        None => (
            ra.iter().map(|r| mass * r).collect(),
            m.accel.iter().map(|a| mass * a).collect(),
        ),
    };
    let (ra, _) = smooth(&ra);
    let (rf, rf_rate) = smooth(&rf);
    let platen = m
        .force
        .as_ref()
        .map(|_| (0..n).map(|k| rf[k] - mass * ra[k]).collect::<Vec<f64>>());
    // Flow balance of the chambers: the measured force rate against the rate the valve law and
    // the chambers give at the measured opening, pressures and motion. The model obeys its own
    // law, so the measured rate is dF_model/dt + dr_F/dt and the model's rate cancels; what is
    // left, over the rate one unit of cap flow (with the rod flow matched to the areas) gives, is
    // the flow the plant has and the model lacks.
    let (_, v_meas) = smooth(&m.disp);
    let plant = (Valves::of(model), ActuatorLane::of(&model.actuator));
    let act = &plant.1;
    let n_act = vshake_kernel::N_ACT as f64;
    let stroke = model.servovalve.k_sp * model.servovalve.u_lim;
    let flow: Vec<f64> = (0..n)
        .map(|k| {
            let (y, y_model) = (c.states[3][k], c.disp_model[k]);
            let x = c.states[0][k] * stroke;
            let expected = force_rate(&plant, x, c.p1[k], c.p2[k], v_meas[k], y)
                - force_rate(
                    &plant,
                    c.spool_model[k],
                    c.p1_model[k],
                    c.p2_model[k],
                    c.vel_model[k],
                    y_model,
                );
            // dF/dt per unit of cap flow, the rod flow matched to the areas.
            let (b1, b2) = actuator::stiffness_factors(act, y);
            let per_flow = n_act * (act.a1 * b1 + act.a2 * b2 * act.a2 / act.a1);
            (rf_rate[k] - expected) / per_flow
        })
        .collect();
    let (flow, _) = smooth(&flow);
    let opening: Vec<f64> = (0..n)
        .map(|k| {
            let x = c.states[0][k] * stroke;
            let gain = plant.0.gains(x, c.p1[k], c.p2[k]).0;
            flow[k] / gain.max(1e-12) / stroke
        })
        .collect();
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    // The opening is already a fraction of the full stroke: not rescaled, so its map reads directly
    // as a width (a dead band δ shows as δ/stroke).
    let scales = [
        rms(&m.accel),
        rms(&f_meas),
        rms(&f_meas),
        rms(&c.states[4]),
        1.0,
    ];
    (
        [Some(ra), Some(rf), platen, Some(flow), Some(opening)],
        scales,
    )
}

/// The mean-and-harmonics part of `x` and its time derivative.
fn harmonic_and_rate(p: &Projector, tau: &[f64], f: f64, x: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let h = p.apply(x);
    let c = p.mean(x);
    let w = 2.0 * PI * f;
    let mut val = vec![c; tau.len()];
    let mut rate = vec![0.0; tau.len()];
    for (i, &t) in tau.iter().enumerate() {
        for (k, hk) in h.iter().enumerate().take(p.n_harm()) {
            let kf = (k + 1) as f64;
            let ph = f * t * kf;
            let (sn, cs) = (2.0 * PI * (ph - ph.floor())).sin_cos();
            // x ≈ Re H cos θ − Im H sin θ
            val[i] += hk.0 * cs - hk.1 * sn;
            rate[i] += -kf * w * (hk.0 * sn + hk.1 * cs);
        }
    }
    (val, rate)
}

/// Central-difference rate of `x` sampled at `rate_hz`, after a moving average over 10 ms.
fn rate_of(x: &[f64], rate_hz: f64) -> Vec<f64> {
    let n = x.len();
    let half = ((0.005 * rate_hz).round() as usize).max(1);
    let smooth: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(n));
            x[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            if b > a {
                (smooth[b] - smooth[a]) * rate_hz / (b - a) as f64
            } else {
                0.0
            }
        })
        .collect()
}

/// One bin of the map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapBin {
    pub state: State,
    /// Bin edges, in the state's scaled units (−1 … 1).
    pub lo: f64,
    pub hi: f64,
    /// The scale the state was divided by (the state's unit per scaled unit).
    pub scale: f64,
    pub samples: usize,
    /// Mean and rms of each residual ([`Residual::ALL`]) in the bin, over the campaign's rms of
    /// the measured quantity (the opening as a fraction of the full stroke).
    pub mean: [f64; 5],
    pub rms: [f64; 5],
}

/// One term of a sparse regression.
#[derive(Debug, Clone, PartialEq)]
pub struct TermFit {
    pub state: State,
    pub term: Term,
    /// Coefficient with the term and the residual at unit rms.
    pub coef: f64,
    /// The same, as the residual over its scale ([`StateMap::res_scale`]) per unit of the term of
    /// the scaled state (neither centred nor at unit rms): what a term written in the state's
    /// own units is multiplied by.
    pub slope: f64,
    /// R² of this term alone (with a constant): how much of the residual it explains by itself.
    pub alone: f64,
}

impl TermFit {
    pub fn formula(&self) -> String {
        self.term.formula(self.state.symbol())
    }
}

/// A sparse regression of one residual on the terms of one state (or of all).
#[derive(Debug, Clone, PartialEq)]
pub struct Regression {
    pub residual: Residual,
    /// The state whose terms were offered; None: every state's.
    pub state: Option<State>,
    /// Share of the residual's variance the sparse model explains.
    pub r2: f64,
    /// The terms kept, the one that alone explains most first.
    pub terms: Vec<TermFit>,
}

/// The residual of a campaign mapped onto the plant's states.
#[derive(Debug, Clone, PartialEq)]
pub struct StateMap {
    pub bins: Vec<MapBin>,
    /// Per residual of [`REGRESSED`] the tests have: one regression per state, largest R² first.
    pub per_state: Vec<Vec<Regression>>,
    /// Per residual: the regression on every state's terms together.
    pub joint: Vec<Regression>,
    /// Residuals regressed on a term with memory ([`crate::diagnosis::residual_memory`]): the platen's force balance
    /// (the residual force when the files have no force) on the force of an oscillator carried by
    /// the platen, the missing opening on a lag of the opening.
    pub memory: Vec<(Residual, MemoryFit)>,
    /// The lowest and highest fundamental of the sine tests, Hz (None: no sine).
    pub band: Option<(f64, f64)>,
    pub samples: usize,
    /// Each residual's scale ([`Residual::ALL`] order; the opening's is 1, a fraction of the
    /// full stroke) and each state's ([`State::ALL`] order; the opening's is 1 likewise).
    pub res_scale: [f64; 5],
    pub state_scale: [f64; 5],
    /// The spool's full stroke k_sp·u_lim, m.
    pub stroke_m: f64,
}

/// What the map names: a static term of one state, or a term with memory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Named<'a> {
    Static(&'a Regression, &'a TermFit),
    Memory(Residual, &'a MemoryFit),
}

/// A term with memory is named over the static terms only when it explains this much more of the
/// residual. [chosen: a spring or a damper to the ground is also an oscillator tuned below the
/// tests; the static reading, simpler, keeps it unless the memory clearly adds.]
pub const MEMORY_MARGIN: f64 = 0.05;

/// The residuals that are regressed on the states: the platen's force balance and the chambers'
/// flow balance; the residual force itself when the files have no force.
pub const REGRESSED: [Residual; 4] = [
    Residual::Force,
    Residual::PlatenForce,
    Residual::ValveFlow,
    Residual::ValveOpening,
];

/// The map and regressions of the compared tests.
pub fn map(compared: &[ComparedTest]) -> StateMap {
    let Pooled {
        mut states,
        res,
        res_scale,
    } = pool(compared);
    let n = states[0].len();
    let memory = memory_fits(compared, &res, &res_scale);
    let fundamentals = compared
        .iter()
        .filter_map(|c| c.test.samples.fundamental_hz);
    let band = fundamentals
        .clone()
        .reduce(f64::min)
        .zip(fundamentals.reduce(f64::max));
    let scales = scale_states(&mut states);
    let bins = State::ALL
        .iter()
        .enumerate()
        .flat_map(|(i, &st)| bins_of(st, scales[i], &states[i], &res))
        .collect();
    let (per_state, joint) = regressions(&states, &res);
    let valve = &compared[0].test.model.servovalve;
    StateMap {
        bins,
        per_state,
        joint,
        memory,
        band,
        samples: n,
        res_scale,
        state_scale: scales,
        stroke_m: valve.k_sp * valve.u_lim,
    }
}

/// The samples of every test, pooled.
struct Pooled {
    /// The plant's states.
    states: [Vec<f64>; 5],
    /// The residuals over their scales, in the order of [`Residual::ALL`] (one some test lacks
    /// is None).
    res: [Option<Vec<f64>>; 5],
    /// Each residual's scale: the tests' ([`test_residuals`]) pooled as an rms over the samples
    /// (1 where 0).
    res_scale: [f64; 5],
}

/// The tests' samples pooled, the residuals scaled.
fn pool(compared: &[ComparedTest]) -> Pooled {
    let mut states: [Vec<f64>; 5] = Default::default();
    let mut res: [Option<Vec<f64>>; 5] = std::array::from_fn(|_| Some(Vec::new()));
    let mut scale_sq = [0.0f64; 5];
    for c in compared {
        let (r, s) = test_residuals(c);
        let n = c.test.samples.len() as f64;
        for (i, r) in r.into_iter().enumerate() {
            match (&mut res[i], r) {
                (Some(all), Some(r)) => all.extend_from_slice(&r),
                (x, _) => *x = None,
            }
            scale_sq[i] += s[i] * s[i] * n;
        }
        for (all, st) in states.iter_mut().zip(&c.states) {
            all.extend_from_slice(st);
        }
    }
    let n = states[0].len();
    let mut res_scale = [1.0; 5];
    for ((r, sq), out) in res.iter_mut().zip(scale_sq).zip(&mut res_scale) {
        let sc = (sq / n.max(1) as f64).sqrt();
        *out = if sc > 0.0 { sc } else { 1.0 };
        if let Some(r) = r {
            r.iter_mut().for_each(|r| *r /= *out);
        }
    }
    Pooled {
        states,
        res,
        res_scale,
    }
}

/// The residuals on a term with memory, in their own units: the platen's balance (the residual
/// force where the files have no force) on a carried oscillator, the missing opening on a lag.
fn memory_fits(
    compared: &[ComparedTest],
    res: &[Option<Vec<f64>>; 5],
    res_scale: &[f64; 5],
) -> Vec<(Residual, MemoryFit)> {
    let at = |r: Residual| Residual::ALL.iter().position(|&x| x == r).unwrap_or(0);
    let platen = if res[at(Residual::PlatenForce)].is_some() {
        Residual::PlatenForce
    } else {
        Residual::Force
    };
    let mut memory = Vec::new();
    for (kind, r) in [(Kind::Carried, platen), (Kind::Lag, Residual::ValveOpening)] {
        let Some(y) = &res[at(r)] else { continue };
        let y: Vec<f64> = y.iter().map(|v| v * res_scale[at(r)]).collect();
        if let Some(mut fit) = residual_memory::fit(
            kind,
            &compared
                .iter()
                .map(|c| input_of(kind, c))
                .collect::<Vec<_>>(),
            &y,
        ) {
            // The residual force in closed loop is what the controller left: no mass can be read.
            if r == Residual::Force {
                fit.gain = f64::NAN;
            }
            memory.push((r, fit));
        }
    }
    memory
}

/// Scales each state (the spool opening aside) to its largest magnitude: the scales.
fn scale_states(states: &mut [Vec<f64>; 5]) -> [f64; 5] {
    let mut scales = [1.0; 5];
    for (i, st) in State::ALL.iter().enumerate() {
        if *st != State::SpoolOpening {
            let m = states[i].iter().fold(0.0f64, |m, x| m.max(x.abs()));
            scales[i] = if m > 0.0 { m } else { 1.0 };
        }
        let s = scales[i];
        states[i].iter_mut().for_each(|x| *x /= s);
    }
    scales
}

/// Each [`REGRESSED`] residual the tests have on the terms of each of its states (largest R²
/// first) and on all of them together.
fn regressions(
    states: &[Vec<f64>; 5],
    res: &[Option<Vec<f64>>; 5],
) -> (Vec<Vec<Regression>>, Vec<Regression>) {
    let mut per_state = Vec::new();
    let mut joint = Vec::new();
    for r in REGRESSED {
        let Some(y) = &res[Residual::ALL.iter().position(|&x| x == r).unwrap_or(0)] else {
            continue;
        };
        let idx = |st: State| State::ALL.iter().position(|&x| x == st).unwrap_or(0);
        let mut v: Vec<Regression> = r
            .states()
            .iter()
            .map(|&st| stlsq(r, Some(st), &[(st, &states[idx(st)])], y))
            .collect();
        v.sort_by(|a, b| b.r2.total_cmp(&a.r2));
        per_state.push(v);
        let all: Vec<(State, &Vec<f64>)> = r
            .states()
            .iter()
            .map(|&st| (st, &states[idx(st)]))
            .collect();
        joint.push(stlsq(r, None, &all, y));
    }
    (per_state, joint)
}

/// A test's input to a term with memory of family `kind` ([`residual_memory::fit`]): the measured
/// displacement (for a record its second rate after the 10 ms average: the base acceleration)
/// or the spool opening.
fn input_of(kind: Kind, c: &ComparedTest) -> Input {
    let s = &c.test.samples;
    let x = match kind {
        Kind::Carried => &c.test.measured.disp,
        Kind::Lag => &c.states[0],
    };
    match (s.fundamental_hz, kind) {
        (Some(f), _) => Input::sine(&Projector::new(&s.tau, f, s.n_harm), f, x),
        (None, Kind::Carried) => Input::Record {
            x: rate_of(&rate_of(x, s.rate_hz), s.rate_hz),
            dt: 1.0 / s.rate_hz,
        },
        (None, Kind::Lag) => Input::Record {
            x: x.clone(),
            dt: 1.0 / s.rate_hz,
        },
    }
}

fn bins_of(state: State, scale: f64, x: &[f64], res: &[Option<Vec<f64>>; 5]) -> Vec<MapBin> {
    let w = 2.0 / N_BINS as f64;
    (0..N_BINS)
        .map(|b| {
            let (lo, hi) = (-1.0 + b as f64 * w, -1.0 + (b + 1) as f64 * w);
            let last = b + 1 == N_BINS;
            let ks: Vec<usize> = (0..x.len())
                .filter(|&k| x[k] >= lo && (x[k] < hi || (last && x[k] <= hi)))
                .collect();
            let stat = |r: &Option<Vec<f64>>| match r {
                Some(r) if !ks.is_empty() => {
                    let m = ks.iter().map(|&k| r[k]).sum::<f64>() / ks.len() as f64;
                    let q = (ks.iter().map(|&k| r[k] * r[k]).sum::<f64>() / ks.len() as f64).sqrt();
                    (m, q)
                }
                _ => (f64::NAN, f64::NAN),
            };
            let s: Vec<(f64, f64)> = res.iter().map(stat).collect();
            MapBin {
                state,
                lo,
                hi,
                scale,
                samples: ks.len(),
                mean: std::array::from_fn(|i| s[i].0),
                rms: std::array::from_fn(|i| s[i].1),
            }
        })
        .collect()
}

/// Least squares of `y` on the columns `cols` (a constant is always in the model), by QR:
/// (coefficients, residual sum of squares).
fn lstsq(cols: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, f64) {
    let (n, p) = (y.len(), cols.len() + 1);
    let a = Mat::<f64>::from_fn(n, p, |i, j| if j == 0 { 1.0 } else { cols[j - 1][i] });
    let b = Mat::<f64>::from_fn(n, 1, |i, _| y[i]);
    let x = a.qr().solve_lstsq(&b);
    let coef: Vec<f64> = (0..p).map(|j| x[(j, 0)]).collect();
    let rss = (0..n)
        .map(|i| {
            let fit = coef[0] + (1..p).map(|j| coef[j] * cols[j - 1][i]).sum::<f64>();
            (y[i] - fit).powi(2)
        })
        .sum();
    (coef[1..].to_vec(), rss)
}

/// The regression's columns: each term of each state, centred and at unit rms, constant ones
/// left out; with each column's (state, term) and its standard deviation before scaling.
#[allow(clippy::type_complexity)]
fn term_columns(
    states: &[(State, &Vec<f64>)],
    n: usize,
) -> (Vec<(State, Term)>, Vec<Vec<f64>>, Vec<f64>) {
    let (mut labels, mut cols, mut sds) = (Vec::new(), Vec::new(), Vec::new());
    for &(st, x) in states {
        for term in TERMS {
            let c: Vec<f64> = x.iter().map(|&v| term.eval(v)).collect();
            let m = c.iter().sum::<f64>() / n as f64;
            let sd = (c.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt();
            if sd > 1e-9 {
                cols.push(c.iter().map(|v| (v - m) / sd).collect::<Vec<f64>>());
                labels.push((st, term));
                sds.push(sd);
            }
        }
    }
    (labels, cols, sds)
}

/// Sequentially thresholded least squares of `y` on the terms of `states`.
fn stlsq(
    residual: Residual,
    state: Option<State>,
    states: &[(State, &Vec<f64>)],
    y: &[f64],
) -> Regression {
    let n = y.len();
    let empty = Regression {
        residual,
        state,
        r2: 0.0,
        terms: Vec::new(),
    };
    if n < 2 * TERMS.len() * states.len() + 2 {
        return empty;
    }
    let ym = y.iter().sum::<f64>() / n as f64;
    let tss: f64 = y.iter().map(|v| (v - ym).powi(2)).sum();
    if tss <= 0.0 {
        return empty;
    }
    let ys = (tss / n as f64).sqrt();
    let y: Vec<f64> = y.iter().map(|v| (v - ym) / ys).collect();
    let (labels, cols, sds) = term_columns(states, n);
    let tss = n as f64;
    let mut active: Vec<usize> = (0..cols.len()).collect();
    let mut coef = Vec::new();
    let mut rss = tss;
    for _ in 0..20 {
        let sel: Vec<Vec<f64>> = active.iter().map(|&j| cols[j].clone()).collect();
        (coef, rss) = lstsq(&sel, &y);
        let keep: Vec<usize> = active
            .iter()
            .zip(&coef)
            .filter(|(_, c)| c.abs() >= THRESHOLD)
            .map(|(&j, _)| j)
            .collect();
        if keep.len() == active.len() || keep.is_empty() {
            if keep.is_empty() {
                active.clear();
                coef.clear();
                rss = tss;
            }
            break;
        }
        active = keep;
    }
    let r2 = (1.0 - rss / tss).max(0.0);
    let mut terms: Vec<TermFit> = active
        .iter()
        .enumerate()
        .map(|(i, &j)| TermFit {
            state: labels[j].0,
            term: labels[j].1,
            coef: coef[i],
            slope: coef[i] * ys / sds[j],
            alone: (1.0 - lstsq(std::slice::from_ref(&cols[j]), &y).1 / tss).max(0.0),
        })
        .collect();
    terms.sort_by(|a, b| b.alone.total_cmp(&a.alone));
    Regression {
        residual,
        state,
        r2,
        terms,
    }
}

impl StateMap {
    /// The regressions of residual `r`, one per state, largest R² first (empty when the tests
    /// lack what it needs).
    pub fn by_state(&self, r: Residual) -> &[Regression] {
        self.per_state
            .iter()
            .find(|v| v.first().is_some_and(|g| g.residual == r))
            .map_or(&[], |v| v.as_slice())
    }

    /// The state and term the residual follows most: over the platen's force balance (the
    /// residual force when the files have no force) and the chambers' flow balance, the
    /// per-state regression of largest R², and its term that alone explains most.
    pub fn strongest(&self) -> Option<(&Regression, &TermFit)> {
        let force = if self.by_state(Residual::PlatenForce).is_empty() {
            Residual::Force
        } else {
            Residual::PlatenForce
        };
        [force, Residual::ValveFlow, Residual::ValveOpening]
            .iter()
            .filter_map(|&r| self.by_state(r).first())
            .max_by(|a, b| a.r2.total_cmp(&b.r2))
            .and_then(|reg| reg.terms.first().map(|t| (reg, t)))
    }

    /// What the residual follows, if anything explains at least [`MIN_R2`] of it: the strongest
    /// static term, or the strongest term with memory when it explains [`MEMORY_MARGIN`] more.
    pub fn named(&self) -> Option<Named<'_>> {
        let fixed = self.strongest().filter(|(reg, _)| reg.state.is_some());
        let fixed_r2 = fixed.map_or(0.0, |(reg, _)| reg.r2);
        match self.memory.iter().max_by(|a, b| a.1.r2.total_cmp(&b.1.r2)) {
            Some((r, o)) if o.r2 >= MIN_R2 && o.r2 >= fixed_r2 + MEMORY_MARGIN => {
                Some(Named::Memory(*r, o))
            }
            _ => fixed
                .filter(|(reg, _)| reg.r2 >= MIN_R2)
                .map(|(reg, t)| Named::Static(reg, t)),
        }
    }

    /// The static term the residual follows written as an expression effect
    /// (`[model.expression]`, docs/formats.md), where its residual is one a hook adds: the
    /// missing opening (the `opening` hook, in the spool's `x`) or the missing platen force
    /// (`force`, in `v` or `y`). Its coefficient, named `c_<hook>`, starts at the regression's
    /// value in SI units, so that `study fit --effect expression` starts near it.
    pub fn expression(&self) -> Option<String> {
        self.term().map(|t| t.toml())
    }

    /// [`StateMap::expression`]'s term: its hook, form and coefficient.
    pub fn term(&self) -> Option<MapTerm> {
        let Some(Named::Static(reg, t)) = self.named() else {
            return None;
        };
        let st = reg.state?;
        let at = |r: Residual| Residual::ALL.iter().position(|&x| x == r).unwrap_or(0);
        let si = State::ALL.iter().position(|&x| x == st).unwrap_or(0);
        // The residual in SI units per unit of the term in the state's SI units: the opening's
        // residual and state are fractions of the stroke; the platen's balance is the force
        // the model lacks with the sign reversed (r_F − M·r_a = −F).
        let (hook, unit, sign, to_si, scale) = match (reg.residual, st) {
            (Residual::ValveOpening, State::SpoolOpening) => {
                (Hook::Opening, "m", 1.0, self.stroke_m, self.stroke_m)
            }
            (Residual::PlatenForce, State::Velocity | State::Displacement) => (
                Hook::Force,
                "N",
                -1.0,
                self.res_scale[at(Residual::PlatenForce)],
                self.state_scale[si],
            ),
            _ => return None,
        };
        let (written, degree) = t.term.expression(st.symbol(), NULL_WIDTH * scale);
        let param = format!("c_{}", hook.key());
        let form = match (hook, t.term) {
            // A step with the opening's sign: lands that overlap (c < 0, no flow while
            // |x| ≤ −c) or underlap (c > 0); the same as x + c·sign(x) outside the band.
            (Hook::Opening, Term::Sign) => format!("sign(x) * max(abs(x) + {param}, 0)"),
            (Hook::Opening, _) => format!("x + {param} * {written}"),
            _ => format!("{param} * {written}"),
        };
        let of = if st == State::Velocity { "m/s" } else { "m" };
        let unit = match (degree, of) {
            (0.0, _) => unit.to_string(),
            (1.0, _) => format!("{unit}/{of}"),
            (2.0, "m") => format!("{unit}/m²"),
            (3.0, "m") => format!("{unit}/m³"),
            (d, _) => format!("{unit}/({of})^{d}"),
        };
        Some(MapTerm {
            hook,
            form,
            param,
            unit,
            value: sign * t.slope * to_si / scale.powf(degree),
        })
    }

    /// One sentence: which state and term the residual follows, and what that suggests.
    pub fn sentence(&self) -> Option<String> {
        Some(match self.named()? {
            Named::Static(reg, t) => {
                let st = reg.state?;
                format!(
                    "the {} follows {} in {} (R² = {:.2}): {}",
                    reg.residual.label(),
                    t.formula(),
                    st.label(),
                    reg.r2,
                    reading(st, t.term)
                )
            }
            Named::Memory(r, o) => format!(
                "the {} follows the {} through a term with memory, {} ({}; R² = {:.2}): {}",
                r.label(),
                o.kind.state().label(),
                o.kind.name(),
                o.describe(),
                o.r2,
                o.reading(self.band)
            ),
        })
    }
}

/// The state map's static term as an expression effect ([`StateMap::term`]): `hook = form`,
/// whose one parameter `param` (of `unit`) starts at `value`; at 0 it changes nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct MapTerm {
    pub hook: Hook,
    pub form: String,
    pub param: String,
    pub unit: String,
    pub value: f64,
}

impl MapTerm {
    /// The `[model.expression]` block that writes it, switched off.
    pub fn toml(&self) -> String {
        format!(
            "[model.expression]\nenabled = false   # a candidate: `fit --effect expression` or a diagnosis switches it on\n{} = \"{}\"\n{} = {{ value = {:.4e}, unit = \"{}\" }}",
            self.hook.key(),
            self.form,
            self.param,
            self.value,
            self.unit
        )
    }

    /// `model` given the term as its expression, its parameter at the map's value (the effect
    /// left as it was: a candidate's fit switches it on).
    pub fn install(&self, model: &mut ModelParams) -> Result<(), String> {
        let any = vshake_kernel::param_table::Range::any();
        model.name_expression_param(&self.param, &self.unit, any, self.value)?;
        (model.expression.set(self.hook, &self.form)).map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual made of one term of one state, among correlated states, is attributed to that
    /// state and term.
    /// The state map's force rate is the kernel's right-hand side at the same state, under
    /// either valve law, at random states across the stroke and the pressure range.
    #[test]
    fn the_force_rate_is_the_kernels_at_random_states() {
        use rand::{RngExt, SeedableRng};
        use vshake_kernel::params::{ModelParams, ValveLaw};
        use vshake_kernel::simulate::plant_derivatives;
        use vshake_kernel::state::{idx, NP};
        let mut rng = rand::rngs::StdRng::seed_from_u64(31);
        for law in [ValveLaw::Orifice, ValveLaw::Linear] {
            let model = ModelParams {
                valve_law: law,
                ..Default::default()
            };
            let plant = (Valves::of(&model), ActuatorLane::of(&model.actuator));
            let (sv, l) = (&model.servovalve, model.actuator.l);
            for _ in 0..200 {
                let x = (rng.random::<f64>() * 2.0 - 1.0) * sv.k_sp * sv.u_lim;
                let p = |r: &mut rand::rngs::StdRng| sv.p_r + r.random::<f64>() * (sv.p_s - sv.p_r);
                let (p1, p2) = (p(&mut rng), p(&mut rng));
                let (v, y) = (
                    rng.random::<f64>() - 0.5,
                    (rng.random::<f64>() * 1.8 - 0.9) * l,
                );
                let mut s = [0.0; NP];
                (s[idx::Y], s[idx::VEL]) = (y, v);
                for i in 0..2 {
                    (s[idx::P1[i]], s[idx::P2[i]]) = (p1, p2);
                }
                let ds = plant_derivatives(&model, x, &s).unwrap();
                let a = &model.actuator;
                let kernel: f64 = (0..2)
                    .map(|i| ds[idx::P1[i]] * a.a1 - ds[idx::P2[i]] * a.a2)
                    .sum();
                let ours = force_rate(&plant, x, p1, p2, v, y);
                assert!(
                    (ours - kernel).abs() <= 1e-12 * kernel.abs().max(1.0),
                    "{law:?}: {ours} against the kernel's {kernel} at x {x}, p {p1} {p2}, v {v}, y {y}"
                );
            }
        }
    }

    #[test]
    fn stlsq_finds_the_term_it_was_made_of() {
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / n as f64 * 6.0).collect();
        // Two correlated states: x a sine, v a sine with a third harmonic and a phase shift.
        let x: Vec<f64> = t.iter().map(|t| (2.0 * PI * t).sin()).collect();
        let v: Vec<f64> = t
            .iter()
            .map(|t| 0.8 * (2.0 * PI * t + 0.3).sin() + 0.2 * (6.0 * PI * t).sin())
            .collect();
        let y: Vec<f64> = x
            .iter()
            .map(|&x| 3.0 * Term::NearNull.eval(x) + 0.1)
            .collect();
        let rx = stlsq(
            Residual::Force,
            Some(State::SpoolOpening),
            &[(State::SpoolOpening, &x)],
            &y,
        );
        let rv = stlsq(
            Residual::Force,
            Some(State::Velocity),
            &[(State::Velocity, &v)],
            &y,
        );
        assert!(rx.r2 > 0.999, "{rx:?}");
        assert!(rv.r2 < rx.r2 - 0.1, "{rv:?}");
        assert_eq!(rx.terms[0].term, Term::NearNull, "{rx:?}");
        let all = stlsq(
            Residual::Force,
            None,
            &[(State::SpoolOpening, &x), (State::Velocity, &v)],
            &y,
        );
        assert_eq!(
            (all.terms[0].state, all.terms[0].term),
            (State::SpoolOpening, Term::NearNull),
            "{all:?}"
        );
        assert!(all.terms.len() <= 3, "sparse: {all:?}");
    }

    /// The harmonic part of a sine residual and its derivative are exact for a band-limited signal.
    #[test]
    fn harmonic_rate_is_the_derivative() {
        let f = 2.0;
        let tau: Vec<f64> = (0..1024).map(|k| k as f64 / 512.0).collect();
        let x: Vec<f64> = tau
            .iter()
            .map(|t| 0.5 + (2.0 * PI * f * t).sin() + 0.3 * (6.0 * PI * f * t).cos())
            .collect();
        let p = Projector::new(&tau, f, 9);
        let (v, r) = harmonic_and_rate(&p, &tau, f, &x);
        for (i, t) in tau.iter().enumerate() {
            let w = 2.0 * PI * f;
            let d = w * (w * t).cos() - 0.9 * w * (3.0 * w * t).sin();
            assert!(
                (v[i] - x[i]).abs() < 1e-9 && (r[i] - d).abs() < 1e-7,
                "{i}: {} {} vs {d}",
                v[i],
                r[i]
            );
        }
    }
}
