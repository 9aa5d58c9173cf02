//! The HTML report of `study tune`: the objective per generation, the gains (start against
//! tuned), and per motion of the plan the errors and the margin to valve saturation, with the
//! response spectra of the target, the start and the tuned gains overlaid. The numbers behind it
//! are in evaluations.parquet and generations.parquet beside it.

use crate::kernel::excitation::Reference;
use crate::orchestration::preparation::tune::{error_term, Tuned, Tuner};
use crate::orchestration::runs::single::SimOutcome;
use crate::shell::report::kit::{draw_line, esc, legend, page_head};
use plotters::prelude::*;
use std::fmt::Write as _;

/// The start and the tuned gains on the nominal model (no uncertain draw), each excitation with
/// its history: for the report's spectra and errors.
pub struct Nominal {
    pub start: Vec<SimOutcome>,
    pub tuned: Vec<SimOutcome>,
}

const G: f64 = 9.806_65;
const START: RGBColor = RGBColor(31, 119, 180);
const TUNED: RGBColor = RGBColor(214, 39, 40);

type Plot = Result<String, Box<dyn std::error::Error>>;

/// The whole report as one self-contained HTML page.
pub fn html(
    tuner: &Tuner,
    t: &Tuned,
    nominal: &Nominal,
    refs: &[Reference],
    wall_s: f64,
) -> anyhow::Result<String> {
    let plot = |r: Plot| r.map_err(|e| anyhow::anyhow!("drawing a plot: {e}"));
    let mut h = String::new();
    head(&mut h, &tuner.spec.name)?;
    summary(&mut h, tuner, t, wall_s)?;
    gains_table(&mut h, tuner, t)?;
    writeln!(
        h,
        "<h2>Objective per generation</h2>\n<figure class=\"plot\" id=\"generations\">{}</figure>",
        plot(generations_svg(t))?
    )?;
    for (e, exc) in tuner.spec.excitations.iter().enumerate() {
        writeln!(
            h,
            "<h2 id=\"motion-{n}\">{n}</h2>\n<p>{}</p>",
            esc(&exc.spec.describe()),
            n = esc(&exc.name)
        )?;
        errors_table(&mut h, tuner, t, nominal, e)?;
        if let Some((spec, target)) = &refs[e].spectrum {
            let svg = plot(spectrum_svg(
                spec,
                target,
                &refs[e],
                &nominal.start[e],
                &nominal.tuned[e],
            ))?;
            writeln!(h, "<figure class=\"plot spectrum\">{svg}</figure>")?;
        }
    }
    h.push_str("<p>Every run of every candidate is in evaluations.parquet, a row per generation in generations.parquet, beside this page.</p>\n</body></html>\n");
    Ok(h)
}

fn head(h: &mut String, name: &str) -> anyhow::Result<()> {
    let legend = [
        ("start (published) gains", "#1f77b4"),
        ("tuned gains", "#d62728"),
        ("target", "#000"),
    ];
    page_head(h, &format!("study tune: {name}"), &legend)
}

fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.5}")
    } else {
        "-".into()
    }
}

fn change(a: f64, b: f64) -> String {
    if a.is_finite() && b.is_finite() && a != 0.0 {
        format!("{:+.1} %", 100.0 * (b / a - 1.0))
    } else {
        "-".into()
    }
}

fn summary(h: &mut String, tuner: &Tuner, t: &Tuned, wall_s: f64) -> anyhow::Result<()> {
    let runs: usize = t.evaluations.iter().map(|e| e.rows.len()).sum();
    writeln!(
        h,
        "<p>{} generations, {} runs in {wall_s:.1} s; stopped at {}. Seed {}.</p>",
        t.generations.len() - 1,
        runs,
        esc(&t.stopped),
        tuner.spec.seed
    )?;
    h.push_str("<h2>Summary</h2>\n<table id=\"summary\"><tr><th></th><th>start</th><th>tuned</th><th>change</th></tr>\n");
    let mut row = |name: &str, a: f64, b: f64| {
        writeln!(
            h,
            "<tr><td>{name}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            fmt(a),
            fmt(b),
            change(a, b)
        )
    };
    row("objective", t.start.objective, t.best.objective)?;
    if tuner.draws.len() > 1 {
        row("mean over the draws", t.start.mean, t.best.mean)?;
        let q = format!(
            "{:.0}th percentile over the draws",
            100.0 * tuner.reported_quantile()
        );
        row(&q, t.start.quantile, t.best.quantile)?;
    }
    row(
        "max |u| / u_lim (all runs)",
        t.start.valve_fraction,
        t.best.valve_fraction,
    )?;
    h.push_str("</table>\n");
    if let Some(why) = &t.start.infeasible {
        writeln!(
            h,
            "<p style=\"color:#a00\">The start is infeasible: {}</p>",
            esc(why)
        )?;
    }
    Ok(())
}

fn gains_table(h: &mut String, tuner: &Tuner, t: &Tuned) -> anyhow::Result<()> {
    h.push_str("<h2>Gains</h2>\n<table id=\"gains\"><tr><th>gain</th><th>low</th><th>high</th><th>start</th><th>tuned</th></tr>\n");
    for (i, g) in tuner.spec.gains.iter().enumerate() {
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.6}</td><td>{:.6}</td></tr>",
            g.info.path(),
            g.low,
            g.high,
            t.start.gains[i],
            t.best.gains[i]
        )?;
    }
    h.push_str("</table>\n");
    Ok(())
}

/// Motion `e`: each objective metric (as an error) and the valve margin, start against tuned,
/// on the nominal model.
fn errors_table(
    h: &mut String,
    tuner: &Tuner,
    t: &Tuned,
    n: &Nominal,
    e: usize,
) -> anyhow::Result<()> {
    h.push_str("<table class=\"errors\"><tr><th>on the nominal model</th><th>start</th><th>tuned</th><th>change</th></tr>\n");
    let (a, b) = (n.start[e].result.metrics, n.tuned[e].result.metrics);
    let (ca, cb) = (a.columns(), b.columns());
    for (m, w) in &tuner.spec.objective {
        let get = |c: &[(&str, f64)]| {
            c.iter()
                .find(|x| x.0 == *m)
                .map_or(f64::NAN, |x| error_term(m, x.1))
        };
        let (va, vb) = (get(&ca), get(&cb));
        writeln!(
            h,
            "<tr><td>{m} (weight {w})</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            fmt(va),
            fmt(vb),
            change(va, vb)
        )?;
    }
    let u_lim = tuner.spec.model.servovalve.u_lim;
    let worst = |ev: &crate::orchestration::preparation::tune::Evaluation| {
        let n_e = tuner.spec.excitations.len();
        ev.rows
            .iter()
            .skip(e)
            .step_by(n_e)
            .map(|r| r.metrics.max_abs_u_v / u_lim)
            .fold(f64::NAN, f64::max)
    };
    let margin = |u: f64| 1.0 - u;
    writeln!(h, "<tr><td>margin to valve saturation, 1 - max|u|/u_lim</td><td>{}</td><td>{}</td><td></td></tr>", fmt(margin(a.max_abs_u_v / u_lim)), fmt(margin(b.max_abs_u_v / u_lim)))?;
    if tuner.draws.len() > 1 {
        writeln!(
            h,
            "<tr><td>the same, smallest over the draws</td><td>{}</td><td>{}</td><td></td></tr>",
            fmt(margin(worst(&t.start))),
            fmt(margin(worst(&t.best)))
        )?;
    }
    h.push_str("</table>\n");
    Ok(())
}

/// Target, start and tuned response spectra (PSA in g against period, log period).
fn spectrum_svg(
    spec: &crate::kernel::spectrum::SpectrumSpec,
    target: &[f64],
    r: &Reference,
    a: &SimOutcome,
    b: &SimOutcome,
) -> Plot {
    let (pa, pb) = (a.history.accel_psa(r, spec), b.history.accel_psa(r, spec));
    let periods = &spec.periods;
    let top = target
        .iter()
        .chain(&pa)
        .chain(&pb)
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(*v))
        / G;
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let (t0, t1) = (periods[0], periods[periods.len() - 1]);
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!("response spectrum, {:.0} % damping", 100.0 * spec.damping),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d((t0..t1).log_scale(), 0.0..1.08 * top.max(1e-9))?;
        c.configure_mesh()
            .x_desc("period (s)")
            .y_desc("PSA (g)")
            .draw()?;
        let line = |v: &[f64]| {
            periods
                .iter()
                .zip(v)
                .map(|(t, a)| (*t, a / G))
                .collect::<Vec<_>>()
        };
        c.draw_series(LineSeries::new(line(target), BLACK.stroke_width(2)))?
            .label("target")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
        c.draw_series(LineSeries::new(line(&pa), START.stroke_width(2)))?
            .label("start")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], START));
        c.draw_series(LineSeries::new(line(&pb), TUNED.stroke_width(2)))?
            .label("tuned")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], TUNED));
        legend(&mut c)?;
        root.present()?;
    }
    Ok(s)
}

/// Each generation's best (points) and the best so far (line); the start as generation 0.
fn generations_svg(t: &Tuned) -> Plot {
    let pts = |f: &dyn Fn(&crate::orchestration::preparation::tune::GenerationSummary) -> f64| {
        t.generations
            .iter()
            .map(|g| (g.generation as f64, f(g)))
            .collect::<Vec<_>>()
    };
    let (best, so_far) = (pts(&|g| g.best), pts(&|g| g.best_so_far));
    let top = best
        .iter()
        .chain(&so_far)
        .map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let last = t.generations.len().max(2) as f64 - 1.0;
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 320)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut c = ChartBuilder::on(&root)
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.3..last + 0.3, 0.0..1.05 * top.max(1e-12))?;
        c.configure_mesh()
            .x_desc("generation")
            .y_desc("objective")
            .draw()?;
        let dots = best
            .iter()
            .filter(|p| p.1.is_finite())
            .map(|&p| Circle::new(p, 3, START.filled()));
        c.draw_series(dots)?
            .label("best of the generation")
            .legend(|(x, y)| Circle::new((x + 8, y), 3, START.filled()));
        draw_line(
            &mut c,
            so_far.into_iter(),
            TUNED.stroke_width(2),
            Some("best so far"),
        )?;
        legend(&mut c)?;
        root.present()?;
    }
    Ok(s)
}
