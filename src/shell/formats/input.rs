//! Inputs as files: a data file's problems ([`TableError`]: each names the file, the column and
//! the row), paths that are not regular files (a folder, a FIFO, a device) refused before they are
//! opened or replaced, and reads guarded against a reader's panic.

use std::fs::File;
use std::path::{Path, PathBuf};

/// A problem with a data file.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("{file}: {}", io_message(err))]
    Io { file: PathBuf, err: std::io::Error },
    #[error("{file}: not a readable {kind} file: {message}")]
    Format {
        file: PathBuf,
        kind: &'static str,
        message: String,
    },
    #[error("{file}: required column `{column}` is missing{hint}")]
    MissingColumn {
        file: PathBuf,
        column: String,
        hint: String,
    },
    #[error("{file}: column `{column}`, row {row}{line}: {message}")]
    BadCell {
        file: PathBuf,
        column: String,
        row: usize,
        line: String,
        message: String,
    },
    #[error("{file}: {message}")]
    Column { file: PathBuf, message: String },
    #[error("{file}: the file has a header but no data rows")]
    Empty { file: PathBuf },
    #[error("{file}: the file is empty (no header, no rows)")]
    EmptyFile { file: PathBuf },
    /// Several problems of one file, each on its own line.
    #[error("{}", .0.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n"))]
    Many(Vec<TableError>),
}

impl TableError {
    /// One problem as itself, several as [`TableError::Many`].
    pub(crate) fn all(mut v: Vec<TableError>) -> TableError {
        if v.len() == 1 {
            v.remove(0)
        } else {
            TableError::Many(v)
        }
    }
    /// The single problems (a [`TableError::Many`] unpacked).
    pub fn each(&self) -> Vec<String> {
        match self {
            TableError::Many(v) => v.iter().map(|e| e.to_string()).collect(),
            e => vec![e.to_string()],
        }
    }
}

/// The first bad cell of each column, and how many more there are.
#[derive(Default)]
pub(crate) struct BadCells {
    first: Vec<(usize, TableError)>,
    more: Vec<usize>,
}

impl BadCells {
    pub(crate) fn push(&mut self, col: usize, e: impl FnOnce() -> TableError) {
        if self.more.len() <= col {
            self.more.resize(col + 1, 0);
        }
        match self.first.iter().position(|(c, _)| *c == col) {
            Some(_) => self.more[col] += 1,
            None => self.first.push((col, e())),
        }
    }
    pub(crate) fn errors(self) -> Vec<TableError> {
        let more = self.more;
        self.first
            .into_iter()
            .map(|(c, e)| match (e, more.get(c).copied().unwrap_or(0)) {
                (
                    TableError::BadCell {
                        file,
                        column,
                        row,
                        line,
                        message,
                    },
                    m,
                ) if m > 0 => TableError::BadCell {
                    file,
                    column,
                    row,
                    line,
                    message: format!("{message} (and {m} more bad cell(s) in this column)"),
                },
                (e, _) => e,
            })
            .collect()
    }
    pub(crate) fn finish(self) -> Result<(), TableError> {
        let errors = self.errors();
        if errors.is_empty() {
            Ok(())
        } else {
            Err(TableError::all(errors))
        }
    }
}

pub(crate) fn io_message(e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::NotFound => "not found".into(),
        std::io::ErrorKind::PermissionDenied => "cannot read: permission denied".into(),
        // Made by `regular_input`: what the path is, in words.
        std::io::ErrorKind::InvalidInput => e.to_string(),
        _ => format!("cannot read: {e}"),
    }
}

/// What a path that exists but is not a regular file is (a folder, a FIFO, a device, a socket),
/// for messages; None for a regular file, or a path whose reader will say why it cannot be read.
pub(crate) fn not_regular(path: &Path) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    let t = std::fs::metadata(path).ok()?.file_type();
    Some(if t.is_file() {
        return None;
    } else if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    })
}

/// Refuses, before opening it, an input that is not a regular file: a FIFO would block the read
/// and a device never end it. The error's kind is `InvalidInput`, its text what the path is.
pub(crate) fn regular_input(path: &Path) -> std::io::Result<()> {
    match not_regular(path) {
        // A link that cannot be followed (a loop: ELOOP, whose kind is not stable) is the
        // user's to mend, as a missing file is.
        None if is_loop(path) => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "is a symbolic link that cannot be followed (a loop of links)",
        )),
        None => Ok(()),
        Some(what) => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("is {what}, not a regular file: vshake reads files"),
        )),
    }
}

/// Whether `path` is a symbolic link whose chain of links loops.
fn is_loop(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
        && std::fs::metadata(path).is_err_and(|e| {
            e.kind() != std::io::ErrorKind::NotFound && e.raw_os_error() == Some(ELOOP)
        })
}

/// ELOOP, "too many levels of symbolic links" (Linux; the BSDs and macOS: 62).
#[cfg(target_os = "linux")]
const ELOOP: i32 = 40;
#[cfg(not(target_os = "linux"))]
const ELOOP: i32 = 62;

/// `std::fs::read` of an input, refused at once when it is not a regular file.
pub(crate) fn read_input(path: &Path) -> std::io::Result<Vec<u8>> {
    regular_input(path)?;
    std::fs::read(path)
}

/// `std::fs::read_to_string` of an input (a study, run, campaign or model file), refused at once
/// when it is not a regular file.
pub(crate) fn read_input_text(path: &Path) -> std::io::Result<String> {
    regular_input(path)?;
    std::fs::read_to_string(path)
}

/// `File::open` of an input, refused at once when it is not a regular file.
pub(crate) fn open_input(path: &Path) -> std::io::Result<File> {
    regular_input(path)?;
    File::open(path)
}

impl TableError {
    /// Whether the error is the user's input (exit code 2) rather than the system's: everything
    /// but a failing disk (a file that is not there or not readable is the user's to fix).
    pub(crate) fn is_input(&self) -> bool {
        match self {
            TableError::Io { err, .. } => matches!(
                err.kind(),
                std::io::ErrorKind::NotFound
                    | std::io::ErrorKind::PermissionDenied
                    | std::io::ErrorKind::IsADirectory
                    | std::io::ErrorKind::InvalidInput
            ),
            TableError::Many(v) => v.iter().all(TableError::is_input),
            _ => true,
        }
    }
}

/// Runs a Parquet read, turning a panic of the Parquet reader into a format error naming the file.
/// The reader asserts on some corrupt footers instead of returning an error (found by
/// `tests/parsers.rs`: "column start and length should not be negative"); a user's corrupt file is
/// bad input, not a crash.
pub(crate) fn guarded<T>(
    path: &Path,
    read: impl FnOnce() -> Result<T, TableError>,
) -> Result<T, TableError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(read)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(TableError::Format {
            file: path.to_path_buf(),
            kind: "Parquet",
            message: format!("the file is corrupt ({what})"),
        })
    })
}

/// Whether the file at `path` begins with `magic`.
pub(crate) fn starts_with(path: &Path, magic: &[u8]) -> bool {
    use std::io::Read;
    let mut head = vec![0u8; magic.len()];
    open_input(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|_| head == magic)
}

/// Refuses an output path that exists and is not a regular file (a device such as /dev/null, a
/// FIFO, a socket, a folder): renaming a finished table over it would replace it. The error's kind
/// is `InvalidInput`, its text what the path is.
pub(crate) fn regular_output(path: &Path) -> std::io::Result<()> {
    match not_regular(path) {
        None => Ok(()),
        Some(what) => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{}: is {what}, not a regular file: vshake writes its outputs to regular files (or a new path); it was left untouched", path.display()),
        )),
    }
}
