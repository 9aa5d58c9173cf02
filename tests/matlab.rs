//! Issue 27: MATLAB MAT-files written by SciPy's `savemat` (tests/data/mat/make.py, an
//! implementation independent of vshake's reader): v5 (uncompressed) and v7 (compressed) files
//! are read to the numbers of the SI file they were written from; files without channels, or
//! with channels of different lengths, are refused naming the file and the cause.

use std::path::{Path, PathBuf};
use vshake::orchestration::measured::campaign::Mapped;
use vshake::shell::formats::measured_files;
use vshake::shell::formats::measured_files::NumTable;

const CHANNELS: [&str; 4] = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/mat")
        .join(name)
}

fn read(name: &str, map: &[(String, Mapped)]) -> Result<NumTable, String> {
    let (table, bad) = measured_files::read_columns_lenient(&fixture(name), &CHANNELS, &[], map)
        .map_err(|e| e.to_string())?;
    assert!(bad.is_empty(), "{name}: {bad:?}");
    Ok(table)
}

/// Every channel within `rel` (relative to the channel's peak) of expected.csv's.
fn assert_expected(t: &NumTable, rel: f64) {
    let want = measured_files::read_columns(&fixture("expected.csv"), &CHANNELS, &[]).unwrap();
    for c in CHANNELS {
        let (a, b) = (t.column(c).unwrap(), want.column(c).unwrap());
        assert_eq!(a.len(), b.len(), "{c}");
        let peak = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= rel * peak, "{c} row {}: {x} vs {y}", i + 1);
        }
    }
}

#[test]
fn v5_with_matlab_names_is_read_exactly() {
    let t = read("v5_names.mat", &[]).unwrap();
    assert_expected(&t, 0.0);
    let notes = t.notes.join("; ");
    assert!(notes.contains("MATLAB MAT-file (v5)"), "{notes}");
    assert!(notes.contains("`RefDisp` read as ref_disp_m"), "{notes}");
}

#[test]
fn v7_compressed_row_vectors_with_units_are_read_to_si() {
    let t = read("v7_units.mat", &[]).unwrap();
    assert_expected(&t, 1e-15);
    let notes = t.notes.join("; ");
    assert!(
        notes.contains("MATLAB MAT-file (v7, compressed)"),
        "{notes}"
    );
    assert!(
        notes.contains("`accel_g` read as accel_mps2 (g → m/s²)"),
        "{notes}"
    );
}

#[test]
fn a_matrix_of_channels_is_mapped_by_position() {
    let map: Vec<(String, Mapped)> = [("time", 1, "s"), ("ref_disp", 2, "mm")]
        .into_iter()
        .chain([("disp", 3, "mm"), ("accel", 4, "g")])
        .map(|(k, i, u)| {
            let m = Mapped {
                name: None,
                index: Some(i),
                unit: Some(u.into()),
            };
            (k.to_string(), m)
        })
        .collect();
    let t = read("v7_matrix.mat", &map).unwrap();
    assert_expected(&t, 1e-15);
    // Unmapped, nothing in it is a channel's name: each missing channel is named.
    let err = read("v7_matrix.mat", &[]).unwrap_err();
    assert!(
        err.contains("v7_matrix.mat") && err.contains("time_s"),
        "{err}"
    );
    assert!(err.contains("data(:,1)"), "{err}");
}

#[test]
fn files_without_channels_or_with_unequal_lengths_are_refused() {
    let err = read("v7_struct.mat", &[]).unwrap_err();
    assert!(
        err.contains("v7_struct.mat") && err.contains("no numeric vector"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    let err = read("v5_lengths.mat", &[]).unwrap_err();
    assert!(
        err.contains("v5_lengths.mat") && err.contains("`accel` 299"),
        "{err}"
    );
}

#[test]
fn a_truncated_mat_file_is_refused_without_printing_it() {
    let d = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(fixture("v7_units.mat")).unwrap();
    for cut in [140, 1000, bytes.len() - 7] {
        let p = d.path().join("cut.mat");
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let err = measured_files::read_columns(&p, &CHANNELS, &[])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cut.mat: not a readable MATLAB .mat file: the file is truncated"),
            "{err}"
        );
        assert!(!err.contains('\0') && err.len() < 300, "{err}");
    }
}
