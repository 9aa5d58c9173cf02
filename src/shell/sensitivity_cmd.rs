//! `study sensitivity results.parquet`: Sobol' indices (Saltelli designs), SRC and PRCC (any
//! design), per excitation and metric; a Parquet table and a ranked printout. The analysis is
//! `orchestration::sensitivity`; this reads the results table, prints and writes.

use super::cli::SensitivityArgs;
use super::meta::{self, Key, Kind};
use super::tables::{self, input_if_user, Column, NumTable};
use super::BadInput;
use crate::orchestration::sensitivity::{self, Indices, Results, SobolIndex};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A results file as the analysis needs it.
pub(crate) struct Loaded {
    pub(crate) design: String,
    /// The varied parameters' paths and columns, in design order.
    pub(crate) paths: Vec<String>,
    pub(crate) columns: Vec<String>,
    pub(crate) metrics: Vec<String>,
    pub(crate) excitations: Vec<String>,
    pub(crate) table: NumTable,
}

impl Loaded {
    pub(crate) fn saltelli(&self) -> bool {
        self.design == "saltelli"
    }

    pub(crate) fn col(&self, name: &str) -> &[f64] {
        self.table.column(name).expect("column read")
    }

    fn results(&self) -> Results<'_> {
        Results {
            excitation: self.col("excitation_id"),
            saltelli: self
                .saltelli()
                .then(|| (self.col("design_base"), self.col("design_block"))),
            inputs: self.columns.iter().map(|c| self.col(c)).collect(),
        }
    }
}

/// Reads the metadata and the columns the analysis needs; refuses a file that is not a complete
/// results file, unknown `--metrics`, and a design where nothing varies.
pub(crate) fn load(file: &Path, wanted_metrics: Option<&[String]>) -> anyhow::Result<Loaded> {
    let pairs = tables::parquet_metadata(file).map_err(input_if_user)?;
    let get = |k: Key| {
        meta::get(&pairs, k).ok_or_else(|| {
            BadInput(format!(
                "{}: not a vshake results file (no `{k}` in its metadata)",
                file.display()
            ))
        })
    };
    if get(Key::Kind)? != Kind::StudyResults.as_str() {
        return Err(BadInput(format!("{}: not a study results file", file.display())).into());
    }
    if let Some((done, total)) = meta::incomplete(&pairs) {
        let f = file.display();
        return Err(BadInput(format!("{f}: incomplete ({done} of {total} rows; the run was stopped): finish it first with `study run --resume {f}`")).into());
    }
    let design = get(Key::Design)?.to_string();
    let all_paths = meta::items(get(Key::Parameters)?);
    let all_columns = meta::items(get(Key::ParameterColumns)?);
    let all_metrics = meta::items(get(Key::Metrics)?);
    let excitations = meta::items(get(Key::Excitations)?);
    let metrics: Vec<String> = match wanted_metrics {
        Some(list) => {
            if let Some(m) = list.iter().find(|m| !all_metrics.contains(m)) {
                return Err(BadInput(format!(
                    "--metrics: {m:?} is not in {} (it has: {})",
                    file.display(),
                    all_metrics.join(", ")
                ))
                .into());
            }
            list.to_vec()
        }
        None => all_metrics,
    };
    let mut wanted: Vec<&str> = vec!["excitation_id"];
    if design == "saltelli" {
        wanted.extend(["design_base", "design_block"]);
    }
    wanted.extend(all_columns.iter().chain(&metrics).map(String::as_str));
    let table = tables::read_columns_allow_nan(file, &wanted).map_err(input_if_user)?;
    // The design's parameters, in design order (recorded by `study run`); older files: the
    // parameter columns that vary.
    let varied: Vec<usize> = match meta::get(&pairs, Key::DesignParameters) {
        Some(list) => meta::items(list)
            .iter()
            .filter_map(|p| all_paths.iter().position(|x| x == p))
            .collect(),
        None => (0..all_columns.len())
            .filter(|&i| {
                let c = table.column(&all_columns[i]).expect("column read");
                c.iter().any(|v| *v != c[0])
            })
            .collect(),
    };
    if varied.is_empty() {
        return Err(BadInput(format!(
            "{}: no parameter varies; nothing to analyse",
            file.display()
        ))
        .into());
    }
    let paths = varied.iter().map(|&i| all_paths[i].clone()).collect();
    let columns = varied.iter().map(|&i| all_columns[i].clone()).collect();
    Ok(Loaded {
        design,
        paths,
        columns,
        metrics,
        excitations,
        table,
    })
}

/// The indices of every (excitation, metric), in parallel on `threads` workers.
pub(crate) fn analyse(
    l: &Loaded,
    bootstrap: usize,
    threads: usize,
) -> anyhow::Result<Vec<(usize, &String, Indices)>> {
    let results = l.results();
    let jobs: Vec<(usize, &String)> = (0..l.excitations.len())
        .flat_map(|e| l.metrics.iter().map(move |m| (e, m)))
        .collect();
    let pool = super::run_cmd::pool(threads)?;
    Ok(pool.install(|| {
        jobs.par_iter()
            .map(|&(e, m)| (e, m, sensitivity::analyse(&results, e, l.col(m), bootstrap)))
            .collect()
    }))
}

pub fn run(args: &SensitivityArgs) -> anyhow::Result<()> {
    super::outputs::check_parquet_outputs([args.out.as_ref()])?;
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
        meta::pair(Key::SchemaVersion, super::run_cmd::SCHEMA_VERSION),
    ]);
    tables::write_table(path, cols, &m)
}
