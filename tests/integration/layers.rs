//! relume's modules are layers: a file may import only from its own layer or a lower one, and
//! no two top-level modules import each other (directly or around a loop). This test reads every
//! `.rs` under `src/`, gives each file its layer by its path ([`LAYERS`], [`layer_of`]), strips
//! comments and literals, finds every path that leaves the file (`crate::…`, `super::…`,
//! `self::…`, `use crate::{a, b}` groups expanded; `relume::…` in the CLI), resolves it to the
//! file that defines the module it names, and fails listing each import that points upward and
//! each cycle between top-level modules.
//!
//! A path is resolved to the deepest module file it names (`crate::gpu::shader::RAY_OFFSET` is
//! `src/gpu/shader/mod.rs`), so a re-export counts as its re-exporting module: a twin importing
//! `crate::gpu::scene::FlatScene` imports the GPU layer even though `FlatScene` is defined in
//! `twin::flat`; it should import `crate::twin::flat::FlatScene`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The layers, lowest first. A file's layer comes from the first row whose module its path is
/// in (`src/<module>.rs` or `src/<module>/…`), except that every twin file is layer 1 wherever
/// it lies: `src/twin/**`, and a `twin.rs` or a file under a `twin/` folder inside a GPU
/// technique's folder (a technique keeps its CPU twin beside it), and every `settings.rs` inside
/// `gpu` is layer 0 (a visibility mode keeps its settings in its folder). A new top-level module
/// must be added here, or the test fails.
///
/// | layer | modules | what |
/// |---|---|---|
/// | 0 | `scene`, `rgbd`, `image`, `val` + `gpu/**/settings.rs` | data: scenes, recordings and frames, images, the VAL, settings |
/// | 1 | `twin` + twin files | the CPU twins: data and twin files only |
/// | 2 | `gpu` | the GPU techniques |
/// | 3 | `renderer` | a frame: the list of techniques |
/// | 4 | `mr`, `bench` | relighting recordings; benchmarks and figures |
/// | 5 | `service` | the HTTP service |
/// | 6 | `cli` (`src/main.rs`, `src/cli/**`) | the binary, which imports the library as `relume::` |
const LAYERS: &[(&str, u8)] = &[
    ("scene", 0),
    ("rgbd", 0),
    ("image", 0),
    ("val", 0),
    ("twin", 1),
    ("gpu", 2),
    ("renderer", 3),
    ("mr", 4),
    ("bench", 4),
    ("service", 5),
    ("cli", 6),
    ("main", 6),
];

/// Layer names for the messages.
const LAYER_NAMES: [&str; 7] = ["data", "twins", "GPU techniques", "renderer", "mr/bench", "service", "CLI"];

/// The layer of the file at `path` (relative to the repository, `/`-separated), or `None` for
/// the crate root `src/lib.rs`, which only declares the modules.
fn layer_of(path: &str) -> Option<Result<u8, String>> {
    let rest = path.strip_prefix("src/").expect("a path under src/");
    if rest == "lib.rs" {
        return None;
    }
    let components: Vec<&str> = rest.split('/').collect();
    let top = components[0].trim_end_matches(".rs");
    let twin_inside = components.iter().any(|c| *c == "twin" || *c == "twin.rs");
    if top == "gpu" && settings_file(&components) {
        return Some(Ok(0));
    }
    if top == "gpu" && twin_inside {
        return Some(Ok(1));
    }
    Some(match LAYERS.iter().find(|(module, _)| *module == top) {
        Some((_, layer)) => Ok(*layer),
        None => Err(format!(
            "{path}: top-level module `{top}` has no layer: add it to LAYERS in tests/integration/layers.rs"
        )),
    })
}

/// Whether a file inside `gpu` is a technique's settings (`settings.rs`: data, layer 0, held by
/// the scene description; the visibility modes keep theirs, and the registry of modes, in
/// their folders).
fn settings_file(components: &[&str]) -> bool {
    components.last() == Some(&"settings.rs")
}

/// The unit of the cycle check: the top-level module, except that a twin file inside `gpu`
/// belongs to `twin` (the twin layer is one unit spread over the techniques' folders, so
/// `twin::bounce` using `gpu::visibility::disks::twin` is not `twin` -> `gpu`).
fn unit_of(path: &str) -> String {
    let rest = path.strip_prefix("src/").unwrap_or(path);
    let components: Vec<&str> = rest.split('/').collect();
    let top = components[0].trim_end_matches(".rs");
    if top == "gpu" && settings_file(&components) {
        return "scene".to_owned();
    }
    if top == "gpu" && components.iter().any(|c| *c == "twin" || *c == "twin.rs") {
        return "twin".to_owned();
    }
    if top == "main" { "cli".to_owned() } else { top.to_owned() }
}

/// `source` with comments, string, byte-string, raw-string and char literals blanked (newlines
/// kept, so line numbers stay).
fn strip(source: &str) -> String {
    let s: Vec<char> = source.chars().collect();
    let mut out = String::with_capacity(source.len());
    let keep_lines = |text: &[char], out: &mut String| {
        for c in text {
            out.push(if *c == '\n' { '\n' } else { ' ' });
        }
    };
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let next = s.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            let end = s[i..].iter().position(|&c| c == '\n').map_or(s.len(), |n| i + n);
            keep_lines(&s[i..end], &mut out);
            i = end;
        } else if c == '/' && next == Some('*') {
            let (mut depth, mut j) = (0usize, i);
            while j < s.len() {
                if s[j] == '/' && s.get(j + 1) == Some(&'*') {
                    depth += 1;
                    j += 2;
                } else if s[j] == '*' && s.get(j + 1) == Some(&'/') {
                    depth -= 1;
                    j += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    j += 1;
                }
            }
            keep_lines(&s[i..j.min(s.len())], &mut out);
            i = j;
        } else if (c == 'r' || (c == 'b' && next == Some('r')))
            && !s.get(i.wrapping_sub(1)).is_some_and(|p| p.is_alphanumeric() || *p == '_')
            && {
                let start = if c == 'b' { i + 2 } else { i + 1 };
                let hashes = s[start..].iter().take_while(|&&h| h == '#').count();
                s.get(start + hashes) == Some(&'"')
            }
        {
            // A raw string: r"…", r#"…"#, br"…".
            let start = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = s[start..].iter().take_while(|&&h| h == '#').count();
            let mut j = start + hashes + 1;
            while j < s.len()
                && !(s[j] == '"' && s[j + 1..].iter().take(hashes).filter(|&&h| h == '#').count() == hashes)
            {
                j += 1;
            }
            let end = (j + 1 + hashes).min(s.len());
            keep_lines(&s[i..end], &mut out);
            i = end;
        } else if c == '"' {
            let mut j = i + 1;
            while j < s.len() && s[j] != '"' {
                j += if s[j] == '\\' { 2 } else { 1 };
            }
            let end = (j + 1).min(s.len());
            keep_lines(&s[i..end], &mut out);
            i = end;
        } else if c == '\'' {
            // A char literal ('x', '\n', '\u{1F600}'), else a lifetime or label ('a).
            let end = if next == Some('\\') {
                s[i + 2..].iter().position(|&c| c == '\'').map(|n| i + 2 + n + 1)
            } else if s.get(i + 2) == Some(&'\'') {
                Some(i + 3)
            } else {
                None
            };
            match end {
                Some(end) => {
                    keep_lines(&s[i..end], &mut out);
                    i = end;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// One path leaving a file: its root (`crate`, `super`, `self`, `relume`; `super` repeated as
/// many times as written), its segments after the root, and its line.
#[derive(Clone, Debug, PartialEq)]
struct PathRef {
    root: String,
    supers: usize,
    segments: Vec<String>,
    line: usize,
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Every path in stripped `code` that starts with `crate::`, `super::`, `self::` or `relume::`,
/// `{…}` groups expanded (`use crate::{a::b, c::{d, e}}` is `crate::a::b`, `crate::c::d`,
/// `crate::c::e`). Also the module paths of inline `mod name {` blocks, by position, so that a
/// `super::` inside one is resolved from there.
fn paths(code: &str) -> Vec<(PathRef, Vec<String>)> {
    let s: Vec<char> = code.chars().collect();
    let mut found = Vec::new();
    // Inline modules: (brace depth at which it closes, name).
    let mut inline: Vec<(usize, String)> = Vec::new();
    let mut depth = 0usize;
    let mut line = 1;
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        if c == '\n' {
            line += 1;
        }
        if c == '{' {
            depth += 1;
        }
        if c == '}' {
            depth = depth.saturating_sub(1);
            while inline.last().is_some_and(|(d, _)| *d > depth) {
                inline.pop();
            }
        }
        let at_word = !s.get(i.wrapping_sub(1)).is_some_and(|p| is_ident(*p) || *p == ':' || *p == '$');
        if at_word && is_ident(c) {
            let word: String = s[i..].iter().take_while(|c| is_ident(**c)).collect();
            let after = i + word.chars().count();
            if word == "mod" {
                // `mod name {`: an inline module.
                let rest: String = s[after..].iter().take(200).collect();
                let name: String = rest.trim_start().chars().take_while(|c| is_ident(*c)).collect();
                let tail = rest.trim_start()[name.len()..].trim_start();
                if !name.is_empty() && tail.starts_with('{') {
                    inline.push((depth + 1, name));
                }
            }
            if ["crate", "super", "self", "relume"].contains(&word.as_str()) && s[after..].starts_with(&[':', ':']) {
                let mut root = word.clone();
                let mut supers = usize::from(word == "super");
                let mut j = after + 2;
                // `super::super::…`
                while root == "super" && s[j..].starts_with(&['s', 'u', 'p', 'e', 'r', ':', ':']) {
                    supers += 1;
                    j += 7;
                }
                if root == "self" && s[j..].starts_with(&['s', 'u', 'p', 'e', 'r', ':', ':']) {
                    root = "super".to_owned();
                    supers = 1;
                    j += 7;
                }
                let (tails, end) = tree(&s, j);
                let inline_path: Vec<String> = inline.iter().map(|(_, n)| n.clone()).collect();
                for segments in tails {
                    found.push((PathRef { root: root.clone(), supers, segments, line }, inline_path.clone()));
                }
                for c in &s[i..end] {
                    if *c == '\n' {
                        line += 1;
                    }
                }
                i = end;
                continue;
            }
            i = after;
            continue;
        }
        i += 1;
    }
    found
}

/// The path tree at `s[i..]` (after a `::`): `a::b::c`, `a::{b, c::d}`, `{…}`, `*`; every
/// complete path's segments and where the tree ends.
fn tree(s: &[char], mut i: usize) -> (Vec<Vec<String>>, usize) {
    let skip_space = |i: &mut usize| {
        while *i < s.len() && s[*i].is_whitespace() {
            *i += 1;
        }
    };
    let mut prefix = Vec::new();
    loop {
        skip_space(&mut i);
        if s.get(i) == Some(&'{') {
            let mut all = Vec::new();
            i += 1;
            loop {
                skip_space(&mut i);
                match s.get(i) {
                    Some('}') => {
                        i += 1;
                        break;
                    }
                    Some(',') => i += 1,
                    None => break,
                    _ => {
                        let (tails, end) = tree(s, i);
                        if end == i {
                            i += 1;
                        } else {
                            i = end;
                        }
                        for t in tails {
                            all.push(prefix.iter().cloned().chain(t).collect());
                        }
                    }
                }
            }
            if all.is_empty() {
                all.push(prefix);
            }
            return (all, i);
        }
        let word: String = s[i..].iter().take_while(|c| is_ident(**c)).collect();
        if word.is_empty() {
            // `*`, or the end of the path.
            if s.get(i) == Some(&'*') {
                i += 1;
            }
            return (vec![prefix], i);
        }
        i += word.chars().count();
        if word != "self" {
            prefix.push(word);
        }
        if s[i..].starts_with(&[':', ':']) {
            i += 2;
            continue;
        }
        // `as name` renames the last segment; the module is the same.
        let mut j = i;
        skip_space(&mut j);
        if s[j..].starts_with(&['a', 's']) && s.get(j + 2).is_some_and(|c| c.is_whitespace()) {
            j += 2;
            skip_space(&mut j);
            i = j + s[j..].iter().take_while(|c| is_ident(**c)).count();
        }
        return (vec![prefix], i);
    }
}

/// The module path of the file at `path` (`src/gpu/visibility/ism/twin.rs`: gpu, visibility,
/// ism, twin; `src/gpu/mod.rs`: gpu; `src/lib.rs`, `src/main.rs`: the root).
fn module_of(path: &str) -> Vec<String> {
    let rest = path.strip_prefix("src/").unwrap_or(path).trim_end_matches(".rs");
    let mut parts: Vec<String> = rest.split('/').map(str::to_owned).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        parts.pop();
    }
    parts
}

/// The file that defines the deepest module `module` names (`gpu::shader::RAY_OFFSET`:
/// `src/gpu/shader/mod.rs`), among `files`.
fn file_of(module: &[String], files: &BTreeSet<String>) -> Option<String> {
    (1..=module.len()).rev().find_map(|n| {
        let joined = module[..n].join("/");
        [format!("src/{joined}.rs"), format!("src/{joined}/mod.rs")].into_iter().find(|f| files.contains(f))
    })
}

/// What one file imports: (line, whether by `crate::`, imported module path, the file defining
/// it).
fn imports(path: &str, source: &str, files: &BTreeSet<String>) -> Vec<(usize, bool, Vec<String>, Option<String>)> {
    let own = module_of(path);
    let cli = layer_of(path).and_then(Result::ok) == Some(6);
    paths(&strip(source))
        .into_iter()
        .filter_map(|(p, inline)| {
            let module: Vec<String> = match p.root.as_str() {
                "relume" if cli => p.segments.clone(),
                "relume" => return None,
                "crate" => p.segments.clone(),
                _ => {
                    let mut here: Vec<String> = own.iter().chain(&inline).cloned().collect();
                    for _ in 0..p.supers {
                        here.pop();
                    }
                    here.into_iter().chain(p.segments.clone()).collect()
                }
            };
            let file = file_of(&module, files);
            Some((p.line, p.root == "crate", module, file))
        })
        .collect()
}

/// Every upward import and every cycle between units in the tree `sources` (path -> source).
fn violations(sources: &BTreeMap<String, String>) -> Vec<String> {
    let files: BTreeSet<String> = sources.keys().cloned().collect();
    let mut problems = Vec::new();
    let mut edges: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for (path, source) in sources {
        let layer = match layer_of(path) {
            None => continue,
            Some(Err(e)) => {
                problems.push(e);
                continue;
            }
            Some(Ok(layer)) => layer,
        };
        for (line, by_crate, _, file) in imports(path, source, &files) {
            let Some(file) = file else { continue };
            if file == *path {
                continue;
            }
            let name = module_of(&file).join("::");
            if layer == 6 && by_crate && unit_of(&file) != "cli" {
                problems.push(format!("{path}:{line}: the CLI imports the library as `relume::{name}`, not `crate::`"));
                continue;
            }
            let Some(Ok(their)) = layer_of(&file) else { continue };
            if their > layer {
                problems.push(format!(
                    "{path}:{line}: imports {name} (layer {their}, {}) from layer {layer} ({})",
                    LAYER_NAMES[their as usize], LAYER_NAMES[layer as usize]
                ));
            }
            let (from, to) = (unit_of(path), unit_of(&file));
            if from != to {
                edges.entry(from).or_default().entry(to).or_insert_with(|| format!("{path}:{line} imports {name}"));
            }
        }
    }
    problems.extend(cycles(&edges));
    // One message per import, however many names a `{…}` group takes from the module.
    let mut seen = BTreeSet::new();
    problems.retain(|p| seen.insert(p.clone()));
    problems
}

/// Every cycle among the units: for each strongly connected group of two or more, one message
/// naming its members and an import behind each edge inside it.
fn cycles(edges: &BTreeMap<String, BTreeMap<String, String>>) -> Vec<String> {
    let nodes: BTreeSet<&String> = edges.keys().chain(edges.values().flat_map(|m| m.keys())).collect();
    let reaches = |from: &String| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(n) = stack.pop() {
            for next in edges.get(&n).into_iter().flat_map(|m| m.keys()) {
                if seen.insert(next.clone()) {
                    stack.push(next.clone());
                }
            }
        }
        seen
    };
    let reach: BTreeMap<&String, BTreeSet<String>> = nodes.iter().map(|n| (*n, reaches(n))).collect();
    let mut reported = BTreeSet::new();
    let mut problems = Vec::new();
    for n in &nodes {
        let group: BTreeSet<String> =
            nodes.iter().filter(|m| reach[*n].contains(**m) && reach[*m].contains(*n)).map(|m| (*m).clone()).collect();
        if group.len() < 2 || !reported.insert(group.clone()) {
            continue;
        }
        let behind: Vec<String> = group
            .iter()
            .flat_map(|a| {
                edges[a].iter().filter(|(b, _)| group.contains(*b)).map(move |(b, why)| format!("{a} -> {b} ({why})"))
            })
            .collect();
        problems.push(format!(
            "import cycle between top-level modules {}: {}",
            group.into_iter().collect::<Vec<_>>().join(", "),
            behind.join("; ")
        ));
    }
    problems
}

/// Every `.rs` under `dir`, by path relative to the repository.
fn read_tree(root: &Path, dir: &Path, out: &mut BTreeMap<String, String>) {
    let mut entries: Vec<_> =
        std::fs::read_dir(dir).expect("readable src/").map(|e| e.expect("entry").path()).collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            read_tree(root, &path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let relative = path.strip_prefix(root).expect("under the root").to_string_lossy().replace('\\', "/");
            out.insert(relative, std::fs::read_to_string(&path).expect("readable source"));
        }
    }
}

#[test]
fn layers_no_module_imports_a_higher_layer_and_no_cycle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sources = BTreeMap::new();
    read_tree(root, &root.join("src"), &mut sources);
    assert!(sources.len() > 100, "read {} files under src/", sources.len());
    let problems = violations(&sources);
    assert!(problems.is_empty(), "{} layering problems:\n{}", problems.len(), problems.join("\n"));
}

fn tree_of(files: &[(&str, &str)]) -> BTreeMap<String, String> {
    files.iter().map(|(p, s)| (p.to_string(), s.to_string())).collect()
}

/// The checker itself: on a small tree, an upward import (a twin using the GPU layer, through
/// `crate::` in a group and through `super::`) is reported with its file, line and layers;
/// downward and sideways imports are not.
#[test]
fn layers_checker_reports_upward_imports() {
    let sources = tree_of(&[
        ("src/lib.rs", "pub mod gpu; pub mod twin; pub mod scene;"),
        ("src/scene/mod.rs", "pub struct Scene;"),
        ("src/twin/mod.rs", "use crate::scene::Scene;\npub mod bounce;"),
        ("src/twin/bounce.rs", "// crate::gpu in a comment\nuse crate::{scene, gpu::shader::RAY};\n"),
        ("src/gpu/mod.rs", "pub mod shader; pub mod ism; use crate::twin;"),
        ("src/gpu/shader/mod.rs", "pub const RAY: f32 = 1.0; const S: &str = \"crate::renderer\";"),
        ("src/gpu/ism/mod.rs", "pub mod twin; pub struct P;"),
        (
            "src/gpu/ism/twin.rs",
            "use crate::twin::bounce;\nuse super::P;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
    ]);
    let problems = violations(&sources);
    assert_eq!(
        problems,
        vec![
            "src/gpu/ism/twin.rs:2: imports gpu::ism (layer 2, GPU techniques) from layer 1 (twins)".to_owned(),
            "src/twin/bounce.rs:2: imports gpu::shader (layer 2, GPU techniques) from layer 1 (twins)".to_owned(),
            "import cycle between top-level modules gpu, twin: gpu -> twin (src/gpu/mod.rs:1 imports twin); \
             twin -> gpu (src/gpu/ism/twin.rs:2 imports gpu::ism)"
                .to_owned(),
        ]
    );
}

/// A cycle between two modules of the same layer is reported, and the data layer reaching up is
/// reported whichever module it reaches.
#[test]
fn layers_checker_reports_cycles_and_the_data_layer_reaching_up() {
    let sources = tree_of(&[
        ("src/mr/mod.rs", "use crate::bench::Plot;"),
        ("src/bench/mod.rs", "pub struct Plot; use crate::mr;"),
        ("src/scene/mod.rs", "use crate::mr::Settings; use crate::gpu::Gpu;"),
        ("src/gpu/mod.rs", "pub struct Gpu;"),
    ]);
    let problems = violations(&sources);
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert_eq!(problems[0], "src/scene/mod.rs:1: imports mr (layer 4, mr/bench) from layer 0 (data)");
    assert_eq!(problems[1], "src/scene/mod.rs:1: imports gpu (layer 2, GPU techniques) from layer 0 (data)");
    assert!(problems[2].starts_with("import cycle between top-level modules bench, mr: "), "{}", problems[2]);
}

#[test]
fn layers_paths_expand_groups_and_skip_literals() {
    let code = strip(
        "use crate::{a::b, c::{d, e as f}, self};\nlet x = 'c'; let s = r#\"crate::no\"#; fn f<'a>() {}\n\
         /* crate::no /* nested */ crate::no */ use super::super::g::*;",
    );
    let found: Vec<(String, usize, String, usize)> =
        paths(&code).into_iter().map(|(p, _)| (p.root, p.supers, p.segments.join("::"), p.line)).collect();
    assert_eq!(
        found,
        vec![
            ("crate".to_owned(), 0, "a::b".to_owned(), 1),
            ("crate".to_owned(), 0, "c::d".to_owned(), 1),
            ("crate".to_owned(), 0, "c::e".to_owned(), 1),
            ("crate".to_owned(), 0, String::new(), 1),
            ("super".to_owned(), 2, "g".to_owned(), 3),
        ]
    );
}

/// An unknown top-level module fails the test until it is given a layer.
#[test]
fn layers_every_top_level_module_has_a_layer() {
    let problems = violations(&tree_of(&[("src/newthing.rs", "")]));
    assert_eq!(problems.len(), 1);
    assert!(problems[0].contains("top-level module `newthing` has no layer"), "{}", problems[0]);
}

/// The CLI is the binary crate: it reaches the library as `relume::`, whose modules are all
/// below it; a `crate::` path there can only name its own `cli` modules.
#[test]
fn layers_the_cli_imports_the_library_as_relume() {
    let sources = tree_of(&[
        ("src/main.rs", "mod cli;"),
        ("src/cli/mod.rs", "use relume::gpu::Gpu;\nuse crate::cli::render;\nuse crate::gpu::Gpu;"),
        ("src/cli/render.rs", "use super::Cli;"),
        ("src/gpu/mod.rs", "pub struct Gpu;"),
    ]);
    assert_eq!(
        violations(&sources),
        vec!["src/cli/mod.rs:3: the CLI imports the library as `relume::gpu`, not `crate::`".to_owned()]
    );
}
