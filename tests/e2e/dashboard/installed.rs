//! One self-contained binary: a copy of `pavlov`, alone in a temporary folder and started from another,
//! empty one (so neither the repository's `web/` nor anything else beside it can be found), serves the whole
//! dashboard, uPlot included, from the files built into it. A real browser (`web/tests/installed.e2e.mjs`,
//! headless Debian Chromium through playwright-core) loads the page and checks that the charts draw;
//! the screenshot stays in the test's temporary folder, whose path is printed.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use super::browser::{Serve, preflight, run_browser_script_with};

/// A fresh folder for this test under the system's temporary directory.
fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pavlov-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("cannot create a temporary folder");
    dir
}

/// Starts `bin serve` with `cwd` as its working directory; returns it, the dashboard's URL and the banner
/// line that says where the page comes from.
fn start_installed(bin: &Path, cwd: &Path) -> (Serve, String, String) {
    let mut child = Command::new(bin)
        .args(["serve", "--bind", "127.0.0.1:0"])
        .current_dir(cwd)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cannot start the copied pavlov binary");
    let stdout = child.stdout.take().expect("piped stdout");
    let serve = Serve(child);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut url = None;
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(u) = line.strip_prefix("dashboard: ") {
                url = Some(u.trim().to_string());
            }
            if let (Some(page), Some(u)) = (line.strip_prefix("dashboard page: "), &url) {
                let _ = tx.send((u.clone(), page.to_string()));
            }
        }
    });
    let (url, page) = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("the copied pavlov did not print its dashboard URL within 60 s");
    (serve, url, page)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_copied_binary_run_from_an_empty_folder_serves_a_dashboard_whose_charts_draw() {
    preflight();
    let install = fresh_dir("installed");
    let bin = install.join("pavlov");
    std::fs::copy(env!("CARGO_BIN_EXE_pavlov"), &bin).expect("cannot copy the pavlov binary");
    let cwd = fresh_dir("empty-cwd");
    let (serve, url, page) = start_installed(&bin, &cwd);
    assert!(page.starts_with("built into the binary"), "{page}");
    eprintln!("the copy says: dashboard page: {page}");

    let screenshot = install.join("dashboard-installed.png");
    let summary = run_browser_script_with("installed.e2e.mjs", &url, &screenshot, &[]).await;
    assert_eq!(summary["uplot"], true, "{summary}");
    assert!(
        summary["drawn_pixels"]
            .as_array()
            .is_some_and(|a| a.len() == 4 && a.iter().all(|n| n.as_u64() > Some(500))),
        "{summary}"
    );
    assert!(std::fs::metadata(&screenshot).is_ok_and(|m| m.len() > 20_000));
    // Nothing was written next to the binary or into the empty folder but what the run itself makes
    // (no web/ folder appeared, nothing was looked up there).
    assert!(!cwd.join("web").exists() && !install.join("web").exists());
    drop(serve);
    eprintln!(
        "installed binary {}: {summary}; screenshot: {}",
        bin.display(),
        screenshot.display()
    );
    // The copy is large (a debug build); the screenshot stays for a look.
    let _ = std::fs::remove_file(&bin);
    let _ = std::fs::remove_dir_all(&cwd);
}
