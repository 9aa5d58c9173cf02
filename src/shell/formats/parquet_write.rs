//! Tables written: the atomic file (a temp file renamed into place; an interrupted write leaves no
//! file that looks complete) and the streaming, checkpointed Parquet writer with its recovery.

use arrow_array::builder::{Float64Builder, ListBuilder, StringBuilder};
use arrow_array::{ArrayRef, Float64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

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
        crate::shell::formats::input::regular_output(&self.path)?;
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
    /// The CRC-32 of each row group written so far ([`crate::shell::formats::integrity`]).
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
            let sum = crate::shell::formats::integrity::row_group_sum(self.writer.inner(), g)
                .ok_or_else(|| {
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
        kv.extend(crate::shell::formats::integrity::checksum_entries(
            &c.kv, &self.sums,
        ));
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
        let sums = crate::shell::formats::integrity::checksum_entries(&kv, &self.sums);
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
        .map(|g| crate::shell::formats::integrity::byte_range(g).map_or(u64::MAX, |(_, b)| b))
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
    crate::shell::formats::integrity::verify(&data, &meta, tmp)?;
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
