//! The repository stands alone: no file in it refers to a path outside it. A clone has nothing beside it,
//! so a test that reads `../../something`, a document that links to a sibling folder, or a module doc that
//! cites a file outside the tree would be broken for everyone who clones it.
//!
//! Every text file of the tree (build output, installed packages and run outputs left out) is read; each
//! relative path with `..` in it is resolved from the file's own folder (and, in Rust, also from the
//! `actors/` package, where `CARGO_MANIFEST_DIR` points) and must stay inside the repository. Markdown
//! links to relative targets, and documents named in backquotes (`` `x.md` ``), must exist in the tree.
//! Paths into the folders that sat beside the repository while it was written are refused by name.
//!
//! It also keeps the layering: no new import circle among the top-level modules of either crate (those
//! still standing are named, and can only go), and the buses (`actors/src/bus/`) beneath everything that
//! uses them.

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
/// Markdown files the studies write into their results folder (not documents of the repository).
const WRITTEN_BY_STUDIES: &[&str] = &["table.md", "variations.md", "learners.md"];

fn quoted_documents(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .filter(|t| t.ends_with(".md") && !t.contains(char::is_whitespace) && !t.contains('*'))
        .filter(|t| !WRITTEN_BY_STUDIES.contains(t))
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

// ---- The module graph: which top-level module of a crate imports which ----

/// The top-level modules of the crate whose sources are in `src` (folders and files, `lib.rs` and
/// `main.rs` aside), each with the top-level modules it names through `crate::` outside comments and
/// tests (a test may reach anywhere; `tests.rs` files and a trailing `#[cfg(test)] mod` are left out).
fn module_graph(
    src: &Path,
) -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let mut modules = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(src)
        .expect("the crate's sources")
        .flatten()
    {
        let name = entry.file_name().to_string_lossy().into_owned();
        let module = if entry.path().is_dir() {
            name
        } else if let Some(stem) = name.strip_suffix(".rs") {
            stem.to_string()
        } else {
            continue;
        };
        if module != "lib" && module != "main" {
            modules.insert(module);
        }
    }
    let mut graph: std::collections::BTreeMap<_, std::collections::BTreeSet<String>> = modules
        .iter()
        .map(|m| (m.clone(), Default::default()))
        .collect();
    let mut files = Vec::new();
    text_files(src, &mut files);
    for file in files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "rs"))
    {
        let rel = file.strip_prefix(src).unwrap_or(file);
        let first = rel
            .components()
            .next()
            .map(|c| c.as_os_str().to_string_lossy().into_owned());
        let Some(first) = first else { continue };
        let owner = first.strip_suffix(".rs").unwrap_or(&first).to_string();
        let in_tests = rel.components().any(|c| {
            let c = c.as_os_str().to_string_lossy();
            c == "tests" || c == "tests.rs"
        });
        if !modules.contains(&owner) || in_tests {
            continue;
        }
        let text = std::fs::read_to_string(file).unwrap_or_default();
        let code = text.split("#[cfg(test)]\nmod ").next().unwrap_or("");
        for line in code.lines() {
            let line = line.split("//").next().unwrap_or("");
            for named in crate_paths(line) {
                if named != owner && modules.contains(&named) {
                    graph.entry(owner.clone()).or_default().insert(named);
                }
            }
        }
    }
    graph
}

/// The first segment of every `crate::` path on `line`, a group's (`crate::{a::X, b}`) included.
fn crate_paths(line: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    for part in line.split("crate::").skip(1) {
        if let Some(group) = part.strip_prefix('{') {
            let mut depth = 0;
            let mut start = true;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => start = true,
                    c if start && !c.is_whitespace() => {
                        out.push(ident(&group[i..]));
                        start = false;
                    }
                    _ => {}
                }
            }
        } else {
            out.push(ident(part));
        }
    }
    out.retain(|m| !m.is_empty());
    out
}

/// The circles of `graph`: each set of two or more modules that reach one another.
fn circles(
    graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
) -> Vec<Vec<String>> {
    let reach = |from: &String| {
        let mut seen = std::collections::BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(m) = todo.pop() {
            for next in graph.get(&m).into_iter().flatten() {
                if seen.insert(next.clone()) {
                    todo.push(next.clone());
                }
            }
        }
        seen
    };
    let reaches: std::collections::BTreeMap<_, _> = graph.keys().map(|m| (m, reach(m))).collect();
    let mut found: Vec<Vec<String>> = Vec::new();
    for m in graph.keys() {
        let circle: Vec<String> = graph
            .keys()
            .filter(|n| reaches[m].contains(*n) && reaches[n].contains(m))
            .cloned()
            .collect();
        if circle.len() > 1 && !found.contains(&circle) {
            found.push(circle);
        }
    }
    found
}

/// The circles among top-level modules still standing: none. The last two were broken by moving a shape
/// to where both sides can import it: the simulator's and the Horde's status live in the shell's
/// `telemetry/` (which the `Health` handle reads, and which the link, the Horde and the simulator write
/// to); the core's checkpoint, which names both the configuration and the learners, sits above both. A
/// change that adds a circle fails here, printing the imports that close it.
const STANDING_CIRCLES: [(&str, &[&[&str]]); 2] = [("actors/src", &[]), ("src", &[])];

#[test]
fn no_new_circle_among_the_top_level_modules_of_either_crate() {
    let root = root();
    let mut problems = Vec::new();
    for (src, standing) in STANDING_CIRCLES {
        let graph = module_graph(&root.join(src));
        assert!(graph.len() > 5, "{src}: only {} modules found", graph.len());
        let standing: Vec<Vec<String>> = standing
            .iter()
            .map(|circle| circle.iter().map(|m| m.to_string()).collect())
            .collect();
        let found = circles(&graph);
        if found != standing {
            let edges: Vec<String> = found
                .iter()
                .flatten()
                .flat_map(|m| {
                    graph[m]
                        .iter()
                        .filter(|n| found.iter().any(|c| c.contains(m) && c.contains(n)))
                        .map(move |n| format!("{m} -> {n}"))
                })
                .collect();
            problems.push(format!(
                "{src}: circles {found:?} (expected only {standing:?}); their imports: {}",
                edges.join(", ")
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_buses_are_beneath_everything_that_uses_them() {
    let graph = module_graph(&root().join("actors/src"));
    assert!(
        graph["bus"].is_empty(),
        "bus/ imports {:?}: it must import no module of the shell",
        graph["bus"]
    );
    for user in ["pipeline", "link", "storage", "telemetry"] {
        assert!(graph[user].contains("bus"), "{user} does not use the bus");
    }
    for lower in [
        "bus",
        "command",
        "link",
        "storage",
        "telemetry",
        "horde",
        "simulated",
    ] {
        assert!(
            !graph[lower].contains("pipeline"),
            "{lower} imports pipeline/, which stands above it"
        );
    }
    assert!(
        !graph["command"].contains("bus"),
        "command.rs is the vocabulary only"
    );
}

#[test]
fn the_graph_reader_sees_groups_and_circles() {
    assert_eq!(
        crate_paths("use crate::{bus::{EventLog, TickFeed}, command::Reply}; crate::link::x()"),
        vec!["bus", "command", "link"]
    );
    let graph = [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")]
        .iter()
        .fold(
            std::collections::BTreeMap::<String, std::collections::BTreeSet<String>>::new(),
            |mut g, (x, y)| {
                g.entry(x.to_string()).or_default().insert(y.to_string());
                g.entry(y.to_string()).or_default();
                g
            },
        );
    assert_eq!(circles(&graph), vec![vec!["a", "b", "c"]]);
}

/// Each module's floor: the length of its longest chain of imports (0 for a module importing none).
/// Only defined on a graph without circles (the test above holds that).
fn floors(
    graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
) -> std::collections::BTreeMap<String, usize> {
    fn floor(
        m: &str,
        graph: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
        memo: &mut std::collections::BTreeMap<String, usize>,
        depth: usize,
    ) -> usize {
        if let Some(f) = memo.get(m) {
            return *f;
        }
        // A circle would recurse for ever; cut it (the circle test reports it).
        if depth > graph.len() {
            return 0;
        }
        let f = graph
            .get(m)
            .into_iter()
            .flatten()
            .map(|n| 1 + floor(n, graph, memo, depth + 1))
            .max()
            .unwrap_or(0);
        memo.insert(m.to_string(), f);
        f
    }
    let mut memo = std::collections::BTreeMap::new();
    for m in graph.keys() {
        floor(m, graph, &mut memo, 0);
    }
    memo
}

/// The floors ARCHITECTURE.md draws for the crate headed `heading` ("shell (actors/src)", "core (src)").
fn documented_floors(
    architecture: &str,
    heading: &str,
) -> std::collections::BTreeMap<String, usize> {
    let mut out = std::collections::BTreeMap::new();
    let mut inside = false;
    for line in architecture.lines() {
        if line.trim() == heading {
            inside = true;
            continue;
        }
        if !inside {
            continue;
        }
        let Some(rest) = line.strip_prefix("floor ") else {
            break;
        };
        let (number, modules) = rest.split_once(' ').unwrap_or((rest, ""));
        let number: usize = number.parse().expect("a floor number");
        for module in modules.split(',').map(str::trim).filter(|m| !m.is_empty()) {
            out.insert(module.to_string(), number);
        }
    }
    out
}

#[test]
fn the_floors_in_architecture_md_are_the_code_s() {
    let root = root();
    let architecture =
        std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    for (src, heading) in [("actors/src", "shell (actors/src)"), ("src", "core (src)")] {
        let graph = module_graph(&root.join(src));
        let actual = floors(&graph);
        let documented = documented_floors(&architecture, heading);
        assert_eq!(
            documented, actual,
            "ARCHITECTURE.md's floors for {src} differ from the imports (left: documented, right: the code)"
        );
    }
}
