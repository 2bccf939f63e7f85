//! End-to-end test of the dashboard in a real browser: starts the `pavlov serve` binary on an ephemeral
//! port, runs `web/tests/dashboard.e2e.mjs` (playwright-core driving headless Debian Chromium) against
//! it — the page loads, the charts update with live ticks, the mode switch and arrow-key teleop drive
//! the wheels, the E-STOP button is pressed and the tick stream shows the robot stopped — and then
//! checks from the server's side, with its own websocket client, that the e-stop is latched and the
//! wheels are commanded to zero. The screenshot goes to `target/dashboard.png`. A second scenario
//! (`web/tests/trip.e2e.mjs`, simulator with trips injected) checks the trip banner, its cause, that nothing
//! re-arms by itself, and the Re-arm button (`target/dashboard-trip.png`). A third (`web/tests/watcher.e2e.mjs`,
//! a server with a token, the page opened without it) checks that a watcher's page draws from the
//! watcher's `hello`, that its E-STOP is disabled, and that an e-stop it sends anyway is refused
//! (`target/dashboard-watcher.png`). A fourth (`web/tests/elbow.e2e.mjs`,
//! config/interaction.toml) checks the gesture experiment's elbow chart, the skeleton status and its warning
//! before and after a `pavlov human` operator starts, and the debounced command count
//! (`target/dashboard-elbow.png`, and `target/dashboard-elbow-none.png` before the operator).
//!
//! Needs Node, `npm ci --prefix web` and `apt-get install chromium` (the test command installs them; see
//! `web/tests/run-browser-test.sh`). It fails, never skips, when any of them is missing.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;

/// The value of the unlabelled sample `name` on the `/metrics` of the server whose dashboard is at
/// `url` (`None` while it does not answer, or has no such sample).
pub(super) async fn metric(url: &str, name: &str) -> Option<f64> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let host = url
        .trim_start_matches("http://")
        .split('/')
        .next()
        .unwrap_or_default()
        .to_string();
    let mut s = tokio::net::TcpStream::connect(&host).await.ok()?;
    s.write_all(
        format!("GET /metrics HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .ok()?;
    let mut text = String::new();
    tokio::time::timeout(Duration::from_secs(10), s.read_to_string(&mut text))
        .await
        .ok()?
        .ok()?;
    text.lines().find_map(|l| {
        let (n, v) = l.split_once(' ')?;
        (n == name).then(|| v.trim().parse().ok()).flatten()
    })
}

/// Waits until the server at `url` says (on `/metrics`) that `name` has reached `at_least`: what a page
/// is opened after, instead of a fixed time that a busy machine may not fill. Fails after 3 minutes.
pub(super) async fn wait_for_metric(url: &str, name: &str, at_least: f64) {
    let deadline = Instant::now() + Duration::from_secs(180);
    loop {
        let now = metric(url, name).await;
        if now.is_some_and(|v| v >= at_least) {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{name} is {now:?} after 3 minutes; {at_least} wanted"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

pub(super) fn repo() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

pub(crate) fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("target"))
}

/// The server process; stopped with SIGTERM (then SIGKILL) when dropped.
pub(super) struct Serve(pub(super) Child);

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.0.id().to_string())
            .status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        eprintln!("warning: pavlov serve did not exit 10 s after SIGTERM; killing it");
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub(crate) fn preflight() {
    let web = repo().join("web");
    for pkg in ["playwright-core", "uplot"] {
        assert!(
            web.join("node_modules")
                .join(pkg)
                .join("package.json")
                .is_file(),
            "web/node_modules/{pkg} is missing: run `npm ci --prefix web` (or web/tests/run-browser-test.sh)"
        );
    }
    let node = Command::new("node").arg("--version").output();
    assert!(
        node.is_ok_and(|o| o.status.success()),
        "node is not installed (Node 18 or newer is needed for the browser test)"
    );
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    assert!(
        std::path::Path::new(&chromium).is_file(),
        "no Chromium at {chromium}: run `apt-get install -y chromium` (or web/tests/run-browser-test.sh)"
    );
}

/// Starts `pavlov serve` on an ephemeral loopback port and returns it with the dashboard URL it printed.
fn start_server() -> (Serve, String) {
    start_server_with(&[])
}

/// [`start_server`] with extra arguments.
fn start_server_with(extra: &[&str]) -> (Serve, String) {
    start_server_at("127.0.0.1:0", extra)
}

/// `pavlov serve --bind bind` with extra arguments, and the dashboard URL it printed.
pub(super) fn start_server_at(bind: &str, extra: &[&str]) -> (Serve, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["serve", "--bind", bind, "--web-dir"])
        .arg(repo().join("web"))
        .args(extra)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("cannot start the pavlov binary");
    let stdout = child.stdout.take().expect("piped stdout");
    let serve = Serve(child);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("dashboard: ") {
                let _ = tx.send(url.trim().to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("pavlov serve did not print its dashboard URL within 30 s");
    (serve, url)
}

/// Runs the browser script `web/tests/<script>` against `url`, saving a screenshot to `screenshot`, and
/// returns its JSON summary (after checking it says `ok`).
async fn run_browser_script(script: &str, url: &str, screenshot: &std::path::Path) -> Value {
    run_browser_script_with(script, url, screenshot, &[]).await
}

/// [`run_browser_script`] with extra environment variables for the script.
pub(crate) async fn run_browser_script_with(
    script: &str,
    url: &str,
    screenshot: &std::path::Path,
    env: &[(&str, &str)],
) -> Value {
    let _ = std::fs::remove_file(screenshot);
    let run = tokio::process::Command::new("node")
        .arg(repo().join("web/tests").join(script))
        .arg(url)
        .arg(screenshot)
        .envs(env.iter().copied())
        .current_dir(repo().join("web"))
        .kill_on_drop(true)
        .output();
    let out = tokio::time::timeout(Duration::from_secs(120), run)
        .await
        .expect("the browser test took more than 120 s")
        .expect("cannot run node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "browser test {script} failed:\n{stdout}\n{stderr}"
    );
    let summary: Value = stdout
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .unwrap_or_else(|| panic!("no JSON summary from {script}:\n{stdout}"));
    assert_eq!(summary["ok"], true, "{summary}");
    summary
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_trip_shows_its_cause_and_the_re_arm_button_resumes_control() {
    preflight();
    // Trips (wheel drops and cliffs of 0.2 s) about every 3 s of simulated time.
    let (_serve, url) = start_server_with(&["--faults", "trip=0.005,trip_ms=200"]);
    let screenshot = target_dir().join("dashboard-trip.png");
    let summary = run_browser_script("trip.e2e.mjs", &url, &screenshot).await;
    assert_eq!(summary["rearmed"], true, "{summary}");
    assert!(std::fs::metadata(&screenshot).is_ok_and(|m| m.len() > 20_000));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watcher_without_the_token_sees_the_live_page_and_cannot_latch_the_estop() {
    preflight();
    let (_serve, url) = start_server_with(&["--token", "watcher-test-token-0123456789"]);
    let screenshot = target_dir().join("dashboard-watcher.png");
    let summary = run_browser_script("watcher.e2e.mjs", &url, &screenshot).await;
    assert_eq!(summary["estop_refused"], true, "{summary}");
    assert!(std::fs::metadata(&screenshot).is_ok_and(|m| m.len() > 20_000));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_shows_live_ticks_and_its_estop_stops_the_robot() {
    preflight();
    let (_serve, url) = start_server();
    let screenshot = target_dir().join("dashboard.png");
    let summary = run_browser_script("dashboard.e2e.mjs", &url, &screenshot).await;
    assert_eq!(
        summary["moving_before_estop"], true,
        "the robot never moved before the e-stop: {summary}"
    );
    assert!(
        summary["chart_points"]
            .as_array()
            .is_some_and(|a| a.iter().all(|n| n.as_u64() > Some(10)))
    );

    // The server's side: the e-stop the browser latched is still in force.
    let ws_url = format!("{}ws", url.replacen("http://", "ws://", 1));
    let (mut ws, _) = tokio_tungstenite::connect_async(ws_url.as_str())
        .await
        .expect("websocket");
    let mut ticks = 0;
    while ticks < 25 {
        let msg = tokio::time::timeout(Duration::from_secs(5), ws.next())
            .await
            .expect("a message within 5 s")
            .expect("open")
            .expect("no error");
        let Message::Text(text) = msg else { continue };
        let v: Value = serde_json::from_str(&text).unwrap();
        if v["type"] != "tick" {
            continue;
        }
        assert_eq!(v["estop"], true, "{v}");
        assert_eq!(v["command"], serde_json::json!({"left":0,"right":0}), "{v}");
        assert_eq!(v["safety_stop"], "e_stop", "{v}");
        ticks += 1;
    }

    let png = std::fs::metadata(&screenshot).expect("the screenshot was not saved");
    assert!(
        png.len() > 20_000,
        "the screenshot is suspiciously small ({} bytes)",
        png.len()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_gesture_dashboard_shows_the_elbows_the_skeleton_status_and_debounced_commands() {
    preflight();
    // The interaction configuration with its skeleton port on a free loopback port.
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free UDP port")
        .port();
    let to = format!("127.0.0.1:{port}");
    let config = std::fs::read_to_string(repo().join("config/interaction.toml")).unwrap()
        + &format!("\n[skeleton]\nlisten = \"{to}\"\n");
    let config_path = target_dir().join(format!("dashboard-elbow-{}.toml", std::process::id()));
    std::fs::write(&config_path, config).unwrap();
    let (_serve, url) = start_server_with(&["--config", config_path.to_str().unwrap()]);
    let screenshot = target_dir().join("dashboard-elbow.png");
    let summary = run_browser_script_with(
        "elbow.e2e.mjs",
        &url,
        &screenshot,
        &[
            ("PAVLOV_BIN", env!("CARGO_BIN_EXE_pavlov")),
            ("SKELETON_TO", &to),
        ],
    )
    .await;
    let _ = std::fs::remove_file(&config_path);
    assert_eq!(summary["warned_without_skeleton"], true, "{summary}");
    assert!(
        summary["commands"]["debounced"].as_u64() >= Some(2),
        "{summary}"
    );
    assert!(std::fs::metadata(&screenshot).is_ok_and(|m| m.len() > 20_000));
}
