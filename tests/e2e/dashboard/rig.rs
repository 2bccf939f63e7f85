//! Helpers for the tests of who gets in (`operator.rs`, `strictness.rs`): a server (simulated robot) whose
//! dashboard has a token and listens on an ephemeral loopback port, and clients that connect from a chosen
//! source address. On Linux all of 127.0.0.0/8 is loopback, so one test can play many machines:
//! 127.0.0.1 is the operator's, the others are watchers' and abusers'.
#![allow(dead_code)]

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use pavlov::config::Config;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// A websocket client connection.
pub type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// The operators' token (long enough for a public bind).
pub const TOKEN: &str = "operator-token-0123456789abcdef";
/// How long any one step may take.
pub const WAIT: Duration = Duration::from_secs(10);

const STALL_CONFIG: &str = include_str!("../../../config/stall.toml");

/// A running server and its dashboard.
pub struct Lab {
    /// The server.
    pub server: Server,
    /// Its dashboard endpoint.
    pub dash: Dashboard,
}

impl Lab {
    /// Starts the stall experiment with the dashboard on 127.0.0.1:0 and [`TOKEN`], after `edit`.
    pub async fn start(edit: impl FnOnce(&mut Config)) -> Lab {
        let mut cfg = Config::from_toml(STALL_CONFIG).unwrap();
        cfg.dashboard.bind = "127.0.0.1:0".into();
        cfg.dashboard.token = Some(TOKEN.into());
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

    /// The dashboard's address.
    pub fn addr(&self) -> SocketAddr {
        self.dash.local_addr()
    }

    /// Stops everything.
    pub async fn stop(self) {
        self.dash.shutdown().await;
        if tokio::time::timeout(Duration::from_secs(5), self.server.shutdown())
            .await
            .is_err()
        {
            eprintln!("warning: the server took more than 5 s to shut down");
        }
    }
}

/// The loopback address 127.0.0.`n`.
pub fn loopback(n: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))
}

/// A TCP connection to `addr` from `source`.
pub async fn tcp_from(source: IpAddr, addr: SocketAddr) -> std::io::Result<TcpStream> {
    let sock = TcpSocket::new_v4()?;
    sock.bind(SocketAddr::new(source, 0))?;
    sock.connect(addr).await
}

/// A websocket handshake from `source`, with `token` in the subprotocol if given; the `hello` on success.
pub async fn ws_from(
    source: IpAddr,
    addr: SocketAddr,
    token: Option<&str>,
) -> Result<(Ws, Value), WsError> {
    let tcp = tcp_from(source, addr).await.map_err(WsError::Io)?;
    let mut req = format!("ws://{addr}/ws").into_client_request()?;
    if let Some(t) = token {
        let protocols = format!("pavlov.v1, token.{t}");
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_str(&protocols).unwrap(),
        );
    }
    let (mut ws, _) = tokio_tungstenite::client_async(req, MaybeTlsStream::Plain(tcp)).await?;
    let hello = next_json(&mut ws).await;
    assert_eq!(hello["type"], "hello", "{hello}");
    Ok((ws, hello))
}

/// The HTTP status of a refused handshake (panics on any other failure).
pub fn refusal(e: &WsError) -> u16 {
    match e {
        WsError::Http(resp) => resp.status().as_u16(),
        other => panic!("expected an HTTP refusal, got {other:?}"),
    }
}

/// The next JSON text message.
pub async fn next_json(ws: &mut Ws) -> Value {
    loop {
        let msg = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("a message in time")
            .expect("the connection is open")
            .expect("no websocket error");
        if let Message::Text(t) = msg {
            return serde_json::from_str(&t).unwrap();
        }
    }
}

/// Sends `msg` with `id` and returns the reply to it, skipping telemetry.
pub async fn command(ws: &mut Ws, mut msg: Value, id: u64) -> Value {
    msg["id"] = json!(id);
    ws.send(Message::text(msg.to_string())).await.unwrap();
    reply_to(ws, id).await
}

/// The reply (ack or error) to `id`, skipping telemetry.
pub async fn reply_to(ws: &mut Ws, id: u64) -> Value {
    loop {
        let v = next_json(ws).await;
        if (v["type"] == "ack" || v["type"] == "error") && v["id"] == id {
            return v;
        }
    }
}

/// Latches the e-stop: the time from sending `estop` to its ack, and the ack.
pub async fn timed_estop(ws: &mut Ws, id: u64) -> (Duration, Value) {
    let t0 = Instant::now();
    let ack = command(ws, json!({"cmd": "estop"}), id).await;
    (t0.elapsed(), ack)
}

/// `GET path` from `source` on a fresh connection: the status and the body.
pub async fn http_get_from(source: IpAddr, addr: SocketAddr, path: &str) -> (u16, String) {
    let mut s = tcp_from(source, addr).await.unwrap();
    s.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(WAIT, s.read_to_end(&mut buf))
        .await
        .expect("an answer in time")
        .expect("a readable answer");
    let text = String::from_utf8_lossy(&buf).to_string();
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = text
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_string();
    (status, body)
}
