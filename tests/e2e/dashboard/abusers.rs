//! Abusive websocket clients for `tests/ws_abuse.rs`: floods of malformed and of valid messages (each
//! keeping a window of replies outstanding and checking every reply against what it sent), over-size
//! messages, a connection storm, and clients that never read.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// A client connection.
pub type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// Replies a flooder lets go unanswered before it waits (well inside the kernel's buffers).
const WINDOW: u64 = 200;
/// How long any one step may take before the test gives up.
pub const PATIENCE: Duration = Duration::from_secs(60);

/// The local address of a client's socket (the endpoint knows the client by it).
pub fn local_addr(ws: &Ws) -> SocketAddr {
    match ws.get_ref() {
        MaybeTlsStream::Plain(s) => s.local_addr().expect("a connected socket"),
        _ => unreachable!("the tests connect without TLS"),
    }
}

/// Connects and reads the `hello`.
pub async fn connect(addr: SocketAddr) -> Result<Ws, WsError> {
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws")).await?;
    loop {
        match ws.next().await {
            Some(Ok(Message::Text(t))) => {
                let v: Value = serde_json::from_str(&t).expect("JSON");
                assert_eq!(v["type"], "hello", "{v}");
                return Ok(ws);
            }
            Some(Ok(_)) => continue,
            Some(Err(e)) => return Err(e),
            None => return Err(WsError::ConnectionClosed),
        }
    }
}

/// The HTTP status of a refused handshake.
pub fn refusal_status(e: &WsError) -> Option<u16> {
    match e {
        WsError::Http(resp) => Some(resp.status().as_u16()),
        _ => None,
    }
}

/// One message a flooder sends, and the error code it must get unless it is rate-limited
/// (`None`: it must be acked).
pub struct Shot {
    /// The frame.
    pub message: Message,
    /// The `id` the reply must echo.
    pub id: Value,
    /// The expected error code, or `None` for an ack.
    pub code: Option<&'static str>,
}

/// What a flood got back.
#[derive(Debug, Default, Clone)]
pub struct FloodOutcome {
    /// Messages sent.
    pub sent: u64,
    /// Replies that were the message's own answer (ack or precise error).
    pub answered: u64,
    /// Replies `rate_limited`.
    pub rate_limited: u64,
    /// Control commands among the answered (forwarded to the server).
    pub control_answered: u64,
    /// How long it took, first send to last reply.
    pub elapsed: Duration,
}

/// The `i`-th malformed or wrong-typed message (five kinds in turn).
pub fn malformed(i: u64) -> Shot {
    match i % 5 {
        0 => Shot {
            message: Message::text(format!(r#"{{"id":{i},"cmd":"set_mode","mode":7}}"#)),
            id: json!(i),
            code: Some("bad_arguments"),
        },
        1 => Shot {
            message: Message::text(format!("not json {i}")),
            id: Value::Null,
            code: Some("bad_json"),
        },
        2 => Shot {
            message: Message::text(format!("[{i}, 2]")),
            id: Value::Null,
            code: Some("bad_message"),
        },
        3 => Shot {
            message: Message::text(format!(r#"{{"id":{i},"cmd":42}}"#)),
            id: json!(i),
            code: Some("missing_cmd"),
        },
        _ => Shot {
            message: Message::binary(vec![0u8, 1, 2, 3]),
            id: Value::Null,
            code: Some("binary_unsupported"),
        },
    }
}

/// The `i`-th valid command (ping, set_rate, and a control command that changes nothing).
pub fn valid(i: u64) -> Shot {
    let text = match i % 3 {
        0 => json!({"id": i, "cmd": "ping"}),
        1 => json!({"id": i, "cmd": "set_rate", "hz": 50}),
        _ => json!({"id": i, "cmd": "set_mode", "mode": "pavlovian"}),
    };
    Shot {
        message: Message::text(text.to_string()),
        id: json!(i),
        code: None,
    }
}

/// Whether shot `i` of [`valid`] is a control command.
pub fn valid_is_control(i: u64) -> bool {
    i % 3 == 2
}

/// Sends `n` shots from `make` as fast as the server takes them (with at most [`WINDOW`] unanswered), and
/// checks that reply `k` answers shot `k`: its own ack or precise error, or `rate_limited` with its id.
pub async fn flood(
    ws: Ws,
    n: u64,
    make: fn(u64) -> Shot,
    is_control: fn(u64) -> bool,
) -> FloodOutcome {
    let (mut tx, mut rx) = ws.split();
    let mut out = FloodOutcome::default();
    let mut expected = std::collections::VecDeque::new();
    let t0 = Instant::now();
    let mut replies = 0u64;
    while replies < n {
        let can_send = out.sent < n && out.sent - replies < WINDOW;
        tokio::select! {
            biased;
            msg = tokio::time::timeout(PATIENCE, rx.next()) => {
                let msg = msg.expect("a reply within the patience").expect("the connection ended").expect("a websocket error");
                let Message::Text(t) = msg else { continue };
                let v: Value = serde_json::from_str(&t).expect("JSON");
                // Only acks and errors answer a shot; ticks, statuses, history and events are the run's.
                if v["type"] != "ack" && v["type"] != "error" {
                    continue;
                }
                let (i, shot): (u64, Shot) = expected.pop_front().expect("a reply to something sent");
                assert_eq!(v["id"], shot.id, "reply {replies} to shot {i}: {v}");
                if v["code"] == "rate_limited" {
                    assert_eq!(v["type"], "error", "{v}");
                    out.rate_limited += 1;
                } else {
                    match shot.code {
                        Some(code) => assert_eq!(v["code"], code, "shot {i}: {v}"),
                        None => assert_eq!(v["type"], "ack", "shot {i}: {v}"),
                    }
                    out.answered += 1;
                    if is_control(i) {
                        out.control_answered += 1;
                    }
                }
                replies += 1;
            }
            _ = std::future::ready(()), if can_send => {
                let i = out.sent;
                let shot = make(i);
                tx.send(shot.message.clone()).await.expect("send");
                expected.push_back((i, shot));
                out.sent += 1;
            }
        }
    }
    out.elapsed = t0.elapsed();
    out
}

/// Connects, sends one message of `bytes` bytes and returns the close code the server answered with
/// (`Err(status)` when the handshake was refused).
pub async fn oversize(addr: SocketAddr, bytes: usize) -> Result<Option<CloseCode>, u16> {
    let mut ws = match connect(addr).await {
        Ok(ws) => ws,
        Err(e) => return Err(refusal_status(&e).unwrap_or(0)),
    };
    let big = format!(r#"{{"cmd":"ping","pad":"{}"}}"#, "x".repeat(bytes));
    if ws.send(Message::text(big)).await.is_err() {
        return Ok(None);
    }
    loop {
        match tokio::time::timeout(PATIENCE, ws.next()).await {
            Ok(Some(Ok(Message::Close(frame)))) => return Ok(frame.map(|f| f.code)),
            Ok(Some(Ok(_))) => continue,
            Ok(None | Some(Err(_))) | Err(_) => return Ok(None),
        }
    }
}

/// A websocket client with a tiny receive buffer that never reads.
pub async fn never_reading(addr: SocketAddr) -> Ws {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    let stream = sock.connect(addr).await.unwrap();
    let (ws, _) =
        tokio_tungstenite::client_async(format!("ws://{addr}/ws"), MaybeTlsStream::Plain(stream))
            .await
            .unwrap();
    ws
}

/// A never-reading client that also sends `n` pings: its replies pile up behind its unread ticks. It then
/// stays silent for `linger` (longer than the server's patience with unread replies) and only then reads
/// what is buffered: true if the connection had been closed by then (the stream ends within a few seconds),
/// false if live messages keep coming.
pub async fn never_reading_pinger(
    addr: SocketAddr,
    wait: Duration,
    n: u64,
    linger: Duration,
) -> bool {
    let mut ws = never_reading(addr).await;
    tokio::time::sleep(wait).await;
    for i in 0..n {
        if ws
            .send(Message::text(json!({"id": i, "cmd": "ping"}).to_string()))
            .await
            .is_err()
        {
            return true;
        }
    }
    tokio::time::sleep(linger).await;
    let drained = async { while let Some(Ok(_)) = ws.next().await {} };
    tokio::time::timeout(Duration::from_secs(5), drained)
        .await
        .is_ok()
}

/// Opens `n` connections at once; returns how many got a `hello` (kept open for `hold`) and the HTTP
/// status of every refusal.
pub async fn storm(addr: SocketAddr, n: usize, hold: Duration) -> (usize, Vec<u16>) {
    let attempts: Vec<_> = (0..n).map(|_| tokio::spawn(connect(addr))).collect();
    let mut open = Vec::new();
    let mut refusals = Vec::new();
    for a in attempts {
        match a.await.expect("storm task") {
            Ok(ws) => open.push(ws),
            Err(e) => refusals.push(refusal_status(&e).unwrap_or(0)),
        }
    }
    let accepted = open.len();
    tokio::time::sleep(hold).await;
    drop(open);
    (accepted, refusals)
}
