//! Connection floods for `pavlov bench --ws-abuse`: many watchers (no token) from many addresses, each
//! reading everything and reconnecting when refused or dropped, and many idle TCP sockets that send
//! nothing and are reopened as soon as the server closes them. They spread over loopback addresses
//! (127.0.0.0/8 is all loopback on Linux) like clients on other machines, so they meet the per-address
//! limits the way a real flood would; where such an address cannot be bound they use the default one.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use futures_util::StreamExt;
use tokio::io::AsyncReadExt;
use tokio::net::{TcpSocket, TcpStream};
use tokio::sync::watch;

/// How long a refused watcher waits before it tries again.
const WATCHER_RETRY: Duration = Duration::from_millis(500);
/// Addresses the watcher flood comes from (127.0.0.10 on).
const WATCHER_SOURCES: u8 = 10;
/// Addresses the idle flood comes from (127.0.0.40 on).
const IDLE_SOURCES: u8 = 20;

/// What the floods did.
#[derive(Debug, Default)]
pub(crate) struct FloodTally {
    /// Watcher handshakes that got a `hello`.
    pub(crate) watchers_admitted: AtomicU64,
    /// Watcher handshakes refused (any status) or cut.
    pub(crate) watchers_refused: AtomicU64,
    /// Idle sockets opened (each reopen counts).
    pub(crate) idle_opened: AtomicU64,
}

fn add(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

/// The `i`-th loopback address from `first`, wrapping over `count` of them.
fn source(first: u8, count: u8, i: usize) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(
        127,
        0,
        0,
        first + (i % usize::from(count)) as u8,
    ))
}

/// A TCP connection from `from` (or from the default address if it cannot be bound).
async fn connect_from(from: IpAddr, addr: SocketAddr) -> std::io::Result<TcpStream> {
    let socket = TcpSocket::new_v4()?;
    if socket.bind(SocketAddr::new(from, 0)).is_err() {
        return TcpStream::connect(addr).await;
    }
    socket.connect(addr).await
}

/// One watcher: connects without a token, reads until dropped, and tries again until `stop`.
async fn watcher(
    from: IpAddr,
    addr: SocketAddr,
    tally: Arc<FloodTally>,
    mut stop: watch::Receiver<bool>,
) {
    let url = format!("ws://{addr}/ws");
    while !*stop.borrow() {
        let attempt = async {
            let tcp = connect_from(from, addr).await.ok()?;
            tokio_tungstenite::client_async(url.as_str(), tcp)
                .await
                .ok()
        };
        match attempt.await {
            Some((mut ws, _)) => {
                add(&tally.watchers_admitted);
                loop {
                    tokio::select! {
                        _ = stop.changed() => return,
                        msg = ws.next() => if !matches!(msg, Some(Ok(_))) { break },
                    }
                }
            }
            None => add(&tally.watchers_refused),
        }
        tokio::select! {
            _ = stop.changed() => return,
            _ = tokio::time::sleep(WATCHER_RETRY) => {}
        }
    }
}

/// One idle socket: open, send nothing, and reopen as soon as the server closes it, until `stop`.
async fn idle_socket(
    from: IpAddr,
    addr: SocketAddr,
    tally: Arc<FloodTally>,
    mut stop: watch::Receiver<bool>,
) {
    while !*stop.borrow() {
        let Ok(mut tcp) = connect_from(from, addr).await else {
            tokio::time::sleep(Duration::from_millis(5)).await;
            continue;
        };
        add(&tally.idle_opened);
        let mut buf = [0u8; 256];
        loop {
            tokio::select! {
                _ = stop.changed() => return,
                n = tcp.read(&mut buf) => if !matches!(n, Ok(1..)) { break },
            }
        }
    }
}

/// Starts `watchers` watchers and `idle` idle sockets against `addr`; they run until `stop`.
pub(crate) fn spawn(
    addr: SocketAddr,
    watchers: usize,
    idle: usize,
    tally: &Arc<FloodTally>,
    stop: &watch::Receiver<bool>,
) -> Vec<tokio::task::JoinHandle<()>> {
    let mut tasks = Vec::with_capacity(watchers + idle);
    for i in 0..watchers {
        tasks.push(tokio::spawn(watcher(
            source(10, WATCHER_SOURCES, i),
            addr,
            tally.clone(),
            stop.clone(),
        )));
    }
    for i in 0..idle {
        tasks.push(tokio::spawn(idle_socket(
            source(40, IDLE_SOURCES, i),
            addr,
            tally.clone(),
            stop.clone(),
        )));
    }
    tasks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floods_spread_over_their_own_loopback_addresses() {
        assert_eq!(source(10, 10, 0).to_string(), "127.0.0.10");
        assert_eq!(source(10, 10, 13).to_string(), "127.0.0.13");
        assert_eq!(source(40, 20, 219).to_string(), "127.0.0.59");
    }
}
