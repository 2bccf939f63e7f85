//! The Horde on the websocket, for the clients that ask (`horde_watch`, see `web/PROTOCOL.md`): the
//! predictions' names once, then their values at the client's rate.
//!
//! The Horde publishes every value ten times a second ([`HordeView::values`]); a watching session samples
//! that at its own rate (at most [`MAX_HZ`] a second) and sends a window of at most [`MAX_VALUES`] of them
//! as one `horde_values` message: each value rounded to a bfloat16 (the top 16 bits of its `f32`: 8
//! significant bits, 0.4 % relative precision, the full `f32` range, NaN kept), little-endian, base64. 10⁴
//! values are 26,668 characters of base64 and about 26.9 kB a message, 54 kB/s at the default 2 Hz and
//! 269 kB/s at 10 Hz.
//!
//! Bounds: the encoding of one Horde publication is shared by every session that asks for the same window
//! (one encoding per publication, not per client); a session holds at most one Horde message in its queue
//! (the queue's slot, [`super::out_queue`]): when its client is slower than its rate the newest values
//! wait and the older ones are skipped (counted), and the ticks are never pushed out by them. The names
//! (up to 10⁵ of them) are serialised once for the run, in messages of at most [`NAMES_MESSAGE_BYTES`],
//! and sent to a connection once, on its first `horde_watch`; a later `horde_watch` only changes the rate
//! or the window.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use axum::extract::ws::Utf8Bytes;
use serde::Serialize;
use tokio::sync::watch;

use super::out_queue::OutQueue;
use crate::horde::status::HordeStatus;
use crate::horde::{HordeValues, HordeView};

/// The most values one `horde_values` message carries (≈ 44 kB).
pub(crate) const MAX_VALUES: usize = 16_384;
/// The highest rate a client may ask for, messages a second (the Horde publishes ten a second).
pub(crate) const MAX_HZ: f64 = 10.0;
/// The lowest rate.
pub(crate) const MIN_HZ: f64 = 0.1;
/// The rate when the client names none.
pub(crate) const DEFAULT_HZ: f64 = 2.0;
/// The largest `horde_names` message, bytes (about).
pub(crate) const NAMES_MESSAGE_BYTES: usize = 32 * 1024;
/// How the values are encoded, as the message says.
pub(crate) const ENCODING: &str = "bf16le-base64";

/// Counters of the Horde's websocket traffic, all sessions together.
#[derive(Debug, Default)]
pub(crate) struct HordeFeedCounters {
    /// `horde_values` messages queued for clients.
    pub(crate) frames_sent: AtomicU64,
    /// Samples not sent because the client had not yet taken the previous message.
    pub(crate) frames_skipped: AtomicU64,
    /// Encodings made (at most one per publication and window).
    pub(crate) encodings: AtomicU64,
}

struct Cached {
    seq: u64,
    from: usize,
    count: usize,
    text: Utf8Bytes,
}

/// The Horde as the dashboard serves it (one for the endpoint, shared by the sessions).
pub(crate) struct HordeFeed {
    names: Arc<Vec<String>>,
    values: watch::Receiver<Arc<HordeValues>>,
    status: watch::Receiver<HordeStatus>,
    name_messages: OnceLock<Arc<Vec<Utf8Bytes>>>,
    cache: Mutex<Option<Cached>>,
    pub(crate) counters: HordeFeedCounters,
}

/// What one session watches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HordeWindow {
    /// The first prediction sent.
    pub(crate) from: usize,
    /// How many.
    pub(crate) count: usize,
    /// Messages a second.
    pub(crate) hz: f64,
}

#[derive(Serialize)]
struct ValuesMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    seq: u64,
    total: usize,
    from: usize,
    count: usize,
    encoding: &'static str,
    values: &'a str,
    horde: HordeFigures,
}

#[derive(Serialize)]
struct HordeFigures {
    ticks_learned: u64,
    skipped_busy: u64,
    chain_breaks: u64,
    stopped: u64,
    step_p50_us: u64,
    step_p99_us: u64,
}

impl From<&HordeStatus> for HordeFigures {
    fn from(s: &HordeStatus) -> Self {
        HordeFigures {
            ticks_learned: s.ticks_learned,
            skipped_busy: s.skipped_busy,
            chain_breaks: s.chain_breaks,
            stopped: s.stopped,
            step_p50_us: s.step.p50_us,
            step_p99_us: s.step.p99_us,
        }
    }
}

#[derive(Serialize)]
struct NamesMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    total: usize,
    from: usize,
    names: &'a [String],
}

impl HordeFeed {
    /// The feed of `view`.
    pub(crate) fn new(view: &HordeView) -> Self {
        HordeFeed {
            names: view.names.clone(),
            values: view.values.clone(),
            status: view.status.clone(),
            name_messages: OnceLock::new(),
            cache: Mutex::new(None),
            counters: HordeFeedCounters::default(),
        }
    }

    /// How many predictions.
    pub(crate) fn len(&self) -> usize {
        self.names.len()
    }

    /// The `horde_names` messages (made on first use, then shared).
    pub(crate) fn name_messages(&self) -> Arc<Vec<Utf8Bytes>> {
        self.name_messages
            .get_or_init(|| {
                Arc::new(
                    names_messages(&self.names, NAMES_MESSAGE_BYTES)
                        .into_iter()
                        .map(Utf8Bytes::from)
                        .collect(),
                )
            })
            .clone()
    }

    /// The sequence number of the newest values.
    fn newest_seq(&self) -> u64 {
        self.values.borrow().seq
    }

    /// The `horde_values` message of the newest values for `from..from + count` (`None` before the Horde
    /// published them all), made once per publication and window.
    fn frame(&self, from: usize, count: usize) -> Option<(u64, Utf8Bytes)> {
        let values = self.values.borrow().clone();
        let mut cache = match self.cache.lock() {
            Ok(g) => g,
            Err(poisoned) => poisoned.into_inner(),
        };
        if let Some(c) = cache.as_ref()
            && c.seq == values.seq
            && c.from == from
            && c.count == count
        {
            return Some((c.seq, c.text.clone()));
        }
        let status = self.status.borrow().clone();
        let text = Utf8Bytes::from(values_message(
            &values,
            self.names.len(),
            from,
            count,
            &status,
        )?);
        self.counters.encodings.fetch_add(1, Ordering::Relaxed);
        *cache = Some(Cached {
            seq: values.seq,
            from,
            count,
            text: text.clone(),
        });
        Some((values.seq, text))
    }
}

/// Streams `window` of `feed` into `queue`'s slot (the names first when `send_names`) until the queue
/// closes. `wrap` makes a queue item of a message.
pub(crate) async fn stream<T>(
    feed: Arc<HordeFeed>,
    queue: Arc<OutQueue<T>>,
    window: HordeWindow,
    send_names: bool,
    wrap: fn(Utf8Bytes) -> T,
) {
    if send_names {
        for m in feed.name_messages().iter() {
            if !queue.put_slot_waiting(wrap(m.clone())).await {
                return;
            }
        }
    }
    let mut every = tokio::time::interval(Duration::from_secs_f64(1.0 / window.hz));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut last_sent = None;
    loop {
        every.tick().await;
        if queue.is_closed() {
            return;
        }
        if last_sent == Some(feed.newest_seq()) {
            continue;
        }
        let Some((seq, text)) = feed.frame(window.from, window.count) else {
            continue;
        };
        match queue.try_put_slot(wrap(text)) {
            Ok(()) => {
                last_sent = Some(seq);
                feed.counters.frames_sent.fetch_add(1, Ordering::Relaxed);
            }
            Err(_) => {
                feed.counters.frames_skipped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// The `horde_values` message for `values[from..from + count]`, or `None` when the values do not reach.
pub(crate) fn values_message(
    values: &HordeValues,
    total: usize,
    from: usize,
    count: usize,
    status: &HordeStatus,
) -> Option<String> {
    let window = values.values.get(from..from.checked_add(count)?)?;
    let mut bytes = Vec::with_capacity(window.len() * 2);
    for &v in window {
        bytes.extend_from_slice(&bf16_bits(v).to_le_bytes());
    }
    let encoded = base64(&bytes);
    serde_json::to_string(&ValuesMessage {
        kind: "horde_values",
        seq: values.seq,
        total,
        from,
        count,
        encoding: ENCODING,
        values: &encoded,
        horde: status.into(),
    })
    .ok()
}

/// The `horde_names` messages: every name in order, cut so each message is about `max_bytes` at most.
pub(crate) fn names_messages(names: &[String], max_bytes: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut start = 0;
    while start < names.len() {
        // JSON text of a name: the name, quotes, a comma, and room for escapes of odd characters.
        let mut end = start;
        let mut size = 64;
        while end < names.len() {
            let add = names[end].len() * 2 + 3;
            if end > start && size + add > max_bytes {
                break;
            }
            size += add;
            end += 1;
        }
        let text = serde_json::to_string(&NamesMessage {
            kind: "horde_names",
            total: names.len(),
            from: start,
            names: &names[start..end],
        })
        .unwrap_or_default();
        out.push(text);
        start = end;
    }
    out
}

/// A bfloat16's bits: the `f32` rounded to nearest (ties to even) at 8 significant bits; NaN stays NaN.
pub(crate) fn bf16_bits(x: f32) -> u16 {
    let bits = x.to_bits();
    if x.is_nan() {
        return ((bits >> 16) as u16) | 0x0040;
    }
    let rounded = bits.wrapping_add(0x7FFF + ((bits >> 16) & 1));
    (rounded >> 16) as u16
}

const BASE64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 with padding (RFC 4648, section 4).
pub(crate) fn base64(bytes: &[u8]) -> String {
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            if i <= chunk.len() {
                out.push(char::from(BASE64[((n >> shift) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_the_rfc_vectors() {
        for (input, want) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(input.as_bytes()), want);
        }
    }

    #[test]
    fn bfloat16_keeps_eight_significant_bits_rounded_to_nearest() {
        assert_eq!(bf16_bits(1.0), 0x3F80);
        assert_eq!(bf16_bits(-2.0), 0xC000);
        assert_eq!(bf16_bits(0.0), 0);
        // 1 + 2⁻⁸ is a tie: to even (1.0); 1 + 3·2⁻⁸ rounds up to 1 + 2⁻⁶.
        assert_eq!(bf16_bits(1.0 + 1.0 / 256.0), 0x3F80);
        assert_eq!(bf16_bits(1.0 + 3.0 / 256.0), 0x3F82);
        assert_eq!(bf16_bits(f32::INFINITY), 0x7F80);
        assert!(f32::from_bits(u32::from(bf16_bits(f32::NAN)) << 16).is_nan());
        // Relative error at most 2⁻⁸ (8 significant bits) over a wide range.
        for x in [0.3f32, 123.456, 1e-20, 3e30, -7.77] {
            let back = f32::from_bits(u32::from(bf16_bits(x)) << 16);
            assert!(((back - x) / x).abs() <= 1.0 / 256.0, "{x} -> {back}");
        }
    }

    #[test]
    fn a_values_message_carries_its_window_and_refuses_one_the_values_do_not_reach() {
        let values = HordeValues {
            seq: 42,
            values: vec![1.0, -2.0, 0.5, 4.0],
        };
        let status = HordeStatus::default();
        let text = values_message(&values, 4, 1, 2, &status).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["type"], "horde_values");
        assert_eq!(v["seq"], 42);
        assert_eq!(
            (v["from"].as_u64(), v["count"].as_u64()),
            (Some(1), Some(2))
        );
        assert_eq!(v["encoding"], ENCODING);
        // −2.0 = 0xC000, 0.5 = 0x3F00, little-endian: 00 C0 00 3F.
        assert_eq!(v["values"], base64(&[0x00, 0xC0, 0x00, 0x3F]));
        assert!(values_message(&values, 4, 3, 2, &status).is_none());
        assert!(values_message(&values, 4, usize::MAX, 2, &status).is_none());
    }

    #[test]
    fn names_are_cut_into_bounded_messages_that_cover_every_name_once() {
        let names: Vec<String> = (0..10_000)
            .map(|i| format!("nexting/obs/dimension_{i}@tau=50"))
            .collect();
        let messages = names_messages(&names, NAMES_MESSAGE_BYTES);
        assert!(messages.len() > 5, "{}", messages.len());
        let mut seen = Vec::new();
        for m in &messages {
            assert!(m.len() <= NAMES_MESSAGE_BYTES, "{}", m.len());
            let v: serde_json::Value = serde_json::from_str(m).unwrap();
            assert_eq!(v["total"], 10_000);
            assert_eq!(v["from"].as_u64().unwrap() as usize, seen.len());
            for n in v["names"].as_array().unwrap() {
                seen.push(n.as_str().unwrap().to_string());
            }
        }
        assert_eq!(seen, names);
        assert!(names_messages(&[], NAMES_MESSAGE_BYTES).is_empty());
    }
}
