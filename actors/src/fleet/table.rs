//! The fleet's table: one row per robot, updated from every sample on
//! `pavlov/v1/<robot>/{tick,event,status}` and from the robots' liveliness tokens
//! (`pavlov/v1/<robot>/alive`).
//!
//! Anyone on the Zenoh network can publish under `pavlov/…`, so every sample is treated as hostile input:
//! a sample whose key is not `pavlov/v1/<robot>/<leaf>` with a valid robot name, whose payload is larger
//! than [`MAX_SAMPLE_BYTES`], or whose payload does not parse, is counted and dropped; a status whose
//! `dashboard_url` is not an `http://` or `https://` URL keeps its row but loses the link (counted), so the
//! page never links a `javascript:` or other scheme.
//!
//! **Presence.** A robot is *alive* while its liveliness token is (Zenoh withdraws it when the robot's
//! session ends, cleanly or not); when the token goes, its row says *departed* and is dropped
//! [`DEPARTED_KEEP_MS`] later. Names seen only in samples, never with a token, are *unknown*: they live in
//! a pool of their own, at most [`MAX_UNKNOWN`] rows and [`MAX_UNKNOWN_PER_SOURCE`] per source (the Zenoh
//! id in the sample's HLC timestamp, the session that stamped it), each dropped [`UNKNOWN_KEEP_MS`] after
//! its last sample; further unknown names are counted and dropped. Robots with a token have their own
//! [`MAX_ROBOTS`] rows (a new token evicts the longest-departed robot when they are full), so no number
//! of made-up names can hide a robot that holds a token.
//!
//! **Losses.** Each put carries its stream's publication number (`super::super::zenoh_bridge::wire`); a
//! jump in it is samples Zenoh dropped between the robot and the fleet, counted per robot
//! (`samples_lost`).

use std::collections::{BTreeMap, HashMap};

use serde::Deserialize;
use serde_json::{Value, json};

use crate::zenoh_bridge::wire;

/// The most robots with a liveliness token (alive or departed) the table keeps.
pub const MAX_ROBOTS: usize = 256;

/// The most names without a liveliness token the table keeps.
pub const MAX_UNKNOWN: usize = 32;

/// The most names without a liveliness token kept from one source.
pub const MAX_UNKNOWN_PER_SOURCE: usize = 4;

/// How long a departed robot's row stays, ms.
pub const DEPARTED_KEEP_MS: u64 = 30_000;

/// How long an unknown name's row stays after its last sample, ms.
pub const UNKNOWN_KEEP_MS: u64 = 10_000;

/// The largest sample the table reads: a status is about 1.5 kB, a tick record a few kB (with a Horde's
/// predictions, tens of kB). The fleet's session also refuses larger messages before delivery.
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
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
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

/// What the fleet knows of a sample besides its key and payload.
#[derive(Debug, Clone, Default)]
pub(crate) struct Meta {
    /// The sample's HLC timestamp, as text (`<time>/<zenoh id>`).
    pub(crate) timestamp: Option<String>,
    /// Who stamped it: the Zenoh id in the timestamp.
    pub(crate) source: Option<String>,
    /// The publication number in its attachment.
    pub(crate) pub_seq: Option<u64>,
}

/// What the fleet reads of a tick record.
#[derive(Deserialize)]
struct TickHead {
    seq: u64,
    mode: Value,
    #[serde(default)]
    estop: bool,
}

/// Whether a row's robot holds a liveliness token.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Presence {
    /// Its token is declared.
    Alive,
    /// Its token was withdrawn at this time (ms).
    Departed(u64),
    /// Never seen with a token; its samples came from this source.
    Unknown(String),
}

/// One robot's row.
#[derive(Debug)]
struct Row {
    presence: Presence,
    ticks: u64,
    last_seq: Option<u64>,
    mode: Value,
    estop: bool,
    events: u64,
    last_event: Value,
    status: Value,
    last_seen_ms: u64,
    timestamp: Option<String>,
    next_pub: HashMap<Leaf, u64>,
    lost: u64,
}

impl Row {
    fn new(presence: Presence, now: u64) -> Row {
        Row {
            presence,
            ticks: 0,
            last_seq: None,
            mode: Value::Null,
            estop: false,
            events: 0,
            last_event: Value::Null,
            status: Value::Null,
            last_seen_ms: now,
            timestamp: None,
            next_pub: HashMap::new(),
            lost: 0,
        }
    }
}

/// Every robot seen.
#[derive(Debug, Default)]
pub(crate) struct RobotTable {
    rows: BTreeMap<String, Row>,
    /// Samples dropped: a bad key or payload.
    ignored: u64,
    /// Robots with a token not kept because their rows were full.
    overflow: u64,
    /// Samples of names without a token dropped because the unknown pool, or the source's share, was full.
    unknown_refused: u64,
    /// Status messages whose dashboard URL was not linkable (removed).
    bad_urls: u64,
}

/// The source of a sample without a timestamp.
const UNSTAMPED: &str = "unstamped";

impl RobotTable {
    fn count(&self, f: impl Fn(&Presence) -> bool) -> usize {
        self.rows.values().filter(|r| f(&r.presence)).count()
    }

    /// Drops departed rows older than [`DEPARTED_KEEP_MS`] and unknown rows silent for
    /// [`UNKNOWN_KEEP_MS`].
    pub(crate) fn prune(&mut self, now: u64) {
        self.rows.retain(|_, r| match r.presence {
            Presence::Alive => true,
            Presence::Departed(since) => now.saturating_sub(since) < DEPARTED_KEEP_MS,
            Presence::Unknown(_) => now.saturating_sub(r.last_seen_ms) < UNKNOWN_KEEP_MS,
        });
    }

    /// A liveliness token appeared (`alive`) or went on `key`.
    pub(crate) fn presence(&mut self, key: &str, alive: bool, now: u64) {
        self.prune(now);
        let Some(robot) = wire::robot_of(key, Some(wire::ALIVE_LEAF)) else {
            self.ignored += 1;
            return;
        };
        if let Some(row) = self.rows.get_mut(robot) {
            if alive {
                row.presence = Presence::Alive;
                row.last_seen_ms = now;
            } else if row.presence == Presence::Alive {
                row.presence = Presence::Departed(now);
            }
            return;
        }
        if !alive {
            return;
        }
        let known = self.count(|p| !matches!(p, Presence::Unknown(_)));
        if known >= MAX_ROBOTS {
            let oldest = self
                .rows
                .iter()
                .filter_map(|(name, r)| match r.presence {
                    Presence::Departed(since) => Some((since, name.clone())),
                    _ => None,
                })
                .min();
            match oldest {
                Some((_, name)) => {
                    self.rows.remove(&name);
                }
                None => {
                    self.overflow += 1;
                    return;
                }
            }
        }
        self.rows
            .insert(robot.to_string(), Row::new(Presence::Alive, now));
    }

    /// Takes one sample on `key`.
    pub(crate) fn observe(&mut self, key: &str, leaf: Leaf, payload: &[u8], meta: Meta, now: u64) {
        self.prune(now);
        let Some(robot) = wire::robot_of(key, Some(leaf.name())) else {
            self.ignored += 1;
            return;
        };
        if payload.len() > MAX_SAMPLE_BYTES {
            self.ignored += 1;
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
        if !self.rows.contains_key(robot) {
            let source = meta.source.clone().unwrap_or_else(|| UNSTAMPED.into());
            let unknown = self.count(|p| matches!(p, Presence::Unknown(_)));
            let from_source = self.count(|p| *p == Presence::Unknown(source.clone()));
            if unknown >= MAX_UNKNOWN || from_source >= MAX_UNKNOWN_PER_SOURCE {
                self.unknown_refused += 1;
                return;
            }
            self.rows
                .insert(robot.to_string(), Row::new(Presence::Unknown(source), now));
        }
        if leaf == Leaf::Status
            && let Some(url) = value.get_mut("dashboard_url")
            && !url.as_str().is_some_and(linkable)
        {
            *url = Value::Null;
            self.bad_urls += 1;
        }
        let Some(row) = self.rows.get_mut(robot) else {
            return;
        };
        row.last_seen_ms = now;
        if meta.timestamp.is_some() {
            row.timestamp = meta.timestamp;
        }
        if let Some(n) = meta.pub_seq {
            if let Some(&expected) = row.next_pub.get(&leaf)
                && n > expected
            {
                row.lost += n - expected;
            }
            row.next_pub.insert(leaf, n.saturating_add(1));
        }
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

    /// The table as `/api/robots` serves it: robots with a token first (alive, then departed), then
    /// unknown names, each group by name.
    pub(crate) fn to_json(&self, now: u64) -> Value {
        let rank = |p: &Presence| match p {
            Presence::Alive => 0,
            Presence::Departed(_) => 1,
            Presence::Unknown(_) => 2,
        };
        let mut rows: Vec<(&String, &Row)> = self.rows.iter().collect();
        rows.sort_by_key(|(name, r)| (rank(&r.presence), name.as_str()));
        let robots: Vec<Value> = rows
            .into_iter()
            .map(|(name, r)| {
                let (presence, departed_ms_ago, source) = match &r.presence {
                    Presence::Alive => ("alive", None, None),
                    Presence::Departed(since) => {
                        ("departed", Some(now.saturating_sub(*since)), None)
                    }
                    Presence::Unknown(source) => ("unknown", None, Some(source.clone())),
                };
                json!({
                    "robot": name,
                    "presence": presence,
                    "departed_ms_ago": departed_ms_ago,
                    "source": source,
                    "ticks_received": r.ticks,
                    "last_seq": r.last_seq,
                    "mode": r.mode,
                    "estop": r.estop,
                    "events_received": r.events,
                    "last_event": r.last_event,
                    "status": r.status,
                    "last_timestamp": r.timestamp,
                    "samples_lost": r.lost,
                    "last_seen_ms_ago": now.saturating_sub(r.last_seen_ms),
                })
            })
            .collect();
        json!({
            "robots": robots,
            "ignored_samples": self.ignored,
            "robots_not_kept": self.overflow,
            "unknown_names_refused": self.unknown_refused,
            "dashboard_urls_removed": self.bad_urls,
            "limits": {
                "max_robots": MAX_ROBOTS,
                "max_unknown": MAX_UNKNOWN,
                "max_unknown_per_source": MAX_UNKNOWN_PER_SOURCE,
                "departed_keep_ms": DEPARTED_KEEP_MS,
                "unknown_keep_ms": UNKNOWN_KEEP_MS,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(robot: &str, leaf: &str) -> String {
        wire::key(robot, leaf)
    }

    fn from(source: &str) -> Meta {
        Meta {
            source: Some(source.into()),
            ..Meta::default()
        }
    }

    fn names(t: &RobotTable, now: u64) -> Vec<(String, String)> {
        t.to_json(now)["robots"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|r| {
                (
                    r["robot"].as_str().unwrap_or_default().to_string(),
                    r["presence"].as_str().unwrap_or_default().to_string(),
                )
            })
            .collect()
    }

    #[test]
    fn rows_come_from_valid_keys_and_payloads_only() {
        let mut t = RobotTable::default();
        let tick = br#"{"seq": 7, "mode": "reactive", "estop": false}"#;
        t.observe(&k("a", "tick"), Leaf::Tick, tick, Meta::default(), 0);
        t.observe(
            &k("a", "status"),
            Leaf::Status,
            br#"{"ok": true}"#,
            Meta::default(),
            0,
        );
        t.observe(&k("b", "tick"), Leaf::Tick, b"not json", Meta::default(), 0);
        let manual = br#"{"seq": 1, "mode": "manual"}"#;
        t.observe("pavlov/v1/a/b/tick", Leaf::Tick, manual, Meta::default(), 0);
        t.observe("pavlov/a/tick", Leaf::Tick, manual, Meta::default(), 0);
        let j = t.to_json(0);
        let robots = j["robots"].as_array().unwrap();
        assert_eq!(robots.len(), 1);
        assert_eq!(robots[0]["robot"], "a");
        assert_eq!(robots[0]["presence"], "unknown");
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
            t.presence(&k(robot, "alive"), true, 0);
            let status = serde_json::json!({ "ok": true, "dashboard_url": url });
            let payload = status.to_string();
            t.observe(
                &k(robot, "status"),
                Leaf::Status,
                payload.as_bytes(),
                Meta::default(),
                0,
            );
        }
        t.presence(&k("f", "alive"), true, 0);
        t.observe(
            &k("f", "status"),
            Leaf::Status,
            br#"{"dashboard_url": 7}"#,
            Meta::default(),
            0,
        );
        let j = t.to_json(0);
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
        t.observe(
            &k("a", "status"),
            Leaf::Status,
            huge.as_bytes(),
            Meta::default(),
            0,
        );
        let j = t.to_json(0);
        assert_eq!(j["robots"].as_array().unwrap().len(), 0);
        assert_eq!(j["ignored_samples"], 1);
    }

    #[test]
    fn made_up_names_never_crowd_out_a_robot_with_a_token() {
        let mut t = RobotTable::default();
        // 300 names from one flooder, then 300 more each from its own source.
        for i in 0..300 {
            t.observe(
                &k(&format!("fake{i}"), "status"),
                Leaf::Status,
                b"{}",
                from("flood"),
                1,
            );
        }
        for i in 300..600 {
            let source = format!("s{i}");
            t.observe(
                &k(&format!("fake{i}"), "status"),
                Leaf::Status,
                b"{}",
                from(&source),
                1,
            );
        }
        let j = t.to_json(1);
        assert_eq!(j["robots"].as_array().unwrap().len(), MAX_UNKNOWN);
        assert_eq!(j["unknown_names_refused"], 600 - MAX_UNKNOWN as u64);
        let flood = names(&t, 1).len() - (MAX_UNKNOWN - MAX_UNKNOWN_PER_SOURCE);
        assert_eq!(flood, MAX_UNKNOWN_PER_SOURCE, "one source's share");
        // A real robot started afterwards: its token gives it a row, and its samples land there.
        t.presence(&k("real", "alive"), true, 2);
        t.observe(
            &k("real", "tick"),
            Leaf::Tick,
            br#"{"seq": 1, "mode": "manual"}"#,
            from("r"),
            3,
        );
        let rows = names(&t, 3);
        assert_eq!(rows[0], ("real".to_string(), "alive".to_string()));
        assert_eq!(t.to_json(3)["robots"][0]["ticks_received"], 1);
        // Unknown names fade when they stop; the live robot stays.
        t.prune(3 + UNKNOWN_KEEP_MS);
        assert_eq!(
            names(&t, 3 + UNKNOWN_KEEP_MS),
            [("real".into(), "alive".into())]
        );
    }

    #[test]
    fn a_departed_robot_is_dropped_after_the_stated_time() {
        let mut t = RobotTable::default();
        t.presence(&k("a", "alive"), true, 0);
        t.presence(&k("a", "alive"), false, 100);
        assert_eq!(names(&t, 100), [("a".into(), "departed".into())]);
        assert_eq!(t.to_json(600)["robots"][0]["departed_ms_ago"], 500);
        t.prune(100 + DEPARTED_KEEP_MS - 1);
        assert_eq!(names(&t, 0).len(), 1);
        t.prune(100 + DEPARTED_KEEP_MS);
        assert!(names(&t, 0).is_empty());
        // Back before that: alive again, same row.
        t.presence(&k("b", "alive"), true, 0);
        t.presence(&k("b", "alive"), false, 10);
        t.presence(&k("b", "alive"), true, 20);
        assert_eq!(names(&t, 20), [("b".into(), "alive".into())]);
    }

    #[test]
    fn robots_with_tokens_are_bounded_and_evict_the_longest_departed() {
        let mut t = RobotTable::default();
        for i in 0..MAX_ROBOTS {
            t.presence(&k(&format!("r{i}"), "alive"), true, 0);
        }
        t.presence(&k("late", "alive"), true, 1);
        assert_eq!(t.to_json(1)["robots_not_kept"], 1);
        t.presence(&k("r7", "alive"), false, 2);
        t.presence(&k("r9", "alive"), false, 3);
        t.presence(&k("late", "alive"), true, 4);
        let rows = names(&t, 4);
        assert_eq!(rows.len(), MAX_ROBOTS);
        assert!(rows.contains(&("late".into(), "alive".into())));
        assert!(
            !rows.iter().any(|(n, _)| n == "r7"),
            "the longest departed went"
        );
        assert!(rows.contains(&("r9".into(), "departed".into())));
    }

    #[test]
    fn gaps_in_publication_numbers_are_counted_as_lost() {
        let mut t = RobotTable::default();
        t.presence(&k("a", "alive"), true, 0);
        let tick = br#"{"seq": 1, "mode": "manual"}"#;
        for n in [0, 1, 2, 5, 6, 10] {
            let meta = Meta {
                pub_seq: Some(n),
                ..Meta::default()
            };
            t.observe(&k("a", "tick"), Leaf::Tick, tick, meta, 0);
        }
        // The status stream numbers its own puts: no loss there.
        let meta = Meta {
            pub_seq: Some(0),
            ..Meta::default()
        };
        t.observe(&k("a", "status"), Leaf::Status, b"{}", meta, 0);
        assert_eq!(t.to_json(0)["robots"][0]["samples_lost"], 2 + 3);
    }
}
