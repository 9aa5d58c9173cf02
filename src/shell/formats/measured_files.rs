//! Measured files read as numeric columns: CSV (its layout, separator, preamble, header and units
//! row found from its lines; decimal commas), MATLAB MAT-files and Parquet, each column found by
//! name or position and converted to SI, every bad cell named by column and row. The time base and
//! the values are checked one floor down ([`crate::orchestration::measured::aligned`]).

use crate::orchestration::measured::campaign::Mapped;
use crate::shell::formats::headers;
use crate::shell::formats::matlab;
use arrow_array::{Array, ArrayRef, Float32Array, Float64Array, Int32Array, Int64Array};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::path::Path;

pub use crate::orchestration::measured::aligned::NumTable;
use crate::shell::formats::input::*;

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

pub(crate) fn missing(file: &Path, column: &str, found: &[String]) -> TableError {
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
    } else if crate::kernel::channels::channel(column).is_some() {
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
        let lay = headers::layout(text);
        let lines: Vec<&str> = text.lines().collect();
        Ok(csv_header(&lines, &lay).0)
    }
}

/// Marks a table error as bad input (exit 2) when it is the user's.
pub(crate) fn input_if_user(e: TableError) -> anyhow::Error {
    if e.is_input() {
        crate::shell::BadInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// A record's time and value columns: from a CSV or Parquet file, or a PEER `.AT2` file.
pub(crate) fn read_record(
    path: &Path,
    column: &str,
    time_column: &str,
) -> Result<NumTable, TableError> {
    if crate::kernel::channels::is_at2(path) {
        crate::shell::formats::at2::read(path)
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
    map: &[(String, Mapped)],
) -> Result<(NumTable, Vec<TableError>), TableError> {
    let (table, bad) = read_columns_lenient_impl(path, (wanted, optional, map), false)?;
    Ok((table, bad.errors()))
}

type Wanted<'a> = (&'a [&'a str], &'a [&'a str], &'a [(String, Mapped)]);

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
/// ([`headers::resolve`]), converted to SI.
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
    let lay = headers::layout(text);
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
    idx: &[headers::Resolved],
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
fn csv_header(lines: &[&str], lay: &headers::Layout) -> (Vec<String>, Option<Vec<String>>) {
    let headers = match lay.header {
        Some(h) => headers::fields(lines[h], lay.sep),
        None => {
            let n = lines
                .get(lay.data)
                .map_or(0, |l| headers::fields(l, lay.sep).len());
            (1..=n).map(|k| format!("column {k}")).collect()
        }
    };
    let units = lay.units.map(|u| {
        (headers::fields(lines[u], lay.sep).iter())
            .map(|c| headers::strip_brackets(c).to_string())
            .collect()
    });
    (headers, units)
}

/// One note for the columns read under another name or unit than vshake's.
fn columns_note(idx: &[headers::Resolved]) -> Option<String> {
    let notes: Vec<&str> = idx.iter().filter_map(|r| r.note.as_deref()).collect();
    (!notes.is_empty()).then(|| notes.join("; "))
}

/// What the layout shows that a plain CSV file would not.
fn layout_notes(lay: &headers::Layout) -> Vec<String> {
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
) -> Result<Vec<headers::Resolved>, TableError> {
    headers::resolve(headers, units, wanted, optional, map).map_err(|problems| {
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
    p: headers::ColumnProblem,
) -> TableError {
    match p {
        headers::ColumnProblem::Missing(c) if !has_header => TableError::MissingColumn {
            file: path.to_path_buf(),
            column: c,
            hint: " (the file has no header row, its first line is numbers: add a header naming the columns, or give each channel's position in the campaign's `columns` table, e.g. columns = { time = { column = 1, unit = \"s\" } }, docs/formats.md)".into(),
        },
        headers::ColumnProblem::Missing(c) => missing(path, &c, headers),
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
    idx: &[headers::Resolved],
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
    let idx = headers::resolve(&found, None, wanted, optional, map).map_err(|problems| {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shell::formats::parquet_write::*;
    use std::path::PathBuf;

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
