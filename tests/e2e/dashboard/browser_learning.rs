//! The learning view in a real browser: starts `pavlov serve` with a small `[horde]` (132 predictions)
//! and runs `web/tests/learning.e2e.mjs` (playwright-core driving headless Debian Chromium): the stall
//! prediction's value against its realised return, TD error, running error and the parameters in force;
//! the Horde grid, hover and click-to-chart. Then the same page against a server with no Horde: the view
//! says so and the page never asks for one. Screenshots: `target/dashboard-learning.png` and
//! `target/dashboard-learning-none.png`.

use std::process::Stdio;
use std::time::Duration;

use serde_json::Value;

use super::browser::{Serve, preflight, repo, start_server_at, target_dir, wait_for_metric};

/// Ticks the server has fired before the page is opened, so that returns are already being paired: 3 s
/// of them at 50 Hz, however long they take.
const TICKS_BEFORE_OPENING: f64 = 150.0;

/// The Horde runs under `SCHED_IDLE` (the default): on a busy machine it learns only when a core has
/// nothing else to do, so the page is opened once it has learned some ticks (its values then move).
const HORDE: &str = r#"
[horde]
precision = "f32"
[[horde.families]]
name = "nexting"
cumulants = ["obs/*"]
taus = [2.0, 10.0, 50.0]
lambda = 0.9
alpha = 0.01
features = { kind = "one_dim", all_obs = true, tiles = 4 }
"#;

/// Runs the script against a server started with `args`; its summary.
async fn run_page(args: &[&str], expect: &str, screenshot: &std::path::Path) -> Value {
    preflight();
    let (serve, url) = start_server_at("127.0.0.1:0", args);
    wait_for_metric(&url, "pavlov_ticks_fired_total", TICKS_BEFORE_OPENING).await;
    if expect == "horde" {
        wait_for_metric(&url, "pavlov_horde_ticks_learned_total", 50.0).await;
    }
    let _ = std::fs::remove_file(screenshot);
    let node = tokio::process::Command::new("node")
        .arg(repo().join("web/tests/learning.e2e.mjs"))
        .arg(&url)
        .arg(screenshot)
        .arg(expect)
        .current_dir(repo().join("web"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .output();
    let out = tokio::time::timeout(Duration::from_secs(150), node)
        .await
        .expect("the browser test took more than 150 s")
        .expect("cannot run node");
    tokio::task::spawn_blocking(move || drop::<Serve>(serve))
        .await
        .expect("stopping the server panicked");
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        out.status.success(),
        "learning.e2e.mjs failed:\n{stdout}\n{stderr}"
    );
    let summary = stdout
        .lines()
        .rev()
        .find_map(|l| {
            serde_json::from_str::<Value>(l)
                .ok()
                .filter(|v| v["ok"] == true)
        })
        .unwrap_or_else(|| panic!("no summary from learning.e2e.mjs:\n{stdout}"));
    eprintln!("{summary}");
    let len = std::fs::metadata(screenshot).map_or(0, |m| m.len());
    assert!(len > 20_000, "{} is {len} bytes", screenshot.display());
    summary
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_learning_view_pairs_values_with_returns_and_charts_a_clicked_horde_cell() {
    let config = target_dir().join("learning-view-horde.toml");
    let stall = std::fs::read_to_string(repo().join("config/stall.toml")).unwrap();
    std::fs::write(&config, format!("{stall}\n{HORDE}")).unwrap();
    let config = config.to_string_lossy().to_string();
    let shot = target_dir().join("dashboard-learning.png");
    let summary = run_page(&["--config", &config], "horde", &shot).await;
    assert!(
        summary["learning"]["both"].as_u64().unwrap() >= 50,
        "{summary}"
    );
    assert_eq!(
        summary["charted"]["labels"].as_array().unwrap().len(),
        2,
        "{summary}"
    );
    assert!(
        summary["charted"]["labels"][0]
            .as_str()
            .unwrap()
            .starts_with("nexting/obs/"),
        "{summary}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_horde_the_learning_view_says_so_and_still_shows_the_stall_prediction() {
    let shot = target_dir().join("dashboard-learning-none.png");
    let summary = run_page(&[], "none", &shot).await;
    assert_eq!(summary["none"]["none_hidden"], false, "{summary}");
}
