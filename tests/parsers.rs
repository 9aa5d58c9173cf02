//! Property tests of every parser a user's file meets: the study TOML, the campaign TOML, and
//! measured tests as CSV, Parquet and MATLAB MAT-files (SciPy-written v5 and v7 seeds). Random
//! bytes, random byte mutations of valid files and random values put into valid files never
//! panic; each ends either accepted or refused as bad input (exit code 2) with a message that
//! names the file.
//!
//! `cargo test` runs 256 cases per property (`PROPTEST_CASES` sets another count); CI's property
//! step sizes them by time instead (`VSHAKE_PROPTEST_SECONDS=10 cargo test --release --test
//! parsers`: rounds of 256 cases until 10 s have passed, per property), so that the step's time
//! does not grow with the parsers' speed or their number of properties, and prints each count.

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use vshake::shell::exit_code;
use vshake::shell::formats::campaign_io::{load_campaign, load_tests};
use vshake::shell::formats::{measured_files, parquet_write};
use vshake::shell::job::study_job::{load_study, plan_for};

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// The outcome a user may see: accepted, or bad input (exit 2) naming the file.
fn check(result: anyhow::Result<()>, file: &Path) -> Result<(), TestCaseError> {
    if let Err(e) = result {
        let message = format!("{e:#}");
        prop_assert_eq!(exit_code(&e), 2, "not bad input: {}", message);
        let name = file.file_name().unwrap().to_string_lossy().to_string();
        prop_assert!(
            message.contains(&name),
            "the message does not name {}: {}",
            name,
            message
        );
    }
    Ok(())
}

/// Runs `test` on random values of `strategy` (proptest's runner, shrinking a failure to its
/// smallest case): `PROPTEST_CASES` cases (256 unless set), or, where `VSHAKE_PROPTEST_SECONDS`
/// is set, rounds of that many cases until the seconds have passed. Prints the count.
fn property<S: Strategy>(
    name: &str,
    strategy: S,
    test: impl Fn(S::Value) -> Result<(), TestCaseError>,
) where
    S::Value: Debug,
{
    let config = Config {
        failure_persistence: None,
        ..Config::default()
    };
    let budget = std::env::var("VSHAKE_PROPTEST_SECONDS")
        .ok()
        .map(|s| match s.parse::<f64>() {
            Ok(secs) if secs > 0.0 => Duration::from_secs_f64(secs),
            _ => panic!("VSHAKE_PROPTEST_SECONDS={s:?}: a positive number of seconds"),
        });
    let (round, start) = (config.cases as usize, Instant::now());
    // A runner counts its cases until it is done: a fresh one per round, its generator drawn from
    // the first's.
    let mut seeds = TestRunner::new(config.clone());
    let mut cases = 0;
    loop {
        let mut runner = TestRunner::new_with_rng(config.clone(), seeds.new_rng());
        if let Err(e) = runner.run(&strategy, &test) {
            panic!("{name}: {e}");
        }
        cases += round;
        if budget.is_none_or(|b| start.elapsed() >= b) {
            break;
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!("{name}: {cases} cases in {secs:.1} s, none failed");
}

/// A byte edit: replace, insert or delete at a position (taken modulo the length).
#[derive(Debug, Clone)]
enum Edit {
    Set(usize, u8),
    Insert(usize, u8),
    Delete(usize),
    Truncate(usize),
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Set(p, b)),
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Insert(p, b)),
        any::<usize>().prop_map(Edit::Delete),
        any::<usize>().prop_map(Edit::Truncate),
    ];
    proptest::collection::vec(edit, 1..8)
}

fn mutate(seed: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for e in edits {
        let n = b.len().max(1);
        match *e {
            Edit::Set(p, x) if !b.is_empty() => b[p % n] = x,
            Edit::Insert(p, x) => b.insert(p % (b.len() + 1), x),
            Edit::Delete(p) if !b.is_empty() => {
                b.remove(p % n);
            }
            Edit::Truncate(p) => b.truncate(p % n),
            _ => {}
        }
    }
    b
}

/// Values that break assumptions: wrong types, out of range, non-finite, huge, empty.
const ODD_VALUES: [&str; 22] = [
    "-1",
    "0",
    "1e400",
    "-1e400",
    "nan",
    "inf",
    "-inf",
    "1e9",
    "1000000000",
    "9223372036854775807",
    "-9223372036854775808",
    "\"\"",
    "\"x\"",
    "[]",
    "{}",
    "[1, \"a\"]",
    "true",
    "0.5",
    "1e-300",
    "65537",
    "\"lhs\"",
    "\"../../nope.csv\"",
];

/// Puts an odd value after the `=` of some lines of a TOML text.
fn odd_values(text: &str, picks: &[(usize, usize)]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for &(line, value) in picks {
        let i = line % lines.len();
        if let Some((key, _)) = lines[i].split_once('=') {
            lines[i] = format!("{key}= {}", ODD_VALUES[value % ODD_VALUES.len()]);
        }
    }
    lines.join("\n")
}

fn picks() -> impl Strategy<Value = Vec<(usize, usize)>> {
    proptest::collection::vec((any::<usize>(), any::<usize>()), 1..5)
}

// ---- study files ----------------------------------------------------------------------------

fn study_seeds() -> Vec<Vec<u8>> {
    [
        "studies/gains_sweep.toml",
        "studies/port_width.toml",
        "studies/smoke.toml",
    ]
    .iter()
    .map(|p| std::fs::read(repo(p)).unwrap())
    .collect()
}

/// Loads a study as `study run` does; an accepted one is also planned (references and the
/// first sample) when it is small enough to plan quickly.
fn try_study(dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = dir.join("fuzzed_study.toml");
    std::fs::write(&path, bytes).unwrap();
    let result = load_study(&path).and_then(|spec| {
        let small = spec.samples <= 100_000
            && spec.excitations.iter().all(|e| match &e.spec {
                vshake::orchestration::runs::spec::ExcitationSpec::Sine { sine, .. } => {
                    sine.duration_s <= 60.0
                }
                _ => true,
            });
        if small {
            let plan = plan_for(&spec, dir)?;
            if plan.samples() > 0 {
                let _ = plan.sample(0);
            }
        }
        Ok(())
    });
    check(result, &path)
}

#[test]
fn study_files_of_random_bytes() {
    property(
        stringify!(study_files_of_random_bytes),
        proptest::collection::vec(any::<u8>(), 0..600),
        |bytes| {
            let d = tempfile::tempdir().unwrap();
            try_study(d.path(), &bytes)?;
            Ok(())
        },
    );
}

#[test]
fn study_files_with_mutated_bytes() {
    property(
        stringify!(study_files_with_mutated_bytes),
        (0usize..3, edits()),
        |(seed, e)| {
            let d = tempfile::tempdir().unwrap();
            try_study(d.path(), &mutate(&study_seeds()[seed], &e))?;
            Ok(())
        },
    );
}

#[test]
fn study_files_with_odd_values() {
    property(
        stringify!(study_files_with_odd_values),
        (0usize..3, picks()),
        |(seed, p)| {
            let d = tempfile::tempdir().unwrap();
            let text = String::from_utf8(study_seeds()[seed].clone()).unwrap();
            try_study(d.path(), odd_values(&text, &p).as_bytes())?;
            Ok(())
        },
    );
}

// ---- campaign files and measured tests ------------------------------------------------------

const CAMPAIGN: &str = "[campaign]\nname = \"fuzz\"\n\n[[test]]\nname = \"t\"\ndata = \"DATA\"\n\
excitation = { kind = \"sine\", freq_hz = 16.0, amp_g = 0.5, taper_s = 0.125, duration_s = 0.75, window_cycles = 4 }\n";

/// A small valid measured test (16 Hz, 0.75 s at 1024 Hz) as CSV text.
fn measured_csv() -> String {
    let mut s = String::from("time_s,ref_disp_m,disp_m,accel_mps2\n");
    for k in 0..=768 {
        let t = k as f64 / 1024.0;
        let w = 2.0 * std::f64::consts::PI * 16.0;
        let x = 4.85e-4 * (w * t).sin() * (t / 0.125).min(1.0);
        s += &format!(
            "{t:.6},{x:.6e},{:.6e},{:.6e}\n",
            0.98 * x,
            -w * w * 0.98 * x
        );
    }
    s
}

fn measured_parquet(dir: &Path) -> Vec<u8> {
    let csv = dir.join("seed.csv");
    std::fs::write(&csv, measured_csv()).unwrap();
    let names = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
    let t = measured_files::read_columns(&csv, &names, &[]).unwrap();
    let cols: Vec<(&str, &[f64])> = names.iter().map(|n| (*n, t.column(n).unwrap())).collect();
    let pq = dir.join("seed.parquet");
    parquet_write::write_parquet(&pq, &cols, &[]).unwrap();
    std::fs::read(&pq).unwrap()
}

/// Loads a campaign and its one test as `study compare` does.
fn try_campaign(
    dir: &Path,
    campaign: &[u8],
    data_name: &str,
    data: &[u8],
) -> Result<(), TestCaseError> {
    let path = dir.join("fuzzed_campaign.toml");
    std::fs::write(&path, campaign).unwrap();
    std::fs::write(dir.join(data_name), data).unwrap();
    let model = vshake::kernel::params::ModelParams::default();
    let result = load_campaign(&path, &model).and_then(|lc| load_tests(&lc, None).map(|_| ()));
    match &result {
        // A problem in the data names the data file; one in the campaign, the campaign.
        Err(e) if format!("{e:#}").contains(data_name) => check(result, &dir.join(data_name)),
        _ => check(result, &path),
    }
}

#[test]
fn campaign_files_of_random_bytes() {
    property(
        stringify!(campaign_files_of_random_bytes),
        proptest::collection::vec(any::<u8>(), 0..600),
        |bytes| {
            let d = tempfile::tempdir().unwrap();
            try_campaign(d.path(), &bytes, "t.csv", measured_csv().as_bytes())?;
            Ok(())
        },
    );
}

#[test]
fn campaign_files_with_mutated_bytes() {
    property(
        stringify!(campaign_files_with_mutated_bytes),
        edits(),
        |e| {
            let d = tempfile::tempdir().unwrap();
            try_campaign(
                d.path(),
                &mutate(CAMPAIGN.replace("DATA", "t.csv").as_bytes(), &e),
                "t.csv",
                measured_csv().as_bytes(),
            )?;
            Ok(())
        },
    );
}

#[test]
fn campaign_files_with_odd_values() {
    property(stringify!(campaign_files_with_odd_values), picks(), |p| {
        let d = tempfile::tempdir().unwrap();
        // One key per line, so that every value can be replaced.
        let text = CAMPAIGN
            .replace("DATA", "t.csv")
            .replace(
                "excitation = { kind = \"sine\", ",
                "[test.excitation]\nkind = \"sine\"\n",
            )
            .replace(", ", "\n")
            .replace(" }", "");
        try_campaign(
            d.path(),
            odd_values(&text, &p).as_bytes(),
            "t.csv",
            measured_csv().as_bytes(),
        )?;
        Ok(())
    });
}

#[test]
fn csv_tests_of_random_bytes() {
    property(
        stringify!(csv_tests_of_random_bytes),
        proptest::collection::vec(any::<u8>(), 0..2000),
        |bytes| {
            let d = tempfile::tempdir().unwrap();
            try_campaign(
                d.path(),
                CAMPAIGN.replace("DATA", "t.csv").as_bytes(),
                "t.csv",
                &bytes,
            )?;
            Ok(())
        },
    );
}

#[test]
fn csv_tests_with_mutated_bytes() {
    property(stringify!(csv_tests_with_mutated_bytes), edits(), |e| {
        let d = tempfile::tempdir().unwrap();
        try_campaign(
            d.path(),
            CAMPAIGN.replace("DATA", "t.csv").as_bytes(),
            "t.csv",
            &mutate(measured_csv().as_bytes(), &e),
        )?;
        Ok(())
    });
}

#[test]
fn parquet_tests_of_random_bytes() {
    property(
        stringify!(parquet_tests_of_random_bytes),
        proptest::collection::vec(any::<u8>(), 0..2000),
        |bytes| {
            let d = tempfile::tempdir().unwrap();
            try_campaign(
                d.path(),
                CAMPAIGN.replace("DATA", "t.parquet").as_bytes(),
                "t.parquet",
                &bytes,
            )?;
            Ok(())
        },
    );
}

#[test]
fn mat_tests_with_mutated_bytes() {
    property(
        stringify!(mat_tests_with_mutated_bytes),
        (any::<bool>(), edits()),
        |(v7, e)| {
            let d = tempfile::tempdir().unwrap();
            let seed = std::fs::read(repo(if v7 {
                "tests/data/mat/v7_units.mat"
            } else {
                "tests/data/mat/v5_names.mat"
            }))
            .unwrap();
            try_campaign(
                d.path(),
                CAMPAIGN.replace("DATA", "t.mat").as_bytes(),
                "t.mat",
                &mutate(&seed, &e),
            )?;
            Ok(())
        },
    );
}

#[test]
fn parquet_tests_with_mutated_bytes() {
    property(stringify!(parquet_tests_with_mutated_bytes), edits(), |e| {
        let d = tempfile::tempdir().unwrap();
        let seed = measured_parquet(d.path());
        try_campaign(
            d.path(),
            CAMPAIGN.replace("DATA", "t.parquet").as_bytes(),
            "t.parquet",
            &mutate(&seed, &e),
        )?;
        Ok(())
    });
}

/// A header field as a lab's export might write it: a channel's name in some spelling with a
/// unit in brackets or after an underscore, a random word and unit, or any string at all.
fn header_field() -> impl Strategy<Value = String> {
    let names = [
        "Time",
        "TIME_S",
        "t",
        "Ref Disp",
        "RefDisp",
        "Reference Displacement",
        "Command",
        "Disp",
        "Displacement",
        "Accel",
        "Acceleration",
        "A1 Table X",
        "Force",
        "Valve Cmd",
        "P1",
        "Pressure B",
        "Spool",
        "",
    ];
    let units = [
        "s", "ms", "mm", "m", "in", "g", "m/s^2", "m/s²", "kN", "N", "kip", "psi", "bar", "MPa",
        "Pa", "V", "mV", "furlongs", "", "(", ")", "[]",
    ];
    prop_oneof![
        (
            proptest::sample::select(names.to_vec()),
            proptest::sample::select(units.to_vec()),
            0usize..5
        )
            .prop_map(|(n, u, form)| match form {
                0 => format!("{n} ({u})"),
                1 => format!("{n} [{u}]"),
                2 => format!("{n}_{u}"),
                3 => format!("{n}{{{u}}}"),
                _ => n.to_string(),
            }),
        "[A-Za-z0-9 _()\\[\\]/^.-]{0,16}",
        any::<String>(),
    ]
}

/// A CSV whose first lines are `preamble`, a header of `fields` (and a units row), then 64 rows
/// of data.
fn csv_with_header(
    preamble: &[String],
    fields: &[String],
    units: &Option<Vec<String>>,
    sep: char,
) -> String {
    let mut s: String = preamble.iter().map(|l| format!("{l}\n")).collect();
    s += &fields.join(&sep.to_string());
    s.push('\n');
    if let Some(u) = units {
        s += &u.join(&sep.to_string());
        s.push('\n');
    }
    // 64 data rows: enough for the reader, few enough for 50 000 cases in CI.
    for line in measured_csv().lines().skip(1).take(64) {
        s += &line.replace(',', &sep.to_string());
        s.push('\n');
    }
    s
}

/// The header parsing alone: each field split into name and unit, the name recognised, the
/// unit looked up, the whole header resolved into the channels (with and without a units
/// row): never a panic.

#[test]
fn random_headers_never_panic() {
    property(
        stringify!(random_headers_never_panic),
        (
            proptest::collection::vec(header_field(), 0..12),
            proptest::option::of(proptest::collection::vec(header_field(), 0..12)),
        ),
        |(fields, units)| {
            use vshake::kernel::channels::unit as unit_of;
            use vshake::shell::formats::headers as channels;
            for f in fields.iter().chain(units.iter().flatten()) {
                let (name, unit) = channels::split(f);
                let _ = channels::recognise(&name);
                if let Some(u) = unit {
                    let _ = unit_of(&u);
                }
            }
            let wanted = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
            let optional = ["valve_cmd_v", "force_n", "p1_pa", "p2_pa", "spool_m"];
            let resolved = channels::resolve(&fields, units.as_deref(), &wanted, &optional, &[]);
            if let Ok(r) = resolved {
                prop_assert!(r.len() >= wanted.len());
                prop_assert!(r
                    .iter()
                    .all(|c| c.index < fields.len() && c.to_si.is_finite() && c.to_si > 0.0));
            }
            Ok(())
        },
    );
}

/// Files with such headers, a units row and a preamble, in every separator: read, or
/// refused as bad input naming the file.

#[test]
fn csv_tests_with_random_headers() {
    property(
        stringify!(csv_tests_with_random_headers),
        (
            proptest::collection::vec("[ -~]{0,30}", 0..4),
            proptest::collection::vec(header_field(), 0..8),
            proptest::option::of(proptest::collection::vec(header_field(), 4..5)),
            proptest::sample::select(vec![',', ';', '\t', ' ']),
        ),
        |(preamble, fields, units, sep)| {
            let d = tempfile::tempdir().unwrap();
            let text = csv_with_header(&preamble, &fields, &units, sep);
            try_campaign(
                d.path(),
                CAMPAIGN.replace("DATA", "t.csv").as_bytes(),
                "t.csv",
                text.as_bytes(),
            )?;
            Ok(())
        },
    );
}
