//! Limits below HTTP: every TCP connection that is not (yet) a websocket sits in the `PendingPool`
//! (bounded in total and per source address, evicting its oldest rather than refusing newcomers), and has
//! [`PRE_UPGRADE_LIMIT`] to become a websocket.
//!
//! A TCP connection costs memory before it is a websocket, and the operator and watcher limits only apply
//! at the handshake: an abuser could open thousands of sockets and send nothing (or half a request), and
//! reopen each one as soon as it is closed. `GuardedListener` admits every new connection into the pool,
//! evicting the oldest pending connection of the source holding the most when the pool (or the new
//! connection's own source) is full — its silent ones first, those that never sent a byte, which the guard
//! learns from its reads — so a fresh connection — the operator's handshake, a `/healthz`
//! probe — from an address holding fewer always gets in. Only a source bursting past its own share
//! faster than [`super::pending::GRACE`] has its newest connections closed at once (refused), so that it does
//! not kill its own handshakes in flight. `GuardedIo` ends a connection that is evicted, or that has not switched to
//! the websocket protocol within [`PRE_UPGRADE_LIMIT`] (page and asset requests take milliseconds, and
//! browsers simply reopen an idle keep-alive connection). It recognises the switch by the `101` status line
//! the server writes; from then on the connection is a websocket and leaves the pool.
//!
//! That deadline is meant for a request head, not for a response: a handler that answers with a long
//! response (the recording's download, `super::download`) says so through the connection's
//! `LongResponse` (handlers reach it as the second field of `Peer`). The connection then leaves the
//! pool, like a websocket, and from then on ends only when the client takes no bytes for [`STALL_LIMIT`]
//! (a slow reader is bounded by its progress, never by the total time).

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::extract::connect_info::Connected;
use axum::serve::{IncomingStream, Listener};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::Sleep;
use tokio_util::sync::WaitForCancellationFutureOwned;

use super::linger::{LINGERING_AT_ONCE, LingerSlots, Lingering};
use super::pending::{Activity, Admission, Admitted, PendingPool};
use super::session::worth_logging;
use super::source::Source;

/// How long a connection may stay plain HTTP (not a websocket).
pub const PRE_UPGRADE_LIMIT: Duration = Duration::from_secs(3);
/// How long a long response's client may take no bytes before its connection is closed.
pub const STALL_LIMIT: Duration = Duration::from_secs(30);
pub use super::pending::GRACE;

/// What the guard did, shared with the endpoint's counters.
#[derive(Debug, Default)]
pub(crate) struct GuardCounters {
    /// New connections closed at once: their source was bursting past its share.
    pub(crate) refused: AtomicU64,
    /// Pending connections closed to make room for a new one.
    pub(crate) evicted: AtomicU64,
    /// Connections closed because they did not become a websocket in time.
    pub(crate) timed_out: AtomicU64,
    /// Long responses closed because their client took no bytes for [`STALL_LIMIT`].
    pub(crate) stalled: AtomicU64,
}

/// The pool shared by the listener and its connections.
pub(crate) type SharedPool = Arc<Mutex<PendingPool>>;

fn lock(pool: &Mutex<PendingPool>) -> MutexGuard<'_, PendingPool> {
    pool.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The peer's address and its connection's `LongResponse` switch, for handlers (`ConnectInfo<Peer>`).
#[derive(Debug, Clone)]
pub(crate) struct Peer(pub(crate) SocketAddr, pub(crate) LongResponse);

impl<L> Connected<IncomingStream<'_, GuardedListener<L>>> for Peer
where
    L: Listener<Addr = SocketAddr>,
    L::Io: BytesWaiting,
{
    fn connect_info(stream: IncomingStream<'_, GuardedListener<L>>) -> Self {
        Peer(*stream.remote_addr(), stream.io().long.clone())
    }
}

/// A handler's word to its connection that the response it is making is long: from then on the
/// connection is not pending (it leaves the pool and its request-head deadline) and ends only when its
/// client takes no bytes for [`STALL_LIMIT`]. Set once; a connection carrying a long response should
/// close after it (`Connection: close`), so it never goes back to waiting for a request.
#[derive(Debug, Clone, Default)]
pub(crate) struct LongResponse(Arc<AtomicBool>);

impl LongResponse {
    /// The response being made is long.
    pub(crate) fn begin(&self) {
        self.0.store(true, Ordering::Release);
    }

    fn begun(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }
}

/// A listener whose connections are pending (bounded, evicting) until they become websockets.
pub(crate) struct GuardedListener<L> {
    inner: L,
    pool: SharedPool,
    counters: Arc<GuardCounters>,
    pre_upgrade_limit: Duration,
    /// Places for the connections that linger once closed (`super::linger`).
    lingering: LingerSlots,
}

impl<L> GuardedListener<L> {
    /// Wraps `inner`: pending connections in `pool`, each plain HTTP for at most `pre_upgrade_limit`.
    pub(crate) fn new(
        inner: L,
        pool: SharedPool,
        pre_upgrade_limit: Duration,
        counters: Arc<GuardCounters>,
    ) -> Self {
        GuardedListener {
            inner,
            pool,
            counters,
            pre_upgrade_limit,
            lingering: LingerSlots::new(LINGERING_AT_ONCE),
        }
    }
}

/// Whether a just-accepted connection already has bytes waiting to be read (its request, sent at once).
/// When the server is behind — a flood — the request of a real client is there by the time it is
/// accepted; an idle socket's never is.
pub(crate) trait BytesWaiting {
    /// Bytes are waiting (never blocks, never consumes them).
    fn bytes_waiting(&self) -> bool;
}

impl BytesWaiting for tokio::net::TcpStream {
    fn bytes_waiting(&self) -> bool {
        let mut one = [std::mem::MaybeUninit::<u8>::uninit(); 1];
        // The socket is non-blocking: no bytes is WouldBlock.
        matches!(socket2::SockRef::from(self).peek(&mut one), Ok(n) if n > 0)
    }
}

impl<L> Listener for GuardedListener<L>
where
    L: Listener<Addr = SocketAddr>,
    L::Io: BytesWaiting,
{
    type Io = GuardedIo<L::Io>;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            let (io, addr) = self.inner.accept().await;
            let source = Source::of(addr.ip());
            let speaking = io.bytes_waiting();
            let admission = lock(&self.pool).admit(source, tokio::time::Instant::now(), speaking);
            match admission {
                Admission::Admitted(admitted) => return self.guard(io, addr, source, admitted),
                Admission::Refused => {
                    let n = self.counters.refused.fetch_add(1, Ordering::Relaxed) + 1;
                    if worth_logging(n) {
                        tracing::info!(
                            total = n,
                            %source,
                            "{source} opens dashboard connections faster than they are served; closing a new one"
                        );
                    }
                }
            }
        }
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

impl<L: Listener<Addr = SocketAddr>> GuardedListener<L> {
    /// Wraps an admitted connection.
    fn guard(
        &self,
        io: L::Io,
        addr: SocketAddr,
        source: Source,
        admitted: Admitted,
    ) -> (GuardedIo<L::Io>, SocketAddr) {
        if let Some(victim) = admitted.evicted {
            let n = self.counters.evicted.fetch_add(1, Ordering::Relaxed) + 1;
            if worth_logging(n) {
                tracing::info!(
                    total = n,
                    %victim,
                    "too many pending connections to the dashboard; evicting the oldest of {victim}"
                );
            }
        }
        let seat = PendingSeat {
            pool: self.pool.clone(),
            source,
            id: admitted.id,
            deadline: Box::pin(tokio::time::sleep(self.pre_upgrade_limit)),
            evicted: Box::pin(admitted.evict.cancelled_owned()),
            activity: admitted.activity,
        };
        let io = GuardedIo {
            inner: Lingering::new(io, self.lingering.clone()),
            pending: Some(seat),
            ended: false,
            counters: self.counters.clone(),
            long: LongResponse::default(),
            progress: None,
        };
        (io, addr)
    }
}

/// A connection's place in the pool while it is pending; leaving it (drop) frees the place.
struct PendingSeat {
    pool: SharedPool,
    source: Source,
    id: u64,
    deadline: Pin<Box<Sleep>>,
    evicted: Pin<Box<WaitForCancellationFutureOwned>>,
    /// What it has sent so far (silent connections are evicted first).
    activity: Activity,
}

impl Drop for PendingSeat {
    fn drop(&mut self) {
        lock(&self.pool).remove(self.source, self.id);
    }
}

/// A connection: pending (bounded in time, evictable) until it becomes a websocket; a websocket lingers
/// when closed (`super::linger`).
pub(crate) struct GuardedIo<T> {
    inner: Lingering<T>,
    /// `None` once the connection is a websocket, or once it ended.
    pending: Option<PendingSeat>,
    /// Evicted or out of time: every read and write fails from then on.
    ended: bool,
    counters: Arc<GuardCounters>,
    /// Set by the handler making a long response.
    long: LongResponse,
    /// While a long response is made: when the connection ends unless the client takes bytes first.
    progress: Option<Pin<Box<Sleep>>>,
}

/// Whether bytes the server writes begin the `101 Switching Protocols` response.
fn is_switch(buf: &[u8]) -> bool {
    buf.starts_with(b"HTTP/1.1 101") || buf.starts_with(b"HTTP/1.0 101")
}

impl<T> GuardedIo<T> {
    /// Whether the connection has ended (evicted, or pending too long); registers the waker otherwise.
    fn ended(&mut self, cx: &mut Context<'_>) -> bool {
        if self.ended {
            return true;
        }
        if self.progress.is_none() && self.long.begun() {
            // The request is in; the response is long: only the client's progress bounds it now.
            self.pending = None;
            self.progress = Some(Box::pin(tokio::time::sleep(STALL_LIMIT)));
        }
        if let Some(progress) = self.progress.as_mut() {
            if progress.as_mut().poll(cx).is_ready() {
                let n = self.counters.stalled.fetch_add(1, Ordering::Relaxed) + 1;
                if worth_logging(n) {
                    tracing::info!(
                        total = n,
                        "a dashboard client took no bytes of a long response for {} s; closing it",
                        STALL_LIMIT.as_secs()
                    );
                }
                self.ended = true;
            }
            return self.ended;
        }
        let Some(seat) = self.pending.as_mut() else {
            return false;
        };
        if seat.evicted.as_mut().poll(cx).is_ready() {
            self.ended = true;
        } else if seat.deadline.as_mut().poll(cx).is_ready() {
            self.counters.timed_out.fetch_add(1, Ordering::Relaxed);
            self.ended = true;
        }
        if self.ended {
            self.pending = None;
        }
        self.ended
    }

    fn saw_write(&mut self, first: &[u8]) {
        if self.pending.is_some() && is_switch(first) {
            self.pending = None;
            self.inner.arm();
        }
    }

    /// Bytes were written: a long response's connection has another [`STALL_LIMIT`].
    fn progressed(&mut self, written: &Poll<io::Result<usize>>) {
        if let (Some(progress), Poll::Ready(Ok(n))) = (self.progress.as_mut(), written)
            && *n > 0
        {
            progress
                .as_mut()
                .reset(tokio::time::Instant::now() + STALL_LIMIT);
        }
    }
}

fn ended_error() -> io::Error {
    io::Error::new(
        io::ErrorKind::TimedOut,
        "the connection did not become a websocket in time, or made room for a newer one",
    )
}

impl<T: AsyncRead + Unpin> AsyncRead for GuardedIo<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.ended(cx) {
            return Poll::Ready(Err(ended_error()));
        }
        let before = buf.filled().len();
        let read = Pin::new(&mut self.inner).poll_read(cx, buf);
        let on_trial = match (&self.pending, &read) {
            (Some(seat), Poll::Ready(Ok(()))) if buf.filled().len() > before => {
                seat.activity.read_bytes();
                false
            }
            (Some(seat), Poll::Pending) => {
                seat.activity.found_nothing() && lock(&seat.pool).over_share(seat.source)
            }
            _ => false,
        };
        if on_trial {
            // Silent while its source is over its share: it makes room at once.
            self.pending = None;
            self.ended = true;
            self.counters.evicted.fetch_add(1, Ordering::Relaxed);
            return Poll::Ready(Err(ended_error()));
        }
        read
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for GuardedIo<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        if self.ended(cx) {
            return Poll::Ready(Err(ended_error()));
        }
        self.saw_write(buf);
        let written = Pin::new(&mut self.inner).poll_write(cx, buf);
        self.progressed(&written);
        written
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        if self.ended(cx) {
            return Poll::Ready(Err(ended_error()));
        }
        if let Some(first) = bufs.iter().find(|b| !b.is_empty()) {
            self.saw_write(first);
        }
        let written = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        self.progressed(&written);
        written
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if self.ended(cx) {
            return Poll::Ready(Err(ended_error()));
        }
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

    /// A listener handing out one end of in-memory pipes, each from the address it was sent with.
    struct Pipes(tokio::sync::mpsc::Receiver<(DuplexStream, SocketAddr)>);

    impl Listener for Pipes {
        type Io = DuplexStream;
        type Addr = SocketAddr;
        async fn accept(&mut self) -> (DuplexStream, SocketAddr) {
            match self.0.recv().await {
                Some(io) => io,
                None => std::future::pending().await,
            }
        }
        fn local_addr(&self) -> io::Result<SocketAddr> {
            Ok(SocketAddr::from(([127, 0, 0, 1], 1)))
        }
    }

    impl BytesWaiting for DuplexStream {
        fn bytes_waiting(&self) -> bool {
            false
        }
    }

    fn from(last: u8) -> SocketAddr {
        SocketAddr::from(([10, 0, 0, last], 40000))
    }

    struct Rig {
        tx: tokio::sync::mpsc::Sender<(DuplexStream, SocketAddr)>,
        listener: GuardedListener<Pipes>,
        pool: SharedPool,
        counters: Arc<GuardCounters>,
    }

    fn rig(total: usize, per_source: usize) -> Rig {
        let (tx, rx) = tokio::sync::mpsc::channel(64);
        let counters = Arc::new(GuardCounters::default());
        let pool = Arc::new(Mutex::new(PendingPool::new(total, per_source)));
        let listener =
            GuardedListener::new(Pipes(rx), pool.clone(), PRE_UPGRADE_LIMIT, counters.clone());
        Rig {
            tx,
            listener,
            pool,
            counters,
        }
    }

    impl Rig {
        /// A client end and the server's guarded end of a new connection from `addr`.
        async fn connect(&mut self, addr: SocketAddr) -> (DuplexStream, GuardedIo<DuplexStream>) {
            let (client, server) = tokio::io::duplex(256);
            self.tx.send((server, addr)).await.unwrap();
            let (io, _) = self.listener.accept().await;
            (client, io)
        }
    }

    #[tokio::test(start_paused = true)]
    async fn a_new_connection_evicts_the_oldest_of_the_busiest_source() {
        let mut rig = rig(3, 3);
        let (_c1, mut flood1) = rig.connect(from(1)).await;
        let (_c2, _flood2) = rig.connect(from(1)).await;
        let (_c3, mut quiet) = rig.connect(from(2)).await;
        let (_c4, mut fresh) = rig.connect(from(3)).await;
        assert_eq!(rig.counters.evicted.load(Ordering::Relaxed), 1);
        assert_eq!(lock(&rig.pool).len(), 3);
        // The evicted connection's reads fail at once; the others are untouched.
        let mut buf = [0u8; 8];
        assert!(flood1.read(&mut buf).await.is_err());
        for io in [&mut quiet, &mut fresh] {
            let read = tokio::time::timeout(Duration::from_millis(10), io.read(&mut buf)).await;
            assert!(read.is_err(), "still waiting for bytes");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn plain_http_ends_at_the_deadline_but_a_websocket_stays_and_leaves_the_pool() {
        let mut rig = rig(8, 8);
        let (_slow_client, mut slow) = rig.connect(from(1)).await;
        let (mut ws_client, mut ws) = rig.connect(from(1)).await;
        ws.write_all(b"HTTP/1.1 101 Switching Protocols\r\n\r\n")
            .await
            .unwrap();
        assert_eq!(
            lock(&rig.pool).len(),
            1,
            "the websocket is no longer pending"
        );
        let mut buf = [0u8; 64];
        let t0 = tokio::time::Instant::now();
        let err = slow.read(&mut buf).await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        assert_eq!(t0.elapsed(), PRE_UPGRADE_LIMIT);
        assert_eq!(rig.counters.timed_out.load(Ordering::Relaxed), 1);
        assert_eq!(lock(&rig.pool).len(), 0);
        // The websocket is read long after the deadline.
        tokio::time::sleep(Duration::from_secs(60)).await;
        ws_client.write_all(b"late").await.unwrap();
        assert_eq!(ws.read(&mut buf).await.unwrap(), 4);
        assert_eq!(rig.counters.timed_out.load(Ordering::Relaxed), 1);
        // Websockets never count against the pool: many more pending connections fit.
        let mut held = Vec::new();
        for i in 0..8 {
            held.push(rig.connect(from(10 + i)).await);
        }
        assert_eq!(rig.counters.evicted.load(Ordering::Relaxed), 0);
    }

    #[tokio::test(start_paused = true)]
    async fn a_source_bursting_past_its_share_has_its_newest_refused_until_the_grace_passes() {
        let mut rig = rig(8, 2);
        let (_a, mut first) = rig.connect(from(1)).await;
        let (_b, _second) = rig.connect(from(1)).await;
        // The third from the same address is closed at once; the listener hands out the next one.
        let (mut third, server_end) = tokio::io::duplex(256);
        rig.tx.send((server_end, from(1))).await.unwrap();
        let (_d, _other) = rig.connect(from(2)).await;
        let mut buf = [0u8; 8];
        assert_eq!(third.read(&mut buf).await.unwrap(), 0);
        assert_eq!(rig.counters.refused.load(Ordering::Relaxed), 1);
        assert_eq!(rig.counters.evicted.load(Ordering::Relaxed), 0);
        // Once the oldest has had its grace, a newcomer takes its place.
        tokio::time::sleep(crate::dashboard::pending::GRACE).await;
        let (_e, _fourth) = rig.connect(from(1)).await;
        assert_eq!(rig.counters.evicted.load(Ordering::Relaxed), 1);
        assert!(first.read(&mut buf).await.is_err());
    }

    #[tokio::test(start_paused = true)]
    async fn a_long_response_outlives_the_head_deadline_and_ends_only_when_the_client_stops_reading()
     {
        let mut rig = rig(8, 8);
        let (mut client, mut server) = rig.connect(from(1)).await;
        server.long.begin();
        server.write_all(b"HTTP/1.1 200 OK\r\n\r\n").await.unwrap();
        assert_eq!(lock(&rig.pool).len(), 0, "a long response is not pending");
        let mut buf = [0u8; 256];
        let _ = client.read(&mut buf).await.unwrap();
        // Ten times the head deadline, a little at a time: the connection stays.
        for _ in 0..30 {
            tokio::time::sleep(Duration::from_secs(1)).await;
            server.write_all(b"0123456789").await.unwrap();
            assert_eq!(client.read(&mut buf).await.unwrap(), 10);
        }
        assert_eq!(rig.counters.timed_out.load(Ordering::Relaxed), 0);
        // The client stops reading: once the pipe is full, the connection ends after STALL_LIMIT.
        let t0 = tokio::time::Instant::now();
        let err = loop {
            if let Err(e) = server.write(&[0u8; 64]).await {
                break e;
            }
        };
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        assert_eq!(t0.elapsed(), STALL_LIMIT);
        assert_eq!(rig.counters.stalled.load(Ordering::Relaxed), 1);
        assert_eq!(rig.counters.timed_out.load(Ordering::Relaxed), 0);
    }

    #[tokio::test(start_paused = true)]
    async fn a_closed_connection_frees_its_place() {
        let mut rig = rig(2, 2);
        let (_a, first) = rig.connect(from(1)).await;
        let (_b, _second) = rig.connect(from(1)).await;
        drop(first);
        assert_eq!(lock(&rig.pool).len(), 1);
        let (_c, _third) = rig.connect(from(1)).await;
        assert_eq!(rig.counters.evicted.load(Ordering::Relaxed), 0);
    }
}
