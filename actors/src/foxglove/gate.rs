//! The Foxglove endpoint's front door: the public listening socket, bound before the robot is touched.
//!
//! The Foxglove SDK's server binds its own socket and upgrades every request that offers its subprotocol;
//! it has no hook to look at a request first and no limit on connections. So the SDK listens on an
//! ephemeral loopback port of its own, and this gate stands in front of it on the public address:
//! - seats ([`Seats`]): at most [`MAX_CONNECTIONS`] TCP connections at once, and at most
//!   [`MAX_PER_ADDRESS`] of them from one source address, a socket still sending its head included (more
//!   are answered 503 and closed, counted as `busy` or `address`), so one host's idle sockets cannot take
//!   every seat;
//! - a request head must arrive within [`HEAD_DEADLINE`] and fit in [`MAX_HEAD_BYTES`];
//! - [`super::access`] decides on the head (token, watch rule): a refusal is answered 401 (400 for what
//!   is not a websocket request, or offers no subprotocol the endpoint speaks) before any upgrade, and
//!   counted;
//! - an admitted connection is spliced, head first, to the SDK's port: the SDK does the handshake and
//!   speaks the Foxglove protocol. A client that offered the published protocol's name
//!   (`foxglove.websocket.v1`) is offered to the SDK as `foxglove.sdk.v1` and the SDK's answer is named
//!   back ([`super::access::for_sdk`], [`super::access::for_client`]); then the gate copies bytes both ways
//!   until either side closes;
//! - a client that does not read is evicted: when the gate has bytes for it and its socket (whose send
//!   buffer is [`SEND_BUFFER`]) has accepted none of them for [`STALL_LIMIT`], it is closed and counted.
//!
//! Everything here runs on the endpoint's own runtime; nothing touches the tick.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_util::sync::CancellationToken;

use super::access::{self, Refusal, WatchPolicy};
use crate::telemetry::counters::FoxgloveCounters;

/// Most TCP connections open at once on the public port (handshaking or connected).
pub(crate) const MAX_CONNECTIONS: u64 = 32;
/// Most of those from one source address (an IPv4 address, or an IPv6 address; IPv4-mapped IPv6 counts
/// as IPv4).
pub(crate) const MAX_PER_ADDRESS: u64 = 8;
/// Longest wait for a complete request head (as the dashboard's).
pub(crate) const HEAD_DEADLINE: Duration = Duration::from_secs(3);
/// Largest request head accepted.
pub(crate) const MAX_HEAD_BYTES: usize = 16 * 1024;
/// Longest a client's socket may accept none of the bytes waiting for it before the client is evicted.
pub(crate) const STALL_LIMIT: Duration = Duration::from_secs(10);
/// The kernel's send buffer for a client (Linux doubles it): bounds what waits in the kernel for a client
/// that does not read, so that it stalls, and is evicted, within seconds rather than megabytes later
/// (ticks flow at about 100 kB/s, far below what such a window carries).
pub(crate) const SEND_BUFFER: usize = 64 * 1024;
/// Longest wait for the SDK's answer to a handshake.
const UPSTREAM_LIMIT: Duration = Duration::from_secs(10);
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
    /// The seats taken now.
    pub(crate) seats: Arc<Seats>,
}

/// The connections open now, in all and per source address.
#[derive(Debug, Default)]
pub(crate) struct Seats {
    held: Mutex<Held>,
}

#[derive(Debug, Default)]
struct Held {
    total: u64,
    by_address: HashMap<IpAddr, u64>,
}

/// Why no seat was free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Full {
    /// [`MAX_CONNECTIONS`] are open.
    All,
    /// [`MAX_PER_ADDRESS`] are open from this source address.
    Address,
}

impl Seats {
    fn lock(&self) -> MutexGuard<'_, Held> {
        // The counts stay consistent even if a holder panicked: each change is one statement.
        self.held.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes a seat for a connection from `ip`, or says why none is free.
    fn take(self: &Arc<Self>, ip: IpAddr) -> Result<Seat, Full> {
        let ip = ip.to_canonical();
        let mut held = self.lock();
        if held.total >= MAX_CONNECTIONS {
            return Err(Full::All);
        }
        let mine = held.by_address.entry(ip).or_insert(0);
        if *mine >= MAX_PER_ADDRESS {
            return Err(Full::Address);
        }
        *mine += 1;
        held.total += 1;
        Ok(Seat {
            seats: self.clone(),
            ip,
        })
    }

    /// Seats taken now: in all, and by `ip`.
    #[cfg(test)]
    fn taken(&self, ip: IpAddr) -> (u64, u64) {
        let held = self.lock();
        let mine = held.by_address.get(&ip.to_canonical()).copied();
        (held.total, mine.unwrap_or(0))
    }
}

/// One seat, given back when dropped.
struct Seat {
    seats: Arc<Seats>,
    ip: IpAddr,
}

impl Drop for Seat {
    fn drop(&mut self) {
        let mut held = self.seats.lock();
        held.total = held.total.saturating_sub(1);
        if let Some(mine) = held.by_address.get_mut(&self.ip) {
            *mine = mine.saturating_sub(1);
            if *mine == 0 {
                held.by_address.remove(&self.ip);
            }
        }
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
        let seat = gate.seats.take(peer.ip());
        let gate = gate.clone();
        let cancel = cancel.clone();
        tokio::spawn(async move {
            let seat = match seat {
                Ok(seat) => seat,
                Err(full) => {
                    let (counter, body) = match full {
                        Full::All => (
                            &gate.counters.refused_busy,
                            format!("too many Foxglove connections (at most {MAX_CONNECTIONS})"),
                        ),
                        Full::Address => (
                            &gate.counters.refused_address,
                            format!(
                                "too many Foxglove connections from {} (at most {MAX_PER_ADDRESS} \
                                 per address)",
                                peer.ip()
                            ),
                        ),
                    };
                    counter.fetch_add(1, Ordering::Relaxed);
                    tracing::debug!(%peer, "foxglove: refused: {body}");
                    refuse(stream, 503, "Service Unavailable", &body).await;
                    return;
                }
            };
            connection(stream, peer, &gate, &cancel).await;
            drop(seat);
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
    let forward = gate
        .policy
        .admit(&head)
        .and_then(|()| access::for_sdk(&head));
    let forward = match forward {
        Ok(f) => f,
        Err(refusal) => {
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
    };
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
    let _ = socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER);
    let mut request = forward.head.into_bytes();
    request.extend_from_slice(&bytes[head_len..]);
    if upstream.write_all(&request).await.is_err() {
        return;
    }
    if forward.translated {
        // The SDK's answer names `foxglove.sdk.v1`: the client offered (and expects) the spec's name.
        let answer = tokio::select! {
            () = cancel.cancelled() => return,
            answer = tokio::time::timeout(UPSTREAM_LIMIT, read_head(&mut upstream)) => answer,
        };
        let Ok(Ok((answer, answer_len))) = answer else {
            tracing::warn!(%peer, "foxglove: the Foxglove server did not answer the handshake");
            return;
        };
        let mut translated =
            access::for_client(&String::from_utf8_lossy(&answer[..answer_len])).into_bytes();
        translated.extend_from_slice(&answer[answer_len..]);
        if write_or_stall(&mut stream, &translated).await.is_err() {
            return;
        }
    }
    let _connected = Connected::new(&gate.counters);
    tracing::info!(%peer, "foxglove: client connected");
    let ended = tokio::select! {
        () = cancel.cancelled() => Ok(()),
        ended = splice(&mut stream, &mut upstream) => ended,
    };
    if ended == Err(Stalled) {
        gate.counters.evicted_slow.fetch_add(1, Ordering::Relaxed);
        tracing::info!(
            %peer,
            "foxglove: client evicted: it read nothing for {STALL_LIMIT:?} while data waited for it"
        );
        // Drop what waits in the kernel for it at once (a reset), rather than keep trying to deliver it.
        let _ = socket2::SockRef::from(&stream).set_linger(Some(Duration::ZERO));
    }
    tracing::info!(%peer, "foxglove: client disconnected");
}

/// A client's socket accepted none of the bytes waiting for it within [`STALL_LIMIT`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stalled;

/// Copies bytes both ways until either side closes (`Ok`) or the client stops reading (`Err`).
async fn splice(client: &mut TcpStream, upstream: &mut TcpStream) -> Result<(), Stalled> {
    let (mut client_read, mut client_write) = client.split();
    let (mut upstream_read, mut upstream_write) = upstream.split();
    let up = async {
        let _ = tokio::io::copy(&mut client_read, &mut upstream_write).await;
        Ok(())
    };
    let down = async {
        let mut buf = vec![0u8; 16 * 1024];
        loop {
            let n = match upstream_read.read(&mut buf).await {
                Ok(0) | Err(_) => return Ok(()),
                Ok(n) => n,
            };
            match write_or_stall(&mut client_write, &buf[..n]).await {
                Ok(()) => {}
                Err(WriteEnd::Closed) => return Ok(()),
                Err(WriteEnd::Stalled) => return Err(Stalled),
            }
        }
    };
    tokio::select! {
        ended = up => ended,
        ended = down => ended,
    }
}

/// How a write to a client ended early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum WriteEnd {
    /// The connection closed or failed.
    Closed,
    /// No byte was accepted within [`STALL_LIMIT`].
    Stalled,
}

/// Writes all of `data`, giving up when the socket accepts nothing for [`STALL_LIMIT`] (each write that
/// takes some bytes starts the wait again).
async fn write_or_stall(
    to: &mut (impl AsyncWrite + Unpin),
    mut data: &[u8],
) -> Result<(), WriteEnd> {
    while !data.is_empty() {
        match tokio::time::timeout(STALL_LIMIT, to.write(data)).await {
            Err(_) => return Err(WriteEnd::Stalled),
            Ok(Ok(0) | Err(_)) => return Err(WriteEnd::Closed),
            Ok(Ok(n)) => data = &data[n..],
        }
    }
    Ok(())
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

/// Reads until the blank line that ends an HTTP head (a request's, or the SDK's response). Returns every
/// byte read and the head's length (bytes after it, if any, belong to the websocket and are forwarded as
/// they are).
async fn read_head(stream: &mut (impl AsyncRead + Unpin)) -> Result<(Vec<u8>, usize), HeadError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_address_takes_at_most_its_share_and_every_seat_comes_back() {
        let seats = Arc::new(Seats::default());
        let one: IpAddr = [127, 0, 0, 1].into();
        let mapped: IpAddr = "::ffff:127.0.0.1".parse().unwrap();
        let mut held: Vec<Seat> = (0..MAX_PER_ADDRESS)
            .map(|_| seats.take(one).unwrap())
            .collect();
        // An IPv4-mapped IPv6 address is the same source.
        assert_eq!(seats.take(mapped).err(), Some(Full::Address));
        assert_eq!(seats.take(one).err(), Some(Full::Address));
        assert_eq!(seats.taken(one), (MAX_PER_ADDRESS, MAX_PER_ADDRESS));
        // Other addresses fill the rest, then nobody gets in.
        let mut host = 2u8;
        while (held.len() as u64) < MAX_CONNECTIONS {
            match seats.take([127, 0, 0, host].into()) {
                Ok(seat) => held.push(seat),
                Err(Full::Address) => host += 1,
                Err(Full::All) => panic!("full before {MAX_CONNECTIONS}"),
            }
        }
        assert_eq!(seats.take([10, 0, 0, 1].into()).err(), Some(Full::All));
        held.truncate(MAX_PER_ADDRESS as usize - 1);
        assert_eq!(seats.taken(one), (MAX_PER_ADDRESS - 1, MAX_PER_ADDRESS - 1));
        assert!(seats.take([10, 0, 0, 1].into()).is_ok());
        drop(held);
        assert_eq!(seats.taken(one), (0, 0));
        assert!(seats.lock().by_address.is_empty());
    }

    #[tokio::test]
    async fn a_reader_that_stops_reading_is_told_apart_from_one_that_closes() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        // A peer that reads nothing: writes stall once both buffers are full.
        let _silent = TcpStream::connect(addr).await.unwrap();
        let (mut to_silent, _) = listener.accept().await.unwrap();
        socket2::SockRef::from(&to_silent)
            .set_send_buffer_size(SEND_BUFFER)
            .unwrap();
        tokio::time::pause();
        let chunk = vec![0u8; 64 * 1024];
        let ended = loop {
            if let Err(end) = write_or_stall(&mut to_silent, &chunk).await {
                break end;
            }
        };
        assert_eq!(ended, WriteEnd::Stalled);
        tokio::time::resume();
        // A peer that closes: the write fails, it is not a stall.
        let closing = TcpStream::connect(addr).await.unwrap();
        let (mut to_closing, _) = listener.accept().await.unwrap();
        drop(closing);
        let ended = loop {
            if let Err(end) = write_or_stall(&mut to_closing, &chunk).await {
                break end;
            }
        };
        assert_eq!(ended, WriteEnd::Closed);
    }
}
