//! Studies as a user meets them: every bundled file validates, results are bit-identical for
//! any thread count and chunk size, bad study files are refused with their key path, and a real
//! reader (pyarrow, DuckDB) opens the results.

mod common;
use common::study;

use std::path::{Path, PathBuf};
use vshake::orchestration::study::batch::{self, Plan, Row};
use vshake::orchestration::study::problem::StudySpec;
use vshake::shell::job::study_job;

fn studies_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("studies")
}

#[test]
fn every_bundled_file_parses_and_validates() {
    let mut n = 0;
    for entry in std::fs::read_dir(studies_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let table: toml::Table = text.parse().unwrap();
        if table.contains_key("study") {
            let spec = StudySpec::from_toml(&text, &path.display().to_string())
                .unwrap_or_else(|e| panic!("{e}"));
            // Its plan can be built (record files found, design sized).
            let plan = study_job::plan_for(&spec, &studies_dir())
                .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
            assert!(plan.rows() > 0);
        } else if table.contains_key("tune") {
            let spec = vshake::orchestration::preparation::tune_spec::TuneSpec::from_toml_on(
                &text,
                &path.display().to_string(),
                Default::default(),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            assert!(!spec.gains.is_empty() && !spec.objective.is_empty());
        } else {
            vshake::orchestration::runs::spec::SimSpec::from_toml(
                &text,
                &path.display().to_string(),
            )
            .unwrap_or_else(|e| panic!("{e}"));
        }
        n += 1;
    }
    assert!(
        n >= 4,
        "studies/ holds the sim example, smoke, gains_sweep and port_width ({n} found)"
    );
    // The tutorial's tuning files and its test (studies/tuning/).
    for entry in std::fs::read_dir(studies_dir().join("tuning")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        let name = path.display().to_string();
        if text.contains("[tune]") {
            vshake::orchestration::preparation::tune_spec::TuneSpec::from_toml_on(
                &text,
                &name,
                Default::default(),
            )
            .unwrap_or_else(|e| panic!("{e}"));
        } else {
            vshake::orchestration::runs::spec::SimSpec::from_toml(&text, &name)
                .unwrap_or_else(|e| panic!("{e}"));
        }
    }
    // Campaign definitions (their data is made by `study synth`).
    let mut c = 0;
    for entry in std::fs::read_dir(studies_dir().join("campaigns")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            let camp = vshake::orchestration::measured::campaign::Campaign::from_toml(
                &text,
                &path.display().to_string(),
                &Default::default(),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            assert!(!camp.tests.is_empty());
            c += 1;
        }
    }
    assert!(c >= 1);
}

const MIXED: &str = r#"
[study]
name = "determinism"
seed = 11
samples = 37
[method]
sampling = "lhs"
[[variables]]
name = "controller.g_d"
distribution = "normal"
mean = 1.5
std = 0.3
low = 0.5
high = 2.5
[[variables]]
name = "controller.l_a"
distribution = "triangular"
low = 0.4
mode = 0.52
high = 0.7
[[variables]]
name = "servovalve.r1"
distribution = "list"
values = [0.7, 0.8, 0.9]
[[variables]]
name = "platen.alpha"
distribution = "list"
values = [0.5, 0.6]
[[variables]]
name = "platen.m"
distribution = "normal"
mean = 144000.0
std = 200000.0
[[excitations]]
name = "a"
kind = "sine"
freq_hz = 3.0
amp_g = 3.2
duration_s = 2.0
taper_s = 0.5
window_cycles = 3
[[excitations]]
name = "b"
kind = "sine"
freq_hz = 5.0
amp_m = 0.01
duration_s = 2.0
taper_s = 0.5
window_cycles = 5
"#;

fn run_rows(plan: &Plan, threads: usize, chunk: usize) -> Vec<Row> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut rows: Vec<Row> = Vec::new();
    batch::run_plan(
        plan,
        0..plan.samples(),
        &pool,
        chunk,
        &mut rows,
        &|_| {},
        &|| false,
    )
    .unwrap();
    rows
}

/// 1 thread vs 2 threads vs several chunk sizes (including ones that are not multiples of the
/// lane count, so samples meet different neighbours): identical numeric columns, bit for bit.
#[test]
fn results_are_identical_for_any_thread_count_and_chunk_size() {
    let spec = StudySpec::from_toml(MIXED, "mixed.toml").unwrap();
    let plan = study_job::plan_for(&spec, Path::new(".")).unwrap();
    let reference = run_rows(&plan, 1, 8);
    assert_eq!(reference.len(), 37 * 2);
    let key = |r: &Row| -> Vec<u64> {
        let mut k = vec![r.sample_id, r.excitation as u64];
        k.extend(r.values.iter().map(|v| v.to_bits()));
        k.extend(r.metrics.columns().iter().map(|(_, v)| v.to_bits()));
        k
    };
    for (threads, chunk) in [(2, 8), (2, 5), (2, 37), (1, 3), (2, 64)] {
        let rows = run_rows(&plan, threads, chunk);
        assert_eq!(rows.len(), reference.len());
        for (a, b) in reference.iter().zip(&rows) {
            assert_eq!(
                key(a),
                key(b),
                "sample {} excitation {} differs with {threads} threads, chunk {chunk}",
                a.sample_id,
                a.excitation
            );
            assert_eq!(a.status, b.status);
        }
    }
    // The design is really mixed: invalid samples (negative mass draws) are rows, both damping
    // laws (α = 0.5 takes the square-root path, 0.6 the power law) run, and the samples fill
    // several groups of lanes.
    assert!(reference.iter().any(|r| r.status.label() == "invalid"));
    let ok: Vec<&Row> = reference
        .iter()
        .filter(|r| r.status.label() == "ok")
        .collect();
    let alpha = plan
        .columns
        .iter()
        .position(|c| c.path() == "platen.alpha")
        .expect("alpha varies");
    let laws: std::collections::BTreeSet<u64> =
        ok.iter().map(|r| r.values[alpha].to_bits()).collect();
    assert_eq!(
        laws.len(),
        2,
        "both damping laws among the runs that finished"
    );
    assert!(
        ok.len() > 2 * vshake::kernel::LANES,
        "{} runs finished",
        ok.len()
    );
}

fn expect_refused(text: &str, needle: &str) {
    let d = tempfile::tempdir().unwrap();
    let f = d.path().join("bad.toml");
    std::fs::write(&f, text).unwrap();
    let out = d.path().join("out.parquet");
    let (code, _, stderr) = study(&["run", f.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("bad.toml") && stderr.contains(needle),
        "expected {needle:?} in {stderr}"
    );
    assert!(
        !out.exists()
            && !d.path().join("out.partial.parquet").exists()
            && !d.path().join("out.partial.parquet.tmp").exists(),
        "no output file"
    );
}

#[test]
fn bad_study_files_are_refused_with_the_key_path() {
    let smoke = std::fs::read_to_string(studies_dir().join("smoke.toml")).unwrap();
    expect_refused(
        &smoke.replacen(
            "name = \"controller.g_d\"",
            "name = \"controller.gain_d\"",
            1,
        ),
        "variables[0].name: unknown parameter `controller.gain_d`",
    );
    expect_refused(
        &smoke.replacen("low = 1.0\nhigh = 2.0", "low = 3.0\nhigh = 2.0", 1),
        "variables[0].low: low = 3 must be below high = 2",
    );
    expect_refused(
        &smoke.replacen(
            "distribution = \"uniform\"\nlow = 1.0\nhigh = 2.0",
            "distribution = \"normal\"\nmean = 1.5\nstd = -0.1",
            1,
        ),
        "variables[0].std: std = -0.1 must be positive",
    );
    expect_refused(
        &smoke.replacen("sampling = \"saltelli\"", "sampling = \"saltire\"", 1),
        "method.sampling: unknown method \"saltire\"",
    );
    let (head, _) = smoke.split_once("[[excitations]]").unwrap();
    let (_, tail) = smoke.split_once("[output]").unwrap();
    expect_refused(
        &format!("excitations = []\n{head}[output]{tail}"),
        "excitations: the excitation list is empty",
    );
}

#[test]
fn smoke_study_results_open_in_pyarrow_and_duckdb() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("smoke.parquet");
    let (code, stdout, stderr) = study(&[
        "run",
        studies_dir().join("smoke.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("64 rows") && stdout.contains("64 ok"),
        "{stdout}"
    );
    assert!(d
        .path()
        .join("smoke_histories/sample0_sine_3hz_1g.parquet")
        .exists());
    let columns = "sample_id,excitation_id,excitation,design_base,design_block,g_d,l_a,mu_coef,amp_ratio,phase_err_deg,h3_ratio,thd_odd_ratio,rms_err_accel_ratio,status,fail_time_s,fail_reason";
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/check_results.py");
    let py = common::python3()
        .arg(&script)
        .arg(&out)
        .arg("64")
        .arg(columns)
        .output()
        .expect("python3");
    assert!(
        py.status.success(),
        "the results file must open in pyarrow and DuckDB (install them with `python3 tests/pydeps.py`):\n{}{}",
        String::from_utf8_lossy(&py.stdout),
        String::from_utf8_lossy(&py.stderr)
    );

    // Sensitivity of the smoke results: a table with a row per (metric, varied parameter).
    let sens = d.path().join("sens.parquet");
    let (code, stdout, stderr) = study(&[
        "sensitivity",
        out.to_str().unwrap(),
        "--out",
        sens.to_str().unwrap(),
        "--metrics",
        "amp_ratio,thd_odd_ratio",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("amp_ratio @ sine_3hz_1g") && stdout.contains("controller.l_a"),
        "{stdout}"
    );
    let t = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &sens,
        &["st", "s1", "src", "prcc"],
    )
    .unwrap();
    assert_eq!(t.rows(), 2 * 2);
    // The acceleration lead dominates the amplitude ratio at 3 Hz (the displacement gain is
    // nearly inert there): its total index and SRC are the larger.
    let first = stdout
        .lines()
        .skip_while(|l| !l.starts_with("amp_ratio"))
        .nth(2)
        .unwrap();
    assert!(first.contains("controller.l_a"), "{stdout}");
}

#[test]
fn a_design_file_drives_a_study() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("design.csv"),
        "controller.g_d,l_a\n1.2,0.5\n1.8,0.55\n1.5,0.52\n",
    )
    .unwrap();
    let text = "[study]\nname = \"fromfile\"\n[method]\nsampling = \"file\"\nfile = \"design.csv\"\n[[excitations]]\nkind = \"sine\"\nfreq_hz = 3.0\namp_g = 1.73\nwindow_cycles = 4\n";
    let f = d.path().join("s.toml");
    std::fs::write(&f, text).unwrap();
    let out = d.path().join("r.parquet");
    let (code, stdout, stderr) = study(&[
        "run",
        f.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("3 rows"), "{stdout}");
    let t = vshake::shell::formats::measured_files::read_columns_allow_nan(
        &out,
        &["g_d", "l_a", "amp_ratio"],
    )
    .unwrap();
    assert_eq!(t.column("g_d").unwrap(), &[1.2, 1.8, 1.5]);
    // Row 3 is the published controller: the reference amplitude ratio.
    assert!((t.column("amp_ratio").unwrap()[2] - 0.9987).abs() < 0.005);
    // An unknown column is refused with the file and the column.
    std::fs::write(
        d.path().join("design.csv"),
        "controller.g_d,bogus\n1.2,0.5\n",
    )
    .unwrap();
    let (code, _, stderr) = study(&[
        "run",
        f.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("design.csv: column `bogus` is not a model parameter"),
        "{stderr}"
    );
}

/// Sobol' indices stay aligned with their parameters when a design dimension happens to be
/// constant (a one-value list): its total index is exactly 0, and the others are computed from
/// their own AB blocks (at 3 Hz the velocity lead matters far more than the displacement gain).
#[test]
fn sensitivity_keeps_saltelli_blocks_aligned() {
    let d = tempfile::tempdir().unwrap();
    let text = r#"
[study]
name = "aligned"
seed = 5
samples = 32
[method]
sampling = "saltelli"
[[variables]]
name = "controller.g_d"
distribution = "uniform"
low = 1.2
high = 1.8
[[variables]]
name = "controller.l_a"
distribution = "list"
values = [0.52]
[[variables]]
name = "controller.l_v"
distribution = "uniform"
low = 0.3
high = 0.46
[[excitations]]
kind = "sine"
freq_hz = 3.0
amp_g = 1.0
taper_s = 0.5
duration_s = 2.0
window_cycles = 3
[responses]
metrics = ["amp_ratio"]
"#;
    let f = d.path().join("aligned.toml");
    std::fs::write(&f, text).unwrap();
    let out = d.path().join("r.parquet");
    let (code, _, stderr) = study(&[
        "run",
        f.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let sens = d.path().join("s.parquet");
    let (code, stdout, stderr) = study(&[
        "sensitivity",
        out.to_str().unwrap(),
        "--out",
        sens.to_str().unwrap(),
        "--bootstrap",
        "50",
    ]);
    assert_eq!(code, 0, "{stderr}");
    // Rows in design order: g_d, l_a, l_v.
    let t = vshake::shell::formats::measured_files::read_columns_allow_nan(&sens, &["st"]).unwrap();
    let st = t.column("st").unwrap();
    assert_eq!(st.len(), 3, "{stdout}");
    assert_eq!(st[1], 0.0, "the constant dimension has no effect: {st:?}");
    assert!(st[2] > 10.0 * st[0], "l_v outranks g_d at 3 Hz: {st:?}");
}

/// Issue 28: `--backend cuda` where no GPU can run the work is refused before any work (exit 2,
/// one line with the cause, nothing written); `auto` runs on the CPU and says why; `cpu` says
/// nothing about GPUs. (On a GPU machine the cause is that this version has no CUDA kernel.)
#[test]
fn the_backend_is_chosen_and_a_gpu_that_cannot_run_is_named() {
    let d = tempfile::tempdir().unwrap();
    let smoke = studies_dir().join("smoke.toml");
    let out = d.path().join("s.parquet");
    let args = |b: &'static str| {
        let mut v = vec![
            "run",
            smoke.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        v.extend(["-q", "--backend", b]);
        v
    };
    let (code, stdout, stderr) = study(&args("cuda"));
    assert_eq!(code, 2, "{stdout}{stderr}");
    assert!(stderr.starts_with("error: --backend cuda: "), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(std::fs::read_dir(d.path()).unwrap().next().is_none());
    let cause = stderr
        .trim()
        .trim_start_matches("error: --backend cuda: ")
        .to_string();
    let (code, stdout, stderr) = study(&args("auto"));
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains(&format!("backend     CPU (no GPU used: {cause})")),
        "{stdout}"
    );
    std::fs::remove_file(&out).unwrap();
    let (code, stdout, _) = study(&args("cpu"));
    assert_eq!(code, 0);
    assert!(stdout.contains("backend     CPU\n"), "{stdout}");
}

/// Two parameters of the same name in different components (two sensors' delays) get columns
/// qualified by their component, so the table opens in pyarrow (which refuses a duplicate name);
/// a design file may name them so.
#[test]
fn same_named_parameters_get_qualified_columns() {
    let d = tempfile::tempdir().unwrap();
    let text = r#"
[study]
name = "two_delays"
seed = 1
samples = 2
[method]
sampling = "monte_carlo"
[model.accel_sensor]
delay = 0.001
[model.disp_sensor]
delay = 0.001
[[variables]]
name = "accel_sensor.delay"
distribution = "uniform"
low = 0.0
high = 0.002
[[variables]]
name = "disp_sensor.delay"
distribution = "uniform"
low = 0.0
high = 0.002
[[excitations]]
name = "s"
kind = "sine"
freq_hz = 3.0
amp_g = 0.5
"#;
    let file = d.path().join("two.toml");
    std::fs::write(&file, text).unwrap();
    let out = d.path().join("two.parquet");
    let (code, _, stderr) = study(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let names = vshake::shell::formats::measured_files::column_names(&out).unwrap();
    assert!(
        names.contains(&"accel_sensor_delay_s".to_string())
            && names.contains(&"disp_sensor_delay_s".to_string()),
        "{names:?}"
    );
    let py = common::python3()
        .args(["-c", &format!("import pyarrow.parquet as pq; t = pq.read_table({:?}); print(t.column('disp_sensor_delay_s')[0])", out.display().to_string())])
        .output()
        .expect("python3");
    assert!(
        py.status.success(),
        "{}",
        String::from_utf8_lossy(&py.stderr)
    );
    // A design file naming the qualified columns is read back onto the same parameters.
    let design = d.path().join("design.csv");
    std::fs::write(
        &design,
        "accel_sensor_delay_s,disp_sensor_delay_s\n0.001,0.0005\n",
    )
    .unwrap();
    let (head, tail) = (
        text.find("[[variables]]").unwrap(),
        text.find("[[excitations]]").unwrap(),
    );
    let from_file = format!("{}{}", &text[..head], &text[tail..]).replace(
        "sampling = \"monte_carlo\"",
        "sampling = \"file\"\nfile = \"design.csv\"",
    );
    std::fs::write(&file, from_file).unwrap();
    let out2 = d.path().join("file.parquet");
    let (code, _, stderr) = study(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let t =
        vshake::shell::formats::measured_files::read_columns(&out2, &["disp_sensor_delay_s"], &[])
            .unwrap();
    assert_eq!(t.columns[0], vec![0.0005]);
}
