//! The three layers of docs/architecture.md, enforced: the kernel (physics, the time loop) names
//! neither orchestration nor the shell, and orchestration (studies, comparison, diagnosis) does
//! not name the shell. A path that climbs out of a layer (`super::super::shell`) counts too.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(rust_files(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out
}

/// The lines (1-based) of `text` whose code (not a comment) names one of the `forbidden` layers:
/// `crate::<layer>`, or `super::super::<layer>` climbing out of this one.
fn reach_ups(text: &str, forbidden: &[&str]) -> Vec<usize> {
    let mut lines = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let code = line.split("//").next().unwrap_or("");
        let names = |other: &&str| {
            code.contains(&format!("crate::{other}"))
                || code.contains(&format!("super::super::{other}"))
        };
        if forbidden.iter().any(names) {
            lines.push(i + 1);
        }
    }
    lines
}

/// Lines of the files under `src/<layer>` that name one of the `forbidden` layers.
fn uses(layer: &str, forbidden: &[&str]) -> Vec<String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    for f in rust_files(&root.join("src").join(layer)) {
        let text = std::fs::read_to_string(&f).unwrap();
        let rel = f.strip_prefix(&root).unwrap().display().to_string();
        for n in reach_ups(&text, forbidden) {
            found.push(format!(
                "{rel}:{n}: {}",
                text.lines().nth(n - 1).unwrap().trim()
            ));
        }
    }
    found
}

#[test]
fn the_kernel_names_neither_orchestration_nor_the_shell() {
    let found = uses("kernel", &["orchestration", "shell"]);
    assert!(
        found.is_empty(),
        "the kernel reaches up:\n{}",
        found.join("\n")
    );
}

#[test]
fn orchestration_does_not_name_the_shell() {
    let found = uses("orchestration", &["shell"]);
    assert!(
        found.is_empty(),
        "orchestration reaches up:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_check_finds_a_reach_up_and_not_a_comment() {
    let text = "use super::params;\n// see crate::shell::report\nuse crate::shell::report;\n\
                fn f() { super::super::orchestration::g() }\n";
    assert_eq!(reach_ups(text, &["orchestration", "shell"]), vec![3, 4]);
}
