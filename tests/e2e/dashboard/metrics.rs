//! `/metrics` of a running server (simulated robot, recorder attached, dashboard on an ephemeral loopback
//! port): served as Prometheus text 0.0.4 with the right Content-Type, every documented family present
//! and valid, the figures consistent with the server's own counters, and the counters growing between
//! two scrapes.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::Duration;

use pavlov::config::Config;
use pavlov::supervision::LinkState;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recorder::Recorder;
use pavlov_actors::storage::recording::RecordingHeader;
use pavlov_actors::telemetry::prometheus_check::{Family, parse};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const STALL_CONFIG: &str = include_str!("../../../config/stall.toml");

/// Every family `/metrics` serves once the first tick is out (the README lists the same).
const FAMILIES: [(&str, &str); 54] = [
    ("pavlov_tick_lateness_seconds", "histogram"),
    ("pavlov_ticks_fired_total", "counter"),
    ("pavlov_tick_timer", "gauge"),
    ("pavlov_tick_age_seconds", "gauge"),
    ("pavlov_healthy", "gauge"),
    ("pavlov_ticks_skipped_total", "counter"),
    ("pavlov_tick_to_command_seconds", "histogram"),
    ("pavlov_serial_write_errors_total", "counter"),
    ("pavlov_link_up", "gauge"),
    ("pavlov_link_state", "gauge"),
    ("pavlov_link_tripped", "gauge"),
    ("pavlov_oi_mode", "gauge"),
    ("pavlov_link_good_frames_total", "counter"),
    ("pavlov_link_bad_frames_total", "counter"),
    ("pavlov_link_skipped_bytes_total", "counter"),
    ("pavlov_link_reconnects_total", "counter"),
    ("pavlov_link_stale_events_total", "counter"),
    ("pavlov_ws_clients", "gauge"),
    ("pavlov_ws_watchers", "gauge"),
    ("pavlov_ws_pending_connections", "gauge"),
    ("pavlov_ws_history_ticks", "gauge"),
    ("pavlov_ws_history_bytes", "gauge"),
    ("pavlov_ws_connections_total", "counter"),
    ("pavlov_ws_handshakes_rejected_total", "counter"),
    ("pavlov_ws_telemetry_dropped_total", "counter"),
    ("pavlov_ws_commands_total", "counter"),
    ("pavlov_ws_error_replies_total", "counter"),
    ("pavlov_ws_rate_limited_total", "counter"),
    ("pavlov_ws_tcp_refused_total", "counter"),
    ("pavlov_ws_token_failures_total", "counter"),
    ("pavlov_ws_token_throttled_total", "counter"),
    ("pavlov_ws_hub_records_missed_total", "counter"),
    ("pavlov_ws_horde_values_total", "counter"),
    ("pavlov_ws_horde_values_skipped_total", "counter"),
    ("pavlov_ws_closed_total", "counter"),
    ("pavlov_foxglove_clients", "gauge"),
    ("pavlov_foxglove_connections_total", "counter"),
    ("pavlov_foxglove_refused_total", "counter"),
    ("pavlov_foxglove_missed_total", "counter"),
    ("pavlov_zenoh_published_total", "counter"),
    ("pavlov_zenoh_missed_total", "counter"),
    ("pavlov_zenoh_put_errors_total", "counter"),
    ("pavlov_zenoh_oversized_dropped_total", "counter"),
    ("pavlov_zenoh_queries_total", "counter"),
    ("pavlov_zenoh_commands_total", "counter"),
    ("pavlov_recorder_backlog", "gauge"),
    ("pavlov_recorder_dropped_total", "counter"),
    ("pavlov_recording_failures_total", "counter"),
    ("pavlov_checkpoint_failures_total", "counter"),
    ("pavlov_actuation_commands_total", "counter"),
    ("pavlov_actuation_pipeline_stalls_total", "counter"),
    ("pavlov_actuation_stale_observations_total", "counter"),
    ("pavlov_actuation_writer_full_total", "counter"),
    ("pavlov_sim_faults_total", "counter"),
];

async fn scrape(addr: SocketAddr) -> (String, BTreeMap<String, Family>, String) {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!("GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let text = String::from_utf8(buf).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    let families = parse(body).unwrap_or_else(|e| panic!("{e}\n{body}"));
    (head.to_ascii_lowercase(), families, body.to_string())
}

fn value(families: &BTreeMap<String, Family>, name: &str) -> f64 {
    families
        .values()
        .flat_map(|f| &f.samples)
        .find(|s| s.name == name && s.labels.is_empty())
        .unwrap_or_else(|| panic!("no {name}"))
        .value
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_are_served_complete_valid_and_consistent() {
    let mut cfg = Config::from_toml(STALL_CONFIG).unwrap();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    let dir = std::env::temp_dir().join(format!("pavlov-metrics-{}", std::process::id()));
    let recorder = Recorder::spawn(
        RecordingHeader::new(&cfg, "metrics"),
        Some(dir.clone()),
        dir.clone(),
        500,
    )
    .unwrap();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .recorder(recorder.link.clone())
        .start()
        .await
        .unwrap();
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    let mut feed = server.feed().subscribe();
    for _ in 0..50 {
        feed.recv().await.unwrap();
    }

    let (head, first, body) = scrape(dash.local_addr()).await;
    if std::env::var_os("PAVLOV_PRINT_METRICS").is_some() {
        eprintln!("{body}");
    }
    assert!(
        head.contains("content-type: text/plain; version=0.0.4; charset=utf-8"),
        "{head}"
    );
    for (name, kind) in FAMILIES {
        let f = first
            .get(name)
            .unwrap_or_else(|| panic!("{name} missing from\n{body}"));
        assert_eq!(f.kind, kind, "{name}");
        assert!(!f.help.is_empty() && !f.samples.is_empty(), "{name}");
    }
    assert_eq!(
        first.len(),
        FAMILIES.len(),
        "undocumented families in\n{body}"
    );

    // The lateness histogram counts every fired tick; the simulated link is up, in Safe mode.
    let fired = value(&first, "pavlov_ticks_fired_total");
    // The history holds the ticks so far (the hub may be a tick or two behind the feed), in compact rows.
    let history = value(&first, "pavlov_ws_history_ticks");
    assert!((40.0..=fired).contains(&history), "{history} of {fired}");
    let bytes = value(&first, "pavlov_ws_history_bytes");
    assert!(bytes > 0.0 && bytes < 250.0 * 128.0, "{bytes}");
    assert!(fired >= 50.0, "{fired}");
    assert_eq!(value(&first, "pavlov_tick_lateness_seconds_count"), fired);
    // In real time the tick runs on its own timer thread.
    let timers: Vec<(&str, f64)> = first["pavlov_tick_timer"]
        .samples
        .iter()
        .map(|s| (s.labels["timer"].as_str(), s.value))
        .collect();
    assert_eq!(timers, vec![("thread", 1.0), ("tokio", 0.0)]);
    let states = &first["pavlov_link_state"].samples;
    assert_eq!(states.len(), LinkState::ALL.len());
    let on: Vec<&str> = states
        .iter()
        .filter(|s| s.value == 1.0)
        .map(|s| s.labels["state"].as_str())
        .collect();
    assert_eq!(on, vec!["up"]);
    assert_eq!(value(&first, "pavlov_link_up"), 1.0);
    assert_eq!(value(&first, "pavlov_oi_mode"), 2.0);
    assert!(value(&first, "pavlov_link_good_frames_total") > 0.0);
    assert!(value(&first, "pavlov_recorder_backlog") <= 500.0);
    assert_eq!(value(&first, "pavlov_recorder_dropped_total"), 0.0);
    assert!(value(&first, "pavlov_actuation_commands_total") > 0.0);

    // Once ten more ticks have fired (half a second at 50 Hz, however long a busy machine takes), the
    // counters have grown and the histogram still counts every tick.
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let (second, fired2) = loop {
        let (_, second, _) = scrape(dash.local_addr()).await;
        let fired2 = value(&second, "pavlov_ticks_fired_total");
        if fired2 >= fired + 10.0 {
            break (second, fired2);
        }
        assert!(std::time::Instant::now() < deadline, "{fired} → {fired2}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(value(&second, "pavlov_tick_lateness_seconds_count"), fired2);
    assert!(
        value(&second, "pavlov_link_good_frames_total")
            > value(&first, "pavlov_link_good_frames_total")
    );

    dash.shutdown().await;
    let _ = tokio::time::timeout(Duration::from_secs(5), server.shutdown()).await;
    // The dashboard keeps no sender of the recorder's queue: with the server gone, the recorder ends.
    let report = tokio::time::timeout(
        Duration::from_secs(10),
        tokio::task::spawn_blocking(move || recorder.join()),
    )
    .await
    .expect("the recorder ends once the server is gone")
    .unwrap();
    assert!(report.errors.is_empty(), "{report:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
