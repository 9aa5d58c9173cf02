//! `study iterate` at full scale (issue 50): on every motion that `study sim` runs inside the
//! table's limits, bare and with specimens of 20–150 t at 1–5 Hz and 1–5 % damping, the iteration
//! ends (exit 0, a drive written) and either reaches 5 % rms acceleration error within the
//! default iterations or says in one line why not; and the only "why not" these motions meet is
//! the table's limits (the drive the target needs is faster than the table), never a stall;
//! at least 8 of the 11 motions reach 5 % with every specimen.

mod common;

use common::study;
use std::path::Path;

/// The motions: stochastic ground motions (duration s, realisation, PGA g, f_g Hz) and the
/// bundled record at a PGA, 0.3–1.2 g, up to the velocity limit.
const MOTIONS: [&str; 11] = [
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 0\npga_g = 0.3\nf_g_hz = 2.5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 1\npga_g = 0.6\nf_g_hz = 1.5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 2\npga_g = 0.9\nf_g_hz = 5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 3\npga_g = 1.2\nf_g_hz = 2.5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 4\npga_g = 0.8\nf_g_hz = 1.0\n",
    "kind = \"stochastic\"\nduration_s = 40\nrealisation = 5\npga_g = 0.5\nf_g_hz = 2.5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 6\npga_g = 1.0\nf_g_hz = 3.5\n",
    "kind = \"stochastic\"\nduration_s = 20\nrealisation = 7\npga_g = 0.4\nf_g_hz = 8\n",
    "kind = \"record\"\nfile = \"RECORD\"\npga_g = 0.3\n",
    "kind = \"record\"\nfile = \"RECORD\"\npga_g = 0.7\n",
    "kind = \"record\"\nfile = \"RECORD\"\npga_g = 1.2\n",
];

/// The kept error (% rms) and the outcome line of `study iterate`'s output.
fn kept_and_outcome(stdout: &str) -> (f64, String) {
    let kept = stdout
        .lines()
        .find_map(|l| l.trim().strip_prefix("kept"))
        .and_then(|l| l.split(':').nth(1))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no kept line:\n{stdout}"));
    let outcome = stdout
        .lines()
        .find_map(|l| l.trim().strip_prefix("outcome"))
        .unwrap_or_else(|| panic!("no outcome line:\n{stdout}"))
        .trim()
        .to_string();
    (kept, outcome)
}

/// Every motion with `specimen` (a `[model.specimen]` table, or none): `sim` runs it, `iterate`
/// ends with a drive and reaches 5 % or names the limit that stops it.
fn every_motion_with(specimen: Option<(f64, f64, f64)>) {
    let d = tempfile::tempdir().unwrap();
    let record = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/records/synthetic_firm.AT2");
    let (mut summary, mut reached) = (Vec::new(), 0);
    for (i, motion) in MOTIONS.iter().enumerate() {
        let mut text = format!(
            "[excitation]\n{}",
            motion.replace("RECORD", record.to_str().unwrap())
        );
        if let Some((m, f, z)) = specimen {
            text += &format!("\n[model.specimen]\nm1 = {m}\nf1 = {f}\nzeta1 = {z}\n");
        }
        let file = d.path().join(format!("m{i}.toml"));
        std::fs::write(&file, &text).unwrap();
        let file = file.to_str().unwrap();
        let (code, stdout, stderr) = study(&["sim", file]);
        assert_eq!(code, 0, "sim runs the motion:\n{text}\n{stdout}{stderr}");
        let out = d.path().join(format!("out{i}"));
        let (code, stdout, stderr) = study(&["iterate", file, "--out", out.to_str().unwrap()]);
        assert_eq!(code, 0, "iterate ends:\n{text}\n{stdout}{stderr}");
        assert!(out.join("drive.csv").is_file(), "{text}");
        let (kept, outcome) = kept_and_outcome(&stdout);
        summary.push(format!("{i}: {kept:.3} % ({outcome})"));
        if kept > 5.0 {
            assert!(
                outcome.starts_with(
                    "goal not reached: the drive it needs would leave the table's limits (peak"
                ),
                "above 5 % without the limits as the reason:\n{text}\n{stdout}"
            );
            assert!(outcome.contains(" Hz"), "{outcome}");
        } else {
            reached += 1;
        }
    }
    eprintln!("{specimen:?}:\n{}", summary.join("\n"));
    // Measured: 11, 11, 10, 8 and 10 of the 11 motions reach 5 % with the five specimens; the
    // others need a drive faster than the table.
    assert!(
        reached >= 8,
        "{reached} of 11 reach 5 %:\n{}",
        summary.join("\n")
    );
}

#[test]
fn every_motion_on_the_bare_table() {
    every_motion_with(None);
}

#[test]
fn every_motion_with_a_light_soft_specimen() {
    every_motion_with(Some((20e3, 1.0, 0.01)));
}

#[test]
fn every_motion_with_a_heavy_stiff_specimen() {
    every_motion_with(Some((150e3, 5.0, 0.05)));
}

#[test]
fn every_motion_with_a_heavy_lightly_damped_specimen() {
    every_motion_with(Some((100e3, 3.0, 0.01)));
}

#[test]
fn every_motion_with_a_medium_specimen() {
    every_motion_with(Some((60e3, 2.0, 0.03)));
}

/// The runs an iteration's journal holds (its `run` lines).
fn journaled(journal: &Path) -> usize {
    std::fs::read_to_string(journal)
        .map(|t| t.lines().filter(|l| l.starts_with("run ")).count())
        .unwrap_or(0)
}

/// An iteration stopped by SIGTERM keeps its runs (the journal) and exits 143 with nothing else
/// written; `--resume` continues it, even after a write cut short by a kill, to files
/// byte-identical to an uninterrupted iteration's; other settings, or a fresh start over the
/// journal, are refused (issue 50, point 6).
#[test]
fn a_stopped_iteration_resumes_to_the_uninterrupted_files() {
    let d = tempfile::tempdir().unwrap();
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/iterate_firm.toml");
    let file = file.to_str().unwrap();
    let (whole, part) = (d.path().join("whole"), d.path().join("part"));
    // Nine runs: the goal is out of reach in 8 iterations.
    let flags = ["--goal", "0.0001", "--iterations", "8"];
    let w = whole.to_str().unwrap();
    let (code, _, stderr) = study(&[&["iterate", file, "--out", w][..], &flags].concat());
    assert_eq!(code, 0, "{stderr}");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_study"))
        .args(
            [
                &["iterate", file, "--out", part.to_str().unwrap()][..],
                &flags,
            ]
            .concat(),
        )
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let journal = part.join("iterate.journal");
    // Stopped once three runs are journaled (an event, not a time).
    while journaled(&journal) < 3 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(2));
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
    let done = journaled(&journal);
    assert!((3..9).contains(&done), "{done} runs journaled");
    assert!(!part.join("drive.csv").exists() && !part.join("iterations.parquet").exists());
    // A kill in the middle of the next write: a torn line after the last whole run.
    let mut j = std::fs::OpenOptions::new()
        .append(true)
        .open(&journal)
        .unwrap();
    std::io::Write::write_all(&mut j, b"run 99 00ff ok 3fd").unwrap();
    let p = part.to_str().unwrap();
    let (code, _, stderr) = study(&[&["iterate", file, "--out", p][..], &flags].concat());
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("holds an interrupted iteration"),
        "{stderr}"
    );
    let other = ["--goal", "0.0001", "--iterations", "9", "--resume"];
    let (code, _, stderr) = study(&[&["iterate", file, "--out", p][..], &other].concat());
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("the settings"), "{stderr}");
    let again = [&["iterate", file, "--out", p][..], &flags, &["--resume"]].concat();
    let (code, stdout, stderr) = study(&again);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains(&format!("resumed     {done} runs")),
        "{stdout}"
    );
    for f in [
        "iterations.parquet",
        "frf.parquet",
        "drive.csv",
        "history.parquet",
        "iteration.svg",
    ] {
        let read = |dir: &Path| std::fs::read(dir.join(f)).unwrap();
        assert!(
            read(&whole) == read(&part),
            "{f} differs from the uninterrupted iteration's"
        );
    }
    assert!(!journal.exists());
}
