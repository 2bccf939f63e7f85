//! The fleet's table: one row per robot, updated from every sample on `pavlov/<robot>/{tick,event,status}`.
//!
//! Anyone on the Zenoh network can publish under `pavlov/…`, so every sample is treated as hostile input:
//! a sample whose key is not `pavlov/<robot>/<leaf>` with a valid robot name, whose payload is larger than
//! [`MAX_SAMPLE_BYTES`], or whose payload does not parse, is counted and dropped; a status whose
//! `dashboard_url` is not an `http://` or `https://` URL keeps its row but loses the link (counted), so the
//! page never links a `javascript:` or other scheme; at most [`MAX_ROBOTS`] robots are kept (further names
//! are counted).

use std::collections::BTreeMap;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::Deserialize;
use serde_json::{Value, json};

/// The most robots the table keeps.
pub const MAX_ROBOTS: usize = 256;

/// The largest sample the table reads: a status is about 1.5 kB, a tick record a few kB (with a Horde's
/// predictions, tens of kB).
pub const MAX_SAMPLE_BYTES: usize = 256 * 1024;

/// Whether `url` may be linked from the page: `http://` or `https://`, at most 2048 bytes, no whitespace
/// or control characters.
fn linkable(url: &str) -> bool {
    let lower = url.get(..8).unwrap_or(url).to_ascii_lowercase();
    (lower.starts_with("http://") || lower.starts_with("https://"))
        && url.len() <= 2048
        && !url.chars().any(|c| c.is_whitespace() || c.is_control())
}

/// Which stream a sample came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Leaf {
    /// `tick`.
    Tick,
    /// `event`.
    Event,
    /// `status`.
    Status,
}

impl Leaf {
    /// The key's last chunk.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Leaf::Tick => "tick",
            Leaf::Event => "event",
            Leaf::Status => "status",
        }
    }
}

/// What the fleet reads of a tick record.
#[derive(Deserialize)]
struct TickHead {
    seq: u64,
    mode: Value,
    #[serde(default)]
    estop: bool,
}

/// One robot's row.
#[derive(Debug, Default)]
struct Row {
    ticks: u64,
    last_seq: Option<u64>,
    mode: Value,
    estop: bool,
    events: u64,
    last_event: Value,
    status: Value,
    last_seen_unix_ms: u64,
}

/// Every robot seen.
#[derive(Debug, Default)]
pub(crate) struct RobotTable {
    rows: BTreeMap<String, Row>,
    /// Samples dropped: a bad key or payload.
    ignored: u64,
    /// Robots not kept because the table was full.
    overflow: u64,
    /// Status messages whose dashboard URL was not linkable (removed).
    bad_urls: u64,
}

fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl RobotTable {
    /// Takes one sample on `key`.
    pub(crate) fn observe(&mut self, key: &str, leaf: Leaf, payload: &[u8]) {
        let mut parts = key.split('/');
        let robot = match (parts.next(), parts.next(), parts.next(), parts.next()) {
            (Some(crate::zenoh_bridge::KEY_ROOT), Some(robot), Some(l), None)
                if l == leaf.name() && pavlov::config::check_robot_name(robot).is_ok() =>
            {
                robot
            }
            _ => {
                self.ignored += 1;
                return;
            }
        };
        if payload.len() > MAX_SAMPLE_BYTES {
            self.ignored += 1;
            return;
        }
        if !self.rows.contains_key(robot) && self.rows.len() >= MAX_ROBOTS {
            self.overflow += 1;
            return;
        }
        let parsed = match leaf {
            Leaf::Tick => {
                serde_json::from_slice::<TickHead>(payload).map(|t| (Some(t), Value::Null))
            }
            _ => serde_json::from_slice::<Value>(payload).map(|v| (None, v)),
        };
        let Ok((tick, mut value)) = parsed else {
            self.ignored += 1;
            return;
        };
        if leaf == Leaf::Status
            && let Some(url) = value.get_mut("dashboard_url")
            && !url.as_str().is_some_and(linkable)
        {
            *url = Value::Null;
            self.bad_urls += 1;
        }
        let row = self.rows.entry(robot.to_string()).or_default();
        row.last_seen_unix_ms = now_ms();
        match (leaf, tick) {
            (Leaf::Tick, Some(t)) => {
                row.ticks += 1;
                row.last_seq = Some(t.seq);
                row.mode = t.mode;
                row.estop = t.estop;
            }
            (Leaf::Event, _) => {
                row.events += 1;
                row.last_event = value;
            }
            (Leaf::Status, _) => row.status = value,
            (Leaf::Tick, None) => {}
        }
    }

    /// The table as `/api/robots` serves it.
    pub(crate) fn to_json(&self) -> Value {
        let now = now_ms();
        let robots: Vec<Value> = self
            .rows
            .iter()
            .map(|(name, r)| {
                json!({
                    "robot": name,
                    "ticks_received": r.ticks,
                    "last_seq": r.last_seq,
                    "mode": r.mode,
                    "estop": r.estop,
                    "events_received": r.events,
                    "last_event": r.last_event,
                    "status": r.status,
                    "last_seen_ms_ago": now.saturating_sub(r.last_seen_unix_ms),
                })
            })
            .collect();
        json!({
            "robots": robots,
            "ignored_samples": self.ignored,
            "robots_not_kept": self.overflow,
            "dashboard_urls_removed": self.bad_urls,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_come_from_valid_keys_and_payloads_only() {
        let mut t = RobotTable::default();
        t.observe(
            "pavlov/a/tick",
            Leaf::Tick,
            br#"{"seq": 7, "mode": "reactive", "estop": false}"#,
        );
        t.observe("pavlov/a/status", Leaf::Status, br#"{"ok": true}"#);
        t.observe("pavlov/b/tick", Leaf::Tick, b"not json");
        t.observe(
            "pavlov/a/b/tick",
            Leaf::Tick,
            br#"{"seq": 1, "mode": "manual"}"#,
        );
        t.observe(
            "other/a/tick",
            Leaf::Tick,
            br#"{"seq": 1, "mode": "manual"}"#,
        );
        let j = t.to_json();
        let robots = j["robots"].as_array().unwrap();
        assert_eq!(robots.len(), 1);
        assert_eq!(robots[0]["robot"], "a");
        assert_eq!(robots[0]["last_seq"], 7);
        assert_eq!(robots[0]["mode"], "reactive");
        assert_eq!(robots[0]["status"]["ok"], true);
        assert_eq!(j["ignored_samples"], 3);
    }

    #[test]
    fn only_http_dashboard_urls_are_kept() {
        let mut t = RobotTable::default();
        for (robot, url) in [
            ("a", "http://10.0.0.5:8080/"),
            ("b", "HTTPS://robot-b.lab/"),
            ("c", "javascript:alert(1)"),
            ("d", "data:text/html,<script>alert(1)</script>"),
            ("e", "http://x y/"),
        ] {
            let status = serde_json::json!({ "ok": true, "dashboard_url": url });
            t.observe(
                &format!("pavlov/{robot}/status"),
                Leaf::Status,
                status.to_string().as_bytes(),
            );
        }
        t.observe("pavlov/f/status", Leaf::Status, br#"{"dashboard_url": 7}"#);
        let j = t.to_json();
        let url = |i: usize| j["robots"][i]["status"]["dashboard_url"].clone();
        assert_eq!(url(0), "http://10.0.0.5:8080/");
        assert_eq!(url(1), "HTTPS://robot-b.lab/");
        for i in 2..6 {
            assert_eq!(url(i), Value::Null, "robot {i}");
        }
        assert_eq!(j["dashboard_urls_removed"], 4);
        assert_eq!(j["robots"].as_array().unwrap().len(), 6);
    }

    #[test]
    fn an_oversized_sample_is_dropped() {
        let mut t = RobotTable::default();
        let huge = format!(r#"{{"pad": "{}"}}"#, "x".repeat(MAX_SAMPLE_BYTES));
        t.observe("pavlov/a/status", Leaf::Status, huge.as_bytes());
        let j = t.to_json();
        assert_eq!(j["robots"].as_array().unwrap().len(), 0);
        assert_eq!(j["ignored_samples"], 1);
    }

    #[test]
    fn the_table_is_bounded() {
        let mut t = RobotTable::default();
        for i in 0..MAX_ROBOTS + 3 {
            t.observe(&format!("pavlov/r{i}/status"), Leaf::Status, b"{}");
        }
        let j = t.to_json();
        assert_eq!(j["robots"].as_array().unwrap().len(), MAX_ROBOTS);
        assert_eq!(j["robots_not_kept"], 3);
    }
}
