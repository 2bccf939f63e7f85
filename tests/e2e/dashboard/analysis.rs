//! What the dashboard needs for analysis, from the server's side, over real sockets: a client that connects
//! mid-run gets the recent history after `hello` (in messages within the size limit, then live ticks from
//! where it ends), every event reaches operators and watchers (a watcher's without file paths), `hello`
//! says what is in force and which robot, and an operator can download the recording being written (a
//! finished copy of it).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov::config::Config;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recorder::Recorder;
use pavlov_actors::storage::recording::RecordingHeader;
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::Message;

use super::rig::{TOKEN, Ws, loopback, tcp_from, ws_from};

const STALL_CONFIG: &str = include_str!("../../../config/stall.toml");
const WAIT: Duration = Duration::from_secs(10);

struct Lab {
    server: Server,
    dash: Dashboard,
    recorder: Recorder,
    root: PathBuf,
}

impl Lab {
    /// The stall experiment with a token, a recorder whose recordings go under a fresh folder, after `edit`.
    async fn start(name: &str, edit: impl FnOnce(&mut Config)) -> Lab {
        let mut cfg = Config::from_toml(STALL_CONFIG).unwrap();
        cfg.dashboard.bind = "127.0.0.1:0".into();
        cfg.dashboard.token = Some(TOKEN.into());
        edit(&mut cfg);
        cfg.validate().unwrap();
        let root = std::env::temp_dir().join(format!("pavlov-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let recorder = Recorder::spawn(
            RecordingHeader::new(&cfg, "analysis"),
            None,
            root.clone(),
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
        Lab {
            server,
            dash,
            recorder,
            root,
        }
    }

    fn addr(&self) -> SocketAddr {
        self.dash.local_addr()
    }

    /// Waits for `n` ticks on the server's feed and returns the last one's `seq`.
    async fn ticks(&self, n: usize) -> u64 {
        let mut feed = self.server.feed().subscribe();
        let mut last = 0;
        for _ in 0..n {
            last = feed.recv().await.unwrap().seq;
        }
        last
    }

    async fn stop(self) {
        self.dash.shutdown().await;
        let _ = tokio::time::timeout(WAIT, self.server.shutdown()).await;
        let recorder = self.recorder;
        let _ = tokio::task::spawn_blocking(move || recorder.join()).await;
        let _ = std::fs::remove_dir_all(&self.root);
    }
}

/// `GET path` from 127.0.0.`from`: the status and the body's bytes.
async fn get(from: u8, addr: SocketAddr, path: &str) -> (u16, Vec<u8>) {
    let mut s = tcp_from(loopback(from), addr).await.unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
    s.write_all(request.as_bytes()).await.unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(WAIT, s.read_to_end(&mut buf))
        .await
        .expect("an answer in time")
        .unwrap();
    let head_end = buf.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&buf[..head_end]).to_string();
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, buf[head_end + 4..].to_vec())
}

/// The next text message, with its length in bytes.
async fn next_text(ws: &mut Ws) -> (Value, usize) {
    loop {
        let msg = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("a message in time")
            .expect("open")
            .expect("no error");
        if let Message::Text(t) = msg {
            return (serde_json::from_str(&t).unwrap(), t.len());
        }
    }
}

/// A client that keeps what it skipped, so that waiting for one message never loses another (an event
/// may come before or after the ack of the command that made it).
struct Client {
    ws: Ws,
    skipped: Vec<Value>,
}

impl Client {
    fn new(ws: Ws) -> Self {
        Client {
            ws,
            skipped: Vec::new(),
        }
    }

    /// The first message (skipped earlier or new) of `kind` that satisfies `pred`.
    async fn next_where(&mut self, kind: &str, pred: impl Fn(&Value) -> bool) -> Value {
        let matches = |v: &Value| v["type"] == kind && pred(v);
        if let Some(i) = self.skipped.iter().position(&matches) {
            return self.skipped.remove(i);
        }
        let deadline = tokio::time::Instant::now() + WAIT;
        loop {
            let (v, _) = next_text(&mut self.ws).await;
            if matches(&v) {
                return v;
            }
            if v["type"] != "tick" && v["type"] != "status" && v["type"] != "learning" {
                self.skipped.push(v);
            }
            assert!(
                tokio::time::Instant::now() < deadline,
                "no {kind} as expected within {WAIT:?}; skipped {:?}",
                self.skipped
            );
        }
    }

    /// Sends a command and waits for its ack.
    async fn ack(&mut self, cmd: Value, id: u64) -> Value {
        let mut cmd = cmd;
        cmd["id"] = json!(id);
        self.ws.send(Message::text(cmd.to_string())).await.unwrap();
        self.next_where("ack", |v| v["id"] == id).await
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_connecting_mid_run_gets_the_recent_history_in_small_messages_then_live_ticks() {
    // 2 s of history; messages of at most 2 KiB, so it must come in many.
    let lab = Lab::start("history", |c| {
        c.dashboard.history_s = 2;
        c.dashboard.max_message_bytes = 2048;
    })
    .await;
    // Every record the feed makes (it holds 20 s of them), to tell a tick skipped on a busy machine from
    // one the history or the live stream lost.
    let mut feed = lab.server.feed().subscribe();
    lab.ticks(200).await;
    let (mut ws, hello) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    assert_eq!(hello["history_s"], 2, "{hello}");
    assert_eq!(
        hello["robot"],
        json!({"model":"create1","link":"simulated","port":null})
    );
    assert!(hello["run"].as_str().is_some_and(|r| !r.is_empty()));
    let p = &hello["in_force"]["params"][0];
    assert_eq!(p["prediction"], "stall", "{hello}");
    assert_eq!(p["threshold"], 0.5, "{hello}");
    assert!(p["alpha"].as_f64().is_some_and(|a| a > 0.0), "{hello}");
    assert_eq!(hello["in_force"]["mode"], "pavlovian");
    assert_eq!(hello["in_force"]["recording"], Value::Null);

    let mut rows = Vec::new();
    let mut messages = 0;
    loop {
        let (v, len) = next_text(&mut ws).await;
        assert_eq!(
            v["type"], "history",
            "the history comes right after hello: {v}"
        );
        assert!(len <= 2048, "a history message of {len} bytes");
        messages += 1;
        rows.extend(v["rows"].as_array().unwrap().iter().cloned());
        if v["more"] == false {
            break;
        }
    }
    // About 20 rows of ~100 bytes in each (never 30 in 2 KiB): as many messages as that takes, however
    // many ticks a busy machine made in the 2 s.
    assert!(
        messages >= rows.len().div_ceil(30),
        "{messages} messages for {} rows",
        rows.len()
    );
    let seqs: Vec<u64> = rows.iter().map(|r| r[0].as_u64().unwrap()).collect();
    let last = *seqs.last().unwrap();
    // The history ends at the newest tick the hub had when the client joined (the hub is a subscriber of
    // the feed like the test, so on a loaded machine it may trail the test's 200th: the live ticks go on
    // from there, checked below), not at a distance in ticks from it.
    let missed_by_hub = lab.dash.stats().records_missed;
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    // Exactly the last 2 s: no row older than 100 ticks of 20 ms before the newest, and every tick the
    // feed made in them (fewer than 100 only if the ticker skipped some on a busy machine).
    assert!(seqs[0] + 99 >= last, "{seqs:?}");
    let mut made = Vec::new();
    let mut newest_made = 0;
    while newest_made < last {
        newest_made = feed.recv().await.unwrap().seq;
        if newest_made + 99 >= last && newest_made <= last {
            made.push(newest_made);
        }
    }
    assert!(seqs.iter().all(|s| made.contains(s)), "{seqs:?} {made:?}");
    assert!(
        (made.len() - seqs.len()) as u64 <= missed_by_hub,
        "the history lacks ticks the feed made: {seqs:?}, made {made:?}"
    );
    let row = &rows[0];
    assert_eq!(row.as_array().unwrap().len(), 17, "{row}");
    assert_eq!(row[2], "pavlovian");
    assert_eq!(row[14], "up");
    assert!(row[15][0][0].is_number() && row[15][0][1] == 0.5, "{row}");
    // Live ticks go on from where the history ends: none repeated.
    let first_live = Client::new(ws).next_where("tick", |_| true).await;
    let first_live = first_live["seq"].as_u64().unwrap();
    assert!(first_live > last, "{first_live} after {last}");
    // …the next the feed made after the history's last (nothing in between lost; the client's own queue
    // holds 5 s, far more than reading the history takes).
    while newest_made < first_live {
        newest_made = feed.recv().await.unwrap().seq;
        assert!(
            newest_made >= first_live,
            "tick {newest_made} came between the history's last {last} and the first live {first_live}"
        );
    }
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_event_reaches_operators_and_watchers_and_the_next_hello_says_what_is_in_force() {
    let lab = Lab::start("events", |_| {}).await;
    lab.ticks(10).await;
    let (op, _) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    let (watcher, hello) = ws_from(loopback(2), lab.addr(), None).await.unwrap();
    let (mut op, mut watcher) = (Client::new(op), Client::new(watcher));
    assert_eq!(hello["can_command"], false);
    op.ack(
        json!({"cmd": "set_params", "alpha": 0.01, "threshold": 0.4}),
        1,
    )
    .await;
    op.ack(json!({"cmd": "set_mode", "mode": "reactive"}), 2)
        .await;
    op.ack(json!({"cmd": "start_recording", "dir": "r1"}), 3)
        .await;
    for client in [&mut op, &mut watcher] {
        let e = client
            .next_where("event", |v| v["kind"] == "params_set")
            .await;
        assert_eq!(
            (
                e["prediction"].clone(),
                e["alpha"].clone(),
                e["threshold"].clone()
            ),
            (json!("stall"), json!(0.01), json!(0.4)),
            "{e}"
        );
        // `t` is the time of the first tick the change applies to.
        let t = e["t"].as_f64().unwrap();
        let after = e["after"].as_f64().unwrap();
        assert!((t - (after + 1.0) * 0.02).abs() < 1e-9, "{e}");
        let m = client
            .next_where("event", |v| v["kind"] == "mode_set")
            .await;
        assert_eq!(m["mode"], "reactive");
    }
    let started = op
        .next_where("event", |v| v["kind"] == "recording_started")
        .await;
    let path = started["path"].as_str().unwrap().to_string();
    assert!(path.contains("r1"), "{started}");
    let hidden = watcher
        .next_where("event", |v| v["kind"] == "recording_started")
        .await;
    assert_eq!(hidden["path"], "<redacted>", "{hidden}");

    // A client connecting now is told what is in force, and gets the events in its history.
    let (mut late, hello) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    let f = &hello["in_force"];
    assert_eq!(f["params"][0]["alpha"], 0.01, "{hello}");
    assert_eq!(f["params"][0]["threshold"], 0.4, "{hello}");
    assert_eq!(f["mode"], "reactive", "{hello}");
    assert_eq!(f["recording"], path.as_str(), "{hello}");
    let mut kinds = Vec::new();
    loop {
        let (v, _) = next_text(&mut late).await;
        assert_eq!(v["type"], "history");
        kinds.extend(
            v["events"]
                .as_array()
                .unwrap()
                .iter()
                .map(|e| e["kind"].clone()),
        );
        if v["more"] == false {
            break;
        }
    }
    for kind in ["params_set", "mode_set", "recording_started"] {
        assert!(kinds.contains(&json!(kind)), "{kind} not in {kinds:?}");
    }
    let (_, watcher_hello) = ws_from(loopback(3), lab.addr(), None).await.unwrap();
    assert_eq!(watcher_hello["in_force"]["recording"], "<redacted>");

    // The recording being written: an operator's download, nobody else's.
    let addr = lab.addr();
    lab.ticks(60).await;
    let (status, body) = get(1, addr, &format!("/recording?token={TOKEN}")).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert!(body.len() > 100, "{} bytes", body.len());
    // A finished copy of the file as far as written (tests/e2e/dashboard/download.rs checks it whole).
    let copy = pavlov_actors::storage::recording::from_bytes(&body).expect("the download reads");
    assert!(!copy.torn_tail, "the download is a finished file");
    assert!(!copy.records.is_empty());
    let (status, _) = get(4, addr, "/recording").await;
    assert_eq!(status, 403, "a watcher may not download it");
    let (status, _) = get(5, addr, "/recording?token=wrong").await;
    assert_eq!(status, 401);
    op.ack(json!({"cmd": "stop_recording"}), 4).await;
    op.next_where("event", |v| v["kind"] == "recording_stopped")
        .await;
    let (status, body) = get(1, addr, &format!("/recording?token={TOKEN}")).await;
    assert_eq!(status, 404, "{}", String::from_utf8_lossy(&body));
    lab.stop().await;
}
