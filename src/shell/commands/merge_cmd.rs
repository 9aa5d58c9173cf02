//! `study merge`: join the shard files of a sharded study into one table equal to the unsharded
//! run, refusing missing, duplicate or mismatched shards.

use crate::shell::cli::MergeArgs;
use crate::shell::formats::integrity;
use crate::shell::formats::measured_files;
use crate::shell::formats::meta::{self, Key, SHARD_KEYS};
use crate::shell::formats::parquet_read;
use crate::shell::formats::parquet_write::ParquetStream;
use crate::shell::job::outputs::{check_output, check_replaceable, OutputLock};
use crate::shell::BadInput;
use anyhow::Context;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// What must agree between the shards of one run: metadata key and what to call it.
const SAME: [(Key, &str); 5] = [
    (Key::Seed, "seed"),
    (Key::Version, "vshake version"),
    (Key::SchemaVersion, "results schema version"),
    (Key::ShardCount, "shard count"),
    (Key::Study, "study (the resolved study file)"),
];

struct ShardFile {
    path: PathBuf,
    meta: BTreeMap<String, String>,
    index: usize,
}

fn get(f: &ShardFile, key: Key) -> anyhow::Result<&str> {
    f.meta.get(key.as_str()).map(String::as_str).ok_or_else(|| {
        BadInput(format!(
            "{}: not a shard of `study run --shard I/N` (no {key} in its metadata)",
            f.path.display()
        ))
        .into()
    })
}

/// Refuses `f` when it is a shard of another run than `first` ([`SAME`]).
fn same_run(first: &ShardFile, f: &ShardFile) -> anyhow::Result<()> {
    for (key, what) in SAME {
        let (a, b) = (get(first, key)?, get(f, key)?);
        if a != b {
            let show = |v: &str| {
                if v.len() > 40 {
                    format!(
                        "{}…",
                        &v[..v.char_indices().nth(40).map_or(v.len(), |(i, _)| i)]
                    )
                } else {
                    v.to_string()
                }
            };
            return Err(BadInput(format!(
                "{}: a shard of another run: its {what} ({}) differs from {}'s ({})",
                f.path.display(),
                show(b),
                first.path.display(),
                show(a)
            ))
            .into());
        }
    }
    Ok(())
}

/// Reads and checks the shards of `dir` (every .parquet file but `skip`, and but merged tables,
/// named in `skipped`), in shard order.
fn shards(dir: &Path, skip: &Path, skipped: &mut Vec<PathBuf>) -> anyhow::Result<Vec<ShardFile>> {
    let files = shard_paths(dir, skip)?;
    let (mut list, unfinished) = read_shards(files, skipped)?;
    if list.is_empty() {
        return Err(BadInput(format!(
            "{}: no complete shard\n{}",
            dir.display(),
            unfinished.join("\n")
        ))
        .into());
    }
    let first = &list[0];
    for f in &list[1..] {
        same_run(first, f)?;
    }
    let count: usize = get(first, Key::ShardCount)?
        .parse()
        .map_err(|_| BadInput(format!("{}: bad {}", first.path.display(), Key::ShardCount)))?;
    let by_index = index_shards(&list, count)?;
    check_missing(dir, &by_index, count, &unfinished)?;
    // The slices must tile the design in order.
    check_tiling(&by_index, count)?;
    list.sort_by_key(|f| f.index);
    Ok(list)
}

/// The .parquet files of `dir` but `skip`, sorted by path; none is an error.
fn shard_paths(dir: &Path, skip: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| BadInput(format!("{}: cannot read the folder: {e}", dir.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "parquet")
                && std::fs::canonicalize(p).ok() != std::fs::canonicalize(skip).ok()
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(BadInput(format!("{}: no .parquet shard files", dir.display())).into());
    }
    Ok(files)
}

/// The shards' metadata and indices: the complete ones, and a line on each incomplete one. A
/// results table that is not a shard (a merge written into the shards' folder) is left out, and
/// its path put in `skipped`.
fn read_shards(
    files: Vec<PathBuf>,
    skipped: &mut Vec<PathBuf>,
) -> anyhow::Result<(Vec<ShardFile>, Vec<String>)> {
    let mut list = Vec::new();
    let mut unfinished = Vec::new();
    for path in files {
        let pairs = parquet_read::parquet_metadata(&path).map_err(measured_files::input_if_user)?;
        if meta::is(&pairs, meta::Kind::StudyResults)
            && meta::get(&pairs, Key::ShardIndex).is_none()
        {
            skipped.push(path);
            continue;
        }
        let done = meta::incomplete(&pairs);
        let meta: BTreeMap<String, String> = pairs.into_iter().collect();
        let mut f = ShardFile {
            path,
            meta,
            index: 0,
        };
        f.index = get(&f, Key::ShardIndex)?
            .parse()
            .map_err(|_| BadInput(format!("{}: bad {}", f.path.display(), Key::ShardIndex)))?;
        match done {
            // A stopped shard counts as missing: its rows are not all there.
            Some((rows, total)) => unfinished.push(format!(
                "{}: shard {} is incomplete ({rows} of {total} rows; continue it with `study run --resume {}`)",
                f.path.display(),
                f.index,
                f.path.display()
            )),
            None => list.push(f),
        }
    }
    Ok((list, unfinished))
}

/// The shards by index, each in range and none twice.
fn index_shards(list: &[ShardFile], count: usize) -> anyhow::Result<BTreeMap<usize, &ShardFile>> {
    let mut by_index: BTreeMap<usize, &ShardFile> = BTreeMap::new();
    for f in list {
        if f.index >= count {
            return Err(BadInput(format!(
                "{}: shard {}/{count} is out of range",
                f.path.display(),
                f.index
            ))
            .into());
        }
        if let Some(other) = by_index.insert(f.index, f) {
            return Err(BadInput(format!(
                "shard {}/{count} appears twice: {} and {}",
                f.index,
                other.path.display(),
                f.path.display()
            ))
            .into());
        }
    }
    Ok(by_index)
}

/// Refuses a set of shards that lacks one of the `count`, naming the incomplete ones too.
fn check_missing(
    dir: &Path,
    by_index: &BTreeMap<usize, &ShardFile>,
    count: usize,
    unfinished: &[String],
) -> anyhow::Result<()> {
    let missing: Vec<String> = (0..count)
        .filter(|i| !by_index.contains_key(i))
        .map(|i| format!("{i}/{count}"))
        .collect();
    if !missing.is_empty() {
        let also = unfinished
            .iter()
            .map(|u| format!("\n  {u}"))
            .collect::<String>();
        return Err(BadInput(format!(
            "{}: shard{} {} missing (found {} of {count}: {}){also}",
            dir.display(),
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            by_index.len(),
            by_index
                .keys()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))
        .into());
    }
    Ok(())
}

/// The shards' sample slices, in index order, tile the design from 0.
fn check_tiling(by_index: &BTreeMap<usize, &ShardFile>, count: usize) -> anyhow::Result<()> {
    let mut at = 0usize;
    for f in by_index.values() {
        let s = get(f, Key::ShardSamples)?;
        let (a, b) = s
            .split_once("..")
            .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
            .ok_or_else(|| BadInput(format!("{}: bad {}", f.path.display(), Key::ShardSamples)))?;
        if a != at {
            return Err(BadInput(format!(
                "{}: shard {}/{count} holds samples {a}..{b}, expected to start at {at}",
                f.path.display(),
                f.index
            ))
            .into());
        }
        at = b;
    }
    Ok(())
}

/// The merged file's metadata: what the unsharded run's says (the first shard's, the shard keys
/// gone), naming every backend that computed the shards' rows.
fn merged_metadata(list: &[ShardFile]) -> Vec<(String, String)> {
    let mut meta = meta::carried(&list[0].meta, &SHARD_KEYS);
    let backends = list
        .iter()
        .filter_map(|f| f.meta.get(Key::Backend.as_str()));
    for b in backends.flat_map(|v| meta::items(v)) {
        meta::add_item(&mut meta, Key::Backend, &b);
    }
    meta
}

pub fn run(args: &MergeArgs) -> anyhow::Result<()> {
    let out = args.out.clone().unwrap_or_else(|| {
        let name = args
            .dir
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_else(|| "merged".into());
        args.dir.with_file_name(format!("{name}.parquet"))
    });
    check_output(&out)?;
    let _lock = OutputLock::acquire(&out)?;
    check_replaceable(&out)?;
    let mut skipped = Vec::new();
    let list = shards(&args.dir, &out, &mut skipped)?;
    // Every shard's rows checked against their checksums before one is written.
    for f in &list {
        integrity::verify_file(&f.path)?;
    }
    let first = &list[0];
    let meta = merged_metadata(&list);
    let (fields, _) =
        parquet_read::parquet_batches(&first.path).map_err(measured_files::input_if_user)?;
    let mut stream = ParquetStream::create_with_fields(&out, fields.clone(), &meta)?;
    let mut rows = 0usize;
    for f in &list {
        let (theirs, reader) =
            parquet_read::parquet_batches(&f.path).map_err(measured_files::input_if_user)?;
        let shape = |v: &[arrow_schema::Field]| {
            v.iter()
                .map(|x| (x.name().clone(), x.data_type().clone()))
                .collect::<Vec<_>>()
        };
        if shape(&theirs) != shape(&fields) {
            return Err(BadInput(format!(
                "{}: its columns differ from {}'s",
                f.path.display(),
                first.path.display()
            ))
            .into());
        }
        for batch in reader {
            let batch = batch.with_context(|| format!("reading {}", f.path.display()))?;
            rows += batch.num_rows();
            stream.write_batch(&batch)?;
        }
    }
    let expected: Option<usize> = (|| {
        let samples: usize = first.meta.get(Key::Samples.as_str())?.parse().ok()?;
        let exc = meta::items(first.meta.get(Key::Excitations.as_str())?).len();
        Some(samples * exc)
    })();
    if let Some(e) = expected.filter(|e| *e != rows) {
        return Err(BadInput(format!(
            "{}: the shards hold {rows} rows, the study has {e}",
            args.dir.display()
        ))
        .into());
    }
    stream
        .finish_with(&meta::completion(rows, rows))
        .with_context(|| format!("writing {}", out.display()))?;
    let mut o = std::io::stdout().lock();
    for p in &skipped {
        writeln!(
            o,
            "study merge: skipped {}: a results table, not a shard (no {})",
            p.display(),
            Key::ShardIndex
        )?;
    }
    writeln!(
        o,
        "study merge {}: {} shards, {rows} rows -> {}",
        args.dir.display(),
        list.len(),
        out.display()
    )?;
    Ok(())
}
