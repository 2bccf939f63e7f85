//! The dashboard as an analysis tool, in a real browser: starts `pavlov serve`, lets it run for a few
//! seconds, then runs `web/tests/analysis.e2e.mjs` (playwright-core driving headless Debian Chromium) —
//! history on connect, pause, drag-to-zoom and double-click back, the hover readout, the window selector,
//! the CSV of the view, a marker after a `set_params` from another client — and, when the script asks,
//! stops the server (the page must grey out and its E-STOP say it cannot send) and starts it again on the
//! same port (the page must come back live by itself). Screenshots: `target/dashboard-analysis.png` and
//! `target/dashboard-analysis-disconnected.png`.

use std::process::Stdio;
use std::time::Duration;

use serde_json::Value;
use tokio::io::{AsyncBufReadExt, BufReader};

use super::browser::{Serve, preflight, repo, start_server_at, target_dir, wait_for_metric};

/// Ticks the server has fired before the page is opened, so that the page has a past to be told of (the
/// page wants to open at least 150 ticks into the run): 5 s of them at 50 Hz, however long they take.
const TICKS_BEFORE_OPENING: f64 = 250.0;

/// Stops a server on a blocking thread (its drop waits for the process to exit).
async fn stop(serve: Serve) {
    tokio::task::spawn_blocking(move || drop(serve))
        .await
        .expect("stopping the server panicked");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_pauses_zooms_marks_events_and_greys_out_when_the_server_stops() {
    preflight();
    let (serve, url) = start_server_at("127.0.0.1:0", &[]);
    let bind = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    wait_for_metric(&url, "pavlov_ticks_fired_total", TICKS_BEFORE_OPENING).await;
    let screenshot = target_dir().join("dashboard-analysis.png");
    let disconnected = target_dir().join("dashboard-analysis-disconnected.png");
    let _ = std::fs::remove_file(&screenshot);
    let _ = std::fs::remove_file(&disconnected);
    let mut node = tokio::process::Command::new("node")
        .arg(repo().join("web/tests/analysis.e2e.mjs"))
        .arg(&url)
        .arg(&screenshot)
        .current_dir(repo().join("web"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("cannot run node");
    let mut lines = BufReader::new(node.stdout.take().expect("piped stdout")).lines();
    let mut server = Some(serve);
    let mut output = Vec::new();
    let steps = async {
        while let Some(line) = lines.next_line().await.expect("node's stdout") {
            let step = serde_json::from_str::<Value>(&line)
                .ok()
                .and_then(|v| v["step"].as_str().map(str::to_string));
            match step.as_deref() {
                Some("stop-server") => {
                    if let Some(s) = server.take() {
                        stop(s).await;
                    }
                }
                Some("restart-server") => {
                    let bind = bind.clone();
                    let (s, _) = tokio::task::spawn_blocking(move || start_server_at(&bind, &[]))
                        .await
                        .expect("restarting the server panicked");
                    server = Some(s);
                }
                _ => {}
            }
            output.push(line);
        }
    };
    tokio::time::timeout(Duration::from_secs(180), steps)
        .await
        .expect("the browser test took more than 180 s");
    let status = node.wait().await.expect("node ran");
    let mut stderr = String::new();
    if let Some(mut e) = node.stderr.take() {
        use tokio::io::AsyncReadExt;
        let _ = e.read_to_string(&mut stderr).await;
    }
    if let Some(s) = server.take() {
        stop(s).await;
    }
    let stdout = output.join("\n");
    assert!(
        status.success(),
        "analysis.e2e.mjs failed:\n{stdout}\n{stderr}"
    );
    let summary: Value = output
        .iter()
        .rev()
        .find_map(|l| {
            serde_json::from_str::<Value>(l)
                .ok()
                .filter(|v| v["ok"] == true)
        })
        .unwrap_or_else(|| panic!("no summary from analysis.e2e.mjs:\n{stdout}"));
    eprintln!("{summary}");
    assert!(
        summary["history"]["earliest_seq"]
            .as_u64()
            .is_some_and(|s| s <= 5),
        "{summary}"
    );
    assert!(
        summary["markers"]
            .as_array()
            .is_some_and(|m| m.iter().any(|l| l == "α=0.01")),
        "{summary}"
    );
    assert_eq!(summary["disconnected"]["estop_disabled"], true, "{summary}");
    for png in [&screenshot, &disconnected] {
        let len = std::fs::metadata(png).map_or(0, |m| m.len());
        assert!(len > 20_000, "{} is {len} bytes", png.display());
    }
}
