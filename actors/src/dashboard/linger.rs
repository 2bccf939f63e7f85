//! A lingering close for the dashboard's websocket connections: when a websocket's connection is dropped,
//! its socket is not closed at once. Its write half is shut down (the FIN goes out after every byte
//! written before it, the close frame included), then whatever the client still sends is read and thrown
//! away until the client closes its side, [`LINGER_LIMIT`] passes or [`LINGER_BYTES`] were thrown away;
//! only then is the socket closed.
//!
//! Why: a socket closed while bytes it received are still unread is reset (RST), not closed (FIN), and a
//! reset throws away what is still waiting in the socket's send queue. When the server refuses a message
//! (an over-size one is refused by its header, with the rest of it still arriving), the close frame that
//! says why (1009) may still be in that queue, behind telemetry a busy client has not read yet; the
//! client's own close frame, answering ours, arrives unread too. A plain close then loses the close frame,
//! and the client sees a reset where it should see why it was refused. A client whose rest is still being
//! written sees its write fail.
//!
//! Bounded: one connection lingers at most [`LINGER_LIMIT`] and reads at most [`LINGER_BYTES`], and at most
//! [`LINGERING_AT_ONCE`] connections of one endpoint linger at once (beyond that a connection is closed
//! at once, as before), so a client that never closes holds a socket a few seconds, not forever. Only
//! connections that became websockets linger ([`Lingering::arm`]); a plain HTTP connection that is evicted
//! or out of time is closed at once, so that it makes room.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// How long a closed websocket's socket may linger for its client to close its side.
pub(crate) const LINGER_LIMIT: Duration = Duration::from_secs(5);
/// Bytes a lingering socket reads and throws away before it is closed anyway.
pub(crate) const LINGER_BYTES: usize = 1024 * 1024;
/// Connections of one endpoint lingering at once; a connection dropped beyond that is closed at once.
pub(crate) const LINGERING_AT_ONCE: usize = 256;
/// Bytes one read of a lingering socket takes.
const SCRAP_BYTES: usize = 2048;

/// How a linger ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Lingered {
    /// The client closed its side: the socket is closed cleanly.
    ClientClosed,
    /// The socket failed (the client reset it, or it was gone already).
    Failed,
    /// The client sent more than [`LINGER_BYTES`].
    OverBudget,
    /// The client did not close its side within [`LINGER_LIMIT`].
    OutOfTime,
}

/// Shuts down `io`'s write half, then reads and throws away what the peer sends until it closes its side,
/// `limit` passes or more than `budget` bytes came; `io` is closed when the caller drops it.
pub(crate) async fn linger<T>(io: &mut T, limit: Duration, budget: usize) -> Lingered
where
    T: AsyncRead + AsyncWrite + Unpin,
{
    let drain = async {
        if io.shutdown().await.is_err() {
            return Lingered::Failed;
        }
        let mut scrap = [0u8; SCRAP_BYTES];
        let mut thrown = 0usize;
        loop {
            match io.read(&mut scrap).await {
                Ok(0) => return Lingered::ClientClosed,
                Ok(n) => {
                    thrown += n;
                    if thrown > budget {
                        return Lingered::OverBudget;
                    }
                }
                Err(_) => return Lingered::Failed,
            }
        }
    };
    tokio::time::timeout(limit, drain)
        .await
        .unwrap_or(Lingered::OutOfTime)
}

/// The places for lingering connections of one endpoint.
#[derive(Debug, Clone)]
pub(crate) struct LingerSlots(Arc<Semaphore>);

impl LingerSlots {
    /// Room for `n` lingering connections at once.
    pub(crate) fn new(n: usize) -> Self {
        LingerSlots(Arc::new(Semaphore::new(n)))
    }

    /// Connections lingering now.
    #[cfg(test)]
    pub(crate) fn free(&self) -> usize {
        self.0.available_permits()
    }
}

/// A connection that lingers when dropped, once armed (it became a websocket).
pub(crate) struct Lingering<T> {
    /// `None` only while being dropped.
    io: Option<T>,
    slots: LingerSlots,
    armed: bool,
    /// Starts the linger on the current runtime (set where `T`'s bounds are known).
    start: fn(T, OwnedSemaphorePermit, &tokio::runtime::Handle),
}

impl<T> Lingering<T>
where
    T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    /// Wraps `io`; it lingers only once [`Lingering::arm`]ed.
    pub(crate) fn new(io: T, slots: LingerSlots) -> Self {
        Lingering {
            io: Some(io),
            slots,
            armed: false,
            start: start_linger::<T>,
        }
    }
}

fn start_linger<T>(mut io: T, place: OwnedSemaphorePermit, runtime: &tokio::runtime::Handle)
where
    T: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    runtime.spawn(async move {
        let how = linger(&mut io, LINGER_LIMIT, LINGER_BYTES).await;
        tracing::trace!(?how, "a closed websocket's socket stopped lingering");
        drop(io);
        drop(place);
    });
}

impl<T> Lingering<T> {
    /// From now on, dropping the connection lingers.
    pub(crate) fn arm(&mut self) {
        self.armed = true;
    }

    fn io(&mut self) -> io::Result<Pin<&mut T>>
    where
        T: Unpin,
    {
        self.io
            .as_mut()
            .map(Pin::new)
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotConnected, "the connection is closed"))
    }
}

impl<T> Drop for Lingering<T> {
    fn drop(&mut self) {
        let Some(io) = self.io.take() else { return };
        if !self.armed {
            return;
        }
        let Ok(runtime) = tokio::runtime::Handle::try_current() else {
            return;
        };
        match self.slots.0.clone().try_acquire_owned() {
            Ok(place) => (self.start)(io, place, &runtime),
            Err(_) => tracing::debug!(
                "{LINGERING_AT_ONCE} closed websockets are lingering already; closing one at once"
            ),
        }
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for Lingering<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        match self.io() {
            Ok(io) => io.poll_read(cx, buf),
            Err(e) => Poll::Ready(Err(e)),
        }
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for Lingering<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        match self.io() {
            Ok(io) => io.poll_write(cx, buf),
            Err(e) => Poll::Ready(Err(e)),
        }
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        match self.io() {
            Ok(io) => io.poll_write_vectored(cx, bufs),
            Err(e) => Poll::Ready(Err(e)),
        }
    }

    fn is_write_vectored(&self) -> bool {
        self.io.as_ref().is_some_and(T::is_write_vectored)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.io() {
            Ok(io) => io.poll_flush(cx),
            Err(e) => Poll::Ready(Err(e)),
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.io() {
            Ok(io) => io.poll_shutdown(cx),
            Err(e) => Poll::Ready(Err(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test]
    async fn an_armed_connection_ends_its_writes_then_reads_the_peer_dry_before_it_closes() {
        let slots = LingerSlots::new(2);
        let (mut client, server) = tokio::io::duplex(256);
        let mut server = Lingering::new(server, slots.clone());
        server.arm();
        server.write_all(b"close frame").await.unwrap();
        drop(server);
        assert_eq!(slots.free(), 1, "lingering");
        // The peer's rest, far more than the pipe holds: it is all taken (a closed end would fail it).
        client.write_all(&[7u8; 64 * 1024]).await.unwrap();
        let mut got = Vec::new();
        client.read_to_end(&mut got).await.unwrap();
        assert_eq!(got, b"close frame", "what was written, then the end");
        drop(client);
        while slots.free() < 2 {
            tokio::task::yield_now().await;
        }
    }

    #[tokio::test]
    async fn an_unarmed_connection_closes_at_once() {
        let slots = LingerSlots::new(2);
        let (mut client, server) = tokio::io::duplex(256);
        drop(Lingering::new(server, slots.clone()));
        assert_eq!(slots.free(), 2);
        assert!(client.write_all(&[7u8; 1024]).await.is_err(), "closed");
    }

    #[tokio::test]
    async fn beyond_its_places_a_connection_closes_at_once() {
        let slots = LingerSlots::new(1);
        let (_first_client, first) = tokio::io::duplex(256);
        let (mut second_client, second) = tokio::io::duplex(256);
        for io in [first, second] {
            let mut io = Lingering::new(io, slots.clone());
            io.arm();
            drop(io);
        }
        assert_eq!(slots.free(), 0);
        assert!(second_client.write_all(&[7u8; 1024]).await.is_err());
    }

    #[tokio::test]
    async fn a_linger_ends_at_its_byte_budget_and_its_time_limit() {
        let (mut client, mut server) = tokio::io::duplex(256);
        let feed = tokio::spawn(async move {
            let _ = client.write_all(&[1u8; 8192]).await;
            client
        });
        let how = linger(&mut server, Duration::from_secs(3600), 4096).await;
        assert_eq!(how, Lingered::OverBudget);
        drop(server);
        let _client = feed.await.unwrap();

        tokio::time::pause();
        let (_silent, mut server) = tokio::io::duplex(256);
        let how = linger(&mut server, Duration::from_secs(5), 4096).await;
        assert_eq!(how, Lingered::OutOfTime);
    }
}
