//! Numeric tables in and out: CSV (header row; comma, semicolon or tab separated, found from the
//! header) and Parquet readers with the error behaviour of the measured-file format (a missing
//! column, a NaN or empty cell, an empty file, a header with other units: each names the file,
//! the column and the row), and an atomic Parquet writer (temp file + rename; an interrupted
//! write leaves no file that looks complete). The time base and the values are checked one floor
//! down ([`crate::orchestration::measured::aligned`]).

use crate::kernel::excitation::Reference;
use crate::kernel::params::ModelParams;
use crate::orchestration::measured::channels;
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::ExcitationSpec;
use crate::shell::matlab;
use arrow_array::builder::{Float64Builder, ListBuilder, StringBuilder};
use arrow_array::{
    Array, ArrayRef, Float32Array, Float64Array, Int32Array, Int64Array, RecordBatch,
};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use crate::orchestration::measured::aligned::NumTable;

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
    fn all(mut v: Vec<TableError>) -> TableError {
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
struct BadCells {
    first: Vec<(usize, TableError)>,
    more: Vec<usize>,
}

impl BadCells {
    fn push(&mut self, col: usize, e: impl FnOnce() -> TableError) {
        if self.more.len() <= col {
            self.more.resize(col + 1, 0);
        }
        match self.first.iter().position(|(c, _)| *c == col) {
            Some(_) => self.more[col] += 1,
            None => self.first.push((col, e())),
        }
    }
    fn errors(self) -> Vec<TableError> {
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
    fn finish(self) -> Result<(), TableError> {
        let errors = self.errors();
        if errors.is_empty() {
            Ok(())
        } else {
            Err(TableError::all(errors))
        }
    }
}

fn io_message(e: &std::io::Error) -> String {
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
fn open_input(path: &Path) -> std::io::Result<File> {
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

/// The unit-free stem of a column name (`disp_mm` → `disp`), to spot a header with other units.
fn stem(name: &str) -> &str {
    name.rsplit_once('_').map_or(name, |(s, _)| s)
}

/// A `columns` table that maps channels by position (the start of one).
const BY_POSITION: &str =
    "columns = { time = { column = 1, unit = \"s\" }, accel = { column = 4, unit = \"g\" }, ... }";

/// `text` quoted short: its first `max` bytes (at a character boundary) and how long it is, so a
/// huge header line or cell is never printed back whole.
pub(crate) fn clip(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_string();
    }
    let end = (0..=max)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    format!("{}… ({} bytes in all)", &text[..end], text.len())
}

/// At most 40 column names, each quoted short ([`clip`]), to list in a message.
fn short_names(found: &[String]) -> Vec<String> {
    let mut v: Vec<String> = found.iter().take(40).map(|f| clip(f, 60)).collect();
    if found.len() > 40 {
        v.push(format!("and {} more", found.len() - 40));
    }
    v
}

fn missing(file: &Path, column: &str, found: &[String]) -> TableError {
    let found = &short_names(found)[..];
    let other_units: Vec<&String> = found
        .iter()
        .filter(|f| stem(f) == stem(column) && *f != column)
        .collect();
    let hint = if !other_units.is_empty() {
        format!(
            " (found {}: other units? vshake reads SI columns named as in docs/formats.md)",
            other_units
                .iter()
                .map(|s| format!("`{s}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    } else if !found.is_empty() && found.iter().all(|f| f.ends_with(')') && f.contains("(:,")) {
        format!(
            " (the MAT-file's matrix columns are {}: give each channel's position in the \
             campaign's `columns` table, e.g. {BY_POSITION}, docs/formats.md)",
            found.join(", ")
        )
    } else if channels::channel(column).is_some() {
        format!(
            " (columns present: {}; a column named otherwise is mapped to it by the campaign's \
             `columns` table, docs/formats.md)",
            found.join(", ")
        )
    } else {
        format!(" (columns present: {})", found.join(", "))
    };
    TableError::MissingColumn {
        file: file.to_path_buf(),
        column: column.to_string(),
        hint,
    }
}

/// The column names of a CSV (header row) or Parquet file.
pub fn column_names(path: &Path) -> Result<Vec<String>, TableError> {
    guarded(path, || column_names_unguarded(path))
}

/// Runs a Parquet read, turning a panic of the Parquet reader into a format error naming the file.
/// The reader asserts on some corrupt footers instead of returning an error (found by
/// `tests/parsers.rs`: "column start and length should not be negative"); a user's corrupt file is
/// bad input, not a crash.
fn guarded<T>(path: &Path, read: impl FnOnce() -> Result<T, TableError>) -> Result<T, TableError> {
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

fn column_names_unguarded(path: &Path) -> Result<Vec<String>, TableError> {
    let file = path.to_path_buf();
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq"))
    {
        let b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| TableError::Format {
            file,
            kind: "Parquet",
            message: e.to_string(),
        })?;
        Ok(b.schema()
            .fields()
            .iter()
            .map(|f| f.name().clone())
            .collect())
    } else if starts_with(path, matlab::V5_MAGIC) {
        Ok(mat_columns(path)?.names)
    } else {
        let bytes = read_input(path).map_err(|e| TableError::Io { file, err: e })?;
        let text = String::from_utf8_lossy(&bytes);
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        let lay = channels::layout(text);
        let lines: Vec<&str> = text.lines().collect();
        Ok(csv_header(&lines, &lay).0)
    }
}

/// Marks a table error as bad input (exit 2) when it is the user's.
pub(crate) fn input_if_user(e: TableError) -> anyhow::Error {
    if e.is_input() {
        super::BadInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// The reference of one excitation for `model`, reading a record's file relative to `base` (a
/// PEER `.AT2` file by [`super::at2`]); a generated motion's noise from `seed`.
pub(crate) fn load_reference(
    excitation: &ExcitationSpec,
    model: &ModelParams,
    base: &Path,
    seed: u64,
) -> anyhow::Result<Reference> {
    let record = match excitation {
        ExcitationSpec::Record {
            file,
            column,
            time_column,
            ..
        } => Some(read_record(&base.join(file), column, time_column).map_err(input_if_user)?),
        _ => None,
    };
    single::reference_for(excitation, model, record.as_ref(), seed)
        .map_err(|p| super::BadInput(p.to_string()).into())
}

/// A record's time and value columns: from a CSV or Parquet file, or a PEER `.AT2` file.
pub(crate) fn read_record(
    path: &Path,
    column: &str,
    time_column: &str,
) -> Result<NumTable, TableError> {
    if crate::orchestration::runs::spec::is_at2(path) {
        super::at2::read(path)
    } else {
        read_columns(path, &[time_column, column], &[])
    }
}

/// Reads the `wanted` columns (all required) plus any of `optional` that are present. Every
/// cell must be a finite number (measured data: a NaN is an error naming column and row).
pub fn read_columns(
    path: &Path,
    wanted: &[&str],
    optional: &[&str],
) -> Result<NumTable, TableError> {
    read_columns_impl(path, wanted, optional, false)
}

/// Reads the `wanted` columns of a Parquet results table, where a null (or NaN, in files
/// written before metrics were null) marks a metric of a run that did not end; both read as NaN.
pub fn read_columns_allow_nan(path: &Path, wanted: &[&str]) -> Result<NumTable, TableError> {
    read_columns_impl(path, wanted, &[], true)
}

fn read_columns_impl(
    path: &Path,
    wanted: &[&str],
    optional: &[&str],
    allow_nan: bool,
) -> Result<NumTable, TableError> {
    let (table, bad) = read_columns_lenient_impl(path, (wanted, optional, &[]), allow_nan)?;
    bad.finish()?;
    Ok(table)
}

/// Reads like [`read_columns`], but bad cells (empty, not a number, not finite) do not stop the
/// read: they come back as NaN in the table and as errors beside it (the first of each column,
/// with a count), so that a caller can add its own checks of the same file to one report.
/// `map` is a campaign's `columns` table (channel key → the file's header or position, unit).
pub fn read_columns_lenient(
    path: &Path,
    wanted: &[&str],
    optional: &[&str],
    map: &[(String, channels::Mapped)],
) -> Result<(NumTable, Vec<TableError>), TableError> {
    let (table, bad) = read_columns_lenient_impl(path, (wanted, optional, map), false)?;
    Ok((table, bad.errors()))
}

type Wanted<'a> = (
    &'a [&'a str],
    &'a [&'a str],
    &'a [(String, channels::Mapped)],
);

fn read_columns_lenient_impl(
    path: &Path,
    (wanted, optional, map): Wanted<'_>,
    allow_nan: bool,
) -> Result<(NumTable, BadCells), TableError> {
    // A Parquet file is recognised by its magic bytes whatever its name, and by its extension.
    let is_parquet = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq"))
        || starts_with(path, b"PAR1");
    let (table, bad) = if is_parquet {
        guarded(path, || {
            read_parquet(path, (wanted, optional, map), allow_nan)
        })?
    } else if starts_with(path, matlab::V5_MAGIC) {
        read_mat(path, (wanted, optional, map))?
    } else {
        read_csv(path, (wanted, optional, map))?
    };
    if table.rows() == 0 {
        return Err(TableError::Empty {
            file: path.to_path_buf(),
        });
    }
    Ok((table, bad))
}

/// Reads the `wanted` (and those of the `optional` present) columns of a CSV file: its layout
/// (separator, preamble, header, units row) found from its lines, its columns by name and unit
/// ([`channels::resolve`]), converted to SI.
fn read_csv(path: &Path, wanted: Wanted<'_>) -> Result<(NumTable, BadCells), TableError> {
    let file = path.to_path_buf();
    let bytes = read_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    if let Some((what, advice)) = binary_kind(&bytes) {
        return Err(TableError::Column {
            file,
            message: format!(
                "{what}, not CSV text (vshake reads CSV, Parquet and MATLAB v5/v7 files){advice}"
            ),
        });
    }
    let text = String::from_utf8_lossy(&bytes);
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    if text.trim().is_empty() {
        return Err(TableError::EmptyFile { file });
    }
    let lay = channels::layout(text);
    let lines: Vec<&str> = text.lines().collect();
    let (headers, units) = csv_header(&lines, &lay);
    let idx = csv_columns(
        path,
        &headers,
        units.as_deref(),
        lay.header.is_some(),
        wanted,
    )?;
    let mut notes = layout_notes(&lay);
    notes.extend(columns_note(&idx));
    let (sep, body) = csv_body(&lines[lay.data.min(lines.len())..], lay.sep);
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .delimiter(sep)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(body.as_bytes());
    let (mut columns, bad_cells, decimal_commas) =
        read_csv_records(&mut rdr, &file, &idx, (sep, lay.data + 1))?;
    if decimal_commas {
        notes.push("decimal commas read as decimal points".into());
    }
    for (c, r) in columns.iter_mut().zip(&idx) {
        c.iter_mut().for_each(|v| *v *= r.to_si);
    }
    Ok((
        NumTable {
            file,
            names: idx.into_iter().map(|r| r.name).collect(),
            columns,
            first_line: Some(lay.data + 1),
            notes,
        },
        bad_cells,
    ))
}

/// The numeric variables of the MAT-file at `path` as columns ([`matlab::columns`]).
fn mat_columns(path: &Path) -> Result<matlab::MatColumns, TableError> {
    let file = path.to_path_buf();
    let bytes = read_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    matlab::columns(&bytes).map_err(|message| TableError::Format {
        file,
        kind: "MATLAB .mat",
        message,
    })
}

/// Reads the `wanted` (and those of the `optional` present) columns of a MATLAB MAT-file (v5,
/// v7): its variables are the header, mapped and converted as a CSV header is; the columns read
/// must be equally long.
fn read_mat(path: &Path, wanted: Wanted<'_>) -> Result<(NumTable, BadCells), TableError> {
    let file = path.to_path_buf();
    let mat = mat_columns(path)?;
    let idx = csv_columns(path, &mat.names, None, true, wanted).map_err(|e| {
        if mat.names.is_empty() {
            let mut found: Vec<String> = mat.skipped.clone();
            found.extend(
                (mat.other > 0)
                    .then(|| format!("{} struct, cell, text or table variable(s)", mat.other)),
            );
            let found = if found.is_empty() {
                "no variable at all".into()
            } else {
                format!("only {}", found.join(", "))
            };
            TableError::Column {
                file: file.clone(),
                message: format!(
                    "the MAT-file holds no numeric vector or matrix, {found} (a MATLAB \
                     table, struct or cell is not read: save each channel as a numeric \
                     variable, e.g. save('test.mat', 't', 'ref_disp', 'disp', 'accel'), or as \
                     CSV: {MATLAB_CSV})"
                ),
            }
        } else if !mat.skipped.is_empty() {
            // Say what was not read: a channel saved complex, or as a scalar, is among them.
            let mut all: Vec<TableError> = match e {
                TableError::Many(v) => v,
                e => vec![e],
            };
            all.push(TableError::Column {
                file: file.clone(),
                message: format!("variables not read: {}", mat.skipped.join(", ")),
            });
            TableError::Many(all)
        } else {
            e
        }
    })?;
    mat_lengths(path, &mat, &idx)?;
    let mut bad_cells = BadCells::default();
    let mut columns = Vec::with_capacity(idx.len());
    for (c, r) in idx.iter().enumerate() {
        let values = &mat.values[r.index];
        for (i, v) in values.iter().enumerate().filter(|(_, v)| !v.is_finite()) {
            bad_cells.push(c, || TableError::BadCell {
                file: file.clone(),
                column: mat.names[r.index].clone(),
                row: i + 1,
                line: String::new(),
                message: format!("{v} is not a finite number"),
            });
        }
        columns.push(values.iter().map(|v| v * r.to_si).collect());
    }
    let mut notes = vec![format!(
        "read as a MATLAB MAT-file ({})",
        if mat.compressed {
            "v7, compressed"
        } else {
            "v5"
        }
    )];
    notes.extend(columns_note(&idx));
    Ok((
        NumTable {
            file,
            names: idx.into_iter().map(|r| r.name).collect(),
            columns,
            first_line: None,
            notes,
        },
        bad_cells,
    ))
}

/// The columns `idx` of a MAT-file must have as many samples each.
fn mat_lengths(
    path: &Path,
    mat: &matlab::MatColumns,
    idx: &[channels::Resolved],
) -> Result<(), TableError> {
    let lens: Vec<(String, usize)> = (idx.iter())
        .map(|r| (mat.names[r.index].clone(), mat.values[r.index].len()))
        .collect();
    if lens.iter().all(|(_, n)| *n == lens[0].1) {
        return Ok(());
    }
    let list: Vec<String> = lens.iter().map(|(v, n)| format!("`{v}` {n}")).collect();
    Err(TableError::Column {
        file: path.to_path_buf(),
        message: format!(
            "the variables read have different lengths ({}): each channel needs one value per sample",
            list.join(", ")
        ),
    })
}

/// Whether the file at `path` begins with `magic`.
fn starts_with(path: &Path, magic: &[u8]) -> bool {
    use std::io::Read;
    let mut head = vec![0u8; magic.len()];
    open_input(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|_| head == magic)
}

/// One line to save MATLAB variables as a file vshake reads.
const MATLAB_CSV: &str = "writetable(table(t, ref_disp, disp, accel, 'VariableNames', \
     {'time_s', 'ref_disp_m', 'disp_m', 'accel_mps2'}), 'test.csv')";

/// What a file that is not text is, by its first bytes (never printed), and what to do: a
/// MATLAB v7.3 MAT-file (v5 and v7 are read by [`read_mat`]), a zip archive (an Excel workbook), or other binary (a NUL byte in its first
/// 8 KiB); None for text.
fn binary_kind(bytes: &[u8]) -> Option<(String, String)> {
    let head = &bytes[..bytes.len().min(8192)];
    if head.starts_with(b"MATLAB 7.3 MAT-file") || head.get(512..520) == Some(b"\x89HDF\r\n\x1a\n")
    {
        let advice = format!(
            "; vshake reads MAT-files up to v7: in MATLAB, load it and save('test.mat', '-v7') \
             saves it readably (or as CSV: {MATLAB_CSV})"
        );
        return Some(("a MATLAB MAT-file (v7.3, HDF5)".into(), advice));
    }
    if head.starts_with(b"PK\x03\x04") {
        let advice = "; save the sheet as CSV".to_string();
        return Some(("a zip archive (an Excel .xlsx workbook?)".into(), advice));
    }
    let nul = head.iter().position(|&b| b == 0)?;
    Some((
        format!("binary content (a NUL byte at byte {nul})"),
        String::new(),
    ))
}

/// The header's fields (`column 1`, ... where the file has none) and the units row's.
fn csv_header(lines: &[&str], lay: &channels::Layout) -> (Vec<String>, Option<Vec<String>>) {
    let headers = match lay.header {
        Some(h) => channels::fields(lines[h], lay.sep),
        None => {
            let n = lines
                .get(lay.data)
                .map_or(0, |l| channels::fields(l, lay.sep).len());
            (1..=n).map(|k| format!("column {k}")).collect()
        }
    };
    let units = lay.units.map(|u| {
        (channels::fields(lines[u], lay.sep).iter())
            .map(|c| channels::strip_brackets(c).to_string())
            .collect()
    });
    (headers, units)
}

/// One note for the columns read under another name or unit than vshake's.
fn columns_note(idx: &[channels::Resolved]) -> Option<String> {
    let notes: Vec<&str> = idx.iter().filter_map(|r| r.note.as_deref()).collect();
    (!notes.is_empty()).then(|| notes.join("; "))
}

/// What the layout shows that a plain CSV file would not.
fn layout_notes(lay: &channels::Layout) -> Vec<String> {
    let mut notes = Vec::new();
    match lay.sep {
        b';' => notes.push("read as semicolon-separated values".to_string()),
        b'\t' => notes.push("read as tab-separated values".to_string()),
        b' ' => notes.push("read as space-separated values".to_string()),
        _ => {}
    }
    if let Some(h) = lay.header.filter(|&h| h > 0) {
        notes.push(format!("{h} line(s) before the header skipped"));
    }
    if let Some(u) = lay.units {
        notes.push(format!(
            "units read from the row under the header (line {})",
            u + 1
        ));
    }
    notes
}

/// The data lines as the CSV reader takes them: white-space separated ones re-joined by tabs.
fn csv_body(lines: &[&str], sep: u8) -> (u8, String) {
    if sep != b' ' {
        return (sep, lines.join("\n"));
    }
    let body = lines
        .iter()
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join("\t"));
    (b'\t', body.collect::<Vec<_>>().join("\n"))
}

/// The columns read from a CSV file with `headers` (and a units row): each wanted one (every
/// one missing is an error), then each optional one present, with its position and factor to SI.
fn csv_columns(
    path: &Path,
    headers: &[String],
    units: Option<&[String]>,
    has_header: bool,
    (wanted, optional, map): Wanted<'_>,
) -> Result<Vec<channels::Resolved>, TableError> {
    channels::resolve(headers, units, wanted, optional, map).map_err(|problems| {
        TableError::all(
            (problems.into_iter())
                .map(|p| column_error(path, headers, has_header, p))
                .collect(),
        )
    })
}

/// A column problem as a table error naming the file.
fn column_error(
    path: &Path,
    headers: &[String],
    has_header: bool,
    p: channels::ColumnProblem,
) -> TableError {
    match p {
        channels::ColumnProblem::Missing(c) if !has_header => TableError::MissingColumn {
            file: path.to_path_buf(),
            column: c,
            hint: " (the file has no header row, its first line is numbers: add a header naming the columns, or give each channel's position in the campaign's `columns` table, e.g. columns = { time = { column = 1, unit = \"s\" } }, docs/formats.md)".into(),
        },
        channels::ColumnProblem::Missing(c) => missing(path, &c, headers),
        p => TableError::Column {
            file: path.to_path_buf(),
            message: clip(&p.to_string(), 400),
        },
    }
}

/// The `idx` columns of a CSV file's records: their values (NaN at a bad cell), the bad cells,
/// and whether a decimal comma was read.
fn read_csv_records(
    rdr: &mut csv::Reader<&[u8]>,
    file: &Path,
    idx: &[channels::Resolved],
    (sep, first_line): (u8, usize),
) -> Result<(Vec<Vec<f64>>, BadCells, bool), TableError> {
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); idx.len()];
    let mut decimal_commas = false;
    let mut bad_cells = BadCells::default();
    for (r, rec) in rdr.records().enumerate() {
        let row = r + 1;
        let rec = rec.map_err(|e| TableError::Format {
            file: file.to_path_buf(),
            kind: "CSV",
            message: format!("row {row} (line {}): {e}", row + first_line - 1),
        })?;
        for (c, (r, col)) in idx.iter().zip(columns.iter_mut()).enumerate() {
            let (name, cell) = (&r.name, rec.get(r.index).unwrap_or(""));
            let bad = |message: String| {
                move || TableError::BadCell {
                    file: file.to_path_buf(),
                    column: name.clone(),
                    row,
                    line: format!(" (line {})", row + first_line - 1),
                    message,
                }
            };
            match csv_number(cell, sep, &mut decimal_commas) {
                Ok(v) if v.is_finite() => col.push(v),
                Ok(_) => {
                    bad_cells.push(c, bad(format!("{cell} is not a finite number")));
                    col.push(f64::NAN);
                }
                Err(m) => {
                    bad_cells.push(c, bad(m));
                    col.push(f64::NAN);
                }
            }
        }
    }
    Ok((columns, bad_cells, decimal_commas))
}

/// A CSV cell's number, or why it is none; a decimal comma (read where the separator is not the
/// comma, and so unambiguous) sets `decimal_commas`.
fn csv_number(cell: &str, sep: u8, decimal_commas: &mut bool) -> Result<f64, String> {
    if cell.is_empty() {
        return Err("empty cell".into());
    }
    match cell.parse::<f64>() {
        Ok(v) => Ok(v),
        Err(_) if sep != b',' && cell.matches(',').count() == 1 && !cell.contains('.') => {
            *decimal_commas = true;
            cell.replace(',', ".")
                .parse()
                .map_err(|_| format!("{:?} is not a number", clip(cell, 80)))
        }
        Err(_) => {
            let hint = if sep == b',' && cell.contains(';') {
                " (the file looks semicolon-separated, but its header is not)"
            } else {
                ""
            };
            Err(format!("{:?} is not a number{hint}", clip(cell, 80)))
        }
    }
}

/// Reads the `wanted` (and those of the `optional` present) numeric columns of a Parquet file;
/// NaN is a bad cell unless `allow_nan`.
fn read_parquet(
    path: &Path,
    (wanted, optional, map): Wanted<'_>,
    allow_nan: bool,
) -> Result<(NumTable, BadCells), TableError> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format {
        file: file.clone(),
        kind: "Parquet",
        message: e.to_string(),
    };
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let found: Vec<String> = builder
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .collect();
    let idx = channels::resolve(&found, None, wanted, optional, map).map_err(|problems| {
        TableError::all(
            (problems.into_iter())
                .map(|p| column_error(path, &found, true, p))
                .collect(),
        )
    })?;
    let reader = builder.build().map_err(|e| fmt(&e))?;
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); idx.len()];
    let mut bad_cells = BadCells::default();
    for batch in reader {
        let batch = batch.map_err(|e| fmt(&e))?;
        for (c, (r, col)) in idx.iter().zip(columns.iter_mut()).enumerate() {
            let arr = batch.column(r.index);
            append_parquet_cells((&file, &r.name), arr, col, (c, &mut bad_cells), allow_nan)?;
        }
    }
    for (c, r) in columns.iter_mut().zip(&idx) {
        c.iter_mut().for_each(|v| *v *= r.to_si);
    }
    Ok((
        NumTable {
            file,
            notes: columns_note(&idx).into_iter().collect(),
            names: idx.into_iter().map(|r| r.name).collect(),
            columns,
            first_line: None,
        },
        bad_cells,
    ))
}

/// Appends a batch's cells of column `c` (`name` in `file`) to `col`: a null is NaN, and a bad
/// cell unless `allow_nan`, as is NaN (and any other value that is not finite); a column of
/// another type than a number is an error.
fn append_parquet_cells(
    (file, name): (&Path, &str),
    arr: &ArrayRef,
    col: &mut Vec<f64>,
    (c, bad_cells): (usize, &mut BadCells),
    allow_nan: bool,
) -> Result<(), TableError> {
    let base = col.len();
    let bad = |row: usize, message: String| TableError::BadCell {
        file: file.to_path_buf(),
        column: name.to_string(),
        row,
        line: String::new(),
        message,
    };
    let Some(get) = numeric_values(arr) else {
        let other = arr.data_type();
        return Err(bad(base + 1, format!("column type {other} is not numeric")));
    };
    for i in 0..arr.len() {
        let row = base + i + 1;
        if arr.is_null(i) {
            if !allow_nan {
                bad_cells.push(c, || bad(row, "empty (null) cell".into()));
            }
            col.push(f64::NAN);
            continue;
        }
        let v = get(i);
        if !(v.is_finite() || allow_nan && v.is_nan()) {
            bad_cells.push(c, || bad(row, format!("{v} is not a finite number")));
        }
        col.push(v);
    }
    Ok(())
}

/// The values of a numeric Arrow array (floats and integers) as f64; None for another type.
fn numeric_values(arr: &ArrayRef) -> Option<Box<dyn Fn(usize) -> f64>> {
    Some(match arr.data_type() {
        DataType::Float64 => {
            let a = arr.as_any().downcast_ref::<Float64Array>().unwrap().clone();
            Box::new(move |i| a.value(i))
        }
        DataType::Float32 => {
            let a = arr.as_any().downcast_ref::<Float32Array>().unwrap().clone();
            Box::new(move |i| a.value(i) as f64)
        }
        DataType::Int64 => {
            let a = arr.as_any().downcast_ref::<Int64Array>().unwrap().clone();
            Box::new(move |i| a.value(i) as f64)
        }
        DataType::Int32 => {
            let a = arr.as_any().downcast_ref::<Int32Array>().unwrap().clone();
            Box::new(move |i| a.value(i) as f64)
        }
        DataType::UInt64 => {
            let a = arr
                .as_any()
                .downcast_ref::<arrow_array::UInt64Array>()
                .unwrap()
                .clone();
            Box::new(move |i| a.value(i) as f64)
        }
        DataType::UInt32 => {
            let a = arr
                .as_any()
                .downcast_ref::<arrow_array::UInt32Array>()
                .unwrap()
                .clone();
            Box::new(move |i| a.value(i) as f64)
        }
        _ => return None,
    })
}

/// A file being written: `path.tmp` until [`AtomicFile::commit`] renames it into place. Dropped
/// without commit, the temp file is removed.
pub struct AtomicFile {
    pub path: PathBuf,
    pub tmp: PathBuf,
    pub committed: bool,
    /// Kept on drop though not committed ([`AtomicFile::keep`]).
    kept: bool,
}

impl AtomicFile {
    pub fn new(path: &Path) -> Self {
        AtomicFile {
            path: path.to_path_buf(),
            tmp: tmp_path(path),
            committed: false,
            kept: false,
        }
    }
    /// Leaves the temp file in place when dropped uncommitted (the rows of a checkpoint in it).
    pub(crate) fn keep(&mut self) {
        self.kept = true;
    }
    pub fn commit(mut self) -> std::io::Result<()> {
        self.commit_in_place()
    }
    /// Renames the temp file into place, keeping the guard (for owners that implement Drop).
    /// Never over something that is not a regular file: a rename would replace a device node
    /// (`/dev/null` for root) or a FIFO with the table.
    pub(crate) fn commit_in_place(&mut self) -> std::io::Result<()> {
        super::outputs::regular_output(&self.path)?;
        std::fs::rename(&self.tmp, &self.path)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed && !self.kept {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// A column to write.
pub enum Column {
    F64(Vec<f64>),
    /// Nullable f64 (None → null).
    OptF64(Vec<Option<f64>>),
    U64(Vec<u64>),
    U32(Vec<u32>),
    Str(Vec<String>),
    /// Nullable string.
    OptStr(Vec<Option<String>>),
    Bool(Vec<bool>),
    /// A list of strings per row (Arrow `List<Utf8>`).
    StrList(Vec<Vec<String>>),
    /// A list of numbers per row (Arrow `List<Float64>`).
    F64List(Vec<Vec<f64>>),
}

impl Column {
    fn field(&self, name: &str) -> Field {
        match self {
            Column::F64(_) => Field::new(name, DataType::Float64, false),
            Column::OptF64(_) => Field::new(name, DataType::Float64, true),
            Column::U64(_) => Field::new(name, DataType::UInt64, false),
            Column::U32(_) => Field::new(name, DataType::UInt32, false),
            Column::Str(_) => Field::new(name, DataType::Utf8, false),
            Column::OptStr(_) => Field::new(name, DataType::Utf8, true),
            Column::Bool(_) => Field::new(name, DataType::Boolean, false),
            Column::StrList(_) => Field::new(
                name,
                DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
                false,
            ),
            Column::F64List(_) => Field::new(
                name,
                DataType::List(Arc::new(Field::new("item", DataType::Float64, true))),
                false,
            ),
        }
    }
    fn array(self) -> ArrayRef {
        match self {
            Column::F64(v) => Arc::new(Float64Array::from(v)),
            Column::OptF64(v) => Arc::new(Float64Array::from(v)),
            Column::U64(v) => Arc::new(arrow_array::UInt64Array::from(v)),
            Column::U32(v) => Arc::new(arrow_array::UInt32Array::from(v)),
            Column::Str(v) => Arc::new(arrow_array::StringArray::from(v)),
            Column::OptStr(v) => Arc::new(arrow_array::StringArray::from(v)),
            Column::Bool(v) => Arc::new(arrow_array::BooleanArray::from(v)),
            Column::StrList(v) => {
                let mut b = ListBuilder::new(StringBuilder::new());
                for row in v {
                    b.values().extend(row.into_iter().map(Some));
                    b.append(true);
                }
                Arc::new(b.finish())
            }
            Column::F64List(v) => {
                let mut b = ListBuilder::new(Float64Builder::new());
                for row in v {
                    b.values().append_slice(&row);
                    b.append(true);
                }
                Arc::new(b.finish())
            }
        }
    }
}

/// Encoded bytes of a row group in progress at which it is flushed (also at 16 384 rows).
const ROW_GROUP_BYTES: usize = 4 << 20;

/// A Parquet file written batch by batch (zstd, bounded row groups), atomically: it appears
/// under its name only when [`ParquetStream::finish`] (or [`ParquetStream::finish_incomplete`])
/// succeeds.
///
/// With [`ParquetStream::checkpoints`], the rows also survive a hard kill (SIGKILL, power loss):
/// every few seconds the buffered rows become a row group, the file is synced, and a footer for
/// the row groups written so far goes to `path.tmp.checkpoint` (8 bytes little-endian: the length
/// of `path.tmp` it describes; then the footer). [`recover_killed`] turns the pair into a
/// readable file.
pub struct ParquetStream {
    file: AtomicFile,
    writer: ArrowWriter<File>,
    schema: Arc<Schema>,
    /// The key-value metadata in the order given (the schema's copy is a map).
    kv: Vec<KeyValue>,
    /// The CRC-32 of each row group written so far ([`super::integrity`]).
    sums: Vec<u32>,
    checkpoint: Option<Checkpoint>,
}

struct Checkpoint {
    every: std::time::Duration,
    last: std::time::Instant,
    path: PathBuf,
    /// The file's key-value metadata, `ARROW:schema` included, for the checkpoint footers.
    kv: Vec<KeyValue>,
    /// Whether a checkpoint was written: its rows are then safe, and an error keeps them.
    saved: bool,
}

/// The checkpoint sidecar of a results file being written: `path.tmp.checkpoint`.
pub(crate) fn checkpoint_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".tmp.checkpoint");
    PathBuf::from(p)
}

/// The temp file a results file is written to until it is closed: `path.tmp`.
pub(crate) fn tmp_path(path: &Path) -> PathBuf {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    PathBuf::from(tmp)
}

/// A write that failed: the file, and the system's reason once (a Parquet error wraps the I/O
/// error it reports, and repeats it).
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write: {cause}", file.display())]
pub struct WriteFailed {
    pub file: PathBuf,
    pub cause: String,
    /// The disk is full, or the file reached its size limit (`ulimit -f`) or a quota.
    pub no_space: bool,
}

/// `e`, an error writing `file`, as a [`WriteFailed`]: the innermost I/O error in its chain as
/// the cause, else the innermost message.
pub(crate) fn write_failed(file: &Path, e: impl Into<anyhow::Error>) -> anyhow::Error {
    use std::io::ErrorKind as K;
    let e: anyhow::Error = e.into();
    if e.downcast_ref::<WriteFailed>().is_some() {
        return e;
    }
    let io = e
        .chain()
        .filter_map(|c| c.downcast_ref::<std::io::Error>())
        .last();
    let cause = io.map_or_else(|| e.root_cause().to_string(), |io| io.to_string());
    let no_space = io.is_some_and(|io| {
        matches!(
            io.kind(),
            K::StorageFull | K::FileTooLarge | K::QuotaExceeded
        )
    });
    WriteFailed {
        file: file.to_path_buf(),
        cause,
        no_space,
    }
    .into()
}

impl ParquetStream {
    /// Opens `path.tmp` for a table with the columns of `template` (names and types).
    pub fn create(
        path: &Path,
        template: &[(String, Column)],
        metadata: &[(String, String)],
    ) -> anyhow::Result<Self> {
        Self::create_with_fields(
            path,
            template.iter().map(|(n, c)| c.field(n)).collect(),
            metadata,
        )
    }

    /// Opens `path.tmp` for a table with these Arrow fields.
    pub(crate) fn create_with_fields(
        path: &Path,
        fields: Vec<Field>,
        metadata: &[(String, String)],
    ) -> anyhow::Result<Self> {
        use anyhow::Context;
        // The metadata goes into the file's key-value block (DuckDB, polars, pandas) and into the
        // Arrow schema too, so `pyarrow.parquet.read_table(path).schema.metadata` shows it.
        let schema = Arc::new(
            Schema::new(fields).with_metadata(
                metadata
                    .iter()
                    .cloned()
                    .collect::<std::collections::HashMap<String, String>>(),
            ),
        );
        // Dictionary encoding only for string columns: float columns of simulation results are
        // nearly all distinct values, and a dictionary per column would hold up to a page each in
        // memory for nothing.
        let mut props = WriterProperties::builder().set_dictionary_enabled(false);
        for f in schema.fields() {
            if f.data_type() == &DataType::Utf8 {
                props = props.set_column_dictionary_enabled(f.name().as_str().into(), true);
            }
        }
        let kv: Vec<KeyValue> = metadata
            .iter()
            .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
            .collect();
        let props = props
            .set_compression(Compression::ZSTD(ZstdLevel::default()))
            .set_max_row_group_row_count(Some(16_384))
            .set_key_value_metadata(Some(kv.clone()))
            .build();
        let file = AtomicFile::new(path);
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        // Read too: each row group's checksum is taken from the bytes in the file.
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&file.tmp)
            .with_context(|| format!("cannot create {}", file.tmp.display()))?;
        let writer = ArrowWriter::try_new(f, schema.clone(), Some(props))
            .map_err(|e| write_failed(&file.tmp, e))?;
        Ok(ParquetStream {
            file,
            writer,
            schema,
            kv,
            sums: Vec::new(),
            checkpoint: None,
        })
    }

    /// Makes the rows recoverable after a hard kill, at most `every` apart (see the type's doc).
    pub fn checkpoints(mut self, every: std::time::Duration) -> Self {
        let mut kv = self.kv.clone();
        kv.push(KeyValue::new(
            "ARROW:schema".to_string(),
            parquet::arrow::encode_arrow_schema(&self.schema),
        ));
        self.checkpoint = Some(Checkpoint {
            every,
            last: std::time::Instant::now(),
            path: checkpoint_path(&self.file.path),
            kv,
            saved: false,
        });
        self
    }

    /// Appends a record batch whose columns match this table's fields.
    pub(crate) fn write_batch(&mut self, batch: &RecordBatch) -> anyhow::Result<()> {
        let batch = RecordBatch::try_new(self.schema.clone(), batch.columns().to_vec())?;
        self.writer
            .write(&batch)
            .map_err(|e| write_failed(&self.file.tmp, e))?;
        self.after_write()
    }

    /// Appends rows (columns in the template's order).
    pub fn write(&mut self, columns: Vec<Column>) -> anyhow::Result<()> {
        let batch = RecordBatch::try_new(
            self.schema.clone(),
            columns.into_iter().map(Column::array).collect(),
        )?;
        self.writer
            .write(&batch)
            .map_err(|e| write_failed(&self.file.tmp, e))?;
        self.after_write()
    }

    /// Bounds the buffered row group by bytes, so memory stays flat however many rows follow;
    /// and, with checkpoints, flushes and checkpoints when one is due.
    fn after_write(&mut self) -> anyhow::Result<()> {
        let due = self
            .checkpoint
            .as_ref()
            .is_some_and(|c| c.last.elapsed() >= c.every);
        if self.writer.in_progress_size() > ROW_GROUP_BYTES
            || (due && self.writer.in_progress_rows() > 0)
        {
            self.writer
                .flush()
                .map_err(|e| write_failed(&self.file.tmp, e))?;
        }
        self.take_sums()?;
        if due && !self.writer.flushed_row_groups().is_empty() {
            self.save_checkpoint()?;
        }
        Ok(())
    }

    /// Takes the checksum of each row group flushed since the last call, from the file's bytes.
    fn take_sums(&mut self) -> anyhow::Result<()> {
        if self.writer.flushed_row_groups().len() == self.sums.len() {
            return Ok(());
        }
        let tmp = &self.file.tmp;
        self.writer.sync().map_err(|e| write_failed(tmp, e))?;
        for g in &self.writer.flushed_row_groups()[self.sums.len()..] {
            let sum = super::integrity::row_group_sum(self.writer.inner(), g).ok_or_else(|| {
                write_failed(
                    tmp,
                    anyhow::anyhow!("a row group just written cannot be read back"),
                )
            })?;
            self.sums.push(sum);
        }
        Ok(())
    }

    /// Syncs the row groups written so far to the disk and writes their footer, with their
    /// checksums, to the sidecar (atomically).
    fn save_checkpoint(&mut self) -> anyhow::Result<()> {
        use parquet::file::metadata::{FileMetaData, ParquetMetaData, ParquetMetaDataWriter};
        use std::io::Write;
        let Some(c) = self.checkpoint.as_mut() else {
            return Ok(());
        };
        let tmp = &self.file.tmp;
        self.writer.sync().map_err(|e| write_failed(tmp, e))?;
        self.writer
            .inner()
            .sync_data()
            .map_err(|e| write_failed(tmp, e))?;
        let len = self.writer.bytes_written() as u64;
        let groups = self.writer.flushed_row_groups().to_vec();
        let rows = groups.iter().map(|g| g.num_rows()).sum();
        let descr = groups[0].schema_descr_ptr();
        let mut kv = c.kv.clone();
        kv.extend(super::integrity::checksum_entries(&c.kv, &self.sums));
        let meta = ParquetMetaData::new(
            FileMetaData::new(
                1,
                rows,
                Some("vshake checkpoint".into()),
                Some(kv),
                descr,
                None,
            ),
            groups,
        );
        let mut bytes = len.to_le_bytes().to_vec();
        ParquetMetaDataWriter::new(&mut bytes, &meta).finish()?;
        let side = AtomicFile::new(&c.path);
        let written = File::create(&side.tmp).and_then(|mut f| {
            f.write_all(&bytes)?;
            f.sync_all()
        });
        written.map_err(|e| write_failed(&side.tmp, e))?;
        side.commit().map_err(|e| write_failed(&c.path, e))?;
        c.last = std::time::Instant::now();
        c.saved = true;
        Ok(())
    }

    /// Rows written so far (flushed or buffered).
    pub fn rows(&self) -> usize {
        self.writer
            .flushed_row_groups()
            .iter()
            .map(|g| g.num_rows() as usize)
            .sum::<usize>()
            + self.writer.in_progress_rows()
    }

    /// Closes the file and moves it into place.
    pub fn finish(self) -> anyhow::Result<()> {
        self.finish_with(&[])
    }

    /// Closes the file with these key-value pairs and the row groups' checksums added to its
    /// metadata, and moves it into place.
    pub(crate) fn finish_with(mut self, extra: &[(String, String)]) -> anyhow::Result<()> {
        use anyhow::Context;
        self.writer
            .flush()
            .map_err(|e| write_failed(&self.file.tmp, e))?;
        self.take_sums()?;
        let mut kv = self.kv.clone();
        kv.extend(
            extra
                .iter()
                .map(|(k, v)| KeyValue::new(k.clone(), v.clone())),
        );
        let sums = super::integrity::checksum_entries(&kv, &self.sums);
        for e in kv.into_iter().skip(self.kv.len()).chain(sums) {
            self.writer.append_key_value_metadata(e);
        }
        self.writer
            .finish()
            .map_err(|e| write_failed(&self.file.tmp, e))?;
        let path = self.file.path.clone();
        self.file
            .commit_in_place()
            .with_context(|| format!("cannot move the finished file to {}", path.display()))?;
        if let Some(c) = &self.checkpoint {
            let _ = std::fs::remove_file(&c.path);
        }
        Ok(())
    }
}

impl Drop for ParquetStream {
    /// A stream dropped unfinished (an error) keeps its temp file and its checkpoint where a
    /// checkpoint was written (those rows are safe, for `study run --resume`), else leaves neither.
    fn drop(&mut self) {
        if let Some(c) = &self.checkpoint {
            if !self.file.committed && c.saved && c.path.exists() {
                self.file.keep();
            } else if !self.file.committed {
                let _ = std::fs::remove_file(&c.path);
            }
        }
    }
}

/// What [`recover_killed`] found.
#[derive(Debug)]
pub enum Recovered {
    /// No `path.tmp`: nothing was killed.
    Nothing,
    /// `path.tmp` exists without a checkpoint: killed before its first checkpoint.
    NoCheckpoint(PathBuf),
    /// The checkpointed rows, now a readable Parquet file at this path (`path.killed`).
    File(PathBuf),
}

/// Where a results table is written until it is complete: `NAME.partial.parquet` for
/// `NAME.parquet` (`NAME.partial` for another name), so that no reader takes a stopped run for
/// a finished one.
pub fn partial_path(out: &Path) -> PathBuf {
    let name = out.file_name().unwrap_or_default().to_string_lossy();
    let partial = match name.strip_suffix(".parquet") {
        Some(stem) => format!("{stem}.partial.parquet"),
        None => format!("{name}.partial"),
    };
    out.with_file_name(partial)
}

/// The results table a partial one becomes (see [`partial_path`]); any other path as it is.
pub(crate) fn final_path(p: &Path) -> PathBuf {
    let name = p.file_name().unwrap_or_default().to_string_lossy();
    match (
        name.strip_suffix(".partial.parquet"),
        name.strip_suffix(".partial"),
    ) {
        (Some(stem), _) => p.with_file_name(format!("{stem}.parquet")),
        (None, Some(stem)) if !stem.is_empty() => p.with_file_name(stem),
        _ => p.to_path_buf(),
    }
}

/// Where a killed run's rows go when they are recovered: `FILE.killed`.
pub(crate) fn killed_path(path: &Path) -> PathBuf {
    let mut killed = path.as_os_str().to_owned();
    killed.push(".killed");
    PathBuf::from(killed)
}

/// Turns the temp file of a killed stream and its checkpoint into a readable Parquet file
/// `path.killed` holding every checkpointed row group (the bytes after the checkpoint are
/// dropped). The checkpoint and the row groups it describes are checked first (its footer, the
/// temp file's length, each row group's checksum): a pair that does not match is refused and left
/// as it is. Then the temp file and the checkpoint are consumed.
pub fn recover_killed(path: &Path) -> anyhow::Result<Recovered> {
    use anyhow::Context;
    use std::io::{Seek, Write};
    let tmp = tmp_path(path);
    let side = checkpoint_path(path);
    if !tmp.exists() {
        return Ok(Recovered::Nothing);
    }
    let Ok(bytes) = std::fs::read(&side) else {
        return Ok(Recovered::NoCheckpoint(tmp));
    };
    let len = checked_checkpoint(&tmp, &side, &bytes)?;
    let killed = killed_path(path);
    std::fs::rename(&tmp, &killed)
        .with_context(|| format!("cannot move {} to {}", tmp.display(), killed.display()))?;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .open(&killed)
        .with_context(|| format!("cannot open {}", killed.display()))?;
    let appended = f
        .set_len(len)
        .and_then(|_| f.seek(std::io::SeekFrom::End(0)))
        .and_then(|_| f.write_all(&bytes[8..]))
        .and_then(|_| f.sync_all());
    appended.map_err(|e| write_failed(&killed, e))?;
    std::fs::remove_file(&side)?;
    Ok(Recovered::File(killed))
}

/// The length of the temp file a checkpoint covers, once checked: its footer is one, the temp
/// file holds every byte of the row groups it lists, and each matches its checksum.
fn checked_checkpoint(tmp: &Path, side: &Path, bytes: &[u8]) -> anyhow::Result<u64> {
    use parquet::file::metadata::ParquetMetaDataReader;
    let bad = |why: String| BadCheckpoint {
        file: side.to_path_buf(),
        why,
    };
    let n = bytes.len();
    if n < 16 || &bytes[n - 4..] != b"PAR1" {
        return Err(bad("it is not a checkpoint (too short, or no Parquet footer)".into()).into());
    }
    let len = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    let footer = &bytes[8..n - 8];
    let decoded = std::panic::catch_unwind(|| ParquetMetaDataReader::decode_metadata(footer));
    let meta = match decoded {
        Ok(Ok(m)) => m,
        Ok(Err(e)) => return Err(bad(format!("its footer cannot be read ({e})")).into()),
        Err(_) => return Err(bad("its footer is corrupt".into()).into()),
    };
    let data = File::open(tmp).map_err(|e| bad(format!("{}: {e}", tmp.display())))?;
    let have = data.metadata().map(|m| m.len()).unwrap_or(0);
    let end = meta
        .row_groups()
        .iter()
        .map(|g| super::integrity::byte_range(g).map_or(u64::MAX, |(_, b)| b))
        .max()
        .unwrap_or(0);
    if have < len || end > len {
        return Err(bad(format!(
            "it covers {len} bytes of {}, whose row groups it lists end at byte {end}, and the file holds {have}",
            tmp.display()
        ))
        .into());
    }
    // The footer's Arrow schema against its Parquet schema, as a reader will take them: a byte
    // changed in a column's name is refused here, before anything is moved.
    let file_meta = meta.file_metadata();
    parquet::arrow::parquet_to_arrow_schema(
        file_meta.schema_descr(),
        file_meta.key_value_metadata(),
    )
    .map_err(|e| bad(format!("its schema cannot be read ({e})")))?;
    super::integrity::verify(&data, &meta, tmp)?;
    Ok(len)
}

/// The rows a checkpoint sidecar covers (None where there is none, or it cannot be read).
pub(crate) fn checkpoint_rows(side: &Path) -> Option<u64> {
    let bytes = std::fs::read(side).ok()?;
    let footer = bytes.get(8..bytes.len().checked_sub(8)?)?;
    let meta = std::panic::catch_unwind(|| {
        parquet::file::metadata::ParquetMetaDataReader::decode_metadata(footer)
    });
    Some(meta.ok()?.ok()?.file_metadata().num_rows().max(0) as u64)
}

/// A checkpoint that does not describe its temp file: both are left as they are.
#[derive(Debug, thiserror::Error)]
#[error("{}: the checkpoint does not match its temp file: {why}; nothing was changed; start the run again (or restore both files)", file.display())]
pub struct BadCheckpoint {
    pub file: PathBuf,
    pub why: String,
}

/// Writes f64 columns as one Parquet file (zstd) with key-value metadata, atomically.
pub fn write_parquet(
    path: &Path,
    columns: &[(&str, &[f64])],
    metadata: &[(String, String)],
) -> anyhow::Result<()> {
    let cols: Vec<(String, Column)> = columns
        .iter()
        .map(|(n, v)| (n.to_string(), Column::F64(v.to_vec())))
        .collect();
    write_table(path, cols, metadata)
}

/// Writes typed columns as one Parquet file, atomically.
pub(crate) fn write_table(
    path: &Path,
    columns: Vec<(String, Column)>,
    metadata: &[(String, String)],
) -> anyhow::Result<()> {
    let mut s = ParquetStream::create(path, &columns, metadata)?;
    s.write(columns.into_iter().map(|(_, c)| c).collect())?;
    s.finish()
}

/// The number of rows of a Parquet file (from its footer).
pub(crate) fn parquet_rows(path: &Path) -> Result<usize, TableError> {
    guarded(path, || parquet_rows_unguarded(path))
}

fn parquet_rows_unguarded(path: &Path) -> Result<usize, TableError> {
    let file = path.to_path_buf();
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| TableError::Format {
        file,
        kind: "Parquet",
        message: e.to_string(),
    })?;
    Ok(builder.metadata().file_metadata().num_rows().max(0) as usize)
}

/// The key-value metadata of a Parquet file.
pub fn parquet_metadata(path: &Path) -> Result<Vec<(String, String)>, TableError> {
    guarded(path, || parquet_metadata_unguarded(path))
}

fn parquet_metadata_unguarded(path: &Path) -> Result<Vec<(String, String)>, TableError> {
    let file = path.to_path_buf();
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| TableError::Format {
        file,
        kind: "Parquet",
        message: e.to_string(),
    })?;
    Ok(builder
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .map(|kv| {
            kv.iter()
                .map(|k| (k.key.clone(), k.value.clone().unwrap_or_default()))
                .collect()
        })
        .unwrap_or_default())
}

/// The string column `column` of a Parquet file (null cells as empty strings).
pub fn read_strings(path: &Path, column: &str) -> Result<Vec<String>, TableError> {
    read_values(path, column, "a string", |arr, out| {
        let s = arr.as_any().downcast_ref::<arrow_array::StringArray>()?;
        out.extend((0..s.len()).map(|i| {
            if s.is_null(i) {
                String::new()
            } else {
                s.value(i).to_string()
            }
        }));
        Some(())
    })
}

/// A nullable number column of a Parquet file (a null reads as None).
pub fn read_opt_f64(path: &Path, column: &str) -> Result<Vec<Option<f64>>, TableError> {
    read_values(path, column, "a number", |arr, out| {
        let x = arr.as_any().downcast_ref::<Float64Array>()?;
        out.extend((0..x.len()).map(|i| (!x.is_null(i)).then(|| x.value(i))));
        Some(())
    })
}

/// A Boolean column of a Parquet file (a null reads as false).
pub fn read_bools(path: &Path, column: &str) -> Result<Vec<bool>, TableError> {
    read_values(path, column, "Boolean", |arr, out| {
        let b = arr.as_any().downcast_ref::<arrow_array::BooleanArray>()?;
        out.extend((0..b.len()).map(|i| !b.is_null(i) && b.value(i)));
        Some(())
    })
}

/// A list-of-strings column of a Parquet file (a null row reads as an empty list).
pub fn read_string_lists(path: &Path, column: &str) -> Result<Vec<Vec<String>>, TableError> {
    read_lists(path, column, "a list of strings", |v| {
        let s = v.as_any().downcast_ref::<arrow_array::StringArray>()?;
        Some((0..s.len()).map(|j| s.value(j).to_string()).collect())
    })
}

/// A list-of-numbers column of a Parquet file (a null row reads as an empty list).
pub fn read_f64_lists(path: &Path, column: &str) -> Result<Vec<Vec<f64>>, TableError> {
    read_lists(path, column, "a list of numbers", |v| {
        Some(v.as_any().downcast_ref::<Float64Array>()?.values().to_vec())
    })
}

/// A list column of a Parquet file, each row's items read by `items` (None: not of the type
/// `kind` names); a null row reads as an empty list.
fn read_lists<T>(
    path: &Path,
    column: &str,
    kind: &str,
    items: impl Fn(&ArrayRef) -> Option<Vec<T>>,
) -> Result<Vec<Vec<T>>, TableError> {
    read_values(path, column, kind, |arr, out| {
        let l = arr.as_any().downcast_ref::<arrow_array::ListArray>()?;
        for i in 0..l.len() {
            out.push(if l.is_null(i) {
                Vec::new()
            } else {
                items(&l.value(i))?
            });
        }
        Some(())
    })
}

/// One column of a Parquet file, each batch's array appended by `take` (None: not of the type
/// `kind` names).
fn read_values<T>(
    path: &Path,
    column: &str,
    kind: &str,
    take: impl Fn(&ArrayRef, &mut Vec<T>) -> Option<()>,
) -> Result<Vec<T>, TableError> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format {
        file: file.clone(),
        kind: "Parquet",
        message: e.to_string(),
    };
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let found: Vec<String> = builder
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .collect();
    if !found.iter().any(|f| f == column) {
        return Err(missing(path, column, &found));
    }
    let mut out = Vec::new();
    for batch in builder.build().map_err(|e| fmt(&e))? {
        let batch = batch.map_err(|e| fmt(&e))?;
        let arr = batch.column_by_name(column).expect("column in schema");
        let row = out.len() + 1;
        take(arr, &mut out).ok_or_else(|| TableError::BadCell {
            file: file.clone(),
            column: column.to_string(),
            row,
            line: String::new(),
            message: format!("column type {} is not {kind}", arr.data_type()),
        })?;
    }
    Ok(out)
}

/// The Arrow fields of a Parquet file, and a reader of its record batches.
pub fn parquet_batches(
    path: &Path,
) -> Result<
    (
        Vec<Field>,
        parquet::arrow::arrow_reader::ParquetRecordBatchReader,
    ),
    TableError,
> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format {
        file: file.clone(),
        kind: "Parquet",
        message: e.to_string(),
    };
    let f = open_input(path).map_err(|e| TableError::Io {
        file: file.clone(),
        err: e,
    })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let fields = builder
        .schema()
        .fields()
        .iter()
        .map(|f| f.as_ref().clone())
        .collect();
    Ok((fields, builder.build().map_err(|e| fmt(&e))?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn csv(text: &str) -> (tempfile::TempDir, PathBuf) {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("t.csv");
        std::fs::write(&p, text).unwrap();
        (d, p)
    }

    #[test]
    fn files_are_recognised_by_content_and_binary_is_never_printed() {
        let d = tempfile::tempdir().unwrap();
        let mut mat = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00".to_vec();
        mat.resize(512, b' ');
        mat.extend(b"\x89HDF\r\n\x1a\n");
        mat.extend((0..2000u32).map(|i| (i * 37 % 251) as u8));
        for (name, bytes, says) in [
            ("m.csv", mat.clone(), "MATLAB MAT-file (v7.3, HDF5)"),
            ("x.csv", b"PK\x03\x04\x14\x00junk".to_vec(), "zip archive"),
            (
                "b.csv",
                b"time_s,x\n0\x00\x01,2\n".to_vec(),
                "NUL byte at byte 10",
            ),
        ] {
            let p = d.path().join(name);
            std::fs::write(&p, &bytes).unwrap();
            let e = read_columns(&p, &["time_s"], &[]).unwrap_err().to_string();
            assert!(
                e.contains(name) && e.contains(says) && e.contains("not CSV text"),
                "{e}"
            );
            assert!(
                !e.contains('\u{fffd}') && !e.contains('\0'),
                "binary printed: {e}"
            );
        }
        let e = read_columns(&d.path().join("m.csv"), &["time_s"], &[]).unwrap_err();
        assert!(e.to_string().contains("writetable("), "{e}");
        // A v5 header over garbage is a corrupt MAT-file, by its content whatever the name.
        let mut v5 = b"MATLAB 5.0 MAT-file, Platform: GLNXA64".to_vec();
        v5.resize(128, b' ');
        v5.extend((0..2000u32).map(|i| (i * 37 % 251) as u8));
        let p = d.path().join("v5.csv");
        std::fs::write(&p, &v5).unwrap();
        let e = read_columns(&p, &["time_s"], &[]).unwrap_err().to_string();
        assert!(
            e.contains("v5.csv: not a readable MATLAB .mat file: the file is corrupt"),
            "{e}"
        );
        assert!(
            !e.contains('\u{fffd}') && !e.contains('\0'),
            "binary printed: {e}"
        );
        // A Parquet file under a .csv name is read as Parquet.
        let pq = d.path().join("p.parquet");
        write_parquet(&pq, &[("time_s", &[0.0, 1.0][..])], &[]).unwrap();
        let renamed = d.path().join("p.csv");
        std::fs::rename(&pq, &renamed).unwrap();
        let t = read_columns(&renamed, &["time_s"], &[]).unwrap();
        assert_eq!(t.column("time_s").unwrap(), &[0.0, 1.0]);
    }

    #[test]
    fn nan_and_empty_cells_name_column_and_row() {
        let (_d, p) = csv("time_s,ref_disp_m\n0,0\n0.001,NaN\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`ref_disp_m`, row 2 (line 3)") && e.contains("NaN"),
            "{e}"
        );
        let (_d, p) = csv("time_s,ref_disp_m\n0,0\n0.001,\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 2") && e.contains("empty cell"), "{e}");
    }

    #[test]
    fn other_units_and_bad_time_are_named() {
        // Issue 27: a unit written in the header is read and converted, with a note.
        let (_d, p) = csv("time_s,ref_disp_mm\n0,1.5\n");
        let t = read_columns(&p, &["time_s", "ref_disp_m"], &[]).unwrap();
        assert_eq!(t.column("ref_disp_m").unwrap(), &[1.5e-3]);
        assert_eq!(t.notes, ["`ref_disp_mm` read as ref_disp_m (mm → m)"]);
        let (_d, p) = csv("time_s,ref_disp_furlongs\n0,0\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`ref_disp_furlongs`: unknown unit `furlongs`"),
            "{e}"
        );
        let (_d, p) = csv("time_s,Ref Disp (furlongs)\n0,0\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.csv: column `Ref Disp (furlongs)`: unknown unit `furlongs`"),
            "{e}"
        );
        let (_d, p) = csv("time_s,x\n0,0\n0.0009765625,0\n0.001953125,0\n0.0009765625,0\n0.0029296875,0\n0.00390625,0\n0.0048828125,0\n");
        let t = read_columns(&p, &["time_s"], &[]).unwrap();
        let e = t.time_base("time_s").unwrap_err().to_string();
        assert!(
            e.contains("row 4 (line 5)") && e.contains("does not increase"),
            "{e}"
        );
        let (_d, p) = csv("time_s,x\n0,0\n0.001,0\n0.003,0\n0.004,0\n0.005,0\n");
        let e = read_columns(&p, &["time_s"], &[])
            .unwrap()
            .time_base("time_s")
            .unwrap_err()
            .to_string();
        assert!(e.contains("row 3") && e.contains("1 row(s) missing"), "{e}");
        let (_d, p) = csv("time_s,x\n");
        let e = read_columns(&p, &["time_s"], &[]).unwrap_err();
        assert!(
            matches!(e, TableError::Empty { .. }) && e.to_string().contains("no data rows"),
            "{e}"
        );
        let (_d, p) = csv("");
        let e = read_columns(&p, &["time_s"], &[]).unwrap_err();
        assert!(
            e.to_string()
                .ends_with("the file is empty (no header, no rows)"),
            "{e}"
        );
        let e = read_columns(Path::new("/nonexistent/t.csv"), &["time_s"], &[]).unwrap_err();
        assert!(
            e.is_input() && e.to_string() == "/nonexistent/t.csv: not found",
            "{e}"
        );
    }

    #[test]
    fn semicolons_tabs_and_decimal_commas_are_read() {
        for (sep, comma) in [(";", true), ("\t", true), (";", false)] {
            let num = |x: &str| {
                if comma {
                    x.replace('.', ",")
                } else {
                    x.to_string()
                }
            };
            let text = format!(
                "time_s{sep}disp_m\n0{sep}{}\n{}{sep}{}\n",
                num("1.5"),
                num("0.001"),
                num("-2.25")
            );
            let (_d, p) = csv(&text);
            let t = read_columns(&p, &["time_s", "disp_m"], &[]).unwrap();
            assert_eq!(t.column("disp_m").unwrap(), &[1.5, -2.25]);
            assert_eq!(t.column("time_s").unwrap(), &[0.0, 0.001]);
            assert!(
                t.notes[0].contains(if sep == ";" { "semicolon" } else { "tab" }),
                "{:?}",
                t.notes
            );
            assert_eq!(t.notes.len() == 2, comma, "{:?}", t.notes);
        }
    }

    #[test]
    fn parquet_round_trip_with_metadata() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x.parquet");
        write_parquet(
            &p,
            &[("time_s", &[0.0, 0.5]), ("disp_m", &[1.0, 2.0])],
            &[("k".into(), "v".into())],
        )
        .unwrap();
        assert!(!d.path().join("x.parquet.tmp").exists());
        let t = read_columns(&p, &["time_s", "disp_m"], &["absent"]).unwrap();
        assert_eq!(t.column("disp_m").unwrap(), &[1.0, 2.0]);
        assert_eq!(t.time_base("time_s").unwrap().rate_hz, 2.0);
    }
}
