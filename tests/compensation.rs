//! Issue 52, the physics-based valve compensator (`valve_compensator`): at the paper's SP09 (3 Hz,
//! 3.20 g) and at 1.73 g on the published model, THD_odd with the compensator is ≥ 3× lower than
//! with the TVC alone, with no adaptation; and still lower at the 90th percentile over ±20 % of β,
//! M, the port widths and the supply pressure.

mod common;
use chacha20::ChaCha8Rng as StdRng;
use rand::{RngExt, SeedableRng};
use vshake::kernel::effects::{effect_set, EffectId};
use vshake::kernel::params::ModelParams;
use vshake::kernel::simulate::{self, LaneParams, LaneStatus, NoObserver, Solver};

/// THD_odd of each model (batches of 8), driven at 3 Hz and `amp_g`; NaN where the run failed
/// (a chamber pressure left its range).
fn thd_odd(models: &[ModelParams], amp_g: f64) -> Vec<f64> {
    let reference = common::reference_sine(amp_g);
    models
        .chunks(8)
        .flat_map(|chunk| {
            let refs: Vec<&ModelParams> = chunk.iter().collect();
            let lanes = simulate::run(
                &LaneParams::<8>::new(&refs).unwrap(),
                &effect_set::<8>(&refs),
                &reference,
                &Solver::default(),
                &mut NoObserver,
            )
            .unwrap();
            lanes.into_iter().take(chunk.len()).map(|r| match r.status {
                LaneStatus::Ok => r.metrics.thd_odd,
                _ => f64::NAN,
            })
        })
        .collect()
}

fn compensated(m: &ModelParams) -> ModelParams {
    let mut m = m.clone();
    *m.effects.get_mut(EffectId::ValveCompensator) = true;
    m
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
    let mut rng = StdRng::seed_from_u64(52);
    let mut u = || rng.random_range(0.8..1.2);
    let tables: Vec<ModelParams> = (0..40)
        .map(|_| {
            let mut m = ModelParams::default();
            m.actuator.beta *= u();
            m.platen.m *= u();
            let sv = &mut m.servovalve;
            (sv.w3, sv.r1, sv.r2, sv.r4, sv.p_s) = (
                sv.w3 * u(),
                sv.r1 * u(),
                sv.r2 * u(),
                sv.r4 * u(),
                sv.p_s * u(),
            );
            m
        })
        .collect();
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
    let p90 = |v: Vec<f64>| {
        let mut v: Vec<f64> = v
            .into_iter()
            .map(|x| if x.is_nan() { f64::INFINITY } else { x })
            .collect();
        v.sort_by(f64::total_cmp);
        v[(0.9 * (v.len() - 1) as f64).round() as usize]
    };
    let (a, b) = (p90(a), p90(b));
    println!("3.20 g, 90th percentile of THD_odd over 40 tables: {a:.5} -> {b:.5}");
    assert!(b.is_finite() && b < a, "{a} {b}");
}
