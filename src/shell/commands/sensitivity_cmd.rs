//! `study sensitivity results.parquet`: Sobol' indices (Saltelli designs), SRC and PRCC (any
//! design), per excitation and metric; a Parquet table and a ranked printout. The analysis is
//! `orchestration::study::sensitivity`; this reads the results table, prints and writes.

use crate::orchestration::study::sensitivity::{self, Indices, SobolIndex};
use crate::shell::cli::SensitivityArgs;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use crate::shell::formats::results_reader::{analyse, load, Loaded};
use std::io::Write;
use std::path::{Path, PathBuf};

pub fn run(args: &SensitivityArgs) -> anyhow::Result<()> {
    crate::shell::job::outputs::check_parquet_outputs([args.out.as_ref()])?;
    let file = &args.file;
    let loaded = load(file, args.metrics.as_deref())?;
    let lines = analyse(&loaded, args.bootstrap, args.threads)?;
    let mut out = std::io::stdout().lock();
    print(&mut out, &loaded, file, &lines)?;
    let out_path: PathBuf = args.out.clone().unwrap_or_else(|| {
        let stem = file
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        file.with_file_name(format!("{stem}_sensitivity.parquet"))
    });
    write(&out_path, &loaded, file, &lines, args.bootstrap)?;
    writeln!(out, "\nwrote {}", out_path.display())?;
    Ok(())
}

/// Per output, the parameters ranked (by total Sobol' index for a Saltelli design, else by |SRC|).
fn print(
    out: &mut dyn Write,
    l: &Loaded,
    file: &Path,
    lines: &[(usize, &String, Indices)],
) -> std::io::Result<()> {
    writeln!(
        out,
        "study sensitivity {} ({} design, {} varied parameters)",
        file.display(),
        l.design,
        l.paths.len()
    )?;
    for (e, metric, ix) in lines {
        let total = |k: usize| ix.sobol.as_ref().map_or(f64::NAN, |s| s[k].total.value);
        let mut ranked: Vec<usize> = (0..l.paths.len()).collect();
        if l.saltelli() {
            ranked.sort_by(|&a, &b| total(b).total_cmp(&total(a)));
        } else {
            ranked.sort_by(|&a, &b| ix.src[b].abs().total_cmp(&ix.src[a].abs()));
        }
        writeln!(out)?;
        let dropped = if ix.dropped > 0 {
            format!(", {} dropped (failed runs)", ix.dropped)
        } else {
            String::new()
        };
        writeln!(
            out,
            "{metric} @ {}  (n = {}{dropped}; R² of the linear fit {:.3})",
            l.excitations[*e], ix.n, ix.r2
        )?;
        if l.saltelli() {
            writeln!(
                out,
                "  {:<4} {:<26} {:>24} {:>24} {:>8} {:>8}",
                "rank", "parameter", "S1 [95% CI]", "ST [95% CI]", "SRC", "PRCC"
            )?;
        } else {
            writeln!(
                out,
                "  {:<4} {:<26} {:>8} {:>8}",
                "rank", "parameter", "SRC", "PRCC"
            )?;
        }
        for (rank, &k) in ranked.iter().enumerate() {
            let p = &l.paths[k];
            match &ix.sobol {
                Some(s) => {
                    let fmt = |e: sensitivity::Estimate| {
                        format!("{:.3} [{:.3}, {:.3}]", e.value, e.ci_low, e.ci_high)
                    };
                    writeln!(
                        out,
                        "  {:<4} {:<26} {:>24} {:>24} {:>+8.3} {:>+8.3}",
                        rank + 1,
                        p,
                        fmt(s[k].first),
                        fmt(s[k].total),
                        ix.src[k],
                        ix.prcc[k]
                    )?;
                }
                None => writeln!(
                    out,
                    "  {:<4} {:<26} {:>+8.3} {:>+8.3}",
                    rank + 1,
                    p,
                    ix.src[k],
                    ix.prcc[k]
                )?,
            }
        }
    }
    Ok(())
}

/// The table: one row per (excitation, metric, parameter).
fn write(
    path: &Path,
    l: &Loaded,
    file: &Path,
    lines: &[(usize, &String, Indices)],
    bootstrap: usize,
) -> anyhow::Result<()> {
    let rows: Vec<(&(usize, &String, Indices), usize)> = lines
        .iter()
        .flat_map(|x| (0..l.paths.len()).map(move |k| (x, k)))
        .collect();
    let s = |f: &dyn Fn(&SobolIndex) -> f64| {
        Column::F64(
            rows.iter()
                .map(|((_, _, ix), k)| ix.sobol.as_ref().map_or(f64::NAN, |s| f(&s[*k])))
                .collect(),
        )
    };
    let x = |f: &dyn Fn(&Indices, usize) -> f64| {
        Column::F64(rows.iter().map(|((_, _, ix), k)| f(ix, *k)).collect())
    };
    let cols = vec![
        (
            "excitation".to_string(),
            Column::Str(
                rows.iter()
                    .map(|((e, _, _), _)| l.excitations[*e].clone())
                    .collect(),
            ),
        ),
        (
            "metric".to_string(),
            Column::Str(rows.iter().map(|((_, m, _), _)| m.to_string()).collect()),
        ),
        (
            "parameter".to_string(),
            Column::Str(rows.iter().map(|(_, k)| l.paths[*k].clone()).collect()),
        ),
        ("s1".to_string(), s(&|x| x.first.value)),
        ("s1_ci_low".to_string(), s(&|x| x.first.ci_low)),
        ("s1_ci_high".to_string(), s(&|x| x.first.ci_high)),
        ("st".to_string(), s(&|x| x.total.value)),
        ("st_ci_low".to_string(), s(&|x| x.total.ci_low)),
        ("st_ci_high".to_string(), s(&|x| x.total.ci_high)),
        ("src".to_string(), x(&|ix, k| ix.src[k])),
        ("prcc".to_string(), x(&|ix, k| ix.prcc[k])),
        ("r2_linear".to_string(), x(&|ix, _| ix.r2)),
        (
            "n".to_string(),
            Column::U64(rows.iter().map(|((_, _, ix), _)| ix.n as u64).collect()),
        ),
        (
            "dropped".to_string(),
            Column::U64(
                rows.iter()
                    .map(|((_, _, ix), _)| ix.dropped as u64)
                    .collect(),
            ),
        ),
    ];
    let mut m = meta::header(Kind::Sensitivity);
    m.extend([
        meta::pair(Key::Source, file.display()),
        meta::pair(Key::Bootstrap, bootstrap),
        meta::pair(
            Key::SchemaVersion,
            crate::shell::job::study_job::SCHEMA_VERSION,
        ),
    ]);
    parquet_write::write_table(path, cols, &m)
}
