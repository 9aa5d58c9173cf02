//! `study run --resume FILE`: continue a run that was stopped (SIGINT, SIGTERM: the rows are
//! closed in `NAME.partial.parquet`, marked incomplete) or killed (SIGKILL, a crash: the temp
//! file and its checkpoint are turned back into a readable file). The study comes from the file's own metadata (the
//! resolved study, the study file's folder for relative paths, the shard), so the resumed run
//! computes exactly what the first one would have; every sample depends only on (seed, sample
//! id), so the finished file equals an uninterrupted run's row for row, bit for bit.

use crate::orchestration::study::problem::StudySpec;
use crate::shell::formats::measured_files::input_if_user;
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_read;
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Recovered;
use crate::shell::job::outputs::{check_output, OutputLock};
use crate::shell::job::study_job::{plan_for, Job, Kept, Shard};
use crate::shell::BadInput;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The file whose rows a resume of `file` (results table `out`) keeps, and whether it is a
/// recovered one (`FILE.killed`, removed once its rows are safe).
fn source(file: &Path, out: &Path) -> anyhow::Result<(PathBuf, bool)> {
    let partial = parquet_write::partial_path(out);
    let killed = parquet_write::killed_path(&partial);
    let (source, temporary) = match parquet_write::recover_killed(&partial)? {
        Recovered::File(p) => (p, true),
        // A resume of a killed run, itself killed before its first checkpoint: the rows recovered
        // the first time are still in FILE.killed.
        Recovered::NoCheckpoint(_) | Recovered::Nothing if !partial.exists() && killed.exists() => (killed, true),
        Recovered::NoCheckpoint(tmp) if !partial.exists() && !out.exists() => {
            return Err(BadInput(format!(
                "{}: the run was killed before its first checkpoint (no rows were safely written), so there is nothing to resume; start it again",
                tmp.display()
            ))
            .into())
        }
        // A stopped run's rows (beside them, perhaps, the temp file of a resumed run killed
        // before its first checkpoint: the stopped file still holds every row it had).
        _ if partial.exists() => (partial, false),
        // The complete table (or one stopped by an older vshake, under its final name).
        _ => (out.to_path_buf(), false),
    };
    if !source.exists() {
        return Err(BadInput(format!("{}: not found (nothing to resume)", file.display())).into());
    }
    Ok((source, temporary))
}

/// The job that continues `file` (the results table, `NAME.parquet`, or its partial one,
/// `NAME.partial.parquet`), or None when it is already complete (said on stdout).
pub fn job(file: &Path) -> anyhow::Result<Option<Job>> {
    let out = parquet_write::final_path(file);
    check_output(&out)?;
    check_output(&parquet_write::partial_path(&out))?;
    // Before anything is read or moved: another process may be writing these files.
    let lock = OutputLock::acquire(&out)?;
    let (source, temporary) = source(file, &out)?;
    let meta = parquet_read::parquet_metadata(&source).map_err(input_if_user)?;
    let get = |k: Key| meta::get(&meta, k);
    if !meta::is(&meta, Kind::StudyResults) {
        return Err(BadInput(format!("{}: not a results file of `study run` (no vshake.kind = study_results in its metadata)", file.display())).into());
    }
    let rows = parquet_read::parquet_rows(&source).map_err(input_if_user)?;
    if !temporary && meta::incomplete(&meta).is_none() {
        writeln!(
            std::io::stdout(),
            "study run --resume {}: the file is complete ({rows} rows); nothing to do",
            file.display()
        )?;
        return Ok(None);
    }
    // The kept rows are checked against their checksums before one is used.
    crate::shell::formats::integrity::verify_file(&source)?;
    let need = |k: Key| {
        get(k).ok_or_else(|| {
            BadInput(format!(
                "{}: no {k} in its metadata; it cannot be resumed",
                file.display()
            ))
        })
    };
    let what = format!("{} (the study in its metadata)", source.display());
    let spec = StudySpec::from_toml(need(Key::Study)?, &what)?;
    let plan = plan_for(
        &spec,
        Path::new(need(Key::StudyFile)?)
            .parent()
            .unwrap_or(Path::new(".")),
    )?;
    let shard = match (get(Key::ShardIndex), get(Key::ShardCount)) {
        (Some(i), Some(n)) => Some(Shard::parse(&format!("{i}/{n}"), plan.samples())?),
        _ => None,
    };
    let range = shard
        .as_ref()
        .map_or(0..plan.samples(), |s| s.range.clone());
    // A row group may end inside a sample's excitations: only whole samples are kept.
    let samples = (rows / plan.references.len()).min(range.len());
    let meta = meta::carried(meta.iter().map(|(k, v)| (k, v)), &[]);
    let kept = Some(Kept {
        source,
        samples,
        temporary,
    });
    Ok(Some(Job {
        spec,
        plan,
        shard,
        range,
        out,
        meta,
        kept,
        lock: Some(lock),
    }))
}
