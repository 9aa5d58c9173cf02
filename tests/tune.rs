//! `study tune` as a user meets it: the bundled tuning lowers the objective of the published gains
//! by at least 30 % at full scale, the same seed gives the same gains bit for bit on any number of
//! threads, the robust mode reports a 90th percentile below the published gains', the outputs
//! are what the report says, and bad input is refused before any work. docs/guide.md's tutorial
//! (tuned at 10 % on the bare table against tuned at full scale with the specimen) is run as
//! written (`--ignored`: a CI step runs it).

mod common;
use common::study;
use std::path::{Path, PathBuf};

fn example(name: &str) -> String {
    format!("{}/studies/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// The value of a row of the result table (`  name   start   tuned   change %`): (start, tuned).
fn result_row(stdout: &str, name: &str) -> (f64, f64) {
    let line = stdout
        .lines()
        .find(|l| l.trim_start().starts_with(name) && l.ends_with('%'))
        .unwrap_or_else(|| panic!("no {name} row in:\n{stdout}"));
    let v: Vec<f64> = line[name.len() + 2..]
        .split_whitespace()
        .take(2)
        .map(|x| x.parse().unwrap())
        .collect();
    (v[0], v[1])
}

/// `study sim` of tune_record.toml's motion (its record, spectrum and solver) with `model`: the
/// tuning's objective from the printed metrics, spectral_err_mean + rms_err_accel_ratio.
fn sim_objective(dir: &Path, model: Option<&Path>) -> f64 {
    let file = dir.join("firm_0p5g.toml");
    let record = example("records/synthetic_firm.AT2");
    let text = format!(
        "[excitation]\nkind = \"record\"\nfile = {record:?}\npga_g = 0.5\n\n\
         [spectrum]\ndamping = 0.05\nt_min_s = 0.05\nt_max_s = 4.0\ncount = 20\n\n\
         [solver]\nsubsteps = 4\n"
    );
    std::fs::write(&file, text).unwrap();
    let mut args = vec!["sim", file.to_str().unwrap(), "-q"];
    if let Some(m) = model {
        args.extend(["--model", m.to_str().unwrap()]);
    }
    let (code, stdout, stderr) = study(&args);
    assert_eq!(code, 0, "{stderr}");
    let metric = |name: &str| -> f64 {
        let line = stdout
            .lines()
            .find(|l| l.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("no {name} in:\n{stdout}"));
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    metric("spectral_err_mean") + metric("rms_err_accel_ratio")
}

fn tune(file: &str, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["tune", file, "--out", out.to_str().unwrap(), "-q"];
    args.extend(extra);
    let (code, stdout, stderr) = study(&args);
    assert_eq!(code, 0, "{stderr}");
    stdout
}

#[test]
fn the_bundled_tuning_gains_30_percent_the_same_on_any_thread_count() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a"), d.path().join("b"));
    let file = example("tune_record.toml");
    let stdout = tune(&file, &a, &["--threads", "1"]);
    let (start, tuned) = result_row(&stdout, "objective");
    assert!(tuned <= 0.7 * start, "{start} -> {tuned}");
    tune(&file, &b, &["--threads", "2"]);
    let model = |dir: &PathBuf| std::fs::read(dir.join("tuned.toml")).unwrap();
    assert_eq!(model(&a), model(&b), "the same gains bit for bit");
    let evals = |dir: &PathBuf| std::fs::read(dir.join("evaluations.parquet")).unwrap();
    assert_eq!(evals(&a), evals(&b), "the same evaluations");
    // The tuned model file is a model file: `study sim --model` takes it, and on the tuning's
    // own motion it tracks better: its objective, recomputed from `study sim`'s metrics, is the
    // tuning's reported one, for the published gains and for the tuned.
    let sim = |model: Option<&Path>| sim_objective(d.path(), model);
    let (published, with_tuned) = (sim(None), sim(Some(&a.join("tuned.toml"))));
    // Both are printed with 5 decimals: the sum of two rounded metrics against a rounded sum.
    let close = |x: f64, y: f64| (x - y).abs() <= 3e-5;
    assert!(
        close(published, start),
        "sim {published}, tune's start {start}"
    );
    assert!(
        close(with_tuned, tuned),
        "sim {with_tuned}, tune's tuned {tuned}"
    );
    assert!(with_tuned <= 0.7 * published, "{published} -> {with_tuned}");
    let report = std::fs::read_to_string(a.join("report.html")).unwrap();
    for needle in [
        "id=\"summary\"",
        "id=\"gains\"",
        "id=\"generations\"",
        "motion-firm_0p5g",
        "response spectrum",
        "margin to valve saturation",
    ] {
        assert!(report.contains(needle), "{needle} in the report");
    }
}

#[test]
fn the_evaluations_table_holds_every_run_and_its_objective() {
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(example("tune_record.toml"))
        .unwrap()
        .replace("generations = 100", "generations = 3")
        .replace("records/", &example("records/"));
    let file = d.path().join("short.toml");
    std::fs::write(&file, text).unwrap();
    let out = d.path().join("o");
    let stdout = tune(file.to_str().unwrap(), &out, &[]);
    assert!(stdout.contains("the generation limit (3)"), "{stdout}");
    let t = vshake::shell::formats::measured_files::read_columns(
        &out.join("evaluations.parquet"),
        &[
            "spectral_err_mean",
            "rms_err_accel_ratio",
            "objective",
            "l_j",
        ],
        &[],
    )
    .unwrap();
    // 1 start + 3 generations of 8 candidates, one motion each.
    assert_eq!(t.rows(), 25);
    for r in 0..t.rows() {
        let sum = t.columns[0][r] + t.columns[1][r];
        assert!(
            (sum - t.columns[2][r]).abs() < 1e-12,
            "row {r}: {sum} vs {}",
            t.columns[2][r]
        );
    }
    assert_eq!(t.columns[3][0], 0.005, "the start is the published l_j");
    let (start, tuned) = result_row(&stdout, "objective");
    let best = t.columns[2].iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(format!("{start:.5}"), format!("{:.5}", t.columns[2][0]));
    assert_eq!(format!("{tuned:.5}"), format!("{best:.5}"));
    let g = vshake::shell::formats::measured_files::read_columns(
        &out.join("generations.parquet"),
        &["best_so_far"],
        &[],
    )
    .unwrap();
    assert_eq!(g.rows(), 4);
    assert!(
        g.columns[0].windows(2).all(|w| w[1] <= w[0]),
        "{:?}",
        g.columns[0]
    );
    // Outputs are not overwritten without --force.
    let (code, _, stderr) = study(&[
        "tune",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("tuned.toml: exists (--force overwrites it)"),
        "{stderr}"
    );
}

#[test]
fn the_robust_tuning_lowers_the_90th_percentile() {
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(example("tune_robust.toml"))
        .unwrap()
        .replace("generations = 60", "generations = 12")
        .replace("draws = 16", "draws = 8");
    let file = d.path().join("robust.toml");
    std::fs::write(&file, text).unwrap();
    let stdout = tune(file.to_str().unwrap(), &d.path().join("o"), &[]);
    let (start, tuned) = result_row(&stdout, "90th percentile");
    assert!(tuned < 0.8 * start, "{start} -> {tuned}");
    let (obj_start, obj_tuned) = result_row(&stdout, "objective");
    assert_eq!(
        (obj_start, obj_tuned),
        (start, tuned),
        "the objective is the 90th percentile"
    );
    let t = vshake::shell::formats::measured_files::read_columns(
        &d.path().join("o/evaluations.parquet"),
        &["draw", "draw_objective", "objective"],
        &[],
    )
    .unwrap();
    // The start's 8 draws: their 90th percentile is its objective.
    let mut first: Vec<f64> = t.columns[1][..8].to_vec();
    first.sort_by(f64::total_cmp);
    let q = first[6] + 0.3 * (first[7] - first[6]);
    assert!(
        (q - t.columns[2][0]).abs() < 1e-12,
        "{q} vs {}",
        t.columns[2][0]
    );
}

#[test]
fn no_feasible_candidate_writes_no_tuned_model() {
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(example("tune_record.toml"))
        .unwrap()
        .replace("generations = 100", "generations = 2")
        .replace("valve_cmd_fraction = 0.9", "valve_cmd_fraction = 0.01")
        .replace("records/", &example("records/"));
    let file = d.path().join("tight.toml");
    std::fs::write(&file, text).unwrap();
    let out = d.path().join("o");
    let (code, stdout, stderr) = study(&[
        "tune",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 1, "{stdout}\n{stderr}");
    assert!(
        stderr.contains("no candidate met the constraints") && stderr.contains("limit 1.0 %"),
        "{stderr}"
    );
    assert!(stdout.contains("infeasible"), "{stdout}");
    assert!(!out.join("tuned.toml").exists() && !out.join("gains.toml").exists());
    // Over an earlier run's results (--force), its tuned model does not stay behind.
    std::fs::write(out.join("tuned.toml"), "[model.controller]\ng_d = 1.0\n").unwrap();
    let (code, _, _) = study(&[
        "tune",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
        "--force",
    ]);
    assert_eq!(code, 1);
    assert!(!out.join("tuned.toml").exists());
    let why = vshake::shell::formats::parquet_read::read_strings(
        &out.join("evaluations.parquet"),
        "infeasible_reason",
    )
    .unwrap();
    assert!(
        why.iter().all(|w| w.starts_with("valve command")),
        "{why:?}"
    );
}

#[test]
fn bad_tuning_files_are_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(example("tune_record.toml")).unwrap();
    let cases = [
        (
            good.replace("controller.l_j", "controller.l_k"),
            "gains[3].name: unknown parameter `controller.l_k`",
        ),
        (
            good.replacen("low = -0.3\nhigh = 0.6", "low = 0.6\nhigh = -0.3", 1),
            "gains[0].low: the bounds are inverted",
        ),
        (
            good.replace("[[excitations]]", "[[excitation]]"),
            "excitations: missing",
        ),
        (
            good.replace("spectral_err_mean = 1.0", "spectral_err_meen = 1.0"),
            "objective.spectral_err_meen: unknown key (did you mean `spectral_err_mean`?)",
        ),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        let file = d.path().join(format!("bad{i}.toml"));
        std::fs::write(&file, text).unwrap();
        let out = d.path().join(format!("out{i}"));
        let (code, _, stderr) = study(&[
            "tune",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 2, "{stderr}");
        assert!(
            stderr.contains(&format!("bad{i}.toml")) && stderr.contains(needle),
            "{needle} in {stderr}"
        );
        assert!(!out.exists(), "no output before the file is right");
    }
}

/// docs/guide.md's tutorial: tuned at 10 % on the bare table, the leads are worse than the published
/// ones at full scale with the specimen; tuned at full scale with it, they are better than both.
#[test]
#[ignore = "slow (about 12 s): a CI step runs it, cargo test --release --test tune -- --ignored"]
fn tuning_at_reduced_amplitude_fails_at_full_scale() {
    let d = tempfile::tempdir().unwrap();
    let (low, full) = (d.path().join("bare_10pct"), d.path().join("specimen_full"));
    tune(&example("tuning/bare_10pct.toml"), &low, &[]);
    tune(&example("tuning/specimen_full.toml"), &full, &[]);
    let test = example("tuning/test_specimen_full.toml");
    let objective = |model: Option<&Path>| {
        let mut args = vec!["sim", test.as_str(), "-q"];
        let m;
        if let Some(p) = model {
            m = p.join("gains.toml").to_str().unwrap().to_string();
            args.extend(["--model", m.as_str()]);
        }
        let (code, stdout, stderr) = study(&args);
        assert_eq!(code, 0, "{stderr}");
        let v = |name: &str| -> f64 {
            let l = stdout
                .lines()
                .find(|l| l.trim_start().starts_with(name))
                .unwrap();
            l.split_whitespace().nth(1).unwrap().parse().unwrap()
        };
        v("spectral_err_mean") + v("rms_err_accel_ratio")
    };
    let (published, at_10, at_full) = (
        objective(None),
        objective(Some(&low)),
        objective(Some(&full)),
    );
    assert!(
        at_10 > published,
        "tuned at 10 % on the bare table: {at_10} vs published {published}"
    );
    assert!(
        at_full < 0.9 * published,
        "tuned at full scale with the specimen: {at_full} vs {published}"
    );
}

/// The generations a journal holds (its `end` lines).
fn journaled(journal: &Path) -> usize {
    std::fs::read_to_string(journal)
        .map(|t| t.lines().filter(|l| l.starts_with("end ")).count())
        .unwrap_or(0)
}

/// A tuning stopped by SIGTERM keeps every evaluation done (evaluations.partial.parquet and the
/// journal) and exits 143; `--resume` continues it, even after a write cut short by a kill, to
/// files byte-identical to an uninterrupted run's; a changed tuning file is refused.
#[test]
fn a_stopped_tuning_resumes_to_the_uninterrupted_files() {
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(example("tune_record.toml"))
        .unwrap()
        .replace("records/", &example("records/"));
    let file = d.path().join("t.toml");
    std::fs::write(&file, &text).unwrap();
    let (whole, part) = (d.path().join("whole"), d.path().join("part"));
    tune(file.to_str().unwrap(), &whole, &[]);
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_study"))
        .args([
            "tune",
            file.to_str().unwrap(),
            "--out",
            part.to_str().unwrap(),
            "-q",
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let journal = part.join("tune.journal");
    // Stopped once two generations are journaled (an event, not a time).
    while journaled(&journal) < 2 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let term = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(143), "{stderr}");
    assert!(stderr.contains("--resume"), "{stderr}");
    assert!(part.join("evaluations.partial.parquet").exists() && !part.join("tuned.toml").exists());
    let done = journaled(&journal);
    assert!(done >= 2, "{done} generations journaled");
    // A kill in the middle of the next write: a torn line after the last whole generation.
    let mut j = std::fs::OpenOptions::new()
        .append(true)
        .open(&journal)
        .unwrap();
    std::io::Write::write_all(&mut j, b"E 99 0 3fd8\nR 0 0 3fd").unwrap();
    // Another tuning file is not this tuning's continuation.
    std::fs::write(&file, text.replace("seed = 1", "seed = 2")).unwrap();
    let p = part.to_str().unwrap();
    let (code, _, stderr) = study(&["tune", file.to_str().unwrap(), "--out", p, "--resume"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("the tuning file differs"), "{stderr}");
    std::fs::write(&file, &text).unwrap();
    let stdout = tune(file.to_str().unwrap(), &part, &["--resume"]);
    assert!(!stdout.is_empty());
    for f in [
        "tuned.toml",
        "gains.toml",
        "evaluations.parquet",
        "generations.parquet",
    ] {
        let read = |dir: &Path| std::fs::read(dir.join(f)).unwrap();
        assert!(
            read(&whole) == read(&part),
            "{f} differs from the uninterrupted run's"
        );
    }
    assert!(!journal.exists() && !part.join("evaluations.partial.parquet").exists());
}
