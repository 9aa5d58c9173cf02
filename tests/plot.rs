//! `study plot`: a study's results drawn; what it refuses.

mod common;
use common::study;

/// The smoke study (a Saltelli design) run into `dir`, its results' path returned.
fn smoke(dir: &std::path::Path) -> std::path::PathBuf {
    let out = dir.join("smoke.parquet");
    let (code, _, err) = study(&[
        "run",
        "studies/smoke.toml",
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    out
}

#[test]
fn draws_indices_scatter_and_index_then_redraws_its_own_folder() {
    let dir = tempfile::tempdir().unwrap();
    let results = smoke(dir.path());
    let (code, out, err) = study(&[
        "plot",
        results.to_str().unwrap(),
        "--metrics",
        "amp_ratio,thd_odd_ratio",
    ]);
    assert_eq!(code, 0, "{err}");
    let plots = dir.path().join("smoke_plots");
    assert!(out.contains("smoke_plots/index.html"), "{out}");
    let index = std::fs::read_to_string(plots.join("index.html")).unwrap();
    for f in [
        "sobol_sine_3hz_1g_amp_ratio.svg",
        "sobol_sine_3hz_1g_thd_odd_ratio.svg",
        "scatter_amp_ratio.svg",
    ] {
        assert!(index.contains(f), "{f} not in index.html");
        let svg = std::fs::read_to_string(plots.join(f)).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{f}");
    }
    // The Sobol' plot names the varied parameters on its axis.
    let sobol = std::fs::read_to_string(plots.join("sobol_sine_3hz_1g_amp_ratio.svg")).unwrap();
    assert!(sobol.contains(">\nl_a\n<") && sobol.contains("S1") && sobol.contains("ST"));
    assert!(
        index.contains("No run failed"),
        "the smoke study has no failed run"
    );
    // Its own folder is redrawn.
    let (code, _, err) = study(&["plot", results.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn refuses_a_folder_of_other_files_and_a_file_that_is_not_results() {
    let dir = tempfile::tempdir().unwrap();
    let results = smoke(dir.path());
    std::fs::write(dir.path().join("notes.txt"), "mine").unwrap();
    let (code, _, err) = study(&[
        "plot",
        results.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("holds other files"), "{err}");
    assert_eq!(
        std::fs::read_to_string(dir.path().join("notes.txt")).unwrap(),
        "mine"
    );
    let (code, _, err) = study(&["plot", dir.path().join("notes.txt").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("notes.txt"), "{err}");
    let (code, _, err) = study(&["plot", results.to_str().unwrap(), "--metrics", "nope"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("nope"), "{err}");
}
