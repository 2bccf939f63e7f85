//! The repository stands alone: no file in it refers to a path outside it. A clone has nothing beside it,
//! so a test that reads `../../something`, a document that links to a sibling folder, or a module doc that
//! cites a file outside the tree would be broken for everyone who clones it.
//!
//! Every text file of the tree (build output, installed packages and run outputs left out) is read; each
//! relative path with `..` in it is resolved from the file's own folder (and, in Rust, also from the
//! `actors/` package, where `CARGO_MANIFEST_DIR` points) and must stay inside the repository. Markdown
//! links to relative targets, and documents named in backquotes (`` `x.md` ``), must exist in the tree.
//! Paths into the folders that sat beside the repository while it was written are refused by name.

use std::path::{Component, Path, PathBuf};

/// Folders that are not part of the tree: build output, installed packages, run outputs, git's store.
const SKIPPED: [&str; 7] = [
    "target",
    "node_modules",
    ".git",
    "results",
    "recordings",
    "weights",
    "checkpoints",
];

/// The folder that sat beside the repository while it was written, spelled in two pieces so that this
/// file, which must name it to refuse it, does not itself read as a reference to it.
const SIBLING: &str = concat!("sha", "red");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if SKIPPED.contains(&name.as_str()) {
            continue;
        }
        if path.is_dir() {
            text_files(&path, out);
        } else if std::fs::read_to_string(&path).is_ok() {
            out.push(path);
        }
    }
}

/// `base/rel` with `.` and `..` folded; `None` when it climbs above the filesystem root.
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

/// The relative paths with a `..` in `text`: runs of path characters that contain `../`.
fn dotted_paths(text: &str) -> Vec<String> {
    let is_path = |c: char| c.is_ascii_alphanumeric() || "._-/".contains(c);
    let mut found = Vec::new();
    for word in text.split(|c: char| !is_path(c)) {
        if let Some(at) = word.find("../") {
            // Start at the first `..`, drop what precedes it (`concat!(…, "/../x")` gives "/../x").
            let path = word[at..].trim_end_matches(['.', '/']);
            if !path.is_empty() {
                found.push(path.to_string());
            }
        }
    }
    found
}

/// The targets of Markdown links `[text](target)` that are relative file paths.
fn markdown_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for part in text.split("](").skip(1) {
        let Some(end) = part.find(')') else { continue };
        let target = part[..end].split('#').next().unwrap_or("").trim();
        let external = target.contains("://") || target.starts_with("mailto:");
        if !target.is_empty() && !external && !target.starts_with('#') {
            out.push(target.to_string());
        }
    }
    out
}

/// Documents named in backquotes: `` `docs/SOURCES.md` ``.
fn quoted_documents(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .filter(|t| t.ends_with(".md") && !t.contains(char::is_whitespace) && !t.contains('*'))
        .map(str::to_string)
        .collect()
}

#[test]
fn nothing_in_the_tree_refers_to_a_path_outside_it() {
    let root = root();
    let actors = root.join("actors");
    let mut files = Vec::new();
    text_files(&root, &mut files);
    assert!(files.len() > 100, "only {} files found", files.len());
    let mut problems = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap_or_default();
        let here = file.parent().unwrap_or(&root);
        let shown = file
            .strip_prefix(&root)
            .unwrap_or(file)
            .display()
            .to_string();
        // This file names the patterns it looks for.
        let itself = file.ends_with("tests/e2e/house.rs");
        let rust = file.extension().is_some_and(|e| e == "rs");
        let bases: &[&Path] = if rust { &[here, &actors] } else { &[here] };
        for path in dotted_paths(&text) {
            let inside = bases
                .iter()
                .filter_map(|base| normalise(base, &path))
                .any(|p| p.starts_with(&root));
            if !inside {
                problems.push(format!("{shown}: `{path}` leads outside the repository"));
            }
        }
        let needles = [
            format!("../{SIBLING}/"),
            format!("{SIBLING}/reference"),
            format!("{SIBLING}/data"),
            format!("{SIBLING}/seed"),
            "/work/".to_string(),
        ];
        for needle in &needles {
            if text.contains(needle.as_str()) && !itself {
                problems.push(format!(
                    "{shown}: mentions `{needle}`, a path outside the repository"
                ));
            }
        }
        for doc in quoted_documents(&text).into_iter().filter(|_| !itself) {
            let name = Path::new(&doc).file_name().map(|n| n.to_os_string());
            if !files
                .iter()
                .any(|f| f.file_name().map(|n| n.to_os_string()) == name)
            {
                problems.push(format!(
                    "{shown}: names `{doc}`, which is not in the repository"
                ));
            }
        }
        if file.extension().is_some_and(|e| e == "md") {
            for target in markdown_targets(&text) {
                let exists =
                    normalise(here, &target).is_some_and(|p| p.starts_with(&root) && p.exists());
                if !exists {
                    problems.push(format!(
                        "{shown}: link to `{target}`, which is not in the repository"
                    ));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_checker_sees_what_it_must_refuse() {
    assert_eq!(
        dotted_paths(
            r#"include_str!("../../config/stall.toml"); see `../beside/ARCHITECTURE.md`."#
        ),
        vec!["../../config/stall.toml", "../beside/ARCHITECTURE.md"]
    );
    assert_eq!(
        dotted_paths(r#"concat!(env!("X"), "/../web")"#),
        vec!["../web"]
    );
    assert_eq!(
        markdown_targets("[a](docs/x.md) [b](https://e.org) [c](#top) [d](../y.md#s)"),
        vec!["docs/x.md", "../y.md"]
    );
    assert_eq!(
        quoted_documents("see `docs/SOURCES.md` and `a b.md`, not `x`"),
        vec!["docs/SOURCES.md"]
    );
    let root = Path::new("/r");
    assert_eq!(normalise(root, "../x"), Some(PathBuf::from("/x")));
    assert!(
        !normalise(Path::new("/r/a"), "../../x")
            .unwrap()
            .starts_with(root)
    );
}
