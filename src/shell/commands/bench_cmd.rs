//! `study bench`: throughput of the kernel in simulated seconds per wall second, the scalar path
//! beside it, the limit set by the model's minimal operation count on this machine
//! ([`crate::shell::machine_rates`]), and a CI gate on ratios measured in the same run (never on absolute
//! times: machines differ).

use crate::kernel::builds;
use crate::kernel::excitation::{Reference, Sine};
use crate::kernel::ground::Processing;
use crate::kernel::params::ModelParams;
use crate::kernel::simulate::{Isa, LaneParams, NoObserver, Solver};
use crate::kernel::{EFFECT_LANES, LANES};
use crate::orchestration::runs::quake;
use crate::orchestration::runs::spec::{ExcitationSpec, Realisation};
use crate::shell::cli::BenchArgs;
use crate::shell::machine_rates::{self, Rates, MINIMAL, TICK_OPS, WINDOW_OPS};
use anyhow::{bail, Context};
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// RK4 stages per step.
const STAGES: f64 = 4.0;

fn reference() -> Reference {
    Sine {
        freq_hz: 3.0,
        amp_m: Sine::amp_from_g(1.73, 3.0),
        taper_s: 1.0,
        duration_s: 3.0,
        window_cycles: Some(4),
    }
    .reference(1024.0)
}

/// The record benchmark's motion: record_sweep.toml's first (firm ground, 0.5 g, 15 s between
/// 10 s pads: 35 s), with the default response spectrum accumulated online.
pub fn record_reference() -> anyhow::Result<Reference> {
    let exc = ExcitationSpec::Stochastic {
        duration_s: 15.0,
        realisation: Realisation::Fixed(0),
        seed: None,
        ground: vec![("pga_g", 0.5)],
        processing: Processing::default(),
        f_ref_hz: 50.0,
    };
    let r =
        quake::generated(&exc, &ModelParams::default(), 20261123, 0).map_err(anyhow::Error::msg)?;
    Ok(r.with_spectrum(crate::orchestration::runs::quake_spec::default_spectrum()))
}

/// Simulated seconds per wall second of `threads` workers each running batches of `r` for about
/// `secs` seconds: N = 1 a single run as `study sim` makes it, N = [`LANES`] a batch of the bare
/// plant as a design study runs it (the kernel's builds, [`builds`]).
fn throughput<const N: usize>(threads: usize, secs: f64, r: &Reference) -> anyhow::Result<f64> {
    const { assert!(N == 1 || N == LANES) };
    let p = ModelParams::default();
    let lp = LaneParams::<LANES>::new(&[&p])?;
    let solver = Solver::default();
    let run_once = || {
        if N == 1 {
            builds::run_lane(&p, r, &solver, &mut NoObserver).map(|x| x.metrics.rms_err_accel_ratio)
        } else {
            builds::run_bare_lanes(&lp, &[r; LANES], &solver)
                .map(|x| x[0].metrics.rms_err_accel_ratio)
        }
    };
    // Size the repetitions to the time budget with one run.
    let t = Instant::now();
    run_once()?;
    let per_run = t.elapsed().as_secs_f64().max(1e-6);
    let reps = ((secs / per_run) as usize).max(2);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let t = Instant::now();
    let done: Vec<f64> = pool.install(|| {
        (0..reps * threads)
            .into_par_iter()
            .map(|_| run_once().unwrap_or(f64::NAN))
            .collect()
    });
    let wall = t.elapsed().as_secs_f64();
    anyhow::ensure!(done.iter().all(|x| x.is_finite()), "benchmark run failed");
    Ok((reps * threads * N) as f64 * r.len() as f64 / r.f_s / wall)
}

/// The library's seal friction written as an expression, as a model file would
/// (`[model.expression] force = ...`), for the expression's cost against the compiled effect.
const FRICTION_EXPR: &str = "-tanh(v / v_eps) * (f_c + (f_s - f_c) * exp(-(v / v_s)^2))";

/// Seal friction at its defaults: compiled (the library's effect), and as [`FRICTION_EXPR`].
fn friction_models() -> anyhow::Result<[ModelParams; 2]> {
    use crate::kernel::effects::expression::Hook;
    use crate::kernel::params::Range;
    let mut compiled = ModelParams::default();
    compiled.effects.seal_friction = true;
    let q = compiled.effect_params.seal_friction.clone();
    anyhow::ensure!(q.sigma == 0.0, "the expression has no viscous term");
    let mut expr = ModelParams::default();
    expr.effects.expression = true;
    for (name, v) in [
        ("f_c", q.f_c),
        ("f_s", q.f_s),
        ("v_s", q.v_s),
        ("v_eps", q.v_eps),
    ] {
        (expr.name_expression_param(name, "-", Range::any(), v)).map_err(anyhow::Error::msg)?;
    }
    expr.expression.set(Hook::Force, FRICTION_EXPR)?;
    Ok([compiled, expr])
}

/// Sim-s per wall-s of a batch of [`EFFECT_LANES`] lanes of `model` (one effect on) on one
/// thread, through the kernel a study or a diagnosis runs for one effect.
fn effect_throughput(model: &ModelParams, secs: f64, r: &Reference) -> anyhow::Result<f64> {
    let id = model.effects.on().next().expect("one effect on");
    let solver = Solver::default();
    let run_once = || {
        let models = [model];
        let mut obs = NoObserver;
        match builds::run_single_effect(id, &models, r, &solver, &mut obs) {
            Some(x) => x,
            None => builds::run_effect_lanes(&models, &[r; EFFECT_LANES], &solver, &mut obs),
        }
        .map(|x| x[0].metrics.rms_err_accel_ratio)
    };
    let t = Instant::now();
    run_once()?;
    let reps = ((secs / t.elapsed().as_secs_f64().max(1e-6)) as usize).max(2);
    let t = Instant::now();
    for _ in 0..reps {
        anyhow::ensure!(run_once()?.is_finite(), "benchmark run failed");
    }
    let wall = t.elapsed().as_secs_f64();
    Ok((reps * EFFECT_LANES) as f64 * r.len() as f64 / r.f_s / wall)
}

/// Figures of one benchmark run.
#[derive(Debug, Clone, Copy)]
pub struct Figures {
    pub clock_hz: f64,
    pub scalar: f64,
    pub batch1: f64,
    pub batch2: f64,
    /// Batch throughput on the record benchmark's motion ([`record_reference`]), 1 and 2 threads.
    pub record1: f64,
    pub record2: f64,
    /// The model's limit on one thread (see [`machine_rates`]).
    pub limit: f64,
    pub rates: Rates,
    pub rhs_per_sim_s: f64,
    /// Seal friction on the sine, a batch of [`EFFECT_LANES`] on one thread: the library's
    /// compiled effect, and the same law as an expression ([`FRICTION_EXPR`]).
    pub friction: f64,
    pub friction_expr: f64,
}

impl Figures {
    pub(crate) fn batch_over_scalar(&self) -> f64 {
        self.batch1 / self.scalar
    }
    pub(crate) fn batch_over_limit(&self) -> f64 {
        self.batch1 / self.limit
    }
    /// Cycles per lane per right-hand-side evaluation (the tick's own work included).
    pub(crate) fn cycles_per_rhs(&self, sim_s_per_s: f64) -> f64 {
        self.clock_hz / (sim_s_per_s * self.rhs_per_sim_s)
    }
}

/// Measures every figure in interleaved rounds and keeps the best of each: interference from
/// other work on the machine only ever slows a measurement down, so the best of several short
/// interleaved measurements is what the code can do, and the ratios (measured side by side) stay
/// stable on a busy machine.
pub fn measure(secs: f64) -> anyhow::Result<Figures> {
    const ROUNDS: usize = 5;
    let budget = secs / (9.0 * ROUNDS as f64);
    let [friction, friction_expr] = friction_models()?;
    let r = reference();
    let quake = record_reference()?;
    let substeps = Solver::default().substeps as f64;
    let rhs_per_tick = substeps * STAGES;
    let window_share = (r.window.1 - r.window.0) as f64 / r.len() as f64;
    let mut f = Figures {
        clock_hz: 0.0,
        scalar: 0.0,
        batch1: 0.0,
        batch2: 0.0,
        record1: 0.0,
        record2: 0.0,
        limit: 0.0,
        rates: Rates {
            flops: 0.0,
            divs: 0.0,
            sqrts: 0.0,
        },
        rhs_per_sim_s: r.f_s * rhs_per_tick,
        friction: 0.0,
        friction_expr: 0.0,
    };
    let chain_iters = 50_000_000;
    for _ in 0..ROUNDS {
        // Clock: a dependent chain of 1-cycle operations, 2 per iteration.
        let t = Instant::now();
        std::hint::black_box(machine_rates::add_chain(
            std::hint::black_box(chain_iters),
            1,
        ));
        f.clock_hz = f
            .clock_hz
            .max(2.0 * chain_iters as f64 / t.elapsed().as_secs_f64());
        let m = machine_rates::rates(budget / 3.0);
        f.rates = Rates {
            flops: f.rates.flops.max(m.flops),
            divs: f.rates.divs.max(m.divs),
            sqrts: f.rates.sqrts.max(m.sqrts),
        };
        f.scalar = f.scalar.max(throughput::<1>(1, budget, &r)?);
        f.batch1 = f.batch1.max(throughput::<LANES>(1, budget, &r)?);
        f.batch2 = f.batch2.max(throughput::<LANES>(2, budget, &r)?);
        f.record1 = f.record1.max(throughput::<LANES>(1, budget, &quake)?);
        f.record2 = f.record2.max(throughput::<LANES>(2, budget, &quake)?);
        f.friction = f.friction.max(effect_throughput(&friction, budget, &r)?);
        f.friction_expr = (f.friction_expr).max(effect_throughput(&friction_expr, budget, &r)?);
    }
    f.limit = f.rates.limit(rhs_per_tick, window_share, r.f_s);
    Ok(f)
}

fn read_baseline(path: &std::path::Path) -> anyhow::Result<(f64, f64)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let t: toml::Table = text
        .parse()
        .with_context(|| format!("{} is not TOML", path.display()))?;
    let get = |k: &str| {
        t.get(k)
            .and_then(|v| v.as_float())
            .with_context(|| format!("{}: missing number `{k}`", path.display()))
    };
    Ok((get("batch_over_scalar")?, get("batch_over_limit")?))
}

/// Times a diagnosis of `campaign` with every candidate of the library (and the state map's
/// term, where it names one), as `study diagnose` runs it.
fn bench_diagnose(campaign: &std::path::Path, max_seconds: Option<f64>) -> anyhow::Result<()> {
    let model = crate::kernel::params::ModelParams::default();
    let mut loaded = crate::shell::fit_problem::load_problem(campaign, &model, false)?;
    // Every batch the diagnosis runs (one per test and group of lanes), counted as it finishes.
    let batches = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let counter = batches.clone();
    loaded.problem.progress = Some(std::sync::Arc::new(move |_| {
        counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }));
    let problem = &mut loaded.problem;
    let candidates: Vec<_> = crate::kernel::params::EffectId::ALL
        .into_iter()
        .filter(|&e| e.screened() || e == crate::kernel::params::EffectId::Expression)
        .collect();
    let simulated: f64 = problem
        .tests
        .iter()
        .map(|t| t.drive.len() as f64 / t.drive.f_s)
        .sum();
    let t0 = std::time::Instant::now();
    let d = crate::orchestration::diagnosis::diagnose::diagnose_campaign(
        problem,
        &candidates,
        &loaded.aligned,
    );
    let secs = t0.elapsed().as_secs_f64();
    let iterations: usize = d
        .candidates
        .iter()
        .filter_map(|c| c.fit.as_ref().ok())
        .map(|f| f.iterations)
        .sum();
    let per_test = batches.load(std::sync::atomic::Ordering::Relaxed) / problem.tests.len();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "study bench --diagnose {}: {} tests ({simulated:.1} s simulated per model), {} candidates, {} threads",
        campaign.display(),
        problem.tests.len(),
        candidates.len(),
        rayon::current_num_threads()
    )?;
    writeln!(out, "  wall time {secs:.1} s; {per_test} batches of {EFFECT_LANES} lanes per test, {iterations} of them the candidates' Levenberg-Marquardt iterations (each with its Jacobian); the rest their start scans and profiles, forward selection and the state maps' model runs")?;
    writeln!(out, "  verdict: {}", d.summary())?;
    if let Some(max) = max_seconds {
        writeln!(
            out,
            "  gate: {secs:.1} s against {max} s {}",
            if secs <= max { "ok" } else { "FAILED" }
        )?;
        if secs > max {
            return Err(crate::shell::RunFailed(format!(
                "the diagnosis took {secs:.1} s, more than {max} s"
            ))
            .into());
        }
    }
    Ok(())
}

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    crate::shell::job::outputs::check_outputs([args.write_baseline.as_ref()])?;
    let engine = match args.diagnose {
        Some(_) => crate::shell::gpu::uncovered(
            args.backend,
            "a diagnosis compares time histories (the CUDA kernel returns metrics only)",
        )?,
        None => crate::shell::gpu::choose(args.backend)?,
    };
    println!("study bench: backend {}", engine.describe());
    if let Some(c) = &args.diagnose {
        return bench_diagnose(c, args.max_seconds);
    }
    if let Some(cuda) = engine.cuda() {
        bench_cuda(&mut std::io::stdout().lock(), cuda)?;
    }
    let f = measure(args.seconds)?;
    let mut out = std::io::stdout().lock();
    print_sine(&mut out, &f)?;
    print_record(&mut out, &f)?;
    print_expression(&mut out, &f)?;
    if let Some(path) = &args.write_baseline {
        write_baseline(&mut out, path, &f)?;
    }
    if let Some(path) = &args.gate {
        gate(&mut out, path, &f)?;
    }
    Ok(())
}

/// The sine's figures: the clock, the scalar path, the batch on one and two threads, and the
/// limit with the operation count and rates it comes from.
fn print_sine(out: &mut dyn Write, f: &Figures) -> anyhow::Result<()> {
    let substeps = Solver::default().substeps;
    let h_us = 1e6 / (1024.0 * substeps as f64);
    writeln!(out, "study bench: 3 s sine at 1.73 g, RK4 h = {h_us:.1} µs ({substeps} substeps per 1024 Hz tick; converged: every metric within 1e-5 of the 32-substep answer), {} kernel", Isa::detected())?;
    writeln!(
        out,
        "  clock (dependent add chain)        {:>8.2} GHz",
        f.clock_hz / 1e9
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  {:>6.1} cycles per lane per RHS",
        "scalar path (1 lane, 1 thread)",
        f.scalar,
        f.cycles_per_rhs(f.scalar)
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  {:>6.1} cycles per lane per RHS",
        format!("batch ({LANES} lanes, 1 thread)"),
        f.batch1,
        f.cycles_per_rhs(f.batch1)
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  ({:.2}x one thread)",
        format!("batch ({LANES} lanes, 2 threads)"),
        f.batch2,
        f.batch2 / f.batch1
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  {:>6.1} cycles per lane per RHS",
        "limit (1 thread)",
        f.limit,
        f.cycles_per_rhs(f.limit)
    )?;
    writeln!(
        out,
        "    the model's minimal operation count per lane: {} mul/add, {} div, {} sqrt, {} (.)^-1/4 per RHS, {TICK_OPS} per tick (+{WINDOW_OPS} in the window);",
        MINIMAL.flops, MINIMAL.divs, MINIMAL.sqrts, MINIMAL.fourth_roots
    )?;
    writeln!(
        out,
        "    this thread's rates: {:.1} G mul/add, {:.2} G div, {:.2} G sqrt per s (lane-operations, best split of the (.)^-1/4 between the units)",
        f.rates.flops / 1e9,
        f.rates.divs / 1e9,
        f.rates.sqrts / 1e9
    )?;
    Ok(())
}

/// The record's figures (one and two threads) and the ratios the gate reads.
fn print_record(out: &mut dyn Write, f: &Figures) -> anyhow::Result<()> {
    let spectrum = crate::orchestration::runs::quake_spec::default_spectrum();
    writeln!(
        out,
        "  record: 35 s stochastic ground motion (record_sweep.toml's firm_0p5g; reference from the 4th-order filter), {}-period {:.0} %-damped spectrum online",
        spectrum.periods.len(),
        100.0 * spectrum.damping
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  {:>6.1} cycles per lane per RHS",
        format!("record batch ({LANES} lanes, 1 thread)"),
        f.record1,
        f.cycles_per_rhs(f.record1)
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  ({:.2}x one thread)",
        format!("record batch ({LANES} lanes, 2 threads)"),
        f.record2,
        f.record2 / f.record1
    )?;
    writeln!(
        out,
        "  ratios: batch/scalar {:.2}, batch/limit {:.2}, 2 threads/1 thread {:.2}",
        f.batch_over_scalar(),
        f.batch_over_limit(),
        f.batch2 / f.batch1
    )?;
    Ok(())
}

/// An effect compiled against the same law written as an expression.
fn print_expression(out: &mut dyn Write, f: &Figures) -> anyhow::Result<()> {
    writeln!(
        out,
        "  effect: seal friction on the sine, {EFFECT_LANES} lanes, 1 thread (the kernel a study runs for one effect)"
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s",
        "compiled (seal_friction)", f.friction
    )?;
    writeln!(
        out,
        "  {:<34} {:>8.0} sim-s/wall-s  ({:.2}x compiled; force = \"{FRICTION_EXPR}\")",
        "as an expression",
        f.friction_expr,
        f.friction_expr / f.friction
    )?;
    Ok(())
}

/// Writes the ratios measured to the baseline file `path`.
fn write_baseline(out: &mut dyn Write, path: &Path, f: &Figures) -> anyhow::Result<()> {
    let text = format!(
        "# Ratios measured by `study bench` (same run, same machine); the CI gate fails when one falls\n# more than 25 % below these.\nbatch_over_scalar = {:.3}\nbatch_over_limit = {:.3}\n",
        f.batch_over_scalar(),
        f.batch_over_limit()
    );
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
    writeln!(out, "  wrote baseline {}", path.display())?;
    Ok(())
}

/// Fails where a ratio fell more than 25 % below the baseline file `path`'s.
fn gate(out: &mut dyn Write, path: &Path, f: &Figures) -> anyhow::Result<()> {
    let (bs, bl) = read_baseline(path)?;
    let mut bad = Vec::new();
    for (name, got, base) in [
        ("batch/scalar", f.batch_over_scalar(), bs),
        ("batch/limit", f.batch_over_limit(), bl),
    ] {
        let floor = 0.75 * base;
        writeln!(
            out,
            "  gate {name}: {got:.3} against baseline {base:.3} (floor {floor:.3}) {}",
            if got >= floor { "ok" } else { "FAILED" }
        )?;
        if got < floor {
            bad.push(name);
        }
    }
    if !bad.is_empty() {
        bail!(
            "benchmark gate failed: {} fell more than 25 % below the baseline {}",
            bad.join(", "),
            path.display()
        );
    }
    Ok(())
}

/// Lanes of the GPU benchmark: the work unit of `benches/peers` at the size the figures
/// were taken (65 536 gain sets).
const GPU_LANES: usize = 1 << 16;

/// The GPU's figure on the peers' work unit (random gain sets of the gains sweep, a 3 s sine at
/// 3 Hz 1.73 g, 1 s taper, harmonics over the last 4 cycles, 8 RK4 substeps per tick), after a
/// warm-up run of the same size (a study's launches after its first find the kernel built, the
/// device's memory pool and a page-locked output buffer in place), with where the time went and
/// the largest difference from the CPU kernel on 256 of the lanes.
fn bench_cuda(out: &mut dyn Write, cuda: &crate::shell::gpu::Cuda) -> anyhow::Result<()> {
    use crate::orchestration::study::batch::LaneEngine;
    let reference = reference();
    let solver = Solver { substeps: 8 };
    let models = gain_sets(GPU_LANES);
    let refs: Vec<&ModelParams> = models.iter().collect();
    cuda.run(&refs, &[&reference], &solver)?
        .context("warm-up run")?;
    let t = Instant::now();
    let got = cuda
        .run(&refs, &[&reference], &solver)?
        .context("GPU batch")?;
    let secs = t.elapsed().as_secs_f64();
    let times = *cuda.last.lock().unwrap_or_else(|e| e.into_inner());
    let worst = worst_difference(&got, &refs[..256], &reference, &solver)?;
    writeln!(
        out,
        "  GPU: {GPU_LANES} gain sets × 3 s sine (3 Hz, 1.73 g), 8 substeps: {secs:.3} s, {:.0} \
         sim-s/wall-s (of it: set-up and packing {:.3} s, upload {:.3} s, kernel {:.3} s, \
         download {:.3} s, finishing {:.3} s); CPU kernel vs GPU on 256 sets: largest relative \
         difference {worst:.1e}",
        GPU_LANES as f64 * 3.0 / secs,
        times.setup,
        times.upload,
        times.kernel,
        times.download,
        times.finish,
    )?;
    Ok(())
}

/// The largest relative difference of any metric between the GPU's results `got` and the CPU
/// kernel on the first lanes, `sets`.
fn worst_difference(
    got: &[crate::kernel::simulate::LaneResult],
    sets: &[&ModelParams],
    reference: &Reference,
    solver: &Solver,
) -> anyhow::Result<f64> {
    let mut worst = 0.0f64;
    for (c, group) in sets.chunks(LANES).enumerate() {
        let lp = LaneParams::<LANES>::new(group)?;
        let want = builds::run_bare_lanes(&lp, &[reference; LANES], solver)?;
        for (l, w) in want.iter().enumerate().take(group.len()) {
            let g = got[c * LANES + l].metrics.columns();
            for ((_, a), (_, b)) in g.into_iter().zip(w.metrics.columns()) {
                if a.to_bits() != b.to_bits() {
                    worst = worst.max((a - b).abs() / a.abs().max(b.abs()).max(1e-300));
                }
            }
        }
    }
    Ok(worst)
}

/// `n` gain sets drawn uniformly over the gains sweep's ranges (a fixed seed).
fn gain_sets(n: usize) -> Vec<ModelParams> {
    use rand::{RngExt, SeedableRng};
    let mut rng = chacha20::ChaCha8Rng::seed_from_u64(7);
    (0..n)
        .map(|_| {
            let mut p = ModelParams::default();
            let c = &mut p.controller;
            c.g_d = rng.random_range(1.1..1.9);
            c.l_v = rng.random_range(0.29..0.47);
            c.l_a = rng.random_range(0.39..0.65);
            c.l_j = rng.random_range(0.0..0.01);
            c.g_f = rng.random_range(-1.9..-1.1);
            c.l_d = rng.random_range(0.0..0.1);
            p
        })
        .collect()
}
