//! `study plot RESULTS.parquet`: a study's results drawn in the house style of the reports. The
//! Sobol' indices with their bootstrap intervals (a Saltelli design; `study sensitivity`'s
//! analysis), each metric against each varied parameter, and the failed runs in parameter space:
//! SVG files and an index.html that shows them, in a folder of their own. A time history (`study
//! sim --out`, `study iterate`'s history.parquet) is drawn channel by channel against time.

use crate::orchestration::study::sensitivity::Indices;
use crate::shell::cli::PlotArgs;
use crate::shell::formats::measured_files::{input_if_user, read_columns_allow_nan};
use crate::shell::formats::meta::{self, Kind};
use crate::shell::formats::parquet_read;
use crate::shell::formats::parquet_write::AtomicFile;
use crate::shell::formats::results_reader::{analyse, load, Loaded};
use crate::shell::report::kit::{esc, legend, page_head};
use crate::shell::BadInput;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

type Plot = Result<String, Box<dyn std::error::Error>>;

const FIRST: RGBColor = RGBColor(31, 119, 180);
const TOTAL: RGBColor = RGBColor(214, 39, 40);
const OK: RGBColor = RGBColor(150, 150, 150);
const FAILED: RGBColor = RGBColor(214, 39, 40);
/// One colour per excitation, in table order (matplotlib's tab10), and its name.
const SERIES: [(RGBColor, &str); 6] = [
    (RGBColor(31, 119, 180), "blue"),
    (RGBColor(255, 127, 14), "orange"),
    (RGBColor(44, 160, 44), "green"),
    (RGBColor(148, 103, 189), "purple"),
    (RGBColor(140, 86, 75), "brown"),
    (RGBColor(227, 119, 194), "pink"),
];
/// Points drawn per scatter panel at most (every k-th row beyond), to keep the SVG light (about
/// 100 bytes a point); failed runs are all drawn.
const MAX_POINTS: usize = 1500;
/// The first line of an index.html this command wrote: a folder holding one may be redrawn.
const MARK: &str = "<!-- study plot -->";

pub fn run(args: &PlotArgs) -> anyhow::Result<()> {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| default_folder(&args.file));
    let index = plot(&args.file, &out, args.metrics.as_deref(), args.bootstrap)?;
    writeln!(std::io::stdout().lock(), "wrote {}", index.display())?;
    Ok(())
}

/// `RESULTS_plots` beside the results file.
fn default_folder(file: &Path) -> PathBuf {
    let stem = file.file_stem().map(|s| s.to_string_lossy().to_string());
    file.with_file_name(format!("{}_plots", stem.unwrap_or_default()))
}

/// Draws the plots of `file` into the folder `out`; returns the index.html path.
pub fn plot(
    file: &Path,
    out: &Path,
    metrics: Option<&[String]>,
    bootstrap: usize,
) -> anyhow::Result<PathBuf> {
    let meta = parquet_read::parquet_metadata(file).map_err(input_if_user)?;
    if meta::is(&meta, Kind::TimeHistory) {
        return plot_history(file, out, metrics);
    }
    let l = load(file, metrics)?;
    let status = parquet_read::read_strings(file, "status").map_err(input_if_user)?;
    check_folder(out)?;
    let indices = if l.saltelli() {
        analyse(&l, bootstrap, 0)?
    } else {
        Vec::new()
    };
    let mut files: Vec<(String, String)> = Vec::new();
    for (e, m, ix) in &indices {
        let title = format!("{m} at {}", l.excitations[*e]);
        if let Some(svg) = sobol_svg(&l.paths, ix, &title).map_err(drawing)? {
            files.push((format!("sobol_{}_{m}.svg", l.excitations[*e]), svg));
        }
    }
    for m in l
        .metrics
        .iter()
        .filter(|m| l.col(m).iter().any(|v| v.is_finite()))
    {
        files.push((
            format!("scatter_{m}.svg"),
            scatter_svg(&l, m).map_err(drawing)?,
        ));
    }
    let failed: Vec<bool> = status.iter().map(|s| s != "ok").collect();
    if failed.iter().any(|&f| f) {
        files.push((
            "failures.svg".into(),
            failures_svg(&l, &failed).map_err(drawing)?,
        ));
    }
    for (name, svg) in &files {
        write_atomic(&out.join(name), svg)?;
    }
    let index = out.join("index.html");
    write_atomic(&index, &page(file, &l, &status, &files)?)?;
    Ok(index)
}

/// A time history's channels (every numeric column but `time_s`, or those of `channels`), one
/// SVG each against time, and an index.html; returns its path.
fn plot_history(file: &Path, out: &Path, channels: Option<&[String]>) -> anyhow::Result<PathBuf> {
    let (fields, _) = parquet_read::parquet_batches(file).map_err(input_if_user)?;
    let numeric = |f: &&arrow_schema::Field| f.data_type().is_numeric();
    let names: Vec<String> = fields
        .iter()
        .filter(numeric)
        .map(|f| f.name().clone())
        .filter(|n| n != "time_s")
        .collect();
    let wanted: Vec<String> = match channels {
        None => names.clone(),
        Some(c) => {
            if let Some(bad) = c.iter().find(|c| !names.contains(c)) {
                return Err(BadInput(format!(
                    "{}: no channel {bad:?}; the file has {}",
                    file.display(),
                    names.join(", ")
                ))
                .into());
            }
            c.to_vec()
        }
    };
    let mut read: Vec<&str> = vec!["time_s"];
    read.extend(wanted.iter().map(String::as_str));
    let t = read_columns_allow_nan(file, &read).map_err(input_if_user)?;
    check_folder(out)?;
    let time = t.column("time_s").expect("read above");
    let mut files = Vec::new();
    for name in &wanted {
        let v = t.column(name).expect("read above");
        files.push((
            format!("channel_{name}.svg"),
            history_svg(time, v, name).map_err(drawing)?,
        ));
    }
    for (name, svg) in &files {
        write_atomic(&out.join(name), svg)?;
    }
    let mut h = String::from(MARK);
    h.push('\n');
    page_head(&mut h, &format!("study plot: {}", file.display()), &[])?;
    writeln!(
        h,
        "<p>A time history: {} rows, {} channels against time.</p>",
        time.len(),
        files.len()
    )?;
    section(
        &mut h,
        "Channels",
        "channel_",
        &files,
        "Each channel over the whole run.",
    )?;
    h.push_str("</body></html>\n");
    let index = out.join("index.html");
    write_atomic(&index, &h)?;
    Ok(index)
}

/// One channel against time (at most about 4 000 points: every k-th row beyond).
fn history_svg(time: &[f64], v: &[f64], name: &str) -> Plot {
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (900, 300)).into_drawing_area();
        root.fill(&WHITE)?;
        let (t0, t1) = span(time);
        let (lo, hi) = span(v);
        let mut c = ChartBuilder::on(&root)
            .caption(name, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, lo..hi)?;
        c.configure_mesh().x_desc("t (s)").y_desc(name).draw()?;
        let pts = thinned(time.len(), 4000).map(|k| (time[k], v[k]));
        for run in crate::shell::report::kit::finite_runs(pts) {
            c.draw_series(LineSeries::new(run, FIRST.stroke_width(1)))?;
        }
        root.present()?;
    }
    Ok(s)
}

fn drawing(e: Box<dyn std::error::Error>) -> anyhow::Error {
    anyhow::anyhow!("drawing a plot: {e}")
}

/// The folder is new, empty, or one this command drew before; anything else is refused.
fn check_folder(out: &Path) -> anyhow::Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(BadInput(format!(
            "{}: is not a folder (--out names the plots' folder)",
            out.display()
        ))
        .into());
    }
    let ours = std::fs::read_to_string(out.join("index.html")).is_ok_and(|t| t.starts_with(MARK));
    let empty = std::fs::read_dir(out).map_or(true, |mut d| d.next().is_none());
    if !(ours || empty) {
        return Err(BadInput(format!("{}: holds other files (no index.html of study plot); nothing was written: choose another --out", out.display())).into());
    }
    std::fs::create_dir_all(out)
        .map_err(|e| BadInput(format!("{}: cannot create the folder: {e}", out.display())))?;
    // An earlier drawing's plots go: the new index shows only the new ones.
    if ours {
        for f in std::fs::read_dir(out)?.flatten() {
            if f.path().extension().is_some_and(|x| x == "svg") {
                std::fs::remove_file(f.path())?;
            }
        }
    }
    Ok(())
}

fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    let f = AtomicFile::new(path);
    std::fs::write(&f.tmp, text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    f.commit()?;
    Ok(())
}

/// The index page: what the file is, then each plot.
fn page(
    file: &Path,
    l: &Loaded,
    status: &[String],
    files: &[(String, String)],
) -> anyhow::Result<String> {
    let mut h = String::from(MARK);
    h.push('\n');
    page_head(&mut h, &format!("study plot: {}", file.display()), &[])?;
    let failed = status.iter().filter(|s| *s != "ok").count();
    writeln!(
        h,
        "<p>{} design, {} rows, {} varied parameters ({}), {} failed or invalid runs.</p>",
        esc(&l.design),
        status.len(),
        l.paths.len(),
        esc(&l.paths.join(", ")),
        failed
    )?;
    section(
        &mut h,
        "Sobol' indices",
        "sobol_",
        files,
        if l.saltelli() {
            "First-order (S1, blue) and total (ST, red) indices with their 95 % bootstrap intervals, per excitation and metric (as study sensitivity computes them)."
        } else {
            "Sobol' indices need a Saltelli design (`sampling = \"saltelli\"`); this file's design has none. `study sensitivity` gives SRC and PRCC for any design."
        },
    )?;
    section(
        &mut h,
        "Each metric against each parameter",
        "scatter_",
        files,
        &format!(
            "A point per run, coloured by excitation: {}.",
            excitation_colours(l)
        ),
    )?;
    let note = if failed == 0 {
        "No run failed or was invalid."
    } else {
        "The failed and invalid runs (red) among those that ended (grey), in each pair of varied parameters."
    };
    section(
        &mut h,
        "Failed runs in parameter space",
        "failures",
        files,
        note,
    )?;
    h.push_str("<p>The numbers behind every plot are in the results file; `study sensitivity` writes the indices as a table.</p>\n</body></html>\n");
    Ok(h)
}

fn section(
    h: &mut String,
    title: &str,
    prefix: &str,
    files: &[(String, String)],
    note: &str,
) -> anyhow::Result<()> {
    writeln!(h, "<h2>{}</h2>\n<p>{}</p>", esc(title), esc(note))?;
    for (name, _) in files.iter().filter(|(n, _)| n.starts_with(prefix)) {
        writeln!(
            h,
            "<figure><img src=\"{n}\" alt=\"{n}\"><figcaption>{n}</figcaption></figure>",
            n = esc(name)
        )?;
    }
    Ok(())
}

/// Each excitation's name with its colour in the scatter plots, in words.
fn excitation_colours(l: &Loaded) -> String {
    let each = l.excitations.iter().enumerate();
    each.map(|(i, e)| format!("{e} {}", SERIES[i % SERIES.len()].1))
        .collect::<Vec<_>>()
        .join(", ")
}

/// S1 and ST bars per parameter with their intervals; None without Sobol' indices (too few base
/// points ended).
fn sobol_svg(
    paths: &[String],
    ix: &Indices,
    title: &str,
) -> Result<Option<String>, Box<dyn std::error::Error>> {
    let Some(sobol) = &ix.sobol else {
        return Ok(None);
    };
    let top = sobol
        .iter()
        .flat_map(|s| [s.first.ci_high, s.total.ci_high, s.total.value])
        .filter(|v| v.is_finite())
        .fold(0.1f64, f64::max);
    let bottom = sobol
        .iter()
        .map(|s| s.first.ci_low)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::min);
    let mut s = String::new();
    {
        let width = (120 + 90 * paths.len()) as u32;
        let root = SVGBackend::with_string(&mut s, (width.max(480), 320)).into_drawing_area();
        root.fill(&WHITE)?;
        let n = paths.len() as f64;
        let mut c = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(-0.5..n - 0.5, bottom..1.05 * top)?;
        let labels: Vec<String> = paths
            .iter()
            .map(|p| p.rsplit('.').next().unwrap_or(p).to_string())
            .collect();
        c.configure_mesh()
            .disable_x_mesh()
            .x_labels(paths.len().max(2))
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                    labels[i as usize].clone()
                } else {
                    String::new()
                }
            })
            .y_desc("Sobol' index")
            .draw()?;
        for (k, colour, label) in [(0, FIRST, "S1"), (1, TOTAL, "ST")] {
            let dx = if k == 0 { -0.18 } else { 0.18 };
            let est = |i: usize| {
                if k == 0 {
                    sobol[i].first
                } else {
                    sobol[i].total
                }
            };
            c.draw_series((0..paths.len()).map(|i| {
                let x = i as f64 + dx;
                Rectangle::new(
                    [(x - 0.15, 0.0), (x + 0.15, est(i).value)],
                    colour.mix(0.7).filled(),
                )
            }))?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 4), (x + 12, y + 4)], colour.filled()));
            c.draw_series((0..paths.len()).map(|i| {
                let x = i as f64 + dx;
                PathElement::new(
                    vec![(x, est(i).ci_low), (x, est(i).ci_high)],
                    BLACK.stroke_width(1),
                )
            }))?;
        }
        legend(&mut c)?;
        root.present()?;
    }
    Ok(Some(s))
}

/// Every k-th row, at most `max`.
fn thinned(rows: usize, max: usize) -> impl Iterator<Item = usize> {
    (0..rows).step_by(rows.div_ceil(max).max(1))
}

/// A metric against each varied parameter: one panel per parameter, a colour per excitation.
fn scatter_svg(l: &Loaded, metric: &str) -> Plot {
    let y = l.col(metric);
    let exc = l.col("excitation_id");
    let finite = y.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite
        .clone()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo < hi {
        (lo, hi)
    } else if lo.is_finite() {
        (lo - 1.0, lo + 1.0)
    } else {
        (0.0, 1.0)
    };
    let cols = l.paths.len().min(3);
    let rows = l.paths.len().div_ceil(cols);
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (320 * cols as u32, 260 * rows as u32))
            .into_drawing_area();
        root.fill(&WHITE)?;
        for (p, area) in root
            .split_evenly((rows, cols))
            .iter()
            .enumerate()
            .take(l.paths.len())
        {
            let x = l.col(&l.columns[p]);
            let (xlo, xhi) = span(x);
            let mut c = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(xlo..xhi, lo..hi)?;
            c.configure_mesh()
                .x_desc(l.paths[p].as_str())
                .y_desc(metric)
                .x_labels(4)
                .y_labels(5)
                .draw()?;
            c.draw_series(
                thinned(y.len(), MAX_POINTS)
                    .filter(|&r| y[r].is_finite())
                    .map(|r| {
                        let colour = SERIES[exc[r] as usize % SERIES.len()].0;
                        Circle::new((x[r], y[r]), 2, colour.mix(0.5).filled())
                    }),
            )?;
        }
        root.present()?;
    }
    Ok(s)
}

fn span(x: &[f64]) -> (f64, f64) {
    let (lo, hi) = x
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if !(lo < hi) {
        let c = if lo.is_finite() { lo } else { 0.0 };
        return (c - 0.5 * c.abs().max(1.0), c + 0.5 * c.abs().max(1.0));
    }
    let pad = 0.03 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Each pair of varied parameters: the runs that ended (grey) and those that did not (red).
fn failures_svg(l: &Loaded, failed: &[bool]) -> Plot {
    let pairs: Vec<(usize, usize)> = (0..l.paths.len())
        .flat_map(|i| (i + 1..l.paths.len()).map(move |j| (i, j)))
        .take(15)
        .collect();
    let pairs = if pairs.is_empty() {
        vec![(0, 0)]
    } else {
        pairs
    };
    let cols = pairs.len().min(3);
    let rows = pairs.len().div_ceil(cols);
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (300 * cols as u32, 260 * rows as u32))
            .into_drawing_area();
        root.fill(&WHITE)?;
        for (&(i, j), area) in pairs.iter().zip(root.split_evenly((rows, cols)).iter()) {
            let (x, y) = (l.col(&l.columns[i]), l.col(&l.columns[j]));
            let (xr, yr) = (span(x), span(y));
            let mut c = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?;
            c.configure_mesh()
                .x_desc(l.paths[i].as_str())
                .y_desc(l.paths[j].as_str())
                .x_labels(4)
                .y_labels(5)
                .draw()?;
            let ok = thinned(x.len(), MAX_POINTS / 3).filter(|&r| !failed[r]);
            c.draw_series(ok.map(|r| Circle::new((x[r], y[r]), 2, OK.mix(0.4).filled())))?;
            c.draw_series(
                (0..x.len())
                    .filter(|&r| failed[r])
                    .map(|r| Circle::new((x[r], y[r]), 3, FAILED.filled())),
            )?;
        }
        root.present()?;
    }
    Ok(s)
}
