//! Foxglove load for `pavlov bench --foxglove-clients N`: runs the server with its Foxglove endpoint on an
//! ephemeral loopback port, connects `N` clients that subscribe to every channel and read every message,
//! and measures tick lateness and tick → command meanwhile.
//!
//! The clients speak just enough of the Foxglove WebSocket protocol to subscribe and count (the subprotocol
//! `foxglove.sdk.v1`, the `advertise` message, `subscribe`, binary message frames); they are load, not a
//! test of the protocol (the end-to-end test uses Foxglove's own client). They run on their own
//! single-threaded runtime in their own OS thread, like Foxglove apps in other processes would. A
//! benchmark, not a test: it reports figures and asserts nothing about them.

use std::collections::HashMap;
use std::fmt;
use std::net::SocketAddr;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov::config::Config;
use tokio::sync::{oneshot, watch};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

use crate::bench::{BenchReport, measure};
use crate::foxglove::{Foxglove, FoxgloveError, TOPIC_TICKS};
use crate::server::{RobotTarget, Server, ServerError};
use crate::telemetry::counters::FoxgloveFigures;

/// Errors of a Foxglove load run.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveLoadError {
    /// The server did not start.
    #[error(transparent)]
    Server(#[from] ServerError),
    /// The Foxglove endpoint did not start.
    #[error(transparent)]
    Foxglove(#[from] FoxgloveError),
    /// The client thread failed.
    #[error("foxglove clients: {0}")]
    Clients(String),
}

/// What a Foxglove load run measured.
#[derive(Debug, Clone)]
pub struct FoxgloveLoadReport {
    /// Tick figures while the clients were connected.
    pub bench: BenchReport,
    /// `/pavlov/ticks` messages each client received, sorted.
    pub(crate) ticks_per_client: Vec<u64>,
    /// Messages of every channel each client received, sorted.
    pub(crate) messages_per_client: Vec<u64>,
    /// The endpoint's counters at the end.
    pub(crate) endpoint: FoxgloveFigures,
}

impl fmt::Display for FoxgloveLoadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.bench)?;
        let first = |v: &Vec<u64>| v.first().copied().unwrap_or(0);
        let last = |v: &Vec<u64>| v.last().copied().unwrap_or(0);
        writeln!(
            f,
            "{} Foxglove clients: /pavlov/ticks messages received min {} / max {} (of {} records); all \
             channels {} … {} messages",
            self.ticks_per_client.len(),
            first(&self.ticks_per_client),
            last(&self.ticks_per_client),
            self.bench.records,
            first(&self.messages_per_client),
            last(&self.messages_per_client),
        )?;
        writeln!(
            f,
            "endpoint: {} connections, {} connected at the end, ticks missed by the publisher {}",
            self.endpoint.connections, self.endpoint.clients, self.endpoint.ticks_missed
        )
    }
}

/// The p50 / p99 of tick lateness and tick → command, without Foxglove (`baseline`) and with it.
pub fn comparison(baseline: &BenchReport, loaded: &FoxgloveLoadReport) -> String {
    let clients = loaded.ticks_per_client.len();
    let (w, l) = (baseline, &loaded.bench);
    let mut out = format!(
        "{:<24}{:>22}{:>22}\n",
        "p50 / p99, µs",
        "without Foxglove",
        format!("with {clients} clients")
    );
    for (name, a, b) in [
        ("tick lateness", &w.lateness, &l.lateness),
        (
            "tick → command written",
            &w.tick_to_command,
            &l.tick_to_command,
        ),
    ] {
        out.push_str(&format!(
            "{:<24}{:>22}{:>22}\n",
            name,
            format!("{} / {}", a.p50_us, a.p99_us),
            format!("{} / {}", b.p50_us, b.p99_us)
        ));
    }
    out
}

/// Runs the server on the simulated robot with its Foxglove endpoint and `clients` subscribed clients for
/// `duration` of real time.
pub async fn run_realtime_with_foxglove_clients(
    config: Config,
    duration: Duration,
    clients: usize,
) -> Result<FoxgloveLoadReport, FoxgloveLoadError> {
    let bound = Foxglove::bind("127.0.0.1:0", &config.dashboard)?;
    let addr = bound.local_addr();
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await?;
    let fox = match Foxglove::serve(bound, &server).await {
        Ok(f) => f,
        Err(e) => {
            server.shutdown().await;
            return Err(e.into());
        }
    };
    let (stop_tx, stop_rx) = watch::channel(false);
    let (ready_tx, ready_rx) = oneshot::channel();
    let thread = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build();
        match rt {
            Ok(rt) => rt.block_on(run_clients(addr, clients, stop_rx, ready_tx)),
            Err(e) => Err(e.to_string()),
        }
    });
    // Measure only once every client has subscribed.
    let connected = ready_rx
        .await
        .unwrap_or_else(|_| Err("the client thread ended".into()));
    let result = match connected {
        Ok(()) => {
            let bench = measure(&server, duration).await;
            let endpoint = fox.stats();
            let _ = stop_tx.send(true);
            match tokio::task::spawn_blocking(move || thread.join()).await {
                Ok(Ok(Ok(counts))) => {
                    let mut ticks_per_client: Vec<u64> = counts.iter().map(|c| c.0).collect();
                    let mut messages_per_client: Vec<u64> = counts.iter().map(|c| c.1).collect();
                    ticks_per_client.sort_unstable();
                    messages_per_client.sort_unstable();
                    Ok(FoxgloveLoadReport {
                        bench,
                        ticks_per_client,
                        messages_per_client,
                        endpoint,
                    })
                }
                Ok(Ok(Err(e))) => Err(FoxgloveLoadError::Clients(e)),
                _ => Err(FoxgloveLoadError::Clients(
                    "the client thread panicked".into(),
                )),
            }
        }
        Err(e) => {
            let _ = stop_tx.send(true);
            Err(FoxgloveLoadError::Clients(e))
        }
    };
    fox.shutdown().await;
    server.shutdown().await;
    result
}

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Connects, waits for the channels and subscribes to all of them; returns the socket and the
/// subscription id of `/pavlov/ticks`.
async fn connect_and_subscribe(addr: SocketAddr) -> Result<(Socket, u32), String> {
    let mut request = format!("ws://{addr}/")
        .into_client_request()
        .map_err(|e| e.to_string())?;
    request.headers_mut().insert(
        "sec-websocket-protocol",
        HeaderValue::from_static("foxglove.sdk.v1"),
    );
    let (mut ws, _) = tokio_tungstenite::connect_async(request)
        .await
        .map_err(|e| format!("connect {addr}: {e}"))?;
    let mut channels: HashMap<u64, String> = HashMap::new();
    while channels.len() < 4 {
        let msg = tokio::time::timeout(Duration::from_secs(10), ws.next())
            .await
            .map_err(|_| "no channel advertisement within 10 s".to_string())?;
        let Some(Ok(Message::Text(text))) = msg else {
            continue;
        };
        let value: serde_json::Value = serde_json::from_str(text.as_str()).unwrap_or_default();
        if value["op"] == "advertise"
            && let Some(list) = value["channels"].as_array()
        {
            for c in list {
                if let (Some(id), Some(topic)) = (c["id"].as_u64(), c["topic"].as_str()) {
                    channels.insert(id, topic.to_string());
                }
            }
        }
    }
    let mut ticks_subscription = 0;
    let subscriptions: Vec<serde_json::Value> = channels
        .iter()
        .enumerate()
        .map(|(i, (id, topic))| {
            if topic == TOPIC_TICKS {
                ticks_subscription = i as u32;
            }
            serde_json::json!({ "id": i, "channelId": id })
        })
        .collect();
    let subscribe = serde_json::json!({ "op": "subscribe", "subscriptions": subscriptions });
    ws.send(Message::text(subscribe.to_string()))
        .await
        .map_err(|e| e.to_string())?;
    Ok((ws, ticks_subscription))
}

/// Per client: (`/pavlov/ticks` messages, all messages).
async fn run_clients(
    addr: SocketAddr,
    clients: usize,
    stop: watch::Receiver<bool>,
    ready: oneshot::Sender<Result<(), String>>,
) -> Result<Vec<(u64, u64)>, String> {
    let mut sockets = Vec::with_capacity(clients);
    for _ in 0..clients {
        match connect_and_subscribe(addr).await {
            Ok(s) => sockets.push(s),
            Err(e) => {
                let _ = ready.send(Err(e.clone()));
                return Err(e);
            }
        }
    }
    let mut readers = Vec::with_capacity(clients);
    for (mut ws, ticks_subscription) in sockets {
        let mut stop = stop.clone();
        readers.push(tokio::spawn(async move {
            let (mut ticks, mut all) = (0u64, 0u64);
            loop {
                tokio::select! {
                    _ = stop.changed() => {
                        let _ = ws.close(None).await;
                        break;
                    }
                    msg = ws.next() => match msg {
                        // Message data: opcode 1, then the subscription id (u32, little-endian).
                        Some(Ok(Message::Binary(b))) if b.len() >= 5 && b[0] == 1 => {
                            all += 1;
                            if u32::from_le_bytes([b[1], b[2], b[3], b[4]]) == ticks_subscription {
                                ticks += 1;
                            }
                        }
                        Some(Ok(_)) => {}
                        Some(Err(_)) | None => break,
                    },
                }
            }
            (ticks, all)
        }));
    }
    let _ = ready.send(Ok(()));
    let mut stop = stop;
    let _ = stop.changed().await;
    let mut counts = Vec::with_capacity(readers.len());
    for r in readers {
        counts.push(r.await.unwrap_or((0, 0)));
    }
    Ok(counts)
}
