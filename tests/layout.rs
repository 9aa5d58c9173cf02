//! The house rules that a reader of the code relies on: the "Layout" section of
//! docs/architecture.md names every module and only modules, the README stays a short front page,
//! no function in the shell or orchestration layers is longer than a screen, and the layers
//! depend one way (kernel <- orchestration <- shell): each layer is a crate, and its manifest
//! names only the layers below it (the compiler then refuses a path that reaches up).

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

/// The "Layout" section of docs/architecture.md: from its `## Layout` heading to the next `## `.
fn layout_section() -> String {
    let text =
        std::fs::read_to_string(root().join("docs/architecture.md")).expect("docs/architecture.md");
    let start = text
        .find("\n## Layout\n")
        .expect("a `## Layout` section in docs/architecture.md");
    let end = text[start + 1..]
        .find("\n## ")
        .map_or(text.len(), |e| start + 1 + e);
    text[start..end].to_string()
}

/// Whether a backticked word is written the way a module is: `name` (the file `name.rs`) or `name/`
/// (a folder), the name in snake_case (a lower-case letter, then lower-case letters, digits and
/// underscores).
fn looks_like_module(word: &str) -> bool {
    let name = word.strip_suffix('/').unwrap_or(word);
    let mut chars = name.chars();
    match chars.next() {
        Some(c) if c.is_ascii_lowercase() => {
            chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        }
        _ => false,
    }
}

/// The modules a Layout section names, per layer, in its order: a layer is a top-level list item
/// that starts with `` - `<folder>/` `` (a folder of [`LAYERS`]); its modules are the backticked words that look like
/// module names (`looks_like_module`) in the nested items under it (lines that start with
/// `"  - "`, and their continuation lines, which start with four spaces). The layer's own line and
/// its continuation lines (two spaces) are prose: their backticked words are not read. In an item
/// that names a room of the layer (`rooms`: `diagnosis/`), the modules after it are the room's
/// (`compare` there is `diagnosis/compare`).
fn named_modules(section: &str, rooms: &dyn Fn(&str) -> Vec<String>) -> Vec<(String, Vec<String>)> {
    let mut layers: Vec<(String, Vec<String>)> = Vec::new();
    let mut nested = false;
    let mut room: Option<String> = None;
    for line in section.lines() {
        let folder = LAYERS
            .iter()
            .find(|(_, dir, _)| line.starts_with(&format!("- `{dir}/`")));
        if let Some((layer, _, _)) = folder {
            layers.push((layer.to_string(), Vec::new()));
            nested = false;
            continue;
        }
        if line.starts_with("  - ") {
            nested = true;
            room = None;
        } else if !line.starts_with("    ") {
            nested = false;
        }
        if !nested {
            continue;
        }
        if let Some((layer, names)) = layers.last_mut() {
            let layer_rooms = rooms(layer);
            for (i, part) in line.split('`').enumerate() {
                if i % 2 == 1 && looks_like_module(part) {
                    match &room {
                        Some(r) if !part.ends_with('/') => names.push(format!("{r}{part}")),
                        _ => names.push(part.to_string()),
                    }
                    if layer_rooms.iter().any(|r| r == part) {
                        room = Some(part.to_string());
                    }
                }
            }
        }
    }
    layers
}

/// The layers, their folders of source (as the Layout section writes them) and their crates.
const LAYERS: [(&str, &str, &str); 3] = [
    ("kernel", "crates/kernel/src", "crates/kernel"),
    (
        "orchestration",
        "crates/orchestration/src",
        "crates/orchestration",
    ),
    ("shell", "src/shell", "."),
];

/// The source folder of `layer`.
fn layer_dir(layer: &str) -> PathBuf {
    let (_, dir, _) = LAYERS.iter().find(|(l, _, _)| *l == layer).unwrap();
    root().join(dir)
}

/// The modules of a layer's folder: `name` for a file `name.rs`; `name/` for a folder that is one
/// module (`name/mod.rs`, or no Rust beside it: `effects/`, `cuda/`); for a room (a folder beside
/// its `name.rs`, which only declares the room's files) `name/` and `name/child` for each file in
/// it. `mod.rs` and `lib.rs` (the crate's root) aside.
fn modules_of(layer: &str) -> Vec<String> {
    let dir = layer_dir(layer);
    let mut out = Vec::new();
    for f in std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()) {
        let stem = f.file_stem().unwrap().to_string_lossy().to_string();
        if stem == "mod" || stem == "lib" {
            continue;
        }
        if f.is_dir() {
            out.push(format!("{stem}/"));
            if is_room(&f) {
                for c in std::fs::read_dir(&f).unwrap().map(|e| e.unwrap().path()) {
                    if c.extension().is_some_and(|x| x == "rs") {
                        let child = c.file_stem().unwrap().to_string_lossy().to_string();
                        out.push(format!("{stem}/{child}"));
                    }
                }
            }
        } else if f.extension().is_some_and(|x| x == "rs") && !dir.join(&stem).is_dir() {
            out.push(stem);
        }
    }
    out.sort();
    out
}

/// Whether folder `f` is a room: its module file `f.rs` stands beside it.
fn is_room(f: &Path) -> bool {
    f.with_extension("rs").is_file()
}

/// The rooms of a layer (`name/`).
fn rooms_of(layer: &str) -> Vec<String> {
    modules_of(layer)
        .into_iter()
        .filter(|m| m.ends_with('/') && is_room(&layer_dir(layer).join(m.trim_end_matches('/'))))
        .collect()
}

#[test]
fn the_architecture_layout_names_every_module_and_only_modules() {
    let named = named_modules(&layout_section(), &rooms_of);
    let layers: Vec<&str> = named.iter().map(|(layer, _)| layer.as_str()).collect();
    assert_eq!(
        layers,
        ["kernel", "orchestration", "shell"],
        "the layers of docs/architecture.md's Layout section"
    );
    for (layer, names) in &named {
        let modules = modules_of(layer);
        for m in &modules {
            assert!(
                names.contains(m),
                "{}/{m} is not named in docs/architecture.md's Layout section \
                 (write `{m}` in an item nested under its layer's folder)",
                layer_dir(layer).display()
            );
        }
        for n in names {
            assert!(
                modules.contains(n),
                "docs/architecture.md's Layout section names `{n}` under the {layer}, \
                 which has no such module"
            );
        }
    }
}

/// The Layout convention's reader on a small section: modules in nested items only, the layer's
/// own lines and other backticked text not read.
#[test]
fn the_layout_reader_reads_nested_items_only() {
    let section = "## Layout\n\n\
        - `crates/kernel/src/` — the `study` prose, `ignored`:\n  \
        also `ignored`.\n  \
        - `controller`, `EffectId`, `effects/mod.rs`, `study tune`,\n    \
        `cuda/` and `gpu_lanes`;\n\
        - `src/shell/` — more.\n  \
        - `cli`\n  \
        - `job/`: `outputs`,\n    \
        `sizing`;\n  \
        - `api`\n\
        After the list, `not_read`.\n";
    let kernel = (
        "kernel".to_string(),
        ["controller", "cuda/", "gpu_lanes"]
            .map(String::from)
            .to_vec(),
    );
    // With `job/` a room of the shell, the modules after it in its item are the room's.
    let rooms = |layer: &str| match layer {
        "shell" => vec!["job/".to_string()],
        _ => vec![],
    };
    assert_eq!(
        named_modules(section, &rooms),
        vec![
            kernel.clone(),
            (
                "shell".to_string(),
                ["cli", "job/", "job/outputs", "job/sizing", "api"]
                    .map(String::from)
                    .to_vec()
            ),
        ]
    );
    // Without rooms, a folder's words are modules of the layer.
    assert_eq!(
        named_modules(section, &|_| vec![]),
        vec![
            kernel,
            (
                "shell".to_string(),
                ["cli", "job/", "outputs", "sizing", "api"]
                    .map(String::from)
                    .to_vec()
            ),
        ]
    );
    assert!(looks_like_module("spec_quake") && looks_like_module("effects/"));
    assert!(!looks_like_module("EffectId") && !looks_like_module("lane.cu"));
    assert!(!looks_like_module("--resume") && !looks_like_module("study tune"));
}

/// The README is a short front page (issue 31): at most 300 lines; the tour, the tutorials and the
/// details are in docs/.
#[test]
fn the_readme_is_at_most_300_lines() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let n = readme.lines().count();
    assert!(
        n <= 300,
        "README.md has {n} lines; at most 300 (move the rest to docs/)"
    );
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
        for f in rust_files(&layer_dir(layer)) {
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

// The three layers of docs/architecture.md, enforced by the compiler: each is a crate, and a
// crate's manifest names only the layers below it, so a path that reaches up does not compile.

/// The vshake crates that the manifest at `dir` (relative to the root) depends on, build and
/// development dependencies alike.
fn vshake_dependencies(dir: &str) -> Vec<String> {
    dependencies_in(&std::fs::read_to_string(root().join(dir).join("Cargo.toml")).unwrap())
}

/// The vshake crates a manifest's text names as dependencies (lines `vshake-NAME = ...`).
fn dependencies_in(text: &str) -> Vec<String> {
    let mut deps: Vec<String> = text
        .lines()
        .filter_map(|l| l.trim_start().strip_prefix("vshake-"))
        .filter_map(|l| {
            l.split_once(['=', ' '])
                .map(|(name, _)| format!("vshake-{name}"))
        })
        .collect();
    deps.sort();
    deps.dedup();
    deps
}

#[test]
fn each_layer_depends_on_the_layers_below_only() {
    assert_eq!(vshake_dependencies("crates/kernel"), Vec::<String>::new());
    assert_eq!(
        vshake_dependencies("crates/orchestration"),
        ["vshake-kernel"]
    );
    assert_eq!(
        vshake_dependencies("."),
        ["vshake-kernel", "vshake-orchestration"]
    );
}

#[test]
fn the_manifest_reader_finds_dependencies() {
    let text = "[package]\nname = \"vshake-shell\"\n[dependencies]\n\
                vshake-kernel = { path = \"../kernel\" }\nrayon = \"1\"\n\
                [dev-dependencies]\nvshake-orchestration= { path = \"o\" }\n";
    assert_eq!(
        dependencies_in(text),
        ["vshake-kernel", "vshake-orchestration"]
    );
}

// Commands are leaves (issue 49): a command file (`src/shell/*_cmd.rs`) parses its arguments,
// calls the services (the shell's other modules, the orchestration) and prints; what two
// commands share is a service, never one command reached through another.

/// The other commands whose module names the code (not a comment) of `text` uses.
fn commands_named(text: &str, own: &str, commands: &[String]) -> Vec<String> {
    let code: String = text
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n");
    let words: Vec<&str> = code
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .collect();
    commands
        .iter()
        .filter(|c| c.as_str() != own && words.contains(&c.as_str()))
        .cloned()
        .collect()
}

#[test]
fn no_command_imports_another() {
    let dir = layer_dir("shell").join("commands");
    let commands: Vec<String> = modules_of("shell")
        .into_iter()
        .filter_map(|m| m.strip_prefix("commands/").map(str::to_string))
        .filter(|c| !c.is_empty())
        .collect();
    assert!(
        commands.len() >= 14 && commands.iter().all(|c| c.ends_with("_cmd")),
        "the commands, each a file of src/shell/commands/ named `<command>_cmd`: {commands:?}"
    );
    let mut found = Vec::new();
    for c in &commands {
        let text = std::fs::read_to_string(dir.join(format!("{c}.rs"))).unwrap();
        for other in commands_named(&text, c, &commands) {
            found.push(format!("src/shell/commands/{c}.rs names {other}"));
        }
    }
    assert!(
        found.is_empty(),
        "commands that import another (move what they share into a service module):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_command_check_finds_an_import_and_not_a_comment() {
    let commands = [
        "fit_cmd".to_string(),
        "run_cmd".to_string(),
        "sim_cmd".to_string(),
    ];
    let text =
        "use super::{\n    tables,\n    run_cmd,\n};\n// see sim_cmd\nfn run() { fit_cmd_x(); }\n";
    assert_eq!(commands_named(text, "fit_cmd", &commands), ["run_cmd"]);
    assert_eq!(
        commands_named("use super::fit_cmd::load;", "sim_cmd", &commands),
        ["fit_cmd"]
    );
}

// Circles of files: module a names b and b names a (or through others). A circle makes two files
// one piece that reads as two. The layers' circles are found by their imports; those that remain
// are listed below, to be broken (docs/architecture.md), and the test fails on a new one and on a
// listed one that is gone (so the list only shrinks).

/// The circles that remain, each sorted: issue 49's list less those broken since. None is left
/// (docs/architecture.md, "Layout").
const KNOWN_CIRCLES: [&str; 0] = [];

/// The module path of a layer's file, from the crate's root (the shell's files sit under `shell`):
/// `diagnosis/compare.rs` is `diagnosis::compare`, `effects/mod.rs` is `effects`.
fn module_path(layer: &str, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(layer_dir(layer)).unwrap();
    let mut path: Vec<String> = if layer == "shell" {
        vec!["shell".into()]
    } else {
        vec![]
    };
    for part in rel.with_extension("").iter() {
        let part = part.to_string_lossy().to_string();
        if part != "mod" {
            path.push(part);
        }
    }
    path
}

/// Every module path that `code` names from module `here`: `crate::a::b`, `super::a`,
/// `super::super::a`, `self::a`, and each path of a group (`crate::a::{b, c::D}`), resolved from
/// the crate's root.
fn paths_named(code: &str, here: &[String]) -> Vec<Vec<String>> {
    let flat: String = code.split_whitespace().collect::<Vec<_>>().join(" ");
    let mut out = Vec::new();
    for start in ["crate::", "super::", "self::"] {
        for (i, _) in flat.match_indices(start) {
            let before = flat[..i].chars().next_back();
            if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            for p in expand(&path_at(&flat[i..])) {
                out.extend(resolve(&p, here));
            }
        }
    }
    out
}

/// The path written at the start of `text`: segments joined by `::`, with a `{...}` group kept
/// whole.
fn path_at(text: &str) -> String {
    let mut end = 0;
    let mut depth = 0;
    for (i, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth > 0 => depth -= 1,
            c if depth == 0 && !(c.is_ascii_alphanumeric() || c == '_' || c == ':') => break,
            _ => {}
        }
        end = i + c.len_utf8();
        if depth == 0 && c == '}' {
            break;
        }
    }
    text[..end].to_string()
}

/// A path with groups as the paths it stands for: `a::{b, c::{d, e}}` is `a::b`, `a::c::d`,
/// `a::c::e`.
fn expand(path: &str) -> Vec<String> {
    let Some(open) = path.find('{') else {
        return vec![path.trim_end_matches("::").to_string()];
    };
    let head = &path[..open];
    let inner = &path[open + 1..path.len().saturating_sub(1)];
    let (mut items, mut depth, mut from) = (Vec::new(), 0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&inner[from..i]);
                from = i + 1;
            }
            _ => {}
        }
    }
    items.push(&inner[from..]);
    items
        .iter()
        .map(|s| s.trim())
        .filter(|s| !s.is_empty() && *s != "self" && *s != "*")
        .flat_map(|s| expand(&format!("{head}{s}")))
        .chain(std::iter::once(head.trim_end_matches("::").to_string()))
        .collect()
}

/// `path` (starting with `crate`, `super` or `self`) from the crate's root, as seen from module
/// `here`.
fn resolve(path: &str, here: &[String]) -> Option<Vec<String>> {
    let mut segs = path.split("::").filter(|s| !s.is_empty());
    let mut out: Vec<String> = match segs.next()? {
        "crate" => vec![],
        "self" => here.to_vec(),
        "super" => here[..here.len().checked_sub(1)?].to_vec(),
        _ => return None,
    };
    for s in segs {
        if s == "super" {
            out.pop()?;
        } else {
            out.push(s.to_string());
        }
    }
    Some(out)
}

/// The node of `modules` a module path falls in: the longest module whose path begins it.
fn node_of(layer: &str, path: &[String], modules: &[String]) -> Option<String> {
    let base = usize::from(layer == "shell");
    if layer == "shell" && path.first().map(String::as_str) != Some("shell") {
        return None;
    }
    modules
        .iter()
        .filter(|m| {
            let segs: Vec<&str> = m.trim_end_matches('/').split('/').collect();
            path.len() >= base + segs.len() && path[base..base + segs.len()] == segs[..]
        })
        .max_by_key(|m| m.len())
        .cloned()
}

/// The modules of `layer` that module `m`'s code (comments aside) names, by any path from the
/// crate's root, `super` or `self`; a folder that is one module (`effects/`) is one node with
/// all its files, and a room's file (`diagnosis.rs`, which only declares the room) none.
fn named_by(layer: &str, m: &str, modules: &[String]) -> Vec<String> {
    let dir = layer_dir(layer);
    let name = m.trim_end_matches('/');
    let files = if m.ends_with('/') {
        if is_room(&dir.join(name)) {
            vec![]
        } else {
            rust_files(&dir.join(name))
        }
    } else {
        vec![dir.join(format!("{name}.rs"))]
    };
    let mut found = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let code: String = text
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        for p in paths_named(&code, &module_path(layer, &f)) {
            if let Some(n) = node_of(layer, &p, modules) {
                if n != m && !found.contains(&n) {
                    found.push(n);
                }
            }
        }
    }
    found.sort();
    found
}

/// The strongly connected components of more than one module (Tarjan), each sorted.
fn circles(graph: &[(String, Vec<String>)]) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a [(String, Vec<String>)],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        stack: Vec<usize>,
        on: Vec<bool>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit(t: &mut T, v: usize) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        for w in &t.g[v].1 {
            let w = t.g.iter().position(|(n, _)| n == w).unwrap();
            match t.index[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(i) if t.on[w] => t.low[v] = t.low[v].min(i),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut c = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on[w] = false;
                c.push(t.g[w].0.clone());
                if w == v {
                    break;
                }
            }
            if c.len() > 1 {
                c.sort();
                t.out.push(c);
            }
        }
    }
    let n = graph.len();
    let mut t = T {
        g: graph,
        index: vec![None; n],
        low: vec![0; n],
        stack: Vec::new(),
        on: vec![false; n],
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(&mut t, v);
        }
    }
    t.out
}

#[test]
fn no_new_circle_of_files_and_the_known_ones_listed() {
    let mut found = Vec::new();
    for (layer, _, _) in LAYERS {
        let modules = modules_of(layer);
        let graph: Vec<(String, Vec<String>)> = modules
            .iter()
            .map(|m| (m.clone(), named_by(layer, m, &modules)))
            .collect();
        for c in circles(&graph) {
            found.push(format!("{layer}: {}", c.join(", ")));
        }
    }
    found.sort();
    assert_eq!(
        found, KNOWN_CIRCLES,
        "the circles of files in the layers (a new one: break it; a listed one gone: strike it \
         from KNOWN_CIRCLES)"
    );
}

#[test]
fn the_circle_finder_finds_circles() {
    let g = |edges: &[(&str, &[&str])]| -> Vec<(String, Vec<String>)> {
        edges
            .iter()
            .map(|(a, bs)| (a.to_string(), bs.iter().map(|b| b.to_string()).collect()))
            .collect()
    };
    let graph = g(&[
        ("a", &["b"]),
        ("b", &["c"]),
        ("c", &["a"]),
        ("d", &["a"]),
        ("e", &[]),
    ]);
    assert_eq!(circles(&graph), [["a", "b", "c"]]);
    assert!(circles(&g(&[("a", &["b"]), ("b", &[])])).is_empty());
}

#[test]
fn the_path_reader_resolves_groups_and_super() {
    let here: Vec<String> = ["shell", "job", "outputs"].map(String::from).to_vec();
    let mut got: Vec<String> = paths_named(
        "use super::super::formats::{input::{self, TableError}, at2};\n\
         let x = crate::kernel::params::G; super::sizing::plan(); my_super::x;",
        &here,
    )
    .iter()
    .map(|p| p.join("::"))
    .collect();
    got.sort();
    got.dedup();
    assert_eq!(
        got,
        [
            "kernel::params::G",
            "shell::formats",
            "shell::formats::at2",
            "shell::formats::input",
            "shell::formats::input::TableError",
            "shell::job::sizing::plan",
        ]
    );
    let modules = ["formats/", "formats/input", "job/", "job/sizing"].map(String::from);
    let input = ["shell", "formats", "input", "TableError"].map(String::from);
    assert_eq!(
        node_of("shell", &input, &modules).as_deref(),
        Some("formats/input")
    );
    assert_eq!(
        node_of("kernel", &input[1..], &modules).as_deref(),
        Some("formats/input")
    );
    let kernel = ["kernel", "params", "G"].map(String::from);
    assert_eq!(node_of("shell", &kernel, &modules), None);
}

// Reading a measured file stays in the shell (issue 49): the readers of src/shell/formats/ use the
// orchestration's plain types and names only (the table they fill, a campaign's column map, the
// record's column names), and call none of its functions; `campaign_io` then hands each file's
// table to the orchestration twice, for its values' ranges and for its alignment.

/// The readers of measured files and what of the orchestration they may name.
const READERS: [&str; 5] = ["input", "measured_files", "headers", "at2", "matlab"];
const PLAIN: [&str; 4] = [
    "measured::aligned::NumTable",
    "measured::campaign::Mapped",
    "runs::quake_spec::AT2_COLUMN",
    "runs::quake_spec::AT2_TIME",
];

/// The orchestration paths `code` names (groups expanded), without the crate's name.
fn orchestration_paths(code: &str) -> Vec<String> {
    let flat: String = code.split_whitespace().collect::<Vec<_>>().join(" ");
    flat.match_indices("orchestration::")
        .flat_map(|(i, _)| expand(&path_at(&flat[i + "orchestration::".len()..])))
        .collect()
}

#[test]
fn reading_a_measured_file_stays_in_the_shell() {
    let dir = layer_dir("shell").join("formats");
    for r in READERS {
        let text = std::fs::read_to_string(dir.join(format!("{r}.rs"))).unwrap();
        let code: String = text
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        for p in orchestration_paths(&code) {
            let plain = |q: &str| q == p || q.starts_with(&format!("{p}::"));
            assert!(
                PLAIN.iter().any(|q| plain(q)),
                "src/shell/formats/{r}.rs names orchestration::{p}: a reader of measured files \
                 uses the orchestration's plain types only (move the work into the shell, or the \
                 vocabulary into the kernel)"
            );
        }
    }
    let io = std::fs::read_to_string(dir.join("campaign_io.rs")).unwrap();
    assert_eq!(
        ["check_limits(", "aligned::align("].map(|c| io.matches(c).count()),
        [1, 1],
        "campaign_io hands each measured file's table to the orchestration twice"
    );
    assert_eq!(
        orchestration_paths("use crate::orchestration::measured::{aligned::NumTable, campaign};"),
        [
            "measured::aligned::NumTable",
            "measured::campaign",
            "measured"
        ]
    );
}
