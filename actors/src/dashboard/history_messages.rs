//! The `event` and `history` messages of the dashboard protocol (`web/PROTOCOL.md`).
//!
//! An event goes to every client as `{"type":"event","t":…,"id":…,"after":…,"kind":…, …}`, `t` being the
//! time of the first tick it applies to. A watcher's copy names no file: the paths of saves and recordings
//! are [`REDACTED`], as in its `hello`.
//!
//! A history is sent as a series of `{"type":"history","fields":[…],"rows":[…],"events":[…],"more":…}`
//! messages, each at most [`HISTORY_MESSAGE_BYTES`] (or the configured `max_message_bytes`, if smaller)
//! unless a single row is larger: the rows oldest first, then the events, the last message saying
//! `"more":false`. [`HistoryMessages`] makes them one at a time, when the client's writer is ready for the
//! next, so a long history costs one message of memory and never holds up anything else.

use std::borrow::Cow;

use pavlov::event::Event;
use serde::Serialize;
use serde::ser::{SerializeSeq, Serializer};

use super::history::{
    FLAG_ELBOW, FLAG_ESTOP, FLAG_GATE, FLAG_OC_LEFT, FLAG_OC_RIGHT, FLAG_STIMULUS, Snapshot,
    TickRow,
};

/// What a watcher sees of a file path.
pub(crate) use pavlov::config::REDACTED;

/// The largest `history` message, bytes (smaller when `max_message_bytes` is). Small, because the
/// websocket library keeps the memory of the largest message a connection sent for as long as it is
/// open (`super::socket_buffers`): 8 KiB of it a client rather than 32.
pub(crate) const HISTORY_MESSAGE_BYTES: usize = 8 * 1024;

/// The entries of a history row, in order (`hello` and every `history` message name them).
pub(crate) const HISTORY_FIELDS: [&str; 17] = [
    "seq",
    "t",
    "mode",
    "stimulus",
    "gate",
    "estop",
    "safety_stop",
    "overcurrent_left",
    "overcurrent_right",
    "battery_current_ma",
    "command_left",
    "command_right",
    "default_left",
    "default_right",
    "link",
    "predictions",
    "elbow",
];

#[derive(Serialize)]
struct EventMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    t: f64,
    #[serde(flatten)]
    event: &'a Event,
}

/// The time of the first tick `event` applies to, seconds since the start.
pub(crate) fn event_time_s(event: &Event, period_ms: u64) -> f64 {
    event.after.map_or(0, |a| a + 1) as f64 * period_ms as f64 / 1000.0
}

/// `text` with every occurrence of `path` redacted.
fn without(text: &str, path: &str) -> String {
    if path.is_empty() {
        text.to_string()
    } else {
        text.replace(path, REDACTED)
    }
}

/// `event` as a watcher may see it: without file paths.
pub(crate) fn for_watcher(event: &Event) -> Cow<'_, Event> {
    // Which text is private is the kind's to say (`EventKind::private_text_mut`, an exhaustive match).
    let mut kind = event.kind.clone();
    let Some((path, message)) = kind.private_text_mut() else {
        return Cow::Borrowed(event);
    };
    let path = std::mem::replace(path, REDACTED.to_string());
    if let Some(message) = message {
        *message = without(message, &path);
    }
    Cow::Owned(Event {
        kind,
        ..event.clone()
    })
}

/// The `event` message for a client (`watcher`: paths redacted).
pub(crate) fn event_json(event: &Event, period_ms: u64, watcher: bool) -> String {
    let event = if watcher {
        for_watcher(event)
    } else {
        Cow::Borrowed(event)
    };
    let message = EventMessage {
        kind: "event",
        t: event_time_s(&event, period_ms),
        event: &event,
    };
    serde_json::to_string(&message).unwrap_or_default()
}

/// A history row: `[seq, t, mode, stimulus, gate, estop, safety_stop, oc_left, oc_right, current,
/// command_left, command_right, default_left, default_right, link, [[value, threshold], …], elbow]`, flags
/// as 0/1; `elbow` is `[left, left_avg, right, right_avg]` (degrees, `null` when invalid) on a tick that
/// carried elbow angles, else `null`.
struct RowJson<'a> {
    row: &'a TickRow,
    predictions: &'a [f64],
}

impl Serialize for RowJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let r = self.row;
        let bit = |flag: u8| u8::from(r.has(flag));
        let mut seq = s.serialize_seq(Some(HISTORY_FIELDS.len()))?;
        seq.serialize_element(&r.seq)?;
        seq.serialize_element(&(r.t_ms / 1000.0))?;
        seq.serialize_element(&r.mode)?;
        seq.serialize_element(&bit(FLAG_STIMULUS))?;
        seq.serialize_element(&bit(FLAG_GATE))?;
        seq.serialize_element(&bit(FLAG_ESTOP))?;
        seq.serialize_element(&r.safety_stop)?;
        seq.serialize_element(&bit(FLAG_OC_LEFT))?;
        seq.serialize_element(&bit(FLAG_OC_RIGHT))?;
        seq.serialize_element(&r.battery_current_ma)?;
        seq.serialize_element(&r.command[0])?;
        seq.serialize_element(&r.command[1])?;
        seq.serialize_element(&r.default[0])?;
        seq.serialize_element(&r.default[1])?;
        seq.serialize_element(&r.link)?;
        let pairs: Vec<&[f64]> = self.predictions.chunks(2).collect();
        seq.serialize_element(&pairs)?;
        let elbow = r
            .has(FLAG_ELBOW)
            .then(|| r.elbow.map(|v| (!v.is_nan()).then_some(v)));
        seq.serialize_element(&elbow)?;
        seq.end()
    }
}

/// The `history` messages of one snapshot, made one at a time.
pub(crate) struct HistoryMessages {
    snapshot: Snapshot,
    limit: usize,
    period_ms: u64,
    watcher: bool,
    /// The next row: chunk, then row within it.
    chunk: usize,
    row: usize,
    next_event: usize,
    done: bool,
}

/// The end of a message at its longest.
const TAIL: &str = r#"],"events":[],"more":false}"#;

impl HistoryMessages {
    /// The messages of `snapshot`, each at most `limit` bytes (unless one row alone is larger), for a
    /// watcher or an operator.
    pub(crate) fn new(snapshot: Snapshot, limit: usize, period_ms: u64, watcher: bool) -> Self {
        HistoryMessages {
            snapshot,
            limit,
            period_ms,
            watcher,
            chunk: 0,
            row: 0,
            next_event: 0,
            done: false,
        }
    }

    /// The next row inside the window, without taking it.
    fn peek_row(&mut self) -> Option<(&TickRow, &[f64])> {
        let width = 2 * self.snapshot.n_predictions;
        loop {
            let chunk = self.snapshot.chunks.get(self.chunk)?;
            match chunk.rows.get(self.row) {
                None => {
                    self.chunk += 1;
                    self.row = 0;
                }
                Some(r) if r.seq < self.snapshot.first_seq => self.row += 1,
                Some(r) => {
                    let i = self.row * width;
                    let preds = chunk.predictions.get(i..i + width).unwrap_or(&[]);
                    return Some((r, preds));
                }
            }
        }
    }

    /// Appends `item` after `count` items when it fits in the limit (or is the message's first).
    fn fits(&self, out: &[u8], item: &[u8], count: usize) -> bool {
        count == 0 || out.len() + 1 + item.len() + TAIL.len() <= self.limit
    }
}

impl Iterator for HistoryMessages {
    type Item = String;

    fn next(&mut self) -> Option<String> {
        if self.done {
            return None;
        }
        let mut out = Vec::with_capacity(self.limit.min(HISTORY_MESSAGE_BYTES) + 256);
        out.extend_from_slice(br#"{"type":"history","fields":"#);
        let _ = serde_json::to_writer(&mut out, &HISTORY_FIELDS);
        out.extend_from_slice(br#","rows":["#);
        let mut count = 0;
        let mut item = Vec::with_capacity(256);
        while let Some((row, predictions)) = self.peek_row() {
            item.clear();
            let _ = serde_json::to_writer(&mut item, &RowJson { row, predictions });
            if !self.fits(&out, &item, count) {
                break;
            }
            if count > 0 {
                out.push(b',');
            }
            out.extend_from_slice(&item);
            count += 1;
            self.row += 1;
        }
        out.extend_from_slice(br#"],"events":["#);
        let rows_done = self.peek_row().is_none();
        if rows_done {
            let mut in_message = 0;
            while let Some(event) = self.snapshot.events.get(self.next_event) {
                let text = event_json(event, self.period_ms, self.watcher);
                if !self.fits(&out, text.as_bytes(), count) {
                    break;
                }
                if in_message > 0 {
                    out.push(b',');
                }
                out.extend_from_slice(text.as_bytes());
                count += 1;
                in_message += 1;
                self.next_event += 1;
            }
        }
        let more = !rows_done || self.next_event < self.snapshot.events.len();
        out.extend_from_slice(if more {
            br#"],"more":true}"#
        } else {
            br#"],"more":false}"#
        });
        self.done = !more;
        // Only JSON went in.
        Some(String::from_utf8(out).unwrap_or_default())
    }
}

#[cfg(test)]
mod tests {
    use super::super::history::{History, Params};
    use super::*;
    use pavlov::control::Mode;
    use pavlov::event::EventKind;
    use pavlov::record::{ElbowAngles, PredictionValue, TickRecord};
    use serde_json::{Value, json};
    use std::sync::Arc;

    fn history(ticks: u64, events: u64) -> History {
        let params = vec![Params {
            prediction: "stall".into(),
            alpha: 0.01,
            lambda: 0.9,
            threshold: 0.5,
        }];
        let h = History::new(3600, 20, Mode::Pavlovian, params);
        for seq in 0..ticks {
            let mut r = TickRecord {
                predictions: vec![PredictionValue {
                    name: "stall".into(),
                    value: 0.25,
                    threshold: 0.5,
                }],
                stimulus: seq == 3,
                ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
            };
            r.sensors.battery_current_ma = Some(-300 - seq as i32);
            h.push(&r);
        }
        for id in 1..=events {
            h.on_event(&Arc::new(Event {
                id,
                after: Some(id),
                kind: EventKind::RecordingStarted {
                    path: format!("recordings/r{id}/ticks.jsonl"),
                },
            }));
        }
        h
    }

    fn all(h: &History, limit: usize, watcher: bool) -> Vec<Value> {
        HistoryMessages::new(h.snapshot(), limit, 20, watcher)
            .map(|m| {
                assert!(m.len() <= limit, "{} > {limit}", m.len());
                serde_json::from_str(&m).unwrap()
            })
            .collect()
    }

    #[test]
    fn a_long_history_comes_in_messages_within_the_limit_rows_then_events() {
        let h = history(3000, 40);
        let messages = all(&h, 4096, false);
        assert!(messages.len() > 10, "{}", messages.len());
        let rows: Vec<&Value> = messages
            .iter()
            .flat_map(|m| m["rows"].as_array().unwrap())
            .collect();
        let seqs: Vec<u64> = rows.iter().map(|r| r[0].as_u64().unwrap()).collect();
        assert_eq!(seqs, (0..3000).collect::<Vec<_>>());
        assert_eq!(
            *rows[3],
            json!([
                3,
                0.06,
                "pavlovian",
                1,
                0,
                0,
                null,
                0,
                0,
                -303,
                0,
                0,
                0,
                0,
                "up",
                [[0.25, 0.5]],
                null
            ])
        );
        let events: Vec<&Value> = messages
            .iter()
            .flat_map(|m| m["events"].as_array().unwrap())
            .collect();
        assert_eq!(events.len(), 40);
        assert_eq!(events[0]["type"], "event");
        assert_eq!(events[0]["kind"], "recording_started");
        assert_eq!(events[0]["t"], 0.04);
        assert_eq!(events[0]["path"], "recordings/r1/ticks.jsonl");
        let more: Vec<bool> = messages
            .iter()
            .map(|m| m["more"].as_bool().unwrap())
            .collect();
        assert!(more[..more.len() - 1].iter().all(|&m| m) && !more[more.len() - 1]);
        assert_eq!(messages[0]["fields"], json!(HISTORY_FIELDS));
    }

    #[test]
    fn a_row_carries_the_elbow_angles_of_its_tick_and_null_for_an_invalid_one() {
        let h = History::new(60, 20, Mode::Pavlovian, vec![]);
        h.push(&TickRecord {
            elbow: Some(ElbowAngles {
                left: Some(85.5),
                left_avg: Some(120.0),
                right: None,
                right_avg: Some(170.25),
                ..ElbowAngles::default()
            }),
            ..TickRecord::at_rest(0, 0.0, Mode::Pavlovian)
        });
        h.push(&TickRecord::at_rest(1, 20.0, Mode::Pavlovian));
        let messages = all(&h, 4096, false);
        let rows = messages[0]["rows"].as_array().unwrap();
        let at = HISTORY_FIELDS.iter().position(|f| *f == "elbow").unwrap();
        assert_eq!(rows[0][at], json!([85.5, 120.0, null, 170.25]));
        assert_eq!(rows[1][at], Value::Null);
    }

    #[test]
    fn an_empty_history_is_one_message_and_a_watcher_sees_no_paths() {
        let empty = all(&history(0, 0), 1024, false);
        assert_eq!(
            empty,
            [json!({"type":"history","fields":HISTORY_FIELDS,"rows":[],"events":[],"more":false})]
        );
        let watched = all(&history(5, 2), 1024, true);
        let text = serde_json::to_string(&watched).unwrap();
        assert!(!text.contains("recordings/"), "{text}");
        assert!(text.contains(REDACTED), "{text}");
    }

    #[test]
    fn an_event_message_says_when_it_applies() {
        let e = Event {
            id: 7,
            after: Some(99),
            kind: EventKind::ParamsSet {
                prediction: "stall".into(),
                alpha: 0.01,
                lambda: 0.5,
                threshold: 0.4,
            },
        };
        let v: Value = serde_json::from_str(&event_json(&e, 20, true)).unwrap();
        assert_eq!(
            v,
            json!({"type":"event","t":2.0,"id":7,"after":99,"kind":"params_set","prediction":"stall",
                   "alpha":0.01,"lambda":0.5,"threshold":0.4})
        );
        let first = Event {
            id: 1,
            after: None,
            kind: EventKind::WeightsReset,
        };
        assert_eq!(event_time_s(&first, 20), 0.0);
    }
}
