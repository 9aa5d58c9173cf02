//! Numeric tables in and out: CSV (header row) and Parquet readers with the error behaviour of
//! FORMATS.md (missing column, NaN or empty cell, non-monotonic or non-uniform time, zero rows,
//! a header with other units: each names the file, the column and the row), and an atomic
//! Parquet writer (temp file + rename; an interrupted write leaves no file that looks complete).

use arrow_array::{Array, ArrayRef, Float32Array, Float64Array, Int32Array, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A problem with a data file.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("{file}: cannot read: {source}")]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{file}: not a readable {kind} file: {message}")]
    Format { file: PathBuf, kind: &'static str, message: String },
    #[error("{file}: required column `{column}` is missing{hint}")]
    MissingColumn { file: PathBuf, column: String, hint: String },
    #[error("{file}: column `{column}`, row {row}{line}: {message}")]
    BadCell { file: PathBuf, column: String, row: usize, line: String, message: String },
    #[error("{file}: the file has no data rows")]
    Empty { file: PathBuf },
    #[error("{file}: column `{column}`, row {row}{line}: {message}")]
    BadTime { file: PathBuf, column: String, row: usize, line: String, message: String },
}

impl TableError {
    /// Whether the error is the user's input (exit code 2) rather than the system's.
    pub fn is_input(&self) -> bool {
        !matches!(self, TableError::Io { .. })
    }
}

/// Named f64 columns read from one file.
#[derive(Debug, Clone)]
pub struct NumTable {
    pub file: PathBuf,
    pub names: Vec<String>,
    pub columns: Vec<Vec<f64>>,
    csv: bool,
}

impl NumTable {
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names.iter().position(|n| n == name).map(|i| self.columns[i].as_slice())
    }
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }
    fn line(&self, row: usize) -> String {
        if self.csv { format!(" (line {})", row + 1) } else { String::new() }
    }

    /// Checks that `column` is a time column: strictly increasing and uniform (to 1e-6 relative
    /// of the step, or 1e-9 s). Returns the step.
    pub fn check_time(&self, column: &str) -> Result<f64, TableError> {
        let t = self.column(column).expect("time column was read");
        let bad = |row: usize, message: String| TableError::BadTime {
            file: self.file.clone(),
            column: column.to_string(),
            row,
            line: self.line(row),
            message,
        };
        if t.len() < 2 {
            return Err(bad(1, "need at least two samples".into()));
        }
        for i in 1..t.len() {
            if t[i] <= t[i - 1] {
                return Err(bad(i + 1, format!("time {} s does not increase (previous row {} s)", t[i], t[i - 1])));
            }
        }
        let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
        for i in 1..t.len() {
            let d = t[i] - t[i - 1];
            if (d - dt).abs() > (1e-6 * dt).max(1e-9) {
                return Err(bad(i + 1, format!("non-uniform time step {d:.6e} s (the file's mean step is {dt:.6e} s)")));
            }
        }
        Ok(dt)
    }
}

/// The unit-free stem of a column name (`disp_mm` → `disp`), to spot a header with other units.
fn stem(name: &str) -> &str {
    name.rsplit_once('_').map_or(name, |(s, _)| s)
}

fn missing(file: &Path, column: &str, found: &[String]) -> TableError {
    let other_units: Vec<&String> = found.iter().filter(|f| stem(f) == stem(column) && *f != column).collect();
    let hint = if !other_units.is_empty() {
        format!(" (found {}: other units? vshake reads SI columns named as in FORMATS.md)", other_units.iter().map(|s| format!("`{s}`")).collect::<Vec<_>>().join(", "))
    } else {
        format!(" (columns present: {})", found.join(", "))
    };
    TableError::MissingColumn { file: file.to_path_buf(), column: column.to_string(), hint }
}

/// The column names of a CSV (header row) or Parquet file.
pub fn column_names(path: &Path) -> Result<Vec<String>, TableError> {
    let file = path.to_path_buf();
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq")) {
        let b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| TableError::Format { file, kind: "Parquet", message: e.to_string() })?;
        Ok(b.schema().fields().iter().map(|f| f.name().clone()).collect())
    } else {
        let mut rdr = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(f);
        let h = rdr.headers().map_err(|e| TableError::Format { file, kind: "CSV", message: e.to_string() })?;
        Ok(h.iter().map(str::to_string).collect())
    }
}

/// Reads the `wanted` columns (all required) plus any of `optional` that are present. Every
/// cell must be a finite number (measured data: a NaN is an error naming column and row).
pub fn read_columns(path: &Path, wanted: &[&str], optional: &[&str]) -> Result<NumTable, TableError> {
    read_columns_impl(path, wanted, optional, false)
}

/// Reads the `wanted` columns of a Parquet results table, where NaN marks a metric of a failed
/// run (nulls are still errors).
pub fn read_columns_allow_nan(path: &Path, wanted: &[&str]) -> Result<NumTable, TableError> {
    read_columns_impl(path, wanted, &[], true)
}

fn read_columns_impl(path: &Path, wanted: &[&str], optional: &[&str], allow_nan: bool) -> Result<NumTable, TableError> {
    let is_parquet = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq"));
    let table = if is_parquet { read_parquet(path, wanted, optional, allow_nan)? } else { read_csv(path, wanted, optional)? };
    if table.rows() == 0 {
        return Err(TableError::Empty { file: path.to_path_buf() });
    }
    Ok(table)
}

fn read_csv(path: &Path, wanted: &[&str], optional: &[&str]) -> Result<NumTable, TableError> {
    let file = path.to_path_buf();
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(f);
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| TableError::Format { file: file.clone(), kind: "CSV", message: e.to_string() })?
        .iter()
        .map(str::to_string)
        .collect();
    let mut idx = Vec::new();
    for w in wanted {
        match headers.iter().position(|h| h == w) {
            Some(i) => idx.push((w.to_string(), i)),
            None => return Err(missing(path, w, &headers)),
        }
    }
    for o in optional {
        if let Some(i) = headers.iter().position(|h| h == o) {
            idx.push((o.to_string(), i));
        }
    }
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); idx.len()];
    for (r, rec) in rdr.records().enumerate() {
        let row = r + 1;
        let rec = rec.map_err(|e| TableError::Format { file: file.clone(), kind: "CSV", message: format!("row {row} (line {}): {e}", row + 1) })?;
        for ((name, i), col) in idx.iter().zip(columns.iter_mut()) {
            let cell = rec.get(*i).unwrap_or("");
            let bad = |message: String| TableError::BadCell { file: file.clone(), column: name.clone(), row, line: format!(" (line {})", row + 1), message };
            if cell.is_empty() {
                return Err(bad("empty cell".into()));
            }
            let v: f64 = cell.parse().map_err(|_| bad(format!("{cell:?} is not a number")))?;
            if !v.is_finite() {
                return Err(bad(format!("{cell} is not a finite number")));
            }
            col.push(v);
        }
    }
    Ok(NumTable { file, names: idx.into_iter().map(|(n, _)| n).collect(), columns, csv: true })
}

fn read_parquet(path: &Path, wanted: &[&str], optional: &[&str], allow_nan: bool) -> Result<NumTable, TableError> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format { file: file.clone(), kind: "Parquet", message: e.to_string() };
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let found: Vec<String> = builder.schema().fields().iter().map(|f| f.name().clone()).collect();
    let mut names: Vec<String> = Vec::new();
    for w in wanted {
        if !found.iter().any(|f| f == w) {
            return Err(missing(path, w, &found));
        }
        names.push(w.to_string());
    }
    names.extend(optional.iter().filter(|o| found.iter().any(|f| f == *o)).map(|s| s.to_string()));
    let reader = builder.build().map_err(|e| fmt(&e))?;
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for batch in reader {
        let batch = batch.map_err(|e| fmt(&e))?;
        for (name, col) in names.iter().zip(columns.iter_mut()) {
            let arr = batch.column_by_name(name).expect("column in schema");
            let base = col.len();
            let bad = |row: usize, message: String| TableError::BadCell { file: file.clone(), column: name.clone(), row, line: String::new(), message };
            let get: Box<dyn Fn(usize) -> f64> = match arr.data_type() {
                DataType::Float64 => { let a = arr.as_any().downcast_ref::<Float64Array>().unwrap().clone(); Box::new(move |i| a.value(i)) }
                DataType::Float32 => { let a = arr.as_any().downcast_ref::<Float32Array>().unwrap().clone(); Box::new(move |i| a.value(i) as f64) }
                DataType::Int64 => { let a = arr.as_any().downcast_ref::<Int64Array>().unwrap().clone(); Box::new(move |i| a.value(i) as f64) }
                DataType::Int32 => { let a = arr.as_any().downcast_ref::<Int32Array>().unwrap().clone(); Box::new(move |i| a.value(i) as f64) }
                DataType::UInt64 => { let a = arr.as_any().downcast_ref::<arrow_array::UInt64Array>().unwrap().clone(); Box::new(move |i| a.value(i) as f64) }
                DataType::UInt32 => { let a = arr.as_any().downcast_ref::<arrow_array::UInt32Array>().unwrap().clone(); Box::new(move |i| a.value(i) as f64) }
                other => return Err(bad(base + 1, format!("column type {other} is not numeric"))),
            };
            for i in 0..arr.len() {
                let row = base + i + 1;
                if arr.is_null(i) {
                    return Err(bad(row, "empty (null) cell".into()));
                }
                let v = get(i);
                if !(v.is_finite() || allow_nan && v.is_nan()) {
                    return Err(bad(row, format!("{v} is not a finite number")));
                }
                col.push(v);
            }
        }
    }
    Ok(NumTable { file, names, columns, csv: false })
}

/// A file being written: `path.tmp` until [`AtomicFile::commit`] renames it into place. Dropped
/// without commit, the temp file is removed.
pub struct AtomicFile {
    pub path: PathBuf,
    pub tmp: PathBuf,
    committed: bool,
}

impl AtomicFile {
    pub fn new(path: &Path) -> Self {
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        AtomicFile { path: path.to_path_buf(), tmp: PathBuf::from(tmp), committed: false }
    }
    pub fn commit(mut self) -> std::io::Result<()> {
        std::fs::rename(&self.tmp, &self.path)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed {
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
        }
    }
}

/// Encoded bytes of a row group in progress at which it is flushed (also at 16 384 rows).
const ROW_GROUP_BYTES: usize = 4 << 20;

/// A Parquet file written batch by batch (zstd, bounded row groups), atomically: it appears
/// under its name only when [`ParquetStream::finish`] succeeds.
pub struct ParquetStream {
    file: AtomicFile,
    writer: ArrowWriter<File>,
    schema: Arc<Schema>,
}

impl ParquetStream {
    /// Opens `path.tmp` for a table with the columns of `template` (names and types).
    pub fn create(path: &Path, template: &[(String, Column)], metadata: &[(String, String)]) -> anyhow::Result<Self> {
        Self::create_with_fields(path, template.iter().map(|(n, c)| c.field(n)).collect(), metadata)
    }

    /// Opens `path.tmp` for a table with these Arrow fields.
    pub fn create_with_fields(path: &Path, fields: Vec<Field>, metadata: &[(String, String)]) -> anyhow::Result<Self> {
        use anyhow::Context;
        // The metadata goes into the file's key-value block (DuckDB, polars, pandas) and into the
        // Arrow schema too, so `pyarrow.parquet.read_table(path).schema.metadata` shows it.
        let schema = Arc::new(Schema::new(fields).with_metadata(metadata.iter().cloned().collect::<std::collections::HashMap<String, String>>()));
        // Dictionary encoding only for string columns: float columns of simulation results are
        // nearly all distinct values, and a dictionary per column would hold up to a page each in
        // memory for nothing.
        let mut props = WriterProperties::builder().set_dictionary_enabled(false);
        for f in schema.fields() {
            if f.data_type() == &DataType::Utf8 {
                props = props.set_column_dictionary_enabled(f.name().as_str().into(), true);
            }
        }
        let props = props
            .set_compression(Compression::ZSTD(ZstdLevel::default()))
            .set_max_row_group_row_count(Some(16_384))
            .set_key_value_metadata(Some(metadata.iter().map(|(k, v)| KeyValue::new(k.clone(), v.clone())).collect()))
            .build();
        let file = AtomicFile::new(path);
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let f = File::create(&file.tmp).with_context(|| format!("cannot create {}", file.tmp.display()))?;
        let writer = ArrowWriter::try_new(f, schema.clone(), Some(props))?;
        Ok(ParquetStream { file, writer, schema })
    }

    /// Appends a record batch whose columns match this table's fields.
    pub fn write_batch(&mut self, batch: &RecordBatch) -> anyhow::Result<()> {
        let batch = RecordBatch::try_new(self.schema.clone(), batch.columns().to_vec())?;
        self.writer.write(&batch)?;
        if self.writer.in_progress_size() > ROW_GROUP_BYTES {
            self.writer.flush()?;
        }
        Ok(())
    }

    /// Appends rows (columns in the template's order).
    pub fn write(&mut self, columns: Vec<Column>) -> anyhow::Result<()> {
        let batch = RecordBatch::try_new(self.schema.clone(), columns.into_iter().map(Column::array).collect())?;
        self.writer.write(&batch)?;
        // Bound the buffered row group by bytes, so memory stays flat however many rows follow.
        if self.writer.in_progress_size() > ROW_GROUP_BYTES {
            self.writer.flush()?;
        }
        Ok(())
    }

    /// Closes the file and moves it into place.
    pub fn finish(self) -> anyhow::Result<()> {
        use anyhow::Context;
        self.writer.close()?;
        let path = self.file.path.clone();
        self.file.commit().with_context(|| format!("cannot move the finished file to {}", path.display()))?;
        Ok(())
    }
}

/// Writes f64 columns as one Parquet file (zstd) with key-value metadata, atomically.
pub fn write_parquet(path: &Path, columns: &[(&str, &[f64])], metadata: &[(String, String)]) -> anyhow::Result<()> {
    let cols: Vec<(String, Column)> = columns.iter().map(|(n, v)| (n.to_string(), Column::F64(v.to_vec()))).collect();
    write_table(path, cols, metadata)
}

/// Writes typed columns as one Parquet file, atomically.
pub fn write_table(path: &Path, columns: Vec<(String, Column)>, metadata: &[(String, String)]) -> anyhow::Result<()> {
    let mut s = ParquetStream::create(path, &columns, metadata)?;
    s.write(columns.into_iter().map(|(_, c)| c).collect())?;
    s.finish()
}

/// The key-value metadata of a Parquet file.
pub fn parquet_metadata(path: &Path) -> Result<Vec<(String, String)>, TableError> {
    let file = path.to_path_buf();
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| TableError::Format { file, kind: "Parquet", message: e.to_string() })?;
    Ok(builder
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .map(|kv| kv.iter().map(|k| (k.key.clone(), k.value.clone().unwrap_or_default())).collect())
        .unwrap_or_default())
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
    fn nan_and_empty_cells_name_column_and_row() {
        let (_d, p) = csv("time_s,ref_disp_m\n0,0\n0.001,NaN\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[]).unwrap_err().to_string();
        assert!(e.contains("`ref_disp_m`, row 2 (line 3)") && e.contains("NaN"), "{e}");
        let (_d, p) = csv("time_s,ref_disp_m\n0,0\n0.001,\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[]).unwrap_err().to_string();
        assert!(e.contains("row 2") && e.contains("empty cell"), "{e}");
    }

    #[test]
    fn other_units_and_bad_time_are_named() {
        let (_d, p) = csv("time_s,ref_disp_mm\n0,0\n");
        let e = read_columns(&p, &["time_s", "ref_disp_m"], &[]).unwrap_err().to_string();
        assert!(e.contains("`ref_disp_m` is missing") && e.contains("`ref_disp_mm`: other units?"), "{e}");
        let (_d, p) = csv("time_s,x\n0,0\n0.001,0\n0.0005,0\n");
        let t = read_columns(&p, &["time_s"], &[]).unwrap();
        let e = t.check_time("time_s").unwrap_err().to_string();
        assert!(e.contains("row 3") && e.contains("does not increase"), "{e}");
        let (_d, p) = csv("time_s,x\n0,0\n0.001,0\n0.003,0\n0.004,0\n");
        let e = read_columns(&p, &["time_s"], &[]).unwrap().check_time("time_s").unwrap_err().to_string();
        assert!(e.contains("non-uniform"), "{e}");
        let (_d, p) = csv("time_s,x\n");
        assert!(matches!(read_columns(&p, &["time_s"], &[]), Err(TableError::Empty { .. })));
    }

    #[test]
    fn parquet_round_trip_with_metadata() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x.parquet");
        write_parquet(&p, &[("time_s", &[0.0, 0.5]), ("disp_m", &[1.0, 2.0])], &[("k".into(), "v".into())]).unwrap();
        assert!(!d.path().join("x.parquet.tmp").exists());
        let t = read_columns(&p, &["time_s", "disp_m"], &["absent"]).unwrap();
        assert_eq!(t.column("disp_m").unwrap(), &[1.0, 2.0]);
        assert_eq!(t.check_time("time_s").unwrap(), 0.5);
    }
}

/// The string column `column` of a Parquet file (null cells as empty strings).
pub fn read_strings(path: &Path, column: &str) -> Result<Vec<String>, TableError> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format { file: file.clone(), kind: "Parquet", message: e.to_string() };
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let found: Vec<String> = builder.schema().fields().iter().map(|f| f.name().clone()).collect();
    if !found.iter().any(|f| f == column) {
        return Err(missing(path, column, &found));
    }
    let mut out = Vec::new();
    for batch in builder.build().map_err(|e| fmt(&e))? {
        let batch = batch.map_err(|e| fmt(&e))?;
        let arr = batch.column_by_name(column).expect("column in schema");
        let s = arr.as_any().downcast_ref::<arrow_array::StringArray>().ok_or_else(|| TableError::BadCell {
            file: file.clone(),
            column: column.to_string(),
            row: out.len() + 1,
            line: String::new(),
            message: format!("column type {} is not a string", arr.data_type()),
        })?;
        out.extend((0..s.len()).map(|i| if s.is_null(i) { String::new() } else { s.value(i).to_string() }));
    }
    Ok(out)
}

/// The Arrow fields of a Parquet file, and a reader of its record batches.
pub fn parquet_batches(path: &Path) -> Result<(Vec<Field>, parquet::arrow::arrow_reader::ParquetRecordBatchReader), TableError> {
    let file = path.to_path_buf();
    let fmt = |e: &dyn std::fmt::Display| TableError::Format { file: file.clone(), kind: "Parquet", message: e.to_string() };
    let f = File::open(path).map_err(|e| TableError::Io { file: file.clone(), source: e })?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| fmt(&e))?;
    let fields = builder.schema().fields().iter().map(|f| f.as_ref().clone()).collect();
    Ok((fields, builder.build().map_err(|e| fmt(&e))?))
}
