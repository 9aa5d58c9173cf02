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
    // Its own folder is redrawn (every metric this time): the same drawings come out the same,
    // and the new index links every drawing in the folder.
    let drawn = |f: &str| std::fs::read_to_string(plots.join(f)).unwrap();
    let first: Vec<(&str, String)> = [
        "sobol_sine_3hz_1g_amp_ratio.svg",
        "sobol_sine_3hz_1g_thd_odd_ratio.svg",
        "scatter_amp_ratio.svg",
        "scatter_thd_odd_ratio.svg",
    ]
    .map(|f| (f, drawn(f)))
    .into();
    let (code, _, err) = study(&["plot", results.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    for (f, svg) in &first {
        assert_eq!(&drawn(f), svg, "{f} drawn again differently");
    }
    let index = drawn("index.html");
    let svgs: Vec<String> = std::fs::read_dir(&plots)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    assert!(svgs.len() > first.len(), "every metric drawn: {svgs:?}");
    for f in &svgs {
        assert!(
            index.contains(f.as_str()),
            "{f} not in the redrawn index.html"
        );
    }
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

/// A time history (`study sim --out`) is drawn channel by channel against time: an SVG per
/// channel asked for, each a line through the run's samples (thinned to about 4 000), and an
/// index; a channel the file lacks is refused naming those it has.
#[test]
fn draws_a_time_history_channel_by_channel() {
    let d = tempfile::tempdir().unwrap();
    let run = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/sim_3hz_1p73g.toml");
    let h = d.path().join("h.parquet");
    let (code, _, err) = study(&["sim", run.to_str().unwrap(), "--out", h.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let out = d.path().join("plots");
    let (h, o) = (h.to_str().unwrap(), out.to_str().unwrap());
    let (code, _, err) = study(&["plot", h, "--out", o, "--metrics", "accel_mps2,p1_pa"]);
    assert_eq!(code, 0, "{err}");
    let mut svgs: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    svgs.sort();
    assert_eq!(svgs, ["channel_accel_mps2.svg", "channel_p1_pa.svg"]);
    let svg = std::fs::read_to_string(out.join("channel_accel_mps2.svg")).unwrap();
    let points = svg
        .split("<polyline")
        .filter(|l| l.contains("#1F77B4"))
        .map(|l| l.matches(',').count())
        .sum::<usize>();
    // 3 s at 1024 Hz: 3 072 samples, all drawn.
    assert!(points >= 3000, "{points} points");
    let index = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(index.contains("channel_p1_pa.svg") && index.contains("A time history"));
    let (code, _, err) = study(&["plot", h, "--out", o, "--metrics", "nope"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("no channel \"nope\"") && err.contains("accel_mps2"),
        "{err}"
    );
}
