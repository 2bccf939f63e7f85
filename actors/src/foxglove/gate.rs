//! The Foxglove endpoint's front door: the public listening socket, bound before the robot is touched.
//!
//! The Foxglove SDK's server binds its own socket and upgrades every request that offers its subprotocol;
//! it has no hook to look at a request first and no limit on connections. So the SDK listens on an
//! ephemeral loopback port of its own, and this gate stands in front of it on the public address:
//! - at most [`MAX_CONNECTIONS`] TCP connections at once (more are answered 503 and closed);
//! - a request head must arrive within [`HEAD_DEADLINE`] and fit in [`MAX_HEAD_BYTES`];
//! - [`super::access`] decides on the head (token, watch rule): a refusal is answered 401 (400 for what
//!   is not a websocket request) before any upgrade, and counted;
//! - an admitted connection is spliced, head first, to the SDK's port: the SDK does the handshake and
//!   speaks the Foxglove protocol, and the gate just copies bytes both ways until either side closes.
//!
//! Everything here runs on the endpoint's own runtime; nothing touches the tick.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_util::sync::CancellationToken;

use super::access::{Refusal, WatchPolicy};
use crate::telemetry::counters::FoxgloveCounters;

/// Most TCP connections open at once on the public port (handshaking or connected).
pub(crate) const MAX_CONNECTIONS: u64 = 32;
/// Longest wait for a complete request head.
pub(crate) const HEAD_DEADLINE: Duration = Duration::from_secs(10);
/// Largest request head accepted.
pub(crate) const MAX_HEAD_BYTES: usize = 16 * 1024;
/// Longest wait to write a refusal before closing anyway.
const REFUSAL_WRITE_LIMIT: Duration = Duration::from_secs(1);

/// What the gate needs to decide and forward.
pub(crate) struct Gate {
    /// Who may watch.
    pub(crate) policy: WatchPolicy,
    /// The SDK server's own (loopback) address.
    pub(crate) upstream: SocketAddr,
    /// Counters shared with `/metrics`.
    pub(crate) counters: Arc<FoxgloveCounters>,
    /// TCP connections open now.
    pub(crate) open: Arc<AtomicU64>,
}

/// Counts one unit in `counter` while it lives.
struct Held(Arc<AtomicU64>);

impl Held {
    /// Adds one and returns the guard with the new value.
    fn take(counter: Arc<AtomicU64>) -> (Held, u64) {
        let now = counter.fetch_add(1, Ordering::Relaxed) + 1;
        (Held(counter), now)
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Accepts connections until `cancel`.
pub(crate) async fn run(listener: TcpListener, gate: Arc<Gate>, cancel: CancellationToken) {
    loop {
        let accepted = tokio::select! {
            () = cancel.cancelled() => return,
            accepted = listener.accept() => accepted,
        };
        let (stream, peer) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // E.g. out of file descriptors: wait a little rather than spin.
                tracing::warn!("foxglove: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let (held, open) = Held::take(gate.open.clone());
        let gate = gate.clone();
        let cancel = cancel.clone();
        tokio::spawn(async move {
            if open > MAX_CONNECTIONS {
                gate.counters.refused_busy.fetch_add(1, Ordering::Relaxed);
                let body = format!("too many Foxglove connections (at most {MAX_CONNECTIONS})");
                refuse(stream, 503, "Service Unavailable", &body).await;
                return;
            }
            connection(stream, peer, &gate, &cancel).await;
            drop(held);
        });
    }
}

/// One connection: the head, the decision, then the splice.
async fn connection(
    mut stream: TcpStream,
    peer: SocketAddr,
    gate: &Gate,
    cancel: &CancellationToken,
) {
    let read = tokio::select! {
        () = cancel.cancelled() => return,
        read = tokio::time::timeout(HEAD_DEADLINE, read_head(&mut stream)) => read,
    };
    let (bytes, head_len) = match read {
        Ok(Ok(h)) => h,
        Ok(Err(why)) => {
            gate.counters
                .refused_bad_request
                .fetch_add(1, Ordering::Relaxed);
            tracing::debug!(%peer, "foxglove: refused: {why}");
            if why == HeadError::TooLarge {
                refuse(
                    stream,
                    431,
                    "Request Header Fields Too Large",
                    why.message(),
                )
                .await;
            }
            return;
        }
        Err(_) => {
            gate.counters
                .refused_bad_request
                .fetch_add(1, Ordering::Relaxed);
            tracing::debug!(%peer, "foxglove: no request head within {HEAD_DEADLINE:?}");
            return;
        }
    };
    let head = String::from_utf8_lossy(&bytes[..head_len]);
    if let Err(refusal) = gate.policy.admit(&head) {
        let counter = match refusal {
            Refusal::BadRequest(_) => &gate.counters.refused_bad_request,
            Refusal::WrongToken | Refusal::TokenRequired => &gate.counters.refused_token,
        };
        counter.fetch_add(1, Ordering::Relaxed);
        tracing::info!(%peer, "foxglove: connection refused: {refusal}");
        let (code, reason) = refusal.status();
        refuse(stream, code, reason, &refusal.to_string()).await;
        return;
    }
    let mut upstream = match TcpStream::connect(gate.upstream).await {
        Ok(u) => u,
        Err(e) => {
            tracing::error!("foxglove: the Foxglove server does not answer: {e}");
            refuse(
                stream,
                503,
                "Service Unavailable",
                "the Foxglove server is down",
            )
            .await;
            return;
        }
    };
    let _ = upstream.set_nodelay(true);
    if upstream.write_all(&bytes).await.is_err() {
        return;
    }
    let _connected = Connected::new(&gate.counters);
    tracing::info!(%peer, "foxglove: client connected");
    tokio::select! {
        () = cancel.cancelled() => {}
        _ = tokio::io::copy_bidirectional(&mut stream, &mut upstream) => {}
    }
    tracing::info!(%peer, "foxglove: client disconnected");
}

/// One connected client in the counters while it lives.
struct Connected(Arc<FoxgloveCounters>);

impl Connected {
    fn new(counters: &Arc<FoxgloveCounters>) -> Self {
        counters.connections.fetch_add(1, Ordering::Relaxed);
        counters.clients.fetch_add(1, Ordering::Relaxed);
        Connected(counters.clone())
    }
}

impl Drop for Connected {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Why a request head could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
enum HeadError {
    /// The head did not end within [`MAX_HEAD_BYTES`].
    #[error("request head larger than {MAX_HEAD_BYTES} bytes")]
    TooLarge,
    /// The peer closed (or failed) before the head ended.
    #[error("the connection closed before the request head ended")]
    Closed,
}

impl HeadError {
    fn message(&self) -> &'static str {
        match self {
            HeadError::TooLarge => "request head too large",
            HeadError::Closed => "closed",
        }
    }
}

/// Reads until the blank line that ends an HTTP request head. Returns every byte read and the head's
/// length (bytes after it, if any, belong to the websocket and are forwarded as they are).
async fn read_head(stream: &mut TcpStream) -> Result<(Vec<u8>, usize), HeadError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let n = stream
            .read(&mut chunk)
            .await
            .map_err(|_| HeadError::Closed)?;
        if n == 0 {
            return Err(HeadError::Closed);
        }
        // Search from a little before the new bytes: the terminator may straddle two reads.
        let from = buf.len().saturating_sub(3);
        buf.extend_from_slice(&chunk[..n]);
        if let Some(at) = find(&buf[from..], b"\r\n\r\n") {
            let end = from + at + 4;
            if end > MAX_HEAD_BYTES {
                return Err(HeadError::TooLarge);
            }
            return Ok((buf, end));
        }
        if buf.len() > MAX_HEAD_BYTES {
            return Err(HeadError::TooLarge);
        }
    }
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Answers with a plain-text HTTP error and closes.
async fn refuse(mut stream: TcpStream, code: u16, reason: &str, body: &str) {
    let response = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{body}\n",
        body.len() + 1
    );
    let write = async {
        stream.write_all(response.as_bytes()).await?;
        stream.shutdown().await
    };
    let _ = tokio::time::timeout(REFUSAL_WRITE_LIMIT, write).await;
}
