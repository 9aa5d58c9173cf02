//! The CUDA lane kernel (`crates/kernel/src/cuda/lane.cu`) built for the host by a C++ compiler and
//! compared with the Rust kernel on random parameter sets of the baseline model and every library
//! effect, every drive and every kind of shared reference: every metric within 1e-12 relative,
//! the same failures.
//!
//! Where the tests were built without a C++ compiler (`$CXX`, else `c++`; build.rs), they are
//! `#[ignore]`d with the reason, so `cargo test` reports them as ignored, not passed; where one was
//! found, or `VSHAKE_REQUIRE_CXX` is set (CI), a compiler missing at run time fails them.

use chacha20::ChaCha8Rng as StdRng;
use rand::{RngExt, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use vshake::kernel::effects::EffectId;
use vshake::kernel::excitation::{Drive, Record, Reference, Signal, Sine};
use vshake::kernel::gpu_lanes::{self, Shared};
use vshake::kernel::ground::{Sweep, SweepLaw};
use vshake::kernel::params::{ModelParams, ValveLaw};
use vshake::kernel::simulate::SetupError;
use vshake::kernel::simulate::{Failure, LaneResult, LaneStatus, Solver};
use vshake::kernel::spectrum::SpectrumSpec;
use vshake::orchestration::runs::single::run_group;
use vshake::orchestration::study::batch::{LaneEngine, RowStatus};
use vshake::orchestration::study::problem::StudySpec;
use vshake::shell::job::study_job;

const LANES: usize = 8;

/// The harness built once (per test process) into the test's scratch folder, or why it cannot be.
fn harness() -> Result<PathBuf, String> {
    static BUILT: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    BUILT.get_or_init(build_harness).clone()
}

fn build_harness() -> Result<PathBuf, String> {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let exe = dir.join("cuda_host");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cuda_host.cpp");
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    // No contraction into FMA and no fast math: the Rust kernel rounds every operation.
    let out = Command::new(&cxx)
        .args(["-O2", "-std=c++14", "-ffp-contract=off", "-o"])
        .arg(&exe)
        .arg(&src)
        .output()
        .map_err(|e| format!("no C++ compiler `{cxx}` ({e})"))?;
    if !out.status.success() {
        panic!(
            "the kernel does not compile:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(exe)
}

/// The host build's results for `models` on `reference`.
fn host_run(
    exe: &Path,
    models: &[&ModelParams],
    refs: &[&Reference],
    solver: &Solver,
) -> Vec<LaneResult> {
    let shared = Shared::new(models, refs, solver).expect("valid run");
    let whole = gpu_lanes::pack_params(models).expect("uniform lanes");
    // As on the GPU: the fields every lane shares in the kernel's constant (`vs_u`), the records
    // of the varying ones alone in `params`.
    let uniform = gpu_lanes::Uniform::of(&whole, models.len());
    let mut params = uniform.compact(&whole, models.len());
    if params.is_empty() {
        params.push(0.0);
    }
    let mut bytes = Vec::new();
    let mut put = |v: &[u8]| bytes.extend_from_slice(v);
    for i in shared.ints {
        put(&i.to_le_bytes());
    }
    put(&shared.f_s.to_le_bytes());
    put(&(models.len() as i64).to_le_bytes());
    let arrays = [
        &shared.refs[0],
        &shared.refs[1],
        &shared.refs[2],
        &shared.refs[3],
        &shared.drive,
        &shared.basis,
        &shared.osc,
        &params,
    ];
    for a in arrays.into_iter().chain([&uniform.values]) {
        put(&(a.len() as i64).to_le_bytes());
        for x in a.iter() {
            put(&x.to_le_bytes());
        }
    }
    for word in uniform.vary {
        put(&word.to_le_bytes());
    }
    let dir = tempfile::tempdir().unwrap();
    let (inp, outp) = (dir.path().join("in"), dir.path().join("out"));
    std::fs::write(&inp, bytes).unwrap();
    let st = Command::new(exe).arg(&inp).arg(&outp).status().unwrap();
    assert!(st.success(), "the host kernel failed");
    let raw = std::fs::read(&outp).unwrap();
    let out: Vec<f64> = raw
        .chunks(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(
        out.len(),
        gpu_lanes::out_fields(shared.n_osc()) * models.len()
    );
    let finish = gpu_lanes::Finisher::new(refs[0], shared.n_osc());
    (0..models.len())
        .map(|l| finish.lane(&out, models.len(), l, refs[l.min(refs.len() - 1)]))
        .collect()
}

/// Switches on, at random, each effect the CUDA kernel has, with random parameters.
fn random_effects(rng: &mut StdRng, p: &mut ModelParams) {
    let mut u = |lo: f64, hi: f64| rng.random_range(lo..hi);
    let e = &mut p.effect_params;
    e.flow_saturation.x_sat = u(0.004, 0.02);
    (e.flow_gain.g0, e.flow_gain.g1, e.flow_gain.g2) = (u(0.3, 1.5), u(0.5, 1.5), u(0.7, 1.3));
    (e.flow_gain.g3, e.flow_gain.g4) = (u(0.8, 1.2), u(0.8, 1.2));
    (e.leakage.c_int, e.leakage.c_ext) = (u(0.0, 6e-11), u(0.0, 1e-11));
    (e.seal_friction.f_c, e.seal_friction.f_s) = (u(0.0, 2e4), u(2e4, 4e4));
    (e.seal_friction.sigma, e.seal_friction.v_s) = (u(0.0, 1e5), u(0.005, 0.05));
    e.compressibility.dead_volume = u(0.0, 0.05);
    (e.compressibility.beta_ratio, e.compressibility.air_fraction) = (u(0.5, 1.0), u(0.0, 0.03));
    (e.bulk_curve.b0, e.bulk_curve.b1, e.bulk_curve.b2) = (u(0.3, 1.0), u(0.6, 1.2), u(0.9, 1.1));
    e.hold_down.k3 = u(-5e8, 5e8);
    e.valve_compensator.g_min = u(0.1, 1.0);
    // The adaptive compensators: fast enough to act within the tests' 2.5 s, capped or not
    // (authority up to half the motion for APC, a tenth for each harmonic of AHC: more drives
    // most lanes out of their pressure band), frozen half-way or adapting to the end.
    for (top, (g, band, tau, authority, freeze)) in [0.5, 0.1].into_iter().zip([
        {
            let a = &mut e.amplitude_phase;
            (
                &mut a.gain,
                &mut a.band_hz,
                &mut a.delay_s,
                &mut a.authority,
                &mut a.freeze_s,
            )
        },
        {
            let a = &mut e.harmonic_cancellation;
            (
                &mut a.gain,
                &mut a.band_hz,
                &mut a.delay_s,
                &mut a.authority,
                &mut a.freeze_s,
            )
        },
    ]) {
        (*g, *band, *tau) = (u(0.5, 5.0), u(1.0, 10.0), u(0.0, 0.02));
        *authority = u(0.1 * top, top);
        *freeze = if u(0.0, 1.0) < 0.5 { 0.0 } else { u(0.5, 2.0) };
    }
    // Adaptive inverse control: its fit's memory, pole, anticipation and weighting anywhere in a
    // useful range, holding its taps or copying them as it learns, taps near the identity.
    let a = &mut e.adaptive_inverse;
    (a.memory_s, a.corner_hz) = (u(0.5, 30.0), u(0.5, 8.0));
    (a.anticipation_s, a.weight_hz) = (u(0.5, 8.0) / 1024.0, u(0.0, 10.0));
    a.copy_s = if u(0.0, 1.0) < 0.5 { 0.0 } else { u(1.0, 4.0) };
    a.freeze_s = if u(0.0, 1.0) < 0.5 { 0.0 } else { u(0.5, 2.0) };
    (a.w_0, a.w_1, a.w_2, a.w_5) = (u(0.8, 1.2), u(-0.05, 0.05), u(-0.05, 0.05), u(-0.05, 0.05));
    e.transport_delay.tau = u(0.5e-3, 3e-3);
    (e.spool_dynamics.freq_hz, e.spool_dynamics.zeta) = (u(60.0, 200.0), u(0.5, 1.0));
    (e.asymmetry.extend_gain, e.asymmetry.act2_gain) = (u(0.9, 1.1), u(0.9, 1.1));
    (e.supply.q_pump, e.supply.c_acc) = (u(0.05, 0.3), u(1e-8, 5e-8));
    e.supply.dp_band = u(3e5, 2e6);
    (e.reaction_mass.m_r, e.reaction_mass.f_r) = (u(5e5, 4e6), u(5.0, 30.0));
    e.reaction_mass.zeta_r = u(0.02, 0.3);
    let s = &mut e.specimen;
    (s.m1, s.f1, s.zeta1) = (u(5e3, 6e4), u(1.0, 12.0), u(0.01, 0.1));
    (s.m2, s.f2, s.zeta2) = (u(0.0, 2e4), u(5.0, 30.0), u(0.01, 0.1));
    (s.m3, s.f3, s.zeta3) = (u(0.0, 1e4), u(10.0, 50.0), u(0.01, 0.1));
    for c in [
        &mut e.accel_sensor.f_c,
        &mut e.disp_sensor.f_c,
        &mut e.force_sensor.f_c,
    ] {
        *c = u(20.0, 300.0);
    }
    // A delay of 0 (the Taylor branch of the chain) to 5 ms (its Padé branch).
    e.accel_sensor.delay = u(0.0, 5e-3);
    e.disp_sensor.delay = u(0.0, 5e-3);
    (e.force_sensor.delay, e.force_sensor.zeta) = (u(0.0, 5e-3), u(0.4, 1.0));
    // A building of 1-10 storeys, each law, storeys that differ, yielding under the tests.
    let b = &mut e.building;
    (b.storeys, b.law) = (u(1.0, 11.0).floor(), u(0.0, 3.0).floor());
    (b.alpha, b.zeta) = (u(0.0, 0.2), u(0.005, 0.05));
    (b.bw_beta, b.bw_gamma, b.bw_n) = (u(0.2, 0.8), u(0.2, 0.8), u(1.0, 4.0));
    for i in 1..=10 {
        for (name, lo, hi) in [("m", 5e3, 4e4), ("k", 5e6, 5e7), ("fy", 2e4, 3e5)] {
            let info = ModelParams::lookup(&format!("building.{name}{i}")).unwrap();
            info.set(p, u(lo, hi));
        }
    }
    for (id, _) in gpu_lanes::EFFECT_BITS {
        *p.effects.get_mut(id) = u(0.0, 1.0) < 0.3;
    }
}

/// A random parameter set of the baseline: gains, valve, actuator, platen, friction, notches.
fn random_model(rng: &mut StdRng, law: ValveLaw) -> ModelParams {
    let mut p = ModelParams::default();
    let mut u = |lo: f64, hi: f64| rng.random_range(lo..hi);
    let c = &mut p.controller;
    (c.g_d, c.l_d, c.l_v, c.l_a) = (u(1.1, 1.9), u(0.0, 0.1), u(0.29, 0.47), u(0.39, 0.65));
    (c.l_j, c.g_f) = (u(0.0, 0.01), u(-1.9, -1.1));
    (c.notch2_depth, c.notch4_f0) = (u(0.0, 20.0), u(60.0, 120.0));
    p.servovalve.r2 = u(0.6, 1.0);
    p.actuator.beta = u(400e6, 900e6);
    p.platen.m = u(100e3, 200e3);
    p.platen.alpha = if u(0.0, 1.0) < 0.5 { 0.5 } else { u(0.3, 1.2) };
    p.friction.kappa = u(0.0, 1.0);
    p.valve_law = law;
    p
}

fn sine(amp_g: f64, freq_hz: f64) -> Reference {
    Sine {
        freq_hz,
        amp_m: Sine::amp_from_g(amp_g, freq_hz),
        taper_s: 0.5,
        duration_s: 2.5,
        window_cycles: None,
    }
    .reference(1024.0)
}

/// A displacement record: a few decaying sines (a command, or the tracked reference).
fn record(signal: Signal) -> Record {
    let t: Vec<f64> = (0..1200).map(|i| i as f64 * 0.005).collect();
    let d = t
        .iter()
        .map(|&t| 0.02 * (-0.3 * t).exp() * ((7.0 * t).sin() + 0.4 * (23.0 * t).sin()) * (t / 6.0))
        .collect();
    Record {
        time_s: t,
        disp_m: d,
        f_ref_hz: 50.0,
        signal,
    }
}

/// Every kind of shared reference the kernel takes, by name.
fn references() -> Vec<(&'static str, Reference)> {
    let spectrum = SpectrumSpec::log_spaced(0.05, 2.0, 40, 0.05);
    let sweep = Sweep {
        f0_hz: 1.0,
        f1_hz: 12.0,
        duration_s: 3.0,
        taper_s: 0.5,
        law: SweepLaw::Log,
        amp_m: None,
        accel_mps2: 6.0,
    };
    let states: Vec<[f64; 4]> = (0..3072).map(|k| sweep.states(k as f64 / 1024.0)).collect();
    let mut sweep = Reference::from_states(1024.0, &states);
    sweep.window = (512, 3072);
    let mut valve = sine(0.8, 4.0);
    valve.drive = Drive::ValveCommand(
        (0..valve.len())
            .map(|k| 12.0 * (k as f64 * 0.02).sin())
            .collect(),
    );
    let mut spool = sine(0.8, 4.0);
    spool.drive = Drive::Spool(
        (0..spool.len())
            .map(|k| 1.5e-3 * (k as f64 * 0.03).sin())
            .collect(),
    );
    vec![
        ("sine 3 Hz 1.73 g", sine(1.73, 3.0)),
        ("sine 8 Hz 0.5 g", sine(0.5, 8.0)),
        ("sine 60 Hz (harmonics above Nyquist)", sine(0.3, 60.0)),
        (
            "log sweep with a spectrum",
            sweep.with_spectrum(spectrum.clone()),
        ),
        (
            "record (command) with a spectrum",
            record(Signal::Command)
                .reference(1024.0)
                .with_spectrum(spectrum),
        ),
        (
            "record (reference)",
            record(Signal::Reference).reference(1024.0),
        ),
        ("open loop, valve command", valve),
        ("open loop, spool", spool),
    ]
}

fn close(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

fn assert_same(what: &str, lane: usize, got: &LaneResult, want: &LaneResult) {
    match (got.status, want.status) {
        (LaneStatus::Ok, LaneStatus::Ok) => {}
        (
            LaneStatus::Failed {
                time_s: t1,
                reason: r1,
            },
            LaneStatus::Failed {
                time_s: t2,
                reason: r2,
            },
        ) => {
            assert_eq!(
                (t1, r1.category()),
                (t2, r2.category()),
                "{what}, lane {lane}"
            );
            assert!(
                close(r1.value().unwrap_or(0.0), r2.value().unwrap_or(0.0)),
                "{what}, lane {lane}: {r1} vs {r2}"
            );
            if let (
                Failure::Pressure {
                    actuator: a1,
                    chamber: c1,
                    ..
                },
                Failure::Pressure {
                    actuator: a2,
                    chamber: c2,
                    ..
                },
            ) = (r1, r2)
            {
                assert_eq!((a1, c1), (a2, c2), "{what}, lane {lane}: {r1} vs {r2}");
            }
        }
        (g, w) => panic!("{what}, lane {lane}: host kernel {g:?}, Rust kernel {w:?}"),
    }
    for ((name, g), (_, w)) in got
        .metrics
        .columns()
        .into_iter()
        .zip(want.metrics.columns())
    {
        assert!(
            close(g, w),
            "{what}, lane {lane}, {name}: host kernel {g:e}, Rust kernel {w:e}"
        );
    }
}

/// The harness; a test fails where there is none (build.rs found a compiler, or
/// `VSHAKE_REQUIRE_CXX` is set: the test was not built ignored).
fn harness_or_fail() -> PathBuf {
    harness().unwrap_or_else(|why| panic!("{why}: install g++ or set CXX, then rebuild the tests"))
}

#[test]
#[cfg_attr(
    vshake_no_cxx,
    ignore = "no C++ compiler ($CXX, else c++) when the tests were built: the CUDA kernel is not built for the host"
)]
fn the_cuda_kernel_built_for_the_host_gives_the_rust_kernels_metrics() {
    let exe = harness_or_fail();
    let mut rng = StdRng::seed_from_u64(28);
    let solver = Solver { substeps: 4 };
    let (mut ok, mut failed, mut identical, mut with_effects) = (0, 0, 0, 0);
    for law in [ValveLaw::Orifice, ValveLaw::Linear] {
        for (what, reference) in references() {
            let mut models: Vec<ModelParams> =
                (0..LANES).map(|_| random_model(&mut rng, law)).collect();
            // Half the batches with effects (the first lane without: an off lane in an effect set).
            if rng.random_range(0.0..1.0) < 0.5 {
                for m in &mut models[1..] {
                    random_effects(&mut rng, m);
                }
            }
            models[LANES - 1].actuator.l = 0.02; // a lane that reaches its stroke limit on most runs
            models[LANES - 2].servovalve.p_s *= 3.0; // and one whose pressure may leave its band
            let refs: Vec<&ModelParams> = models.iter().collect();
            let want = run_group(&refs, &[&reference], &solver).unwrap();
            let got = host_run(&exe, &refs, &[&reference], &solver);
            for l in 0..LANES {
                assert_same(&format!("{what}, {law:?} valve"), l, &got[l], &want[l]);
                match want[l].status {
                    LaneStatus::Ok => ok += 1,
                    _ => failed += 1,
                }
                identical += usize::from(got[l].metrics.bits() == want[l].metrics.bits());
                with_effects +=
                    usize::from(models[l].effects.any() && want[l].status == LaneStatus::Ok);
            }
        }
    }
    eprintln!(
        "{ok} lanes ran ({with_effects} with effects), {failed} failed, {identical} of them bit \
         for bit identical"
    );
    assert!(
        with_effects >= 20,
        "only {with_effects} lanes with effects ran to the end"
    );
    // Both outcomes are compared, and most lanes run to the end (their metrics compared).
    assert!(
        ok >= 2 * 8 * (LANES - 2) && failed >= 8,
        "{ok} ran, {failed} failed"
    );
}

/// Each library effect alone, in lanes 1.. of a batch (lane 0 without it), on a sine with its
/// harmonics and a record with its spectrum: the host kernel gives the Rust kernel's metrics, and
/// the effect changes them in every lane that has it (so the kernel does apply it); actuator 2's
/// own gain makes the kernel integrate both actuators.
#[test]
#[cfg_attr(
    vshake_no_cxx,
    ignore = "no C++ compiler ($CXX, else c++) when the tests were built: the CUDA kernel is not built for the host"
)]
fn each_effect_alone_gives_the_rust_kernels_metrics() {
    let exe = harness_or_fail();
    let mut rng = StdRng::seed_from_u64(29);
    let solver = Solver { substeps: 4 };
    let refs = references();
    for (id, _) in gpu_lanes::EFFECT_BITS {
        for (what, reference) in [&refs[1], &refs[4]] {
            let base: Vec<ModelParams> = (0..LANES)
                .map(|_| random_model(&mut rng, ValveLaw::Orifice))
                .collect();
            let mut models = base.clone();
            for m in &mut models[1..] {
                random_effects(&mut rng, m);
                m.effects = Default::default();
                *m.effects.get_mut(id) = true;
            }
            let run = |ms: &[ModelParams]| {
                let ms: Vec<&ModelParams> = ms.iter().collect();
                let want = run_group(&ms, &[reference], &solver).unwrap();
                (want, host_run(&exe, &ms, &[reference], &solver))
            };
            let (want, got) = run(&models);
            let (plain, _) = run(&base);
            let (mut changed, mut ran) = (0, 0);
            for l in 0..LANES {
                assert_same(&format!("{id} on {what}"), l, &got[l], &want[l]);
                changed += usize::from(
                    got[l].metrics.bits() != plain[l].metrics.bits()
                        || got[l].status != plain[l].status,
                );
                ran += usize::from(got[l].status == LaneStatus::Ok);
            }
            // Lane 0 is without the effect; most others run to the end. The force sensor changes
            // only the recorded force, which no metric reads.
            let moved = if id == EffectId::ForceSensor {
                0
            } else {
                LANES - 1
            };
            assert!(
                changed == moved && ran >= LANES / 2,
                "{id} on {what}: {changed} lanes changed, {ran} ran"
            );
        }
    }
}

#[test]
fn what_the_cuda_kernel_does_not_cover_is_named() {
    let mut p = ModelParams::default();
    let r = sine(1.0, 3.0);
    assert_eq!(gpu_lanes::unsupported(&[&p], &r), None);
    // Every library effect is covered, all of them at once included, but the expressions
    // (interpreted on the CPU), which are named.
    for id in EffectId::ALL
        .into_iter()
        .filter(|&e| e != EffectId::Expression)
    {
        *p.effects.get_mut(id) = true;
        assert_eq!(gpu_lanes::unsupported(&[&p], &r), None, "{id}");
    }
    *p.effects.get_mut(EffectId::Expression) = true;
    let why = gpu_lanes::unsupported(&[&p], &r).expect("the expressions run on the CPU");
    assert!(why.contains("the effect expression"), "{why}");
    let many = r.with_spectrum(SpectrumSpec::log_spaced(0.05, 4.0, 200, 0.05));
    let why = gpu_lanes::unsupported(&[&ModelParams::default()], &many).expect("too many periods");
    assert!(why.contains("200 periods"), "{why}");
}

/// The host build as the plan's lane engine: what `study run --backend cuda` does on a GPU, with
/// the launch replaced by the host harness.
struct HostEngine(PathBuf);

impl LaneEngine for HostEngine {
    fn run(
        &self,
        models: &[&ModelParams],
        refs: &[&Reference],
        solver: &Solver,
    ) -> anyhow::Result<Result<Vec<LaneResult>, SetupError>> {
        Ok(Ok(host_run(&self.0, models, refs, solver)))
    }
}

/// A study's rows on the CPU kernel and through the engine, for `samples` spread over its design:
/// the same status and every metric within 1e-12 (the GPU acceptance asks 1e-9).
fn same_rows_through_the_engine(study: &str, samples: usize) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(study);
    same_rows_of_text(&std::fs::read_to_string(&path).unwrap(), study, samples);
}

fn same_rows_of_text(text: &str, study: &str, samples: usize) {
    let exe = harness_or_fail();
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("studies")
        .join("x.toml");
    let spec = StudySpec::from_toml(text, study).unwrap();
    let mut plan = study_job::plan_for(&spec, path.parent().unwrap()).unwrap();
    let names: Vec<String> = spec.excitations.iter().map(|e| e.name.clone()).collect();
    assert_eq!(plan.engine_unsupported(&names), None, "{study} is covered");
    let step = (plan.samples() / samples).max(1);
    let ids: Vec<usize> = (0..plan.samples()).step_by(step).take(samples).collect();
    let cpu = plan.run_samples(ids.iter().copied()).unwrap();
    plan.engine = Some(Arc::new(HostEngine(exe)));
    let gpu = plan.run_samples(ids.iter().copied()).unwrap();
    assert_eq!(cpu.len(), gpu.len());
    let mut ok = 0;
    for (c, g) in cpu.iter().zip(&gpu) {
        assert_eq!((c.sample_id, c.excitation), (g.sample_id, g.excitation));
        assert_eq!(c.status, g.status, "{study}, sample {}", c.sample_id);
        ok += usize::from(c.status == RowStatus::Ok);
        for ((name, a), (_, b)) in c.metrics.columns().into_iter().zip(g.metrics.columns()) {
            assert!(
                close(a, b),
                "{study}, sample {}, {name}: CPU {a:e}, engine {b:e}",
                c.sample_id
            );
        }
    }
    assert!(
        ok * 2 > cpu.len(),
        "{study}: most rows run ({ok} of {})",
        cpu.len()
    );
}

#[test]
#[cfg_attr(
    vshake_no_cxx,
    ignore = "no C++ compiler ($CXX, else c++) when the tests were built: the CUDA kernel is not built for the host"
)]
fn the_gains_sweep_through_the_host_kernel_equals_the_cpu_backend() {
    same_rows_through_the_engine("studies/gains_sweep.toml", 48);
}

#[test]
#[cfg_attr(
    vshake_no_cxx,
    ignore = "no C++ compiler ($CXX, else c++) when the tests were built: the CUDA kernel is not built for the host"
)]
fn the_record_sweep_through_the_host_kernel_equals_the_cpu_backend() {
    same_rows_through_the_engine("studies/record_sweep.toml", 8);
}

/// A motion made per sample (its own realisation of the noise): each lane takes its own
/// reference, and its spectral error is against its own target.
#[test]
#[cfg_attr(
    vshake_no_cxx,
    ignore = "no C++ compiler ($CXX, else c++) when the tests were built: the CUDA kernel is not built for the host"
)]
fn motions_made_per_sample_through_the_host_kernel_equal_the_cpu_backend() {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/record_sweep.toml");
    let text = std::fs::read_to_string(file)
        .unwrap()
        .replace("realisation = 1", "realisation = \"per_sample\"");
    assert!(text.contains("per_sample"));
    same_rows_of_text(&text, "per_sample.toml", 6);
}

/// A device failure ends the run with its message (no rows are made up).
#[test]
fn a_device_failure_ends_the_run() {
    struct Broken;
    impl LaneEngine for Broken {
        fn run(
            &self,
            _: &[&ModelParams],
            _: &[&Reference],
            _: &Solver,
        ) -> anyhow::Result<Result<Vec<LaneResult>, SetupError>> {
            anyhow::bail!("the GPU (test) failed: an illegal address")
        }
    }
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/smoke.toml");
    let spec = StudySpec::from_toml(&std::fs::read_to_string(&path).unwrap(), "smoke").unwrap();
    let mut plan = study_job::plan_for(&spec, path.parent().unwrap()).unwrap();
    plan.engine = Some(Arc::new(Broken));
    let err = plan.run_samples(0..4).unwrap_err();
    assert!(err.to_string().contains("illegal address"), "{err}");
}
