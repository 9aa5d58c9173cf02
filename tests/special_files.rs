//! Inputs that are not regular files (a FIFO, a device, a folder): refused at once, saying what
//! they are, never read (a FIFO with no writer would block the read forever).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn mkfifo(path: &Path) {
    let ok = Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("mkfifo")
        .success();
    assert!(ok, "mkfifo {}", path.display());
}

/// `study ARGS` with a guard against a hang (a read blocked on a FIFO never ends): killed after
/// 20 s. Not a speed limit: a refusal is shown by its message and exit code, not by its time.
/// Returns the exit code and stderr.
fn study_watched(args: &[&str]) -> (i32, String) {
    let t0 = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn study");
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            panic!("study {args:?} blocked for 20 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    (out.status.code().unwrap_or(-1), err)
}

#[test]
fn a_fifo_as_a_tests_data_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    mkfifo(&dir.path().join("f1.csv"));
    let campaign = dir.path().join("campaign.toml");
    std::fs::write(
        &campaign,
        "[campaign]\nname = \"c\"\n[[test]]\nname = \"f1\"\ndata = \"f1.csv\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.0 }\n",
    )
    .unwrap();
    let (code, err) = study_watched(&["compare", campaign.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("f1.csv: is a FIFO (named pipe), not a data file"),
        "{err}"
    );
    assert_eq!(
        err.matches("f1.csv").count(),
        1,
        "the file named once: {err}"
    );
}

#[test]
fn a_fifo_as_a_record_and_as_a_study_file_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    mkfifo(&dir.path().join("record.csv"));
    let run = dir.path().join("run.toml");
    std::fs::write(
        &run,
        "[excitation]\nkind = \"record\"\nfile = \"record.csv\"\ncolumn = \"accel_g\"\nunit = \"g\"\n",
    )
    .unwrap();
    let (code, err) = study_watched(&["sim", run.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("record.csv: is a FIFO (named pipe), not a regular file"),
        "{err}"
    );
    mkfifo(&dir.path().join("study.toml"));
    let (code, err) = study_watched(&["run", dir.path().join("study.toml").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("study.toml: cannot read: is a FIFO (named pipe)"),
        "{err}"
    );
}

#[test]
fn a_device_as_data_is_refused_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = dir.path().join("campaign.toml");
    std::fs::write(
        &campaign,
        "[campaign]\nname = \"c\"\n[[test]]\nname = \"z\"\ndata = \"/dev/zero\"\nexcitation = { kind = \"sine\", freq_hz = 3.0, amp_g = 1.0 }\n",
    )
    .unwrap();
    let (code, err) = study_watched(&["compare", campaign.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("/dev/zero: is a device, not a data file"),
        "{err}"
    );
}
