//! Each effect of the library leaves its signature in the comparison of a synthetic campaign
//! made with it hidden against the baseline model (`study synth --effect`, `study compare`).

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

fn study(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_study")).args(args).output().expect("run study");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

/// Per test: the columns of the compare report's tests table, and the residual bins.
struct Report {
    tests: HashMap<String, HashMap<String, f64>>,
}

impl Report {
    fn get(&self, test: &str, col: &str) -> f64 {
        self.tests[test][col]
    }
}

fn hidden(effect: &str, sets: &[&str]) -> Report {
    let d = tempfile::tempdir().unwrap();
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/campaigns/signatures.toml");
    let mut args = vec!["synth", campaign.to_str().unwrap(), "--out", d.path().to_str().unwrap(), "--effect", effect];
    for s in sets {
        args.extend(["--set", s]);
    }
    let (code, out, err) = study(&args);
    assert_eq!(code, 0, "{out}{err}");
    let report = d.path().join("report");
    let (code, out, err) = study(&["compare", d.path().join("signatures.toml").to_str().unwrap(), "--report", report.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    let cols = ["amp_ratio_measured", "amp_ratio_model", "phase_measured_deg", "phase_model_deg", "h3_measured_ratio", "h3_model_ratio", "rms_residual_accel_ratio", "rms_residual_disp_ratio", "drift_measured_per_cycle", "drift_model_per_cycle"];
    let t = vshake::shell::tables::read_columns_allow_nan(&report.join("tests.parquet"), &cols).unwrap();
    let names = ["f2_a0p3", "f2_a1p5", "f6_a0p3", "f6_a1p5", "f3_a3p2"];
    let mut tests = HashMap::new();
    for (i, n) in names.iter().enumerate() {
        let row: HashMap<String, f64> = cols.iter().map(|c| (c.to_string(), t.column(c).unwrap()[i])).collect();
        tests.insert(n.to_string(), row);
    }
    // Residual magnitude of harmonics 2 and 3 per test (harmonics table: 9 rows per test).
    let h = vshake::shell::tables::read_columns_allow_nan(&report.join("harmonics.parquet"), &["residual_abs"]).unwrap();
    for (i, n) in names.iter().enumerate() {
        let row = tests.get_mut(*n).unwrap();
        row.insert("r2".into(), h.column("residual_abs").unwrap()[9 * i + 1]);
        row.insert("r3".into(), h.column("residual_abs").unwrap()[9 * i + 2]);
    }
    // Bins: velocity reversal and peak velocity residuals per test.
    let b = vshake::shell::tables::read_columns_allow_nan(&report.join("bins.parquet"), &["rms_residual_ratio"]).unwrap();
    for (i, n) in names.iter().enumerate() {
        let row = tests.get_mut(*n).unwrap();
        row.insert("bin_reversal".into(), b.column("rms_residual_ratio").unwrap()[3 * i]);
        row.insert("bin_peak_velocity".into(), b.column("rms_residual_ratio").unwrap()[3 * i + 1]);
    }
    Report { tests }
}

/// Stribeck seal friction: a force step at every reversal. Relative h3 rises at low amplitude
/// (not at high), and the residual sits near velocity reversal.
#[test]
fn seal_friction_raises_h3_at_low_amplitude_near_reversal() {
    let r = hidden("seal_friction", &[]);
    let dh3 = |t: &str| r.get(t, "h3_measured_ratio") - r.get(t, "h3_model_ratio");
    assert!(dh3("f2_a0p3") > 0.002, "h3 rises at 0.3 g: {}", dh3("f2_a0p3"));
    assert!(dh3("f2_a0p3") > 5.0 * dh3("f2_a1p5").abs(), "more at low amplitude: {} vs {}", dh3("f2_a0p3"), dh3("f2_a1p5"));
    assert!(r.get("f2_a0p3", "bin_reversal") > 3.0 * r.get("f2_a0p3", "bin_peak_velocity"));
    assert!(r.get("f2_a0p3", "rms_residual_accel_ratio") > 3.0 * r.get("f2_a1p5", "rms_residual_accel_ratio"));
}

/// Supply droop: the residual grows with amplitude (the pump cannot follow the draw of large
/// tests) and the envelope sinks from cycle to cycle.
#[test]
fn supply_droop_grows_with_amplitude_and_shows_in_the_envelope() {
    let r = hidden("supply", &[]);
    let res = |t: &str| r.get(t, "rms_residual_accel_ratio");
    assert!(res("f2_a1p5") > 5.0 * res("f2_a0p3"), "{} vs {}", res("f2_a1p5"), res("f2_a0p3"));
    assert!(res("f3_a3p2") > res("f2_a1p5"));
    let drift = |t: &str| r.get(t, "drift_measured_per_cycle") - r.get(t, "drift_model_per_cycle");
    assert!(drift("f3_a3p2") < -0.005, "envelope sinks: {}", drift("f3_a3p2"));
    assert!(drift("f2_a0p3").abs() < 0.001, "not at small draw: {}", drift("f2_a0p3"));
}

/// Spool dynamics (80 Hz, ζ = 0.7): the spool lags its command by 2ζ·f/f_n, and at 2 Hz the
/// closed loop passes that lag to the acceleration (≈ −2°); the amplitude ratio falls everywhere.
#[test]
fn spool_dynamics_adds_phase_lag() {
    let r = hidden("spool_dynamics", &[]);
    let lag = 2.0 * 0.7 * 2.0 / 80.0 * 180.0 / std::f64::consts::PI;
    for t in ["f2_a0p3", "f2_a1p5"] {
        let d = r.get(t, "phase_measured_deg") - r.get(t, "phase_model_deg");
        assert!((d + lag).abs() < 0.5 * lag, "{t}: phase change {d}° against the spool's lag −{lag:.2}°");
    }
    for t in ["f2_a0p3", "f2_a1p5", "f6_a0p3", "f6_a1p5", "f3_a3p2"] {
        assert!(r.get(t, "amp_ratio_measured") < r.get(t, "amp_ratio_model") - 0.01, "{t}");
    }
}

/// Leakage across the piston: a flow loss proportional to the load pressure, which the weak
/// displacement loop corrects slowly: the displacement residual far exceeds the acceleration's.
#[test]
fn leakage_shows_in_displacement_more_than_acceleration() {
    let r = hidden("leakage", &["leakage.c_int=2e-10"]);
    for t in ["f2_a0p3", "f6_a0p3", "f6_a1p5"] {
        let (x, a) = (r.get(t, "rms_residual_disp_ratio"), r.get(t, "rms_residual_accel_ratio"));
        assert!(x > 5.0 * a && a < 0.02, "{t}: displacement {x} vs acceleration {a}");
    }
}

/// Spool-to-flow saturation: flow is lost where the velocity demand is high (2 Hz at 1.5 g,
/// 3.2 g), with more odd distortion; nothing at small demand.
#[test]
fn flow_saturation_bites_at_high_velocity_demand() {
    let r = hidden("flow_saturation", &[]);
    let res = |t: &str| r.get(t, "rms_residual_accel_ratio");
    assert!(res("f2_a1p5") > 100.0 * res("f6_a0p3"), "{} vs {}", res("f2_a1p5"), res("f6_a0p3"));
    assert!(res("f3_a3p2") > 0.05);
    let dh3 = |t: &str| r.get(t, "h3_measured_ratio") - r.get(t, "h3_model_ratio");
    assert!(dh3("f3_a3p2") > 0.01 && dh3("f6_a0p3").abs() < 1e-3, "{} {}", dh3("f3_a3p2"), dh3("f6_a0p3"));
    assert!(r.get("f3_a3p2", "amp_ratio_measured") < r.get("f3_a3p2", "amp_ratio_model") - 0.05);
}

/// Hold-down stiffness nonlinearity: matters where the displacement is large (2 Hz, 1.5 g:
/// X = 9 cm), with more odd distortion there, and not at 6 Hz (X = 1 cm).
#[test]
fn hold_down_nonlinearity_grows_with_displacement() {
    let r = hidden("hold_down", &[]);
    let res = |t: &str| r.get(t, "rms_residual_accel_ratio");
    assert!(res("f2_a1p5") > 100.0 * res("f6_a1p5"), "{} vs {}", res("f2_a1p5"), res("f6_a1p5"));
    let dh3 = r.get("f2_a1p5", "h3_measured_ratio") - r.get("f2_a1p5", "h3_model_ratio");
    assert!(dh3 > 0.005, "{dh3}");
}

/// Port asymmetry (extension 5 % stronger than retraction): the residual is an even harmonic,
/// larger in h2 than in h3 in every test, and the displacement shifts.
#[test]
fn port_asymmetry_shows_as_even_harmonics() {
    let r = hidden("asymmetry", &[]);
    for t in ["f2_a0p3", "f2_a1p5", "f6_a0p3", "f6_a1p5", "f3_a3p2"] {
        assert!(r.get(t, "r2") > 2.0 * r.get(t, "r3"), "{t}: |R2| {} vs |R3| {}", r.get(t, "r2"), r.get(t, "r3"));
        assert!(r.get(t, "rms_residual_disp_ratio") > r.get(t, "rms_residual_accel_ratio"), "{t}");
    }
}

/// Off is off: a model file that switches an effect on and then off again reproduces the
/// baseline to the bit.
#[test]
fn a_switched_off_effect_is_neutral() {
    let d = tempfile::tempdir().unwrap();
    let base = "[excitation]\nkind = \"sine\"\nfreq_hz = 3.0\namp_g = 1.73\nwindow_cycles = 4\n";
    std::fs::write(d.path().join("a.toml"), base).unwrap();
    std::fs::write(d.path().join("b.toml"), format!("[model.seal_friction]\nenabled = false\nf_c = 9000.0\n[model.spool_dynamics]\nenabled = false\n{base}")).unwrap();
    let (_, a, _) = study(&["sim", d.path().join("a.toml").to_str().unwrap(), "-q"]);
    let (_, b, _) = study(&["sim", d.path().join("b.toml").to_str().unwrap(), "-q"]);
    assert_eq!(a, b);
    std::fs::write(d.path().join("c.toml"), format!("[model.seal_friction]\n{base}")).unwrap();
    let (_, c, _) = study(&["sim", d.path().join("c.toml").to_str().unwrap(), "-q"]);
    assert_ne!(a, c, "switched on, it changes the run");
}
