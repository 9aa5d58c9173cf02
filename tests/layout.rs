//! The house rules that a reader of the code relies on: the README's "Layout" section names every
//! module, and no function in the shell or orchestration layers is longer than a screen.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

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
    out.sort();
    out
}

/// Every module of the three layers (its file stem, `mod.rs` aside) is named in backticks in the
/// README's "Layout" section, and the section names no module that is not there.
#[test]
fn the_readme_layout_names_every_module() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let start = readme.find("\n## Layout\n").expect("a Layout section");
    let end = readme[start + 1..]
        .find("\n## ")
        .map_or(readme.len(), |e| start + 1 + e);
    let section = &readme[start..end];
    for layer in ["kernel", "orchestration", "shell"] {
        assert!(
            section.contains(&format!("`src/{layer}/`")),
            "the layer {layer} is not in the Layout section"
        );
        let dir = root().join("src").join(layer);
        for f in std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()) {
            let stem = f.file_stem().unwrap().to_string_lossy().to_string();
            if stem == "mod" {
                continue;
            }
            let name = if f.is_dir() {
                format!("`{stem}/`")
            } else {
                format!("`{stem}`")
            };
            assert!(
                section.contains(&name),
                "src/{layer}/{stem} is not named in the README's Layout section"
            );
        }
    }
}

/// The length of every function (from its `fn` line to its closing brace) in a Rust source, test
/// modules included: (lines, name, first line).
fn function_lengths(src: &str) -> Vec<(usize, String, usize)> {
    let lines: Vec<&str> = src.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim_start();
        let code = line
            .trim_start_matches("pub ")
            .trim_start_matches("pub(crate) ")
            .trim_start_matches("const ")
            .trim_start_matches("unsafe ");
        if let Some(rest) = code.strip_prefix("fn ") {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            let (mut depth, mut started, mut j) = (0i64, false, i);
            'scan: while j < lines.len() {
                let text = strip(lines[j]);
                for ch in text.chars() {
                    match ch {
                        '{' => {
                            depth += 1;
                            started = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                    if started && depth == 0 {
                        break 'scan;
                    }
                }
                if !started && text.trim_end().ends_with(';') {
                    break;
                }
                j += 1;
            }
            out.push((j - i + 1, name, i + 1));
            i = if started { j + 1 } else { i + 1 };
            continue;
        }
        i += 1;
    }
    out
}

/// A line without its comment and with string and char literals emptied (their braces do not count).
fn strip(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    let mut in_str = false;
    while let Some(c) = chars.next() {
        if in_str {
            match c {
                '\\' => {
                    chars.next();
                }
                '"' => in_str = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_str = true,
            '/' if chars.peek() == Some(&'/') => break,
            '\'' => {
                // A char literal ('{', '\n'); a lifetime ('a) has no closing quote nearby.
                let ahead: String = chars.clone().take(3).collect();
                if let Some(k) = ahead.find('\'').filter(|&k| k > 0) {
                    for _ in 0..=k {
                        chars.next();
                    }
                } else {
                    out.push(c);
                }
            }
            _ => out.push(c),
        }
    }
    out
}

#[test]
fn the_length_counter_counts() {
    let src = "fn a() {\n    let s = \"}\";\n    let c = '{';\n}\n\npub fn b<'a>(x: &'a str) -> &'a str {\n    // }\n    x\n}\n";
    assert_eq!(
        function_lengths(src),
        vec![(4, "a".to_string(), 1), (4, "b".to_string(), 6)]
    );
}

/// No function in the shell or orchestration layers is over 80 lines (STYLE: one screen).
#[test]
fn shell_and_orchestration_functions_fit_on_a_screen() {
    let mut long = Vec::new();
    for layer in ["shell", "orchestration"] {
        for f in rust_files(&root().join("src").join(layer)) {
            for (n, name, line) in function_lengths(&std::fs::read_to_string(&f).unwrap()) {
                if n > 80 {
                    long.push(format!(
                        "{}:{line} {name}: {n} lines",
                        f.strip_prefix(root()).unwrap().display()
                    ));
                }
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over 80 lines:\n{}",
        long.join("\n")
    );
}
