//! Part of the build script (`actors/build.rs`): embeds the dashboard into the `pavlov` binary: every page, script and style sheet at the top of
//! `web/` (`*.html`, `*.js`, `*.css`) and uPlot's built files from `web/node_modules/uplot/dist/`, so an
//! installed binary serves the whole dashboard from any directory, with nothing beside it.
//!
//! It writes `$OUT_DIR/web_assets.rs`: a table of `(path under web/, bytes)` made of `include_bytes!`, and
//! uPlot's version, which `actors/src/dashboard/assets.rs` includes. When uPlot is not installed the build
//! stops with the command that installs it (`npm ci --prefix web`).
//!
//! Cargo reruns the script when any embedded file changes, and when uPlot's files or its `package.json`
//! change. A file added to `web/` is picked up on the next build that reruns the script:
//! a new file is only loaded when a page or script names it, and that edit reruns the script.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// uPlot's files the page loads, under `web/`.
const UPLOT_FILES: [&str; 2] = [
    "node_modules/uplot/dist/uPlot.iife.min.js",
    "node_modules/uplot/dist/uPlot.min.css",
];
/// uPlot's package description (its version), under `web/`.
const UPLOT_PACKAGE: &str = "node_modules/uplot/package.json";
/// The extensions of `web/`'s own files that are embedded.
const EXTENSIONS: [&str; 3] = ["html", "js", "css"];

/// Writes `$OUT_DIR/web_assets.rs`, or stops the build saying what is missing.
pub(crate) fn embed() {
    let manifest = std::env::var_os("CARGO_MANIFEST_DIR").map(PathBuf::from);
    let out = std::env::var_os("OUT_DIR").map(PathBuf::from);
    let (Some(manifest), Some(out)) = (manifest, out) else {
        fail("CARGO_MANIFEST_DIR and OUT_DIR must be set (run the build through cargo)");
    };
    let web = manifest.join("..").join("web");
    let web = web.canonicalize().unwrap_or(web);
    let mut files = own_files(&web);
    for rel in UPLOT_FILES.iter().chain([&UPLOT_PACKAGE]) {
        let path = web.join(rel);
        println!("cargo:rerun-if-changed={}", path.display());
        if !path.is_file() {
            fail(&format!(
                "the dashboard's chart library is not installed ({} is missing).\n\
                 Run `npm ci --prefix web` in the repository (it installs uPlot from web/package-lock.json), \
                 then build again: the dashboard and uPlot are embedded into the binary at compile time.",
                path.display()
            ));
        }
    }
    files.extend(
        UPLOT_FILES
            .iter()
            .map(|rel| (rel.to_string(), web.join(rel))),
    );
    let version = uplot_version(&web.join(UPLOT_PACKAGE));

    let mut code = String::from(
        "// Written by actors/build.rs: the dashboard's files, embedded.\n\
         /// Every embedded file of the dashboard: its path under `web/` and its bytes.\n\
         pub(crate) static FILES: &[(&str, &[u8])] = &[\n",
    );
    for (rel, path) in &files {
        println!("cargo:rerun-if-changed={}", path.display());
        let _ = writeln!(
            code,
            "    ({rel:?}, include_bytes!({:?})),",
            path.display().to_string()
        );
    }
    code.push_str("];\n");
    let _ = writeln!(
        code,
        "/// The version of the embedded uPlot (from its package.json).\n\
         pub(crate) const UPLOT_VERSION: &str = {version:?};"
    );
    if let Err(e) = std::fs::write(out.join("web_assets.rs"), code) {
        fail(&format!("cannot write web_assets.rs into OUT_DIR: {e}"));
    }
}

/// `web/`'s own pages, scripts and style sheets (not its tests or packages), by name.
fn own_files(web: &Path) -> Vec<(String, PathBuf)> {
    let entries = match std::fs::read_dir(web) {
        Ok(e) => e,
        Err(e) => fail(&format!("cannot read {}: {e}", web.display())),
    };
    let mut files: Vec<(String, PathBuf)> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .filter(|p| {
            p.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| EXTENSIONS.contains(&x))
        })
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?.to_string();
            Some((name, p))
        })
        .collect();
    files.sort();
    files
}

/// The `"version"` of a package.json, read without a JSON parser (the build script has no dependencies).
fn uplot_version(package: &Path) -> String {
    let text = std::fs::read_to_string(package).unwrap_or_default();
    text.split("\"version\"")
        .nth(1)
        .and_then(|rest| rest.split('"').nth(1))
        .unwrap_or("unknown")
        .to_string()
}

/// Stops the build with `message` (cargo shows it under the failed build script).
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    println!("cargo::error={}", message.replace('\n', " "));
    std::process::exit(1);
}
