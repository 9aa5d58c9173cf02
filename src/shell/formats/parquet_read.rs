//! Parquet tables read back: rows, metadata, typed columns and record batches.

use arrow_array::{Array, ArrayRef, Float64Array};
use arrow_schema::Field;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::path::Path;

use crate::shell::formats::input::*;
use crate::shell::formats::measured_files::missing;

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
