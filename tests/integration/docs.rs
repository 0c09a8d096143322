//! The documentation holds together: the README stays a guide (short), no page or source file
//! names a ticket instead of saying what it means, every file the code cites exists (and every
//! section of the design it cites), and every relative link of the README and `docs/` resolves,
//! anchors included. Pure file reading: no GPU.
//!
//! Each check is a function over text, so the unit tests at the end can show it failing on a
//! bad input; the repository checks then run the same functions over the real files.

use std::collections::HashSet;
use std::fs;
use std::path::{Component, Path, PathBuf};

/// The README is a user's guide; the reference pages live in `docs/`.
const README_MAX_LINES: usize = 450;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every file under `dir` (recursively) whose name ends with `suffix` (any file for ""),
/// skipping hidden directories and installed packages.
fn files_under(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = fs::read_dir(&d).unwrap_or_else(|e| panic!("reading {}: {e}", d.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if path.is_dir() {
                if !name.starts_with('.') && name != "node_modules" && name != "target" {
                    stack.push(path);
                }
            } else if name.ends_with(suffix) {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// A file's text; binary files read lossily (a ticket number in them would still show).
fn read(path: &Path) -> String {
    let bytes = fs::read(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    String::from_utf8_lossy(&bytes).into_owned()
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root()).unwrap_or(path).display().to_string()
}

/// The README and every Markdown page under `docs/`.
fn markdown_pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    pages.extend(files_under(&root().join("docs"), ".md"));
    pages
}

// ---- (b) ticket numbers -------------------------------------------------------------------

/// 1-based line numbers where "issue" or "issues" (any case of the first letter) is followed by
/// one space and a digit, as a whole word ("tissue 3" does not count).
fn ticket_references(text: &str) -> Vec<usize> {
    let mut lines = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let bytes = line.as_bytes();
        let mut start = 0;
        while let Some(found) = line[start..].find("ssue") {
            let s = start + found; // index of "ssue"
            start = s + 4;
            if s == 0 || !matches!(bytes[s - 1], b'i' | b'I') {
                continue;
            }
            let word_start = s - 1;
            if word_start > 0 && (bytes[word_start - 1].is_ascii_alphanumeric() || bytes[word_start - 1] == b'_') {
                continue;
            }
            let mut after = s + 4;
            if bytes.get(after) == Some(&b's') {
                after += 1;
            }
            if bytes.get(after) == Some(&b' ') && bytes.get(after + 1).is_some_and(|b| b.is_ascii_digit()) {
                lines.push(n + 1);
                break;
            }
        }
    }
    lines
}

// ---- (c) files and sections the code cites ------------------------------------------------

/// A Markdown file cited in code: the path token, and the sections cited with it.
#[derive(Debug, PartialEq)]
struct Citation {
    path: String,
    line: usize,
    /// `§N` sections, each with the `step M` items cited in it.
    sections: Vec<(u32, Vec<u32>)>,
    /// Headings cited by title: `docs/rgbd.md "Recording layouts"`.
    titles: Vec<String>,
}

fn is_path_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'/' | b'-')
}

/// Reads a run of ASCII digits at `*i`, advancing past it.
fn digits(s: &[u8], i: &mut usize) -> Option<u32> {
    let start = *i;
    while *i < s.len() && s[*i].is_ascii_digit() {
        *i += 1;
    }
    std::str::from_utf8(&s[start..*i]).ok()?.parse().ok()
}

fn eat(s: &[u8], i: &mut usize, word: &str) -> bool {
    if s[*i..].starts_with(word.as_bytes()) {
        *i += word.len();
        true
    } else {
        false
    }
}

/// What follows a cited path on its line: `§2`, `§2-§4`, `§1-3`, `§4 step 2`,
/// `§4 steps 0, 2, 4`, `"Title"`, several of them separated by ", " (`§2 "RGB-D frames", §6`).
/// Anything else ends the list.
fn parse_references(rest: &str, sections: &mut Vec<(u32, Vec<u32>)>, titles: &mut Vec<String>) {
    let s = rest.as_bytes();
    let mut i = 0;
    loop {
        while i < s.len() && s[i] == b' ' {
            i += 1;
        }
        if eat(s, &mut i, "§") {
            let Some(first) = digits(s, &mut i) else { return };
            let mut last = first;
            if i < s.len() && s[i] == b'-' {
                let mut j = i + 1;
                eat(s, &mut j, "§");
                if let Some(n) = digits(s, &mut j) {
                    last = n;
                    i = j;
                }
            }
            let mut steps = Vec::new();
            if eat(s, &mut i, " steps ") || eat(s, &mut i, " step ") {
                while let Some(n) = digits(s, &mut i) {
                    steps.push(n);
                    let mut j = i;
                    if (eat(s, &mut j, ", ") || eat(s, &mut j, " and ")) && j < s.len() && s[j].is_ascii_digit() {
                        i = j;
                    } else {
                        break;
                    }
                }
            }
            for n in first..=last.max(first) {
                sections.push((n, if n == first { steps.clone() } else { Vec::new() }));
            }
            while i < s.len() && s[i] == b' ' {
                i += 1;
            }
        }
        if i < s.len() && s[i] == b'"' {
            let Some(len) = rest[i + 1..].find('"') else { return };
            titles.push(rest[i + 1..i + 1 + len].to_string());
            i += len + 2;
        }
        if !eat(s, &mut i, ", ") || !(rest[i..].starts_with('§') || rest[i..].starts_with('"')) {
            return;
        }
    }
}

/// Every Markdown path cited in `text`: a token of path characters ending in `.md` that holds a
/// `/` (`docs/design.md`) or is `README.md`. Bare names such as a fixture's `SOURCE.md` are
/// relative to something else and are not citations of the repository's pages.
fn citations(text: &str) -> Vec<Citation> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let bytes = line.as_bytes();
        let mut i = 0;
        while let Some(found) = line[i..].find(".md") {
            let end = i + found + 3;
            i = end;
            if bytes.get(end).is_some_and(|&b| b.is_ascii_alphanumeric() || b == b'_') {
                continue; // ".mdx", ".md_file": not a Markdown path
            }
            let mut start = end - 3;
            while start > 0 && is_path_byte(bytes[start - 1]) {
                start -= 1;
            }
            let path = line[start..end].trim_start_matches("./").to_string();
            if !(path.contains('/') || path == "README.md") {
                continue;
            }
            let mut sections = Vec::new();
            let mut titles = Vec::new();
            parse_references(&line[end..], &mut sections, &mut titles);
            out.push(Citation { path, line: n + 1, sections, titles });
        }
    }
    out
}

/// The text of each heading line (`#`s and surrounding spaces removed), outside code blocks.
fn headings(markdown: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for line in markdown.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced || !trimmed.starts_with('#') {
            continue;
        }
        let level = trimmed.bytes().take_while(|&b| b == b'#').count();
        let text = trimmed[level..].trim();
        if level <= 6 && trimmed[level..].starts_with(' ') {
            out.push((level, text.to_string()));
        }
    }
    out
}

/// What is wrong with one citation, if anything, given a way to read the cited file.
fn citation_problems(c: &Citation, read_cited: &dyn Fn(&str) -> Option<String>) -> Vec<String> {
    let Some(text) = read_cited(&c.path) else {
        return vec![format!("cites {}, which does not exist", c.path)];
    };
    let heads = headings(&text);
    let mut problems = Vec::new();
    for (section, steps) in &c.sections {
        let prefix = format!("{section}. ");
        let Some(at) = heads.iter().position(|(level, t)| *level == 2 && t.starts_with(&prefix)) else {
            problems.push(format!("cites {} §{section}, which has no heading `## {section}.`", c.path));
            continue;
        };
        let end = heads[at + 1..].iter().position(|(level, _)| *level <= 2).map_or(heads.len(), |p| at + 1 + p);
        for step in steps {
            let step_prefix = format!("Step {step}.");
            if !heads[at + 1..end].iter().any(|(_, t)| t.starts_with(&step_prefix)) {
                problems.push(format!(
                    "cites {} §{section} step {step}, which §{section} has no heading `Step {step}.` for",
                    c.path
                ));
            }
        }
    }
    for title in &c.titles {
        if !heads.iter().any(|(_, t)| t == title) {
            problems.push(format!("cites {} \"{title}\", which has no such heading", c.path));
        }
    }
    problems
}

// ---- (d) links ----------------------------------------------------------------------------

/// GitHub's anchor for a heading: lower case, letters, digits, `_` and `-` kept, spaces become
/// `-`, everything else dropped; a repeated anchor gets `-1`, `-2`, ...
fn anchors(markdown: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for (_, text) in headings(markdown) {
        let base: String = text
            .chars()
            .flat_map(char::to_lowercase)
            .filter_map(|c| match c {
                ' ' => Some('-'),
                c if c.is_alphanumeric() || c == '_' || c == '-' => Some(c),
                _ => None,
            })
            .collect();
        let mut anchor = base.clone();
        let mut n = 0;
        while !seen.insert(anchor.clone()) {
            n += 1;
            anchor = format!("{base}-{n}");
        }
    }
    seen
}

/// Every link target `](target)` of a Markdown text with its line, outside code blocks and
/// inline code.
fn link_targets(markdown: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (n, line) in markdown.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Drop inline code spans: a link's syntax inside backticks is text.
        let mut prose = String::new();
        for (k, part) in line.split('`').enumerate() {
            if k % 2 == 0 {
                prose.push_str(part);
            }
        }
        let mut rest = prose.as_str();
        while let Some(at) = rest.find("](") {
            let after = &rest[at + 2..];
            let Some(close) = after.find(')') else { break };
            let target = after[..close].split_whitespace().next().unwrap_or("").to_string();
            out.push((n + 1, target));
            rest = &after[close..];
        }
    }
    out
}

/// `path` joined onto `dir` with `.` and `..` resolved lexically, or None when it climbs out.
fn join_lexically(dir: &Path, path: &str) -> Option<PathBuf> {
    let mut parts: Vec<Component> = dir.components().collect();
    for component in Path::new(path).components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::Normal(_) => parts.push(component),
            _ => return None,
        }
    }
    Some(parts.iter().collect())
}

/// What is wrong with the links of one page. `page` is its path relative to the repository
/// root; `read_file` gives a file's text by its path relative to the root (None: missing),
/// `exists` whether any file or folder is there.
fn link_problems(
    page: &str,
    markdown: &str,
    read_file: &dyn Fn(&str) -> Option<String>,
    exists: &dyn Fn(&str) -> bool,
) -> Vec<String> {
    let dir = Path::new(page).parent().unwrap_or(Path::new(""));
    let mut problems = Vec::new();
    for (line, target) in link_targets(markdown) {
        if target.starts_with("http://") || target.starts_with("https://") || target.starts_with("mailto:") {
            continue;
        }
        let (path, anchor) = match target.split_once('#') {
            Some((p, a)) => (p, Some(a)),
            None => (target.as_str(), None),
        };
        let file = if path.is_empty() {
            page.to_string()
        } else {
            match join_lexically(dir, path) {
                Some(p) => p.display().to_string(),
                None => {
                    problems.push(format!("{page}:{line}: link {target} climbs out of the repository"));
                    continue;
                }
            }
        };
        if target.is_empty() || (!path.is_empty() && !exists(&file)) {
            problems.push(format!("{page}:{line}: link {target} points at {file}, which does not exist"));
            continue;
        }
        if let Some(anchor) = anchor {
            if !file.ends_with(".md") {
                continue;
            }
            let text = if path.is_empty() { Some(markdown.to_string()) } else { read_file(&file) };
            if !text.is_some_and(|t| anchors(&t).contains(anchor)) {
                problems.push(format!("{page}:{line}: link {target}: {file} has no heading with the anchor #{anchor}"));
            }
        }
    }
    problems
}

fn read_from_root(path: &str) -> Option<String> {
    fs::read_to_string(root().join(path)).ok()
}

fn exists_from_root(path: &str) -> bool {
    root().join(path).exists()
}

// ---- the checks on the repository ---------------------------------------------------------

#[test]
fn readme_is_a_guide_of_at_most_450_lines() {
    let lines = read(&root().join("README.md")).lines().count();
    assert!(
        lines <= README_MAX_LINES,
        "README.md has {lines} lines, over {README_MAX_LINES}: move reference material into docs/"
    );
}

#[test]
fn no_page_or_source_file_names_a_ticket_number() {
    let mut files = markdown_pages();
    files.extend(files_under(&root().join("src"), ""));
    let found: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let text = read(f);
            ticket_references(&text).into_iter().map(move |n| format!("{}:{n}", relative(f)))
        })
        .collect();
    assert!(found.is_empty(), "ticket numbers (say what, not which ticket) at:\n{}", found.join("\n"));
}

#[test]
fn every_page_and_section_the_code_cites_exists() {
    let mut files = files_under(&root().join("src"), "");
    files.extend(files_under(&root().join("tests"), ""));
    let mut problems = Vec::new();
    let mut cited = 0;
    for f in &files {
        for c in citations(&read(f)) {
            cited += 1;
            for p in citation_problems(&c, &read_from_root) {
                problems.push(format!("{}:{}: {p}", relative(f), c.line));
            }
        }
    }
    assert!(cited > 0, "no citation of docs/ found in src/ or tests/: is the scan broken?");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn every_relative_link_of_the_readme_and_docs_resolves() {
    let mut problems = Vec::new();
    let mut links = 0;
    for page in markdown_pages() {
        let text = read(&page);
        links += link_targets(&text).len();
        problems.extend(link_problems(&relative(&page), &text, &read_from_root, &exists_from_root));
    }
    assert!(links > 0, "no link found: is the scan broken?");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

// ---- each check fails on a bad input --------------------------------------------------------
//
// The paths below are assembled at run time: written out, they would be citations of pages
// that do not exist, which the scan of tests/ above would rightly report.

fn under(parts: &[&str]) -> String {
    parts.join("/")
}

#[test]
fn ticket_references_are_found_and_ordinary_words_are_not() {
    let text = "fine\nsee issue 15\n(Issue 17)\nissues 3 and 4\nissue-free\ntissue 3\nan issue\nissue #4";
    assert_eq!(ticket_references(text), vec![2, 3, 4]);
}

#[test]
fn citations_name_their_sections_steps_and_titles() {
    let design = under(&["docs", "design.md"]);
    let rgbd = under(&["docs", "rgbd.md"]);
    let text = format!(
        "// ({design} §2 \"RGB-D frames\", §6): x\n// ({design} §4 steps 0, 2, 4). y\n// {design} §1-3; {rgbd} \"Recording layouts\"\n// SOURCE.md and {design}'s reflect"
    );
    let found = citations(&text);
    assert_eq!(found.len(), 5, "{found:?}");
    assert_eq!(found[0].sections, vec![(2, vec![]), (6, vec![])]);
    assert_eq!(found[0].titles, vec!["RGB-D frames".to_string()]);
    assert_eq!(found[1].sections, vec![(4, vec![0, 2, 4])]);
    assert_eq!(found[2].sections, vec![(1, vec![]), (2, vec![]), (3, vec![])]);
    assert_eq!(found[3].titles, vec!["Recording layouts".to_string()]);
    assert!(found[4].sections.is_empty() && found[4].path == design);
}

#[test]
fn citation_problems_catch_missing_files_sections_steps_and_titles() {
    let page_path = under(&["docs", "page.md"]);
    let page = "# Design\n## 1. Units\n## 4. Pipeline\n### Step 0. Load\n### Step 1. Gather\n## 5. References\n### Step 2. Not in four\n";
    let reader = |p: &str| (p == page_path).then(|| page.to_string());
    let check =
        |text: &str| -> Vec<String> { citations(text).iter().flat_map(|c| citation_problems(c, &reader)).collect() };
    assert!(check(&format!("{page_path} §1, §4 step 1")).is_empty());
    assert_eq!(check(&format!("{page_path} §2")).len(), 1, "a missing section");
    assert_eq!(check(&format!("{page_path} §4 step 2")).len(), 1, "a step of another section");
    assert_eq!(check(&format!("{page_path} \"Units\"")).len(), 1, "a title that is not a heading");
    assert!(check(&format!("{page_path} \"1. Units\"")).is_empty());
    assert_eq!(check(&under(&["docs", "gone.md"])).len(), 1, "a missing file");
}

#[test]
fn anchors_follow_githubs_rule() {
    let a = anchors(
        "# Top\n## 4. The sparse shading pipeline (per frame)\n### Step 3. Occlusion\n## VALs from every light's RSM\n## The scene's `light`\n## Top\n```\n# not a heading\n```\n",
    );
    for expected in [
        "top",
        "4-the-sparse-shading-pipeline-per-frame",
        "step-3-occlusion",
        "vals-from-every-lights-rsm",
        "the-scenes-light",
        "top-1",
    ] {
        assert!(a.contains(expected), "{expected} missing from {a:?}");
    }
    assert!(!a.contains("not-a-heading"));
}

#[test]
fn link_problems_catch_missing_files_and_anchors() {
    let page = under(&["docs", "b.md"]);
    let files = [(under(&["docs", "a.md"]), "# A\n## Here\n"), (under(&["docs", "images", "x.png"]), "")];
    let read_file = |p: &str| files.iter().find(|(f, _)| f == p).map(|(_, t)| t.to_string());
    let exists = |p: &str| files.iter().any(|(f, _)| f == p) || p == under(&["docs", "images"]);
    let check = |text: &str| link_problems(&page, text, &read_file, &exists);
    let good = "[a](a.md) [h](a.md#here) ![x](images/x.png) [w](https://example.com/x) `[c](gone.md)`\n```\n[d](gone.md)\n```\n## Self\n[s](#self)";
    assert!(check(good).is_empty(), "{:?}", check(good));
    assert_eq!(check("[a](gone.md)").len(), 1, "a missing file");
    assert_eq!(check("[a](a.md#there)").len(), 1, "a missing anchor");
    assert_eq!(check("[a](#nowhere)").len(), 1, "a missing anchor on the page itself");
    assert_eq!(check(&format!("[a]({})", under(&["..", "..", "..", "a.md"]))).len(), 1, "a path out of the repository");
    assert_eq!(
        check(&format!("![x]({})", under(&["..", "images", "x.png"]))).len(),
        1,
        "a path relative to the wrong folder"
    );
}
