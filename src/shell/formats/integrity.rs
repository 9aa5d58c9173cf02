//! Row-group checksums: every Parquet file vshake streams carries, in its key-value metadata
//! (`vshake.row_group_crc32`), the CRC-32 of each row group's bytes as written (the column chunks,
//! from the first to the end of the last), and so does each checkpoint footer of a run being
//! written. `study run --resume` and `study merge` check them before they use a row: a byte changed
//! on the disk or in a copy is refused, naming the file and the rows, instead of being carried into
//! a file marked complete.

use crate::shell::formats::meta::Key;
use crate::shell::BadInput;
use parquet::file::metadata::{KeyValue, ParquetMetaData, RowGroupMetaData};
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::Path;

/// A running CRC-32 (IEEE 802.3, as zlib and PNG): crc32fast's.
type Crc = crc32fast::Hasher;

/// The CRC-32 of `bytes`.
#[cfg(test)]
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = Crc::new();
    c.update(bytes);
    c.finalize()
}

/// The bytes a row group occupies in its file: from the first column chunk's start to the last
/// one's end; None where the footer says something impossible (a negative offset or size).
pub(crate) fn byte_range(group: &RowGroupMetaData) -> Option<(u64, u64)> {
    let mut range: Option<(u64, u64)> = None;
    for c in group.columns() {
        let start = c.dictionary_page_offset().unwrap_or(c.data_page_offset());
        let (start, len) = (
            u64::try_from(start).ok()?,
            u64::try_from(c.compressed_size()).ok()?,
        );
        let end = start.checked_add(len)?;
        range = Some(range.map_or((start, end), |(a, b)| (a.min(start), b.max(end))));
    }
    range
}

/// The CRC-32 of a row group's bytes in `file` (None where they are not all there).
pub(crate) fn row_group_sum(file: &File, group: &RowGroupMetaData) -> Option<u32> {
    let (start, end) = byte_range(group)?;
    let mut crc = Crc::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut at = start;
    while at < end {
        let n = ((end - at) as usize).min(buf.len());
        file.read_exact_at(&mut buf[..n], at).ok()?;
        crc.update(&buf[..n]);
        at += n as u64;
    }
    Some(crc.finalize())
}

/// The metadata value of a list of row-group checksums: `crc32:` and one 8-digit hexadecimal
/// number per row group, in order, comma-separated.
pub(crate) fn encode(sums: &[u32]) -> String {
    let list: Vec<String> = sums.iter().map(|s| format!("{s:08x}")).collect();
    format!("crc32:{}", list.join(","))
}

/// The checksums a metadata value lists (None where it is not such a list).
fn decode(value: &str) -> Option<Vec<u32>> {
    let list = value.strip_prefix("crc32:")?;
    if list.is_empty() {
        return Some(Vec::new());
    }
    list.split(',')
        .map(|s| u32::from_str_radix(s.trim(), 16).ok())
        .collect()
}

/// Whether a metadata key is one of the checksums (not covered by [`metadata_sum`]).
fn is_checksum(key: &str) -> bool {
    key == Key::RowGroupCrc32.as_str() || key == Key::MetadataCrc32.as_str()
}

/// The CRC-32 of the `vshake.*` key-value pairs of a file but the checksums, sorted, each as
/// `key=value` and a newline: what a resume or a merge takes from the file (its study, seed,
/// shard), so that a byte changed there is refused like one changed in the rows. Sorted, so that
/// files with the same metadata have the same sum whatever order their writer gave the keys (a
/// merged table and the single run it equals).
pub(crate) fn metadata_sum(kv: &[KeyValue]) -> u32 {
    let mut pairs: Vec<(&str, &str)> = kv
        .iter()
        .filter(|e| e.key.starts_with("vshake.") && !is_checksum(&e.key))
        .map(|e| (e.key.as_str(), e.value.as_deref().unwrap_or("")))
        .collect();
    pairs.sort_unstable();
    let mut crc = Crc::new();
    for (key, value) in pairs {
        crc.update(key.as_bytes());
        crc.update(b"=");
        crc.update(value.as_bytes());
        crc.update(b"\n");
    }
    crc.finalize()
}

/// The checksum entries of a file whose other metadata is `kv` and whose row groups' sums are
/// `sums`: the row groups' list ([`encode`]) and the metadata's ([`metadata_sum`]).
pub(crate) fn checksum_entries(kv: &[KeyValue], sums: &[u32]) -> [KeyValue; 2] {
    [
        KeyValue::new(Key::RowGroupCrc32.as_str().to_string(), encode(sums)),
        KeyValue::new(
            Key::MetadataCrc32.as_str().to_string(),
            format!("crc32:{:08x}", metadata_sum(kv)),
        ),
    ]
}

/// Checks the metadata of `meta` against its checksum, where it has one.
fn verify_metadata(meta: &ParquetMetaData, name: &Path) -> anyhow::Result<()> {
    let kv = meta
        .file_metadata()
        .key_value_metadata()
        .map_or(&[][..], |kv| kv);
    let Some(stored) = kv
        .iter()
        .rev()
        .find(|k| k.key == Key::MetadataCrc32.as_str())
    else {
        return Ok(());
    };
    let want = format!("crc32:{:08x}", metadata_sum(kv));
    if stored.value.as_deref() != Some(want.as_str()) {
        return Err(BadInput(format!(
            "{}: its metadata (the study, seed and shard its rows were made for) does not match its checksum: the file was damaged or changed after it was written; it was not used, and nothing was changed (restore it, or run its rows again)",
            name.display()
        ))
        .into());
    }
    Ok(())
}

/// Checks every row group of `meta` (the footer of `data`, or of its checkpoint) against the
/// checksums it lists; `name` is the file the message names. A file without checksums (written by
/// an older vshake) passes. A mismatch is bad input (exit 2), naming the file and the rows.
pub(crate) fn verify(data: &File, meta: &ParquetMetaData, name: &Path) -> anyhow::Result<()> {
    verify_metadata(meta, name)?;
    let value = meta
        .file_metadata()
        .key_value_metadata()
        .and_then(|kv| {
            kv.iter()
                .rev()
                .find(|k| k.key == Key::RowGroupCrc32.as_str())
        })
        .and_then(|k| k.value.clone());
    let Some(value) = value else {
        return Ok(());
    };
    let groups = meta.row_groups();
    let sums = decode(&value).filter(|s| s.len() == groups.len()).ok_or_else(|| {
        BadInput(format!(
            "{}: its row-group checksums ({}) do not match its {} row groups: the file was changed after it was written; it was not used",
            name.display(),
            Key::RowGroupCrc32,
            groups.len()
        ))
    })?;
    let mut first_row = 0u64;
    for (i, (g, want)) in groups.iter().zip(sums).enumerate() {
        let rows = g.num_rows().max(0) as u64;
        if row_group_sum(data, g) != Some(want) {
            return Err(BadInput(format!(
                "{}: row group {i} (rows {first_row}..{}) does not match its checksum: the file was damaged or changed after it was written; it was not used, and nothing was changed (restore it, or run its rows again)",
                name.display(),
                first_row + rows
            ))
            .into());
        }
        first_row += rows;
    }
    Ok(())
}

/// Checks the row groups of the Parquet file at `path` against its checksums ([`verify`]).
pub(crate) fn verify_file(path: &Path) -> anyhow::Result<()> {
    use parquet::file::metadata::ParquetMetaDataReader;
    let f =
        File::open(path).map_err(|e| BadInput(format!("{}: cannot read: {e}", path.display())))?;
    let meta = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        ParquetMetaDataReader::new().parse_and_finish(&f)
    }))
    .map_err(|_| {
        BadInput(format!(
            "{}: not a readable Parquet file (its footer is corrupt)",
            path.display()
        ))
    })?
    .map_err(|e| {
        BadInput(format!(
            "{}: not a readable Parquet file: {e}",
            path.display()
        ))
    })?;
    verify(&f, &meta, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_is_the_standard_one() {
        // The check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn checksum_lists_round_trip() {
        let s = [0u32, 0xCBF4_3926, 7];
        assert_eq!(encode(&s), "crc32:00000000,cbf43926,00000007");
        assert_eq!(decode(&encode(&s)), Some(s.to_vec()));
        assert_eq!(decode(&encode(&[])), Some(vec![]));
        assert_eq!(decode("md5:00"), None);
        assert_eq!(decode("crc32:zz"), None);
    }
}
