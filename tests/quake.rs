//! Earthquake excitations end to end: an `.AT2` record read, scaled and integrated (its residual
//! drift bounded), stochastic realisations bit-identical across threads, chunks and shards, and
//! the bundled record sweep's spectral-error columns read by DuckDB and ranked by `study
//! sensitivity`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use vshake::kernel::ground::{self, GroundParams, Processing};
use vshake::kernel::params::G;
use vshake::orchestration::runs::quake;
use vshake::orchestration::runs::spec::RecordUnit;
mod common;
use common::content;
use common::study;
use vshake::shell::formats::measured_files::read_columns_allow_nan;
use vshake::shell::formats::parquet_read::read_strings;

fn ok(args: &[&str]) -> String {
    let (code, out, err) = study(args);
    assert_eq!(code, 0, "{args:?}: {out}{err}");
    out
}

/// A record as a PEER NGA-West2 file: 5 values a line in E format, like the database's.
fn write_at2(path: &Path, accel_g: &[f64], dt: f64) {
    let mut s = String::from("PEER NGA STRONG MOTION DATABASE RECORD\nSYNTHETIC, 11/23/2026, VSHAKE TEST STATION, 090\nACCELERATION TIME SERIES IN UNITS OF G\n");
    writeln!(s, "NPTS= {:>5}, DT= {dt:.4} SEC", accel_g.len()).unwrap();
    for line in accel_g.chunks(5) {
        for v in line {
            write!(s, "{v:>15.7E}").unwrap();
        }
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

/// A 30 s ground acceleration, g, every 0.01 s, with a baseline error (a constant 0.01 g offset
/// and a slow 0.005 g ramp) of the kind real records carry.
fn record_g() -> Vec<f64> {
    let dt = 0.01;
    let white = quake::noise(42, 0, 3000);
    let g = GroundParams {
        t_strong_s: 10.0,
        ..GroundParams::default()
    };
    ground::filtered_noise(&g, &white, dt)
        .iter()
        .enumerate()
        .map(|(k, a)| a / G + 0.01 + 0.005 * k as f64 / 3000.0)
        .collect()
}

#[test]
fn an_at2_record_round_trips_read_scaled_integrated() {
    let d = tempfile::tempdir().unwrap();
    let at2 = d.path().join("RSN_TEST_090.AT2");
    let rec = record_g();
    write_at2(&at2, &rec, 0.01);

    // Read: every value back to the file's 8 significant digits, on the DT grid.
    let t = vshake::shell::formats::at2::read(&at2).unwrap();
    let (time, accel) = (t.column("time_s").unwrap(), t.column("accel_g").unwrap());
    assert_eq!(accel.len(), 3000);
    assert!((time[2999] - 29.99).abs() < 1e-12, "{}", time[2999]);
    for (a, b) in accel.iter().zip(&rec) {
        assert!((a - b).abs() <= 1e-7 * b.abs().max(1e-3), "{a} vs {b}");
    }

    // Scaled: to a PGA of 0.35 g exactly.
    let scaled = quake::scaled(accel, RecordUnit::G, 1.0, Some(0.35));
    let pga = scaled.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!((pga / (0.35 * G) - 1.0).abs() < 1e-14, "{}", pga / G);

    // Integrated: without processing, the baseline error runs the displacement away (tens of
    // metres); processed, the residual drift stays below 1e-3 of the peak displacement and the
    // table ends at rest.
    let naive: f64 = scaled
        .iter()
        .enumerate()
        .map(|(k, a)| a * 0.01 * (3000 - k) as f64 * 0.01)
        .sum();
    assert!(naive.abs() > 5.0, "naive drift {naive} m");
    let p = ground::to_displacement(&scaled, 0.01, &Processing::default());
    let peak = p.disp_m.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let peak_v = p
        .disp_m
        .windows(2)
        .fold(0.0f64, |m, w| m.max(((w[1] - w[0]) / 0.01).abs()));
    assert!(
        p.drift_m <= 1e-3 * peak,
        "drift {} m of a {peak} m peak",
        p.drift_m
    );
    assert!(
        p.end_velocity_mps <= 1e-3 * peak_v,
        "end velocity {} m/s of a {peak_v} m/s peak",
        p.end_velocity_mps
    );
    println!("naive drift {naive:.2} m; processed: drift {:.3e} m of a {peak:.4} m peak ({:.2e}), end velocity {:.3e} m/s of {peak_v:.4} m/s", p.drift_m, p.drift_m / peak, p.end_velocity_mps);
    assert_eq!(p.pad, 1000);
    assert_eq!(p.disp_m.len(), 3000 + 2 * 1000);

    // The same file as a study excitation: `study sim` runs it and reports the spectral metrics.
    let sim = d.path().join("sim.toml");
    std::fs::write(
        &sim,
        "[excitation]\nkind = \"record\"\nfile = \"RSN_TEST_090.AT2\"\npga_g = 0.35\n",
    )
    .unwrap();
    let out = ok(&["sim", sim.to_str().unwrap()]);
    assert!(
        out.contains("acceleration record") && out.contains("scaled to 0.35 g"),
        "{out}"
    );
    let line = out
        .lines()
        .find(|l| l.trim_start().starts_with("spectral_err_mean"))
        .expect(&out);
    let v: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(v.is_finite() && v > 0.0 && v < 1.0, "{line}");
    // Scaled beyond the table: refused before the run, naming the limit.
    std::fs::write(
        &sim,
        "[excitation]\nkind = \"record\"\nfile = \"RSN_TEST_090.AT2\"\npga_g = 6.0\n",
    )
    .unwrap();
    let (code, out, err) = study(&["sim", sim.to_str().unwrap()]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains("RSN_TEST_090.AT2") && err.contains("table's limits"),
        "{err}"
    );
}

const PER_SAMPLE: &str = r#"
[study]
name = "per_sample"
seed = 11
samples = 13

[method]
sampling = "monte_carlo"

[[variables]]
name = "controller.g_d"
distribution = "uniform"
low = 1.2
high = 1.8

[[variables]]
name = "ground.f_g_hz"
distribution = "uniform"
low = 1.5
high = 4.0

[[excitations]]
name = "quake"
kind = "stochastic"
duration_s = 4
realisation = "per_sample"
pga_g = 0.3
highpass_hz = 0.5

[[excitations]]
name = "noise"
kind = "random"
f_lo_hz = 1.0
f_hi_hz = 12.0
rms_g = 0.05
duration_s = 4
realisation = "per_sample"

[responses]
metrics = ["spectral_err_mean", "spectral_err_max", "pga_ratio", "pgd_ratio", "rms_err_accel_ratio"]
"#;

#[test]
fn stochastic_realisations_are_bit_identical_across_threads_chunks_and_shards() {
    let d = tempfile::tempdir().unwrap();
    let spec = d.path().join("per_sample.toml");
    std::fs::write(&spec, PER_SAMPLE).unwrap();
    let s = spec.to_str().unwrap();
    let run = |name: &str, extra: &[&str]| -> PathBuf {
        let out = d.path().join(name);
        let mut args = vec!["run", s, "--out", out.to_str().unwrap(), "-q"];
        args.extend_from_slice(extra);
        ok(&args);
        out
    };
    let want = content(&run("t1.parquet", &["--threads", "1", "--chunk", "5"]));
    assert_eq!(want[0].1.len(), 26);
    assert_eq!(
        content(&run("t2.parquet", &["--threads", "2", "--chunk", "3"])),
        want
    );
    let shards = d.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    for i in 0..3 {
        let part = shards.join(format!("part{i}.parquet"));
        ok(&[
            "run",
            s,
            "--shard",
            &format!("{i}/3"),
            "--out",
            part.to_str().unwrap(),
            "--threads",
            &(i % 2 + 1).to_string(),
            "--chunk",
            "2",
            "-q",
        ]);
    }
    let merged = d.path().join("merged.parquet");
    ok(&[
        "merge",
        shards.to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
    ]);
    assert_eq!(content(&merged), want);

    // Each sample has its own realisation: no two samples' spectral errors are equal, and a
    // sample's differ from what the same gains give on the next sample's motion.
    let col = |name: &str| want.iter().find(|(n, _)| n == name).unwrap().1.clone();
    let (err, status) = (col("spectral_err_mean"), col("status"));
    assert!(status.iter().all(|s| s == "ok"), "{status:?}");
    let mut distinct = err.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), err.len());
    // Another seed, other motions.
    std::fs::write(&spec, PER_SAMPLE.replace("seed = 11", "seed = 12")).unwrap();
    let other = content(&run("seed12.parquet", &[]));
    let other_err = other
        .iter()
        .find(|(n, _)| n == "spectral_err_mean")
        .unwrap()
        .1
        .clone();
    assert!(other_err.iter().zip(&err).all(|(a, b)| a != b));
}

#[test]
fn the_record_sweep_writes_spectral_columns_duckdb_reads_and_sensitivity_ranks_the_gains() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("record_sweep.parquet");
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/record_sweep.toml");
    // 32 base points of the bundled design: 256 samples x 3 motions (about 2 s).
    ok(&[
        "run",
        file.to_str().unwrap(),
        "--samples",
        "32",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/check_spectral.py");
    let py = common::python3()
        .arg(&script)
        .arg(&out)
        .arg("768")
        .output()
        .expect("python3");
    assert!(
        py.status.success(),
        "DuckDB must read the spectral columns:\n{}{}",
        String::from_utf8_lossy(&py.stdout),
        String::from_utf8_lossy(&py.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&py.stdout).lines().count(), 3);

    let sens = d.path().join("sens.parquet");
    let said = ok(&[
        "sensitivity",
        out.to_str().unwrap(),
        "--out",
        sens.to_str().unwrap(),
        "--metrics",
        "spectral_err_mean,spectral_err_max",
    ]);
    for m in ["firm_0p5g", "soft_0p4g", "rock_0p8g"] {
        assert!(said.contains(&format!("spectral_err_max @ {m}")), "{said}");
    }
    let t = read_columns_allow_nan(&sens, &["st", "st_ci_low", "st_ci_high"]).unwrap();
    let (excitation, metric, parameter) = (
        read_strings(&sens, "excitation").unwrap(),
        read_strings(&sens, "metric").unwrap(),
        read_strings(&sens, "parameter").unwrap(),
    );
    // One row per motion, metric and gain, each with a total index.
    assert_eq!(t.rows(), 3 * 2 * 6);
    let st = |e: &str, m: &str| -> Vec<(String, f64, f64, f64)> {
        (0..t.rows())
            .filter(|&i| excitation[i] == e && metric[i] == m)
            .map(|i| {
                let col = |c: &str| t.column(c).unwrap()[i];
                (
                    parameter[i].clone(),
                    col("st"),
                    col("st_ci_low"),
                    col("st_ci_high"),
                )
            })
            .collect()
    };
    // The ranking of the full sweep (docs/guide.md, N = 256), which this eighth of it resolves:
    // the worst period's error is the velocity lead's on every motion, its total index's interval
    // above every other gain's; the jerk lead matters least everywhere.
    for e in ["firm_0p5g", "soft_0p4g", "rock_0p8g"] {
        let rows = st(e, "spectral_err_max");
        let lv = rows.iter().find(|r| r.0 == "controller.l_v").unwrap();
        for r in rows.iter().filter(|r| r.0 != "controller.l_v") {
            assert!(lv.2 > r.3, "{e}: ST(l_v) {lv:?} does not stand above {r:?}");
        }
        for m in ["spectral_err_mean", "spectral_err_max"] {
            let rows = st(e, m);
            let least = rows.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
            assert_eq!(least.0, "controller.l_j", "{e} {m}: {rows:?}");
        }
    }
    // On soft ground the velocity lead leads the mean spectral error too.
    let soft = st("soft_0p4g", "spectral_err_mean");
    let first = soft.iter().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    assert_eq!(first.0, "controller.l_v", "{soft:?}");
}

/// The default step is converged on earthquake motions too: on the record benchmark's motion
/// and on the record sweep's three motions, at the published gains and at two corners of the
/// sweep, every metric of 4 substeps is within 1e-5 of the 32-substep answer (in its own unit).
#[test]
fn the_default_step_is_converged_on_ground_motions() {
    use vshake::kernel::params::ModelParams;
    use vshake::kernel::simulate::{LaneStatus, NoObserver, Solver};
    use vshake::orchestration::preparation::tune_spec::applies;
    use vshake::orchestration::runs::spec::{ExcitationSpec, Realisation};
    let motions = [
        vec![("pga_g", 0.5)],
        vec![("pga_g", 0.4), ("f_g_hz", 1.2), ("zeta_g", 0.35)],
        vec![("pga_g", 0.8), ("f_g_hz", 5.0), ("t_strong_s", 4.0)],
    ];
    let mut worst = common::Worst::default();
    for (k, ground) in motions.into_iter().enumerate() {
        let exc = ExcitationSpec::Stochastic {
            duration_s: 15.0,
            realisation: Realisation::Fixed(k as u64),
            seed: None,
            ground,
            processing: Processing::default(),
            f_ref_hz: 50.0,
        };
        let r = quake::generated(&exc, &ModelParams::default(), 20261123, 0)
            .unwrap()
            .with_spectrum(vshake::orchestration::runs::quake_spec::default_spectrum());
        for (g_d, l_v, l_a, g_f) in [
            (1.5, 0.38, 0.52, -1.5),
            (1.1, 0.29, 0.39, -1.9),
            (1.9, 0.47, 0.65, -1.1),
        ] {
            let mut p = ModelParams::default();
            (
                p.controller.g_d,
                p.controller.l_v,
                p.controller.l_a,
                p.controller.g_f,
            ) = (g_d, l_v, l_a, g_f);
            let run = |substeps| {
                vshake::orchestration::runs::single::run_one(
                    &p,
                    &r,
                    &Solver { substeps },
                    &mut NoObserver,
                )
                .unwrap()
            };
            let (a, b) = (run(Solver::default().substeps), run(32));
            assert!(
                a.status == LaneStatus::Ok && b.status == LaneStatus::Ok,
                "motion {k}: {:?} {:?}",
                a.status,
                b.status
            );
            for ((name, x), (_, y)) in a
                .metrics
                .columns_for(false)
                .into_iter()
                .zip(b.metrics.columns_for(false))
            {
                // A record has no fundamental: its harmonic metrics do not apply (NaN in both).
                if !applies(name, false) {
                    continue;
                }
                worst.see(x, y, || {
                    format!("motion {k}, gains {g_d}/{l_v}/{l_a}/{g_f}, {name}: {x} against {y}")
                });
            }
        }
    }
    worst.assert_within(1e-5, "4 substeps are not converged");
    println!("largest difference: {:e} ({})", worst.diff, worst.what);
}
