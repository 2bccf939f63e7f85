//! A full disk on the dashboard, in a real browser: `pavlov serve --record` runs with its working folder on
//! a 2 MiB tmpfs, and `web/tests/storage.e2e.mjs` fills it while the page is open. The recording badge must
//! turn to "stopped" with the OS's reason, a failed Save weights must say why, and Start must record again
//! once the room is back (`target/dashboard-storage.png`). Skipped, with a message, where the test may not
//! mount a tmpfs; like the other browser tests, it fails when Node, the npm packages or Chromium are
//! missing.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use super::browser::{preflight, repo, run_browser_script_with, target_dir};
use crate::storage::disk_full::Tmpfs;

/// The server process, killed when dropped.
struct Serve(Child);

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `pavlov serve --record rec` with its working folder `dir`; returns it and the dashboard URL.
fn start(dir: &Path) -> (Serve, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--record",
            "rec",
            "--web-dir",
        ])
        .arg(repo().join("web"))
        .current_dir(dir)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("cannot start the pavlov binary");
    let stdout = child.stdout.take().expect("piped stdout");
    let serve = Serve(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("dashboard: ") {
                let _ = tx.send(url.trim().to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("pavlov serve did not print its dashboard URL within 60 s");
    (serve, url)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_shows_on_the_dashboard_and_start_records_again_with_room() {
    preflight();
    let Some(fs) = Tmpfs::mount() else {
        eprintln!("skipped: this machine does not let the test mount a tmpfs (needs root)");
        return;
    };
    let (_serve, url) = start(fs.path());
    let screenshot = target_dir().join("dashboard-storage.png");
    let dir = fs.path().display().to_string();
    let summary =
        run_browser_script_with("storage.e2e.mjs", &url, &screenshot, &[("FILL_DIR", &dir)]).await;
    assert_eq!(summary["resumed"], true, "{summary}");
    assert!(std::fs::metadata(&screenshot).is_ok_and(|m| m.len() > 20_000));
}
