//! Long studies survive interruption and resume; impossible designs fail before they start.
//! Each test runs the `study` binary as a user would, on studies written here.

mod common;
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};
use common::{study, wait_for};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;
use vshake::shell::formats::parquet_read::{parquet_batches, parquet_metadata};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_study"))
}

fn gains_sweep() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/gains_sweep.toml")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every cell of a results file, as text (floats by their bit patterns, so NaN compares too).
fn cells(path: &Path) -> Vec<(String, Vec<String>)> {
    let (fields, reader) = parquet_batches(path).unwrap();
    let mut cols: Vec<(String, Vec<String>)> = fields
        .iter()
        .map(|f| (f.name().clone(), Vec::new()))
        .collect();
    for batch in reader {
        let batch = batch.unwrap();
        for (i, c) in batch.columns().iter().enumerate() {
            let a = c.as_any();
            let text: Vec<String> = if let Some(x) = a.downcast_ref::<Float64Array>() {
                (0..x.len())
                    .map(|r| {
                        if x.is_null(r) {
                            "null".into()
                        } else {
                            format!("{:x}", x.value(r).to_bits())
                        }
                    })
                    .collect()
            } else if let Some(x) = a.downcast_ref::<UInt64Array>() {
                x.values().iter().map(|v| v.to_string()).collect()
            } else if let Some(x) = a.downcast_ref::<UInt32Array>() {
                x.values().iter().map(|v| v.to_string()).collect()
            } else if let Some(x) = a.downcast_ref::<StringArray>() {
                (0..x.len())
                    .map(|r| {
                        if x.is_null(r) {
                            "null".into()
                        } else {
                            x.value(r).to_string()
                        }
                    })
                    .collect()
            } else {
                panic!(
                    "{}: unexpected column type {:?}",
                    path.display(),
                    c.data_type()
                )
            };
            cols[i].1.extend(text);
        }
    }
    cols
}

/// The key-value metadata but the row groups' checksums (row groups differ between a resumed run
/// and an uninterrupted one; their cells do not).
fn kv(path: &Path) -> Vec<(String, String)> {
    let mut m = parquet_metadata(path).unwrap();
    m.retain(|(k, _)| k != "vshake.row_group_crc32");
    m
}

fn meta(path: &Path, key: &str) -> Option<String> {
    parquet_metadata(path)
        .unwrap()
        .into_iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v)
}

/// The uninterrupted gains sweep, computed once for the tests of this file.
fn reference() -> &'static Path {
    static REF: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    let (_, p) = REF.get_or_init(|| {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("full.parquet");
        let (code, out, err) = study(&["run", s(&gains_sweep()), "--out", s(&p), "-q"]);
        assert_eq!(code, 0, "{out}{err}");
        (d, p)
    });
    p
}

/// Starts the gains sweep on one thread (about 7 s) with checkpoints every 0.2 s.
fn start(out: &Path, extra: &[&str]) -> Child {
    bin()
        .args([
            "run",
            s(&gains_sweep()),
            "--out",
            s(out),
            "--threads",
            "1",
            "--checkpoint-secs",
            "0.2",
            "-q",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn with_suffix(p: &Path, suffix: &str) -> PathBuf {
    let mut o = p.as_os_str().to_owned();
    o.push(suffix);
    PathBuf::from(o)
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig}");
}

/// Acceptance: SIGTERM mid-study leaves a readable file marked incomplete, `NAME.partial.parquet`
/// (issue 27: never under the final name); `--resume` (of either name) finishes it,
/// and the result equals an uninterrupted run bit for bit (every cell and the metadata).
#[test]
fn sigterm_then_resume_equals_an_uninterrupted_run() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("stopped.parquet");
    let partial = d.path().join("stopped.partial.parquet");
    let child = start(&out, &[]);
    wait_for(&with_suffix(&partial, ".tmp"), Duration::from_millis(1500));
    signal(&child, "-TERM");
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(143), "{err}");
    assert!(
        err.contains("stopped by SIGTERM") && err.contains("--resume"),
        "{err}"
    );
    // No reader takes the stopped run for a finished one: its rows are under another name.
    assert!(
        !out.exists() && err.contains("stopped.partial.parquet"),
        "{err}"
    );
    assert_eq!(meta(&partial, "vshake.complete").as_deref(), Some("false"));
    let done: usize = meta(&partial, "vshake.rows_done").unwrap().parse().unwrap();
    assert!(done > 0 && done < 16_384, "{done} rows");
    assert_eq!(
        cells(&partial)[0].1.len(),
        done,
        "every finished row is readable"
    );
    assert!(!with_suffix(&partial, ".tmp.checkpoint").exists());

    let (code, _, err) = study(&["sensitivity", s(&partial)]);
    assert!(
        code == 2 && err.contains("incomplete") && err.contains("--resume"),
        "sensitivity reads only complete files: {err}"
    );
    // A new run of the same table does not start over the stopped one's rows.
    let (code, _, err) = study(&["run", s(&gains_sweep()), "--out", s(&out), "-q"]);
    assert!(
        code == 2 && err.contains("interrupted run") && err.contains("--resume"),
        "{err}"
    );

    // --resume takes either name.
    let (code, stdout, err) = study(&["run", "--resume", s(&partial), "-q"]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(
        stdout.contains(&format!("{} samples ({done} rows) kept", done / 2)),
        "{stdout}"
    );
    assert!(!partial.exists(), "the complete table took its name");
    assert_eq!(cells(&out), cells(reference()));
    assert!(kv(&out) == kv(reference()), "the metadata differs");
    assert_eq!(meta(&out, "vshake.backend").as_deref(), Some("cpu"));
    // A complete file is left alone.
    let (code, stdout, _) = study(&["run", "--resume", s(&out)]);
    assert!(
        code == 0 && stdout.contains("complete (16384 rows); nothing to do"),
        "{stdout}"
    );
}

/// Acceptance: SIGKILL mid-study leaves the temp file and its checkpoint; `--resume` recovers
/// every checkpointed row group and finishes the run equal to an uninterrupted one. Killed
/// before its first checkpoint, the refusal names the reason.
#[test]
fn sigkill_then_resume_from_the_last_checkpoint() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("killed.parquet");
    let partial = d.path().join("killed.partial.parquet");
    let mut child = start(&out, &[]);
    wait_for(
        &with_suffix(&partial, ".tmp.checkpoint"),
        Duration::from_millis(1000),
    );
    signal(&child, "-KILL");
    child.wait().unwrap();
    assert!(!out.exists() && with_suffix(&partial, ".tmp").exists());
    // A resume killed before its own first checkpoint: the rows recovered into FILE.killed stay,
    // and the next resume starts from them.
    let mut again = bin()
        .args([
            "run",
            "--resume",
            s(&out),
            "--threads",
            "1",
            "--checkpoint-secs",
            "1000",
            "-q",
        ])
        .spawn()
        .unwrap();
    wait_for(&with_suffix(&partial, ".tmp"), Duration::from_millis(300));
    signal(&again, "-KILL");
    again.wait().unwrap();
    assert!(
        !out.exists()
            && with_suffix(&partial, ".killed").exists()
            && !with_suffix(&partial, ".tmp.checkpoint").exists()
    );
    let (code, stdout, err) = study(&["run", "--resume", s(&out), "-q"]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(
        stdout.contains("kept from") && stdout.contains(".killed"),
        "{stdout}"
    );
    assert_eq!(cells(&out), cells(reference()));
    assert!(kv(&out) == kv(reference()), "the metadata differs");
    assert!(
        !with_suffix(&partial, ".killed").exists()
            && !with_suffix(&partial, ".tmp").exists()
            && !partial.exists()
    );

    let early = d.path().join("early.parquet");
    let mut child = bin()
        .args([
            "run",
            s(&gains_sweep()),
            "--out",
            s(&early),
            "--threads",
            "1",
            "--checkpoint-secs",
            "1000",
            "-q",
        ])
        .spawn()
        .unwrap();
    let early_partial = d.path().join("early.partial.parquet");
    wait_for(
        &with_suffix(&early_partial, ".tmp"),
        Duration::from_millis(300),
    );
    signal(&child, "-KILL");
    child.wait().unwrap();
    let (code, _, err) = study(&["run", "--resume", s(&early)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("early.partial.parquet.tmp")
            && err.contains("killed before its first checkpoint"),
        "{err}"
    );
}

/// `study merge` counts a stopped shard as missing and says how to finish it; resumed, the
/// shards merge into the unsharded run.
#[test]
fn merge_treats_an_incomplete_shard_as_missing() {
    let d = tempfile::tempdir().unwrap();
    let shards = d.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    let s0 = shards.join("s0.parquet");
    let mut child = bin()
        .args([
            "run",
            s(&gains_sweep()),
            "--shard",
            "0/2",
            "--out",
            s(&s0),
            "--threads",
            "1",
            "-q",
        ])
        .spawn()
        .unwrap();
    wait_for(
        &shards.join("s0.partial.parquet.tmp"),
        Duration::from_millis(800),
    );
    signal(&child, "-TERM");
    assert_eq!(child.wait().unwrap().code(), Some(143));
    let s1 = shards.join("s1.parquet");
    let (code, _, err) = study(&[
        "run",
        s(&gains_sweep()),
        "--shard",
        "1/2",
        "--out",
        s(&s1),
        "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    let merged = d.path().join("merged.parquet");
    let (code, _, err) = study(&["merge", s(&shards), "--out", s(&merged)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("shard 0/2 missing")
            && err.contains("s0.partial.parquet: shard 0 is incomplete")
            && err.contains("--resume"),
        "{err}"
    );
    assert!(!merged.exists());
    let (code, _, err) = study(&["run", "--resume", s(&s0), "-q"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = study(&["merge", s(&shards), "--out", s(&merged)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(cells(&merged), cells(reference()));
}

/// A small study file: Monte Carlo over two gains, one sine.
fn small_study(
    dir: &Path,
    samples: &str,
    sampling: &str,
    excitation: &str,
    extra: &str,
) -> PathBuf {
    let p = dir.join("small.toml");
    let text = format!(
        "[study]\nname = \"small\"\nseed = 1\nsamples = {samples}\n\n[method]\nsampling = \"{sampling}\"\n\n\
         [[variables]]\nname = \"controller.g_d\"\ndistribution = \"uniform\"\nlow = 1.2\nhigh = 1.8\n\n\
         [[variables]]\nname = \"controller.l_v\"\ndistribution = \"uniform\"\nlow = 0.3\nhigh = 0.45\n\n\
         [[excitations]]\nname = \"s\"\n{excitation}\n{extra}"
    );
    std::fs::write(&p, text).unwrap();
    p
}

const SINE: &str = "kind = \"sine\"\nfreq_hz = 3.0\namp_g = 1.0\nduration_s = 3.0";

/// `--out DIR` writes `<name>.parquet` inside the folder; a results path that is a folder, or
/// a folder that cannot be written, fails before any computing (no "done" line, no file).
#[test]
fn the_output_path_is_checked_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let st = small_study(d.path(), "16", "monte_carlo", SINE, "");
    let dir = d.path().join("results");
    std::fs::create_dir(&dir).unwrap();
    let (code, out, err) = study(&["run", s(&st), "--out", s(&dir), "-q"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        dir.join("small.parquet").exists()
            && out.contains("wrote       ")
            && out.contains("small.parquet"),
        "{out}"
    );

    // A path ending in `/` is a folder, made where missing, that holds the default name.
    let new = format!("{}/", s(&d.path().join("new")));
    let (code, out, err) = study(&["run", s(&st), "--out", &new, "-q"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(d.path().join("new/small.parquet").is_file(), "{out}");

    std::fs::remove_file(dir.join("small.parquet")).unwrap();
    std::fs::create_dir(dir.join("small.parquet")).unwrap();
    let (code, out, err) = study(&["run", s(&st), "--out", s(&dir)]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains("small.parquet: is a folder") && !out.contains("done"),
        "{out}{err}"
    );

    // Read-only: a folder without write permission, or (for root, who ignores permissions) sysfs.
    let ro = d.path().join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::os::unix::fs::PermissionsExt::from_mode(0o555)).unwrap();
    let target = if std::fs::File::create(ro.join("probe")).is_ok() {
        PathBuf::from("/sys/vshake-test.parquet")
    } else {
        ro.join("x.parquet")
    };
    let (code, out, err) = study(&["run", s(&st), "--out", s(&target)]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains("cannot write the results file") && !out.contains("done") && !target.exists(),
        "{out}{err}"
    );
}

// A file-size limit reached mid-run (`ulimit -f`): tests/output_safety.rs.

/// `--dry-run` prints the runs, an estimate and the output size, and writes nothing.
#[test]
fn dry_run_sizes_the_run_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    let st = small_study(d.path(), "4096", "lhs", SINE, "");
    let (code, out, err) = study(&["run", s(&st), "--dry-run"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.contains("4096 samples x 1 excitations = 4096 runs")
            && out.contains("estimate")
            && out.contains("output"),
        "{out}"
    );
    assert!(
        std::fs::read_dir(d.path()).unwrap().count() == 1,
        "only the study file"
    );
}

/// A Latin hypercube whose permutations would not fit in memory is refused at once with the
/// estimate; a Monte Carlo run estimated at days warns loudly when stderr is not a terminal.
#[test]
fn huge_designs_are_refused_or_announced() {
    let d = tempfile::tempdir().unwrap();
    let st = small_study(d.path(), "1000000000", "lhs", SINE, "");
    let (code, out, err) = study(&["run", s(&st)]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains("study.samples") && err.contains("7.5 GiB") && err.contains("monte_carlo"),
        "{err}"
    );
    assert!(!out.contains("done"), "refused before any run: {out}");
    let (code, _, err) = study(&[
        "run",
        s(&small_study(d.path(), "64", "lhs", SINE, "")),
        "--samples",
        "1000000000",
    ]);
    assert!(
        code == 2 && err.contains("--samples 1000000000") && err.contains("GiB"),
        "{err}"
    );

    let st = small_study(d.path(), "4000000000", "monte_carlo", SINE, "");
    let (code, out, err) = study(&["run", s(&st), "--dry-run"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("days wall") && out.contains("--yes"), "{out}");
    let mut child = bin()
        .args([
            "run",
            s(&st),
            "--out",
            s(&d.path().join("mc.parquet")),
            "-q",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stderr.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        first.starts_with("WARNING: this run is estimated at") && first.contains("days"),
        "{first}"
    );
}

/// Settings that cannot work are refused with the key, or noted.
#[test]
fn impossible_settings_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let high = "kind = \"sine\"\nfreq_hz = 200.0\namp_g = 0.1\nduration_s = 3.0";
    // A harmonic at or above Nyquist, asked for by name: refused.
    let st = small_study(
        d.path(),
        "8",
        "monte_carlo",
        high,
        "[responses]\nmetrics = [\"amp_ratio\", \"h3_ratio\"]\n",
    );
    let (code, _, err) = study(&["run", s(&st)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("responses.metrics[1]") && err.contains("600 Hz") && err.contains("Nyquist"),
        "{err}"
    );
    // By default: the column is null, with a note.
    let st = small_study(d.path(), "8", "monte_carlo", high, "");
    let out_file = d.path().join("high.parquet");
    let (code, out, err) = study(&["run", s(&st), "--out", s(&out_file), "-q"]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("note")
            && out.contains("h3, h4, h5, h6, h7, h8, h9 at or above the Nyquist frequency 512 Hz"),
        "{out}"
    );
    let c = cells(&out_file);
    let col = |n: &str| c.iter().find(|(k, _)| k == n).unwrap().1.clone();
    let nan = |v: &String| v == "null";
    let status = col("status");
    let ok: Vec<usize> = (0..status.len()).filter(|&i| status[i] == "ok").collect();
    assert!(!ok.is_empty());
    assert!(ok.iter().all(|&i| nan(&col("h3_ratio")[i])
        && !nan(&col("h2_ratio")[i])
        && !nan(&col("thd_even_ratio")[i])));

    let bad_taper = "kind = \"sine\"\nfreq_hz = 3.0\namp_g = 1.0\ntaper_s = 4.0\nduration_s = 3.0";
    let (code, _, err) = study(&[
        "run",
        s(&small_study(d.path(), "8", "monte_carlo", bad_taper, "")),
    ]);
    assert!(
        code == 2
            && err.contains("excitations[0].taper_s")
            && err.contains("shorter than duration_s"),
        "{err}"
    );

    let hist = small_study(
        d.path(),
        "8",
        "monte_carlo",
        SINE,
        "[output]\nhistories = [3, 999999]\n",
    );
    let (code, out, err) = study(&["run", s(&hist), "--out", s(&d.path().join("h.parquet"))]);
    assert!(
        code == 2
            && err.contains("output.histories[1]: sample 999999 does not exist")
            && !out.contains("done"),
        "{out}{err}"
    );
    assert!(!d.path().join("h_histories").exists());

    for bad in ["\"lots\"", "1.5e9", "-3"] {
        let (code, _, err) = study(&[
            "run",
            s(&small_study(d.path(), bad, "monte_carlo", SINE, "")),
        ]);
        assert_eq!(code, 2, "{err}");
        assert!(
            err.contains("study.samples") && !err.contains("missing"),
            "samples = {bad}: {err}"
        );
    }
}

/// A panic anywhere is caught at the top: an internal error with its own exit code (70) and the
/// place, not a Rust backtrace dump.
#[test]
fn a_panic_is_reported_as_an_internal_error() {
    let o = bin()
        .arg("params")
        .env("VSHAKE_PANIC_FOR_TEST", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(70), "{err}");
    assert!(
        err.starts_with("internal error (a bug in vshake")
            && err.contains("VSHAKE_PANIC_FOR_TEST is set at src/main.rs:"),
        "{err}"
    );
    assert!(!err.contains("panicked at"), "{err}");
}
