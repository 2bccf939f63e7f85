//! Limits below HTTP: at most a fixed number of TCP connections at once, and a deadline for a connection
//! to become a websocket.
//!
//! `max_clients` bounds websocket clients, but a TCP connection costs memory before it is one: an abuser
//! could open thousands and send nothing (or half a request). [`GuardedListener`] accepts a connection only
//! while fewer than its limit are open (the rest are closed at once and counted), and [`GuardedIo`] ends a
//! connection that has not switched to the websocket protocol within [`PRE_UPGRADE_LIMIT`] — page
//! and asset requests take milliseconds, and browsers simply reopen an idle keep-alive connection. It
//! recognises the switch by the `101` status line the server writes.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::serve::Listener;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::Sleep;

/// How long a connection may stay plain HTTP (not a websocket).
pub const PRE_UPGRADE_LIMIT: Duration = Duration::from_secs(10);
/// TCP connections allowed beyond `max_clients`, for page loads, `/metrics` and handshakes in progress.
pub const EXTRA_CONNECTIONS: usize = 64;

/// What the guard refused, shared with the endpoint's counters.
#[derive(Debug, Default)]
pub(crate) struct GuardCounters {
    /// Connections closed at once because the limit was reached.
    pub(crate) refused: AtomicU64,
    /// Connections closed because they did not become a websocket in time.
    pub(crate) timed_out: AtomicU64,
}

/// A listener that holds at most `limit` connections open.
pub(crate) struct GuardedListener<L> {
    inner: L,
    slots: Arc<Semaphore>,
    counters: Arc<GuardCounters>,
    pre_upgrade_limit: Duration,
}

impl<L> GuardedListener<L> {
    /// Wraps `inner`: at most `limit` connections at once, each plain HTTP for at most `pre_upgrade_limit`.
    pub(crate) fn new(
        inner: L,
        limit: usize,
        pre_upgrade_limit: Duration,
        counters: Arc<GuardCounters>,
    ) -> Self {
        GuardedListener {
            inner,
            slots: Arc::new(Semaphore::new(limit.max(1))),
            counters,
            pre_upgrade_limit,
        }
    }
}

impl<L: Listener> Listener for GuardedListener<L> {
    type Io = GuardedIo<L::Io>;
    type Addr = L::Addr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            let (io, addr) = self.inner.accept().await;
            match self.slots.clone().try_acquire_owned() {
                Ok(permit) => {
                    let io = GuardedIo {
                        inner: io,
                        _permit: permit,
                        deadline: Some(Box::pin(tokio::time::sleep(self.pre_upgrade_limit))),
                        expired: false,
                        counters: self.counters.clone(),
                    };
                    return (io, addr);
                }
                Err(_) => {
                    self.counters.refused.fetch_add(1, Ordering::Relaxed);
                    tracing::debug!("too many TCP connections to the dashboard; closing a new one");
                }
            }
        }
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// A connection holding its slot; plain HTTP only until its deadline.
pub(crate) struct GuardedIo<T> {
    inner: T,
    _permit: OwnedSemaphorePermit,
    /// `None` once the connection is a websocket.
    deadline: Option<Pin<Box<Sleep>>>,
    /// The deadline passed: every read fails from then on.
    expired: bool,
    counters: Arc<GuardCounters>,
}

/// Whether bytes the server writes begin the `101 Switching Protocols` response.
fn is_switch(buf: &[u8]) -> bool {
    buf.starts_with(b"HTTP/1.1 101") || buf.starts_with(b"HTTP/1.0 101")
}

impl<T> GuardedIo<T> {
    fn expired(&mut self, cx: &mut Context<'_>) -> bool {
        if !self.expired
            && self
                .deadline
                .as_mut()
                .is_some_and(|d| d.as_mut().poll(cx).is_ready())
        {
            self.counters.timed_out.fetch_add(1, Ordering::Relaxed);
            self.expired = true;
            self.deadline = None;
        }
        self.expired
    }

    fn saw_write(&mut self, first: &[u8]) {
        if !self.expired && self.deadline.is_some() && is_switch(first) {
            self.deadline = None;
        }
    }
}

fn timed_out() -> io::Error {
    io::Error::new(
        io::ErrorKind::TimedOut,
        "the connection did not become a websocket in time",
    )
}

impl<T: AsyncRead + Unpin> AsyncRead for GuardedIo<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.expired(cx) {
            return Poll::Ready(Err(timed_out()));
        }
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for GuardedIo<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.saw_write(buf);
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        if let Some(first) = bufs.iter().find(|b| !b.is_empty()) {
            self.saw_write(first);
        }
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
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

    /// A listener handing out one end of in-memory pipes.
    struct Pipes(tokio::sync::mpsc::Receiver<DuplexStream>);

    impl Listener for Pipes {
        type Io = DuplexStream;
        type Addr = ();
        async fn accept(&mut self) -> (DuplexStream, ()) {
            match self.0.recv().await {
                Some(io) => (io, ()),
                None => std::future::pending().await,
            }
        }
        fn local_addr(&self) -> io::Result<()> {
            Ok(())
        }
    }

    #[tokio::test(start_paused = true)]
    async fn connections_beyond_the_limit_are_closed_and_counted() {
        let (tx, rx) = tokio::sync::mpsc::channel(8);
        let counters = Arc::new(GuardCounters::default());
        let mut l = GuardedListener::new(Pipes(rx), 2, PRE_UPGRADE_LIMIT, counters.clone());
        let mut clients = Vec::new();
        for _ in 0..3 {
            let (a, b) = tokio::io::duplex(64);
            tx.send(b).await.unwrap();
            clients.push(a);
        }
        let (first, _) = l.accept().await;
        let (_second, _) = l.accept().await;
        // The third is closed at once: its client reads EOF.
        let pending = tokio::spawn(async move { l.accept().await.0 });
        let mut buf = [0u8; 1];
        assert_eq!(clients[2].read(&mut buf).await.unwrap(), 0);
        assert_eq!(counters.refused.load(Ordering::Relaxed), 1);
        // Closing one frees its slot.
        drop(first);
        let (a, b) = tokio::io::duplex(64);
        tx.send(b).await.unwrap();
        let _fourth = pending.await.unwrap();
        drop(a);
        assert_eq!(counters.refused.load(Ordering::Relaxed), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn plain_http_ends_at_the_deadline_but_a_websocket_stays() {
        let (tx, rx) = tokio::sync::mpsc::channel(8);
        let counters = Arc::new(GuardCounters::default());
        let limit = Duration::from_secs(10);
        let mut l = GuardedListener::new(Pipes(rx), 8, limit, counters.clone());
        let (_slow_client, b) = tokio::io::duplex(64);
        tx.send(b).await.unwrap();
        let (mut slow, _) = l.accept().await;
        let (mut ws_client, b) = tokio::io::duplex(64);
        tx.send(b).await.unwrap();
        let (mut ws, _) = l.accept().await;
        ws.write_all(b"HTTP/1.1 101 Switching Protocols\r\n\r\n")
            .await
            .unwrap();
        let mut buf = [0u8; 64];
        let t0 = tokio::time::Instant::now();
        let err = slow.read(&mut buf).await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        assert_eq!(t0.elapsed(), limit);
        assert_eq!(counters.timed_out.load(Ordering::Relaxed), 1);
        // The websocket is read long after the deadline.
        tokio::time::sleep(Duration::from_secs(60)).await;
        ws_client.write_all(b"late").await.unwrap();
        assert_eq!(ws.read(&mut buf).await.unwrap(), 4);
        assert_eq!(counters.timed_out.load(Ordering::Relaxed), 1);
    }
}
