//! The operator's e-stop, timed: an operator (with the token) latches the e-stop, waits for its ack,
//! releases it, and does it again, spread over the run. The figure is the time from sending `estop` to
//! receiving its ack with `estop: true`, the path a browser's E-STOP button takes.

use std::fmt;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// How long one command may wait for its reply before the probe counts it as lost.
const REPLY_WAIT: Duration = Duration::from_secs(5);

/// The e-stop latencies of one run.
#[derive(Debug, Clone, Default)]
pub struct EstopLatency {
    /// Send → ack of every acked e-stop, sorted.
    pub(crate) samples: Vec<Duration>,
    /// E-stops tried.
    pub(crate) tried: usize,
    /// Why the operator could not connect, if it could not.
    pub(crate) refused: Option<String>,
}

impl EstopLatency {
    /// The `q` quantile (nearest rank) of the acked latencies.
    pub(crate) fn quantile(&self, q: f64) -> Option<Duration> {
        if self.samples.is_empty() {
            return None;
        }
        let rank = (q * self.samples.len() as f64).ceil() as usize;
        self.samples
            .get(rank.clamp(1, self.samples.len()) - 1)
            .copied()
    }
}

impl fmt::Display for EstopLatency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(why) = &self.refused {
            return write!(f, "the operator could not connect: {why}");
        }
        let ms = |d: Option<Duration>| d.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
        write!(
            f,
            "p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms ({} of {} acked)",
            ms(self.quantile(0.5)),
            ms(self.quantile(0.99)),
            ms(self.samples.last().copied()),
            self.samples.len(),
            self.tried
        )
    }
}

async fn reply(ws: &mut Ws, id: u64) -> Option<Value> {
    loop {
        let msg = ws.next().await?.ok()?;
        let Message::Text(t) = msg else { continue };
        let v: Value = serde_json::from_str(&t).ok()?;
        if (v["type"] == "ack" || v["type"] == "error") && v["id"] == id {
            return Some(v);
        }
    }
}

async fn timed(ws: &mut Ws, cmd: &str, id: u64) -> Option<(Duration, Value)> {
    let t0 = Instant::now();
    ws.send(Message::text(json!({"cmd": cmd, "id": id}).to_string()))
        .await
        .ok()?;
    let v = tokio::time::timeout(REPLY_WAIT, reply(ws, id))
        .await
        .ok()??;
    Some((t0.elapsed(), v))
}

/// Waits `start_after`, connects as an operator with `token`, and latches and releases the e-stop `n`
/// times, `spacing` apart.
pub(crate) async fn probe(
    addr: SocketAddr,
    token: String,
    n: usize,
    start_after: Duration,
    spacing: Duration,
) -> EstopLatency {
    let mut out = EstopLatency::default();
    tokio::time::sleep(start_after).await;
    let connected = async {
        let mut request = format!("ws://{addr}/ws")
            .into_client_request()
            .map_err(|e| e.to_string())?;
        let protocols = HeaderValue::from_str(&format!("pavlov.v1, token.{token}"))
            .map_err(|e| e.to_string())?;
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", protocols);
        tokio_tungstenite::connect_async(request)
            .await
            .map_err(|e| e.to_string())
    };
    let mut ws = match connected.await {
        Ok((ws, _)) => ws,
        Err(e) => {
            out.refused = Some(e);
            return out;
        }
    };
    for i in 0..n as u64 {
        out.tried += 1;
        if let Some((latency, ack)) = timed(&mut ws, "estop", 2 * i).await
            && ack["type"] == "ack"
            && ack["result"]["estop"] == true
        {
            out.samples.push(latency);
        }
        let _ = timed(&mut ws, "release", 2 * i + 1).await;
        tokio::time::sleep(spacing).await;
    }
    out.samples.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_nearest_rank() {
        let l = EstopLatency {
            samples: (1..=20).map(Duration::from_millis).collect(),
            tried: 20,
            refused: None,
        };
        assert_eq!(l.quantile(0.5), Some(Duration::from_millis(10)));
        assert_eq!(l.quantile(0.99), Some(Duration::from_millis(20)));
        assert_eq!(EstopLatency::default().quantile(0.5), None);
        assert!(l.to_string().contains("20 of 20 acked"), "{l}");
    }
}
