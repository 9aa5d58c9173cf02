//! The lane kernel: N samples integrated together, structure-of-arrays, allocation-free.
//!
//! Each controller tick t_k = k/f_s:
//! 1. actuator force F and the controller ([`super::controller::tick`]) → spool command x_c, held
//!    over [t_k, t_{k+1}) (zero-order hold); in open loop ([`super::excitation::Drive`]) a measured
//!    valve command or spool position takes the controller's place;
//! 2. one right-hand-side evaluation at t_k gives the platen acceleration a = dv/dt at t_k (a does
//!    not depend on x_c) and the first RK4 stage;
//! 3. the channels are offered to the [`Observer`] and the online metrics;
//! 4. the plant is advanced to t_{k+1} by `substeps` classical RK4 steps of h = 1/(f_s·substeps)
//!    (the plant is smooth inside a tick, so the hold costs no accuracy; the integrator was chosen
//!    for vectorisation: fixed step, no data-dependent control flow; its convergence is checked
//!    by `tests/reference.rs`);
//! 5. the guard of docs/model.md §3: a lane whose state is non-finite, whose |y| reaches L, or whose
//!    pressure leaves [−1 MPa, 2·P_S] is marked failed with time and reason, reset to rest and
//!    carried along (its metrics become NaN); it never aborts the batch.
//!
//! The valve law (`Q`), the damping law (`D`) and the effect (`E`) are type parameters, so the
//! step has no branch on configuration. N = 1 is the scalar path: the same code, one lane. The
//! bare plant (no effect) takes `kernel::bare`'s right-hand side: every lane in explicit SIMD
//! registers, the same operations and bits; every other right-hand side is compiled once per build,
//! out of line. The builds the rest of vshake runs are made in `crate::builds`, each at a
//! [`Site`] of its own (a module, so a codegen unit).

use super::actuator;
use super::bare;
use super::controller::{self, ControllerMemory, RefState};
use super::effects::{hook, Effect, PlantView};
use super::excitation::{Drive, Reference};
use super::friction;
pub use super::lane_params::{LaneParams, SetupError};
use super::lanes::{AVX2, AVX512, PORTABLE};
use super::metrics::{Basis, Metrics, MetricsAcc, SpecimenAcc, WindowTick};
use super::params::{ModelParams, ValveLaw};
use super::platen::{self, Damping, PowDamping, SqrtDamping};
use super::servovalve::{EitherLaw, FlowLaw, Linear, Orifice};
use super::N_ACT;
use std::fmt;

use super::state::idx::*;
use super::state::NP;

/// Integrator settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solver {
    /// RK4 steps per controller tick. Default 4 (h = 244 µs at 1024 Hz) [chosen: the fewest
    /// that keep every metric within 1e-5 of the 32-substep answer, in the metric's own unit,
    /// over the gains sweep and the reference cases; `tests/reference.rs`].
    pub substeps: usize,
}

impl Default for Solver {
    fn default() -> Self {
        Solver { substeps: 4 }
    }
}

/// Why a lane failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Failure {
    /// A state became NaN or infinite.
    NonFinite,
    /// |y| reached the half stroke L.
    StrokeLimit { disp_m: f64 },
    /// A chamber pressure left [−1 MPa, 2·P_S].
    Pressure {
        actuator: usize,
        chamber: usize,
        pa: f64,
    },
}

impl Failure {
    /// A fixed category, to group on (a results table's `fail_reason`).
    pub fn category(&self) -> &'static str {
        match self {
            Failure::NonFinite => "diverged",
            Failure::StrokeLimit { .. } => "stroke_limit",
            Failure::Pressure { .. } => "pressure_limit",
        }
    }
    /// The value that left its bound, SI (m for the stroke, Pa for a pressure; None when the
    /// state diverged).
    pub fn value(&self) -> Option<f64> {
        match self {
            Failure::NonFinite => None,
            Failure::StrokeLimit { disp_m } => Some(*disp_m),
            Failure::Pressure { pa, .. } => Some(*pa),
        }
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Failure::NonFinite => write!(f, "state became non-finite (diverged)"),
            Failure::StrokeLimit { disp_m } => {
                write!(f, "stroke limit reached (y = {disp_m:.4} m)")
            }
            Failure::Pressure {
                actuator,
                chamber,
                pa,
            } => write!(
                f,
                "pressure P{chamber} of actuator {} left [-1 MPa, 2 P_S] ({:.3} MPa)",
                actuator + 1,
                pa / 1e6
            ),
        }
    }
}

/// Outcome of one lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LaneStatus {
    Ok,
    Failed { time_s: f64, reason: Failure },
}

/// Result of one lane: status and metrics (NaN for a failed lane).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaneResult {
    pub status: LaneStatus,
    pub metrics: Metrics,
}

/// The channels of docs/model.md §5 at one tick (or, for an observer that asks for them, at one
/// RK4 substep inside a tick), for every lane.
pub struct TickView<'a, const N: usize> {
    /// Controller tick.
    pub k: usize,
    /// Substep inside the tick: 0 at the tick itself, 1 … substeps − 1 at t_k + sub·h.
    pub sub: usize,
    /// Time, s.
    pub t: f64,
    pub r: &'a RefState,
    /// Displacement feedback: the actuator stroke (ideal LVDT; the platen displacement unless an
    /// effect moves the actuators' base), m.
    pub x: &'a [f64; N],
    /// Platen acceleration dv/dt at t_k, m/s².
    pub a: &'a [f64; N],
    /// Valve command after the clamp, V.
    pub u: &'a [f64; N],
    /// Spool command, m.
    pub x_c: &'a [f64; N],
    /// Spool position of actuator 1 (after the valve effects; x_c in the baseline), m.
    pub spool: &'a [f64; N],
    /// Total actuator force, N.
    pub f: &'a [f64; N],
    pub state: &'a [[f64; N]; NP],
    /// The effects' own channels of a lane ([`Effect::responses`]: a building's drifts, floor
    /// accelerations, base shear), each given to the callback by name.
    pub responses: &'a dyn Fn(usize, &mut ResponseSink<'_>),
}

/// Where an effect's channels go, by name and value ([`Effect::responses`]).
pub type ResponseSink<'a> = dyn FnMut(&'static str, f64) + 'a;

/// Receives every tick (time histories, live plots). The batch engine passes [`NoObserver`].
///
/// An observer that needs the plant at other times (dense output at a measured file's sample
/// rate, [`super::resample::Resampler`]) lists them in [`Observer::probe_times`] (s, ascending);
/// it then receives [`Observer::probe`] at each, in order: the plant integrated to that time by
/// a partial RK4 step from the substep before it (the command held, as in the tick), with the
/// acceleration, force, stroke and spool evaluated there, and the tick's held command and
/// reference. A time on a substep node (to 1e-9 of a substep) takes that node exactly.
pub trait Observer<const N: usize> {
    fn tick(&mut self, view: &TickView<'_, N>);
    /// Times at which [`Observer::probe`] is wanted (asked as the run goes).
    fn probe_times(&self) -> &[f64] {
        &[]
    }
    /// The plant at the next of [`Observer::probe_times`].
    fn probe(&mut self, _view: &TickView<'_, N>) {}
}

/// Where time `t` falls: its tick and its position in the tick in substeps, in [0, S); a
/// position within 1e-9 of a node is that node.
pub(crate) fn slot(t: f64, f_s: f64, substeps: usize) -> (usize, f64) {
    let s = substeps as f64;
    let p = t * f_s;
    let mut tick = p.floor().max(0.0) as usize;
    let mut pos = (p - tick as f64) * s;
    let node = pos.round();
    if (pos - node).abs() < 1e-9 {
        pos = node;
        if node >= s {
            tick += 1;
            pos = 0.0;
        }
    }
    (tick, pos.max(0.0))
}

/// Observes nothing.
pub struct NoObserver;
impl<const N: usize> Observer<N> for NoObserver {
    #[inline(always)]
    fn tick(&mut self, _view: &TickView<'_, N>) {}
}

/// The instruction set a batch's kernel is built for, narrowest first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Isa {
    /// The portable build (x86-64 baseline: SSE2).
    Portable,
    /// The same code compiled with AVX2 and FMA enabled (x86-64 CPUs that report both).
    Avx2,
    /// AVX-512 F and VL as well: the bare plant in eight-lane registers, with 32 of them (the
    /// runs with effects take the AVX2 build).
    Avx512,
}

impl Isa {
    /// The widest instruction set this CPU runs (runtime detection).
    pub fn detected() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx2") && has!("fma") {
                if has!("avx512f") && has!("avx512vl") {
                    return Isa::Avx512;
                }
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    /// Its name, as `study bench` and the run banner print it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Runs a batch: dispatches once on the valve law, the damping law and the instruction set, then
/// integrates.
///
/// The AVX2 and AVX-512 builds are the same generic code compiled with wider vectors, the bare
/// plant's right-hand side in explicit registers of that width (`kernel::bare`). Rust never
/// contracts a multiply and an add into an FMA, and square root and division are correctly
/// rounded, so every build gives bit-identical results (`tests/reference.rs` checks it).
pub fn run<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized>(
    lp: &LaneParams<N>,
    effect: &E,
    reference: &Reference,
    solver: &Solver,
    obs: &mut O,
) -> Result<[LaneResult; N], SetupError> {
    run_on(Isa::detected(), lp, effect, reference, solver, obs)
}

/// [`run`] with a reference per lane (a stochastic ground motion: one realisation per sample).
/// The references must agree in rate, length, window, fundamental and spectrum, and drive the
/// spool by the controller unless they are one reference; lane l follows `refs[l]` with the same
/// bits as when every lane shares it.
pub fn run_each<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized>(
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> Result<[LaneResult; N], SetupError> {
    run_each_on::<N, E, O, here::Here>(Isa::detected(), lp, effect, refs, solver, obs)
}

/// [`run`] on a chosen instruction set.
pub fn run_on<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized>(
    isa: Isa,
    lp: &LaneParams<N>,
    effect: &E,
    reference: &Reference,
    solver: &Solver,
    obs: &mut O,
) -> Result<[LaneResult; N], SetupError> {
    run_each_on::<N, E, O, here::Here>(isa, lp, effect, &[reference; N], solver, obs)
}

/// [`run_each`] on a chosen instruction set, its builds compiled at `P` ([`Site`]).
pub(crate) fn run_each_on<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized, P: Site>(
    isa: Isa,
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> Result<[LaneResult; N], SetupError> {
    check(lp.f_s, refs, solver)?;
    // Never more than the CPU has: asking for more runs the widest build it has.
    let isa = isa.min(Isa::detected());
    // The published laws (orifice flow, α = ½) have builds of their own; every other pair runs
    // one build that reads the law from the lanes (`EitherLaw`, `PowDamping`: the same bits).
    Ok(match (lp.valve_law, lp.alpha_half) {
        (ValveLaw::Orifice, true) => {
            actuators::<N, Orifice, SqrtDamping, E, O, P>(isa, lp, effect, refs, solver, obs)
        }
        _ => actuators::<N, EitherLaw, PowDamping, E, O, P>(isa, lp, effect, refs, solver, obs),
    })
}

/// [`run`] for the usual configuration only — orifice valves, α = ½, a CPU with AVX2 and FMA —
/// and `None` elsewhere (the caller then runs [`run`]). For callers that instantiate the kernel
/// for many effect types ([`crate::effects::with_single`]): two integrators per effect
/// (one or two actuators) instead of [`run`]'s sixteen, which keeps the build time in check.
pub(crate) fn run_usual<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized, P: Site>(
    lp: &LaneParams<N>,
    effect: &E,
    reference: &Reference,
    solver: &Solver,
    obs: &mut O,
) -> Option<Result<[LaneResult; N], SetupError>> {
    #[cfg(target_arch = "x86_64")]
    if matches!(lp.valve_law, ValveLaw::Orifice) && lp.alpha_half && Isa::detected() >= Isa::Avx2 {
        let refs = &[reference; N];
        if let Err(e) = check(lp.f_s, refs, solver) {
            return Some(Err(e));
        }
        if const { !E::SPLITS } {
            assert_symmetric(effect);
            // SAFETY: the CPU reports AVX2 and FMA (`Isa::detected`).
            return Some(Ok(unsafe {
                P::avx2::<N, 1, Orifice, SqrtDamping, E, O>(lp, effect, refs, solver, obs)
            }));
        }
        // SAFETY: the CPU reports AVX2 and FMA (`Isa::detected`).
        return Some(Ok(unsafe {
            if effect.symmetric() {
                P::avx2::<N, 1, Orifice, SqrtDamping, E, O>(lp, effect, refs, solver, obs)
            } else {
                P::avx2::<N, N_ACT, Orifice, SqrtDamping, E, O>(lp, effect, refs, solver, obs)
            }
        }));
    }
    let _ = (lp, effect, reference, solver, obs);
    None
}

/// The baseline plant's state derivative for one parameter set at state `s` (indexed by
/// [`super::state::idx`]) and spool command `x_c`, m: the time loop's right-hand side (both
/// actuators, no effect, the set's valve law and damping exponent) at one state, against which
/// the analyses that evaluate the plant outside the loop are checked.
pub fn plant_derivatives(
    model: &ModelParams,
    x_c: f64,
    s: &[f64; NP],
) -> Result<[f64; NP], SetupError> {
    let lp = LaneParams::<1>::new(&[model])?;
    let state: [[f64; 1]; NP] = std::array::from_fn(|i| [s[i]]);
    let mut ds = [[0.0; 1]; NP];
    let (e, x) = (&super::effects::Baseline, &[x_c]);
    let (es, mut des) = ([], []);
    match (lp.valve_law, lp.alpha_half) {
        (ValveLaw::Orifice, true) => rhs_general::<1, N_ACT, PORTABLE, Orifice, SqrtDamping, _>(
            &lp, e, x, &state, &es, &mut ds, &mut des,
        ),
        (ValveLaw::Orifice, false) => rhs_general::<1, N_ACT, PORTABLE, Orifice, PowDamping, _>(
            &lp, e, x, &state, &es, &mut ds, &mut des,
        ),
        (ValveLaw::Linear, true) => rhs_general::<1, N_ACT, PORTABLE, Linear, SqrtDamping, _>(
            &lp, e, x, &state, &es, &mut ds, &mut des,
        ),
        (ValveLaw::Linear, false) => rhs_general::<1, N_ACT, PORTABLE, Linear, PowDamping, _>(
            &lp, e, x, &state, &es, &mut ds, &mut des,
        ),
    }
    Ok(std::array::from_fn(|i| ds[i][0]))
}

/// The checks before a run: the reference's rate is the controller's, substeps ≥ 1, a drive as
/// long as the reference.
pub fn check(f_s: f64, refs: &[&Reference], solver: &Solver) -> Result<(), SetupError> {
    let reference = refs[0];
    for r in &refs[1..] {
        let same = std::ptr::eq(*r, reference)
            || (r.f_s == reference.f_s
                && r.len() == reference.len()
                && r.window == reference.window
                && r.fundamental_hz == reference.fundamental_hz
                && r.spectrum.as_ref().map(|s| &s.0) == reference.spectrum.as_ref().map(|s| &s.0)
                && r.drive == Drive::ClosedLoop
                && reference.drive == Drive::ClosedLoop);
        if !same {
            return Err(SetupError::LaneReferences);
        }
    }
    if reference.f_s != f_s {
        return Err(SetupError::RateMismatch {
            reference: reference.f_s,
            controller: f_s,
        });
    }
    if solver.substeps == 0 {
        return Err(SetupError::Substeps);
    }
    if let Drive::ValveCommand(d) | Drive::Spool(d) = &reference.drive {
        if d.len() != reference.len() {
            return Err(SetupError::DriveLength {
                got: d.len(),
                expected: reference.len(),
            });
        }
    }
    Ok(())
}

/// One equivalent actuator when the effect keeps the two identical ([`Effect::symmetric`]: every
/// lane's actuators share their parameters, so only an effect can tell them apart), else both.
fn actuators<
    const N: usize,
    Q: FlowLaw,
    D: Damping,
    E: Effect<N>,
    O: Observer<N> + ?Sized,
    P: Site,
>(
    isa: Isa,
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> [LaneResult; N] {
    // Decided by the type where the effect cannot tell the actuators apart (`Effect::SPLITS`):
    // the kernel with both actuators is then not built (the branch is pruned at compile time).
    if const { !E::SPLITS } {
        assert_symmetric(effect);
        return dispatch::<N, 1, Q, D, E, O, P>(isa, lp, effect, refs, solver, obs);
    }
    if effect.symmetric() {
        dispatch::<N, 1, Q, D, E, O, P>(isa, lp, effect, refs, solver, obs)
    } else {
        dispatch::<N, N_ACT, Q, D, E, O, P>(isa, lp, effect, refs, solver, obs)
    }
}

/// [`run_each`] for effects that leave the hydraulics alone ([`Effect::hydraulic`]: a specimen, a
/// building, a measurement chain) in a batch the bare plant's AVX2 registers take
/// ([`bare::fits`]: up to 16 lanes), in the usual configuration (orifice valves, α = ½, identical
/// actuators) on a CPU with AVX2 and FMA; `None` elsewhere (the caller then runs [`run_each`] in
/// narrower batches: lanes are independent, the same numbers bit for bit). The AVX2 build, not
/// the AVX-512 one: with an effect's states in the loop, the AVX-512 build of 16 lanes ran 1.4
/// times slower than this one here (docs/performance.md).
pub(crate) fn run_platen_forces<const N: usize, E: Effect<N>, O: Observer<N> + ?Sized, P: Site>(
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> Option<Result<[LaneResult; N], SetupError>> {
    #[cfg(target_arch = "x86_64")]
    if const { bare::fits::<AVX2>(N) }
        && matches!(lp.valve_law, ValveLaw::Orifice)
        && lp.alpha_half
        && Isa::detected() >= Isa::Avx2
        && !effect.hydraulic()
        && effect.symmetric()
    {
        if let Err(e) = check(lp.f_s, refs, solver) {
            return Some(Err(e));
        }
        // SAFETY: the CPU reports AVX2 and FMA (`Isa::detected`).
        return Some(Ok(unsafe {
            P::avx2::<N, 1, Orifice, SqrtDamping, E, O>(lp, effect, refs, solver, obs)
        }));
    }
    let _ = (lp, effect, refs, solver, obs);
    None
}

/// An effect that does not declare [`Effect::SPLITS`] keeps the actuators identical.
fn assert_symmetric<const N: usize, E: Effect<N>>(effect: &E) {
    assert!(
        effect.symmetric(),
        "an effect whose `symmetric` can say false declares `const SPLITS: bool = true`"
    );
}

fn dispatch<
    const N: usize,
    const A: usize,
    Q: FlowLaw,
    D: Damping,
    E: Effect<N>,
    O: Observer<N> + ?Sized,
    P: Site,
>(
    isa: Isa,
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> [LaneResult; N] {
    // The vector builds are made for the published laws (orifice flow, α = ½), and for every law
    // on the bare plant's full batches (design exploration's); elsewhere the portable build runs,
    // the same bits, which keeps the build time of the many kernels in check.
    #[cfg(target_arch = "x86_64")]
    if const { (Q::USUAL && D::USUAL) || (E::BARE && N == crate::LANES) } {
        // SAFETY (both calls): `isa` is at most what the CPU reports (`run_each_on`).
        match isa {
            // The AVX-512 build is made for the bare plant's vector path only.
            Isa::Avx512 if const { E::BARE && A == 1 && bare::fits::<AVX512>(N) } => {
                return unsafe { P::avx512::<N, A, Q, D, E, O>(lp, effect, refs, solver, obs) }
            }
            Isa::Avx512 | Isa::Avx2 => {
                return unsafe { P::avx2::<N, A, Q, D, E, O>(lp, effect, refs, solver, obs) }
            }
            Isa::Portable => {}
        }
    }
    // One portable build serves every law (the same bits as a build for the law).
    let _ = isa;
    P::portable::<N, A, EitherLaw, PowDamping, E, O>(lp, effect, refs, solver, obs)
}

/// Where the builds of the integrator are compiled. rustc compiles a generic function's copies in
/// the codegen unit of the module that defines it, one LLVM module optimised on one core, and a
/// method's in that of its type's module: the integrator's entry points (the portable build, the
/// AVX2 and the AVX-512 one, into which [`integrate`] is inlined) are methods of a site, one
/// module each ([`site!`]), so that the builds of several sites are optimised in parallel
/// (`crate::builds`).
pub(crate) trait Site: 'static {
    fn portable<
        const N: usize,
        const A: usize,
        Q: FlowLaw,
        D: Damping,
        E: Effect<N>,
        O: Observer<N> + ?Sized,
    >(
        lp: &LaneParams<N>,
        effect: &E,
        refs: &[&Reference; N],
        solver: &Solver,
        obs: &mut O,
    ) -> [LaneResult; N];

    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    unsafe fn avx2<
        const N: usize,
        const A: usize,
        Q: FlowLaw,
        D: Damping,
        E: Effect<N>,
        O: Observer<N> + ?Sized,
    >(
        lp: &LaneParams<N>,
        effect: &E,
        refs: &[&Reference; N],
        solver: &Solver,
        obs: &mut O,
    ) -> [LaneResult; N];

    /// The general right-hand side ([`rhs_general`]) in the build of instruction set `SIMD`, out
    /// of line.
    ///
    /// # Safety
    /// The CPU has the instruction set `SIMD`.
    #[allow(clippy::too_many_arguments)]
    unsafe fn rhs<
        const N: usize,
        const A: usize,
        const SIMD: u8,
        Q: FlowLaw,
        D: Damping,
        E: Effect<N>,
    >(
        lp: &LaneParams<N>,
        effect: &E,
        x_c: &[f64; N],
        s: &[[f64; N]; NP],
        es: &E::State,
        ds: &mut [[f64; N]; NP],
        des: &mut E::State,
    );

    /// # Safety
    /// The CPU has AVX-512 (F and VL), AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    unsafe fn avx512<
        const N: usize,
        const A: usize,
        Q: FlowLaw,
        D: Damping,
        E: Effect<N>,
        O: Observer<N> + ?Sized,
    >(
        lp: &LaneParams<N>,
        effect: &E,
        refs: &[&Reference; N],
        solver: &Solver,
        obs: &mut O,
    ) -> [LaneResult; N];
}

/// A module `$name` holding a [`Site`], `$name::Here`, and its builds of the integrator.
macro_rules! site {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        pub(crate) mod $name {
            use $crate::effects::Effect;
            use $crate::excitation::Reference;
            use $crate::platen::Damping;
            use $crate::servovalve::FlowLaw;
            use $crate::simulate::{integrate, rhs_general, LaneParams, LaneResult, Observer, Solver};
            use $crate::state::NP;

            /// This module's site.
            pub struct Here;

            impl $crate::simulate::Site for Here {
                fn portable<
                    const N: usize,
                    const A: usize,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                    O: Observer<N> + ?Sized,
                >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    refs: &[&Reference; N],
                    solver: &Solver,
                    obs: &mut O,
                ) -> [LaneResult; N] {
                    integrate::<N, A, { $crate::lanes::PORTABLE }, Q, D, E, O, Here>(
                        lp, effect, refs, solver, obs,
                    )
                }

                #[allow(clippy::too_many_arguments)]
                unsafe fn rhs<
                    const N: usize,
                    const A: usize,
                    const SIMD: u8,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    x_c: &[f64; N],
                    s: &[[f64; N]; NP],
                    es: &E::State,
                    ds: &mut [[f64; N]; NP],
                    des: &mut E::State,
                ) {
                    #[cfg(target_arch = "x86_64")]
                    match SIMD {
                        // SAFETY (both): the caller's (the CPU has the instruction set).
                        $crate::lanes::AVX2 => {
                            return unsafe {
                                rhs_avx2::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des)
                            }
                        }
                        $crate::lanes::AVX512 => {
                            return unsafe {
                                rhs_avx512::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des)
                            }
                        }
                        _ => {}
                    }
                    rhs_general::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des)
                }

                #[cfg(target_arch = "x86_64")]
                unsafe fn avx2<
                    const N: usize,
                    const A: usize,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                    O: Observer<N> + ?Sized,
                >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    refs: &[&Reference; N],
                    solver: &Solver,
                    obs: &mut O,
                ) -> [LaneResult; N] {
                    // SAFETY: the caller's (the CPU has AVX2 and FMA).
                    unsafe { avx2::<N, A, Q, D, E, O>(lp, effect, refs, solver, obs) }
                }

                #[cfg(target_arch = "x86_64")]
                unsafe fn avx512<
                    const N: usize,
                    const A: usize,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                    O: Observer<N> + ?Sized,
                >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    refs: &[&Reference; N],
                    solver: &Solver,
                    obs: &mut O,
                ) -> [LaneResult; N] {
                    // SAFETY: the caller's (the CPU has AVX-512, AVX2 and FMA).
                    unsafe { avx512::<N, A, Q, D, E, O>(lp, effect, refs, solver, obs) }
                }
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2<
                    const N: usize,
                    const A: usize,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                    O: Observer<N> + ?Sized,
            >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    refs: &[&Reference; N],
                    solver: &Solver,
                    obs: &mut O,
            ) -> [LaneResult; N] {
                integrate::<N, A, { $crate::lanes::AVX2 }, Q, D, E, O, Here>(
                    lp, effect, refs, solver, obs,
                )
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            #[inline(never)]
            #[allow(clippy::too_many_arguments)]
            unsafe fn rhs_avx2<
                    const N: usize,
                    const A: usize,
                    const SIMD: u8,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
            >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    x_c: &[f64; N],
                    s: &[[f64; N]; NP],
                    es: &E::State,
                    ds: &mut [[f64; N]; NP],
                    des: &mut E::State,
            ) {
                rhs_general::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des)
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
            unsafe fn avx512<
                    const N: usize,
                    const A: usize,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
                    O: Observer<N> + ?Sized,
            >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    refs: &[&Reference; N],
                    solver: &Solver,
                    obs: &mut O,
            ) -> [LaneResult; N] {
                integrate::<N, A, { $crate::lanes::AVX512 }, Q, D, E, O, Here>(
                    lp, effect, refs, solver, obs,
                )
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
            #[inline(never)]
            #[allow(clippy::too_many_arguments)]
            unsafe fn rhs_avx512<
                    const N: usize,
                    const A: usize,
                    const SIMD: u8,
                    Q: FlowLaw,
                    D: Damping,
                    E: Effect<N>,
            >(
                    lp: &LaneParams<N>,
                    effect: &E,
                    x_c: &[f64; N],
                    s: &[[f64; N]; NP],
                    es: &E::State,
                    ds: &mut [[f64; N]; NP],
                    des: &mut E::State,
            ) {
                rhs_general::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des)
            }
        }
    };
}
pub(crate) use site;

site! {
    /// The site of the generic entry points ([`run`], [`run_each`], [`run_on`]): the builds
    /// that tests, benchmarks and other crates make with their own types.
    here
}

/// Plant right-hand side for every lane: the bare plant's vector path ([`bare::rhs`]) inline, the
/// general one ([`rhs_general`]) out of line, compiled once per build at its site
/// ([`Site::rhs`]) instead of inlined at each of an integrator's nine evaluations (the RK4
/// stages, the first of each substep and a probe's four): a call per evaluation of every lane,
/// a ninth of the code to compile.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn rhs<
    const N: usize,
    const A: usize,
    const SIMD: u8,
    Q: FlowLaw,
    D: Damping,
    E: Effect<N>,
    P: Site,
>(
    lp: &LaneParams<N>,
    effect: &E,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    es: &E::State,
    ds: &mut [[f64; N]; NP],
    des: &mut E::State,
) {
    if const { E::BARE && A == 1 && bare::fits::<SIMD>(N) } {
        bare::rhs::<N, SIMD, Q, D>(lp, x_c, s, ds, None, None);
        return;
    }
    // The bare plant's single lane (`study sim`, a comparison's runs) is small code, and a call per
    // evaluation costs it about a fifth of its speed: inline.
    if const { E::BARE && N == 1 } {
        rhs_general::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des);
        return;
    }
    // SAFETY: a build runs only where the CPU has its instruction set (`dispatch`).
    unsafe { P::rhs::<N, A, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des) }
}

/// Plant right-hand side for every lane, computing `A` actuators: both, or (A = 1) the first
/// standing for both, whose derivatives, force and supply flow are then copied and doubled
/// (x + x is exact, so this equals computing the identical second actuator, bit for bit).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn rhs_general<
    const N: usize,
    const A: usize,
    const SIMD: u8,
    Q: FlowLaw,
    D: Damping,
    E: Effect<N>,
>(
    lp: &LaneParams<N>,
    effect: &E,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    es: &E::State,
    ds: &mut [[f64; N]; NP],
    des: &mut E::State,
) {
    // Effects that leave the hydraulics alone (a force on the platen, a measurement chain) take
    // the bare plant's vector path, their force added to the actuators' (the same bits).
    if const { A == 1 && bare::fits::<SIMD>(N) } && !effect.hydraulic() {
        rhs_platen_forces::<N, SIMD, Q, D, E>(lp, effect, x_c, s, es, ds, des);
        return;
    }
    let mut q_in1 = [[0.0; N]; N_ACT];
    let mut q_out2 = [[0.0; N]; N_ACT];
    let mut xs = [[0.0; N]; N_ACT];
    let mut q_supply = [0.0; N];
    let mut f_act = [0.0; N];
    // One hook of every lane before the next ([`Effect::supplies`]): each lane's numbers are
    // those of the hooks called lane by lane, in the same order.
    let p_s = effect.supplies(&lp.p_s, es);
    // The chambers follow the actuator stroke (the platen's motion unless an effect says so).
    let [stroke, v_s] = effect.strokes(&s[Y], &s[VEL], es);
    let mut b = [[0.0; N]; 2];
    for l in 0..N {
        (b[0][l], b[1][l]) = actuator::stiffness_factors(&lp.act.lane(l), stroke[l]);
    }
    for i in 0..A {
        let p = [&s[P1[i]], &s[P2[i]]];
        let x = effect.openings(i, x_c, es);
        let mut q = [[0.0; N]; 2];
        for l in 0..N {
            let (q1, q2) = Q::flows(&lp.valve.lane(l), x[l], p[0][l], p[1][l], p_s[l]);
            // Supply → chamber 1 when x > 0, supply → chamber 2 (q2 < 0) otherwise.
            q_supply[l] += if x[l] > 0.0 { q1 } else { -q2 };
            (q[0][l], q[1][l]) = (q1, q2);
        }
        let [q1, q2] = effect.all_flows(i, q, (p, &p_s), es);
        let [b1, b2] = effect.stiffnesses(i, b, p, es);
        for l in 0..N {
            let act = lp.act.lane(l);
            let (d1, d2) = actuator::pressure_rates(&act, b1[l], b2[l], q1[l], q2[l], v_s[l]);
            ds[P1[i]][l] = d1;
            ds[P2[i]][l] = d2;
            f_act[l] += actuator::force(&act, p[0][l], p[1][l]);
        }
        (xs[i], q_in1[i], q_out2[i]) = (x, q1, q2);
    }
    if A == 1 {
        for l in 0..N {
            f_act[l] = f_act[l] + f_act[l];
            q_supply[l] = q_supply[l] + q_supply[l];
            for j in [P1, P2] {
                ds[j[1]][l] = ds[j[0]][l];
            }
        }
        (xs[1], q_in1[1], q_out2[1]) = (xs[0], q_in1[0], q_out2[0]);
    }
    let fe = effect.extra_forces(&s[Y], &s[VEL], es);
    for l in 0..N {
        let (y, v, z) = (s[Y][l], s[VEL][l], s[Z][l]);
        ds[VEL][l] = platen::accel::<D>(&lp.platen.lane(l), f_act[l], fe[l], y, v, z);
        ds[Y][l] = v;
        ds[Z][l] = friction::dz_dt(&lp.friction.lane(l), v, z);
    }
    let view = PlantView {
        x_c,
        opening: &xs,
        q_supply: &q_supply,
        state: s,
        q_in1: &q_in1,
        q_out2: &q_out2,
        p_s: &p_s,
        f_act: &f_act,
        accel: &ds[VEL],
        stroke: &stroke,
    };
    effect.derivs(&view, es, des);
}

/// [`rhs_general`] for an effect that leaves the hydraulics alone ([`Effect::hydraulic`] says
/// false): its force on the platen, lane by lane, then the plant in the registers of the build
/// `SIMD` ([`bare::rhs`], the batch fits), then the effect's derivatives from the same view of
/// the plant as [`rhs_general`] gives them.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn rhs_platen_forces<const N: usize, const SIMD: u8, Q: FlowLaw, D: Damping, E: Effect<N>>(
    lp: &LaneParams<N>,
    effect: &E,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    es: &E::State,
    ds: &mut [[f64; N]; NP],
    des: &mut E::State,
) {
    let f_ext: [f64; N] = effect.extra_forces(&s[Y], &s[VEL], es);
    let mut h = bare::Hydraulics::default();
    bare::rhs::<N, SIMD, Q, D>(lp, x_c, s, ds, Some(&f_ext), Some(&mut h));
    let view = PlantView {
        x_c,
        opening: &[*x_c; N_ACT],
        q_supply: &h.q_supply,
        state: s,
        q_in1: &[h.q1; N_ACT],
        q_out2: &[h.q2; N_ACT],
        p_s: &lp.p_s,
        f_act: &h.f_act,
        accel: &ds[VEL],
        stroke: &s[Y],
    };
    effect.derivs(&view, es, des);
}

/// The held part of a probe's view: its tick, substep, time, reference and command.
struct Held<'a, const N: usize> {
    k: usize,
    sub: usize,
    t: f64,
    r: &'a RefState,
    u: &'a [f64; N],
}

/// Scratch for dense output: one RK4 step of a chosen length from a substep node, kept apart
/// from the integrator's own buffers (allocated once, on the stack, before the run).
struct Probe<const N: usize, E: Effect<N>> {
    s: [[f64; N]; NP],
    tmp: [[f64; N]; NP],
    k: [[[f64; N]; NP]; 4],
    es: E::State,
    etmp: E::State,
    ek: [E::State; 4],
}

impl<const N: usize, E: Effect<N>> Probe<N, E> {
    fn new(es: E::State) -> Self {
        Probe {
            s: [[0.0; N]; NP],
            tmp: [[0.0; N]; NP],
            k: [[[0.0; N]; NP]; 4],
            es,
            etmp: es,
            ek: [bytemuck::Zeroable::zeroed(); 4],
        }
    }

    /// The plant `delta` after the node (s, es) whose derivatives are (k1, ek1), by one RK4 step
    /// with the command held; its channels go to `obs.probe`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn probe<
        const A: usize,
        const SIMD: u8,
        Q: FlowLaw,
        D: Damping,
        O: Observer<N> + ?Sized,
        P: Site,
    >(
        &mut self,
        lp: &LaneParams<N>,
        effect: &E,
        x_c: &[f64; N],
        s: &[[f64; N]; NP],
        es: &E::State,
        k1: &[[f64; N]; NP],
        ek1: &E::State,
        delta: f64,
        held: &Held<'_, N>,
        obs: &mut O,
    ) {
        if delta > 0.0 {
            let [k2, k3, k4, ka] = &mut self.k;
            let [ek2, ek3, ek4, eka] = &mut self.ek;
            let live = effect.live_states();
            plant_axpy::<N, A>(&mut self.tmp, s, 0.5 * delta, k1);
            axpy(
                live,
                self.etmp.as_mut(),
                es.as_ref(),
                0.5 * delta,
                ek1.as_ref(),
            );
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, x_c, &self.tmp, &self.etmp, k2, ek2);
            plant_axpy::<N, A>(&mut self.tmp, s, 0.5 * delta, k2);
            axpy(
                live,
                self.etmp.as_mut(),
                es.as_ref(),
                0.5 * delta,
                ek2.as_ref(),
            );
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, x_c, &self.tmp, &self.etmp, k3, ek3);
            plant_axpy::<N, A>(&mut self.tmp, s, delta, k3);
            axpy(live, self.etmp.as_mut(), es.as_ref(), delta, ek3.as_ref());
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, x_c, &self.tmp, &self.etmp, k4, ek4);
            self.s = *s;
            self.es = *es;
            plant_combine::<N, A>(&mut self.s, delta / 6.0, [k1, k2, k3, k4]);
            rk4_combine(
                live,
                self.es.as_mut(),
                delta / 6.0,
                ek1.as_ref(),
                ek2.as_ref(),
                ek3.as_ref(),
                ek4.as_ref(),
            );
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, x_c, &self.s, &self.es, ka, eka);
        } else {
            self.s = *s;
            self.es = *es;
            self.k[3] = *k1;
        }
        let (mut f, mut x, mut spool) = ([0.0; N], [0.0; N], [0.0; N]);
        total_force(lp, &self.s, &mut f);
        for l in 0..N {
            x[l] = effect.stroke(motion(l, &self.s), &self.es).0;
            spool[l] = effect.spool_position(opening(l, 0, x_c[l]), &self.es);
        }
        let mut a = self.k[3][VEL];
        recorded(effect, &self.es, &mut a, &mut x, &mut f);
        obs.probe(&TickView {
            k: held.k,
            sub: held.sub,
            t: held.t,
            r: held.r,
            x: &x,
            a: &a,
            u: held.u,
            x_c,
            spool: &spool,
            f: &f,
            state: &self.s,
            responses: &|l, out| effect.responses(l, &self.es, out),
        });
    }
}

/// The channels as the data-acquisition system records them ([`Effect::sensed`]): the
/// acceleration, displacement and force of every lane, changed in place.
#[inline(always)]
fn recorded<const N: usize, E: Effect<N>>(
    effect: &E,
    es: &E::State,
    a: &mut [f64; N],
    x: &mut [f64; N],
    f: &mut [f64; N],
) {
    for l in 0..N {
        let raw = [a[l], x[l], f[l]];
        [a[l], x[l], f[l]] = effect.sensed(hook::Sensed { lane: l, raw }, es);
    }
}

/// What [`Effect::opening`] and [`Effect::spool_position`] are given: lane `lane`'s actuator
/// `act` at command `x`, m.
#[inline(always)]
fn opening(lane: usize, act: usize, x: f64) -> hook::Opening {
    hook::Opening { lane, act, x }
}

/// What [`Effect::stroke`] is given: the platen's motion in lane `lane` at state `s`.
#[inline(always)]
fn motion<const N: usize>(lane: usize, s: &[[f64; N]; NP]) -> hook::Motion {
    hook::Motion {
        lane,
        y: s[Y][lane],
        v: s[VEL][lane],
    }
}

#[inline(always)]
fn axpy<const N: usize>(
    live: usize,
    out: &mut [[f64; N]],
    base: &[[f64; N]],
    h: f64,
    k: &[[f64; N]],
) {
    for ((o, b), k) in out[..live].iter_mut().zip(&base[..live]).zip(&k[..live]) {
        for l in 0..N {
            o[l] = b[l] + h * k[l];
        }
    }
}

#[inline(always)]
fn rk4_combine<const N: usize>(
    live: usize,
    s: &mut [[f64; N]],
    h6: f64,
    k1: &[[f64; N]],
    k2: &[[f64; N]],
    k3: &[[f64; N]],
    k4: &[[f64; N]],
) {
    for j in 0..live {
        for l in 0..N {
            // 2·m as m + m (the same bits, on an adder rather than a multiplier).
            let m = k2[j][l] + k3[j][l];
            s[j][l] += h6 * (k1[j][l] + (m + m) + k4[j][l]);
        }
    }
}

/// The plant rows a step computes: with one equivalent actuator (A = 1) the second actuator's
/// rows are copies of the first's, which no right-hand side reads.
const fn plant_rows<const A: usize>() -> &'static [usize] {
    if A == 1 {
        &[P1[0], P2[0], Y, VEL, Z]
    } else {
        &[0, 1, 2, 3, 4, 5, 6]
    }
}

/// [`axpy`] over the [`plant_rows`].
#[inline(always)]
fn plant_axpy<const N: usize, const A: usize>(
    out: &mut [[f64; N]; NP],
    base: &[[f64; N]; NP],
    h: f64,
    k: &[[f64; N]; NP],
) {
    for &j in plant_rows::<A>() {
        axpy(1, &mut out[j..=j], &base[j..=j], h, &k[j..=j]);
    }
}

/// [`rk4_combine`] over the [`plant_rows`]; with A = 1 the second actuator's rows then copy the
/// first's (the same operations would give the same bits).
#[inline(always)]
fn plant_combine<const N: usize, const A: usize>(
    s: &mut [[f64; N]; NP],
    h6: f64,
    k: [&[[f64; N]; NP]; 4],
) {
    for &j in plant_rows::<A>() {
        let r = j..=j;
        rk4_combine(
            1,
            &mut s[r.clone()],
            h6,
            &k[0][r.clone()],
            &k[1][r.clone()],
            &k[2][r.clone()],
            &k[3][r],
        );
    }
    if A == 1 {
        s[P1[1]] = s[P1[0]];
        s[P2[1]] = s[P2[0]];
    }
}

fn initial_state<const N: usize>(lp: &LaneParams<N>) -> [[f64; N]; NP] {
    let mut s = [[0.0; N]; NP];
    for l in 0..N {
        for i in 0..N_ACT {
            s[P1[i]][l] = lp.p0[l].0;
            s[P2[i]][l] = lp.p0[l].1;
        }
    }
    s
}

/// What the controller reads at a tick, per lane: the reference, the stroke, the force and (for
/// a compensator) the chamber pressures, in the plant's state.
struct Feedback<'a, const N: usize> {
    /// The tick's time, s.
    t: f64,
    r: &'a [RefState; N],
    x: &'a [f64; N],
    f: &'a [f64; N],
    s: &'a [[f64; N]; NP],
}

impl<const N: usize> Feedback<'_, N> {
    /// Lane `l`'s chamber pressures (cap, rod) of each actuator, Pa.
    #[inline(always)]
    fn pressures(&self, l: usize) -> [(f64, f64); N_ACT] {
        std::array::from_fn(|i| (self.s[P1[i]][l], self.s[P2[i]][l]))
    }
}

/// The valve command `u` and the held spool command `x_c` of every lane at tick `k`: from the
/// controller in closed loop (the TVC's sum, the effects' compensators, the notches), else from
/// the open-loop drive (one branch per tick, not per lane).
#[inline(always)]
fn commands<const N: usize, E: Effect<N>>(
    lp: &LaneParams<N>,
    effect: &E,
    es: &mut E::State,
    drive: &Drive,
    k: usize,
    fed: &Feedback<'_, N>,
    mem: &mut [ControllerMemory; N],
) -> ([f64; N], [f64; N]) {
    let (mut u, mut x_c) = ([0.0; N], [0.0; N]);
    match drive {
        Drive::ClosedLoop => {
            for l in 0..N {
                let (c, m) = (&lp.ctrl[l], &mut mem[l]);
                let sum = controller::sum(c, m, &fed.r[l], fed.x[l], fed.f[l]);
                let r = &fed.r[l];
                let command = hook::Command {
                    lane: l,
                    u: sum,
                    p: fed.pressures(l),
                    t: fed.t,
                    r: [r.x, r.v, r.a, r.j],
                    x: fed.x[l],
                };
                let u_c = effect.command(command, es);
                u[l] = controller::shape(c, m, u_c);
                x_c[l] = lp.ctrl[l].k_sp * u[l];
            }
        }
        Drive::ValveCommand(cmd) => {
            for l in 0..N {
                u[l] = cmd[k].clamp(-lp.ctrl[l].u_lim, lp.ctrl[l].u_lim);
                x_c[l] = lp.ctrl[l].k_sp * u[l];
            }
        }
        Drive::Spool(measured) => {
            // A measured spool moves continuously; holding its sample at t_k over the tick would
            // delay it by half a tick (0.5/f_s). The held value is the mean of its linear
            // interpolant over [t_k, t_{k+1}] instead (a choice; error O((ωT)²)).
            let held = 0.5 * (measured[k] + measured[(k + 1).min(measured.len() - 1)]);
            for l in 0..N {
                x_c[l] = held;
                u[l] = x_c[l] / lp.ctrl[l].k_sp;
            }
        }
    }
    (u, x_c)
}

#[inline(always)]
fn total_force<const N: usize>(lp: &LaneParams<N>, s: &[[f64; N]; NP], f: &mut [f64; N]) {
    for l in 0..N {
        let act = lp.act.lane(l);
        f[l] = (0..N_ACT)
            .map(|i| actuator::force(&act, s[P1[i]][l], s[P2[i]][l]))
            .sum();
    }
}

/// The lanes that [`check_lane`] passes, found without branches (so the lanes are checked
/// together): finite, inside the stroke and every pressure in [−1 MPa, 2·P_S].
#[inline(always)]
fn healthy<const N: usize>(lp: &LaneParams<N>, s: &[[f64; N]; NP]) -> [bool; N] {
    let mut ok = [true; N];
    for l in 0..N {
        let mut good = s[Y][l].abs() < lp.act.l[l];
        for row in s {
            good &= row[l].is_finite();
        }
        let p_hi = 2.0 * lp.p_s[l];
        for i in 0..N_ACT {
            for j in [P1[i], P2[i]] {
                good &= (s[j][l] >= -1.0e6) & (s[j][l] <= p_hi);
            }
        }
        ok[l] = good;
    }
    ok
}

fn check_lane<const N: usize>(lp: &LaneParams<N>, s: &[[f64; N]; NP], l: usize) -> Option<Failure> {
    if (0..NP).any(|j| !s[j][l].is_finite()) {
        return Some(Failure::NonFinite);
    }
    if s[Y][l].abs() >= lp.act.l[l] {
        return Some(Failure::StrokeLimit { disp_m: s[Y][l] });
    }
    let p_hi = 2.0 * lp.p_s[l];
    for i in 0..N_ACT {
        for (chamber, j) in [(1, P1[i]), (2, P2[i])] {
            let p = s[j][l];
            if !(-1.0e6..=p_hi).contains(&p) {
                return Some(Failure::Pressure {
                    actuator: i,
                    chamber,
                    pa: p,
                });
            }
        }
    }
    None
}

#[inline(always)]
pub(crate) fn integrate<
    const N: usize,
    const A: usize,
    const SIMD: u8,
    Q: FlowLaw,
    D: Damping,
    E: Effect<N>,
    O: Observer<N> + ?Sized,
    P: Site,
>(
    lp: &LaneParams<N>,
    effect: &E,
    refs: &[&Reference; N],
    solver: &Solver,
    obs: &mut O,
) -> [LaneResult; N] {
    let mut s = initial_state(lp);
    let s_rest = s;
    let mut es = effect.initial_state();
    let es_rest = es;
    let mut f = [0.0; N];
    total_force(lp, &s, &mut f);
    let mut mem: [ControllerMemory; N] = std::array::from_fn(|l| ControllerMemory::new(f[l]));
    let mut status = [LaneStatus::Ok; N];
    let reference = refs[0];
    let mut acc = MetricsAcc::<N>::new(
        reference
            .spectrum
            .as_ref()
            .map(|(spec, _)| (spec, 1.0 / lp.f_s)),
    );
    let mut specimen = SpecimenAcc::<N>::default();

    let (mut k1, mut k2, mut k3, mut k4, mut tmp) = (
        [[0.0; N]; NP],
        [[0.0; N]; NP],
        [[0.0; N]; NP],
        [[0.0; N]; NP],
        [[0.0; N]; NP],
    );
    // The derivatives start at 0 ([`Effect::derivs`]: an effect whose states stand still need
    // not write them).
    let ez: E::State = bytemuck::Zeroable::zeroed();
    let (mut ek1, mut ek2, mut ek3, mut ek4, mut etmp) = (ez, ez, ez, ez, es);
    // The effects' states that move in this batch; the rest keep their values at t = 0.
    let live = effect.live_states();
    let mut a = [0.0; N];
    let mut x = [0.0; N];
    let h = 1.0 / (lp.f_s * solver.substeps as f64);
    // Dense output: the next requested probe time's slot.
    let mut next_probe = 0usize;
    let probe_slot = |obs: &O, i: usize| {
        obs.probe_times()
            .get(i)
            .map(|&t| slot(t, lp.f_s, solver.substeps))
    };
    let mut pending = probe_slot(obs, 0);
    let mut probe = Probe::<N, E>::new(es);
    let (w0, w1) = reference.window;
    let fundamental = reference.fundamental_hz;

    let (mut a_r, mut v_r, mut x_r, mut v) = ([0.0; N], [0.0; N], [0.0; N], [0.0; N]);
    for k in 0..reference.len() {
        let t = reference.time(k);
        let rl: [RefState; N] = std::array::from_fn(|l| RefState {
            x: refs[l].x[k],
            v: refs[l].v[k],
            a: refs[l].a[k],
            j: refs[l].j[k],
        });
        // Observers (single-lane histories) see lane 0's reference.
        let r = rl[0];
        total_force(lp, &s, &mut f);
        for l in 0..N {
            // The displacement feedback (LVDT) reads the actuator stroke.
            x[l] = effect.stroke(motion(l, &s), &es).0;
        }
        let fed = Feedback {
            t,
            r: &rl,
            x: &x,
            f: &f,
            s: &s,
        };
        let (u, x_c) = commands(lp, effect, &mut es, &reference.drive, k, &fed, &mut mem);
        rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, &x_c, &s, &es, &mut k1, &mut ek1);
        a.copy_from_slice(&k1[VEL]);
        let spool = effect.spool_positions(0, &x_c, &es);
        // Observers and the metrics see the channels as recorded (a measurement chain changes
        // them); the controller, the plant's.
        let (mut a_rec, mut x_rec, mut f_rec) = (a, x, f);
        recorded(effect, &es, &mut a_rec, &mut x_rec, &mut f_rec);
        obs.tick(&TickView {
            k,
            sub: 0,
            t,
            r: &r,
            x: &x_rec,
            a: &a_rec,
            u: &u,
            x_c: &x_c,
            spool: &spool,
            f: &f_rec,
            state: &s,
            responses: &|l, out| effect.responses(l, &es, out),
        });
        acc.every_tick(&u);
        effect.watch(&es, &mut specimen);
        if (w0..w1).contains(&k) {
            let basis = fundamental.map(|f0| Basis::at(k, lp.f_s, f0));
            for l in 0..N {
                (a_r[l], v_r[l], x_r[l], v[l]) = (rl[l].a, rl[l].v, rl[l].x, s[VEL][l]);
            }
            acc.window_tick(
                basis.as_ref(),
                &WindowTick {
                    a_r: &a_r,
                    v_r: &v_r,
                    x_r: &x_r,
                    a: &a_rec,
                    v: &v,
                    x: &x_rec,
                },
            );
        }

        for sub in 0..solver.substeps {
            if sub > 0 {
                rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, &x_c, &s, &es, &mut k1, &mut ek1);
            }
            // Probes in [t_k + sub·h, t_k + (sub + 1)·h): a partial step from this node.
            while let Some((tk, pos)) = pending {
                if tk != k || pos >= (sub + 1) as f64 {
                    break;
                }
                let delta = (pos - sub as f64) * h;
                probe.probe::<A, SIMD, Q, D, O, P>(
                    lp,
                    effect,
                    &x_c,
                    &s,
                    &es,
                    &k1,
                    &ek1,
                    delta,
                    &Held {
                        k,
                        sub,
                        t: t + pos * h,
                        r: &r,
                        u: &u,
                    },
                    obs,
                );
                next_probe += 1;
                pending = probe_slot(obs, next_probe);
            }
            plant_axpy::<N, A>(&mut tmp, &s, 0.5 * h, &k1);
            axpy(live, etmp.as_mut(), es.as_ref(), 0.5 * h, ek1.as_ref());
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, &x_c, &tmp, &etmp, &mut k2, &mut ek2);
            plant_axpy::<N, A>(&mut tmp, &s, 0.5 * h, &k2);
            axpy(live, etmp.as_mut(), es.as_ref(), 0.5 * h, ek2.as_ref());
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, &x_c, &tmp, &etmp, &mut k3, &mut ek3);
            plant_axpy::<N, A>(&mut tmp, &s, h, &k3);
            axpy(live, etmp.as_mut(), es.as_ref(), h, ek3.as_ref());
            rhs::<N, A, SIMD, Q, D, E, P>(lp, effect, &x_c, &tmp, &etmp, &mut k4, &mut ek4);
            plant_combine::<N, A>(&mut s, h / 6.0, [&k1, &k2, &k3, &k4]);
            rk4_combine(
                live,
                es.as_mut(),
                h / 6.0,
                ek1.as_ref(),
                ek2.as_ref(),
                ek3.as_ref(),
                ek4.as_ref(),
            );
        }

        // Guard (docs/model.md §3), once per tick: every lane at once, the reason where one fails.
        let mut alive = 0;
        let healthy = healthy(lp, &s);
        for l in 0..N {
            if status[l] != LaneStatus::Ok {
                continue;
            }
            if healthy[l] {
                alive += 1;
                continue;
            }
            if let Some(reason) = check_lane(lp, &s, l) {
                status[l] = LaneStatus::Failed {
                    time_s: reference.time(k + 1),
                    reason,
                };
                for j in 0..NP {
                    s[j][l] = s_rest[j][l];
                }
                for (d, r) in es.as_mut().iter_mut().zip(es_rest.as_ref()) {
                    d[l] = r[l];
                }
                mem[l] = ControllerMemory::new(0.0);
            } else {
                alive += 1;
            }
        }
        if alive == 0 {
            break;
        }
    }

    std::array::from_fn(|l| match status[l] {
        LaneStatus::Ok => LaneResult {
            status: status[l],
            metrics: acc
                .finish(
                    l,
                    fundamental.map(|f0| Metrics::highest_harmonic(f0, lp.f_s)),
                    refs[l]
                        .spectrum
                        .as_ref()
                        .map(|(spec, psa)| (spec, psa.as_slice())),
                )
                .with_specimen(specimen.lane(l)),
        },
        failed => LaneResult {
            status: failed,
            metrics: Metrics::NAN,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::{Baseline, LibraryEffect, ModelView};
    use crate::excitation::Sine;

    /// The lanes [`healthy`] passes are those [`check_lane`] finds no failure in: a lane at
    /// rest, a chamber above 2·P_S, one below −1 MPa, a state not finite.
    #[test]
    fn healthy_lanes_are_those_without_a_failure() {
        let m = ModelParams::default();
        let lp = LaneParams::<4>::new(&[&m]).unwrap();
        let mut s = initial_state(&lp);
        s[P1[0]][1] = 2.5 * m.servovalve.p_s;
        s[P2[1]][2] = -2.0e6;
        s[Z][3] = f64::NAN;
        assert_eq!(healthy(&lp, &s), [true, false, false, false]);
        let checked: Vec<bool> = (0..4).map(|l| check_lane(&lp, &s, l).is_none()).collect();
        assert_eq!(checked, [true, false, false, false]);
    }

    /// A build for one law pair, on every instruction set this CPU has: the lanes' results.
    fn each_isa<const N: usize, Q: FlowLaw, D: Damping, E: Effect<N>>(
        lp: &LaneParams<N>,
        effect: &E,
        r: &Reference,
    ) -> Vec<[LaneResult; N]> {
        let (refs, solver, obs) = (&[r; N], &Solver::default(), &mut NoObserver);
        let mut out = vec![here::Here::portable::<N, 1, Q, D, E, _>(
            lp, effect, refs, solver, obs,
        )];
        #[cfg(target_arch = "x86_64")]
        if Isa::detected() >= Isa::Avx2 {
            // SAFETY: the CPU reports AVX2 and FMA.
            out.push(unsafe {
                here::Here::avx2::<N, 1, Q, D, E, _>(lp, effect, refs, solver, obs)
            });
        }
        #[cfg(target_arch = "x86_64")]
        if E::BARE && Isa::detected() >= Isa::Avx512 {
            // SAFETY: the CPU reports AVX-512.
            out.push(unsafe {
                here::Here::avx512::<N, 1, Q, D, E, _>(lp, effect, refs, solver, obs)
            });
        }
        out
    }

    /// An effect as it is, declared hydraulic: the kernel then takes the general right-hand side.
    struct Hydraulic<'a, E>(&'a E);

    impl<const N: usize, E: Effect<N>> Effect<N> for Hydraulic<'_, E> {
        type State = E::State;
        const MOVES_SPOOL: bool = E::MOVES_SPOOL;
        const SPLITS: bool = E::SPLITS;
        fn initial_state(&self) -> Self::State {
            self.0.initial_state()
        }
        fn live_states(&self) -> usize {
            self.0.live_states()
        }
        fn symmetric(&self) -> bool {
            self.0.symmetric()
        }
        fn supply(&self, c: hook::Supply, s: &Self::State) -> f64 {
            self.0.supply(c, s)
        }
        fn opening(&self, c: hook::Opening, s: &Self::State) -> f64 {
            self.0.opening(c, s)
        }
        fn spool_position(&self, c: hook::Opening, s: &Self::State) -> f64 {
            self.0.spool_position(c, s)
        }
        fn stroke(&self, c: hook::Motion, s: &Self::State) -> (f64, f64) {
            self.0.stroke(c, s)
        }
        fn chamber_stiffness(&self, c: hook::Chambers, s: &Self::State) -> (f64, f64) {
            self.0.chamber_stiffness(c, s)
        }
        fn flows(&self, c: hook::Flows, s: &Self::State) -> (f64, f64) {
            self.0.flows(c, s)
        }
        fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
            self.0.extra_force(c, s)
        }
        fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
            self.0.derivs(plant, s, ds)
        }
        fn sensed(&self, c: hook::Sensed, s: &Self::State) -> [f64; 3] {
            self.0.sensed(c, s)
        }
        fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
            self.0.command(c, s)
        }
        fn watch(&self, s: &Self::State, acc: &mut crate::metrics::SpecimenAcc<N>) {
            self.0.watch(s, acc)
        }
        fn responses(&self, l: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
            self.0.responses(l, s, out)
        }
    }

    /// Every library effect that leaves the hydraulics alone, run through the bare plant's vector
    /// path and through the general right-hand side ([`Hydraulic`]), 16 lanes (the wide batches)
    /// and 8, on every instruction set this CPU has a build for: the same bits.
    struct VectorPathEqualsGeneral<'a, const N: usize> {
        lp: &'a LaneParams<N>,
        r: &'a Reference,
        compared: &'a mut Vec<crate::effects::EffectId>,
        id: crate::effects::EffectId,
    }

    impl<const N: usize> crate::effects::EffectFn<N> for VectorPathEqualsGeneral<'_, N> {
        type Output = ();
        fn call<E: Effect<N>>(self, effect: &E) {
            if E::HYDRAULIC {
                return;
            }
            assert!(!effect.hydraulic(), "{}", self.id);
            let (lp, r) = (self.lp, self.r);
            let fast = each_isa::<N, Orifice, SqrtDamping, _>(lp, effect, r);
            let general = each_isa::<N, Orifice, SqrtDamping, _>(lp, &Hydraulic(effect), r);
            let mut compared = 0;
            for (a, b) in fast.iter().flatten().zip(general.iter().flatten()) {
                assert_eq!(a.status, LaneStatus::Ok, "{}", self.id);
                assert_eq!(a.status, b.status, "{}", self.id);
                for ((name, x), (_, y)) in a.metrics.columns().into_iter().zip(b.metrics.columns())
                {
                    assert_eq!(x.to_bits(), y.to_bits(), "{} lanes {N}: {name}", self.id);
                    compared += 1;
                }
            }
            assert!(compared >= 2 * N * 10, "{}: {compared} compared", self.id);
            self.compared.push(self.id);
        }
    }

    #[test]
    fn effects_that_leave_the_hydraulics_alone_give_the_same_bits_in_the_vector_path() {
        use crate::effects::{with_single, EffectId};
        let r = Sine {
            freq_hz: 3.0,
            amp_m: Sine::amp_from_g(1.2, 3.0),
            taper_s: 0.5,
            duration_s: 1.5,
            window_cycles: Some(2),
        }
        .reference(1024.0);
        let mut compared = Vec::new();
        for id in EffectId::ALL {
            // The effect on in three lanes of four, the plant different in each lane.
            let sets: Vec<ModelParams> = (0..16)
                .map(|i| {
                    let mut p = ModelParams::default();
                    p.controller.g_d = 0.9 + 0.05 * i as f64;
                    *p.effects.get_mut(id) = i % 4 != 3;
                    p
                })
                .collect();
            let refs: Vec<&ModelParams> = sets.iter().collect();
            let lanes16: [&ModelParams; 16] = std::array::from_fn(|l| refs[l]);
            let lp16 = LaneParams::<16>::new(&refs).unwrap();
            let (mut c16, mut c8) = (Vec::new(), Vec::new());
            let f = VectorPathEqualsGeneral {
                lp: &lp16,
                r: &r,
                compared: &mut c16,
                id,
            };
            with_single(id, lanes16, f);
            let lanes8: [&ModelParams; 8] = std::array::from_fn(|l| refs[l]);
            let lp8 = LaneParams::<8>::new(&refs[..8]).unwrap();
            let f = VectorPathEqualsGeneral {
                lp: &lp8,
                r: &r,
                compared: &mut c8,
                id,
            };
            with_single(id, lanes8, f);
            assert_eq!(c16, c8);
            compared.extend(c16);
        }
        // A specimen, a building, the three sensors, the hold-down and the seal friction.
        assert_eq!(compared.len(), 7, "{compared:?}");
    }

    /// An effect that leaves the hydraulics alone and copies into its derivatives every field of
    /// the plant's view; its force on the platen is its first state.
    struct ViewProbe;

    impl<const N: usize> Effect<N> for ViewProbe {
        type State = [[f64; N]; 12];
        const HYDRAULIC: bool = false;
        fn initial_state(&self) -> Self::State {
            [[0.0; N]; 12]
        }
        fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
            s[0][c.lane]
        }
        fn derivs(&self, v: &PlantView<'_, N>, _s: &Self::State, ds: &mut Self::State) {
            *ds = [
                *v.x_c,
                v.opening[0],
                v.opening[1],
                *v.q_supply,
                v.q_in1[0],
                v.q_in1[1],
                v.q_out2[0],
                v.q_out2[1],
                *v.p_s,
                *v.f_act,
                *v.accel,
                *v.stroke,
            ];
        }
    }

    /// The vector path's right-hand side gives the general one's derivatives and the same view of
    /// the plant to the effect (flows both ways, supply flow, force, acceleration, stroke), bit
    /// for bit, at states on both sides of a closed valve.
    #[test]
    fn the_vector_path_gives_the_effects_the_general_view_of_the_plant() {
        let sets: Vec<ModelParams> = (0..8)
            .map(|i| {
                let mut p = ModelParams::default();
                p.servovalve.p_s *= 1.0 + 0.01 * i as f64;
                p
            })
            .collect();
        let refs: Vec<&ModelParams> = sets.iter().collect();
        let lp = LaneParams::<8>::new(&refs).unwrap();
        let mut s = initial_state(&lp);
        let p_s = lp.p_s[0];
        for l in 0..8 {
            let t = l as f64 - 3.5;
            s[P1[0]][l] = p_s * (0.5 + 0.05 * t);
            s[P2[0]][l] = p_s * (0.45 - 0.04 * t);
            s[P1[1]][l] = s[P1[0]][l];
            s[P2[1]][l] = s[P2[0]][l];
            s[Y][l] = 0.01 * t;
            s[VEL][l] = -0.2 * t;
            s[Z][l] = 0.3 * t.signum();
        }
        let x_c: [f64; 8] = std::array::from_fn(|l| 2e-4 * (l as f64 - 3.5) * (l % 3) as f64);
        let mut es = [[0.0; 8]; 12];
        es[0] = std::array::from_fn(|l| 1e4 * (l as f64 - 2.0));
        let run = |hydraulic: bool| {
            let (mut ds, mut des) = ([[0.0; 8]; NP], [[0.0; 8]; 12]);
            let probe = &ViewProbe;
            if hydraulic {
                let e = &Hydraulic(probe);
                rhs_general::<8, 1, PORTABLE, Orifice, SqrtDamping, _>(
                    &lp, e, &x_c, &s, &es, &mut ds, &mut des,
                );
            } else {
                rhs_general::<8, 1, PORTABLE, Orifice, SqrtDamping, _>(
                    &lp, probe, &x_c, &s, &es, &mut ds, &mut des,
                );
            }
            (ds, des)
        };
        let (general, vector) = (run(true), run(false));
        let bits =
            |a: &[[f64; 8]]| -> Vec<u64> { a.iter().flatten().map(|x| x.to_bits()).collect() };
        assert_eq!(bits(&general.0), bits(&vector.0), "the plant's derivatives");
        for (k, (a, b)) in general.1.iter().zip(&vector.1).enumerate() {
            assert_eq!(bits(&[*a]), bits(&[*b]), "the view's field {k}");
        }
        // The view is not empty: flows both ways, a force, an acceleration.
        let mut open = (0..8).filter(|&l| x_c[l] != 0.0);
        assert!(open.clone().count() >= 4 && open.clone().any(|l| x_c[l] < 0.0));
        assert!(open.all(|l| general.1[3][l] != 0.0) && general.1[9][0] != 0.0);
    }

    /// An effect that declares it leaves the hydraulics alone passes every hydraulic hook's input
    /// through, whatever its states, and keeps the actuators identical.
    struct HooksAreIdentities {
        id: crate::effects::EffectId,
        checked: usize,
    }

    impl crate::effects::EffectFn<4> for &mut HooksAreIdentities {
        type Output = ();
        fn call<E: Effect<4>>(self, effect: &E) {
            if E::HYDRAULIC {
                return;
            }
            let id = self.id;
            assert!(effect.symmetric(), "{id}");
            let mut s = effect.initial_state();
            for (k, row) in s.as_mut().iter_mut().enumerate() {
                *row = std::array::from_fn(|l| 1e-3 * (k as f64 + 1.0) * (l as f64 - 1.5));
            }
            for lane in 0..4 {
                for (x, y, v, p1, p2) in [
                    (3e-4, 0.02, 0.3, 9e6, 12e6),
                    (-1e-4, -0.1, -0.7, 2e5, 2.5e7),
                ] {
                    let p_s = 2.07e7;
                    assert_eq!(effect.supply(hook::Supply { lane, p_s }, &s), p_s, "{id}");
                    assert_eq!(
                        effect.stroke(hook::Motion { lane, y, v }, &s),
                        (y, v),
                        "{id}"
                    );
                    for act in 0..N_ACT {
                        let o = hook::Opening { lane, act, x };
                        assert_eq!(effect.opening(o, &s), x, "{id}");
                        let b = (4e12, 5e12);
                        let c = hook::Chambers {
                            lane,
                            act,
                            b,
                            p1,
                            p2,
                        };
                        assert_eq!(effect.chamber_stiffness(c, &s), b, "{id}");
                        let q = (0.01, -0.02);
                        let c = hook::Flows {
                            lane,
                            act,
                            q,
                            p1,
                            p2,
                            p_s,
                        };
                        assert_eq!(effect.flows(c, &s), q, "{id}");
                        self.checked += 1;
                    }
                }
            }
        }
    }

    #[test]
    fn an_effect_that_leaves_the_hydraulics_alone_passes_their_hooks_through() {
        use crate::effects::{with_single, EffectId};
        let mut checked = Vec::new();
        for id in EffectId::ALL {
            let mut p = ModelParams::default();
            *p.effects.get_mut(id) = true;
            let mut f = HooksAreIdentities { id, checked: 0 };
            with_single(id, [&p; 4], &mut f);
            if f.checked > 0 {
                checked.push(id);
            }
        }
        assert_eq!(checked.len(), 7, "{checked:?}");
    }

    /// The builds that read the law from the lanes (`EitherLaw`, `PowDamping`, which serve every
    /// configuration but the published one) give the bits of a build made for each law pair:
    /// the orifice and the linear valve, α = ½ and α ≠ ½ (some lanes, then all), bare (the bare
    /// plant's right-hand side) and with an effect (the general one), on every instruction set
    /// this CPU has a build for.
    #[test]
    fn the_build_for_every_law_equals_a_build_for_each_law() {
        let r = Sine {
            freq_hz: 3.0,
            amp_m: Sine::amp_from_g(1.5, 3.0),
            taper_s: 0.5,
            duration_s: 1.5,
            window_cycles: Some(2),
        }
        .reference(1024.0);
        for (law, alphas) in [
            (ValveLaw::Orifice, [0.5; 8]),
            (ValveLaw::Orifice, [0.5, 0.7, 0.5, 0.3, 0.5, 0.5, 0.9, 0.5]),
            (ValveLaw::Linear, [0.5; 8]),
            (ValveLaw::Linear, [0.6; 8]),
        ] {
            let sets: Vec<ModelParams> = (0..8)
                .map(|i| {
                    let mut p = ModelParams {
                        valve_law: law,
                        ..ModelParams::default()
                    };
                    p.platen.alpha = alphas[i];
                    p.controller.g_d = 0.9 + 0.2 * i as f64;
                    *p.effects.get_mut(crate::effects::EffectId::Supply) = i % 2 == 0;
                    p
                })
                .collect();
            let refs: Vec<&ModelParams> = sets.iter().collect();
            let lp = LaneParams::<8>::new(&refs).unwrap();
            // One library effect (on in half the lanes) takes the general right-hand side.
            let lanes: [&dyn ModelView; 8] = std::array::from_fn(|l| refs[l] as &dyn ModelView);
            let set = crate::effects::supply::Supply::<8>::new(lanes);
            let either = (
                each_isa::<8, EitherLaw, PowDamping, _>(&lp, &Baseline, &r),
                each_isa::<8, EitherLaw, PowDamping, _>(&lp, &set, &r),
            );
            let own = match (law, lp.alpha_half) {
                (ValveLaw::Orifice, true) => (
                    each_isa::<8, Orifice, SqrtDamping, _>(&lp, &Baseline, &r),
                    each_isa::<8, Orifice, SqrtDamping, _>(&lp, &set, &r),
                ),
                (ValveLaw::Orifice, false) => (
                    each_isa::<8, Orifice, PowDamping, _>(&lp, &Baseline, &r),
                    each_isa::<8, Orifice, PowDamping, _>(&lp, &set, &r),
                ),
                (ValveLaw::Linear, true) => (
                    each_isa::<8, Linear, SqrtDamping, _>(&lp, &Baseline, &r),
                    each_isa::<8, Linear, SqrtDamping, _>(&lp, &set, &r),
                ),
                (ValveLaw::Linear, false) => (
                    each_isa::<8, Linear, PowDamping, _>(&lp, &Baseline, &r),
                    each_isa::<8, Linear, PowDamping, _>(&lp, &set, &r),
                ),
            };
            let pairs = either
                .0
                .iter()
                .zip(&own.0)
                .chain(either.1.iter().zip(&own.1));
            let mut compared = 0;
            for (a, b) in pairs {
                for (l, (a, b)) in a.iter().zip(b).enumerate() {
                    assert_eq!(a.status, LaneStatus::Ok, "{law:?} {alphas:?} lane {l}");
                    assert_eq!(a.status, b.status);
                    for ((name, x), (_, y)) in
                        a.metrics.columns().into_iter().zip(b.metrics.columns())
                    {
                        assert_eq!(
                            x.to_bits(),
                            y.to_bits(),
                            "{law:?} {alphas:?} lane {l} {name}"
                        );
                        compared += 1;
                    }
                }
            }
            assert!(compared >= 2 * 8 * 10, "{compared} numbers compared");
        }
    }

    /// The equivalent actuator (A = 1) gives the two-actuator step's numbers bit for bit, on both
    /// instruction sets, with differing lanes and a lane that fails, bare and with effects.
    #[test]
    fn one_equivalent_actuator_equals_two_bit_for_bit() {
        let sets: Vec<ModelParams> = (0..8)
            .map(|i| {
                let mut p = ModelParams::default();
                p.controller.g_d = 0.9 + 0.2 * i as f64;
                p.servovalve.r2 = 0.7 + 0.03 * i as f64;
                if i == 7 {
                    p.actuator.l = 0.04; // the 5.5 cm amplitude reaches this stroke limit
                }
                p
            })
            .collect();
        let refs: Vec<&ModelParams> = sets.iter().collect();
        let lp = LaneParams::<8>::new(&refs).unwrap();
        let r = Sine {
            freq_hz: 3.0,
            amp_m: Sine::amp_from_g(2.0, 3.0),
            taper_s: 0.5,
            duration_s: 2.0,
            window_cycles: Some(3),
        }
        .reference(1024.0);
        let solver = Solver::default();
        // The same with effects that have states of their own per actuator (the spool's, the
        // delay's) or shared (the supply's), on in some lanes.
        let with_effects: Vec<ModelParams> = sets
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut p = p.clone();
                use crate::effects::EffectId;
                for (k, id) in [
                    EffectId::SpoolDynamics,
                    EffectId::TransportDelay,
                    EffectId::Supply,
                    EffectId::SealFriction,
                    EffectId::Leakage,
                ]
                .into_iter()
                .enumerate()
                {
                    *p.effects.get_mut(id) = (i + k) % 3 != 0;
                }
                p
            })
            .collect();
        let erefs: Vec<&ModelParams> = with_effects.iter().collect();
        let elp = LaneParams::<8>::new(&erefs).unwrap();
        let set = crate::effects::effect_set::<8>(&erefs);
        assert!(set.symmetric());
        for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .filter(|&i| i <= Isa::detected())
        {
            let one = dispatch::<8, 1, Orifice, SqrtDamping, _, NoObserver, here::Here>(
                isa,
                &elp,
                &set,
                &[&r; 8],
                &solver,
                &mut NoObserver,
            );
            let two = dispatch::<8, 2, Orifice, SqrtDamping, _, NoObserver, here::Here>(
                isa,
                &elp,
                &set,
                &[&r; 8],
                &solver,
                &mut NoObserver,
            );
            assert!(one.iter().any(|x| x.status == LaneStatus::Ok));
            for (l, (a, b)) in one.iter().zip(&two).enumerate() {
                assert_eq!(a.status, b.status, "effects, lane {l}");
                for ((name, x), (_, y)) in a.metrics.columns().into_iter().zip(b.metrics.columns())
                {
                    assert_eq!(
                        x.to_bits(),
                        y.to_bits(),
                        "effects, lane {l} {name}: {x} vs {y}"
                    );
                }
            }
        }
        for isa in [Isa::Portable, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .filter(|&i| i <= Isa::detected())
        {
            let one = dispatch::<8, 1, Orifice, SqrtDamping, Baseline, NoObserver, here::Here>(
                isa,
                &lp,
                &Baseline,
                &[&r; 8],
                &solver,
                &mut NoObserver,
            );
            let two = dispatch::<8, 2, Orifice, SqrtDamping, Baseline, NoObserver, here::Here>(
                isa,
                &lp,
                &Baseline,
                &[&r; 8],
                &solver,
                &mut NoObserver,
            );
            assert!(
                one.iter().any(|x| x.status == LaneStatus::Ok)
                    && one.iter().any(|x| x.status != LaneStatus::Ok),
                "wants ok and failed lanes: {:?}",
                one.map(|x| x.status)
            );
            for (l, (a, b)) in one.iter().zip(&two).enumerate() {
                assert_eq!(a.status, b.status, "lane {l}");
                for ((name, x), (_, y)) in a.metrics.columns().into_iter().zip(b.metrics.columns())
                {
                    assert_eq!(x.to_bits(), y.to_bits(), "lane {l} {name}: {x} vs {y}");
                }
            }
        }
    }
}
