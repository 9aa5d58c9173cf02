//! The journal of `study tune` on disk (`DIR/tune.journal`, its format in
//! `orchestration::preparation::tune_journal`): started with its header, a generation appended
//! and flushed as each ends, read back and checked against the inputs by `--resume`, removed
//! once the tuning's files are written.

use crate::orchestration::preparation::tune_journal::{self, Stored};
use crate::shell::BadInput;
use anyhow::Context;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The journal's name in the output folder.
pub const JOURNAL: &str = "tune.journal";

/// An open journal, appended to as generations end.
pub struct JournalFile {
    path: PathBuf,
    file: File,
}

impl JournalFile {
    /// A new journal in `dir` for these inputs (an earlier one is replaced).
    pub fn start(dir: &Path, spec_text: &str, model_text: Option<&str>) -> anyhow::Result<Self> {
        let path = dir.join(JOURNAL);
        let head = tune_journal::header(spec_text, model_text);
        crate::shell::job::outputs::write_whole(&path, head.as_bytes())?;
        Self::open(path)
    }

    /// The journal of an interrupted tuning in `dir`, for these inputs: its complete
    /// generations, and the journal kept open (what a kill cut short is dropped from it).
    pub fn resume(
        dir: &Path,
        spec_text: &str,
        model_text: Option<&str>,
    ) -> anyhow::Result<(Self, Vec<Vec<Stored>>)> {
        let path = dir.join(JOURNAL);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            BadInput(format!(
                "{}: no interrupted tuning to resume ({e})",
                path.display()
            ))
        })?;
        let j =
            tune_journal::read(&text).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
        if j.spec_text != spec_text || j.model_text.as_deref() != model_text {
            let which = if j.spec_text != spec_text {
                "the tuning file"
            } else {
                "the --model file (or its absence)"
            };
            return Err(BadInput(format!(
                "{}: {which} differs from the interrupted tuning's; resume with the same files, or start over with --force",
                path.display()
            ))
            .into());
        }
        let kept = tune_journal::complete(&text);
        crate::shell::job::outputs::write_whole(&path, kept.as_bytes())?;
        Ok((Self::open(path)?, j.generations))
    }

    fn open(path: PathBuf) -> anyhow::Result<Self> {
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        Ok(JournalFile { path, file })
    }

    /// Where the journal is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// One generation's lines, appended and flushed to the disk.
    pub fn append(&mut self, lines: &str) -> anyhow::Result<()> {
        self.file
            .write_all(lines.as_bytes())
            .and_then(|_| self.file.sync_data())
            .with_context(|| format!("writing {}", self.path.display()))
    }

    /// The journal removed (the tuning's files are written).
    pub fn remove(self) -> anyhow::Result<()> {
        drop(self.file);
        std::fs::remove_file(&self.path)
            .with_context(|| format!("removing {}", self.path.display()))
    }
}
