//! Helpers shared by the integration tests.

use std::path::Path;
use std::process::Command;
use vshake::shell::formats::measured_files::{column_names, read_columns_allow_nan};
use vshake::shell::formats::parquet_read::{read_bools, read_strings};

/// The state and term a report's residual follows, from its `stateterms.parquet`: the row the
/// map's sentence names (`named`), else (nothing named) the per-state regression of largest R²
/// over the platen's force balance and the chambers' flow balance, and its strongest term.
/// Returns (residual, state, term, R²).
#[allow(dead_code)] // used by compare and diagnose, not by every test crate
pub fn followed_state(report: &Path) -> (String, String, String, f64) {
    let p = report.join("stateterms.parquet");
    let (res, states, terms) = (
        read_strings(&p, "residual").unwrap(),
        read_strings(&p, "states").unwrap(),
        read_strings(&p, "term").unwrap(),
    );
    let named = read_bools(&p, "named").unwrap();
    let r2 = read_columns_allow_nan(&p, &["r2"])
        .unwrap()
        .column("r2")
        .unwrap()
        .to_vec();
    let rows = || {
        (0..res.len()).filter(|&i| {
            states[i] != "all"
                && (res[i] == "platen_force" || res[i] == "valve_flow" || res[i] == "valve_opening")
        })
    };
    let top = rows().map(|i| r2[i]).fold(f64::NEG_INFINITY, f64::max);
    let best = (0..res.len())
        .find(|&i| named[i])
        .or_else(|| rows().find(|&i| r2[i] == top))
        .unwrap();
    (
        res[best].clone(),
        states[best].clone(),
        terms[best].clone(),
        r2[best],
    )
}

/// A column's cells, comparable: numbers as bit patterns (NaN compares too), strings as text,
/// nulls as `-`.
pub type Cells = Vec<String>;

/// Every column: the numeric ones, the string ones (excitation, status, fail_reason) and the
/// nullable fail_time_s.
#[allow(dead_code)] // not every test crate compares results files
pub fn content(path: &Path) -> Vec<(String, Cells)> {
    let strings = ["excitation", "status", "fail_reason", "fail_detail"];
    let nullable = ["fail_time_s", "fail_value"];
    let names: Vec<String> = column_names(path)
        .unwrap()
        .into_iter()
        .filter(|n| !strings.contains(&n.as_str()) && !nullable.contains(&n.as_str()))
        .collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let t = read_columns_allow_nan(path, &refs).unwrap();
    let mut out: Vec<(String, Cells)> = names
        .iter()
        .map(|n| {
            (
                n.clone(),
                t.column(n)
                    .unwrap()
                    .iter()
                    .map(|v| v.to_bits().to_string())
                    .collect(),
            )
        })
        .collect();
    for s in strings {
        out.push((s.into(), read_strings(path, s).unwrap()));
    }
    for n in nullable {
        out.push((
            n.into(),
            vshake::shell::formats::parquet_read::read_opt_f64(path, n)
                .unwrap()
                .iter()
                .map(|v| v.map_or("-".into(), |x| x.to_bits().to_string()))
                .collect(),
        ));
    }
    out
}

/// `python3` with the repository's `.pydeps/` (where `tests/pydeps.py` installs pyarrow and DuckDB
/// on a PEP 668 system) in front of its `PYTHONPATH`.
#[allow(dead_code)] // used by the tests that open results in Python
pub fn python3() -> Command {
    let deps = Path::new(env!("CARGO_MANIFEST_DIR")).join(".pydeps");
    let mut path = deps.into_os_string();
    if let Some(old) = std::env::var_os("PYTHONPATH") {
        path.push(":");
        path.push(old);
    }
    let mut c = Command::new("python3");
    c.env("PYTHONPATH", path);
    c
}

/// Runs the `study` binary of this build with `args`: (exit code, stdout, stderr).
#[allow(dead_code)] // used by the command-line tests
pub fn study(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run study");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// The reference sine of docs/model.md §5 at `amp_g`: 3 Hz, 1 s taper, 3 s run, the last 4 cycles
/// analysed, at the controller's 1024 Hz.
#[allow(dead_code)] // used by the tests that pin the kernel's metrics
pub fn reference_sine(amp_g: f64) -> vshake::kernel::excitation::Reference {
    use vshake::kernel::excitation::Sine;
    Sine {
        freq_hz: 3.0,
        amp_m: Sine::amp_from_g(amp_g, 3.0),
        taper_s: 1.0,
        duration_s: 3.0,
        window_cycles: Some(4),
    }
    .reference(1024.0)
}

/// Waits until `path` exists (a temp file or a checkpoint of a run in the background), at most a
/// minute, then `extra` more.
#[allow(dead_code)] // used by the interruption tests, not by every test crate
pub fn wait_for(path: &Path, extra: std::time::Duration) {
    let t = std::time::Instant::now();
    while !path.exists() {
        assert!(
            t.elapsed() < std::time::Duration::from_secs(60),
            "{} never appeared",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::thread::sleep(extra);
}

/// The largest difference over a loop of compared values, NaN-aware: a NaN on either side counts
/// as an infinite difference (it can never hide behind a later, smaller one, as
/// `if !(d <= worst)` let it), and the comparisons are counted, so that a loop that compared
/// nothing fails too. A metric that does not apply is left out by the caller, by name.
#[allow(dead_code)] // used by the convergence tests, not by every test crate
#[derive(Debug, Default)]
pub struct Worst {
    pub diff: f64,
    pub what: String,
    pub count: usize,
}

#[allow(dead_code)]
impl Worst {
    /// |x − y| (infinite when either is NaN), kept with `what` if it is the largest so far.
    pub fn see(&mut self, x: f64, y: f64, what: impl FnOnce() -> String) {
        self.count += 1;
        let d = match (x - y).abs() {
            d if d.is_nan() => f64::INFINITY,
            d => d,
        };
        if self.count == 1 || d > self.diff {
            (self.diff, self.what) = (d, what());
        }
    }

    /// Fails unless something was compared and the largest difference is within `tol`.
    pub fn assert_within(&self, tol: f64, context: &str) {
        assert!(self.count > 0, "{context}: nothing was compared");
        assert!(
            self.diff <= tol,
            "{context}: {:e} > {tol:e} at {}",
            self.diff,
            self.what
        );
    }
}

/// Fails unless |a − b| ≤ tol, NaN included, naming `what` (the column and row).
#[allow(dead_code)]
pub fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    let d = (a - b).abs();
    assert!(
        d <= tol,
        "{what}: {a} against {b} (|difference| {d:e}, tolerance {tol:e})"
    );
}

/// The metrics of each model (batches of 8, the library's effect set for each batch) on
/// `reference` with the default solver; NaN metrics where a run failed (a chamber pressure left
/// its range, the stroke limit).
#[allow(dead_code)] // used by the compensator tests
pub fn metrics_of(
    models: &[vshake::kernel::params::ModelParams],
    reference: &vshake::kernel::excitation::Reference,
) -> Vec<vshake::kernel::metrics::Metrics> {
    use vshake::kernel::effects::effect_set;
    use vshake::kernel::metrics::Metrics;
    use vshake::kernel::params::ModelParams;
    use vshake::kernel::simulate::{self, LaneParams, LaneStatus, NoObserver, Solver};
    models
        .chunks(8)
        .flat_map(|chunk| {
            let refs: Vec<&ModelParams> = chunk.iter().collect();
            let lanes = simulate::run(
                &LaneParams::<8>::new(&refs).unwrap(),
                &effect_set::<8>(&refs),
                reference,
                &Solver::default(),
                &mut NoObserver,
            )
            .unwrap();
            lanes.into_iter().take(chunk.len()).map(|r| match r.status {
                LaneStatus::Ok => r.metrics,
                _ => Metrics::NAN,
            })
        })
        .collect()
}

/// The 90th percentile of `v`, a NaN (a failed run) counted as the worst.
#[allow(dead_code)] // used by the compensator tests
pub fn p90(v: &[f64]) -> f64 {
    let mut v: Vec<f64> = v
        .iter()
        .map(|&x| if x.is_nan() { f64::INFINITY } else { x })
        .collect();
    v.sort_by(f64::total_cmp);
    v[(0.9 * (v.len() - 1) as f64).round() as usize]
}

/// `n` tables drawn within ±20 % of the published model's β, M, the four port widths (w3 and the
/// ratios r1, r2, r4) and P_S (issue 52's uncertainty).
#[allow(dead_code)] // used by the compensator tests
pub fn uncertain_tables(seed: u64, n: usize) -> Vec<vshake::kernel::params::ModelParams> {
    use chacha20::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut u = || rng.random_range(0.8..1.2);
    (0..n)
        .map(|_| {
            let mut m = vshake::kernel::params::ModelParams::default();
            m.actuator.beta *= u();
            m.platen.m *= u();
            let sv = &mut m.servovalve;
            (sv.w3, sv.r1, sv.r2, sv.r4, sv.p_s) = (
                sv.w3 * u(),
                sv.r1 * u(),
                sv.r2 * u(),
                sv.r4 * u(),
                sv.p_s * u(),
            );
            m
        })
        .collect()
}

/// The `col`-th value (1: the value, 2: the TVC alone's) of metric `name` in `study sim`'s table.
#[allow(dead_code)] // used by compensation, not by every test crate
pub fn metric_column(stdout: &str, name: &str, col: usize) -> f64 {
    let row = stdout
        .lines()
        .find(|l| l.split_whitespace().next() == Some(name))
        .unwrap_or_else(|| panic!("{name} in:\n{stdout}"));
    row.split_whitespace().nth(col).unwrap().parse().unwrap()
}
