//! Measured files the way data-acquisition systems export them (issue 10): made from the model
//! with `study synth`, then transformed — rounded time, other sample rates, a pre-trigger, extra
//! length, another time origin, reordered and extra columns, other separators, wrong units, a
//! flipped sign, corrupt cells. Each variant is either read to the clean file's results or gets
//! its specific warning or error.

mod common;
use common::study;

use std::path::{Path, PathBuf};

/// Two sine tests (3 Hz 1.73 g and 4 Hz 1 g), CSV files.
const CAMPAIGN: &str = r#"[campaign]
name = "real"

[[test]]
name = "sine_3hz_1p73g"
data = "sine_3hz_1p73g.csv"
excitation = { kind = "sine", freq_hz = 3.0, amp_g = 1.73, taper_s = 1.0 }

[[test]]
name = "sine_4hz_1p00g"
data = "sine_4hz_1p00g.csv"
excitation = { kind = "sine", freq_hz = 4.0, amp_g = 1.0, taper_s = 1.0 }
"#;

const FILES: [&str; 2] = ["sine_3hz_1p73g.csv", "sine_4hz_1p00g.csv"];

/// The campaign's files made by `study synth` in `dir` (created), with `extra` options.
fn synth(dir: &Path, extra: &[&str]) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let c = dir.join("real.toml");
    std::fs::write(&c, CAMPAIGN).unwrap();
    let mut args = vec!["synth", c.to_str().unwrap(), "--out", dir.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = study(&args);
    assert_eq!(code, 0, "{stdout}{stderr}");
    c
}

/// A CSV file as text cells.
#[derive(Clone)]
struct Csv {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Csv {
    fn read(path: &Path) -> Csv {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let header = lines
            .next()
            .unwrap()
            .split(',')
            .map(str::to_string)
            .collect();
        let rows = lines
            .map(|l| l.split(',').map(str::to_string).collect())
            .collect();
        Csv { header, rows }
    }
    fn write(&self, path: &Path, sep: &str) {
        let mut s = self.header.join(sep) + "\n";
        for r in &self.rows {
            s.push_str(&r.join(sep));
            s.push('\n');
        }
        std::fs::write(path, s).unwrap();
    }
    fn col(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }
    /// Applies `f` to every cell of column `name`.
    fn map(&mut self, name: &str, f: impl Fn(f64) -> String) {
        let c = self.col(name);
        for r in &mut self.rows {
            r[c] = f(r[c].parse().unwrap());
        }
    }
}

/// `v` printed with `d` significant digits, as a DAQ export does (`%.{d}g`).
fn sig(v: f64, d: usize) -> String {
    format!("{:.*e}", d - 1, v)
        .parse::<f64>()
        .unwrap()
        .to_string()
}

/// Copies the campaign in `from` to `to`, each data file transformed by `f`.
fn transform(from: &Path, to: &Path, f: impl Fn(&mut Csv)) -> PathBuf {
    std::fs::create_dir_all(to).unwrap();
    std::fs::copy(from.join("real.toml"), to.join("real.toml")).unwrap();
    for name in FILES {
        let mut csv = Csv::read(&from.join(name));
        f(&mut csv);
        csv.write(&to.join(name), ",");
    }
    to.join("real.toml")
}

/// The compare results of a campaign: one row per test of the tests table, and the console.
struct Results {
    stdout: String,
    report: PathBuf,
}

impl Results {
    fn col(&self, name: &str) -> Vec<f64> {
        let t = vshake::shell::formats::measured_files::read_columns_allow_nan(
            &self.report.join("tests.parquet"),
            &[name],
        )
        .unwrap();
        t.column(name).unwrap().to_vec()
    }
}

fn compare(campaign: &Path, extra: &[&str]) -> Results {
    let report = campaign.parent().unwrap().join("report");
    let mut args = vec![
        "compare",
        campaign.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = study(&args);
    assert_eq!(code, 0, "{stdout}{stderr}");
    Results { stdout, report }
}

/// Columns of the tests table that must not move with the file's layout.
const RESULT_COLUMNS: [&str; 7] = [
    "amp_ratio_measured",
    "amp_ratio_model",
    "phase_measured_deg",
    "phase_model_deg",
    "h3_measured_ratio",
    "rms_residual_accel_ratio",
    "rms_residual_disp_ratio",
];

fn assert_same(a: &Results, b: &Results, tol: f64, what: &str) {
    for c in RESULT_COLUMNS {
        for (x, y) in a.col(c).iter().zip(b.col(c)) {
            assert!((x - y).abs() <= tol, "{what}: {c} {x} vs clean {y}");
        }
    }
}

/// Time printed with 6, 7 and 9 significant digits: read, the grid rebuilt from the row index,
/// and the results are the clean file's exactly; the console says that rounding was the cause.
#[test]
fn rounded_time_is_rebuilt_and_gives_the_clean_results() {
    let d = tempfile::tempdir().unwrap();
    let clean = synth(&d.path().join("clean"), &[]);
    let base = compare(&clean, &[]);
    for digits in [6, 7, 9] {
        let c = transform(
            &d.path().join("clean"),
            &d.path().join(format!("t{digits}")),
            |csv| csv.map("time_s", |t| sig(t, digits)),
        );
        let r = compare(&c, &[]);
        assert_same(&r, &base, 1e-12, &format!("{digits} digits"));
        assert!(
            r.stdout.contains("consistent with rounding to")
                && r.stdout.contains("the grid was rebuilt"),
            "{}",
            r.stdout
        );
        assert_eq!(r.col("rate_hz"), vec![1024.0, 1024.0]);
    }
}

/// Files at 256, 500 and 2048 Hz (500 is not a whole ratio of the 1024 Hz controller): the
/// model, sampled at the file's own instants, reproduces a finer-integrated truth to 1e-5 of
/// the signal, and the amplitude ratio and phase agree with the controller-rate file's.
#[test]
fn other_sample_rates_are_compared_on_their_own_samples() {
    let d = tempfile::tempdir().unwrap();
    let base = compare(&synth(&d.path().join("clean"), &[]), &[]);
    for rate in ["256", "500", "2048"] {
        let r = compare(&synth(&d.path().join(rate), &["--rate", rate]), &[]);
        assert_eq!(r.col("rate_hz"), vec![rate.parse::<f64>().unwrap(); 2]);
        for c in [
            "rms_residual_accel_ratio",
            "rms_residual_disp_ratio",
            "rms_residual_force_ratio",
        ] {
            for v in r.col(c) {
                assert!(v < 1e-5, "{rate} Hz: {c} = {v}");
            }
        }
        // The acceleration sampled off the ticks aliases the controller-rate ripple (no
        // anti-aliasing filter in synth): a few 1e-4 of the fundamental.
        for (c, tol) in [
            ("amp_ratio_measured", 1e-3),
            ("phase_measured_deg", 0.05),
            ("h3_measured_ratio", 1e-3),
        ] {
            for (x, y) in r.col(c).iter().zip(base.col(c)) {
                assert!((x - y).abs() < tol, "{rate} Hz: {c} {x} vs {y} at 1024 Hz");
            }
        }
    }
}

/// A harmonic at or above the file's Nyquist frequency is left out with a note, and neither
/// the tables' NaN nor anything else reaches the report as a number.
#[test]
fn harmonics_above_nyquist_are_left_out_and_never_drawn() {
    let d = tempfile::tempdir().unwrap();
    let r = compare(&synth(d.path(), &["--rate", "50"]), &[]);
    assert!(
        r.stdout
            .contains("at or above the Nyquist frequency of a 50 Hz file (25 Hz): left out"),
        "{}",
        r.stdout
    );
    // 3 Hz: h9 (27 Hz) is out, h8 (24 Hz) is in; 4 Hz: h7 (28 Hz) and up are out.
    let h9 = r.col("h9_measured_ratio");
    assert!(h9[0].is_nan() && h9[1].is_nan());
    assert!(
        r.col("h8_measured_ratio")[0].is_finite()
            && r.col("h6_measured_ratio")[1].is_finite()
            && r.col("h7_measured_ratio")[1].is_nan()
    );
    let html = std::fs::read_to_string(r.report.join("report.html")).unwrap();
    for bad in ["NaN", "inf"] {
        assert!(!html.contains(bad), "the report shows {bad}");
    }
}

/// 0.5 s at rest before the excitation, 1 s at rest after it, and a clock that starts at
/// 1000 s: the start and end are found, reported, and the results are the clean file's.
#[test]
fn pre_trigger_extra_length_and_time_origin_are_found() {
    let d = tempfile::tempdir().unwrap();
    let base = compare(&synth(&d.path().join("clean"), &[]), &[]);
    // synth's own pre-trigger.
    let pre = compare(
        &synth(&d.path().join("pre"), &["--pre-trigger", "0.5"]),
        &[],
    );
    assert_same(&pre, &base, 1e-9, "pre-trigger");
    assert_eq!(pre.col("start_s"), vec![0.5, 0.5]);
    assert_eq!(pre.col("start_row"), vec![513.0, 513.0]);
    assert!(
        pre.stdout
            .contains("the excitation starts at t = 0.5000 s (row 513; found from ref_disp_m)"),
        "{}",
        pre.stdout
    );
    // 1 s at rest appended (the reference back at 0, the sensors at their last value).
    let post = transform(&d.path().join("clean"), &d.path().join("post"), |csv| {
        let (t, x) = (csv.col("time_s"), csv.col("ref_disp_m"));
        let last = csv.rows.last().unwrap().clone();
        let n = csv.rows.len();
        for i in 0..1024 {
            let mut row = last.clone();
            row[t] = format!("{:?}", (n + i) as f64 / 1024.0);
            row[x] = "0".into();
            csv.rows.push(row);
        }
    });
    let post = compare(&post, &[]);
    assert_same(&post, &base, 1e-9, "1 s longer");
    assert_eq!(post.col("end_s"), vec![3.0, 3.0]);
    assert!(
        post.stdout.contains("the excitation ends at t = 3.0000 s"),
        "{}",
        post.stdout
    );
    // Another time origin.
    let late = transform(&d.path().join("clean"), &d.path().join("late"), |csv| {
        csv.map("time_s", |t| format!("{:?}", t + 1000.0))
    });
    let late = compare(&late, &[]);
    assert_same(&late, &base, 1e-9, "time from 1000 s");
    assert_eq!(late.col("start_s"), vec![1000.0, 1000.0]);
    // `t0_s` in the campaign overrides the search.
    let given = d.path().join("pre/given.toml");
    std::fs::write(
        &given,
        CAMPAIGN.replace("taper_s = 1.0 }", "taper_s = 1.0 }\nt0_s = 0.5"),
    )
    .unwrap();
    let (code, stdout, stderr) = study(&["compare", given.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("0.5000 s (row 513, t0_s)"), "{stdout}");
    // Too short for the analysis window: an error naming the test.
    let short = transform(&d.path().join("clean"), &d.path().join("short"), |csv| {
        csv.rows.truncate(1500)
    });
    let (code, _, stderr) = study(&["compare", short.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("sine_3hz_1p73g") && stderr.contains("too short"),
        "{stderr}"
    );
}

/// Issue 27: a table homed 10 mm off zero (`ref_disp_m` and `disp_m` offset by 10 mm, 1 s at
/// rest before the excitation, sensor noise): the same start, phases within 0.1° of the clean
/// file's, and a note naming the offset of each column.
#[test]
fn a_static_offset_is_found_removed_and_named() {
    let d = tempfile::tempdir().unwrap();
    let noise = ["--pre-trigger", "1.0", "--noise", "accel=0.05,disp=2e-5"];
    let base = compare(&synth(&d.path().join("clean"), &noise), &[]);
    let off = transform(&d.path().join("clean"), &d.path().join("off"), |csv| {
        for c in ["ref_disp_m", "disp_m"] {
            csv.map(c, |x| format!("{:?}", x + 0.010));
        }
    });
    let off = compare(&off, &[]);
    assert_eq!(off.col("start_row"), base.col("start_row"));
    assert_eq!(base.col("start_s"), vec![1.0, 1.0]);
    for c in ["phase_measured_deg", "phase_model_deg"] {
        for (x, y) in off.col(c).iter().zip(base.col(c)) {
            assert!(
                (x - y).abs() <= 0.1,
                "{c}: {x}° with the offset, {y}° clean"
            );
        }
    }
    for c in ["ref_disp_m rests at +10.0", "disp_m rests at +10.0"] {
        assert!(
            off.stdout.contains(c) && off.stdout.contains("a static offset"),
            "{c}:\n{}",
            off.stdout
        );
    }
    // The clean files have none to remove.
    assert!(!base.stdout.contains("static offset"), "{}", base.stdout);
}

/// The same offset in files that start with the excitation (no quiet lead to measure it over):
/// found from the reference's departure from the campaign's sine, removed from both columns,
/// named; the start, the phases and the displacement residual as in the clean files.
#[test]
fn a_static_offset_without_a_quiet_lead_is_found_from_the_sine() {
    let d = tempfile::tempdir().unwrap();
    let noise = ["--noise", "accel=0.05,disp=2e-5"];
    let base = compare(&synth(&d.path().join("clean"), &noise), &[]);
    let off = transform(&d.path().join("clean"), &d.path().join("off"), |csv| {
        for c in ["ref_disp_m", "disp_m"] {
            csv.map(c, |x| format!("{:?}", x - 0.010));
        }
    });
    let off = compare(&off, &[]);
    assert_eq!(off.col("start_row"), base.col("start_row"));
    for c in ["phase_measured_deg", "phase_model_deg"] {
        for (x, y) in off.col(c).iter().zip(base.col(c)) {
            assert!(
                (x - y).abs() <= 0.1,
                "{c}: {x}° with the offset, {y}° clean"
            );
        }
    }
    for (x, y) in off
        .col("rms_residual_disp_ratio")
        .iter()
        .zip(base.col("rms_residual_disp_ratio"))
    {
        assert!(
            (x / y - 1.0).abs() < 0.01,
            "residual x {x} with the offset, {y} clean"
        );
    }
    assert!(
        off.stdout.contains("ref_disp_m is offset by -10.0"),
        "{}",
        off.stdout
    );
    assert!(!base.stdout.contains("static offset"), "{}", base.stdout);
}

/// A displacement transducer not zeroed (`disp_m` alone 2 mm off) in files that start with the
/// excitation: measured where the reference rests at zero, removed, named; the displacement
/// residual as in the clean files.
#[test]
fn a_feedback_offset_without_a_quiet_lead_is_found_where_the_reference_rests() {
    let d = tempfile::tempdir().unwrap();
    let noise = ["--noise", "accel=0.05,disp=2e-5"];
    let base = compare(&synth(&d.path().join("clean"), &noise), &[]);
    let off = transform(&d.path().join("clean"), &d.path().join("off"), |csv| {
        csv.map("disp_m", |x| format!("{:?}", x + 0.002));
    });
    let off = compare(&off, &[]);
    assert_eq!(off.col("start_row"), base.col("start_row"));
    // The offset removed is 2 mm to within 4 standard errors of a median of the noise (σ 2e-5 m)
    // over the rows it was measured on.
    let note = off.stdout.split("disp_m is ").nth(1).expect(&off.stdout);
    let mm: f64 = note.split(" mm").next().unwrap().parse().unwrap();
    let rows: f64 = note
        .split("its first ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let se = 1.25 * 2e-5 / rows.sqrt();
    assert!(
        (mm * 1e-3 - 0.002).abs() < 4.0 * se,
        "{mm} mm over {rows} rows"
    );
    assert!(note.contains("where the reference rests"), "{}", off.stdout);
    for (x, y) in off
        .col("phase_measured_deg")
        .iter()
        .zip(base.col("phase_measured_deg"))
    {
        assert!(
            (x - y).abs() <= 0.1,
            "phase {x}° with the offset, {y}° clean"
        );
    }
    assert!(!base.stdout.contains("from ref_disp_m"), "{}", base.stdout);
}

/// Columns in another order, columns vshake does not read, `;` with decimal commas and tabs:
/// the clean results exactly, and a note on the separator.
#[test]
fn column_order_extra_columns_and_separators_do_not_matter() {
    let d = tempfile::tempdir().unwrap();
    let clean_dir = d.path().join("clean");
    let base = compare(&synth(&clean_dir, &[]), &[]);
    let shuffled = transform(&clean_dir, &d.path().join("shuffled"), |csv| {
        let order: Vec<usize> = vec![3, 0, 8, 1, 5, 2, 7, 4, 6];
        assert_eq!(csv.header.len(), order.len());
        fn pick(order: &[usize], r: &[String]) -> Vec<String> {
            order.iter().map(|&i| r[i].clone()).collect()
        }
        csv.header = pick(&order, &csv.header);
        csv.rows = csv.rows.iter().map(|r| pick(&order, r)).collect();
        csv.header.insert(2, "temperature_c".into());
        csv.header.push("channel_17_raw".into());
        for (i, r) in csv.rows.iter_mut().enumerate() {
            r.insert(2, format!("{}", 21.5 + 1e-3 * i as f64));
            r.push(format!("{}", i % 4096));
        }
    });
    assert_same(&compare(&shuffled, &[]), &base, 0.0, "columns reordered");
    for (dir, sep, comma, word) in [
        ("semi", ";", true, "semicolon"),
        ("tab", "\t", false, "tab"),
    ] {
        let to = d.path().join(dir);
        std::fs::create_dir_all(&to).unwrap();
        std::fs::copy(clean_dir.join("real.toml"), to.join("real.toml")).unwrap();
        for name in FILES {
            let mut csv = Csv::read(&clean_dir.join(name));
            if comma {
                for r in &mut csv.rows {
                    for v in r.iter_mut() {
                        *v = v.replace('.', ",");
                    }
                }
            }
            csv.write(&to.join(name), sep);
        }
        let r = compare(&to.join("real.toml"), &[]);
        assert_same(&r, &base, 0.0, word);
        assert!(
            r.stdout
                .contains(&format!("read as {word}-separated values")),
            "{}",
            r.stdout
        );
    }
}

/// Files that read fine but are the wrong science get a warning naming the test and the likely
/// cause; `--strict` makes each an error (exit 2). Results still come out.
#[test]
fn wrong_files_get_a_warning_that_names_test_and_cause() {
    let d = tempfile::tempdir().unwrap();
    let clean = d.path().join("clean");
    synth(&clean, &[]);
    type Mangle = Box<dyn Fn(&Path, &Path)>;
    let cases: Vec<(&str, Mangle, Vec<&str>)> = vec![
        (
            "4 Hz file under a 3 Hz test",
            Box::new(|from: &Path, to: &Path| {
                std::fs::copy(from.join("sine_4hz_1p00g.csv"), to.join("sine_3hz_1p73g.csv")).unwrap();
            }),
            vec!["test \"sine_3hz_1p73g\": ref_disp_m does not match the campaign's excitation (sine 3 Hz", "4.000 Hz", "the file of another test?"],
        ),
        ("acceleration in g", Box::new(scale_column("accel_mps2", 1.0 / 9.80665)), vec!["likely the acceleration is in g"]),
        ("flipped acceleration", Box::new(scale_column("accel_mps2", -1.0)), vec!["`accel_mps2` is in antiphase with the reference", "a flipped sign?"]),
        ("reference 20 % too large", Box::new(scale_column("ref_disp_m", 1.2)), vec!["ref_disp_m does not match the campaign's excitation"]),
    ];
    for (i, (what, make, needles)) in cases.iter().enumerate() {
        let to = d.path().join(format!("case{i}"));
        std::fs::create_dir_all(&to).unwrap();
        for f in ["real.toml", FILES[0], FILES[1]] {
            std::fs::copy(clean.join(f), to.join(f)).unwrap();
        }
        make(&clean, &to);
        let c = to.join("real.toml");
        let (code, stdout, stderr) = study(&["compare", c.to_str().unwrap()]);
        assert_eq!(code, 0, "{what}: {stderr}");
        assert!(
            stderr.contains("warning(s) about the measured data"),
            "{what}: {stderr}"
        );
        for n in needles {
            assert!(stdout.contains(n), "{what}: expected {n:?} in\n{stdout}");
        }
        assert!(
            stdout.contains("sine_3hz_1p73g"),
            "{what}: results still come out"
        );
        let (code, _, stderr) = study(&["compare", c.to_str().unwrap(), "--strict"]);
        assert_eq!(code, 2, "{what} under --strict: {stderr}");
        assert!(
            stderr.contains(needles[0]),
            "{what} under --strict: {stderr}"
        );
    }
    // A displacement in mm at a 47.7 mm amplitude is beyond any stroke: an error with the cause.
    let to = d.path().join("mm");
    transform(&clean, &to, |csv| {
        csv.map("disp_m", |v| format!("{:?}", v * 1000.0))
    });
    let (code, _, stderr) = study(&["compare", to.join("real.toml").to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("sine_3hz_1p73g.csv: column `disp_m`")
            && stderr.contains("beyond any physical range")
            && stderr.contains("mm?"),
        "{stderr}"
    );
}

/// Multiplies column `name` of the 3 Hz test's file by `k`.
fn scale_column(name: &'static str, k: f64) -> impl Fn(&Path, &Path) {
    move |from: &Path, to: &Path| {
        let mut csv = Csv::read(&from.join(FILES[0]));
        csv.map(name, |v| format!("{:?}", v * k));
        csv.write(&to.join(FILES[0]), ",");
    }
}

/// Every data problem of a campaign in one pass, exit 2: a gap named at its own row, a missing
/// file said once, a NaN and a 1e300 in one file, an empty file, a file with no data rows.
#[test]
fn every_data_problem_of_a_campaign_at_once() {
    let d = tempfile::tempdir().unwrap();
    let clean = d.path().join("clean");
    synth(&clean, &[]);
    let bad = d.path().join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    let text = CAMPAIGN.to_string()
        + "\n[[test]]\nname = \"missing\"\ndata = \"missing.csv\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.0 }\n"
        + "\n[[test]]\nname = \"empty\"\ndata = \"empty.csv\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.0 }\n";
    std::fs::write(bad.join("real.toml"), text).unwrap();
    std::fs::write(bad.join("empty.csv"), "").unwrap();
    // A gap: rows 500 … 509 dropped, so data row 500 is the first after the gap.
    let mut a = Csv::read(&clean.join(FILES[0]));
    a.rows.drain(499..509);
    a.write(&bad.join(FILES[0]), ",");
    // NaN and 1e300 in the other file.
    let mut b = Csv::read(&clean.join(FILES[1]));
    let (x, acc) = (b.col("disp_m"), b.col("accel_mps2"));
    b.rows[99][x] = "NaN".into();
    b.rows[199][acc] = "1e300".into();
    b.write(&bad.join(FILES[1]), ",");
    let (code, _, stderr) = study(&["compare", bad.join("real.toml").to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    for n in [
        "5 problems in the measured data of",
        "sine_3hz_1p73g.csv: column `time_s`, row 500 (line 501): time jumps",
        "10 row(s) missing before this row",
        "sine_4hz_1p00g.csv: column `disp_m`, row 100 (line 101): NaN is not a finite number",
        "sine_4hz_1p00g.csv: column `accel_mps2`, row 200 (line 201): 1e300 is beyond any physical range",
        "missing.csv: not found",
        "empty.csv: the file is empty",
    ] {
        assert!(stderr.contains(n), "expected {n:?} in\n{stderr}");
    }
    assert_eq!(
        stderr.matches("not found").count(),
        1,
        "said once: {stderr}"
    );
    // The same under fit and diagnose (they read through the same path).
    for cmd in ["fit", "diagnose"] {
        let c = bad.join("real.toml");
        let mut args = vec![cmd, c.to_str().unwrap()];
        if cmd == "fit" {
            args.extend(["--effect", "seal_friction"]);
        }
        let (code, _, stderr) = study(&args);
        assert_eq!(code, 2, "{cmd}: {stderr}");
        assert!(
            stderr.contains("5 problems in the measured data of"),
            "{cmd}: {stderr}"
        );
    }
}

/// docs/formats.md describes every key the campaign file accepts; README and `--help` point to
/// the repository's docs, which exist.
#[test]
fn the_docs_describe_every_campaign_key() {
    use vshake::orchestration::measured::campaign;
    use vshake::orchestration::runs::spec;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let formats = std::fs::read_to_string(root.join("docs/formats.md")).expect("docs/formats.md");
    assert!(root.join("docs/model.md").is_file(), "docs/model.md");
    for key in campaign::CAMPAIGN_KEYS
        .iter()
        .chain(&campaign::TEST_KEYS)
        .chain(&campaign::WEIGHT_KEYS)
        .chain(&campaign::COLUMN_KEYS)
        .chain(&spec::SINE_KEYS)
        .chain(&spec::RECORD_KEYS)
    {
        assert!(
            formats.contains(&format!("`{key}`")),
            "docs/formats.md does not describe `{key}`"
        );
    }
    let (code, help, _) = study(&["--help"]);
    assert_eq!(code, 0);
    assert!(
        help.contains("docs/model.md") && help.contains("docs/formats.md"),
        "{help}"
    );
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(readme.contains("docs/model.md") && readme.contains("docs/formats.md"));
    for text in [&readme, &help] {
        for stray in ["(FORMATS.md", "(MODEL.md", " FORMATS.md", " MODEL.md"] {
            assert!(
                !text.contains(stray),
                "points to {stray:?} outside the repository"
            );
        }
    }
}

/// The diagnosis of a campaign with a hidden effect is the same on the clean files and on their
/// re-export at 256 Hz with time at 6 significant digits and a 0.5 s pre-trigger: the same
/// verdict and the fitted values within their standard errors.
#[test]
fn diagnosis_of_a_re_exported_campaign_is_the_clean_ones() {
    let d = tempfile::tempdir().unwrap();
    let noise = "accel=0.05,disp=2e-5";
    let clean = synth(
        &d.path().join("clean"),
        &["--effect", "seal_friction", "--noise", noise],
    );
    let re = synth(
        &d.path().join("re_raw"),
        &[
            "--effect",
            "seal_friction",
            "--noise",
            noise,
            "--rate",
            "256",
            "--pre-trigger",
            "0.5",
        ],
    );
    let re = transform(re.parent().unwrap(), &d.path().join("re"), |csv| {
        csv.map("time_s", |t| sig(t, 6))
    });
    let run = |c: &Path| {
        let report = c.parent().unwrap().join("report");
        let (code, stdout, stderr) = study(&[
            "diagnose",
            c.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stderr}");
        // The verdict and the candidate's estimates from the report's tables.
        use vshake::shell::formats::{meta, parquet_read};
        let verdict = meta::get(
            &parquet_read::parquet_metadata(&report.join("candidates.parquet")).unwrap(),
            meta::Key::Verdict,
        )
        .unwrap()
        .to_string();
        let cands = report.join("candidates.parquet");
        let effects = parquet_read::read_strings(&cands, "effect").unwrap();
        let i = effects
            .iter()
            .position(|e| e == "seal_friction")
            .unwrap_or_else(|| panic!("{effects:?}"));
        let (est, se) = (
            parquet_read::read_f64_lists(&cands, "estimates").unwrap(),
            parquet_read::read_f64_lists(&cands, "std_errors").unwrap(),
        );
        let fitted: Vec<(f64, f64)> = est[i].iter().copied().zip(se[i].iter().copied()).collect();
        (verdict, fitted, stdout)
    };
    let (v0, f0, out0) = run(&clean);
    let (v1, f1, out1) = run(&re);
    assert!(
        v0.contains("most likely missing: seal_friction (friction)"),
        "{out0}"
    );
    assert!(
        v1.contains("most likely missing: seal_friction (friction)"),
        "{out1}"
    );
    assert_eq!(f0.len(), 2);
    for ((a, sa), (b, sb)) in f0.iter().zip(&f1) {
        // Two independent noise draws: the difference has the combined standard error.
        assert!(
            (a - b).abs() <= 3.0 * sa.hypot(*sb),
            "{a} ± {sa} vs {b} ± {sb}\n{out0}\n{out1}"
        );
    }
}

/// Issue 27: column names and units as a lab's system writes them. Each variant is read to the
/// clean file's results (within the rounding of the unit conversion), with a note saying what
/// was read: units in brackets and parentheses, upper case, MATLAB `writetable` names, a units
/// row, a preamble, space, tab and semicolon separators, g, mm, ms, kN, bar.
#[test]
fn lab_headers_and_units_are_read_to_the_si_results() {
    let d = tempfile::tempdir().unwrap();
    let clean_dir = d.path().join("clean");
    let base = compare(&synth(&clean_dir, &[]), &[]);
    let g = 9.80665;
    // (folder, separator, header per SI column, factor SI → file unit, units row, preamble lines)
    type Variant = (
        &'static str,
        &'static str,
        [&'static str; 5],
        [f64; 5],
        Option<&'static str>,
        usize,
    );
    let variants: [Variant; 8] = [
        (
            "brackets",
            ",",
            [
                "Time (s)",
                "Ref Disp [mm]",
                "Disp (mm)",
                "Accel (g)",
                "P1 (bar)",
            ],
            [1.0, 1e3, 1e3, 1.0 / g, 1e-5],
            None,
            0,
        ),
        (
            "upper",
            ",",
            ["TIME_S", "REF_DISP_M", "DISP_M", "ACCEL_MPS2", "P1_PA"],
            [1.0; 5],
            None,
            0,
        ),
        (
            "matlab",
            ",",
            ["Time", "RefDisp", "Disp", "Accel", "p1"],
            [1.0; 5],
            None,
            0,
        ),
        (
            "unitsrow",
            ",",
            [
                "Time",
                "Reference Displacement",
                "Displacement",
                "Acceleration",
                "Pressure 1",
            ],
            [1.0, 1e3, 1e3, 1.0 / g, 1e-5],
            Some("s,mm,mm,g,bar"),
            0,
        ),
        (
            "preamble",
            ",",
            [
                "Time (s)",
                "Command Position (mm)",
                "Position (mm)",
                "Accel (m/s^2)",
                "P1 (MPa)",
            ],
            [1.0, 1e3, 1e3, 1.0, 1e-6],
            None,
            5,
        ),
        (
            "space",
            " ",
            ["time_s", "ref_disp_mm", "disp_mm", "accel_g", "p1_bar"],
            [1.0, 1e3, 1e3, 1.0 / g, 1e-5],
            None,
            0,
        ),
        (
            "tab",
            "\t",
            [
                "Time (ms)",
                "Ref Disp (mm)",
                "Disp (mm)",
                "Accel (g)",
                "P1 (psi)",
            ],
            [1e3, 1e3, 1e3, 1.0 / g, 1.0 / 6894.757293168361],
            None,
            0,
        ),
        (
            "semicolon",
            ";",
            [
                "Time [s]",
                "Target Disp [mm]",
                "Table Disp [mm]",
                "Table Accel [g]",
                "P1 [kPa]",
            ],
            [1.0, 1e3, 1e3, 1.0 / g, 1e-3],
            None,
            0,
        ),
    ];
    let si = ["time_s", "ref_disp_m", "disp_m", "accel_mps2", "p1_pa"];
    for (dir, sep, header, k, units, preamble) in variants {
        let to = d.path().join(dir);
        std::fs::create_dir_all(&to).unwrap();
        std::fs::copy(clean_dir.join("real.toml"), to.join("real.toml")).unwrap();
        for name in FILES {
            let csv = Csv::read(&clean_dir.join(name));
            let mut text = String::new();
            for i in 0..preamble {
                text.push_str(&format!(
                    "Export line {i}: lab DAQ v2, channel list below\n"
                ));
            }
            text.push_str(&(header.join(sep) + "\n"));
            if let Some(u) = units {
                text.push_str(&(u.replace(',', sep) + "\n"));
            }
            let cols: Vec<usize> = si.iter().map(|c| csv.col(c)).collect();
            for r in &csv.rows {
                let cells: Vec<String> = (cols.iter().zip(&k))
                    .map(|(&c, f)| format!("{:e}", r[c].parse::<f64>().unwrap() * f))
                    .collect();
                text.push_str(&(cells.join(sep) + "\n"));
            }
            std::fs::write(to.join(name), text).unwrap();
        }
        let r = compare(&to.join("real.toml"), &[]);
        assert_same(&r, &base, 1e-9, dir);
        if dir != "upper" {
            assert!(
                r.stdout.contains("read as accel_mps2"),
                "{dir}: {}",
                r.stdout
            );
        }
    }
}

/// Issue 27: names the reader does not recognise, mapped by the campaign's `columns` table (by
/// header, with their units), and a MATLAB `save -ascii` file (no header, columns separated by
/// runs of spaces, 8 significant digits) mapped by position: read to the clean file's results
/// (within the digits written), with a note naming what was read.
#[test]
fn a_columns_table_maps_headers_and_positions() {
    let d = tempfile::tempdir().unwrap();
    let clean_dir = d.path().join("clean");
    let base = compare(&synth(&clean_dir, &[]), &[]);
    let g = 9.80665;
    let si = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
    let k = [1.0, 1e3, 1e3, 1.0 / g];
    let by_name = "columns = { time = \"Zeit\", ref_disp = { name = \"Soll\", unit = \"mm\" }, \
                   disp = { name = \"Ist\", unit = \"mm\" }, accel = { name = \"A1 Table X\", unit = \"g\" } }";
    let by_position = "columns = { time = { column = 1, unit = \"s\" }, \
                       ref_disp = { column = 2, unit = \"mm\" }, disp = { column = 3, unit = \"mm\" }, \
                       accel = { column = 4, unit = \"g\" } }";
    let variants = [
        ("mapped", Some("Zeit,Soll,Ist,A1 Table X"), by_name, 1e-9),
        ("ascii", None, by_position, 1e-6),
    ];
    for (dir, header, columns, tol) in variants {
        let to = d.path().join(dir);
        std::fs::create_dir_all(&to).unwrap();
        let campaign = CAMPAIGN.replace(
            "name = \"real\"\n",
            &format!("name = \"real\"\n{columns}\n"),
        );
        std::fs::write(to.join("real.toml"), campaign).unwrap();
        for name in FILES {
            let csv = Csv::read(&clean_dir.join(name));
            let mut text = header.map_or(String::new(), |h| format!("{h}\n"));
            let cols: Vec<usize> = si.iter().map(|c| csv.col(c)).collect();
            for r in &csv.rows {
                let cells: Vec<String> = (cols.iter().zip(&k))
                    .map(|(&c, f)| {
                        let v = r[c].parse::<f64>().unwrap() * f;
                        if header.is_some() {
                            format!("{v:e}")
                        } else {
                            format!("{v:15.7e}")
                        }
                    })
                    .collect();
                text.push_str(&(cells.join(if header.is_some() { "," } else { " " }) + "\n"));
            }
            std::fs::write(to.join(name), text).unwrap();
        }
        let r = compare(&to.join("real.toml"), &[]);
        assert_same(&r, &base, tol, dir);
        assert!(
            r.stdout.contains("read as accel_mps2"),
            "{dir}: {}",
            r.stdout
        );
    }
    // A channel the file does not have, a key that is no channel, a unit vshake does not know:
    // each named.
    let to = d.path().join("mapped");
    let bad = CAMPAIGN.replace(
        "name = \"real\"\n",
        "name = \"real\"\ncolumns = { accel = { name = \"A9\", unit = \"g\" }, acel = \"x\", disp = { name = \"Ist\", unit = \"furlongs\" } }\n",
    );
    std::fs::write(to.join("bad.toml"), bad).unwrap();
    let (code, _, err) = study(&["compare", to.join("bad.toml").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("campaign.columns.acel") && err.contains("furlongs"),
        "{err}"
    );
}

/// Issue 27: a unit vshake does not know, or of another quantity, is refused with one line
/// naming the file, the column and the cause.
#[test]
fn unknown_units_are_refused_naming_file_and_column() {
    let d = tempfile::tempdir().unwrap();
    let clean_dir = d.path().join("clean");
    synth(&clean_dir, &[]);
    for (header, needle) in [
        (
            "Accel (furlongs/s^2)",
            "column `Accel (furlongs/s^2)`: unknown unit `furlongs/s^2`",
        ),
        (
            "Accel (mm)",
            "column `Accel (mm)` read as `accel_mps2`, but its unit `mm` is not one of m/s²",
        ),
    ] {
        let c = transform(&clean_dir, &d.path().join("bad"), |csv| {
            let i = csv.col("accel_mps2");
            csv.header[i] = header.to_string();
        });
        let (code, _, stderr) = study(&["compare", c.to_str().unwrap()]);
        assert_eq!(code, 2, "{stderr}");
        assert!(
            stderr.contains("sine_3hz_1p73g.csv: ") && stderr.contains(needle),
            "{stderr}"
        );
    }
}

/// A level 5 MAT-file of double column vectors: vshake's writer (`study synth`, as MATLAB's
/// `save -v6`), or with each variable zlib-compressed as MATLAB's `save -v7` writes it
/// [MathWorks, "MAT-File Format": an miCOMPRESSED element (15) holding the miMATRIX one]. (The
/// reader is checked against SciPy-written files in tests/matlab.rs.)
fn write_mat(path: &Path, vars: &[(&str, Vec<f64>)], compress: bool) {
    let v: Vec<(&str, &[f64])> = vars.iter().map(|(n, v)| (*n, v.as_slice())).collect();
    let v5 = vshake::shell::formats::matlab::v5_bytes(&v);
    if !compress {
        return std::fs::write(path, v5).unwrap();
    }
    let mut out = v5[..128].to_vec();
    let mut at = 128;
    while at < v5.len() {
        let size = u32::from_le_bytes(v5[at + 4..at + 8].try_into().unwrap()) as usize;
        use std::io::Write;
        let mut z = libflate::zlib::Encoder::new(Vec::new()).unwrap();
        z.write_all(&v5[at..at + 8 + size]).unwrap();
        let packed = z.finish().into_result().unwrap();
        out.extend(15u32.to_le_bytes());
        out.extend((packed.len() as u32).to_le_bytes());
        out.extend(packed);
        at += 8 + size;
    }
    std::fs::write(path, out).unwrap();
}

/// Issue 27: the campaign's files saved as MATLAB MAT-files, v5 (MATLAB names, SI) and v7
/// (compressed; units in the names: mm, g): read to the clean file's results, with a note.
#[test]
fn matlab_files_are_read_to_the_si_results() {
    let d = tempfile::tempdir().unwrap();
    let clean_dir = d.path().join("clean");
    let base = compare(&synth(&clean_dir, &[]), &[]);
    let g = 9.80665;
    let si = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
    let variants = [
        (
            "v5",
            ["Time", "RefDisp", "Disp", "Accel"],
            [1.0; 4],
            false,
            0.0,
        ),
        (
            "v7",
            ["t", "ref_disp_mm", "disp_mm", "accel_g"],
            [1.0, 1e3, 1e3, 1.0 / g],
            true,
            1e-9,
        ),
    ];
    for (dir, names, k, compress, tol) in variants {
        let to = d.path().join(dir);
        std::fs::create_dir_all(&to).unwrap();
        std::fs::write(to.join("real.toml"), CAMPAIGN.replace(".csv", ".mat")).unwrap();
        for name in FILES {
            let csv = Csv::read(&clean_dir.join(name));
            let vars: Vec<(&str, Vec<f64>)> = (si.iter().zip(names).zip(k))
                .map(|((c, n), f)| {
                    let i = csv.col(c);
                    (
                        n,
                        csv.rows
                            .iter()
                            .map(|r| r[i].parse::<f64>().unwrap() * f)
                            .collect(),
                    )
                })
                .collect();
            write_mat(&to.join(name.replace(".csv", ".mat")), &vars, compress);
        }
        let r = compare(&to.join("real.toml"), &[]);
        assert_same(&r, &base, tol, dir);
        let says = if compress {
            "MAT-file (v7, compressed)"
        } else {
            "MAT-file (v5)"
        };
        assert!(r.stdout.contains(says), "{dir}: {}", r.stdout);
        assert!(
            r.stdout.contains("read as accel_mps2"),
            "{dir}: {}",
            r.stdout
        );
    }
}
