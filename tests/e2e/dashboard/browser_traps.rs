//! The dashboard without traps (issue 25) in a real browser: starts `pavlov serve` with the gesture
//! experiment (config/interaction.toml, its skeleton port on a free loopback port, a simulated operator
//! streaming to it) and a token, lets the run go on for a while, then runs `web/tests/traps.e2e.mjs`
//! (playwright-core driving headless Debian Chromium): one left edge for every stacked chart, one window
//! for all of them (the elbow chart and the learning view included, filled from the server's history),
//! marker labels that never overlap at the long windows with their legend and hover text, the first-run
//! note, and a watcher's disabled E-STOP and Re-arm that say they need the operator's token.
//! Screenshots: `target/dashboard-traps.png` (operator), `target/dashboard-traps-watcher.png`,
//! `target/dashboard-traps-5min.png`.

use std::process::{Child, Command, Stdio};

use super::browser::{
    preflight, repo, run_browser_script_with, start_server_at, target_dir, wait_for_metric,
};

/// The operator's token of this test's server.
const TOKEN: &str = "traps-test-token-0c7f2a9e41d8";

/// Ticks the server has fired before the page is opened (20 s at 50 Hz, however long they take), so that
/// the history holds elbow angles and learning figures from well before the page connected.
const TICKS_BEFORE_OPENING: f64 = 1000.0;

/// The simulated operator (`pavlov human`), stopped when dropped.
struct Human(Child);

impl Drop for Human {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_chart_shares_one_time_axis_labels_never_overlap_and_a_watcher_cannot_press_estop() {
    preflight();
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free UDP port")
        .port();
    let to = format!("127.0.0.1:{port}");
    let config = std::fs::read_to_string(repo().join("config/interaction.toml"))
        .expect("config/interaction.toml")
        + &format!("\n[skeleton]\nlisten = \"{to}\"\n");
    let config_path = target_dir().join(format!("dashboard-traps-{}.toml", std::process::id()));
    std::fs::write(&config_path, config).expect("the test's configuration");
    let (_serve, url) = start_server_at(
        "127.0.0.1:0",
        &[
            "--config",
            config_path.to_str().expect("a UTF-8 path"),
            "--token",
            TOKEN,
        ],
    );
    let _human = Human(
        Command::new(env!("CARGO_BIN_EXE_pavlov"))
            .args(["human", "--to", &to, "--seed", "3"])
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cannot start pavlov human"),
    );
    wait_for_metric(&url, "pavlov_ticks_fired_total", TICKS_BEFORE_OPENING).await;
    let screenshot = target_dir().join("dashboard-traps.png");
    let summary =
        run_browser_script_with("traps.e2e.mjs", &url, &screenshot, &[("TOKEN", TOKEN)]).await;
    let _ = std::fs::remove_file(&config_path);
    println!("{summary}");
    assert_eq!(summary["first_run_note_remembered"], true, "{summary}");
    // The page connected after the run had gone on; the elbow chart and the learning view hold the time
    // before it (from the server's history).
    for k in ["elbow_left", "value", "return", "td"] {
        assert!(
            summary["history_filled"][k].as_u64() > Some(50),
            "{k}: {summary}"
        );
    }
    for name in [
        "dashboard-traps.png",
        "dashboard-traps-watcher.png",
        "dashboard-traps-5min.png",
    ] {
        let png = target_dir().join(name);
        assert!(
            std::fs::metadata(&png).is_ok_and(|m| m.len() > 20_000),
            "{} is missing or suspiciously small",
            png.display()
        );
    }
}
