//! Sharded studies (`study run --shard I/N`, `study merge`): the merged shards equal the
//! unsharded run, and merging refuses a missing, a duplicated or a foreign shard.

use std::path::{Path, PathBuf};
mod common;
use common::content;
use common::study;

fn smoke() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/smoke.toml")
}

fn ok(args: &[&str]) -> String {
    let (code, out, err) = study(args);
    assert_eq!(code, 0, "{args:?}: {out}{err}");
    out
}

/// Acceptance 3: for N = 1, 3, 4, 7 the merged shards have the unsharded run's columns, bit for bit.
#[test]
fn merged_shards_equal_the_unsharded_run() {
    let d = tempfile::tempdir().unwrap();
    let s = smoke();
    let full = d.path().join("full.parquet");
    ok(&[
        "run",
        s.to_str().unwrap(),
        "--out",
        full.to_str().unwrap(),
        "-q",
    ]);
    let want = content(&full);
    assert!(
        want.len() > 5 && want[0].1.len() == 64,
        "{} columns, {} rows",
        want.len(),
        want[0].1.len()
    );
    for n in [1usize, 3, 4, 7] {
        let dir = d.path().join(format!("n{n}"));
        std::fs::create_dir(&dir).unwrap();
        for i in 0..n {
            let out = dir.join(format!("part{i}.parquet"));
            // Threads and chunk sizes differ per shard: the slice, not the schedule, decides.
            let (threads, chunk) = ((i % 2 + 1).to_string(), (3 + i).to_string());
            ok(&[
                "run",
                s.to_str().unwrap(),
                "--shard",
                &format!("{i}/{n}"),
                "--out",
                out.to_str().unwrap(),
                "--threads",
                &threads,
                "--chunk",
                &chunk,
                "-q",
            ]);
        }
        let merged = d.path().join(format!("merged{n}.parquet"));
        let said = ok(&[
            "merge",
            dir.to_str().unwrap(),
            "--out",
            merged.to_str().unwrap(),
        ]);
        assert!(said.contains(&format!("{n} shards, 64 rows")), "{said}");
        assert_eq!(content(&merged), want, "N = {n}");
        // The merged file says what the unsharded one says (no shard keys left).
        let meta = vshake::shell::formats::parquet_read::parquet_metadata(&merged).unwrap();
        assert!(
            meta.iter().all(|(k, _)| !k.starts_with("vshake.shard")),
            "{meta:?}"
        );
        let full_meta = vshake::shell::formats::parquet_read::parquet_metadata(&full).unwrap();
        let keys = |m: &[(String, String)]| {
            let mut v = m
                .iter()
                // The row groups' checksums differ (the merge's row groups are the shards').
                .filter(|(k, _)| k.starts_with("vshake.") && k != "vshake.row_group_crc32")
                .cloned()
                .collect::<Vec<_>>();
            v.sort();
            v
        };
        assert_eq!(keys(&meta), keys(&full_meta));
        let backend = meta.iter().find(|(k, _)| k == "vshake.backend");
        assert_eq!(backend.map(|(_, v)| v.as_str()), Some("cpu"), "{meta:?}");
    }
}

/// Acceptance 2: a missing shard, a duplicated shard and a shard of another seed are refused,
/// each with the file or shard named; exit 2 and no merged file.
#[test]
fn merge_refuses_missing_duplicate_and_foreign_shards() {
    let d = tempfile::tempdir().unwrap();
    let s = smoke();
    let part = |dir: &Path, study: &Path, i: usize, n: usize, name: &str| {
        std::fs::create_dir_all(dir).unwrap();
        ok(&[
            "run",
            study.to_str().unwrap(),
            "--shard",
            &format!("{i}/{n}"),
            "--out",
            dir.join(name).to_str().unwrap(),
            "-q",
        ]);
    };
    let merge = |dir: &Path| {
        let out = dir.with_extension("parquet");
        let (code, stdout, stderr) = study(&[
            "merge",
            dir.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 2, "{stdout}{stderr}");
        assert!(!out.exists(), "no merged file");
        assert!(!dir.with_extension("parquet.tmp").exists(), "no temp file");
        stderr
    };
    // Missing: shards 0 and 2 of 3.
    let missing = d.path().join("missing");
    part(&missing, &s, 0, 3, "a.parquet");
    part(&missing, &s, 2, 3, "c.parquet");
    let e = merge(&missing);
    assert!(
        e.contains("shard 1/3 missing") && e.contains("found 2 of 3"),
        "{e}"
    );
    // Duplicate: shard 1 of 2 twice.
    let dup = d.path().join("dup");
    part(&dup, &s, 0, 2, "a.parquet");
    part(&dup, &s, 1, 2, "b.parquet");
    part(&dup, &s, 1, 2, "b_again.parquet");
    let e = merge(&dup);
    assert!(
        e.contains("shard 1/2 appears twice")
            && e.contains("b.parquet")
            && e.contains("b_again.parquet"),
        "{e}"
    );
    // Another seed: the same study with seed 8 for shard 1.
    let other = d.path().join("smoke_seed8.toml");
    std::fs::write(
        &other,
        std::fs::read_to_string(&s)
            .unwrap()
            .replace("seed = 7", "seed = 8"),
    )
    .unwrap();
    let foreign = d.path().join("foreign");
    part(&foreign, &s, 0, 2, "a.parquet");
    part(&foreign, &other, 1, 2, "b.parquet");
    let e = merge(&foreign);
    assert!(
        e.contains("b.parquet")
            && e.contains("another run")
            && e.contains("seed (8)")
            && e.contains("(7)"),
        "{e}"
    );
    // A file that is no shard, and bad --shard values.
    let (code, _, e) = study(&["run", s.to_str().unwrap(), "--shard", "4/4", "-q"]);
    assert_eq!(code, 2);
    assert!(e.contains("--shard \"4/4\"") && e.contains("0..3"), "{e}");
    let (code, _, e) = study(&["run", s.to_str().unwrap(), "--shard", "0/65", "-q"]);
    assert_eq!(code, 2);
    assert!(e.contains("64 samples"), "{e}");
}

/// `study slurm` writes the array, the merge job and the submit script, with the shard wiring.
#[test]
fn slurm_scripts_wire_the_array_to_the_shards() {
    let d = tempfile::tempdir().unwrap();
    let s = smoke();
    let dir = d.path().join("job");
    let args = [
        "slurm",
        s.to_str().unwrap(),
        "--shards",
        "4",
        "--partition",
        "debug",
        "--time",
        "00:10:00",
        "--cpus",
        "1",
        "--dir",
        dir.to_str().unwrap(),
    ];
    let out = ok(&args);
    assert!(
        out.contains("64 samples x 1 excitations in 4 shards"),
        "{out}"
    );
    let array = std::fs::read_to_string(dir.join("array.sbatch")).unwrap();
    for want in [
        "#SBATCH --array=0-3",
        "#SBATCH --partition=debug",
        "#SBATCH --time=00:10:00",
        "#SBATCH --cpus-per-task=1",
        "--shard \"${SLURM_ARRAY_TASK_ID}/4\"",
        "--log-progress",
    ] {
        assert!(array.contains(want), "{want} not in\n{array}");
    }
    let merge = std::fs::read_to_string(dir.join("merge.sbatch")).unwrap();
    assert!(
        merge.contains(" merge ") && merge.contains("smoke.parquet"),
        "{merge}"
    );
    assert!(
        !array.contains("--gpus-per-task") && !array.contains("--backend"),
        "{array}"
    );
    let submit = std::fs::read_to_string(dir.join("submit.sh")).unwrap();
    assert!(submit.contains("--dependency=afterok:${array}"), "{submit}");
    // Into the same folder: the same options rewrite the same scripts; other options (8 shards)
    // are refused before any script is written, and an edited script is kept.
    ok(&args);
    let mut other = args;
    other[3] = "8";
    let (code, _, e) = study(&other);
    assert_eq!(code, 2, "{e}");
    assert!(
        e.contains("array.sbatch: exists with other contents"),
        "{e}"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("array.sbatch")).unwrap(),
        array
    );
    std::fs::write(dir.join("submit.sh"), "edited").unwrap();
    let (code, _, e) = study(&args);
    assert_eq!(code, 2, "{e}");
    assert!(e.contains("submit.sh: exists with other contents"), "{e}");
    assert_eq!(
        std::fs::read_to_string(dir.join("submit.sh")).unwrap(),
        "edited"
    );
    // A GPU array: each task asks for a GPU and runs (and resumes) with --backend cuda.
    let gpu_dir = d.path().join("gpu");
    let out = ok(&[
        "slurm",
        s.to_str().unwrap(),
        "--shards",
        "2",
        "--gpus-per-task",
        "1",
        "--dir",
        gpu_dir.to_str().unwrap(),
    ]);
    assert!(out.contains("2 CPUs and 1 GPU"), "{out}");
    let array = std::fs::read_to_string(gpu_dir.join("array.sbatch")).unwrap();
    assert!(array.contains("#SBATCH --gpus-per-task=1\n"), "{array}");
    assert_eq!(array.matches("--backend cuda").count(), 2, "{array}");
    let (code, _, e) = study(&[
        "slurm",
        s.to_str().unwrap(),
        "--shards",
        "2",
        "--gpus-per-task",
        "2",
    ]);
    assert_eq!(code, 2);
    assert!(e.contains("one GPU per task"), "{e}");
    let (code, _, e) = study(&[
        "slurm",
        s.to_str().unwrap(),
        "--shards",
        "4",
        "--time",
        "1 day",
        "--dir",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(e.contains("--time"), "{e}");
}
