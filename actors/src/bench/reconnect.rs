//! Websocket clients for `pavlov bench --ws-reconnect-every S`: each reads the stream for `S` seconds, closes
//! and connects again, reading the whole history the server sends after `hello` every time, so that the
//! benchmark shows what a page opening mid-run costs the server (and the tick) and how long its history takes
//! to arrive. A benchmark's clients: they report figures and assert nothing.

use std::fmt;
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::Message;

/// How long a connection may take to deliver its history before the client gives up on it.
const HISTORY_PATIENCE: Duration = Duration::from_secs(30);

/// One connection's history: from the start of the connection to the last `history` message.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fetch {
    /// Connect, handshake, `hello` and every `history` message.
    pub(crate) took: Duration,
    /// Bytes of the `history` messages.
    pub(crate) bytes: usize,
    /// `history` messages.
    pub(crate) messages: usize,
}

/// Every fetch of a run, summarised.
#[derive(Debug, Clone, Default)]
pub(crate) struct Fetches(pub(crate) Vec<Fetch>);

impl Fetches {
    /// One line on `fetches`: how many, how long (p50, p99, max), how large on average.
    fn line(f: &mut fmt::Formatter<'_>, what: &str, fetches: &[Fetch]) -> fmt::Result {
        let mut took: Vec<Duration> = fetches.iter().map(|x| x.took).collect();
        took.sort_unstable();
        let at = |q: f64| took[((took.len() - 1) as f64 * q).round() as usize];
        let ms = |d: Duration| d.as_secs_f64() * 1000.0;
        let bytes: usize = fetches.iter().map(|x| x.bytes).sum();
        let messages: usize = fetches.iter().map(|x| x.messages).sum();
        let n = fetches.len();
        writeln!(
            f,
            "{what}: {n}; connect → history complete p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; \
             {:.0} KB in {:.1} messages each on average",
            ms(at(0.5)),
            ms(at(0.99)),
            ms(at(1.0)),
            bytes as f64 / n as f64 / 1024.0,
            messages as f64 / n as f64
        )
    }
}

impl fmt::Display for Fetches {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return Ok(());
        }
        Self::line(f, "connections with history", &self.0)?;
        // The ring fills over the run: the connections that got (nearly) the longest history.
        let largest = self.0.iter().map(|x| x.bytes).max().unwrap_or(0);
        let full: Vec<Fetch> = self
            .0
            .iter()
            .copied()
            .filter(|x| x.bytes * 10 >= largest * 9)
            .collect();
        Self::line(f, "  of which with the longest history", &full)
    }
}

/// Connects to `url` and reads `hello` and the whole history.
async fn connect(
    url: &str,
) -> Result<
    (
        tokio_tungstenite::WebSocketStream<
            tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
        >,
        Fetch,
    ),
    String,
> {
    let t0 = Instant::now();
    let (mut ws, _) = tokio_tungstenite::connect_async(url)
        .await
        .map_err(|e| format!("connect {url}: {e}"))?;
    let mut fetch = Fetch {
        took: Duration::ZERO,
        bytes: 0,
        messages: 0,
    };
    loop {
        let msg = tokio::time::timeout(HISTORY_PATIENCE, ws.next())
            .await
            .map_err(|_| "no history within 30 s".to_string())?;
        match msg {
            Some(Ok(Message::Text(t))) if t.as_str().starts_with(r#"{"type":"history""#) => {
                fetch.bytes += t.len();
                fetch.messages += 1;
                if t.as_str().ends_with(r#""more":false}"#) {
                    fetch.took = t0.elapsed();
                    return Ok((ws, fetch));
                }
            }
            Some(Ok(_)) => {}
            Some(Err(e)) => return Err(e.to_string()),
            None => return Err("closed before the history was complete".into()),
        }
    }
}

/// A client that connects, reads for `every`, closes and connects again until `stop`; the ticks it read and
/// each connection's history.
pub(crate) async fn reader(
    url: String,
    every: Duration,
    mut stop: watch::Receiver<bool>,
) -> (u64, Vec<Fetch>) {
    let mut ticks = 0;
    let mut fetches = Vec::new();
    while !*stop.borrow() {
        let (mut ws, fetch) = match connect(&url).await {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("bench client: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        fetches.push(fetch);
        let until = tokio::time::Instant::now() + every;
        loop {
            tokio::select! {
                _ = stop.changed() => break,
                _ = tokio::time::sleep_until(until) => break,
                msg = ws.next() => match msg {
                    Some(Ok(Message::Text(t))) => {
                        if t.as_str().starts_with(r#"{"type":"tick""#) {
                            ticks += 1;
                        }
                    }
                    Some(Ok(_)) => {}
                    Some(Err(_)) | None => break,
                },
            }
        }
        let _ = ws.close(None).await;
    }
    (ticks, fetches)
}
