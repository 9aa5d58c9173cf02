//! Model versus measurement: synthetic campaigns whose truth is known, and every malformed
//! measured file of docs/formats.md.

mod common;
use common::followed_state;
use common::study;
use std::path::{Path, PathBuf};

fn campaign() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/campaigns/sines.toml")
}

fn synth(dir: &Path, extra: &[&str]) {
    let c = campaign();
    let mut args = vec!["synth", c.to_str().unwrap(), "--out", dir.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = study(&args);
    assert_eq!(code, 0, "{stdout}{stderr}");
}

fn tests_table(report: &Path, col: &str) -> Vec<f64> {
    let t = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &report.join("tests.parquet"),
        &[col],
    )
    .unwrap();
    t.column(col).unwrap().to_vec()
}

/// A synthesis whose model fails in one test writes nothing: every test is run before any file
/// is written, so no half-written campaign is left that looks complete (at 3 MPa of supply the
/// 3.2 g test empties a chamber).
#[test]
fn a_synthesis_that_fails_in_one_test_leaves_no_files() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("out");
    let c = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/campaigns/diagnosis.toml");
    let args = ["synth", c.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let (code, stdout, stderr) = study(&[&args[..], &["--set", "servovalve.p_s=3e6"]].concat());
    assert_ne!(code, 0, "{stdout}");
    assert!(
        stderr.contains("test \"f3_a3p2\": the model failed"),
        "{stderr}"
    );
    let left: Vec<_> = std::fs::read_dir(&out).map_or(Vec::new(), |r| r.collect());
    assert!(left.is_empty(), "{left:?}");
}

/// Acceptance 1: files that are exactly the model's own output compare at floating-point level
/// (CSV written with round-trip digits, and Parquet).
#[test]
fn the_models_own_output_compares_at_floating_point_level() {
    let d = tempfile::tempdir().unwrap();
    synth(d.path(), &[]);
    let report = d.path().join("report");
    let (code, stdout, stderr) = study(&[
        "compare",
        d.path().join("sines.toml").to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("sine_3hz_3p20g"), "{stdout}");
    for col in [
        "rms_residual_accel_ratio",
        "rms_residual_disp_ratio",
        "rms_residual_force_ratio",
    ] {
        for v in tests_table(&report, col) {
            assert!(v.abs() < 1e-12, "{col} = {v}");
        }
    }
    let h = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &report.join("harmonics.parquet"),
        &["residual_abs"],
    )
    .unwrap();
    assert_eq!(h.rows(), 4 * 9);
    assert!(h.column("residual_abs").unwrap().iter().all(|v| *v < 1e-12));
    // The HTML report: one plot across the campaign, the state map, and an overlay and harmonic
    // bars per test.
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert_eq!(
        html.matches("<svg").count(),
        2 + 2 * 4,
        "plots in the report"
    );
    assert_eq!(html.matches("class=\"plot overlay\"").count(), 4);
    assert!(html.contains("id=\"test-sine_2hz_1p00g\"") && html.contains("<table id=\"summary\">"));
    // The reference case reproduces docs/model.md §5 through the whole file path, to half a unit
    // of the digit the table prints.
    let ratio = tests_table(&report, "amp_ratio_measured");
    assert!((ratio[0] - 0.9987).abs() <= 5e-5, "{ratio:?}");
}

/// Open loop on the model's own valve command reproduces the closed-loop run exactly (the
/// command is the one the controller produced), so the residual is again at floating-point level.
/// A campaign without the drive's column is refused with the file and the column.
#[test]
fn open_loop_on_the_models_own_command_is_exact_and_needs_its_column() {
    let d = tempfile::tempdir().unwrap();
    synth(d.path(), &[]);
    let report = d.path().join("report");
    let c = d.path().join("sines.toml");
    let (code, stdout, stderr) = study(&[
        "compare",
        c.to_str().unwrap(),
        "--open-loop",
        "valve",
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("open loop on the measured valve_cmd_v"),
        "{stdout}"
    );
    for col in [
        "rms_residual_accel_ratio",
        "rms_residual_disp_ratio",
        "rms_residual_force_ratio",
    ] {
        for v in tests_table(&report, col) {
            assert!(v.abs() < 1e-12, "{col} = {v}");
        }
    }
    // Without the column: exit 2, naming the file and the column.
    let dir = d.path().join("no_cmd");
    std::fs::create_dir(&dir).unwrap();
    let text = std::fs::read_to_string(d.path().join("sine_3hz_1p73g.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let drop = header.iter().position(|h| *h == "spool_m").unwrap();
    let stripped: String = text
        .lines()
        .map(|l| {
            l.split(',')
                .enumerate()
                .filter(|(i, _)| *i != drop)
                .map(|(_, v)| v)
                .collect::<Vec<_>>()
                .join(",")
                + "\n"
        })
        .collect();
    std::fs::write(dir.join("t.csv"), stripped).unwrap();
    std::fs::write(dir.join("c.toml"), "[campaign]\nname = \"x\"\n[[test]]\nname = \"t\"\ndata = \"t.csv\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.73 }\n").unwrap();
    let (code, _, stderr) = study(&[
        "compare",
        dir.join("c.toml").to_str().unwrap(),
        "--open-loop",
        "spool",
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("t.csv") && stderr.contains("`spool_m`"),
        "{stderr}"
    );
}

/// Acceptance 1: with sensor noise, the residual is at the noise level.
#[test]
fn with_noise_the_residual_is_at_the_noise_level() {
    let d = tempfile::tempdir().unwrap();
    let sigma = 0.05;
    synth(
        d.path(),
        &["--noise", "accel=0.05,disp=2e-5", "--seed", "9"],
    );
    let report = d.path().join("report");
    let (code, _, stderr) = study(&[
        "compare",
        d.path().join("sines.toml").to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    // Expected: rms(noise)/rms(measured accel) over the window. The overlay table holds the
    // window's measured acceleration and the residual (= −noise).
    let ov = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &report.join("overlay.parquet"),
        &["accel_measured_mps2", "residual_mps2"],
    )
    .unwrap();
    let res = ov.column("residual_mps2").unwrap();
    let rms_res = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
    assert!(
        (rms_res - sigma).abs() < 0.05 * sigma,
        "window residual rms {rms_res} vs noise {sigma}"
    );
    let got = tests_table(&report, "rms_residual_accel_ratio");
    let amps = [1.73, 3.20, 1.0, 1.0];
    for (g, r) in amps.iter().zip(&got) {
        // rms of a sine of amplitude g·9.81 is g·9.81/√2.
        let expect = sigma / (g * 9.80665 / 2f64.sqrt());
        assert!(
            (r / expect - 1.0).abs() < 0.15,
            "{g} g: residual ratio {r} vs noise level {expect}"
        );
    }
    // The harmonic residuals sit at the noise floor: σ·√(2/n)/|H1(a_r)| is below 1e-3.
    let h = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &report.join("harmonics.parquet"),
        &["residual_abs"],
    )
    .unwrap();
    assert!(
        h.column("residual_abs").unwrap().iter().all(|v| *v < 1e-3),
        "{:?}",
        h.column("residual_abs")
    );
}

/// A hidden change of the plant shows in the comparison: 10 % less valve flow gain lowers the
/// measured amplitude ratio against the model's and leaves a fundamental residual of that order.
#[test]
fn a_hidden_flow_gain_change_shows_in_the_fundamental() {
    let d = tempfile::tempdir().unwrap();
    synth(d.path(), &["--set", "servovalve.kv=0.016696"]);
    let report = d.path().join("report");
    let (code, _, stderr) = study(&[
        "compare",
        d.path().join("sines.toml").to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (meas, model) = (
        tests_table(&report, "amp_ratio_measured"),
        tests_table(&report, "amp_ratio_model"),
    );
    for (a, b) in meas.iter().zip(&model) {
        assert!(
            b - a > 0.005,
            "measured {a} should fall below the model's {b}"
        );
    }
    let r = tests_table(&report, "rms_residual_accel_ratio");
    assert!(r.iter().all(|v| *v > 0.01 && *v < 0.3), "{r:?}");
}

fn one_test_campaign(dir: &Path, data: &str, text: &str) -> PathBuf {
    std::fs::write(dir.join(data), text).unwrap();
    let c = dir.join("c.toml");
    std::fs::write(
        &c,
        format!("[campaign]\nname = \"bad\"\n[[test]]\nname = \"t\"\ndata = \"{data}\"\nexcitation = {{ kind = \"sine\", freq_hz = 3.0, amp_g = 1.0, taper_s = 0.0 }}\n"),
    )
    .unwrap();
    c
}

fn good_rows(n: usize) -> String {
    let mut s = String::from("time_s,ref_disp_m,disp_m,accel_mps2\n");
    for k in 0..n {
        s.push_str(&format!("{:?},0,0,0\n", k as f64 / 1024.0));
    }
    s
}

/// Acceptance 3: every malformed case of docs/formats.md is a clear error naming file, column and row.
#[test]
fn malformed_measured_files_name_file_column_and_row() {
    let d = tempfile::tempdir().unwrap();
    let header_ok = good_rows(3000);
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            header_ok.replace(
                "time_s,ref_disp_m,disp_m,accel_mps2",
                "time_s,ref_disp_m,disp_m,velocity",
            ),
            vec!["`accel_mps2` is missing"],
        ),
        (
            header_ok.replace(
                "time_s,ref_disp_m,disp_m,accel_mps2",
                "time_s,ref_disp_m,disp_furlongs,accel_mps2",
            ),
            vec!["column `disp_furlongs`: unknown unit `furlongs`"],
        ),
        (
            header_ok.replacen("\n0.0009765625,0,0,0\n", "\n0.0009765625,0,NaN,0\n", 1),
            vec!["column `disp_m`, row 2 (line 3)", "NaN"],
        ),
        (
            header_ok.replacen("\n0.0009765625,0,0,0\n", "\n0.0009765625,,0,0\n", 1),
            vec!["column `ref_disp_m`, row 2 (line 3)", "empty cell"],
        ),
        (
            header_ok.replacen("\n0.001953125,0,0,0\n", "\n0.0,0,0,0\n", 1),
            vec!["column `time_s`, row 3 (line 4)", "does not increase"],
        ),
        (
            header_ok.replacen("\n0.001953125,0,0,0\n", "\n0.0025,0,0,0\n", 1),
            vec!["column `time_s`, row 3 (line 4)", "off the uniform grid"],
        ),
        (
            "time_s,ref_disp_m,disp_m,accel_mps2\n".to_string(),
            vec!["no data rows"],
        ),
        (String::new(), vec!["the file is empty"]),
    ];
    for (text, needles) in cases {
        let c = one_test_campaign(d.path(), "t.csv", &text);
        let (code, _, stderr) = study(&["compare", c.to_str().unwrap()]);
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains("t.csv"), "names the file: {stderr}");
        for n in needles {
            assert!(stderr.contains(n), "expected {n:?} in {stderr}");
        }
    }
    // A bad campaign file names the key.
    std::fs::write(d.path().join("c2.toml"), "[campaign]\nname = \"x\"\n[[test]]\nname = \"t\"\ndata = \"t.csv\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.0, colour = 1 }\n").unwrap();
    let (code, _, stderr) = study(&["compare", d.path().join("c2.toml").to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("test[0].excitation.colour: unknown key"),
        "{stderr}"
    );
}

/// Issue 11, the residual in state space: effects whose state is known (a friction force on the
/// velocity, a spring on the displacement, a leakage on the load pressure) are placed there by
/// the map's regressions, each through the balance it breaks; with nothing hidden no state is named.
#[test]
fn the_state_map_places_known_effects_on_their_states() {
    let diag = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/campaigns/diagnosis.toml");
    type Named<'a> = Option<(&'a str, &'a str, &'a str)>;
    let cases: [(&[&str], Named); 4] = [
        (
            &[
                "--effect",
                "seal_friction",
                "--set",
                "seal_friction.f_c=9000",
            ],
            Some(("platen_force", "velocity", "sign(v)")),
        ),
        (
            &["--effect", "hold_down", "--set", "hold_down.k3=3e8"],
            Some(("platen_force", "displacement", "y³")),
        ),
        (
            &["--effect", "leakage"],
            Some(("valve_flow", "pressure_difference", "Δp")),
        ),
        (&[], None),
    ];
    for (extra, want) in cases {
        let d = tempfile::tempdir().unwrap();
        let mut args = vec![
            "synth",
            diag.to_str().unwrap(),
            "--out",
            d.path().to_str().unwrap(),
            "--noise",
            "accel=0.02,disp=1e-5,force=2000",
        ];
        args.extend_from_slice(extra);
        let (code, out, err) = study(&args);
        assert_eq!(code, 0, "{out}{err}");
        let rep = d.path().join("report");
        let (code, out, err) = study(&[
            "compare",
            d.path().join("diagnosis.toml").to_str().unwrap(),
            "--report",
            rep.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{out}{err}");
        let (res, state, term, r2) = followed_state(&rep);
        match want {
            Some(w) => {
                assert_eq!(
                    (res.as_str(), state.as_str(), term.as_str()),
                    w,
                    "{extra:?}: R² {r2}\n{out}"
                );
                assert!(r2 > 0.5, "{extra:?}: R² {r2}");
                assert!(
                    out.contains("-> the "),
                    "{extra:?}: the sentence is printed\n{out}"
                );
            }
            None => {
                assert!(
                    r2 < 0.5,
                    "nothing hidden, yet {res} follows {term} in {state} with R² {r2}\n{out}"
                );
                assert!(
                    out.contains("-> no state's terms explain the residual"),
                    "{out}"
                );
            }
        }
    }
}

/// Issue 11, part 5: the bundled campaign of the tutorial (docs/guide.md) "An effect the library does not
/// have" hides a spool overlap; the map points at small spool openings.
#[test]
fn the_overlap_tutorial_campaign_points_at_small_spool_openings() {
    let c = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/overlap/campaign.toml");
    let d = tempfile::tempdir().unwrap();
    let rep = d.path().join("report");
    let (code, out, err) = study(&[
        "compare",
        c.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let (res, state, term, r2) = followed_state(&rep);
    assert!(
        res.starts_with("valve_") && state == "spool_opening",
        "{res} follows {term} in {state}, R² {r2}\n{out}"
    );
    assert!(
        term == "sign(x)" || term.starts_with("sign(x)·min"),
        "a term of small openings: {term}\n{out}"
    );
    assert!(r2 > 0.9, "{r2}");
    assert!(out.contains("at small spool openings"), "{out}");
    // The report shows the map as a plot.
    let html = std::fs::read_to_string(rep.join("report.html")).unwrap();
    assert!(
        html.contains("id=\"state-map\"><svg"),
        "the state map is drawn"
    );
}

/// Issue 11: effects with memory, which no static term of one state holds, are named through a
/// term with memory on the right state, with the filter's parameters: a mass the model lacks (an
/// oscillator above the tests, its mass the missing mass) and a spool that lags its command
/// (files with the valve command but neither the spool nor the pressures, as a controller's
/// export has them; the lag on the opening, at the spool's frequency).
#[test]
fn effects_with_memory_are_named_through_a_filter_on_their_state() {
    use vshake::shell::formats::measured_files::read_columns_allow_nan;
    use vshake::shell::formats::parquet_read::{read_bools, read_strings};
    let diag = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/campaigns/diagnosis.toml");
    type Expected = (f64, f64, f64);
    let cases: [(&[&str], (&str, &str), Expected); 2] = [
        // 16 t more than the model's 144 t: the oscillator's frequency lies far above the tests.
        (
            &["--set", "platen.m=160000"],
            ("platen_force", "displacement"),
            (50.0, f64::INFINITY, 16_000.0),
        ),
        // A 40 Hz spool: the lag's frequency within 10 %, all of the opening lagging.
        (
            &[
                "--effect",
                "spool_dynamics",
                "--set",
                "spool_dynamics.freq_hz=40",
            ],
            ("valve_opening", "spool_opening"),
            (36.0, 44.0, 1.0),
        ),
    ];
    for (extra, want, (f_lo, f_hi, gain)) in cases {
        let d = tempfile::tempdir().unwrap();
        let mut args = vec![
            "synth",
            diag.to_str().unwrap(),
            "--out",
            d.path().to_str().unwrap(),
            "--noise",
            "accel=0.02,disp=1e-5,force=2000",
        ];
        args.extend_from_slice(extra);
        let (code, out, err) = study(&args);
        assert_eq!(code, 0, "{out}{err}");
        // Keep what a controller's export has: no spool position, no chamber pressures.
        for e in std::fs::read_dir(d.path()).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "parquet") {
                let keep = [
                    "time_s",
                    "ref_disp_m",
                    "disp_m",
                    "accel_mps2",
                    "valve_cmd_v",
                    "force_n",
                ];
                let t = read_columns_allow_nan(&p, &keep).unwrap();
                let cols: Vec<(&str, Vec<f64>)> = keep
                    .iter()
                    .map(|&k| (k, t.column(k).unwrap().to_vec()))
                    .collect();
                vshake::shell::commands::synth_cmd::write_measured(&p, &cols, &[]).unwrap();
            }
        }
        let rep = d.path().join("report");
        let (code, out, err) = study(&[
            "compare",
            d.path().join("diagnosis.toml").to_str().unwrap(),
            "--report",
            rep.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{out}{err}");
        let (res, state, term, r2) = followed_state(&rep);
        assert_eq!(
            (res.as_str(), state.as_str()),
            want,
            "{extra:?}: {term}, R² {r2}\n{out}"
        );
        assert!(r2 > 0.9, "{extra:?}: R² {r2}\n{out}");
        assert!(out.contains("through a term with memory"), "{out}");
        let p = rep.join("stateterms.parquet");
        let i = read_bools(&p, "named")
            .unwrap()
            .iter()
            .position(|&b| b)
            .unwrap();
        assert!(
            read_strings(&p, "term").unwrap()[i].contains('('),
            "the filter's parameters are in the term"
        );
        let num = read_columns_allow_nan(&p, &["f_n_hz", "coef"]).unwrap();
        let (f_n, g) = (
            num.column("f_n_hz").unwrap()[i],
            num.column("coef").unwrap()[i],
        );
        assert!(f_n > f_lo && f_n < f_hi, "{extra:?}: f_n {f_n} Hz\n{out}");
        assert!(
            (g / gain - 1.0).abs() < 0.05,
            "{extra:?}: gain {g}, want {gain}\n{out}"
        );
    }
}
