//! Issue 52, the physics-based valve compensator (`valve_compensator`): at the paper's SP09 (3 Hz,
//! 3.20 g) and at 1.73 g on the published model, THD_odd with the compensator is ≥ 3× lower than
//! with the TVC alone, with no adaptation; and still lower at the 90th percentile over ±20 % of β,
//! M, the port widths and the supply pressure. Adaptive harmonic cancellation
//! (`harmonic_cancellation`): ≥ 5× lower once adapted (the adaptation time reported), lower at the
//! 90th percentile too. Amplitude/phase control (`amplitude_phase`): the fundamental's amplitude
//! ratio within 1 % and its phase within 1° on sines of 1–10 Hz.

mod common;
use common::{metrics_of, p90, uncertain_tables};
use vshake::kernel::effects::EffectId;
use vshake::kernel::excitation::{Reference, Sine};
use vshake::kernel::params::ModelParams;

/// THD_odd of each model, driven at 3 Hz and `amp_g` for 3 s; NaN where the run failed.
fn thd_odd(models: &[ModelParams], amp_g: f64) -> Vec<f64> {
    let reference = common::reference_sine(amp_g);
    metrics_of(models, &reference)
        .iter()
        .map(|m| m.thd_odd)
        .collect()
}

/// `m` with the compensator `id` on.
fn with(m: &ModelParams, id: EffectId) -> ModelParams {
    let mut m = m.clone();
    *m.effects.get_mut(id) = true;
    m
}

fn compensated(m: &ModelParams) -> ModelParams {
    with(m, EffectId::ValveCompensator)
}

#[test]
fn the_valve_compensator_lowers_thd_odd_three_times_with_no_adaptation() {
    let tvc = ModelParams::default();
    for amp_g in [1.73, 3.20] {
        let thd = thd_odd(&[tvc.clone(), compensated(&tvc)], amp_g);
        assert!(thd.iter().all(|x| x.is_finite()), "{thd:?}");
        let factor = thd[0] / thd[1];
        println!(
            "{amp_g} g: THD_odd {:.5} -> {:.5} ({factor:.1}x)",
            thd[0], thd[1]
        );
        assert!(thd[0].is_finite() && factor >= 3.0, "{amp_g} g: {:?}", thd);
    }
}

/// The 90th percentile of THD_odd over 40 tables drawn within ±20 % of β, M, the four port widths
/// (w3 and the ratios r1, r2, r4) and P_S: lower with the compensator, on the same tables
/// (measured: 0.077 → 0.026; the compensator's extra opening cavitates 2 tables more than the
/// TVC's 2 of 40, which the percentile counts as its worst).
#[test]
fn the_compensator_is_better_at_the_90th_percentile_of_an_uncertain_table() {
    let tables = uncertain_tables(52, 40);
    let with: Vec<ModelParams> = tables.iter().map(compensated).collect();
    let (a, b) = (thd_odd(&tables, 3.20), thd_odd(&with, 3.20));
    for (i, t) in tables.iter().enumerate() {
        println!(
            "{i:2} beta {:.3e} m {:.0} w3 {:.3} r {:.2} {:.2} {:.2} p_s {:.2e}: {:.5} -> {:.5}",
            t.actuator.beta,
            t.platen.m,
            t.servovalve.w3,
            t.servovalve.r1,
            t.servovalve.r2,
            t.servovalve.r4,
            t.servovalve.p_s,
            a[i],
            b[i]
        );
    }
    // A failed run (a chamber pressure below −1 MPa: the heaviest tables at the lowest supply
    // cavitate at 3.20 g, with the TVC alone too) counts as the worst THD.
    let failed = |v: &[f64]| v.iter().filter(|x| x.is_nan()).count();
    println!(
        "failed runs: TVC alone {}, compensated {}",
        failed(&a),
        failed(&b)
    );
    let (a, b) = (p90(&a), p90(&b));
    println!("3.20 g, 90th percentile of THD_odd over 40 tables: {a:.5} -> {b:.5}");
    assert!(b.is_finite() && b < a, "{a} {b}");
}

/// A sine at `freq_hz` and `amp_g` of `duration_s` (1 s taper), analysed over its last 4 cycles.
fn sine(freq_hz: f64, amp_g: f64, duration_s: f64) -> Reference {
    Sine {
        freq_hz,
        amp_m: Sine::amp_from_g(amp_g, freq_hz),
        taper_s: 1.0,
        duration_s,
        window_cycles: Some(4),
    }
    .reference(1024.0)
}

/// SP09's THD_odd over the last 4 cycles of runs of growing length, TVC alone and with AHC: the
/// distortion falls ≥ 5×, and the adaptation time is the shortest run whose last 4 cycles are
/// within 10 % of the longest's THD_odd.
#[test]
fn harmonic_cancellation_lowers_thd_odd_five_times_once_adapted() {
    let tvc = ModelParams::default();
    let both = [tvc.clone(), with(&tvc, EffectId::HarmonicCancellation)];
    let lengths = [2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0];
    let thd: Vec<[f64; 2]> = lengths
        .iter()
        .map(|&d| {
            let m = metrics_of(&both, &sine(3.0, 3.20, d));
            println!(
                "{d:4} s: THD_odd {:.5} -> {:.5} ({:.1}x)",
                m[0].thd_odd,
                m[1].thd_odd,
                m[0].thd_odd / m[1].thd_odd
            );
            [m[0].thd_odd, m[1].thd_odd]
        })
        .collect();
    let [alone, adapted] = *thd.last().unwrap();
    assert!(alone.is_finite() && adapted.is_finite(), "{thd:?}");
    let settled = lengths
        .iter()
        .zip(&thd)
        .find(|(_, t)| t[1] <= 1.1 * adapted)
        .unwrap();
    println!(
        "3.20 g at 3 Hz: THD_odd {alone:.5} -> {adapted:.5} ({:.1}x), adapted after {} s of the \
         run (1 s taper)",
        alone / adapted,
        settled.0
    );
    assert!(alone / adapted >= 5.0, "{thd:?}");
    // The TVC alone does not change with the run's length: the fall is the cancellation's.
    assert!((thd[0][0] / alone - 1.0).abs() < 0.05, "{thd:?}");
}

/// Not SP09 only: on sines of 1–10 Hz (0.5 g, and 0.1 g at 1 Hz where the TVC alone follows 60 %
/// of the motion), 10 s runs, AHC lowers THD_odd ≥ 5× (the band filter's 0.5 Hz keeps each
/// harmonic's canceller off its neighbours down to a 1 Hz fundamental).
#[test]
fn harmonic_cancellation_lowers_thd_odd_five_times_from_1_to_10_hz() {
    let tvc = ModelParams::default();
    let both = [tvc.clone(), with(&tvc, EffectId::HarmonicCancellation)];
    let mut worst = f64::INFINITY;
    for (f, amp_g) in [
        (1.0, 0.1),
        (1.0, 0.5),
        (2.0, 0.5),
        (5.0, 0.5),
        (7.0, 0.5),
        (10.0, 0.5),
    ] {
        let m = metrics_of(&both, &sine(f, amp_g, 10.0));
        let factor = m[0].thd_odd / m[1].thd_odd;
        println!(
            "{f:4} Hz, {amp_g} g: THD_odd {:.5} -> {:.3e} ({factor:.0}x)",
            m[0].thd_odd, m[1].thd_odd
        );
        assert!(factor.is_finite(), "{f} Hz: {m:?}");
        worst = worst.min(factor);
    }
    println!("AHC lowers THD_odd at least {worst:.1}x on 1-10 Hz");
    assert!(worst >= 5.0, "{worst}");
}

/// The 90th percentile of THD_odd over the 40 uncertain tables, adapted runs (8 s): lower with AHC.
#[test]
fn harmonic_cancellation_is_better_at_the_90th_percentile_of_an_uncertain_table() {
    let tables = uncertain_tables(52, 40);
    let cancelled: Vec<ModelParams> = tables
        .iter()
        .map(|m| with(m, EffectId::HarmonicCancellation))
        .collect();
    let reference = sine(3.0, 3.20, 8.0);
    let thd = |ms: &[ModelParams]| -> Vec<f64> {
        metrics_of(ms, &reference)
            .iter()
            .map(|m| m.thd_odd)
            .collect()
    };
    let (a, b) = (thd(&tables), thd(&cancelled));
    for i in 0..tables.len() {
        println!("{i:2}: {:.5} -> {:.5}", a[i], b[i]);
    }
    let (a, b) = (p90(&a), p90(&b));
    println!("3.20 g, 90th percentile of THD_odd over 40 tables, AHC: {a:.5} -> {b:.5}");
    assert!(b.is_finite() && b < a, "{a} {b}");
}

/// On sines of 1–10 Hz the fundamental's amplitude ratio and phase, TVC alone and with APC once
/// adapted: within 1 % and 1° with it.
#[test]
fn amplitude_phase_control_brings_the_fundamental_within_one_percent_and_one_degree() {
    let tvc = ModelParams::default();
    let both = [tvc.clone(), with(&tvc, EffectId::AmplitudePhase)];
    let mut worst = (0.0f64, 0.0f64);
    for f in [1.0, 2.0, 3.0, 5.0, 7.0, 10.0] {
        let m = metrics_of(&both, &sine(f, 0.5, 8.0));
        println!(
            "{f:4} Hz: amplitude ratio {:.5} -> {:.5}, phase {:+.3} -> {:+.3} deg",
            m[0].amp_ratio, m[1].amp_ratio, m[0].phase_err_deg, m[1].phase_err_deg
        );
        // NaN (a failed run) fails: max keeps the NaN's partner, so test each before folding.
        assert!(
            m[1].amp_ratio.is_finite() && m[1].phase_err_deg.is_finite(),
            "{f} Hz: {m:?}"
        );
        worst.0 = worst.0.max((m[1].amp_ratio - 1.0).abs());
        worst.1 = worst.1.max(m[1].phase_err_deg.abs());
    }
    println!(
        "with APC: amplitude ratio within {:.4}, phase within {:.3} deg",
        worst.0, worst.1
    );
    assert!(worst.0 <= 0.01 && worst.1 <= 1.0, "{worst:?}");
}

/// The compensators' plant model, a delay τ of 2.8 ms (their `delay_s`), is the published model's:
/// the loop from reference to feedback displacement lags as a delay within 10 % of it at 12–40 Hz
/// (the harmonics of the sines AHC works on), and below 5 Hz its phase is within 20° of the
/// model's (the LMS converges while within 90°).
#[test]
fn the_compensators_delay_is_the_published_models_lag() {
    let e = ModelParams::default().effect_params;
    let tau = e.amplitude_phase.delay_s;
    assert_eq!(tau, e.harmonic_cancellation.delay_s);
    for f in [1.0, 2.0, 3.0, 5.0, 9.0, 12.0, 15.0, 20.0, 25.0, 30.0, 40.0] {
        let m = metrics_of(&[ModelParams::default()], &sine(f, 0.2, 4.0));
        let lag = -m[0].disp_phase_err_deg / 360.0 / f;
        println!(
            "{f:4} Hz: displacement ratio {:.4}, phase {:+.2} deg (a delay of {:.2} ms)",
            m[0].disp_amp_ratio,
            m[0].disp_phase_err_deg,
            lag * 1e3
        );
        if f >= 12.0 {
            assert!((lag / tau - 1.0).abs() < 0.1, "{f} Hz: {lag}");
        } else if f <= 5.0 {
            let model = -360.0 * f * tau;
            assert!(
                (m[0].disp_phase_err_deg - model).abs() < 20.0,
                "{f} Hz: {m:?}"
            );
        }
    }
}
