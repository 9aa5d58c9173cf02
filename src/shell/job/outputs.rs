//! Output files: only regular files (or a path that does not exist yet) are written, and a
//! results table has one writer at a time.

use crate::shell::formats::input::regular_output;
use crate::shell::BadInput;
use anyhow::Context;
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// [`regular_output`] for a command's output, before any work: bad input (exit 2).
pub(crate) fn check_output(path: &Path) -> anyhow::Result<()> {
    regular_output(path).map_err(|e| BadInput(format!("{e}; choose another output")).into())
}

/// [`check_output`] for an optional output.
pub(crate) fn check_outputs<'a>(
    paths: impl IntoIterator<Item = Option<&'a PathBuf>>,
) -> anyhow::Result<()> {
    paths
        .into_iter()
        .flatten()
        .try_for_each(|p| check_output(p))
}

/// A Parquet output may replace a file vshake wrote (its metadata has `vshake.kind`: an earlier
/// run's table, history, spectrum or analysis), never another file of the same name, nor a link
/// (vshake does not write through one): exit 2, nothing replaced.
pub(crate) fn check_replaceable(out: &Path) -> anyhow::Result<()> {
    let Ok(md) = std::fs::symlink_metadata(out) else {
        return Ok(());
    };
    if md.file_type().is_symlink() {
        return Err(BadInput(format!(
            "{}: is a symbolic link, and vshake does not write through links; nothing was replaced: give the file it points to, or another path",
            out.display()
        ))
        .into());
    }
    let ours = md.is_file()
        && crate::shell::formats::parquet_read::parquet_metadata(out).is_ok_and(|m| {
            crate::shell::formats::meta::get(&m, crate::shell::formats::meta::Key::Kind).is_some()
        });
    if !ours {
        return Err(BadInput(format!(
            "{}: exists and is not a file vshake wrote (no vshake.kind in its Parquet metadata); nothing was replaced: choose another output, or remove it",
            out.display()
        ))
        .into());
    }
    Ok(())
}

/// [`check_output`] and [`check_replaceable`] for optional Parquet outputs.
pub(crate) fn check_parquet_outputs<'a>(
    paths: impl IntoIterator<Item = Option<&'a PathBuf>>,
) -> anyhow::Result<()> {
    paths.into_iter().flatten().try_for_each(|p| {
        check_output(p)?;
        check_replaceable(p)
    })
}

/// The lock file of a results table: `NAME.parquet.lock` beside it.
pub(crate) fn lock_path(out: &Path) -> PathBuf {
    let mut p = out.as_os_str().to_owned();
    p.push(".lock");
    PathBuf::from(p)
}

/// An exclusive lock on a results table, its partial file, temp file and checkpoint: an advisory
/// `flock` on `NAME.parquet.lock`, which holds the writer's process id. The kernel drops the lock
/// when its process ends, however it ends, so the lock of a dead process is taken over; the file
/// is removed when the lock is released.
#[derive(Debug)]
pub struct OutputLock {
    file: File,
    path: PathBuf,
}

impl OutputLock {
    /// Takes the lock of `out` (the results table), or refuses at once (exit 2) naming the process
    /// that holds it.
    pub(crate) fn acquire(out: &Path) -> anyhow::Result<OutputLock> {
        let path = lock_path(out);
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| BadInput(format!("{}: cannot create: {e}", dir.display())))?;
        }
        check_output(&path)?;
        loop {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| {
                    BadInput(format!(
                        "{}: cannot create the lock file: {e}",
                        path.display()
                    ))
                })?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => return Err(held(out, &path, file)),
                // A file system without locks: the run goes on unlocked.
                Err(std::fs::TryLockError::Error(_)) => return Ok(OutputLock { file, path }),
            }
            // The holder before may have removed the file between our open and our lock: then
            // the lock is on a file no other process can find, and it is taken again.
            if !same_file(&file, &path) {
                continue;
            }
            let mut lock = OutputLock { file, path };
            lock.write_pid()
                .map_err(|e| BadInput(format!("{}: cannot write: {e}", lock.path.display())))?;
            return Ok(lock);
        }
    }

    fn write_pid(&mut self) -> std::io::Result<()> {
        self.file.set_len(0)?;
        (&self.file).write_all(format!("{}\n", std::process::id()).as_bytes())?;
        self.file.flush()
    }
}

/// Whether `path` still names the open file `file`.
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// The refusal of a second writer: the holder's process id, from the lock file.
fn held(out: &Path, lock: &Path, mut file: File) -> anyhow::Error {
    let mut text = String::new();
    let _ = file.read_to_string(&mut text);
    let holder = match text.trim().parse::<u32>() {
        Ok(pid) => format!("process {pid}"),
        Err(_) => "another process".to_string(),
    };
    BadInput(format!(
        "{}: {holder} is writing this table (it holds the lock {}); nothing was done: wait for it to end, or give another --out",
        out.display(),
        lock.display()
    ))
    .into()
}

impl Drop for OutputLock {
    /// Removes the lock file, still locked (a process that opened it just before locks a file no
    /// other can find, sees that, and takes the lock again).
    fn drop(&mut self) {
        if same_file(&self.file, &self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// The files `names` in the folder `dir`: refused before any work where `dir` is not a folder,
/// or one of them exists and `force` is not given.
pub(crate) fn output_paths(
    dir: &Path,
    names: &[&str],
    force: bool,
) -> anyhow::Result<Vec<PathBuf>> {
    if dir.exists() && !dir.is_dir() {
        return Err(BadInput(format!("{}: exists and is not a folder", dir.display())).into());
    }
    let paths: Vec<PathBuf> = names.iter().map(|f| dir.join(f)).collect();
    if let Some(p) = paths.iter().find(|p| p.exists()) {
        if !force {
            return Err(
                BadInput(format!("{}: exists (--force overwrites it)", p.display())).into(),
            );
        }
    }
    Ok(paths)
}

/// `bytes` written to `path.tmp`, then renamed into place (removed if the write fails).
pub(crate) fn write_whole(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let file = crate::shell::formats::parquet_write::AtomicFile::new(path);
    std::fs::write(&file.tmp, bytes)
        .and_then(|_| file.commit())
        .with_context(|| format!("writing {}", path.display()))
}
