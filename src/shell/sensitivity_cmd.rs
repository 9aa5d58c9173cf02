//! `study sensitivity results.parquet`: Sobol' indices (Saltelli designs), SRC and PRCC (any
//! design), per excitation and metric; a Parquet table and a ranked printout.

use super::cli::SensitivityArgs;
use super::sim_cmd::input_if_user;
use super::tables::{self, Column};
use super::BadInput;
use crate::orchestration::sensitivity::{self, SobolIndex};
use rayon::prelude::*;
use std::io::Write;
use std::path::PathBuf;

/// Indices of one (excitation, metric, parameter).
struct Line {
    excitation: String,
    metric: String,
    parameter: String,
    sobol: Option<SobolIndex>,
    src: f64,
    prcc: f64,
    r2: f64,
    n: usize,
    dropped: usize,
}

pub fn run(args: &SensitivityArgs) -> anyhow::Result<()> {
    let file = &args.file;
    let meta: std::collections::HashMap<String, String> = tables::parquet_metadata(file).map_err(input_if_user)?.into_iter().collect();
    let get = |k: &str| meta.get(k).cloned().ok_or_else(|| BadInput(format!("{}: not a vshake results file (no `{k}` in its metadata)", file.display())));
    if get("vshake.kind")? != "study_results" {
        return Err(BadInput(format!("{}: not a study results file", file.display())).into());
    }
    let pairs: Vec<(String, String)> = meta.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    if let Some((done, total)) = super::run_cmd::incomplete(&pairs) {
        return Err(BadInput(format!(
            "{}: incomplete ({done} of {total} rows; the run was stopped): finish it first with `study run --resume {}`",
            file.display(),
            file.display()
        ))
        .into());
    }
    let design = get("vshake.design")?;
    let paths: Vec<String> = get("vshake.parameters")?.split(',').filter(|s| !s.is_empty()).map(str::to_string).collect();
    let pcols: Vec<String> = get("vshake.parameter_columns")?.split(',').filter(|s| !s.is_empty()).map(str::to_string).collect();
    let all_metrics: Vec<String> = get("vshake.metrics")?.split(',').map(str::to_string).collect();
    let exc_names: Vec<String> = get("vshake.excitations")?.split(',').map(str::to_string).collect();
    let metrics: Vec<String> = match &args.metrics {
        Some(list) => {
            for m in list {
                if !all_metrics.contains(m) {
                    return Err(BadInput(format!("--metrics: {m:?} is not in {} (it has: {})", file.display(), all_metrics.join(", "))).into());
                }
            }
            list.clone()
        }
        None => all_metrics.clone(),
    };
    let saltelli = design == "saltelli";
    let mut wanted: Vec<&str> = vec!["excitation_id"];
    if saltelli {
        wanted.extend(["design_base", "design_block"]);
    }
    wanted.extend(pcols.iter().map(String::as_str));
    wanted.extend(metrics.iter().map(String::as_str));
    let t = tables::read_columns_allow_nan(file, &wanted).map_err(input_if_user)?;
    let col = |n: &str| t.column(n).expect("column read");
    // The design's parameters, in design order (recorded by `study run`); older files: the
    // parameter columns that vary.
    let varied: Vec<usize> = match meta.get("vshake.design_parameters") {
        Some(list) => list.split(',').filter(|s| !s.is_empty()).filter_map(|p| paths.iter().position(|x| x == p)).collect(),
        None => (0..pcols.len())
            .filter(|&i| {
                let c = col(&pcols[i]);
                c.iter().any(|v| *v != c[0])
            })
            .collect(),
    };
    if varied.is_empty() {
        return Err(BadInput(format!("{}: no parameter varies; nothing to analyse", file.display())).into());
    }
    let d = varied.len();
    let exc = col("excitation_id");
    let jobs: Vec<(usize, &String)> = (0..exc_names.len()).flat_map(|e| metrics.iter().map(move |m| (e, m))).collect();
    let bootstrap = args.bootstrap;
    let lines: Vec<Vec<Line>> = jobs
        .par_iter()
        .map(|&(e, m)| {
            let y = col(m);
            let rows: Vec<usize> = (0..t.rows()).filter(|&r| exc[r] as usize == e).collect();
            let mut sobol_idx: Option<Vec<SobolIndex>> = None;
            let dropped;
            let regression_rows: Vec<usize>;
            if saltelli {
                let (base, block) = (col("design_base"), col("design_block"));
                let n_base = rows.iter().map(|&r| base[r] as usize + 1).max().unwrap_or(0);
                let mut table = vec![vec![f64::NAN; d + 2]; n_base];
                for &r in &rows {
                    let (b, k) = (base[r] as usize, block[r] as usize);
                    if k < d + 2 {
                        table[b][k] = y[r];
                    }
                }
                let complete: Vec<&Vec<f64>> = table.iter().filter(|v| v.iter().all(|x| x.is_finite())).collect();
                dropped = n_base - complete.len();
                if complete.len() >= 2 {
                    let fa: Vec<f64> = complete.iter().map(|v| v[0]).collect();
                    let fb: Vec<f64> = complete.iter().map(|v| v[1]).collect();
                    let fab: Vec<Vec<f64>> = (0..d).map(|i| complete.iter().map(|v| v[2 + i]).collect()).collect();
                    sobol_idx = Some(sensitivity::sobol(&fa, &fb, &fab, bootstrap, 0x5eed ^ (e as u64) << 8));
                }
                regression_rows = rows.iter().copied().filter(|&r| block[r] < 2.0 && y[r].is_finite()).collect();
            } else {
                regression_rows = rows.iter().copied().filter(|&r| y[r].is_finite()).collect();
                dropped = rows.len() - regression_rows.len();
            }
            let n = regression_rows.len();
            let (src, r2, prcc) = if n > d + 2 && regression_rows.iter().any(|&r| y[r] != y[regression_rows[0]]) {
                let x: Vec<Vec<f64>> = varied
                    .iter()
                    .map(|&i| {
                        let c = col(&pcols[i]);
                        regression_rows.iter().map(|&r| c[r]).collect()
                    })
                    .collect();
                let yy: Vec<f64> = regression_rows.iter().map(|&r| y[r]).collect();
                let (src, r2) = sensitivity::src(&x, &yy);
                (src, r2, sensitivity::prcc(&x, &yy))
            } else {
                (vec![f64::NAN; d], f64::NAN, vec![f64::NAN; d])
            };
            varied
                .iter()
                .enumerate()
                .map(|(k, &i)| Line {
                    excitation: exc_names[e].clone(),
                    metric: m.clone(),
                    parameter: paths[i].clone(),
                    sobol: sobol_idx.as_ref().map(|s| s[k]),
                    src: src[k],
                    prcc: prcc[k],
                    r2,
                    n,
                    dropped,
                })
                .collect()
        })
        .collect();

    let mut out = std::io::stdout().lock();
    writeln!(out, "study sensitivity {} ({} design, {} varied parameters)", file.display(), design, d)?;
    for group in &lines {
        let Some(first) = group.first() else { continue };
        let mut ranked: Vec<&Line> = group.iter().collect();
        if saltelli {
            ranked.sort_by(|a, b| b.sobol.map_or(f64::NAN, |s| s.total.value).total_cmp(&a.sobol.map_or(f64::NAN, |s| s.total.value)));
        } else {
            ranked.sort_by(|a, b| b.src.abs().total_cmp(&a.src.abs()));
        }
        writeln!(out)?;
        let dropped = if first.dropped > 0 { format!(", {} dropped (failed runs)", first.dropped) } else { String::new() };
        writeln!(out, "{} @ {}  (n = {}{dropped}; R² of the linear fit {:.3})", first.metric, first.excitation, first.n, first.r2)?;
        if saltelli {
            writeln!(out, "  {:<4} {:<26} {:>24} {:>24} {:>8} {:>8}", "rank", "parameter", "S1 [95% CI]", "ST [95% CI]", "SRC", "PRCC")?;
        } else {
            writeln!(out, "  {:<4} {:<26} {:>8} {:>8}", "rank", "parameter", "SRC", "PRCC")?;
        }
        for (k, l) in ranked.iter().enumerate() {
            if let Some(s) = l.sobol {
                let fmt = |e: sensitivity::Estimate| format!("{:.3} [{:.3}, {:.3}]", e.value, e.ci_low, e.ci_high);
                writeln!(out, "  {:<4} {:<26} {:>24} {:>24} {:>+8.3} {:>+8.3}", k + 1, l.parameter, fmt(s.first), fmt(s.total), l.src, l.prcc)?;
            } else {
                writeln!(out, "  {:<4} {:<26} {:>+8.3} {:>+8.3}", k + 1, l.parameter, l.src, l.prcc)?;
            }
        }
    }
    let out_path: PathBuf = args.out.clone().unwrap_or_else(|| {
        let stem = file.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        file.with_file_name(format!("{stem}_sensitivity.parquet"))
    });
    let all: Vec<&Line> = lines.iter().flatten().collect();
    let s = |f: &dyn Fn(&SobolIndex) -> f64| Column::F64(all.iter().map(|l| l.sobol.as_ref().map_or(f64::NAN, f)).collect());
    let cols = vec![
        ("excitation".to_string(), Column::Str(all.iter().map(|l| l.excitation.clone()).collect())),
        ("metric".to_string(), Column::Str(all.iter().map(|l| l.metric.clone()).collect())),
        ("parameter".to_string(), Column::Str(all.iter().map(|l| l.parameter.clone()).collect())),
        ("s1".to_string(), s(&|x| x.first.value)),
        ("s1_ci_low".to_string(), s(&|x| x.first.ci_low)),
        ("s1_ci_high".to_string(), s(&|x| x.first.ci_high)),
        ("st".to_string(), s(&|x| x.total.value)),
        ("st_ci_low".to_string(), s(&|x| x.total.ci_low)),
        ("st_ci_high".to_string(), s(&|x| x.total.ci_high)),
        ("src".to_string(), Column::F64(all.iter().map(|l| l.src).collect())),
        ("prcc".to_string(), Column::F64(all.iter().map(|l| l.prcc).collect())),
        ("r2_linear".to_string(), Column::F64(all.iter().map(|l| l.r2).collect())),
        ("n".to_string(), Column::U64(all.iter().map(|l| l.n as u64).collect())),
        ("dropped".to_string(), Column::U64(all.iter().map(|l| l.dropped as u64).collect())),
    ];
    let meta = vec![
        ("vshake.kind".to_string(), "sensitivity".to_string()),
        ("vshake.source".to_string(), file.display().to_string()),
        ("vshake.bootstrap".to_string(), bootstrap.to_string()),
        ("vshake.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
        ("vshake.schema_version".to_string(), super::run_cmd::SCHEMA_VERSION.to_string()),
    ];
    tables::write_table(&out_path, cols, &meta)?;
    writeln!(out, "\nwrote {}", out_path.display())?;
    Ok(())
}
