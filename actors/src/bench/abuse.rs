//! Abusive websocket clients for the dashboard benchmark (`pavlov bench --ws-clients N --ws-abuse`):
//! connections that flood valid commands and malformed messages as fast as the server takes them, a
//! churn of over-size messages, connection storms once a second, clients that never read, and (in
//! `super::floods`) a flood of watchers and one of idle sockets reopened as soon as they are closed.
//! The command flooders hold the operators' token (the worst case: a runaway script of an operator); the
//! storms and the watchers have none. They run until told to stop and count what they threw and what
//! came back.
//!
//! `tests/ws_abuse.rs` checks the server's answers one by one; this module only counts, for figures.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::Value;
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::Message;

/// Replies a flooder lets go unanswered before it waits for them.
const WINDOW: u64 = 200;
/// How long an over-size client waits for its close.
const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// What to throw at the endpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Abuse {
    /// Connections flooding valid commands (ping, set_rate, set_mode to the configured mode).
    pub(crate) flooders: usize,
    /// Connections flooding malformed and wrong-typed messages.
    pub(crate) malformed: usize,
    /// Clients that never read (each also sends 150 pings once, which it never reads the replies to).
    pub(crate) never_readers: usize,
    /// Connections opened at once, once a second.
    pub(crate) storm: usize,
    /// Whether one client keeps connecting and sending over-size messages.
    pub(crate) oversize: bool,
    /// Watchers (no token) from ten addresses, each reconnecting when refused or dropped.
    pub(crate) watchers: usize,
    /// Idle sockets from twenty addresses, each reopened as soon as the server closes it.
    pub(crate) idle_sockets: usize,
}

impl Default for Abuse {
    fn default() -> Self {
        Abuse {
            flooders: 3,
            malformed: 2,
            never_readers: 2,
            storm: 50,
            oversize: true,
            watchers: 100,
            idle_sockets: 200,
        }
    }
}

impl Abuse {
    /// No abuse at all (the baseline of a comparison).
    pub(crate) fn none() -> Self {
        Abuse {
            flooders: 0,
            malformed: 0,
            never_readers: 0,
            storm: 0,
            oversize: false,
            watchers: 0,
            idle_sockets: 0,
        }
    }

    /// Connections the abuse keeps open at once (before storms).
    pub(crate) fn connections(&self) -> usize {
        self.flooders + self.malformed + self.never_readers + usize::from(self.oversize)
    }
}

/// What the abusers threw and got back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Thrown {
    /// Valid commands sent.
    pub(crate) valid: u64,
    /// Malformed or wrong-typed messages sent.
    pub(crate) malformed: u64,
    /// Acks received.
    pub(crate) acks: u64,
    /// `rate_limited` errors received.
    pub(crate) rate_limited: u64,
    /// Other error replies received.
    pub(crate) errors: u64,
    /// Over-size messages sent.
    pub(crate) oversize: u64,
    /// Connections closed with 1009 after an over-size message.
    pub(crate) closed_1009: u64,
    /// Storm connection attempts.
    pub(crate) storm_attempts: u64,
    /// Storm attempts refused at the handshake.
    pub(crate) storm_refused: u64,
    /// Pings sent by clients that never read.
    pub(crate) unread_pings: u64,
    /// Watcher handshakes that got in (each reconnect counts).
    pub(crate) watchers_admitted: u64,
    /// Watcher handshakes refused.
    pub(crate) watchers_refused: u64,
    /// Idle sockets opened (each reopen counts).
    pub(crate) idle_opened: u64,
}

impl std::fmt::Display for Thrown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "thrown: {} valid commands, {} malformed messages, {} over-size messages, {} storm connections, {} unread pings",
            self.valid, self.malformed, self.oversize, self.storm_attempts, self.unread_pings
        )?;
        writeln!(
            f,
            "answers: {} acks, {} rate_limited, {} other errors, {} closes with 1009, {} storm handshakes refused",
            self.acks, self.rate_limited, self.errors, self.closed_1009, self.storm_refused
        )?;
        writeln!(
            f,
            "floods: {} watcher handshakes admitted, {} refused; {} idle sockets opened",
            self.watchers_admitted, self.watchers_refused, self.idle_opened
        )
    }
}

#[derive(Default)]
struct Tally {
    valid: AtomicU64,
    malformed: AtomicU64,
    acks: AtomicU64,
    rate_limited: AtomicU64,
    errors: AtomicU64,
    oversize: AtomicU64,
    closed_1009: AtomicU64,
    storm_attempts: AtomicU64,
    storm_refused: AtomicU64,
    unread_pings: AtomicU64,
}

fn add(counter: &AtomicU64, n: u64) {
    counter.fetch_add(n, Ordering::Relaxed);
}

impl Tally {
    fn thrown(&self) -> Thrown {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Thrown {
            watchers_admitted: 0,
            watchers_refused: 0,
            idle_opened: 0,
            valid: get(&self.valid),
            malformed: get(&self.malformed),
            acks: get(&self.acks),
            rate_limited: get(&self.rate_limited),
            errors: get(&self.errors),
            oversize: get(&self.oversize),
            closed_1009: get(&self.closed_1009),
            storm_attempts: get(&self.storm_attempts),
            storm_refused: get(&self.storm_refused),
            unread_pings: get(&self.unread_pings),
        }
    }

    fn reply(&self, text: &str) {
        let Ok(v) = serde_json::from_str::<Value>(text) else {
            return;
        };
        match (v["type"].as_str(), v["code"].as_str()) {
            (Some("ack"), _) => add(&self.acks, 1),
            (Some("error"), Some("rate_limited")) => add(&self.rate_limited, 1),
            (Some("error"), _) => add(&self.errors, 1),
            _ => {}
        }
    }
}

fn valid_message(i: u64, control: &str) -> Message {
    match i % 3 {
        0 => Message::text(format!(r#"{{"id":{i},"cmd":"ping"}}"#)),
        1 => Message::text(format!(r#"{{"id":{i},"cmd":"set_rate","hz":50}}"#)),
        _ => Message::text(control.to_string()),
    }
}

fn malformed_message(i: u64) -> Message {
    match i % 5 {
        0 => Message::text(format!(r#"{{"id":{i},"cmd":"set_mode","mode":7}}"#)),
        1 => Message::text(format!("not json {i}")),
        2 => Message::text(format!("[{i}, 2]")),
        3 => Message::text(format!(r#"{{"id":{i},"cmd":42}}"#)),
        _ => Message::binary(vec![0u8, 1, 2, 3]),
    }
}

/// Tries `connect` every 50 ms until it succeeds (a storm from the same address may have the first tries
/// closed on arrival) or `stop` turns true.
async fn connect_until_stopped<T, E, F: std::future::Future<Output = Result<T, E>>>(
    connect: impl Fn() -> F,
    stop: &watch::Receiver<bool>,
) -> Option<T> {
    while !*stop.borrow() {
        if let Ok(c) = connect().await {
            return Some(c);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    None
}

/// Floods one connection until `stop`, keeping at most [`WINDOW`] replies outstanding.
async fn flood(
    url: String,
    malformed: bool,
    control: String,
    tally: Arc<Tally>,
    mut stop: watch::Receiver<bool>,
) {
    let connect = || async { tokio_tungstenite::connect_async(url.as_str()).await };
    let Some((ws, _)) = connect_until_stopped(connect, &stop).await else {
        return;
    };
    let (mut tx, mut rx) = ws.split();
    let (mut sent, mut replies) = (0u64, 0u64);
    loop {
        let can_send = sent - replies.min(sent) < WINDOW;
        tokio::select! {
            biased;
            _ = stop.changed() => break,
            msg = rx.next() => match msg {
                Some(Ok(Message::Text(t))) => {
                    if ![r#"{"type":"tick""#, r#"{"type":"status""#, r#"{"type":"learning""#]
                        .iter()
                        .any(|kind| t.as_str().starts_with(kind))
                    {
                        replies += 1;
                        tally.reply(&t);
                    }
                }
                Some(Ok(_)) => {}
                Some(Err(_)) | None => break,
            },
            _ = std::future::ready(()), if can_send => {
                let msg = if malformed { malformed_message(sent) } else { valid_message(sent, &control) };
                if tx.send(msg).await.is_err() {
                    break;
                }
                sent += 1;
                add(if malformed { &tally.malformed } else { &tally.valid }, 1);
            }
        }
    }
}

/// Connects over and over, each time sending one over-size message and waiting for the close.
async fn oversize(url: String, bytes: usize, tally: Arc<Tally>, stop: watch::Receiver<bool>) {
    let big = format!(r#"{{"cmd":"ping","pad":"{}"}}"#, "x".repeat(bytes));
    while !*stop.borrow() {
        let Ok((mut ws, _)) = tokio_tungstenite::connect_async(url.as_str()).await else {
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        if ws.send(Message::text(big.clone())).await.is_err() {
            continue;
        }
        add(&tally.oversize, 1);
        let closed = async {
            while let Some(Ok(msg)) = ws.next().await {
                if let Message::Close(Some(frame)) = msg {
                    return u16::from(frame.code) == 1009;
                }
            }
            false
        };
        if let Ok(true) = tokio::time::timeout(CLOSE_WAIT, closed).await {
            add(&tally.closed_1009, 1);
        }
    }
}

/// Once a second, opens `n` connections at once and holds those accepted for half a second.
async fn storm(url: String, n: usize, tally: Arc<Tally>, stop: watch::Receiver<bool>) {
    while !*stop.borrow() {
        let attempts: Vec<_> = (0..n)
            .map(|_| tokio::spawn(tokio_tungstenite::connect_async(url.clone())))
            .collect();
        let mut open = Vec::new();
        for a in attempts {
            add(&tally.storm_attempts, 1);
            match a.await {
                Ok(Ok((ws, _))) => open.push(ws),
                _ => add(&tally.storm_refused, 1),
            }
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(open);
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
}

/// A client with a tiny receive buffer that never reads; after 2 s it sends 150 pings, then waits.
async fn never_reader(
    addr: SocketAddr,
    url: String,
    tally: Arc<Tally>,
    mut stop: watch::Receiver<bool>,
) {
    let connect = || async {
        let sock = tokio::net::TcpSocket::new_v4()?;
        sock.set_recv_buffer_size(4096)?;
        let tcp = sock.connect(addr).await?;
        tokio_tungstenite::client_async(url.as_str(), tcp)
            .await
            .map_err(std::io::Error::other)
    };
    let Some((mut ws, _)) = connect_until_stopped(connect, &stop).await else {
        return;
    };
    tokio::select! {
        _ = stop.changed() => return,
        _ = tokio::time::sleep(Duration::from_secs(2)) => {}
    }
    for i in 0..150u64 {
        if ws
            .send(Message::text(format!(r#"{{"id":{i},"cmd":"ping"}}"#)))
            .await
            .is_err()
        {
            break;
        }
        add(&tally.unread_pings, 1);
    }
    let _ = stop.changed().await;
}

/// Runs `abuse` against the endpoint at `addr` until `stop` turns true. `control` is the JSON text of a
/// harmless control command (it goes to the server's command router); over-size messages are
/// `max_message_bytes` + 1 KiB; `token` is the operators' token.
pub(crate) async fn run(
    addr: SocketAddr,
    abuse: Abuse,
    control: String,
    max_message_bytes: usize,
    token: String,
    stop: watch::Receiver<bool>,
) -> Thrown {
    let url = format!("ws://{addr}/ws?token={token}");
    let storm_url = format!("ws://{addr}/ws");
    let tally = Arc::new(Tally::default());
    let floods = Arc::new(super::floods::FloodTally::default());
    let mut tasks = super::floods::spawn(addr, abuse.watchers, abuse.idle_sockets, &floods, &stop);
    for i in 0..abuse.flooders + abuse.malformed {
        tasks.push(tokio::spawn(flood(
            url.clone(),
            i >= abuse.flooders,
            control.clone(),
            tally.clone(),
            stop.clone(),
        )));
    }
    for _ in 0..abuse.never_readers {
        tasks.push(tokio::spawn(never_reader(
            addr,
            url.clone(),
            tally.clone(),
            stop.clone(),
        )));
    }
    if abuse.oversize {
        tasks.push(tokio::spawn(oversize(
            url.clone(),
            max_message_bytes + 1024,
            tally.clone(),
            stop.clone(),
        )));
    }
    if abuse.storm > 0 {
        tasks.push(tokio::spawn(storm(
            storm_url,
            abuse.storm,
            tally.clone(),
            stop.clone(),
        )));
    }
    for t in tasks {
        let _ = t.await;
    }
    let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
    Thrown {
        watchers_admitted: get(&floods.watchers_admitted),
        watchers_refused: get(&floods.watchers_refused),
        idle_opened: get(&floods.idle_opened),
        ..tally.thrown()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replies_are_tallied_by_kind() {
        let t = Tally::default();
        t.reply(r#"{"type":"ack","id":1,"cmd":"ping","result":{}}"#);
        t.reply(r#"{"type":"error","id":2,"code":"rate_limited","message":"…"}"#);
        t.reply(r#"{"type":"error","id":null,"code":"bad_json","message":"…"}"#);
        t.reply(r#"{"type":"tick","seq":3}"#);
        t.reply("garbage");
        let thrown = t.thrown();
        assert_eq!((thrown.acks, thrown.rate_limited, thrown.errors), (1, 1, 1));
    }

    #[test]
    fn the_messages_cycle_through_their_kinds() {
        let texts: Vec<String> = (0..5)
            .map(|i| match malformed_message(i) {
                Message::Text(t) => t.to_string(),
                Message::Binary(_) => "binary".into(),
                other => format!("{other:?}"),
            })
            .collect();
        assert!(texts[1].starts_with("not json"));
        assert_eq!(texts[4], "binary");
        let control = r#"{"cmd":"set_mode","mode":"pavlovian"}"#;
        assert_eq!(valid_message(2, control), Message::text(control));
        assert_eq!(Abuse::default().connections(), 8);
    }
}
