//! The journal of `study iterate` on disk (`DIR/iterate.journal`, its format in
//! `orchestration::preparation::iterate_journal`): started with its header, each run appended
//! and flushed as it ends, read back and checked against the inputs by `--resume` (its runs
//! replayed, not made again), removed once the iteration's files are written. It is the
//! iteration's [`RunLog`]: a signal stops the iteration before its next run.

use crate::orchestration::preparation::drive_iteration::RunLog;
use crate::orchestration::preparation::iterate_journal::{self, drive_hash, StoredRun};
use crate::shell::job::interrupt;
use crate::shell::BadInput;
use anyhow::Context;
use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The journal's name in the output folder.
pub const JOURNAL: &str = "iterate.journal";

/// What the journal is checked against on `--resume`: the run file's text, the --model file's,
/// and the settings as a line.
pub struct Inputs<'a> {
    pub spec_text: &'a str,
    pub model_text: Option<&'a str>,
    pub settings: &'a str,
}

/// An open journal: the runs left to replay, and new runs appended as they end.
pub struct IterateLog {
    path: PathBuf,
    file: File,
    to_replay: VecDeque<StoredRun>,
    /// Runs in the journal so far (replayed and new).
    runs: usize,
    /// Runs replayed from the journal.
    pub replayed: usize,
    /// What went wrong with the journal (a write, a replayed run of another drive): the
    /// iteration stops before its next run.
    pub fault: Option<String>,
}

impl IterateLog {
    /// A new journal in `dir` for these inputs (an earlier one is replaced).
    pub fn start(dir: &Path, inputs: &Inputs) -> anyhow::Result<Self> {
        let path = dir.join(JOURNAL);
        let head = iterate_journal::header(inputs.spec_text, inputs.model_text, inputs.settings);
        crate::shell::job::outputs::write_whole(&path, head.as_bytes())?;
        Self::open(path, VecDeque::new())
    }

    /// The journal of an interrupted iteration in `dir`, for these inputs: its runs to replay,
    /// and the journal kept open (what a kill cut short is dropped from it).
    pub fn resume(dir: &Path, inputs: &Inputs) -> anyhow::Result<Self> {
        let path = dir.join(JOURNAL);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            BadInput(format!(
                "{}: no interrupted iteration to resume ({e})",
                path.display()
            ))
        })?;
        let j = iterate_journal::read(&text)
            .map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
        let differs = if j.spec_text != inputs.spec_text {
            Some("the run file differs".to_string())
        } else if j.model_text.as_deref() != inputs.model_text {
            Some("the --model file (or its absence) differs".to_string())
        } else if j.settings != inputs.settings {
            Some(format!(
                "the settings differ ({} here, {} there)",
                inputs.settings, j.settings
            ))
        } else {
            None
        };
        if let Some(which) = differs {
            return Err(BadInput(format!(
                "{}: {which} from the interrupted iteration's; resume with the same files and flags, or start over with --force",
                path.display()
            ))
            .into());
        }
        let kept = iterate_journal::complete(&text);
        crate::shell::job::outputs::write_whole(&path, kept.as_bytes())?;
        Self::open(path, j.runs.into())
    }

    fn open(path: PathBuf, to_replay: VecDeque<StoredRun>) -> anyhow::Result<Self> {
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        Ok(IterateLog {
            path,
            file,
            to_replay,
            runs: 0,
            replayed: 0,
            fault: None,
        })
    }

    /// Where the journal is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// How many runs the journal holds.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// How many runs a resumed iteration will replay (before it starts) or has replayed.
    pub fn replayed_runs(&self) -> usize {
        self.replayed + self.to_replay.len()
    }

    /// The journal removed (the iteration's files are written).
    pub fn remove(self) -> anyhow::Result<()> {
        drop(self.file);
        std::fs::remove_file(&self.path)
            .with_context(|| format!("removing {}", self.path.display()))
    }
}

impl RunLog for IterateLog {
    fn replay(&mut self, drive: &[f64]) -> Option<Result<Vec<f64>, String>> {
        let next = self.to_replay.pop_front()?;
        if next.drive_hash != drive_hash(drive) {
            self.fault = Some(format!(
                "{}: run {} was made with another drive than this iteration's; start over with --force",
                self.path.display(),
                self.runs + 1
            ));
            self.to_replay.clear();
            return None;
        }
        self.runs += 1;
        self.replayed += 1;
        Some(next.response)
    }

    fn keep(&mut self, drive: &[f64], result: &Result<Vec<f64>, String>) {
        self.runs += 1;
        let run = StoredRun {
            drive_hash: drive_hash(drive),
            response: result.clone(),
        };
        let line = iterate_journal::run_line(self.runs, &run);
        let written = self
            .file
            .write_all(line.as_bytes())
            .and_then(|_| self.file.sync_data());
        if let Err(e) = written {
            self.fault = Some(format!("writing {}: {e}", self.path.display()));
        }
    }

    fn stop(&self) -> bool {
        self.fault.is_some() || interrupt::requested().is_some()
    }
}
