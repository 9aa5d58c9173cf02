//! A results table read for analysis (`study sensitivity`, `study plot`): its design, the
//! varied parameters, the excitations and metrics, and the indices of every (excitation, metric)
//! computed on a pool.

use crate::orchestration::study::sensitivity::{self, Indices, Results};
use crate::shell::formats::measured_files;
use crate::shell::formats::measured_files::{input_if_user, NumTable};
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_read;
use crate::shell::BadInput;
use rayon::prelude::*;
use std::path::Path;

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
    let pairs = parquet_read::parquet_metadata(file).map_err(input_if_user)?;
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
    let table = measured_files::read_columns_allow_nan(file, &wanted).map_err(input_if_user)?;
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
    let pool = crate::shell::job::study_job::pool(threads)?;
    Ok(pool.install(|| {
        jobs.par_iter()
            .map(|&(e, m)| (e, m, sensitivity::analyse(&results, e, l.col(m), bootstrap)))
            .collect()
    }))
}
