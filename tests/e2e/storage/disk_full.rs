//! A full disk, as a researcher meets it: the real `pavlov serve --record` runs with its working folder on a
//! 2 MiB tmpfs (a real filesystem with a real `ENOSPC`), followed over its websocket. Once the recording has
//! begun, a filler file takes all the room but a few kilobytes, and then:
//!
//! - the recording stops with a `recording_stopped` event that names the file and carries the OS's reason;
//! - a new client's `hello` names no recording in force, and `/metrics` counts the failure;
//! - `save_weights` fails with a `checkpoint_failed` event (and an error reply), counted, and no `.tmp` file
//!   is left anywhere;
//! - what was recorded before the disk filled up still loads;
//! - once the filler is removed, `start_recording` records again, into a file that loads whole.
//!
//! Mounting needs root (or `CAP_SYS_ADMIN`). Where `mount` is refused (or with `PAVLOV_TEST_FULL=limit`),
//! the server runs in an ordinary folder with `SIGXFSZ` ignored, and its file-size limit (`RLIMIT_FSIZE`,
//! set with `prlimit --pid`) is lowered to 4 KiB below the recording's size: every write past it fails with
//! the OS's `EFBIG` ("File too large"); raising the limit again gives the room back. Where neither works,
//! the test says so and does nothing. Every wait is for a message, with a generous bound: nothing is timed.

use std::io::{BufRead, BufReader, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov_actors::storage::recording::{self, MCAP_FILE};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::Message;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");
/// The filesystem's size.
const TMPFS_SIZE: &str = "2m";
/// What the filler leaves free: a few seconds of recording.
const ROOM: u64 = 16 * 1024;
/// The longest wait for any one message (a loaded machine is slow; a hang still ends).
const WAIT: Duration = Duration::from_secs(120);

/// A tmpfs mounted for the test, unmounted (and its mount point removed) when dropped.
pub(crate) struct Tmpfs(PathBuf);

impl Tmpfs {
    /// Where it is mounted.
    pub(crate) fn path(&self) -> &Path {
        &self.0
    }

    /// Mounts a tmpfs of [`TMPFS_SIZE`]; `None` when this machine does not let the test mount.
    pub(crate) fn mount() -> Option<Tmpfs> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir = std::env::temp_dir().join(format!("pavlov-full-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).ok()?;
        let mounted = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={TMPFS_SIZE}"), "tmpfs"])
            .arg(&dir)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !mounted {
            let _ = std::fs::remove_dir(&dir);
            return None;
        }
        Some(Tmpfs(dir))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

/// A folder in the temporary directory, removed when dropped.
struct Folder(PathBuf);

impl Folder {
    fn new() -> Folder {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir = std::env::temp_dir().join(format!("pavlov-fsize-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        Folder(dir)
    }
}

impl Drop for Folder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// How the test makes the disk full.
enum Full {
    /// A small tmpfs, filled by a filler file but [`ROOM`] bytes; the room comes back when it is removed.
    Tmpfs(Tmpfs),
    /// An ordinary folder, and the server's file-size limit lowered to [`LIMIT`] bytes; the room comes back
    /// when the limit is raised.
    Limit(Folder),
}

/// The file-size limit of [`Full::Limit`]: less than a recording's first chunk, less than a checkpoint.
const LIMIT: u64 = 4096;

impl Full {
    /// A tmpfs if this machine lets the test mount one (unless `PAVLOV_TEST_FULL=limit`), else the
    /// file-size limit if `prlimit` is there.
    fn new() -> Option<Full> {
        let forced = std::env::var("PAVLOV_TEST_FULL").is_ok_and(|v| v == "limit");
        if !forced && let Some(fs) = Tmpfs::mount() {
            return Some(Full::Tmpfs(fs));
        }
        let prlimit = Command::new("prlimit")
            .arg("--version")
            .stdout(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        prlimit.then(|| Full::Limit(Folder::new()))
    }

    fn dir(&self) -> &Path {
        match self {
            Full::Tmpfs(fs) => fs.path(),
            Full::Limit(folder) => &folder.0,
        }
    }

    /// What the OS says when a write finds no room.
    fn reason(&self) -> &'static str {
        match self {
            Full::Tmpfs(_) => "No space left on device",
            Full::Limit(_) => "File too large",
        }
    }

    /// Takes the room away from the server `pid`.
    fn fill(&self, pid: u32) {
        match self {
            Full::Tmpfs(fs) => fill(fs.path(), ROOM),
            Full::Limit(folder) => {
                // Below the recording's size, so that what it holds already (a chunk at least) stays.
                let recording = folder.0.join("rec").join(MCAP_FILE);
                let deadline = std::time::Instant::now() + WAIT;
                while std::fs::metadata(&recording).map_or(0, |m| m.len()) <= LIMIT {
                    assert!(
                        std::time::Instant::now() < deadline,
                        "the recording did not grow past {LIMIT} bytes within {WAIT:?}"
                    );
                    std::thread::sleep(Duration::from_millis(50));
                }
                set_file_size_limit(pid, &format!("{LIMIT}:unlimited"));
            }
        }
    }

    /// Gives the room back to the server `pid`.
    fn free(&self, pid: u32) {
        match self {
            Full::Tmpfs(fs) => {
                std::fs::remove_file(fs.path().join("filler")).expect("free the room")
            }
            Full::Limit(_) => set_file_size_limit(pid, "unlimited:unlimited"),
        }
    }
}

/// Sets the file-size limit of process `pid` (`soft:hard`) with `prlimit`.
fn set_file_size_limit(pid: u32, limits: &str) {
    let status = Command::new("prlimit")
        .arg("--pid")
        .arg(pid.to_string())
        .arg(format!("--fsize={limits}"))
        .status()
        .expect("run prlimit");
    assert!(
        status.success(),
        "prlimit --pid {pid} --fsize={limits}: {status}"
    );
}

/// Kills the server if the test ends before it does.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `pavlov serve --record rec` in `dir` on an ephemeral port, with `SIGXFSZ` ignored (so that a
/// write past a file-size limit fails with `EFBIG` instead of killing it); returns it and its dashboard
/// address.
fn start(dir: &Path) -> (Server, SocketAddr) {
    // An ignored signal stays ignored across exec; the server keeps the shell's process id.
    let mut child = Command::new("sh")
        .args(["-c", "trap '' XFSZ; exec \"$0\" \"$@\"", PAVLOV])
        .args(["serve", "--bind", "127.0.0.1:0", "--record", "rec"])
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("run pavlov serve");
    let stdout = child.stdout.take().expect("its stdout");
    let server = Server(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("dashboard: ") {
                let _ = tx.send(url.to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(WAIT)
        .expect("the server prints its dashboard URL");
    let addr = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .parse()
        .unwrap_or_else(|e| panic!("{url}: {e}"));
    (server, addr)
}

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A websocket client of the dashboard.
struct Client {
    ws: Ws,
    next_id: u64,
    /// Messages that came while waiting for a reply (an event may come before its command's `ack`).
    read_ahead: std::collections::VecDeque<Value>,
}

impl Client {
    /// Connects; returns the client and its `hello`.
    async fn connect(addr: SocketAddr) -> (Client, Value) {
        let (ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws"))
            .await
            .expect("connect to the dashboard");
        let mut c = Client {
            ws,
            next_id: 1,
            read_ahead: Default::default(),
        };
        let hello = c.next_where("hello", |_| true).await;
        (c, hello)
    }

    /// The next message of type `kind` for which `pred` holds (others are skipped).
    async fn next_where(&mut self, kind: &str, pred: impl Fn(&Value) -> bool) -> Value {
        let wanted = |v: &Value| v["type"] == kind && pred(v);
        while let Some(v) = self.read_ahead.pop_front() {
            if wanted(&v) {
                return v;
            }
        }
        let deadline = tokio::time::Instant::now() + WAIT;
        loop {
            let v = self
                .receive(deadline)
                .await
                .unwrap_or_else(|| panic!("no {kind} message within {WAIT:?}"));
            if wanted(&v) {
                return v;
            }
        }
    }

    /// The next text message, as JSON (`None`: none came before `deadline`).
    async fn receive(&mut self, deadline: tokio::time::Instant) -> Option<Value> {
        loop {
            let msg = tokio::time::timeout_at(deadline, self.ws.next())
                .await
                .ok()?
                .expect("the connection is open")
                .expect("no websocket error");
            if let Message::Text(t) = msg {
                return Some(serde_json::from_str(&t).expect("JSON"));
            }
        }
    }

    /// Sends `cmd` with `args`; returns its reply (`ack` or `error`).
    async fn command(&mut self, cmd: &str, args: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        let mut msg = json!({"cmd": cmd, "id": id});
        if let (Some(m), Some(a)) = (msg.as_object_mut(), args.as_object()) {
            m.extend(a.clone());
        }
        self.ws
            .send(Message::text(msg.to_string()))
            .await
            .expect("send");
        let deadline = tokio::time::Instant::now() + WAIT;
        loop {
            let v = self
                .receive(deadline)
                .await
                .unwrap_or_else(|| panic!("no reply to {cmd} within {WAIT:?}"));
            if (v["type"] == "ack" || v["type"] == "error") && v["id"] == id {
                return v;
            }
            // Ticks pile up fast and are not waited for; everything else may be.
            if v["type"] != "tick" {
                self.read_ahead.push_back(v);
            }
        }
    }

    /// The next event of `kind` for which `pred` holds.
    async fn event(&mut self, kind: &str, pred: impl Fn(&Value) -> bool) -> Value {
        self.next_where("event", |v| v["kind"] == kind && pred(v))
            .await
    }
}

/// The value of the unlabelled sample `name` in `/metrics`.
async fn metric(addr: SocketAddr, name: &str) -> f64 {
    let mut s = tokio::net::TcpStream::connect(addr).await.expect("connect");
    s.write_all(
        format!("GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .expect("request");
    let mut text = String::new();
    tokio::time::timeout(WAIT, s.read_to_string(&mut text))
        .await
        .expect("an answer")
        .expect("read");
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in\n{text}"))
}

/// Fills the filesystem of `dir` with `dir/filler` but `room` bytes.
fn fill(dir: &Path, room: u64) {
    let path = dir.join("filler");
    let mut f = std::fs::File::create(&path).expect("create the filler");
    let block = vec![0xa5u8; 64 * 1024];
    loop {
        match f.write(&block) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) if e.raw_os_error() == Some(28) => break,
            Err(e) => panic!("filling: {e}"),
        }
    }
    let _ = f.flush();
    let len = f.metadata().expect("its size").len();
    f.set_len(len.saturating_sub(room)).expect("make room");
}

/// Every file under `dir` whose name ends in `.tmp`.
fn temporary_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let path = entry.path();
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                todo.push(path);
            } else if path.to_string_lossy().ends_with(".tmp") {
                found.push(path);
            }
        }
    }
    found
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_stops_the_recording_and_fails_checkpoints_as_events_and_recording_resumes_with_room()
 {
    let Some(full) = Full::new() else {
        eprintln!(
            "skipped: this machine lets the test neither mount a tmpfs (needs root) nor run prlimit"
        );
        return;
    };
    let dir = full.dir().to_path_buf();
    let no_room = full.reason();
    let (server, addr) = start(&dir);
    let pid = server.0.id();
    let (mut client, hello) = Client::connect(addr).await;
    let recording = dir.join("rec").join(MCAP_FILE);
    // The recording is in force (it began with the run; a late hello names it, an early one sees it start).
    if hello["in_force"]["recording"].is_null() {
        client.event("recording_started", |_| true).await;
    }
    // Some ticks are recorded before the disk fills up.
    client
        .next_where("tick", |t| t["seq"].as_u64() > Some(100))
        .await;

    full.fill(pid);
    let stopped = client
        .event("recording_stopped", |e| e["reason"].is_string())
        .await;
    let reason = stopped["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains(no_room),
        "the reason is the OS's: {stopped}"
    );
    assert!(
        Path::new(stopped["path"].as_str().unwrap_or_default())
            .ends_with(Path::new("rec").join(MCAP_FILE)),
        "{stopped}"
    );
    // Control goes on.
    let seq = client.next_where("tick", |_| true).await["seq"].as_u64();
    client.next_where("tick", |t| t["seq"].as_u64() > seq).await;

    // A new client is told no recording is in force; /metrics counts the failure.
    let (_late, hello) = Client::connect(addr).await;
    assert!(
        hello["in_force"]["recording"].is_null(),
        "{}",
        hello["in_force"]
    );
    assert_eq!(metric(addr, "pavlov_recording_failures_total").await, 1.0);

    // A save the disk has no room for: an error reply, a checkpoint_failed event, no temporary file.
    let reply = client
        .command("save_weights", json!({"path": "w.json"}))
        .await;
    assert_eq!(reply["type"], "error", "{reply}");
    assert!(
        reply["message"]
            .as_str()
            .unwrap_or_default()
            .contains(no_room),
        "{reply}"
    );
    let failed = client
        .event("checkpoint_failed", |e| {
            e["path"].as_str().is_some_and(|p| p.ends_with("w.json"))
        })
        .await;
    assert!(
        failed["reason"]
            .as_str()
            .unwrap_or_default()
            .contains(no_room),
        "{failed}"
    );
    assert!(metric(addr, "pavlov_checkpoint_failures_total").await >= 1.0);
    assert_eq!(temporary_files(&dir), Vec::<PathBuf>::new());
    assert!(!dir.join("weights").join("saved").join("w.json").exists());

    // What was recorded before the disk filled up loads.
    let before = recording::load(&dir.join("rec")).expect("the stopped recording loads");
    assert!(!before.records.is_empty(), "ticks were recorded");
    assert!(
        before.records.windows(2).all(|w| w[0].seq < w[1].seq),
        "records out of order"
    );
    eprintln!(
        "{} ticks recorded before the disk was full ({} bytes; torn tail: {})",
        before.records.len(),
        std::fs::metadata(&recording).map_or(0, |m| m.len()),
        before.torn_tail
    );

    // With room again, recording resumes when asked.
    full.free(pid);
    let reply = client
        .command("start_recording", json!({"dir": "again"}))
        .await;
    assert_eq!(reply["type"], "ack", "{reply}");
    let started = client.event("recording_started", |_| true).await;
    assert!(
        started["path"]
            .as_str()
            .unwrap_or_default()
            .contains("again"),
        "{started}"
    );
    // Every tick made after the recording began is in it: collect 50 that the client saw (a loaded
    // machine may skip ticks, so count ticks seen, not seq numbers).
    let began = started["after"].as_u64().unwrap_or_default();
    let mut seen = Vec::new();
    while seen.len() < 50 {
        let tick = client
            .next_where("tick", |t| t["seq"].as_u64() > Some(began))
            .await;
        seen.extend(tick["seq"].as_u64());
    }
    let reply = client.command("stop_recording", json!({})).await;
    assert_eq!(reply["type"], "ack", "{reply}");
    let again =
        recording::load(&dir.join("recordings").join("again")).expect("the new recording loads");
    assert!(!again.torn_tail, "finished whole");
    let recorded: std::collections::HashSet<u64> = again.records.iter().map(|r| r.seq).collect();
    let missing: Vec<u64> = seen.into_iter().filter(|s| !recorded.contains(s)).collect();
    assert!(
        missing.is_empty(),
        "ticks seen live after the recording began but not in it: {missing:?}"
    );
    assert_eq!(metric(addr, "pavlov_recording_failures_total").await, 1.0);
    drop(server);
}
