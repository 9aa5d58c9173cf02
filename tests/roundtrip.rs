//! Issue 26, record semantics (docs/model.md §4): the model's own output, written as a
//! data-acquisition system writes it — `ref_disp_m` the reference the controller tracked, at
//! 1024 Hz with time rounded to 1 ms (coarser than a step: two rows print the same time every
//! 43 rows) and at 500 Hz to 10 µs — and compared as measured tests of the right
//! kind, is at the numerical floor: sine, sweep, stochastic, a record run as a command (its
//! tracked reference read back with `signal = "reference"`, the campaign default) and a record
//! run as a reference. A diagnosis of it finds nothing missing.

mod common;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use vshake::shell::formats::measured_files::read_columns_allow_nan;
use vshake::shell::formats::parquet_read::read_strings;

/// Runs `study` with `args`: (success, stdout, stderr).
fn study(args: &[&str]) -> (bool, String, String) {
    let (code, out, err) = common::study(args);
    (code == 0, out, err)
}

/// A drive record (displacement, m) at `rate` Hz for 10 s: a multisine of equal acceleration
/// amplitude from 0.3 to 12 Hz, tapered in and out over 2 s.
fn drive(path: &Path, rate: f64) {
    let comps: Vec<(f64, f64)> = (0..33)
        .map(|i| (0.3 * 1.12f64.powi(i), 0.7 * i as f64))
        .collect();
    let taper = |t: f64| 0.5 * (1.0 - (PI * (t.min(10.0 - t) / 2.0).min(1.0)).cos());
    let mut text = String::from("time_s,disp_m\n");
    for i in 0..=(10.0 * rate) as usize {
        let t = i as f64 / rate;
        let x: f64 = comps
            .iter()
            .map(|(f, p)| 0.5 / (2.0 * PI * f).powi(2) * (2.0 * PI * f * t + p).sin())
            .sum();
        text.push_str(&format!("{t:?},{:?}\n", x * taper(t)));
    }
    std::fs::write(path, text).unwrap();
}

const CAMPAIGN: &str = r#"[campaign]
name = "roundtrip"
[[test]]
name = "sine"
data = "sine.csv"
excitation = { kind = "sine", freq_hz = 3.0, amp_g = 1.0, taper_s = 1.0, duration_s = 4.0 }
[[test]]
name = "sweep"
data = "sweep.csv"
excitation = { kind = "sweep", f0_hz = 0.5, f1_hz = 12, duration_s = 10, amp_g = 0.3, law = "log" }
[[test]]
name = "stochastic"
data = "stochastic.csv"
excitation = { kind = "stochastic", duration_s = 10, realisation = 2 }
[[test]]
name = "command_run"
data = "command_run.csv"
excitation = { kind = "record", file = "drive_1024.csv", column = "disp_m", signal = "command" }
[[test]]
name = "reference_run"
data = "reference_run.csv"
excitation = { kind = "record", file = "drive_100.csv", column = "disp_m", signal = "reference" }
"#;

/// Rewrites the time column of a CSV written by synth with `decimals` decimals, as an export
/// with a fixed number of decimals does.
fn round_time(path: &Path, decimals: usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let (t, rest) = line.split_once(',').unwrap();
        if i == 0 {
            out.push_str(line);
        } else {
            let t: f64 = t.parse().unwrap();
            out.push_str(&format!("{t:.decimals$},{rest}"));
        }
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

/// The campaign synthesised at `rate` Hz with rounded time (1 ms at 1024 Hz, else 10 µs), in
/// `dir`.
fn synthesise(dir: &Path, rate: &str) -> PathBuf {
    let src = dir.join("src");
    std::fs::create_dir_all(&src).unwrap();
    std::fs::write(src.join("campaign.toml"), CAMPAIGN).unwrap();
    drive(&src.join("drive_1024.csv"), 1024.0);
    drive(&src.join("drive_100.csv"), 100.0);
    let out = dir.join(format!("at_{rate}"));
    let (ok, stdout, err) = study(&[
        "synth",
        src.join("campaign.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--rate",
        rate,
    ]);
    assert!(ok, "{err}");
    assert!(
        stdout.contains("ref_disp_m holds the reference the controller tracked")
            && stdout.contains("record test(s), signal = \"reference\""),
        "{stdout}"
    );
    for t in [
        "sine",
        "sweep",
        "stochastic",
        "command_run",
        "reference_run",
    ] {
        let decimals = if rate == "1024" { 3 } else { 5 };
        round_time(&out.join(format!("{t}.csv")), decimals);
    }
    out.join("campaign.toml")
}

/// `study compare` of `campaign` with its report in `report`: each test's name and acceleration
/// residual (over the acceleration's rms), and the printed table.
fn compared(campaign: &Path, report: &Path) -> (Vec<String>, Vec<f64>, String) {
    let (ok, stdout, err) = study(&[
        "compare",
        campaign.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}{err}");
    let p = report.join("tests.parquet");
    let names = read_strings(&p, "test").unwrap();
    let t = read_columns_allow_nan(&p, &["rms_residual_accel_ratio"]).unwrap();
    let resid = t.column("rms_residual_accel_ratio").unwrap().to_vec();
    (names, resid, stdout)
}

#[test]
#[ignore = "slow (about 35 s): a CI step runs it, cargo test --release --test roundtrip -- --ignored"]
fn the_models_own_output_compares_at_the_numerical_floor() {
    let d = tempfile::tempdir().unwrap();
    for rate in ["1024", "500"] {
        let campaign = synthesise(d.path(), rate);
        let written = std::fs::read_to_string(&campaign).unwrap();
        assert!(
            written.matches("\nsignal = \"reference\"\n").count() == 2,
            "{written}"
        );
        let (names, resid, stdout) = compared(&campaign, &d.path().join(format!("report_{rate}")));
        assert_eq!(names.len(), 5);
        for (name, r) in names.iter().zip(resid) {
            // docs/model.md §4's floor, 1e-4 of the acceleration's rms. Measured (2026-11-30): 0
            // for every test at 1024 Hz; 1.3e-7 (sine) to 3.8e-6 (stochastic) at 500 Hz, the
            // reference run 3.6e-6 (5.9e-4 while synth wrote x_r re-interpolated from the ticks
            // instead of the record's own samples).
            assert!(
                r <= 1e-4,
                "{rate} Hz, {name}: acceleration residual {r:e}\n{stdout}"
            );
        }
        let (ok, stdout, err) = study(&["diagnose", campaign.to_str().unwrap()]);
        assert!(ok, "{err}");
        assert!(
            stdout.contains("no significant missing effect"),
            "{rate} Hz:\n{stdout}"
        );
    }
}

/// Issue 51, point 6: the model's own 35 s stochastic run, written as a DAQ writes it (1024 Hz,
/// time rounded to 1 ms; and 500 Hz) and compared as a measured *record* test of its own
/// `ref_disp_m` (the tracked reference, whose derivatives the model must make itself: docs/model.md
/// §4), is within 1e-3 of the acceleration's rms, and a diagnosis names nothing for it.
#[test]
#[ignore = "slow (about 40 s): a CI step runs it, cargo test --release --test roundtrip -- --ignored"]
fn a_broadband_run_read_back_as_a_record_compares_within_1e_3() {
    let d = tempfile::tempdir().unwrap();
    let src = d.path().join("src.toml");
    std::fs::write(
        &src,
        "[campaign]\nname = \"broadband\"\n[[test]]\nname = \"stochastic\"\ndata = \"stochastic.csv\"\n\
         excitation = { kind = \"stochastic\", duration_s = 35, realisation = 1 }\n",
    )
    .unwrap();
    for (rate, decimals) in [("1024", 3), ("500", 5)] {
        let out = d.path().join(format!("at_{rate}"));
        let args = [
            "synth",
            src.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        let (ok, _, err) = study(&[&args[..], &["--rate", rate]].concat());
        assert!(ok, "{err}");
        round_time(&out.join("stochastic.csv"), decimals);
        let campaign = out.join("as_record.toml");
        std::fs::write(
            &campaign,
            "[campaign]\nname = \"as_record\"\n[[test]]\nname = \"stochastic\"\ndata = \"stochastic.csv\"\n\
             excitation = { kind = \"record\", file = \"stochastic.csv\", column = \"ref_disp_m\" }\n",
        )
        .unwrap();
        let (_, resid, stdout) = compared(&campaign, &out.join("report"));
        let r = resid[0];
        // Measured (2026-11-29): 1.2e-4 at 1024 Hz, 1.8e-4 at 500 Hz (1.1e-2 with the
        // derivatives' corner at f_ref).
        assert!(
            r <= 1e-3,
            "{rate} Hz: acceleration residual {r:e}\n{stdout}"
        );
        if rate == "1024" {
            let (ok, stdout, err) = study(&["diagnose", campaign.to_str().unwrap()]);
            assert!(ok, "{err}");
            assert!(
                stdout.contains("no significant missing effect"),
                "{rate} Hz:\n{stdout}"
            );
        }
    }
}
