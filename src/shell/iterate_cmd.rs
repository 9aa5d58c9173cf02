//! `study iterate`: offline iteration of an earthquake test's drive on the virtual table.

use super::cli::IterateArgs;
use super::meta::{self, Key, Kind};
use super::{sim_cmd, tables, BadInput, RunFailed};
use crate::orchestration::drive_iteration::{
    iterate_on_model, IterationRow, IterationSettings, TableIteration,
};
use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The files `--out` receives.
const OUTPUTS: [&str; 4] = [
    "iterations.parquet",
    "frf.parquet",
    "drive.csv",
    "history.parquet",
];

pub fn run(args: &IterateArgs) -> anyhow::Result<()> {
    let settings = settings(args)?;
    let spec = sim_cmd::load_spec(&args.file, args.model.as_deref())?;
    let targets = outputs(args)?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let target = sim_cmd::build_reference(&spec, base)?;
    let mut o = std::io::stdout().lock();
    writeln!(o, "study iterate {}", args.file.display())?;
    if let Some(m) = &args.model {
        writeln!(
            o,
            "  model       {} (the run file's [model.*] on top)",
            m.display()
        )?;
    }
    writeln!(o, "  target      {}", spec.excitation.describe())?;
    writeln!(
        o,
        "  settings    gain {}, at most {} iterations, goal {:.2} % rms, FRF from a random run (seed {})",
        settings.gain,
        settings.max_iterations,
        100.0 * settings.goal,
        args.seed
    )?;
    writeln!(o, "\n  {:>9} {:>22}", "iteration", "rms accel error, %")?;
    let print = |r: &IterationRow| {
        println!("  {:>9} {:>22.3}", r.iteration, 100.0 * r.rms_error_ratio);
    };
    let done = iterate_on_model(
        &spec.model,
        &spec.solver,
        &target,
        &settings,
        args.seed,
        print,
    )
    .map_err(|e| RunFailed(format!("{}: {e}", args.file.display())))?;
    summary(&mut o, &done)?;
    if let Some(dir) = &args.out {
        write_outputs(dir, &targets, &done, &spec.resolved_toml())?;
        writeln!(
            o,
            "\n  wrote       {}",
            targets
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        writeln!(
            o,
            "  the drive as an excitation: kind = \"record\", file = \"{}\", column = \"drive_disp_m\", signal = \"reference\"",
            targets[2].display()
        )?;
    }
    Ok(())
}

/// The iteration's settings from the flags, each checked.
fn settings(args: &IterateArgs) -> anyhow::Result<IterationSettings> {
    if !(args.gain > 0.0 && args.gain <= 1.0) {
        return Err(BadInput(format!("--gain {}: must be in (0, 1]", args.gain)).into());
    }
    if !(args.goal > 0.0 && args.goal < 1.0) {
        return Err(BadInput(format!(
            "--goal {}: must be in (0, 1) (a fraction of the target's rms)",
            args.goal
        ))
        .into());
    }
    if args.iterations == 0 {
        return Err(BadInput("--iterations 0: at least one".into()).into());
    }
    Ok(IterationSettings {
        gain: args.gain,
        goal: args.goal,
        max_iterations: args.iterations,
        ..Default::default()
    })
}

/// The output paths, refused before any work where one exists and --force is not given.
fn outputs(args: &IterateArgs) -> anyhow::Result<Vec<PathBuf>> {
    let Some(dir) = &args.out else {
        return Ok(Vec::new());
    };
    if dir.exists() && !dir.is_dir() {
        return Err(BadInput(format!(
            "--out {}: exists and is not a folder",
            dir.display()
        ))
        .into());
    }
    let paths: Vec<PathBuf> = OUTPUTS.iter().map(|f| dir.join(f)).collect();
    if let Some(p) = paths.iter().find(|p| p.exists()) {
        if !args.force {
            return Err(
                BadInput(format!("{}: exists (--force overwrites it)", p.display())).into(),
            );
        }
    }
    Ok(paths)
}

fn summary(o: &mut impl Write, done: &TableIteration) -> anyhow::Result<()> {
    let best = done
        .rows
        .iter()
        .min_by(|a, b| a.rms_error_ratio.total_cmp(&b.rms_error_ratio))
        .expect("iteration 0 is always run");
    writeln!(
        o,
        "\n  kept        iteration {}: {:.3} % rms (the raw target as drive: {:.3} %)",
        best.iteration,
        100.0 * best.rms_error_ratio,
        100.0 * done.rows[0].rms_error_ratio
    )?;
    Ok(())
}

/// iterations.parquet, frf.parquet and drive.csv (each written whole, then renamed).
fn write_outputs(
    dir: &Path,
    paths: &[PathBuf],
    done: &TableIteration,
    spec: &str,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let iteration: Vec<f64> = done.rows.iter().map(|r| r.iteration as f64).collect();
    let error: Vec<f64> = done.rows.iter().map(|r| r.rms_error_ratio).collect();
    let mut m = meta::header(Kind::DriveIteration);
    m.push(meta::pair(Key::Spec, spec));
    let cols: [(&str, &[f64]); 2] = [("iteration", &iteration), ("rms_err_accel_ratio", &error)];
    tables::write_parquet(&paths[0], &cols, &m)
        .with_context(|| format!("writing {}", paths[0].display()))?;
    let frf = &done.frf;
    let freq: Vec<f64> = (0..frf.re.len())
        .map(|k| k as f64 * frf.rate_hz / frf.n_fft as f64)
        .collect();
    let gain: Vec<f64> = (0..frf.re.len())
        .map(|k| frf.re[k].hypot(frf.im[k]))
        .collect();
    let phase: Vec<f64> = (0..frf.re.len())
        .map(|k| frf.im[k].atan2(frf.re[k]).to_degrees())
        .collect();
    let cols: [(&str, &[f64]); 3] = [("freq_hz", &freq), ("gain", &gain), ("phase_deg", &phase)];
    let m = meta::header(Kind::FrequencyResponse);
    tables::write_parquet(&paths[1], &cols, &m)
        .with_context(|| format!("writing {}", paths[1].display()))?;
    write_drive(&paths[2], done)?;
    write_history(&paths[3], done)
}

/// Per tick: the target acceleration, the one achieved with the final drive, the drive.
fn write_history(path: &Path, done: &TableIteration) -> anyhow::Result<()> {
    let d = &done.drive;
    let time: Vec<f64> = (0..d.len()).map(|k| d.time(k)).collect();
    let target: Vec<f64> = done.target.clone();
    let cols: [(&str, &[f64]); 4] = [
        ("time_s", &time),
        ("target_accel_mps2", &target),
        ("accel_mps2", &done.achieved),
        ("drive_disp_m", &d.x),
    ];
    let m = meta::header(Kind::TimeHistory);
    tables::write_parquet(path, &cols, &m).with_context(|| format!("writing {}", path.display()))
}

/// The final drive's displacement per controller tick, as CSV (time_s, drive_disp_m).
fn write_drive(path: &Path, done: &TableIteration) -> anyhow::Result<()> {
    let d = &done.drive;
    let mut text = String::from("time_s,drive_disp_m\n");
    for k in 0..d.len() {
        text.push_str(&format!("{:.6},{:.9e}\n", d.time(k), d.x[k]));
    }
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, text)
        .and_then(|_| std::fs::rename(&tmp, path))
        .with_context(|| format!("writing {}", path.display()))
}
