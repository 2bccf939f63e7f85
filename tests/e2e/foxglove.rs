//! `--foxglove`: the live tick stream over the Foxglove WebSocket protocol, read by a client nobody here
//! wrote — Foxglove's own `FoxgloveClient` (npm `@foxglove/ws-protocol`, over the `ws` package), driven by
//! `tests/foxglove/client.mjs`, which only chooses what to subscribe to and prints what arrives. The
//! server runs on the simulated robot in real time; the endpoint listens on an ephemeral loopback port.
//!
//! Needs `node` and `npm ci --prefix tests/foxglove` (tests/run.sh installs both); without them the tests
//! fail and say so.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::Stdio;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov_actors::command::{ControlRequest, GatingCommand};
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::foxglove::{Foxglove, TOPIC_CONFIG, TOPIC_EVENTS, TOPIC_SIGNALS, TOPIC_TICKS};
use pavlov_actors::server::{RobotTarget, Server};
use serde_json::Value;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::process::{Child, ChildStdout, Command};

use crate::common::{init_logging, stall_config};

fn client_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/foxglove"))
}

/// Fails (never skips) when the client cannot run, saying how to install it.
fn require_client() {
    let node = std::process::Command::new("node").arg("--version").output();
    assert!(
        node.is_ok_and(|o| o.status.success()),
        "the Foxglove test client needs Node.js (`node`): install it (Debian: apt-get install nodejs npm)"
    );
    let library = client_dir().join("node_modules/@foxglove/ws-protocol/package.json");
    assert!(
        library.exists(),
        "the Foxglove test client's packages are missing ({}): run `npm ci --prefix tests/foxglove` \
         (tests/run.sh does)",
        library.display()
    );
}

/// One run of the client, its output read line by line.
struct ClientRun {
    child: Child,
    lines: tokio::io::Lines<BufReader<ChildStdout>>,
}

impl ClientRun {
    fn spawn(url: &str, args: &[&str]) -> ClientRun {
        let mut child = Command::new("node")
            .arg(client_dir().join("client.mjs"))
            .arg(url)
            .args(args)
            .stdout(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .expect("node runs");
        let stdout = child.stdout.take().unwrap();
        ClientRun {
            child,
            lines: BufReader::new(stdout).lines(),
        }
    }

    /// The next line, or `None` at the end.
    async fn next(&mut self) -> Option<Value> {
        let line = tokio::time::timeout(Duration::from_secs(40), self.lines.next_line())
            .await
            .expect("the Foxglove client said nothing for 40 s")
            .unwrap()?;
        Some(serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}")))
    }

    /// Reads until a line with `"event": event` (returned) and returns the lines before it too.
    async fn until(&mut self, event: &str) -> (Value, Vec<Value>) {
        let mut before = Vec::new();
        while let Some(v) = self.next().await {
            if v["event"] == event {
                return (v, before);
            }
            before.push(v);
        }
        panic!("the client ended before `{event}`: {before:#?}");
    }

    /// Every remaining line, and the exit code.
    async fn finish(mut self) -> (Vec<Value>, i32) {
        let mut rest = Vec::new();
        while let Some(v) = self.next().await {
            rest.push(v);
        }
        let status = tokio::time::timeout(Duration::from_secs(10), self.child.wait())
            .await
            .unwrap()
            .unwrap();
        (rest, status.code().unwrap_or(-1))
    }
}

fn of_kind<'a>(lines: &'a [Value], event: &str) -> Vec<&'a Value> {
    lines.iter().filter(|v| v["event"] == event).collect()
}

fn log_time(v: &Value) -> u64 {
    v["log_time"].as_str().unwrap().parse().unwrap()
}

/// The seqs of every record the server publishes from now on, collected in the background.
fn published_seqs(server: &Server) -> std::sync::Arc<std::sync::Mutex<Vec<u64>>> {
    let seqs = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let mut feed = server.feed().subscribe();
    let sink = seqs.clone();
    tokio::spawn(async move {
        while let Ok(r) = feed.recv().await {
            sink.lock().unwrap().push(r.seq);
        }
    });
    seqs
}

/// Checks that `received` is exactly what the server published over the same span: every record, in
/// order (a tick the ticker skipped on a busy machine is a gap in both).
fn assert_every_record_in_order(received: &[&Value], published: &[u64]) {
    let received: Vec<u64> = received
        .iter()
        .map(|t| t["seq"].as_u64().unwrap())
        .collect();
    let (first, last) = (received[0], received[received.len() - 1]);
    let span: Vec<u64> = published
        .iter()
        .copied()
        .filter(|s| (first..=last).contains(s))
        .collect();
    assert_eq!(received, span, "ticks lost, repeated or out of order");
}

async fn start(config: Config) -> (Server, Foxglove) {
    init_logging();
    let bound = Foxglove::bind("127.0.0.1:0", &config.dashboard).unwrap();
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let fox = Foxglove::serve(bound, &server).await.unwrap();
    (server, fox)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_foxglove_client_receives_every_tick_in_order_with_the_events_and_the_configuration() {
    require_client();
    let (server, fox) = start(stall_config()).await;
    let published = published_seqs(&server);
    let mut client = ClientRun::spawn(&fox.url(), &["--ticks", "100", "--events", "1"]);
    let (subscribed, before) = client.until("subscribed").await;

    // Foxglove's client negotiated the SDK's protocol and saw a read-only server with four JSON channels.
    let open = &of_kind(&before, "open")[0];
    assert_eq!(open["protocol"], "foxglove.sdk.v1");
    let info = &of_kind(&before, "serverInfo")[0];
    assert_eq!(info["capabilities"], serde_json::json!([]));
    let channels = of_kind(&before, "channel");
    let topics: BTreeSet<&str> = channels
        .iter()
        .map(|c| c["topic"].as_str().unwrap())
        .collect();
    let expected: BTreeSet<&str> = [TOPIC_TICKS, TOPIC_SIGNALS, TOPIC_EVENTS, TOPIC_CONFIG].into();
    assert_eq!(topics, expected);
    for c in &channels {
        assert_eq!(c["encoding"], "json");
        assert_eq!(c["schemaEncoding"], "jsonschema");
        let schema: Value = serde_json::from_str(c["schema"].as_str().unwrap()).unwrap();
        assert_eq!(schema["type"], "object", "{}", c["topic"]);
    }
    assert_eq!(subscribed["topics"].as_array().unwrap().len(), 4);

    // A change made now reaches the client as an event.
    let (req, reply) = ControlRequest::new(GatingCommand::SetMode { mode: Mode::Manual });
    server.commands().send(req).await.unwrap();
    reply.await.unwrap().unwrap();

    let (lines, code) = client.finish().await;
    assert_eq!(code, 0, "{lines:#?}");

    // 100 ticks: every record the server published meanwhile, in order, each stamped at its scheduled
    // time on the Unix clock.
    let ticks = of_kind(&lines, "tick");
    assert_eq!(ticks.len(), 100);
    assert_every_record_in_order(&ticks, &published.lock().unwrap());
    let seq = |t: &Value| t["seq"].as_u64().unwrap();
    let (first_seq, first_time) = (seq(ticks[0]), log_time(ticks[0]));
    for t in &ticks {
        let scheduled_ns = (t["t_ms"].as_f64().unwrap() - ticks[0]["t_ms"].as_f64().unwrap()) * 1e6;
        let stamped_ns = (log_time(t) - first_time) as f64;
        assert!((stamped_ns - scheduled_ns).abs() <= 1e3, "{t}");
        assert_eq!(log_time(t) - first_time, (seq(t) - first_seq) * 20_000_000);
    }
    let now_ns = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    assert!(
        now_ns.abs_diff(first_time) < 60_000_000_000,
        "log times are Unix times"
    );

    // The event, stamped at the first tick it applies to.
    let events: Vec<&Value> = of_kind(&lines, "message")
        .into_iter()
        .filter(|m| m["topic"] == TOPIC_EVENTS)
        .collect();
    let mode_set = events
        .iter()
        .find(|e| e["message"]["kind"] == "mode_set")
        .unwrap_or_else(|| panic!("no mode_set event in {events:#?}"));
    assert_eq!(mode_set["message"]["mode"], "manual");
    let after = mode_set["message"]["after"].as_u64().unwrap();
    assert_eq!(
        log_time(mode_set) as i128 - first_time as i128,
        (after as i128 + 1 - first_seq as i128) * 20_000_000
    );

    // The configuration and the observation names, sent to the client when it subscribed.
    let config = of_kind(&before, "message")
        .into_iter()
        .chain(of_kind(&lines, "message"))
        .find(|m| m["topic"] == TOPIC_CONFIG)
        .expect("the configuration");
    assert_eq!(config["message"]["config"]["tick"]["period_ms"], 20);
    assert!(
        config["message"]["program"]
            .as_str()
            .unwrap()
            .starts_with("pavlov ")
    );
    let names: Vec<String> =
        serde_json::from_value(config["message"]["obs_names"].clone()).unwrap();
    assert_eq!(names, server.obs_names());

    // The flat message names every observation and prediction.
    let signals = &of_kind(&lines, "signals")[0];
    let obs: BTreeSet<String> = signals["obs"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(obs, server.obs_names().iter().cloned().collect());
    assert!(signals["predictions"]["stall"].is_number());

    let stats = fox.stats();
    assert_eq!((stats.connections, stats.refused_token), (1, 0));
    assert_eq!(stats.ticks_missed, 0);
    fox.shutdown().await;
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn foxgloves_client_library_connects_offering_its_own_subprotocol_foxglove_websocket_v1() {
    require_client();
    let (server, fox) = start(stall_config()).await;
    let published = published_seqs(&server);
    let (lines, code) = ClientRun::spawn(&fox.url(), &["--ticks", "25", "--spec-subprotocol"])
        .finish()
        .await;
    assert_eq!(code, 0, "{lines:#?}");
    let open = of_kind(&lines, "open");
    assert_eq!(open.len(), 1, "{lines:#?}");
    assert_eq!(open[0]["protocol"], "foxglove.websocket.v1");
    let ticks = of_kind(&lines, "tick");
    assert_eq!(ticks.len(), 25);
    assert_every_record_in_order(&ticks, &published.lock().unwrap());
    fox.shutdown().await;
    server.shutdown().await;
}

async fn scrape_metrics(addr: SocketAddr) -> String {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let request = format!("GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    s.write_all(request.as_bytes()).await.unwrap();
    let mut buf = String::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_string(&mut buf))
        .await
        .unwrap()
        .unwrap();
    buf
}

fn metric(text: &str, sample: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(sample)?.strip_prefix(' '))
        .unwrap_or_else(|| panic!("no {sample} in\n{text}"))
        .parse()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_the_token_a_foxglove_client_is_refused_and_with_it_can_only_read() {
    require_client();
    let mut cfg = stall_config();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    cfg.dashboard.token = Some("s3cret".into());
    cfg.dashboard.watch_without_token = false;
    let (server, fox) = start(cfg).await;
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    let mut events = server.events().subscribe();
    let published = published_seqs(&server);
    assert!(fox.token_required());

    // No token, and a wrong one: refused before the upgrade, with 401.
    for url in [fox.url(), format!("{}/?token=wrong", fox.url())] {
        let (lines, code) = ClientRun::spawn(&url, &["--ticks", "1"]).finish().await;
        assert_eq!(code, 2, "{url}: {lines:#?}");
        assert!(of_kind(&lines, "open").is_empty(), "{url}: {lines:#?}");
        let error = of_kind(&lines, "error");
        assert!(
            error
                .iter()
                .any(|e| e["message"].as_str().unwrap().contains("401")),
            "{url}: {lines:#?}"
        );
    }

    // With the token: it reads, and every attempt to do more is refused by the server.
    let url = format!("{}/?token=s3cret", fox.url());
    let (lines, code) = ClientRun::spawn(&url, &["--ticks", "25", "--try-commands"])
        .finish()
        .await;
    assert_eq!(code, 0, "{lines:#?}");
    assert_eq!(of_kind(&lines, "open").len(), 1);
    let ticks = of_kind(&lines, "tick");
    assert_eq!(ticks.len(), 25);
    assert_every_record_in_order(&ticks, &published.lock().unwrap());
    let statuses: Vec<&str> = of_kind(&lines, "status")
        .iter()
        .map(|s| s["message"].as_str().unwrap())
        .collect();
    assert!(
        statuses
            .iter()
            .any(|m| m.contains("does not support clientPublish")),
        "{statuses:?}"
    );
    assert_eq!(
        statuses
            .iter()
            .filter(|m| m.contains("does not support parameters"))
            .count(),
        2,
        "{statuses:?}"
    );
    let failures = of_kind(&lines, "serviceCallFailure");
    assert_eq!(failures.len(), 1, "{lines:#?}");
    assert!(of_kind(&lines, "parameterValues").is_empty());
    // Nothing reached the server: no command's event was made, the e-stop never latched. (A busy host
    // may stall the pipeline or the simulated link meanwhile: those events are the host's, not a client's.)
    assert!(ticks.iter().all(|t| t["estop"] == false));
    loop {
        match events.try_recv() {
            Ok(event) => assert!(
                matches!(
                    event.kind,
                    pavlov::event::EventKind::PipelineStall { .. }
                        | pavlov::event::EventKind::Link { .. }
                ),
                "a Foxglove client changed something: {event:?}"
            ),
            Err(tokio::sync::broadcast::error::TryRecvError::Empty) => break,
            Err(e) => panic!("the event log: {e}"),
        }
    }

    // /metrics counts both refusals and the one connection.
    let text = scrape_metrics(dash.local_addr()).await;
    assert_eq!(
        metric(&text, "pavlov_foxglove_refused_total{reason=\"token\"}"),
        2.0
    );
    assert_eq!(metric(&text, "pavlov_foxglove_connections_total"), 1.0);
    assert_eq!(
        metric(&text, "pavlov_foxglove_missed_total{stream=\"ticks\"}"),
        0.0
    );
    dash.shutdown().await;
    fox.shutdown().await;
    server.shutdown().await;
}

#[test]
fn a_busy_or_unprotected_foxglove_address_stops_start_up_before_the_robot_is_touched() {
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let busy_addr = busy.local_addr().unwrap().to_string();
    let cases = [
        (busy_addr.as_str(), "in use"),
        ("0.0.0.0:0", "requires a strong token"),
        ("localhost:x", "not an address"),
    ];
    for (addr, why) in cases {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
            .args(["serve", "--bind", "127.0.0.1:0", "--foxglove", addr])
            .env("RUST_LOG", "info")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{addr}: {stderr}");
        assert!(stderr.contains("--foxglove"), "{addr}: {stderr}");
        assert!(stderr.contains(why), "{addr}: {stderr}");
        assert!(
            !stderr.contains("robot link up"),
            "{addr}: the robot was touched: {stderr}"
        );
    }
    drop(busy);
}
