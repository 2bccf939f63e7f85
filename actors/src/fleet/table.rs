//! The fleet's table: one row per robot, updated from every sample on `pavlov/<robot>/{tick,event,status}`.
//!
//! A sample whose key is not `pavlov/<robot>/<leaf>` with a valid robot name, or whose payload does not
//! parse, is counted and dropped; at most [`MAX_ROBOTS`] robots are kept (further names are counted).

use std::collections::BTreeMap;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::Deserialize;
use serde_json::{Value, json};

/// The most robots the table keeps.
pub const MAX_ROBOTS: usize = 256;

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
        let Ok((tick, value)) = parsed else {
            self.ignored += 1;
            return;
        };
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
        json!({ "robots": robots, "ignored_samples": self.ignored, "robots_not_kept": self.overflow })
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
