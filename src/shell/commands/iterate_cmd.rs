//! `study iterate`: offline iteration of an earthquake test's drive on the virtual table.

use crate::kernel::excitation::Reference;
use crate::kernel::simulate::LaneStatus;
use crate::orchestration::preparation::drive_iteration::{
    iterate_on_model, IterationRow, IterationSettings, NoLog, RunLog, TableIteration, MIN_TARGET_S,
};
use crate::orchestration::runs::building_response::{building_response, BuildingResponse};
use crate::orchestration::runs::single::{run_one, History};
use crate::orchestration::runs::spec::SimSpec;
use crate::shell::cli::IterateArgs;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::job::interrupt;
use crate::shell::job::iterate_journal_file::{Inputs, IterateLog, JOURNAL};
use crate::shell::job::outputs::{output_paths, write_whole};
use crate::shell::run_spec;
use crate::shell::BadInput;
use crate::shell::RunFailed;
use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The files `--out` receives.
const OUTPUTS: [&str; 5] = [
    "iterations.parquet",
    "frf.parquet",
    "drive.csv",
    "history.parquet",
    "iteration.svg",
];

pub fn run(args: &IterateArgs) -> anyhow::Result<()> {
    let settings = settings(args)?;
    let spec = run_spec::load_spec(&args.file, args.model.as_deref())?;
    let targets = outputs(args)?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let target = run_spec::build_reference(&spec, base)?;
    let seconds = target.len() as f64 / target.f_s;
    if seconds < MIN_TARGET_S {
        return Err(BadInput(format!(
            "{}: the excitation is {seconds:.2} s long; the iteration needs at least \
             {MIN_TARGET_S:.1} s",
            args.file.display(),
        ))
        .into());
    }
    let mut journal = open_journal(args, &settings)?;
    let mut o = std::io::stdout().lock();
    header(&mut o, args, &spec, &settings, journal.as_ref())?;
    let print = |r: &IterationRow| {
        println!(
            "  {:>9} {:>22.3} {:>6.3}",
            r.iteration,
            100.0 * r.rms_error_ratio,
            r.step * settings.gain
        );
    };
    let log: &mut dyn RunLog = match journal.as_mut() {
        Some(j) => j,
        None => &mut NoLog,
    };
    let done = iterate_on_model(&spec.model, &spec.solver, &target, &settings, log, print);
    let done = match done {
        Ok(done) => done,
        Err(e) => return Err(not_done(args, journal, e)),
    };
    summary(&mut o, &done, &settings)?;
    if let Some(b) = building_with(&spec, &done.drive) {
        write!(o, "\n  with the kept drive\n{b}")?;
    }
    if let Some(dir) = &args.out {
        write_outputs(dir, &targets, &done, &spec.resolved_toml())?;
        if let Some(j) = journal {
            j.remove()?;
        }
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

/// The lines before the iteration's table: the file, the model, the target, the settings, what
/// a resumed iteration replays, and the table's header.
fn header(
    o: &mut impl Write,
    args: &IterateArgs,
    spec: &SimSpec,
    settings: &IterationSettings,
    journal: Option<&IterateLog>,
) -> std::io::Result<()> {
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
        "  settings    gain {}, regularisation {:e}, at most {} iterations, goal {:.2} % rms, FRF from the iteration's own runs",
        settings.gain,
        settings.epsilon,
        settings.max_iterations,
        100.0 * settings.goal,
    )?;
    if let Some(j) = journal {
        if j.replayed_runs() > 0 {
            writeln!(
                o,
                "  resumed     {} runs in {}, replayed, not made again",
                j.replayed_runs(),
                j.path().display()
            )?;
        }
    }
    writeln!(
        o,
        "\n  {:>9} {:>22} {:>6}",
        "iteration", "rms accel error, %", "step"
    )?;
    Ok(())
}

/// What the building on the platen (if the model has one) experiences under `drive`.
fn building_with(spec: &SimSpec, drive: &Reference) -> Option<BuildingResponse> {
    if !spec.model.effects.building {
        return None;
    }
    let mut h = History::with_capacity(drive.len());
    let run = run_one(&spec.model, drive, &spec.solver, &mut h).ok()?;
    (run.status == LaneStatus::Ok).then_some(())?;
    building_response(&spec.model, &h)
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
    if !(args.epsilon > 0.0 && args.epsilon < 1.0) {
        return Err(BadInput(format!("--epsilon {}: must be in (0, 1)", args.epsilon)).into());
    }
    if args.iterations == 0 {
        return Err(BadInput("--iterations 0: at least one".into()).into());
    }
    Ok(IterationSettings {
        gain: args.gain,
        goal: args.goal,
        max_iterations: args.iterations,
        epsilon: args.epsilon,
        ..Default::default()
    })
}

/// The output paths, refused before any work where one exists and --force is not given; a
/// fresh start also refuses an interrupted iteration's journal, and `--resume` needs it.
fn outputs(args: &IterateArgs) -> anyhow::Result<Vec<PathBuf>> {
    let Some(dir) = &args.out else {
        return Ok(Vec::new());
    };
    let journal = dir.join(JOURNAL).exists();
    if args.resume && !journal {
        return Err(BadInput(format!(
            "{}: no interrupted iteration to resume (no {JOURNAL})",
            dir.display()
        ))
        .into());
    }
    if !args.resume && !args.force && journal {
        return Err(BadInput(format!(
            "{}: holds an interrupted iteration ({JOURNAL}): continue it with --resume, or start over with --force",
            dir.display()
        ))
        .into());
    }
    output_paths(dir, &OUTPUTS, args.force)
}

/// With --out, the iteration's journal (a new one, or with --resume the interrupted one's, its
/// inputs checked) and the signal handlers that stop it between runs.
fn open_journal(
    args: &IterateArgs,
    settings: &IterationSettings,
) -> anyhow::Result<Option<IterateLog>> {
    let Some(dir) = &args.out else {
        return Ok(None);
    };
    let read = |p: &Path| {
        crate::shell::formats::input::read_input_text(p)
            .map_err(|e| BadInput(format!("{}: cannot read: {e}", p.display())))
    };
    let spec_text = read(&args.file)?;
    let model_text = args.model.as_deref().map(read).transpose()?;
    // The flags as a user gives them (each number's shortest form that reads back to its bits).
    let settings = format!(
        "--iterations {} --gain {} --goal {} --epsilon {}",
        settings.max_iterations, settings.gain, settings.goal, settings.epsilon
    );
    let inputs = Inputs {
        spec_text: &spec_text,
        model_text: model_text.as_deref(),
        settings: &settings,
    };
    std::fs::create_dir_all(dir).map_err(|e| {
        BadInput(format!(
            "{}: cannot create the output folder: {e}",
            dir.display()
        ))
    })?;
    let log = match args.resume {
        true => IterateLog::resume(dir, &inputs)?,
        false => IterateLog::start(dir, &inputs)?,
    };
    interrupt::install().context("installing the signal handlers")?;
    Ok(Some(log))
}

/// The error of an iteration that did not finish: stopped ([`stopped`]), or failed (its journal
/// removed: there is nothing to resume).
fn not_done(args: &IterateArgs, journal: Option<IterateLog>, e: String) -> anyhow::Error {
    match journal {
        Some(j) if j.stop() => stopped(args, &j),
        Some(j) => match j.remove() {
            Ok(()) => RunFailed(format!("{}: {e}", args.file.display())).into(),
            Err(removing) => removing,
        },
        None => RunFailed(format!("{}: {e}", args.file.display())).into(),
    }
}

/// An iteration stopped before its next run: by a signal (exit 128 + it, the journal kept for
/// --resume), or by a fault of its journal.
fn stopped(args: &IterateArgs, j: &IterateLog) -> anyhow::Error {
    if let Some(fault) = &j.fault {
        return BadInput(fault.clone()).into();
    }
    let signal = interrupt::requested().unwrap_or(signal_hook::consts::SIGTERM);
    let model = args
        .model
        .as_ref()
        .map_or(String::new(), |m| format!(" --model {}", m.display()));
    let out = args.out.as_ref().expect("a journal needs --out").display();
    interrupt::Interrupted {
        signal,
        message: format!(
            "stopped by {} after {} runs, kept in {}; continue with: study iterate {}{model} --out {out} --iterations {} --gain {} --goal {} --epsilon {} --resume",
            interrupt::name(signal),
            j.runs(),
            j.path().display(),
            args.file.display(),
            args.iterations,
            args.gain,
            args.goal,
            args.epsilon,
        ),
    }
    .into()
}

fn summary(
    o: &mut impl Write,
    done: &TableIteration,
    settings: &IterationSettings,
) -> anyhow::Result<()> {
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
    let ran = done.rows.last().map_or(0, |r| r.iteration);
    writeln!(
        o,
        "  outcome     {}",
        done.outcome.describe(settings.goal, ran)
    )?;
    Ok(())
}

/// iterations.parquet, frf.parquet, drive.csv, history.parquet and iteration.svg (each written
/// whole, then renamed).
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
    parquet_write::write_parquet(&paths[0], &cols, &m)
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
    parquet_write::write_parquet(&paths[1], &cols, &m)
        .with_context(|| format!("writing {}", paths[1].display()))?;
    write_drive(&paths[2], done)?;
    write_history(&paths[3], done)?;
    let svg = plot(done).map_err(|e| anyhow::anyhow!("drawing {}: {e}", paths[4].display()))?;
    write_whole(&paths[4], svg.as_bytes())
}

/// The error of each iteration (left) and the target against the achieved acceleration with the
/// kept drive (right), as SVG.
fn plot(done: &TableIteration) -> Result<String, Box<dyn std::error::Error>> {
    use crate::shell::report::kit::{draw_line, legend};
    use plotters::prelude::*;
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (960, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let (left, right) = root.split_horizontally(320);
        let last = done.rows.len() as f64 - 1.0;
        let top = done
            .rows
            .iter()
            .map(|r| 100.0 * r.rms_error_ratio)
            .fold(1.0, f64::max);
        let mut c = ChartBuilder::on(&left)
            .caption("rms acceleration error", ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(-0.2..last.max(1.0) + 0.2, 0.0..1.05 * top)?;
        c.configure_mesh()
            .x_desc("iteration")
            .y_desc("% of the target's rms")
            .draw()?;
        let pts: Vec<(f64, f64)> = done
            .rows
            .iter()
            .map(|r| (r.iteration as f64, 100.0 * r.rms_error_ratio))
            .collect();
        c.draw_series(LineSeries::new(pts.clone(), BLUE.stroke_width(2)))?;
        c.draw_series(pts.iter().map(|&p| Circle::new(p, 3, BLUE.filled())))?;
        let f_s = done.drive.f_s;
        let (w0, w1) = done.drive.window;
        let t = |k: usize| k as f64 / f_s;
        let peak = done.target[w0..w1]
            .iter()
            .chain(&done.achieved[w0..w1])
            .fold(0.0, |m: f64, v| m.max(v.abs()));
        let mut c = ChartBuilder::on(&right)
            .caption(
                "target and achieved acceleration (kept drive)",
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(t(w0)..t(w1), -1.05 * peak..1.05 * peak)?;
        c.configure_mesh().x_desc("t (s)").y_desc("m/s²").draw()?;
        // At most about 4 000 points a line (every step-th tick).
        let step = ((w1 - w0) / 4000).max(1);
        let line = |v: &[f64]| {
            (w0..w1)
                .step_by(step)
                .map(|k| (t(k), v[k]))
                .collect::<Vec<_>>()
        };
        let target = line(&done.target).into_iter();
        draw_line(&mut c, target, BLACK.stroke_width(2), Some("target"))?;
        let achieved = line(&done.achieved).into_iter();
        draw_line(&mut c, achieved, RED.stroke_width(1), Some("achieved"))?;
        legend(&mut c)?;
        root.present()?;
    }
    Ok(s)
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
    parquet_write::write_parquet(path, &cols, &m)
        .with_context(|| format!("writing {}", path.display()))
}

/// The final drive's displacement per controller tick, as CSV (time_s, drive_disp_m).
fn write_drive(path: &Path, done: &TableIteration) -> anyhow::Result<()> {
    let d = &done.drive;
    let mut text = String::from("time_s,drive_disp_m\n");
    for k in 0..d.len() {
        text.push_str(&format!("{:.6},{:.9e}\n", d.time(k), d.x[k]));
    }
    write_whole(path, text.as_bytes())
}
