//! The kernel pinned to an independent implementation inside `cargo test`: the NumPy peer's
//! metrics (benches/peers/numpy_peer.py, a transcription of docs/model.md that shares no code
//! with vshake), committed in tests/fixtures/numpy_peer_metrics.csv by
//! benches/peers/make_fixture.py, for 16 gain sets at 0.5, 1.73 and 3.20 g of the 3 Hz reference
//! sine, RK4 with 4 substeps. Every metric agrees to 1e-9 relative to max(|value|, 1) (a phase in
//! degrees), and a run the peer stops the kernel fails too. A change of any plant constant by
//! 0.01 % moves some metric by far more than that (`a_small_change_of_beta_is_caught`).

mod common;
use vshake::kernel::effects::Baseline;
use vshake::kernel::params::ModelParams;
use vshake::kernel::simulate::{self, LaneParams, LaneResult, LaneStatus, NoObserver, Solver};

const TOLERANCE: f64 = 1e-9;

struct Case {
    amp_g: f64,
    gains: Vec<(String, f64)>,
    metrics: Vec<(String, f64)>,
}

fn cases() -> Vec<Case> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/numpy_peer_metrics.csv"
    );
    let mut r = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    let split = header.iter().position(|h| h == "amp_ratio").unwrap();
    r.records()
        .map(|rec| {
            let v: Vec<f64> = rec.unwrap().iter().map(|x| x.parse().unwrap()).collect();
            let named = |range: std::ops::Range<usize>| {
                range.map(|i| (header[i].clone(), v[i])).collect::<Vec<_>>()
            };
            Case {
                amp_g: v[0],
                gains: named(1..split),
                metrics: named(split..header.len()),
            }
        })
        .collect()
}

fn run(case: &Case, base: &ModelParams) -> LaneResult {
    let mut model = base.clone();
    for (path, v) in &case.gains {
        ModelParams::lookup(path).unwrap().set(&mut model, *v);
    }
    let lp = LaneParams::<1>::new(&[&model]).unwrap();
    let solver = Solver { substeps: 4 };
    let [r] = simulate::run(
        &lp,
        &Baseline,
        &common::reference_sine(case.amp_g),
        &solver,
        &mut NoObserver,
    )
    .unwrap();
    r
}

/// The largest deviation of `r`'s metrics from the case's, relative to max(|value|, 1), with
/// the metric's name; infinite when one run failed and the other did not.
fn deviation(case: &Case, r: &LaneResult) -> (f64, String) {
    let failed = case.metrics.iter().any(|(_, v)| v.is_nan());
    if failed || r.status != LaneStatus::Ok {
        let agree = failed && matches!(r.status, LaneStatus::Failed { .. });
        return (if agree { 0.0 } else { f64::INFINITY }, "status".into());
    }
    let ours = r.metrics.columns();
    case.metrics
        .iter()
        .map(|(name, want)| {
            let got = ours.iter().find(|(n, _)| n == name).unwrap().1;
            // A NaN on one side is the largest deviation, never dropped by the fold.
            let d = (got - want).abs() / want.abs().max(1.0);
            (if d.is_nan() { f64::INFINITY } else { d }, name.clone())
        })
        .fold((0.0, String::new()), |a, b| if b.0 > a.0 { b } else { a })
}

#[test]
fn the_kernel_agrees_with_the_numpy_peer_to_1e_9() {
    let cases = cases();
    assert_eq!(cases.len(), 48, "16 gain sets x 3 amplitudes");
    let base = ModelParams::default();
    let mut worst = (0.0f64, String::new());
    for (i, case) in cases.iter().enumerate() {
        let (d, name) = deviation(case, &run(case, &base));
        assert!(
            d <= TOLERANCE,
            "row {} ({} g): {name} deviates by {d:e} from the NumPy peer",
            i + 2,
            case.amp_g
        );
        if d > worst.0 {
            worst = (d, format!("row {} {name}", i + 2));
        }
    }
    println!(
        "largest deviation from the NumPy peer: {:e} ({})",
        worst.0, worst.1
    );
}

/// The pin can fail: β (the oil's bulk modulus) 0.1 % and 0.01 % off its default moves a metric
/// of the reference case far beyond the tolerance.
#[test]
fn a_small_change_of_beta_is_caught() {
    let cases = cases();
    for change in [1e-3, 1e-4] {
        let mut model = ModelParams::default();
        model.actuator.beta *= 1.0 + change;
        let (d, name) = deviation(&cases[16], &run(&cases[16], &model));
        assert!(
            d > 100.0 * TOLERANCE,
            "β x (1 + {change}) moved the metrics by only {d:e} ({name})"
        );
    }
}
