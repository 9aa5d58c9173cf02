//! The HTML report of `study compare`: a summary table and, drawn by plotters as inline SVG, the
//! time-history overlay with its residual, the harmonic bars (model against measured) per test,
//! the error against amplitude across the campaign, and the residual mapped onto the plant's
//! states. The numbers behind every plot are the Parquet tables written beside it. A non-finite
//! value is never drawn: a line breaks around it and a bar is left out, and a table cell shows "-".

use crate::kernel::metrics::N_HARM;
use crate::orchestration::diagnosis::compare::ComparedTest;
use crate::orchestration::diagnosis::statemap::{self, Residual, StateMap};
use crate::orchestration::diagnosis::states::State;
use crate::orchestration::measured::timebase::fmt_rate;
use plotters::prelude::*;
use std::fmt::Write as _;

const MEASURED: RGBColor = RGBColor(31, 119, 180);
const MODEL: RGBColor = RGBColor(214, 39, 40);
const RESIDUAL: RGBColor = RGBColor(90, 90, 90);

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-12);
    (lo - pad, hi + pad)
}

/// The runs of consecutive finite points of a line (a NaN breaks the line; it is never drawn).
pub(crate) fn finite_runs(pts: impl Iterator<Item = (f64, f64)>) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for p in pts {
        if p.0.is_finite() && p.1.is_finite() {
            runs.last_mut().expect("one run").push(p);
        } else if !runs.last().expect("one run").is_empty() {
            runs.push(Vec::new());
        }
    }
    runs.retain(|r| !r.is_empty());
    runs
}

/// Draws a line of possibly non-finite points as its finite runs, the first run labelled `label`
/// in the legend.
pub(crate) fn draw_line<DB: DrawingBackend>(
    c: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    pts: impl Iterator<Item = (f64, f64)>,
    style: ShapeStyle,
    label: Option<&str>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    for (i, run) in finite_runs(pts).into_iter().enumerate() {
        let series = c.draw_series(LineSeries::new(run, style))?;
        if let (0, Some(l)) = (i, label) {
            series
                .label(l)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], style));
        }
    }
    Ok(())
}

/// A chart's legend in the house style: the series' labels on a translucent white box.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    c: &mut ChartContext<'a, DB, CT>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Measured and model acceleration over the window, and their residual below.
fn overlay_svg(r: &ComparedTest) -> Result<String, Box<dyn std::error::Error>> {
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 420)).into_drawing_area();
        root.fill(&WHITE)?;
        let (top, bottom) = root.split_vertically(280);
        let t = &r.test.samples.time;
        let meas = &r.test.measured.accel;
        let (tx0, tx1) = (t[0], t[t.len() - 1]);
        let (y0, y1) = range(meas.iter().chain(&r.accel_model).copied());
        let mut c = ChartBuilder::on(&top)
            .caption(
                format!("{}: platen acceleration", r.test.name),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(20)
            .y_label_area_size(55)
            .build_cartesian_2d(tx0..tx1, y0..y1)?;
        c.configure_mesh().y_desc("m/s²").draw()?;
        draw_line(
            &mut c,
            t.iter().copied().zip(meas.iter().copied()),
            MEASURED.stroke_width(2),
            Some("measured"),
        )?;
        draw_line(
            &mut c,
            t.iter().copied().zip(r.accel_model.iter().copied()),
            MODEL.stroke_width(1),
            Some("model"),
        )?;
        legend(&mut c)?;
        let res: Vec<f64> = r.accel_model.iter().zip(meas).map(|(m, x)| m - x).collect();
        let (r0, r1) = range(res.iter().copied());
        let mut c = ChartBuilder::on(&bottom)
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(55)
            .build_cartesian_2d(tx0..tx1, r0..r1)?;
        c.configure_mesh()
            .x_desc("t (s)")
            .y_desc("model − meas.")
            .draw()?;
        draw_line(
            &mut c,
            t.iter().copied().zip(res.iter().copied()),
            RESIDUAL.into(),
            None,
        )?;
        root.present()?;
    }
    Ok(s)
}

/// h2 … h9, measured and model, as grouped bars.
fn harmonics_svg(r: &ComparedTest) -> Result<String, Box<dyn std::error::Error>> {
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 300)).into_drawing_area();
        root.fill(&WHITE)?;
        let c = &r.comparison;
        let top = c
            .h_measured
            .iter()
            .chain(&c.h_model)
            .copied()
            .filter(|x| x.is_finite())
            .fold(1e-6, f64::max)
            * 1.1;
        let mut ch = ChartBuilder::on(&root)
            .caption(
                format!(
                    "{}: harmonics of the acceleration, h_k = |H_k|/|H_1|",
                    r.test.name
                ),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(55)
            .build_cartesian_2d(1.5f64..(N_HARM as f64 + 0.5), 0f64..top)?;
        ch.configure_mesh()
            .x_desc("harmonic k")
            .disable_x_mesh()
            .draw()?;
        for k in 2..=N_HARM {
            let x = k as f64;
            let (m, d) = (c.h_measured[k - 2], c.h_model[k - 2]);
            if m.is_finite() {
                ch.draw_series(std::iter::once(Rectangle::new(
                    [(x - 0.35, 0.0), (x - 0.02, m)],
                    MEASURED.filled(),
                )))?;
            }
            if d.is_finite() {
                ch.draw_series(std::iter::once(Rectangle::new(
                    [(x + 0.02, 0.0), (x + 0.35, d)],
                    MODEL.filled(),
                )))?;
            }
        }
        root.present()?;
    }
    Ok(s)
}

/// RMS acceleration residual against amplitude, one line per frequency.
fn amplitude_svg(results: &[ComparedTest]) -> Result<Option<String>, Box<dyn std::error::Error>> {
    let mut pts: Vec<(f64, f64, f64)> = results
        .iter()
        .filter_map(|r| match &r.test.excitation {
            crate::orchestration::runs::spec::ExcitationSpec::Sine { sine, .. } => {
                let g = sine.amp_m * (2.0 * std::f64::consts::PI * sine.freq_hz).powi(2)
                    / crate::kernel::params::G;
                Some((sine.freq_hz, g, r.comparison.rms_residual_accel_ratio))
            }
            _ => None,
        })
        .collect();
    if pts.is_empty() {
        return Ok(None);
    }
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 320)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = range(pts.iter().map(|p| p.1));
        let (_, y1) = range(pts.iter().map(|p| p.2));
        let mut c = ChartBuilder::on(&root)
            .caption(
                "campaign: acceleration residual against amplitude, per frequency",
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d(x0.min(0.0)..x1, 0f64..y1.max(1e-9))?;
        c.configure_mesh()
            .x_desc("amplitude (g)")
            .y_desc("rms residual / rms measured")
            .draw()?;
        let freqs: Vec<f64> = pts.iter().map(|p| p.0).fold(Vec::new(), |mut v, f| {
            if v.last() != Some(&f) {
                v.push(f);
            }
            v
        });
        for (i, f) in freqs.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let line: Vec<(f64, f64)> = pts
                .iter()
                .filter(|p| p.0 == *f)
                .map(|p| (p.1, p.2))
                .collect();
            draw_line(
                &mut c,
                line.iter().copied(),
                color.stroke_width(2),
                Some(&format!("{f} Hz")),
            )?;
            c.draw_series(
                line.into_iter()
                    .filter(|p| p.1.is_finite())
                    .map(|p| Circle::new(p, 4, color.filled())),
            )?;
        }
        legend(&mut c)?;
        root.present()?;
    }
    Ok(Some(s))
}

/// The state map: per regressed residual, its mean in each bin of each scaled state.
fn state_map_svg(map: &StateMap) -> Result<String, Box<dyn std::error::Error>> {
    let shown: Vec<(usize, Residual)> = Residual::ALL
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, r)| statemap::REGRESSED.contains(r) && !map.by_state(*r).is_empty())
        .collect();
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, (760, 260 * shown.len().max(1) as u32))
            .into_drawing_area();
        root.fill(&WHITE)?;
        for ((i, r), area) in shown.iter().zip(root.split_evenly((shown.len().max(1), 1))) {
            let (y0, y1) = range(map.bins.iter().map(|b| b.mean[*i]));
            let mut c = ChartBuilder::on(&area)
                .caption(
                    format!("{}: mean per bin of each state", r.label()),
                    ("sans-serif", 15),
                )
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(-1f64..1f64, y0..y1)?;
            c.configure_mesh()
                .x_desc("state / its scale (spool: / full stroke)")
                .y_desc("/ rms measured")
                .draw()?;
            for (k, st) in State::ALL.iter().enumerate() {
                let color = Palette99::pick(k).to_rgba();
                let pts = map
                    .bins
                    .iter()
                    .filter(|b| b.state == *st)
                    .map(|b| (0.5 * (b.lo + b.hi), b.mean[*i]));
                draw_line(&mut c, pts, color.stroke_width(2), Some(st.label()))?;
            }
            c.configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
        root.present()?;
    }
    Ok(s)
}

/// The report's section on where in state space the residual lies: the sentence, the plot and
/// the per-state regressions.
pub(crate) fn state_map_section(map: &StateMap) -> anyhow::Result<String> {
    let mut h = String::from("<h2>Where in state space</h2>\n");
    match map.sentence() {
        Some(s) => writeln!(h, "<p id=\"state-sentence\">{}</p>", esc(&s))?,
        None => writeln!(
            h,
            "<p id=\"state-sentence\">No state's terms explain the residual (R² < {}).</p>",
            statemap::MIN_R2
        )?,
    }
    let svg = state_map_svg(map).map_err(|e| anyhow::anyhow!("drawing a plot: {e}"))?;
    writeln!(h, "<figure class=\"plot\" id=\"state-map\">{svg}</figure>")?;
    h.push_str("<table id=\"state-terms\"><tr><th>residual</th><th>state</th><th>R²</th><th>terms kept (R² alone)</th></tr>\n");
    for reg in map.per_state.iter().flatten() {
        let terms: Vec<String> = reg
            .terms
            .iter()
            .map(|t| format!("{} ({:.2})", t.formula(), t.alone))
            .collect();
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td style=\"text-align:left\">{}</td></tr>",
            reg.residual.label(),
            reg.state.map_or("all", |s| s.label()),
            reg.r2,
            esc(&terms.join(", "))
        )?;
    }
    for (r, m) in &map.memory {
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td style=\"text-align:left\">{}</td></tr>",
            r.label(),
            m.kind.name(),
            m.r2,
            esc(&crate::orchestration::diagnosis::statemap::memory_text(m))
        )?;
    }
    h.push_str("</table>\n");
    Ok(h)
}

pub(crate) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A number for a table cell ("-" when not finite).
fn num(v: f64, f: impl Fn(f64) -> String) -> String {
    if v.is_finite() {
        f(v)
    } else {
        "-".into()
    }
}

/// The whole report as one self-contained HTML page.
pub fn html(
    title: &str,
    results: &[ComparedTest],
    map: &StateMap,
    extra_warnings: &[String],
) -> anyhow::Result<String> {
    let mut h = String::new();
    page_head(
        &mut h,
        title,
        &[("measured", "#1f77b4"), ("model", "#d62728")],
    )?;
    summary_table(&mut h, results)?;
    warnings_list(&mut h, results, extra_warnings)?;
    files_table(&mut h, results)?;
    if let Some(svg) = amplitude_svg(results).map_err(|e| anyhow::anyhow!("drawing a plot: {e}"))? {
        write!(h, "<h2>Across the campaign</h2>\n<figure class=\"plot\" id=\"amplitude\">{svg}</figure>\n")?;
    }
    h.push_str(&state_map_section(map)?);
    test_sections(&mut h, results)?;
    h.push_str("<p>The numbers behind every plot are in the Parquet tables beside this page (tests, harmonics, bins, cycles, overlay, statemap, stateterms).</p>\n</body></html>\n");
    Ok(h)
}

/// A report page's head (title and the house style), its title and the plots' legend: each entry
/// a label and its CSS colour.
pub(crate) fn page_head(
    h: &mut String,
    title: &str,
    legend: &[(&str, &str)],
) -> anyhow::Result<()> {
    write!(
        h,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
body{{font-family:sans-serif;margin:24px;color:#222}} table{{border-collapse:collapse;font-size:13px}}\
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}} th{{background:#f2f2f2}} td:first-child{{text-align:left}}\
figure{{margin:12px 0}} .legend span{{display:inline-block;width:14px;height:4px;margin:0 4px 2px 12px}}\
</style></head><body>\n<h1>{t}</h1>\n<p class=\"legend\">",
        t = esc(title)
    )?;
    for (label, colour) in legend {
        write!(
            h,
            "{}<span style=\"background:{colour}\"></span> ",
            esc(label)
        )?;
    }
    h.truncate(h.trim_end().len());
    h.push_str("</p>\n");
    Ok(())
}

/// The summary table: a row of headline numbers per test.
fn summary_table(h: &mut String, results: &[ComparedTest]) -> anyhow::Result<()> {
    h.push_str("<h2>Summary</h2>\n<table id=\"summary\"><tr><th>test</th><th>amp. ratio meas.</th><th>model</th><th>phase° meas.</th><th>model</th><th>h3 meas.</th><th>model</th><th>rms resid. a</th><th>x</th><th>F</th><th>drift meas./cycle</th><th>model</th></tr>\n");
    for r in results {
        let c = &r.comparison;
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&r.test.name),
            num(c.amp_ratio_measured, |v| format!("{v:.4}")),
            num(c.amp_ratio_model, |v| format!("{v:.4}")),
            num(c.phase_measured_deg, |v| format!("{v:+.2}")),
            num(c.phase_model_deg, |v| format!("{v:+.2}")),
            num(c.h_measured[1], |v| format!("{v:.4}")),
            num(c.h_model[1], |v| format!("{v:.4}")),
            num(c.rms_residual_accel_ratio, |v| format!("{v:.2e}")),
            num(c.rms_residual_disp_ratio, |v| format!("{v:.2e}")),
            c.rms_residual_force_ratio.map_or("-".into(), |v| num(v, |v| format!("{v:.2e}"))),
            num(c.drift_measured, |v| format!("{v:+.1e}")),
            num(c.drift_model, |v| format!("{v:+.1e}"))
        )?;
    }
    h.push_str("</table>\n");
    Ok(())
}

/// The warnings of every test and the extra ones, where there are any.
fn warnings_list(
    h: &mut String,
    results: &[ComparedTest],
    extra_warnings: &[String],
) -> anyhow::Result<()> {
    let warnings: Vec<&String> = results
        .iter()
        .flat_map(|r| r.test.warnings.iter())
        .chain(extra_warnings)
        .collect();
    if !warnings.is_empty() {
        h.push_str("<h2>Warnings</h2>\n<ul id=\"warnings\" style=\"color:#a00\">\n");
        for w in warnings {
            writeln!(h, "<li>{}</li>", esc(w))?;
        }
        h.push_str("</ul>\n");
    }
    Ok(())
}

/// The data files table: where each test's excitation and window lie in its file.
fn files_table(h: &mut String, results: &[ComparedTest]) -> anyhow::Result<()> {
    h.push_str("<h2>Data files</h2>\n<table id=\"files\"><tr><th>test</th><th>file</th><th>rate</th><th>excitation starts</th><th>ends</th><th>window</th><th>notes</th></tr>\n");
    for r in results {
        let a = &r.test.alignment;
        writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{} Hz</td><td>{:.4} s</td><td>{:.4} s</td><td>{} samples</td><td style=\"text-align:left\">{}</td></tr>",
            esc(&r.test.name),
            esc(&r.test.file.display().to_string()),
            fmt_rate(a.time.rate_hz),
            a.start_s(),
            a.end_s(),
            r.test.samples.len(),
            esc(&r.test.notes.join("; "))
        )?;
    }
    h.push_str("</table>\n");
    Ok(())
}

/// Each test's section: its overlay, and its harmonics where the model has an amplitude ratio.
fn test_sections(h: &mut String, results: &[ComparedTest]) -> anyhow::Result<()> {
    let plot = |r: Result<String, Box<dyn std::error::Error>>| {
        r.map_err(|e| anyhow::anyhow!("drawing a plot: {e}"))
    };
    for r in results {
        writeln!(h, "<h2 id=\"test-{n}\">{n}</h2>", n = esc(&r.test.name))?;
        writeln!(
            h,
            "<figure class=\"plot overlay\">{}</figure>",
            plot(overlay_svg(r))?
        )?;
        if r.comparison.amp_ratio_model.is_finite() {
            writeln!(
                h,
                "<figure class=\"plot harmonics\">{}</figure>",
                plot(harmonics_svg(r))?
            )?;
        }
    }
    Ok(())
}
