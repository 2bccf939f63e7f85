//! Build-time provenance: what `pavlov --version`, every recording and every study's summary say about the
//! code they came from.
//!
//! Sets, for `actors/src/provenance.rs`:
//! - `PAVLOV_GIT_COMMIT`: the commit checked out (`git rev-parse HEAD`), or `unknown` when the build is not
//!   inside a git checkout (a source tarball, `cargo install` from a registry) or `git` is missing;
//!   `PAVLOV_BUILD_COMMIT` in the environment overrides it (for packagers building from an export);
//! - `PAVLOV_GIT_DIRTY`: `true` when tracked or untracked (not ignored) files differ from that commit,
//!   `false` when clean, `unknown` without git;
//! - `PAVLOV_FEATURES`: the cargo features of this package, comma-separated;
//! - `PAVLOV_RUSTC`: `rustc --version` of the compiler building it;
//! - `PAVLOV_TARGET` and `PAVLOV_PROFILE`: the target triple and the profile (`debug`/`release`).
//!
//! It also asks the linker to compress the binary's debug sections (zlib, Linux release builds only): the
//! release profile keeps line tables so that backtraces name files and lines, and compressed they cost a
//! quarter of the space (Rust's backtraces and `perf` read compressed sections).
//!
//! And it embeds the dashboard's files (`build/web_assets.rs`).
//!
//! So that the dirty flag stays true, the script runs again whenever git's HEAD, index or refs move, or a
//! file the binary is compiled from changes (an edit to a test or a document alone is seen at the next
//! such change; rebuilding the library for every edit of a test would slow every test run).

use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "build/web_assets.rs"]
mod web_assets;

fn main() {
    web_assets::embed();

    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let root = manifest
        .parent()
        .map_or_else(|| manifest.clone(), Path::to_path_buf);

    let (commit, dirty) = match std::env::var("PAVLOV_BUILD_COMMIT") {
        Ok(c) if !c.trim().is_empty() => (c.trim().to_string(), "unknown".to_string()),
        _ => git_state(&root),
    };
    println!("cargo:rerun-if-env-changed=PAVLOV_BUILD_COMMIT");
    println!("cargo:rustc-env=PAVLOV_GIT_COMMIT={commit}");
    println!("cargo:rustc-env=PAVLOV_GIT_DIRTY={dirty}");

    let mut features: Vec<String> = std::env::vars()
        .filter_map(|(k, _)| k.strip_prefix("CARGO_FEATURE_").map(str::to_string))
        .map(|f| f.to_ascii_lowercase().replace('_', "-"))
        .collect();
    features.sort();
    println!("cargo:rustc-env=PAVLOV_FEATURES={}", features.join(","));

    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let rustc_version = Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=PAVLOV_RUSTC={rustc_version}");
    println!(
        "cargo:rustc-env=PAVLOV_TARGET={}",
        std::env::var("TARGET").unwrap_or_else(|_| "unknown".into())
    );
    println!(
        "cargo:rustc-env=PAVLOV_PROFILE={}",
        std::env::var("PROFILE").unwrap_or_else(|_| "unknown".into())
    );
    compress_debug_sections();
}

/// Linux release binaries: the linker compresses the debug sections (line tables) with zlib.
fn compress_debug_sections() {
    let linux = std::env::var("CARGO_CFG_TARGET_OS").is_ok_and(|os| os == "linux");
    let release = std::env::var("PROFILE").is_ok_and(|p| p == "release");
    if linux && release {
        println!("cargo:rustc-link-arg-bins=-Wl,--compress-debug-sections=zlib");
    }
}

/// The commit and dirty flag of the checkout at `root`, and the paths whose change reruns this script.
fn git_state(root: &Path) -> (String, String) {
    let git = |args: &[&str]| {
        Command::new("git")
            .arg("-C")
            .arg(root)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let Some(commit) = git(&["rev-parse", "HEAD"]).filter(|c| !c.is_empty()) else {
        return ("unknown".into(), "unknown".into());
    };
    // In a worktree `.git` is a file: ask git where its directories are.
    for what in ["--git-dir", "--git-common-dir"] {
        if let Some(dir) = git(&["rev-parse", what]) {
            let dir = root.join(dir);
            for part in ["HEAD", "index", "refs", "packed-refs"] {
                let p = dir.join(part);
                if p.exists() {
                    println!("cargo:rerun-if-changed={}", p.display());
                }
            }
        }
    }
    // What the binary is compiled from (an edit there rebuilds it anyway). An edit elsewhere (a test, the
    // docs) marks the tree dirty at the next build that git's index or a source change triggers.
    for part in [
        "Cargo.toml",
        "Cargo.lock",
        "src",
        "actors/Cargo.toml",
        "actors/src",
        "config",
    ] {
        let p = root.join(part);
        if p.exists() {
            println!("cargo:rerun-if-changed={}", p.display());
        }
    }
    let dirty = match git(&["status", "--porcelain", "--untracked-files=normal"]) {
        Some(s) if s.is_empty() => "false",
        Some(_) => "true",
        None => "unknown",
    };
    (commit, dirty.into())
}
