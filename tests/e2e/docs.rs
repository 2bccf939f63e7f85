//! The documents cannot drift from the tree or from the code.
//!
//! Links: every relative Markdown link in README.md, ARCHITECTURE.md, `docs/**/*.md` and web/PROTOCOL.md
//! (the book's sources included) must lead to a file or folder of the tree, and every `#anchor` to a
//! heading of its target (or of the same document), with headings turned into anchors the way GitHub
//! and mdBook both do it; so must every file a chapter includes (`{{#include …}}`). Code blocks and code
//! spans are not read for links. No network: links with a scheme (`https:`, `mailto:`) are left alone.
//!
//! The websocket protocol (`protocol`): the message names and fields web/PROTOCOL.md documents, against
//! what the server sends and the core's serde names.

mod protocol;

use std::collections::{BTreeSet, HashMap};
use std::path::{Component, Path, PathBuf};

pub(crate) fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

/// The documents whose links are checked, relative to the root.
fn documents(root: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut out = vec![
        root.join("README.md"),
        root.join("ARCHITECTURE.md"),
        root.join("web/PROTOCOL.md"),
    ];
    walk(&root.join("docs"), &mut out);
    out.sort();
    out
}

/// The text with fenced code blocks blanked out (lines kept, so line numbers stay right).
pub(crate) fn without_fences(text: &str) -> Vec<String> {
    let mut fence: Option<String> = None;
    let mut out = Vec::new();
    for line in text.lines() {
        let trimmed = line.trim_start();
        let marker: String = trimmed
            .chars()
            .take_while(|&c| c == '`' || c == '~')
            .collect();
        match &fence {
            Some(open) => {
                if marker.len() >= open.len() && marker.starts_with(&open[..1]) {
                    fence = None;
                }
                out.push(String::new());
            }
            None if marker.len() >= 3 => {
                fence = Some(marker);
                out.push(String::new());
            }
            None => out.push(line.to_string()),
        }
    }
    out
}

/// A line with its code spans removed.
fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    let mut rest = line;
    while let Some(at) = rest.find('`') {
        out.push_str(&rest[..at]);
        let ticks = rest[at..].chars().take_while(|&c| c == '`').count();
        let after = &rest[at + ticks..];
        let closing = "`".repeat(ticks);
        match after.find(&closing) {
            Some(end) => rest = &after[end + ticks..],
            None => {
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// The anchor GitHub and mdBook give a heading: its text without Markdown (code ticks, link targets,
/// emphasis), lower case, spaces to `-`, everything but letters, digits, `-` and `_` dropped.
pub(crate) fn slug(heading: &str) -> String {
    // Links keep their text: `[text](target)` → `text`.
    let mut text = String::new();
    let mut rest = heading;
    while let Some(open) = rest.find('[') {
        match rest[open..].find("](") {
            Some(mid) => {
                let close = rest[open + mid..].find(')').map(|c| open + mid + c);
                match close {
                    Some(close) => {
                        text.push_str(&rest[..open]);
                        text.push_str(&rest[open + 1..open + mid]);
                        rest = &rest[close + 1..];
                    }
                    None => break,
                }
            }
            None => break,
        }
    }
    text.push_str(rest);
    text.trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// Every anchor of a Markdown document: its headings' slugs (a repeated one gets `-1`, `-2`, …).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut out = BTreeSet::new();
    for line in without_fences(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if !(1..=6).contains(&hashes) || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = slug(line[hashes..].trim().trim_end_matches('#'));
        let n = seen.entry(base.clone()).or_insert(0);
        out.insert(if *n == 0 {
            base.clone()
        } else {
            format!("{base}-{n}")
        });
        *n += 1;
    }
    out
}

/// The link targets of a document with their line numbers: inline links `[text](target)` and reference
/// definitions `[label]: target`, outside code.
pub(crate) fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (i, line) in without_fences(text).iter().enumerate() {
        let line = without_code_spans(line);
        for part in line.split("](").skip(1) {
            let Some(end) = part.find(')') else { continue };
            let target = part[..end].trim();
            // `[x](<a b.md> "title")` and `[x](a.md "title")`: the target is the first word.
            let target = target.split_whitespace().next().unwrap_or("");
            out.push((i + 1, target.trim_matches(['<', '>']).to_string()));
        }
        // mdBook's `{{#include path}}` (a missing file is only a warning to mdBook).
        if let Some(at) = line.find("{{#include ") {
            let rest = &line[at + "{{#include ".len()..];
            if let Some(end) = rest.find("}}") {
                let target = rest[..end].trim().split(':').next().unwrap_or("");
                out.push((i + 1, target.to_string()));
            }
        }
        let t = line.trim_start();
        if let (true, Some(close)) = (t.starts_with('['), t.find("]:")) {
            let target = t[close + 2..].split_whitespace().next().unwrap_or("");
            if !target.is_empty() {
                out.push((i + 1, target.to_string()));
            }
        }
    }
    out
}

fn normalise(base: &Path, rel: &str) -> Option<PathBuf> {
    let mut out = base.to_path_buf();
    for c in Path::new(rel).components() {
        match c {
            Component::ParentDir if !out.pop() => return None,
            Component::ParentDir => {}
            Component::Normal(p) => out.push(p),
            _ => {}
        }
    }
    Some(out)
}

/// The problems with `file`'s links, one line each.
fn check(root: &Path, file: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(file).expect("a readable document");
    let shown = file
        .strip_prefix(root)
        .unwrap_or(file)
        .display()
        .to_string();
    let here = file.parent().unwrap_or(root);
    let mut problems = Vec::new();
    for (line, target) in links(&text) {
        if target.is_empty() {
            problems.push(format!("{shown}:{line}: an empty link"));
            continue;
        }
        if target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let (path, anchor) = match target.split_once('#') {
            Some((p, a)) => (p, Some(a)),
            None => (target.as_str(), None),
        };
        let dest = if path.is_empty() {
            Some(file.to_path_buf())
        } else {
            normalise(here, path)
        };
        let Some(dest) = dest.filter(|d| d.starts_with(root) && d.exists()) else {
            problems.push(format!(
                "{shown}:{line}: `{target}`: no such file in the tree"
            ));
            continue;
        };
        if let Some(anchor) = anchor {
            if dest.extension().is_none_or(|e| e != "md") {
                problems.push(format!(
                    "{shown}:{line}: `{target}`: an anchor into a file that is not Markdown"
                ));
                continue;
            }
            let there = std::fs::read_to_string(&dest).unwrap_or_default();
            if !anchors(&there).contains(anchor) {
                problems.push(format!(
                    "{shown}:{line}: `{target}`: no heading with the anchor `#{anchor}`"
                ));
            }
        }
    }
    problems
}

#[test]
fn every_relative_link_and_anchor_in_the_documents_resolves() {
    let root = root();
    let files = documents(&root);
    assert!(
        files.iter().any(|f| f.ends_with("docs/src/SUMMARY.md")),
        "the book's docs/src/SUMMARY.md is missing"
    );
    let mut problems = Vec::new();
    let mut checked = 0;
    for file in &files {
        checked += links(&std::fs::read_to_string(file).unwrap()).len();
        problems.extend(check(&root, file));
    }
    assert!(
        checked > 20,
        "only {checked} links found: is the parser broken?"
    );
    assert!(
        problems.is_empty(),
        "broken links:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_link_checker_reads_markdown_as_github_and_mdbook_do() {
    assert_eq!(slug("`hello` (once, first)"), "hello-once-first");
    assert_eq!(
        slug("Health and metrics (`/healthz`, `/metrics`)"),
        "health-and-metrics-healthz-metrics"
    );
    assert_eq!(slug("Replies: `ack` and `error`"), "replies-ack-and-error");
    assert_eq!(slug("See [the book](docs/x.md)"), "see-the-book");
    assert_eq!(slug("Client → server: commands"), "client--server-commands");
    let doc = "# A\n\n```sh\n# not a heading\n[x](nowhere.md)\n```\n## A\n`[y](code.md)` [z](b.md#a-1)\n[r]: c.md\n{{#include ../d.md}}\n";
    assert_eq!(
        anchors(doc).into_iter().collect::<Vec<_>>(),
        vec!["a", "a-1"]
    );
    assert_eq!(
        links(doc),
        vec![
            (8, "b.md#a-1".to_string()),
            (9, "c.md".to_string()),
            (10, "../d.md".to_string())
        ]
    );
}
