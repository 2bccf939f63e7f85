//! Protocol tests of the dashboard websocket over real sockets: the whole server runs on the simulated
//! robot, the endpoint listens on an ephemeral loopback port, and a Rust websocket client speaks
//! `web/PROTOCOL.md` to it — hello, ticks, rates, every command, every error path, the handshake's
//! origin/token/client-count checks, the size cap, a stalled client, the static files and shut-down.

use std::net::SocketAddr;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov::config::Config;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::{HeaderName, HeaderValue};
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

const STALL_CONFIG: &str = include_str!("../../../config/stall.toml");
const INTERACTION_CONFIG: &str = include_str!("../../../config/interaction.toml");
const WAIT: Duration = Duration::from_secs(5);

struct Lab {
    server: Server,
    dash: Dashboard,
}

mod tempdir {
    //! A throw-away directory (no extra dependency).
    use std::path::{Path, PathBuf};

    pub struct TempDir(PathBuf);
    impl TempDir {
        pub fn new(tag: &str) -> TempDir {
            let p = std::env::temp_dir().join(format!(
                "pavlov-ws-{tag}-{}-{:?}",
                std::process::id(),
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .unwrap()
                    .as_nanos()
            ));
            std::fs::create_dir_all(&p).unwrap();
            TempDir(p)
        }
        pub fn path(&self) -> &Path {
            &self.0
        }
    }
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

async fn start_with(edit: impl FnOnce(&mut Config)) -> Lab {
    start_from(STALL_CONFIG, edit).await
}

async fn start_from(toml: &str, edit: impl FnOnce(&mut Config)) -> Lab {
    let mut cfg = Config::from_toml(toml).unwrap();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    edit(&mut cfg);
    cfg.validate().unwrap();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    Lab { server, dash }
}

/// Stops the server; its own shut-down is tested elsewhere, so a slow one only warns here.
async fn stop_server(server: Server) {
    if tokio::time::timeout(WAIT, server.shutdown()).await.is_err() {
        eprintln!("warning: the server took more than 5 s to shut down");
    }
}

async fn start() -> Lab {
    start_with(|_| {}).await
}

impl Lab {
    fn addr(&self) -> SocketAddr {
        self.dash.local_addr()
    }

    fn url(&self, query: &str) -> String {
        format!("ws://{}/ws{query}", self.addr())
    }

    async fn try_connect(&self, query: &str, headers: &[(&str, &str)]) -> Result<Ws, WsError> {
        let mut req = self.url(query).into_client_request().unwrap();
        for (k, v) in headers {
            req.headers_mut().insert(
                HeaderName::from_bytes(k.as_bytes()).unwrap(),
                HeaderValue::from_str(v).unwrap(),
            );
        }
        tokio_tungstenite::connect_async(req)
            .await
            .map(|(ws, _)| ws)
    }

    async fn connect(&self) -> (Ws, Value) {
        let mut ws = self.try_connect("", &[]).await.unwrap();
        let hello = next_json(&mut ws).await;
        assert_eq!(hello["type"], "hello", "{hello}");
        (ws, hello)
    }

    async fn stop(self) {
        self.dash.shutdown().await;
        stop_server(self.server).await;
    }
}

async fn next_json(ws: &mut Ws) -> Value {
    loop {
        let msg = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("no message within 5 s")
            .expect("the connection ended")
            .expect("a websocket error");
        match msg {
            Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            Message::Ping(_) | Message::Pong(_) => continue,
            other => panic!("unexpected frame {other:?}"),
        }
    }
}

/// The next message of `kind`, skipping the others.
async fn next_of(ws: &mut Ws, kind: &str) -> Value {
    loop {
        let v = next_json(ws).await;
        if v["type"] == kind {
            return v;
        }
    }
}

/// The reply (ack or error) to the message with `id`, skipping telemetry.
async fn reply_to(ws: &mut Ws, id: &Value) -> Value {
    loop {
        let v = next_json(ws).await;
        if (v["type"] == "ack" || v["type"] == "error") && v["id"] == *id {
            return v;
        }
        assert!(
            ["tick", "status", "learning", "event", "history"]
                .contains(&v["type"].as_str().unwrap_or("")),
            "unexpected reply {v}"
        );
    }
}

async fn send(ws: &mut Ws, text: impl Into<String>) {
    ws.send(Message::text(text.into())).await.unwrap();
}

async fn command(ws: &mut Ws, mut msg: Value, id: u64) -> Value {
    msg["id"] = json!(id);
    send(ws, msg.to_string()).await;
    reply_to(ws, &json!(id)).await
}

/// Ticks until `pred` holds for one (or panics after `within`).
async fn tick_where(ws: &mut Ws, within: Duration, pred: impl Fn(&Value) -> bool) -> Value {
    let deadline = tokio::time::Instant::now() + within;
    loop {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no matching tick within {within:?}"
        );
        let t = next_of(ws, "tick").await;
        if pred(&t) {
            return t;
        }
    }
}

fn handshake_status(e: WsError) -> u16 {
    match e {
        WsError::Http(resp) => resp.status().as_u16(),
        other => panic!("expected an HTTP refusal, got {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hello_comes_first_with_version_config_and_signals() {
    let lab = start().await;
    let (mut ws, hello) = lab.connect().await;
    assert_eq!(hello["protocol"], 1);
    assert_eq!(hello["tick_period_ms"], 20);
    assert_eq!(hello["rate_hz"], 50.0);
    assert_eq!(hello["can_command"], true);
    assert_eq!(hello["signals"]["predictions"], json!(["stall"]));
    assert_eq!(hello["signals"]["gate_prediction"], "stall");
    assert_eq!(hello["config"]["control"]["mode"], "pavlovian");
    assert_eq!(hello["config"]["tick"]["period_ms"], 20);
    assert_eq!(hello["limits"]["max_message_bytes"], 64 * 1024);
    let commands: Vec<&str> = hello["commands"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    for c in [
        "set_mode",
        "estop",
        "release",
        "teleop",
        "human_request",
        "set_params",
        "reset_weights",
        "save_weights",
        "start_recording",
        "stop_recording",
        "set_rate",
    ] {
        assert!(commands.contains(&c), "{c} missing from {commands:?}");
    }
    let names = hello["signals"]["obs"].as_array().unwrap();
    assert_eq!(names.len(), lab.server.obs_names().len());
    let tick = next_of(&mut ws, "tick").await;
    assert_eq!(tick["obs"].as_array().unwrap().len(), names.len());
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ticks_stream_at_the_tick_rate_with_every_field() {
    let lab = start().await;
    let mut feed = lab.server.feed().subscribe();
    let (mut ws, _) = lab.connect().await;
    let first = next_of(&mut ws, "tick").await;
    let mut seqs = vec![first["seq"].as_u64().unwrap()];
    let mut times = vec![first["t"].as_f64().unwrap()];
    let mut status = None;
    let mut last = first.clone();
    // 100 ticks (2 s at 50 Hz, however long a busy machine takes) and a status.
    tokio::time::timeout(Duration::from_secs(60), async {
        while seqs.len() < 100 || status.is_none() {
            let m = next_json(&mut ws).await;
            match m["type"].as_str() {
                Some("tick") => {
                    seqs.push(m["seq"].as_u64().unwrap());
                    times.push(m["t"].as_f64().unwrap());
                    last = m;
                }
                Some("status") => status = Some(m),
                // (Events too: a busy machine may make the server log a stale stream or a stall.)
                Some("learning" | "event") => {}
                other => panic!("unexpected {other:?}"),
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("{} ticks in 60 s", seqs.len()));
    assert!(
        seqs.windows(2).all(|w| w[1] > w[0]),
        "sequence numbers must increase"
    );
    // The tick rate: every tick is stamped with its place on the 20 ms schedule (a tick the ticker
    // skipped on a busy machine is a gap in it, never a tick off it).
    for (seq, t) in seqs.iter().zip(&times) {
        assert!(
            (t - *seq as f64 * 0.020).abs() < 1e-9,
            "tick {seq} at {t} s"
        );
    }
    // Every tick the feed made in the span reached the client, but for any counted as dropped for it.
    let dropped = lab.dash.telemetry_dropped_for(client_addr(&ws)).unwrap();
    let (first_seq, last_seq) = (seqs[0], *seqs.last().unwrap());
    let mut made = 0;
    loop {
        let seq = feed.recv().await.unwrap().seq;
        if seq >= first_seq {
            made += 1;
        }
        if seq >= last_seq {
            break;
        }
    }
    assert!(
        made - seqs.len() as u64 <= dropped + lab.dash.stats().records_missed,
        "ticks missing: {} of the {made} made, {dropped} dropped for the client",
        made - seqs.len() as u64
    );
    for key in [
        "t",
        "mode",
        "obs",
        "predictions",
        "stimulus",
        "gate",
        "command",
        "default",
        "estop",
        "safety_stop",
        "sensors",
        "link",
        "lateness_us",
    ] {
        assert!(last.get(key).is_some(), "tick lacks `{key}`: {last}");
    }
    let p = &last["predictions"][0];
    assert_eq!(p["name"], "stall");
    assert!(p["value"].is_number() && p["threshold"] == 0.5, "{p}");
    assert!(last["command"]["left"].is_i64() && last["default"]["right"].is_i64());
    assert!(
        last["sensors"]["battery_current_ma"].is_i64(),
        "{}",
        last["sensors"]
    );
    assert!(last["sensors"]["overcurrent_left"].is_boolean());
    assert_eq!(last["link"]["up"], true);
    assert!(
        last["link"]["good_frames"].as_u64().unwrap()
            > first["link"]["good_frames"].as_u64().unwrap()
    );
    assert!(last["t"].as_f64().unwrap() > first["t"].as_f64().unwrap());
    let status = status.expect("a status message in 2 s");
    assert_eq!(status["seq"].as_u64().unwrap() % 10, 0);
    assert!(status["health"]["lateness_p99_us"].is_u64());
    assert!(status["health"]["ticks_fired"].as_u64().unwrap() > 50);
    assert!(status["counters"]["ticks"].as_u64().unwrap() > 50);
    assert!(status["counters"]["distance_m"].is_number());
    assert_eq!(status["clients"], 1);
    assert!(
        status.get("interaction").is_none(),
        "the stall run has no commands: {status}"
    );
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn statuses_of_the_gesture_command_run_carry_the_interaction_metrics() {
    // No skeleton socket: the stimulus stays off, so every figure is zero but present.
    let lab = start_from(INTERACTION_CONFIG, |c| c.skeleton.enabled = Some(false)).await;
    let (mut ws, _) = lab.connect().await;
    let status = next_of(&mut ws, "status").await;
    let i = &status["interaction"];
    for key in ["commands", "early", "missed", "false_starts"] {
        assert!(i[key].is_u64(), "`interaction.{key}` in {status}");
    }
    assert_eq!(i["commands"], 0, "{i}");
    assert!(
        i["mean_lead_ms"].is_null() && i["last_lead_ms"].is_null(),
        "{i}"
    );
    // The aligned averages come on the statuses of every 50th tick only (at most 6 statuses away).
    let mut aligned = None;
    for _ in 0..7 {
        let status = next_of(&mut ws, "status").await;
        let seq = status["seq"].as_u64().unwrap();
        match status["interaction"].get("aligned") {
            Some(a) => {
                assert_eq!(seq % 50, 0, "{status}");
                aligned = Some(a.clone());
                break;
            }
            None => assert_ne!(seq % 50, 0, "{status}"),
        }
    }
    let a = aligned.expect("an aligned payload within 7 statuses");
    assert_eq!(a["offsets_ms"].as_array().unwrap().len(), 76, "{a}");
    assert_eq!(a["reactive"]["commands"], 0, "{a}");
    assert_eq!(a["pavlovian"]["commands"], 0, "{a}");
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_can_ask_for_a_lower_rate() {
    let lab = start().await;
    let mut feed = lab.server.feed().subscribe();
    let (mut ws, _) = lab.connect().await;
    let ack = command(&mut ws, json!({"cmd":"set_rate","hz":10}), 1).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    assert_eq!(ack["result"]["every"], 5);
    assert_eq!(ack["result"]["rate_hz"], 10.0);
    let mut seqs = Vec::new();
    while seqs.len() < 8 {
        seqs.push(next_of(&mut ws, "tick").await["seq"].as_u64().unwrap());
    }
    assert!(seqs.windows(2).all(|w| w[1] - w[0] >= 5), "{seqs:?}");
    // Each is the first tick made at least 5 after the one before (on a busy machine the ticker may skip
    // the fifth: then the next one made goes), unless counted as lost for this client.
    let lost =
        lab.dash.telemetry_dropped_for(client_addr(&ws)).unwrap() + lab.dash.stats().records_missed;
    let mut made = Vec::new();
    while made.last().is_none_or(|&s| s < *seqs.last().unwrap()) {
        made.push(feed.recv().await.unwrap().seq);
    }
    let late = seqs
        .windows(2)
        .filter(|w| made.iter().any(|&m| m >= w[0] + 5 && m < w[1]))
        .count();
    assert!(late as u64 <= lost, "{seqs:?}, made {made:?}");
    // Back to full rate.
    command(&mut ws, json!({"cmd":"set_rate","hz":1000}), 2).await;
    let a = next_of(&mut ws, "tick").await["seq"].as_u64().unwrap();
    let b = next_of(&mut ws, "tick").await["seq"].as_u64().unwrap();
    let c = next_of(&mut ws, "tick").await["seq"].as_u64().unwrap();
    assert!(b - a < 5 || c - b < 5, "{a} {b} {c}");
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_bad_message_gets_an_error_and_the_connection_stays_open() {
    let lab = start().await;
    let (mut ws, _) = lab.connect().await;
    let cases: &[(&str, Value, &str, &str)] = &[
        // (message, expected id, code, a word the message must contain)
        (r#"{"cmd":"estop","id":1"#, Value::Null, "bad_json", "EOF"),
        ("not json at all", Value::Null, "bad_json", "expected"),
        ("[1,2,3]", Value::Null, "bad_message", "array"),
        ("42", Value::Null, "bad_message", "number"),
        (
            r#"{"cmd":"estop","id":{"a":1}}"#,
            Value::Null,
            "bad_id",
            "object",
        ),
        (r#"{"id":7}"#, json!(7), "missing_cmd", "cmd"),
        (r#"{"id":8,"cmd":12}"#, json!(8), "missing_cmd", "cmd"),
        (
            r#"{"id":"u","cmd":"self_destruct"}"#,
            json!("u"),
            "unknown_command",
            "self_destruct",
        ),
        (
            r#"{"id":9,"cmd":"set_mode","mode":"turbo"}"#,
            json!(9),
            "bad_arguments",
            "turbo",
        ),
        (
            r#"{"id":10,"cmd":"set_mode"}"#,
            json!(10),
            "bad_arguments",
            "mode",
        ),
        (
            r#"{"id":11,"cmd":"estop","now":true}"#,
            json!(11),
            "bad_arguments",
            "now",
        ),
        (
            r#"{"id":12,"cmd":"teleop","left_mm_s":"fast","right_mm_s":0}"#,
            json!(12),
            "bad_arguments",
            "fast",
        ),
        (
            r#"{"id":13,"cmd":"teleop","left_mm_s":99999,"right_mm_s":0}"#,
            json!(13),
            "bad_arguments",
            "99999",
        ),
        (
            r#"{"id":14,"cmd":"set_rate","hz":0}"#,
            json!(14),
            "bad_arguments",
            "hz",
        ),
        (
            r#"{"id":15,"cmd":"set_params","alpha":"big"}"#,
            json!(15),
            "bad_arguments",
            "big",
        ),
        // Well-formed, but refused by the server.
        (
            r#"{"id":16,"cmd":"teleop","left_mm_s":100,"right_mm_s":100}"#,
            json!(16),
            "rejected",
            "manual",
        ),
        (
            r#"{"id":17,"cmd":"teleop","left_mm_s":600,"right_mm_s":0}"#,
            json!(17),
            "rejected",
            "500",
        ),
        (
            r#"{"id":18,"cmd":"set_params","prediction":"nope","alpha":0.1}"#,
            json!(18),
            "rejected",
            "nope",
        ),
    ];
    for (i, (text, id, code, word)) in cases.iter().enumerate() {
        send(&mut ws, *text).await;
        let reply = loop {
            let v = next_json(&mut ws).await;
            if v["type"] == "error" || v["type"] == "ack" {
                break v;
            }
        };
        assert_eq!(reply["type"], "error", "{text} → {reply}");
        assert_eq!(reply["id"], *id, "{text} → {reply}");
        assert_eq!(reply["code"], *code, "{text} → {reply}");
        let message = reply["message"].as_str().unwrap();
        assert!(message.contains(word), "{text} → {message}");
        // Still open and answering.
        let pong = command(&mut ws, json!({"cmd":"ping"}), 1000 + i as u64).await;
        assert_eq!(pong["type"], "ack", "after {text}: {pong}");
    }
    // A binary frame is refused the same way.
    ws.send(Message::binary(vec![1u8, 2, 3])).await.unwrap();
    let reply = next_of(&mut ws, "error").await;
    assert_eq!(reply["code"], "binary_unsupported");
    assert_eq!(
        command(&mut ws, json!({"cmd":"ping"}), 2000).await["type"],
        "ack"
    );
    assert!(lab.dash.stats().errors > cases.len() as u64);
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_oversize_message_closes_the_connection_with_1009() {
    let lab = start_with(|c| c.dashboard.max_message_bytes = 4096).await;
    let (mut ws, hello) = lab.connect().await;
    assert_eq!(hello["limits"]["max_message_bytes"], 4096);
    let big = format!(r#"{{"cmd":"ping","pad":"{}"}}"#, "x".repeat(8000));
    send(&mut ws, big).await;
    let code = loop {
        match tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("closed within 5 s")
        {
            Some(Ok(Message::Close(Some(frame)))) => break Some(frame.code),
            Some(Ok(Message::Close(None))) | None | Some(Err(_)) => break None,
            Some(Ok(_)) => continue,
        }
    };
    assert_eq!(code, Some(CloseCode::Size));
    // The server is fine: a new client connects.
    let (_ws2, hello) = lab.connect().await;
    assert_eq!(hello["type"], "hello");
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_message_just_under_the_cap_is_parsed() {
    let lab = start_with(|c| c.dashboard.max_message_bytes = 4096).await;
    let (mut ws, _) = lab.connect().await;
    let text = format!(r#"{{"cmd":"ping","id":1,"pad":"{}"}}"#, "x".repeat(3900));
    assert!(text.len() < 4096);
    send(&mut ws, text).await;
    let reply = reply_to(&mut ws, &json!(1)).await;
    assert_eq!(reply["code"], "bad_arguments", "{reply}");
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn estop_stops_the_robot_until_released() {
    let lab = start().await;
    let (mut ws, _) = lab.connect().await;
    // The default policy drives the wheels.
    tick_where(&mut ws, Duration::from_secs(3), |t| {
        t["command"]["left"] != 0 || t["command"]["right"] != 0
    })
    .await;
    let ack = command(&mut ws, json!({"cmd":"estop"}), 1).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    assert_eq!(ack["cmd"], "estop");
    assert_eq!(ack["result"]["estop"], true);
    let stopped = |t: &Value| {
        t["estop"] == true
            && t["command"] == json!({"left":0,"right":0})
            && t["safety_stop"] == "e_stop"
    };
    tick_where(&mut ws, Duration::from_secs(1), stopped).await;
    for _ in 0..50 {
        let t = next_of(&mut ws, "tick").await;
        assert!(stopped(&t), "the e-stop did not hold: {t}");
    }
    let ack = command(&mut ws, json!({"cmd":"release"}), 2).await;
    assert_eq!(ack["result"]["estop"], false);
    tick_where(&mut ws, Duration::from_secs(3), |t| {
        t["estop"] == false && (t["command"]["left"] != 0 || t["command"]["right"] != 0)
    })
    .await;
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn manual_mode_and_teleop_drive_the_wheels() {
    let lab = start().await;
    let (mut ws, _) = lab.connect().await;
    let ack = command(&mut ws, json!({"cmd":"set_mode","mode":"manual"}), 1).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    tick_where(&mut ws, Duration::from_secs(1), |t| t["mode"] == "manual").await;
    let ack = command(
        &mut ws,
        json!({"cmd":"teleop","left_mm_s":120,"right_mm_s":-120}),
        2,
    )
    .await;
    assert_eq!(ack["type"], "ack", "{ack}");
    tick_where(&mut ws, Duration::from_secs(1), |t| {
        t["command"] == json!({"left":120,"right":-120})
    })
    .await;
    // Without a refresh the teleop command expires and the wheels stop.
    tick_where(&mut ws, Duration::from_secs(2), |t| {
        t["command"] == json!({"left":0,"right":0})
    })
    .await;
    let ack = command(&mut ws, json!({"cmd":"set_mode","mode":"reactive"}), 3).await;
    assert_eq!(ack["type"], "ack");
    tick_where(&mut ws, Duration::from_secs(1), |t| t["mode"] == "reactive").await;
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn learning_commands_are_applied() {
    let dir = tempdir::TempDir::new("weights");
    let weights_dir = dir.path().to_path_buf();
    let lab = start_with(move |cfg| cfg.checkpoint.dir = weights_dir.display().to_string()).await;
    let (mut ws, _) = lab.connect().await;
    let ack = command(
        &mut ws,
        json!({"cmd":"set_params","alpha":0.01,"lambda":0.7,"threshold":0.3}),
        1,
    )
    .await;
    assert_eq!(ack["type"], "ack", "{ack}");
    tick_where(&mut ws, Duration::from_secs(1), |t| {
        t["predictions"][0]["threshold"] == 0.3
    })
    .await;
    let ack = command(&mut ws, json!({"cmd":"human_request","duration_ms":200}), 2).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    let ack = command(&mut ws, json!({"cmd":"reset_weights"}), 3).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    // Saves go into `[checkpoint] dir/saved/`, apart from the automatic checkpoints.
    let path = dir.path().join("saved").join("w.json");
    let ack = command(&mut ws, json!({"cmd":"save_weights","path":"w.json"}), 4).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    assert_eq!(ack["result"]["path"], path.display().to_string(), "{ack}");
    // A client names a file, never a place on the server's disk.
    let outside = command(
        &mut ws,
        json!({"cmd":"save_weights","path":"/tmp/evil.json"}),
        5,
    )
    .await;
    assert_eq!(outside["type"], "error", "{outside}");
    assert_eq!(outside["code"], "rejected", "{outside}");
    assert!(
        outside["message"]
            .as_str()
            .is_some_and(|m| m.contains("absolute path")),
        "{outside}"
    );
    let up = command(&mut ws, json!({"cmd":"save_weights","path":"../w.json"}), 6).await;
    assert_eq!(up["type"], "error", "{up}");
    assert!(
        up["message"]
            .as_str()
            .is_some_and(|m| m.contains("path separator")),
        "{up}"
    );
    // Nor the automatic checkpoints' names, nor a save that exists.
    let reserved = command(
        &mut ws,
        json!({"cmd":"save_weights","path":"checkpoint-99999999990.json"}),
        7,
    )
    .await;
    assert!(
        reserved["message"]
            .as_str()
            .is_some_and(|m| m.contains("reserved")),
        "{reserved}"
    );
    let again = command(&mut ws, json!({"cmd":"save_weights","path":"w.json"}), 8).await;
    assert!(
        again["message"]
            .as_str()
            .is_some_and(|m| m.contains("never overwrites")),
        "{again}"
    );
    let deadline = std::time::Instant::now() + WAIT;
    while !path.exists() && std::time::Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(path.exists(), "weights not written to {}", path.display());
    // Recording commands are always answered (ack when a recorder runs, `rejected` otherwise).
    for (i, cmd) in ["start_recording", "stop_recording"]
        .into_iter()
        .enumerate()
    {
        let r = command(&mut ws, json!({ "cmd": cmd }), 10 + i as u64).await;
        assert!(r["type"] == "ack" || r["code"] == "rejected", "{cmd}: {r}");
        assert_eq!(r["id"], 10 + i as u64);
    }
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_token_only_its_holder_may_command() {
    let lab = start_with(|c| c.dashboard.token = Some("s3cret".into())).await;
    assert_eq!(
        lab.server.config().dashboard.token.as_deref(),
        Some("s3cret")
    );
    // Without the token: watch-only.
    let (mut ws, hello) = lab.connect().await;
    assert_eq!(hello["can_command"], false);
    assert!(hello["config"].get("dashboard").is_none(), "{hello}");
    let r = command(&mut ws, json!({"cmd":"estop"}), 1).await;
    assert_eq!(r["code"], "unauthorized", "{r}");
    let r = command(&mut ws, json!({"cmd":"set_rate","hz":25}), 2).await;
    assert_eq!(r["type"], "ack", "session commands need no token: {r}");
    next_of(&mut ws, "tick").await;
    // A wrong token is refused in the handshake.
    let e = lab.try_connect("?token=guess", &[]).await.unwrap_err();
    assert_eq!(handshake_status(e), 401);
    let e = lab
        .try_connect("", &[("Sec-WebSocket-Protocol", "pavlov.v1, token.guess")])
        .await
        .unwrap_err();
    assert_eq!(handshake_status(e), 401);
    // The token in the query string.
    let mut ws = lab.try_connect("?token=s3cret", &[]).await.unwrap();
    assert_eq!(next_json(&mut ws).await["can_command"], true);
    assert_eq!(
        command(&mut ws, json!({"cmd":"estop"}), 3).await["type"],
        "ack"
    );
    // The token as a subprotocol: the server selects pavlov.v1, never echoes the token.
    let mut req = lab.url("").into_client_request().unwrap();
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static("pavlov.v1, token.s3cret"),
    );
    let (mut ws, resp) = tokio_tungstenite::connect_async(req).await.unwrap();
    assert_eq!(
        resp.headers().get("sec-websocket-protocol").unwrap(),
        "pavlov.v1"
    );
    assert_eq!(next_json(&mut ws).await["can_command"], true);
    assert_eq!(
        command(&mut ws, json!({"cmd":"release"}), 4).await["type"],
        "ack"
    );
    assert!(lab.dash.stats().rejected >= 2);
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watching_without_the_token_can_be_forbidden() {
    let lab = start_with(|c| {
        c.dashboard.token = Some("s3cret".into());
        c.dashboard.watch_without_token = false;
    })
    .await;
    let e = lab.try_connect("", &[]).await.unwrap_err();
    assert_eq!(handshake_status(e), 401);
    let mut ws = lab.try_connect("?token=s3cret", &[]).await.unwrap();
    assert_eq!(next_json(&mut ws).await["type"], "hello");
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_origin_header_is_checked_against_the_allowlist() {
    let lab =
        start_with(|c| c.dashboard.allowed_origins = vec!["https://lab.example.org".into()]).await;
    let port = lab.addr().port();
    for bad in ["http://evil.example", "http://127.0.0.1:1", "null"] {
        let e = lab.try_connect("", &[("Origin", bad)]).await.unwrap_err();
        assert_eq!(handshake_status(e), 403, "{bad}");
    }
    let own = format!("http://127.0.0.1:{port}");
    let local = format!("http://localhost:{port}");
    for good in [own.as_str(), local.as_str(), "https://lab.example.org"] {
        let mut ws = lab.try_connect("", &[("Origin", good)]).await.unwrap();
        assert_eq!(next_json(&mut ws).await["type"], "hello", "{good}");
    }
    // Non-browser clients send no Origin at all.
    lab.connect().await;
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_beyond_the_limit_are_refused_until_one_leaves() {
    let lab = start_with(|c| c.dashboard.max_operators = 2).await;
    let (a, _) = lab.connect().await;
    let (_b, _) = lab.connect().await;
    let e = lab.try_connect("", &[]).await.unwrap_err();
    assert_eq!(handshake_status(e), 503);
    drop(a);
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        match lab.try_connect("", &[]).await {
            Ok(_) => break,
            Err(e) => {
                assert_eq!(handshake_status(e), 503);
                assert!(
                    std::time::Instant::now() < deadline,
                    "the slot was never freed"
                );
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
    lab.stop().await;
}

/// A websocket client with a tiny receive buffer that never reads.
async fn stalled_client(addr: SocketAddr) -> Ws {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    let stream = sock.connect(addr).await.unwrap();
    let (ws, _) =
        tokio_tungstenite::client_async(format!("ws://{addr}/ws"), MaybeTlsStream::Plain(stream))
            .await
            .unwrap();
    ws
}

/// The local address of a client's socket (the endpoint knows the client by it).
fn client_addr(ws: &Ws) -> SocketAddr {
    match ws.get_ref() {
        MaybeTlsStream::Plain(s) => s.local_addr().unwrap(),
        _ => unreachable!("the tests connect without TLS"),
    }
}

/// Live ticks the healthy client reads before the counters are compared.
const HEALTHY_TICKS: usize = 250;

/// What the endpoint guarantees, on a busy machine too: each client's queue drops only its own oldest
/// telemetry, and counts what it drops. So the stalled client's queue (8 messages) overflows and counts it,
/// and every tick the tick feed produced between the healthy client's first and last tick reached the
/// healthy client, in order — except for as many as the endpoint counted as lost for the healthy client
/// itself (its own queue's drops) or as missed by the hub. Nothing here counts ticks against wall time: a
/// loaded machine may skip ticks (then the feed has no such record) or starve the healthy reader for more
/// than its queue holds (then its own counter says so); neither is the stalled client's doing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_client_loses_old_ticks_and_delays_nobody() {
    let lab = start_with(|c| c.dashboard.client_queue = 8).await;
    // Every record the feed produces from here on (the feed holds 20 s of records for a slow reader).
    // It returns once it has the tick `until` names (the healthy client's last).
    let mut feed = lab.server.feed().subscribe();
    let (until_tx, until) = tokio::sync::watch::channel(u64::MAX);
    let produced = tokio::spawn(async move {
        let mut seqs = Vec::new();
        while seqs.last().is_none_or(|&s| s < *until.borrow()) {
            match feed.recv().await {
                Ok(record) => seqs.push(record.seq),
                Err(e) => panic!("the test's own feed reader: {e}"),
            }
        }
        seqs
    });
    let stalled = stalled_client(lab.addr()).await;
    let (mut ws, _) = lab.connect().await;
    let dropped_for = |ws: &Ws| lab.dash.telemetry_dropped_for(client_addr(ws));
    let missed_before = lab.dash.stats().records_missed;
    let mut received: Vec<u64> = Vec::new();
    // Until the healthy client has its ticks and the stalled one's queue has overflowed (a generous bound:
    // at 50 Hz this takes about 5 s on an idle machine).
    tokio::time::timeout(Duration::from_secs(120), async {
        while received.len() < HEALTHY_TICKS || dropped_for(&stalled) == Some(0) {
            let seq = next_of(&mut ws, "tick").await["seq"].as_u64().unwrap();
            if let Some(&last) = received.last() {
                assert!(seq > last, "tick {seq} after {last}");
            }
            received.push(seq);
        }
    })
    .await
    .unwrap_or_else(|_| {
        panic!(
            "{} ticks in 120 s; the stalled client dropped {:?}",
            received.len(),
            dropped_for(&stalled)
        )
    });
    let stalled_dropped = dropped_for(&stalled).expect("the stalled client is still connected");
    let healthy_dropped = dropped_for(&ws).expect("the healthy client is connected");
    let stats = lab.dash.stats();
    let hub_missed = stats.records_missed - missed_before;
    assert_eq!(stats.clients, 2);
    assert!(stalled_dropped > 0, "{stats:?}");
    let (first, last) = (received[0], *received.last().unwrap());
    until_tx.send_replace(last);
    let produced: Vec<u64> = produced
        .await
        .unwrap()
        .into_iter()
        .filter(|s| (first..=last).contains(s))
        .collect();
    // Nothing the feed did not produce, and each produced tick received or counted as lost.
    let produced_set: std::collections::BTreeSet<u64> = produced.iter().copied().collect();
    assert!(
        received.iter().all(|s| produced_set.contains(s)),
        "the client got ticks the feed never produced"
    );
    let missing = produced.len() - received.len();
    assert!(
        missing as u64 <= healthy_dropped + hub_missed,
        "the healthy client missed {missing} of the {} ticks produced between {first} and {last}, \
         but only {healthy_dropped} messages were dropped for it and the hub missed {hub_missed} \
         (the stalled client dropped {stalled_dropped})",
        produced.len()
    );
    eprintln!(
        "healthy: {} of {} produced ticks, {healthy_dropped} dropped for it; stalled: {stalled_dropped} \
         dropped; hub missed {hub_missed}",
        received.len(),
        produced.len()
    );
    drop((stalled, ws));
    lab.stop().await;
}

async fn http_get(addr: SocketAddr, path: &str) -> (u16, String, String) {
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(WAIT, s.read_to_end(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let text = String::from_utf8_lossy(&buf).to_string();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, head.to_ascii_lowercase(), body.to_string())
}

/// `/healthz` once the first ticks are out (it answers 503 until the tick loop and the link are up).
async fn healthy(addr: SocketAddr) -> (u16, String) {
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        let (status, _, body) = http_get(addr, "/healthz").await;
        if status == 200 || std::time::Instant::now() > deadline {
            return (status, body);
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "current_thread")]
async fn healthz_says_when_the_tick_loop_stalls() {
    // The server's actors share this test's one runtime thread; the dashboard has its own.
    let lab = start().await;
    let addr = lab.addr();
    assert_eq!(healthy(addr).await, (200, "ok".to_string()));
    // Block the control runtime for 1.6 s and ask from another thread meanwhile.
    let probe = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(1300));
        let mut s = std::net::TcpStream::connect(addr).unwrap();
        use std::io::{Read, Write};
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
            .unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).unwrap();
        text
    });
    std::thread::sleep(Duration::from_millis(1600));
    let text = probe.join().unwrap();
    assert!(text.starts_with("HTTP/1.1 503"), "{text}");
    assert!(
        text.contains("the tick loop is stalled: no tick for"),
        "{text}"
    );
    // It recovers once ticks flow again.
    assert_eq!(healthy(addr).await, (200, "ok".to_string()));
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_its_assets_and_healthz_are_served() {
    let lab = start().await;
    let addr = lab.addr();
    let (status, head, body) = http_get(addr, "/").await;
    assert_eq!(status, 200);
    assert!(head.contains("content-type: text/html"));
    assert!(head.contains("content-security-policy"));
    assert!(body.contains("E-STOP") && body.contains("/vendor/uplot.iife.min.js"));
    let (status, head, body) = http_get(addr, "/app.js").await;
    assert_eq!(status, 200);
    assert!(head.contains("javascript"));
    assert!(body.contains("new WebSocket"));
    assert_eq!(http_get(addr, "/lib.js").await.0, 200);
    assert_eq!(http_get(addr, "/style.css").await.0, 200);
    // uPlot, built into the binary from web/node_modules.
    let (status, _, body) = http_get(addr, "/vendor/uplot.iife.min.js").await;
    assert_eq!(status, 200);
    assert!(
        body.contains("uPlot") && body.len() > 20_000,
        "{}",
        body.len()
    );
    assert_eq!(http_get(addr, "/vendor/uplot.min.css").await.0, 200);
    assert_eq!(healthy(addr).await, (200, "ok".to_string()));
    assert_eq!(http_get(addr, "/nope").await.0, 404);
    // A plain GET of /ws is not an upgrade.
    assert!(http_get(addr, "/ws").await.0 >= 400);
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_web_dir_without_uplot_is_reported_with_the_install_command() {
    let mut cfg = Config::from_toml(STALL_CONFIG).unwrap();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    // --web-dir with the page but no node_modules: the page is read from it, uPlot's absence is named.
    let dev = tempdir::TempDir::new("dev-web");
    std::fs::write(dev.path().join("index.html"), "<p>the page under work</p>").unwrap();
    let dash = Dashboard::start(&server, WebAssets::Dir(dev.path().to_path_buf()))
        .await
        .unwrap();
    let (status, _, body) = http_get(dash.local_addr(), "/vendor/uplot.iife.min.js").await;
    assert_eq!(status, 503);
    assert!(body.contains("npm ci --prefix web"), "{body}");
    let (status, _, body) = http_get(dash.local_addr(), "/").await;
    assert_eq!((status, body.as_str()), (200, "<p>the page under work</p>"));
    let (status, _, body) = http_get(dash.local_addr(), "/app.js").await;
    assert_eq!(status, 503);
    assert!(body.contains("--web-dir"), "{body}");
    dash.shutdown().await;
    stop_server(server).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_closes_clients_with_going_away() {
    let lab = start().await;
    let (mut ws, _) = lab.connect().await;
    next_of(&mut ws, "tick").await;
    let Lab { server, dash } = lab;
    dash.shutdown().await;
    let code = loop {
        match tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("closed within 5 s")
        {
            Some(Ok(Message::Close(frame))) => break frame.map(|f| f.code),
            Some(Ok(_)) => continue,
            None | Some(Err(_)) => break None,
        }
    };
    assert_eq!(code, Some(CloseCode::Away));
    stop_server(server).await;
}
