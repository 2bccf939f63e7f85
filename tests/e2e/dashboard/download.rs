//! `GET /recording` over real sockets while the recorder writes (issue 22, item 4): the download is a
//! finished MCAP file that the `mcap` Python package's `make_reader(...).iter_messages()` opens, holding
//! every tick the dashboard had before the request; a client reading it at about 100 kB/s, for far longer
//! than the request-head deadline, gets all of it, as long as `Content-Length` says, while a second
//! download is answered busy; and `/recording` and `/metrics` refuse a `Host` that is not this server's
//! (a DNS-rebinding page's).
//!
//! Every wait is bounded generously and every assertion is on bytes and contents, never on time.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recorder::Recorder;
use pavlov_actors::storage::recording::{self, RecordingHeader};
use serde_json::Value;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

use super::rig::{TOKEN, loopback, next_json, tcp_from, ws_from};
use crate::common::{TestDir, stall_config};

/// The longest any one download may take to arrive (it waits for the recorder's flush, at most 10 s).
const WAIT: Duration = Duration::from_secs(60);

/// A server recording from its start, with its dashboard.
struct Lab {
    server: Server,
    dash: Dashboard,
    recorder: Recorder,
    dir: TestDir,
}

impl Lab {
    /// The stall experiment with a token, recording into a fresh folder with `label`.
    async fn start(name: &str, label: &str) -> Lab {
        let mut cfg = stall_config();
        cfg.dashboard.bind = "127.0.0.1:0".into();
        cfg.dashboard.token = Some(TOKEN.into());
        cfg.validate().unwrap();
        let dir = TestDir::new(name);
        let recorder = Recorder::spawn(
            RecordingHeader::new(&cfg, label),
            Some(dir.join("rec")),
            dir.to_path_buf(),
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
            dir,
        }
    }

    fn addr(&self) -> SocketAddr {
        self.dash.local_addr()
    }

    /// Waits for `n` more ticks on the server's feed, then until the dashboard has them too (an operator
    /// is sent a tick at least as new); returns the newest one's `seq`.
    async fn ticks_seen_by_the_dashboard(&self, n: usize) -> u64 {
        let mut feed = self.server.feed().subscribe();
        let mut last = 0;
        for _ in 0..n {
            last = tokio::time::timeout(WAIT, feed.recv())
                .await
                .expect("ticks in time")
                .unwrap()
                .seq;
        }
        let (mut ws, _) = ws_from(loopback(1), self.addr(), Some(TOKEN))
            .await
            .unwrap();
        loop {
            let v = next_json(&mut ws).await;
            if v["type"] == "tick" && v["seq"].as_u64().is_some_and(|s| s >= last) {
                return last;
            }
        }
    }

    async fn stop(self) {
        self.dash.shutdown().await;
        let _ = tokio::time::timeout(WAIT, self.server.shutdown()).await;
        let recorder = self.recorder;
        let _ = tokio::task::spawn_blocking(move || recorder.join()).await;
        drop(self.dir);
    }
}

/// A response: the status, the head's lines (lowercase names), the body.
struct Answer {
    status: u16,
    head: String,
    body: Vec<u8>,
}

impl Answer {
    fn header(&self, name: &str) -> Option<&str> {
        self.head.lines().find_map(|line| {
            let (n, v) = line.split_once(':')?;
            n.trim().eq_ignore_ascii_case(name).then(|| v.trim())
        })
    }

    fn content_length(&self) -> usize {
        self.header("content-length")
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no Content-Length in\n{}", self.head))
    }
}

fn request(path: &str, host: &str) -> String {
    format!("GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n")
}

/// Reads the response head from `s`; returns it and the body bytes read with it.
async fn read_head(s: &mut TcpStream) -> (u16, String, Vec<u8>) {
    let mut buf = Vec::new();
    let mut piece = [0u8; 4096];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let head = String::from_utf8_lossy(&buf[..end]).to_string();
            let status = head
                .split(' ')
                .nth(1)
                .and_then(|c| c.parse().ok())
                .unwrap_or(0);
            return (status, head, buf[end + 4..].to_vec());
        }
        let n = tokio::time::timeout(WAIT, s.read(&mut piece))
            .await
            .expect("a response head in time")
            .expect("a readable response");
        assert!(
            n > 0,
            "the connection closed before the head ended: {buf:?}"
        );
        buf.extend_from_slice(&piece[..n]);
    }
}

/// `GET path` with `Host: host` from 127.0.0.1, read at full speed.
async fn get(addr: SocketAddr, path: &str, host: &str) -> Answer {
    let mut s = tcp_from(loopback(1), addr).await.unwrap();
    s.write_all(request(path, host).as_bytes()).await.unwrap();
    let (status, head, mut body) = read_head(&mut s).await;
    tokio::time::timeout(WAIT, s.read_to_end(&mut body))
        .await
        .expect("the body in time")
        .expect("a readable body");
    Answer { status, head, body }
}

/// The venv tests/run.sh makes (`<target>/py-mcap`), or `PAVLOV_PYTHON`.
fn python() -> PathBuf {
    std::env::var_os("PAVLOV_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
                .parent()
                .expect("the target directory")
                .join("py-mcap")
                .join("bin")
                .join("python")
        })
}

/// What tests/python/read_mcap.py (Foxglove's `mcap` package: `make_reader`, its summary and
/// `iter_messages`) reads from `file`.
fn read_with_python(file: &Path) -> Value {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/python/read_mcap.py");
    let out = Command::new(python())
        .arg(script)
        .arg(file)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e}; install the reader: python3 -m venv <target>/py-mcap && <target>/py-mcap/bin/pip install -r tests/python/requirements.txt",
                python().display()
            )
        });
    assert!(
        out.status.success(),
        "the mcap Python package cannot read the download: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the reader prints JSON")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_download_taken_while_recording_opens_in_the_mcap_python_package_with_every_tick_before_it()
 {
    let lab = Lab::start("download-python", "download while recording").await;
    let addr = lab.addr();
    let before = lab.ticks_seen_by_the_dashboard(100).await;
    let answer = get(
        addr,
        &format!("/recording?token={TOKEN}"),
        &addr.to_string(),
    )
    .await;
    assert_eq!(
        answer.status,
        200,
        "{}",
        String::from_utf8_lossy(&answer.body)
    );
    assert_eq!(answer.body.len(), answer.content_length(), "whole");
    let file = lab.dir.join("download.mcap");
    std::fs::write(&file, &answer.body).unwrap();

    // The standard reader: its summary, and every message by iterating.
    let read = read_with_python(&file);
    assert_eq!(read["summary_counts"], read["counted"], "{read}");
    assert_eq!(read["counted"]["config"], 1);
    assert_eq!(read["counted"]["learner"], 1);
    let seqs: Vec<u64> = read["ticks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row[0].as_u64().unwrap())
        .collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    let last = *seqs.last().expect("ticks");
    assert!(
        last >= before,
        "the download ends at tick {last}, before tick {before} the dashboard had when it was asked for"
    );
    assert_eq!(
        answer.header("x-pavlov-ticks"),
        Some(seqs.len().to_string().as_str())
    );
    assert_eq!(
        answer.header("x-pavlov-last-tick"),
        Some(last.to_string().as_str())
    );
    assert_eq!(
        read["metadata"]["pavlov.recording"]["label"],
        "download while recording"
    );

    // pavlov reads the same ticks, as a finished file, not a torn one.
    let rec = recording::load(&file).expect("pavlov reads the download");
    assert!(!rec.torn_tail, "the download has its summary and footer");
    assert_eq!(rec.records.iter().map(|r| r.seq).collect::<Vec<_>>(), seqs);
    assert!(
        read["events"]
            .as_array()
            .unwrap()
            .contains(&Value::from("recording_started")),
        "{}",
        read["events"]
    );
    lab.stop().await;
}

/// `n` bytes of letters and digits that do not repeat in any short period.
fn noise(n: usize) -> String {
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            char::from(b"abcdefghijklmnopqrstuvwxyz0123456789"[(x % 36) as usize])
        })
        .collect()
}

/// Connects from 127.0.0.1 with a small receive buffer (so that the kernel holds little of a response the
/// client does not read yet), asks for the recording and reads the response head: the stream, the
/// `Content-Length` and the body bytes that came with the head.
async fn begin_download(addr: SocketAddr) -> (TcpStream, usize, Vec<u8>) {
    let sock = TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(16 * 1024).unwrap();
    sock.bind(SocketAddr::new(loopback(1), 0)).unwrap();
    let mut s = sock.connect(addr).await.unwrap();
    s.write_all(request(&format!("/recording?token={TOKEN}"), &addr.to_string()).as_bytes())
        .await
        .unwrap();
    let (status, head, body) = read_head(&mut s).await;
    assert_eq!(status, 200, "{head}");
    let answer = Answer {
        status,
        head,
        body: Vec::new(),
    };
    (s, answer.content_length(), body)
}

/// Reads `s` to its end, `per_read` bytes at a time with `pause` after each; fails on more than
/// `expected` bytes.
async fn read_paced(
    s: &mut TcpStream,
    body: &mut Vec<u8>,
    expected: usize,
    per_read: usize,
    pause: Duration,
) {
    let mut piece = vec![0u8; per_read];
    loop {
        let n = tokio::time::timeout(WAIT, s.read(&mut piece))
            .await
            .expect("progress in time")
            .unwrap_or_else(|e| panic!("after {} of {expected} bytes: {e}", body.len()));
        if n == 0 {
            return;
        }
        body.extend_from_slice(&piece[..n]);
        assert!(body.len() <= expected, "more than Content-Length");
        if !pause.is_zero() {
            tokio::time::sleep(pause).await;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_download_read_at_100_kb_a_second_arrives_whole() {
    // A long label makes the recording about 700 kB from its first second: at 100 kB/s, about 7 s to
    // read, well past the 3 s a request head has.
    let label = noise(700 * 1024);
    let lab = Lab::start("download-slow", &label).await;
    let addr = lab.addr();
    lab.ticks_seen_by_the_dashboard(50).await;
    let (mut s, expected, mut body) = begin_download(addr).await;
    assert!(expected > 700 * 1024, "{expected} bytes");
    // 10 kB every 100 ms, until the server closes.
    let began = tokio::time::Instant::now();
    read_paced(
        &mut s,
        &mut body,
        expected,
        10_000,
        Duration::from_millis(100),
    )
    .await;
    // The premise: the reading outlasted the request-head deadline (the pauses alone take longer).
    assert!(
        began.elapsed() > pavlov_actors::dashboard::guard::PRE_UPGRADE_LIMIT,
        "{:?}",
        began.elapsed()
    );
    assert_eq!(
        body.len(),
        expected,
        "the whole download, as Content-Length said"
    );
    let rec = recording::from_bytes(&body).expect("the download reads");
    assert!(!rec.torn_tail, "a finished file");
    assert_eq!(rec.header.label, label);
    assert!(!rec.records.is_empty());
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_download_while_one_is_being_sent_is_answered_busy() {
    let lab = Lab::start("download-busy", &noise(700 * 1024)).await;
    let addr = lab.addr();
    lab.ticks_seen_by_the_dashboard(50).await;
    // The first download's client reads nothing for now: its response cannot be all sent.
    let (mut s, expected, mut body) = begin_download(addr).await;
    let busy = get(
        addr,
        &format!("/recording?token={TOKEN}"),
        &addr.to_string(),
    )
    .await;
    let text = String::from_utf8_lossy(&busy.body);
    assert_eq!(busy.status, 503, "{text}");
    assert!(text.contains("busy"), "{text}");
    assert!(busy.header("retry-after").is_some(), "{}", busy.head);
    // The first arrives whole all the same; then the slot is free again.
    read_paced(&mut s, &mut body, expected, 64 * 1024, Duration::ZERO).await;
    assert_eq!(body.len(), expected);
    let again = get(
        addr,
        &format!("/recording?token={TOKEN}"),
        &addr.to_string(),
    )
    .await;
    assert_eq!(
        again.status,
        200,
        "{}",
        String::from_utf8_lossy(&again.body)
    );
    assert_eq!(again.body.len(), again.content_length());
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recording_and_metrics_refuse_a_host_that_is_not_this_servers() {
    let lab = Lab::start("download-host", "host").await;
    let addr = lab.addr();
    lab.ticks_seen_by_the_dashboard(10).await;
    let rejected = lab.dash.stats().rejected;
    for path in [format!("/recording?token={TOKEN}"), "/metrics".to_string()] {
        let refused = get(addr, &path, "evil.example").await;
        let text = String::from_utf8_lossy(&refused.body);
        assert_eq!(refused.status, 403, "{path}: {text}");
        assert!(
            text.contains("Host `evil.example` is not a name of this server"),
            "{path}: {text}"
        );
        let port = format!("evil.example:{}", addr.port());
        assert_eq!(get(addr, &path, &port).await.status, 403, "{path}");
    }
    assert_eq!(
        lab.dash.stats().rejected,
        rejected + 4,
        "counted as refusals"
    );
    // The server's own names pass.
    for host in [addr.to_string(), format!("localhost:{}", addr.port())] {
        assert_eq!(get(addr, "/metrics", &host).await.status, 200, "{host}");
    }
    let metrics = get(addr, "/metrics", &addr.to_string()).await;
    assert!(
        String::from_utf8_lossy(&metrics.body).contains("pavlov_"),
        "{}",
        String::from_utf8_lossy(&metrics.body)
    );
    // A foreign page's Origin is refused too, as on the websocket.
    let mut s = tcp_from(loopback(1), addr).await.unwrap();
    let with_origin = format!(
        "GET /metrics HTTP/1.1\r\nHost: {addr}\r\nOrigin: http://evil.example\r\nConnection: close\r\n\r\n"
    );
    s.write_all(with_origin.as_bytes()).await.unwrap();
    let (status, _, _) = read_head(&mut s).await;
    assert_eq!(status, 403);
    lab.stop().await;
}
