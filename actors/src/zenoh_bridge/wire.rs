//! The wire's conventions in one place: the versioned key space, the encoding every put and reply
//! declares, the publication sequence number carried as an attachment, and the settings every session
//! this program opens gets on top of the user's Zenoh file (HLC timestamps, a receive size limit).
//!
//! - Keys are `pavlov/v1/<robot>/<leaf>`: `v1` is the wire format's version, raised when a payload or key
//!   changes incompatibly, so an old and a new robot can share a network and a client subscribes to the
//!   version it reads.
//! - Every put and reply, error replies included, is JSON and says so (`application/json`), except the
//!   checkpoint file, which is sent as its bytes (`application/json` too: checkpoints are JSON files).
//! - Each put on `tick`, `event` and `status` carries an attachment: the stream's publication sequence
//!   number, 8 bytes little-endian, counting from 0 at the bridge's start. A subscriber that sees it jump
//!   lost samples between the robot and itself (Zenoh dropped them under congestion); the record's own
//!   `seq` jumping while the attachment does not is a tick the robot skipped.
//! - [`harden`] turns on Zenoh's hybrid logical clock (`timestamping.enabled`, off by default in peer
//!   mode) and caps `transport.link.rx.max_message_size`, the largest message Zenoh reassembles from
//!   fragments: a larger one is dropped by Zenoh's transport before anything of it is delivered.

use std::sync::atomic::{AtomicU64, Ordering};

/// The wire format's version, the second chunk of every key.
pub const WIRE_VERSION: &str = "v1";

/// The root of every key: `pavlov/v1`.
pub const KEY_ROOT: &str = "pavlov/v1";

/// The last chunk of the liveliness token each robot declares: `pavlov/v1/<robot>/alive`.
pub const ALIVE_LEAF: &str = "alive";

/// The largest message a robot's session reassembles, bytes. A command is at most 4 KiB; Zenoh does not
/// fragment a message that fits one batch (64 KiB), so this limit cuts at one batch in practice.
pub const ROBOT_MAX_MESSAGE_BYTES: usize = 64 * 1024;

/// The key `pavlov/v1/<robot>/<leaf>`.
pub fn key(robot: &str, leaf: &str) -> String {
    format!("{KEY_ROOT}/{robot}/{leaf}")
}

/// The robot named by `key` if it is `pavlov/v1/<robot>/<leaf>` (any leaf when `leaf` is `None`) with a
/// valid robot name.
pub fn robot_of<'k>(key: &'k str, leaf: Option<&str>) -> Option<&'k str> {
    let rest = key.strip_prefix(KEY_ROOT)?.strip_prefix('/')?;
    let (robot, last) = rest.split_once('/')?;
    let leaf_ok = match leaf {
        Some(l) => last == l,
        None => !last.contains('/'),
    };
    (leaf_ok && pavlov::config::check_robot_name(robot).is_ok()).then_some(robot)
}

/// The encoding every put and reply declares.
pub fn json_encoding() -> zenoh::bytes::Encoding {
    zenoh::bytes::Encoding::APPLICATION_JSON
}

/// The attachment of publication number `n`: 8 bytes, little-endian.
pub fn seq_attachment(n: u64) -> Vec<u8> {
    n.to_le_bytes().to_vec()
}

/// The publication number in an attachment, if it is one.
pub fn seq_of(attachment: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(attachment.try_into().ok()?))
}

/// A stream's publication counter.
#[derive(Debug, Default)]
pub(crate) struct SeqCounter(AtomicU64);

impl SeqCounter {
    /// The next number.
    pub(crate) fn next(&self) -> u64 {
        self.0.fetch_add(1, Ordering::Relaxed)
    }
}

/// Sets what every session of this program needs on top of the user's file: HLC timestamps on, and at
/// most `max_message_bytes` reassembled per message. A smaller limit in the file is kept.
pub fn harden(config: &mut zenoh::Config, max_message_bytes: usize) -> Result<(), String> {
    config
        .insert_json5("timestamping/enabled", "true")
        .map_err(|e| format!("timestamping/enabled: {e}"))?;
    let path = "transport/link/rx/max_message_size";
    let current = config
        .get_json(path)
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or(usize::MAX);
    let limit = current.min(max_message_bytes);
    config
        .insert_json5(path, &limit.to_string())
        .map_err(|e| format!("{path}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_versioned_and_parsed_back() {
        assert_eq!(key("alpha", "tick"), "pavlov/v1/alpha/tick");
        assert_eq!(
            robot_of("pavlov/v1/alpha/tick", Some("tick")),
            Some("alpha")
        );
        assert_eq!(robot_of("pavlov/v1/alpha/alive", None), Some("alpha"));
        assert_eq!(robot_of("pavlov/v1/alpha/tick", Some("status")), None);
        assert_eq!(robot_of("pavlov/alpha/tick", Some("tick")), None);
        assert_eq!(robot_of("pavlov/v2/alpha/tick", Some("tick")), None);
        assert_eq!(robot_of("pavlov/v1/a/b/tick", Some("tick")), None);
        assert_eq!(robot_of("pavlov/v1/a.b/tick", Some("tick")), None);
    }

    #[test]
    fn a_sequence_attachment_round_trips() {
        assert_eq!(seq_of(&seq_attachment(0)), Some(0));
        assert_eq!(seq_of(&seq_attachment(u64::MAX - 3)), Some(u64::MAX - 3));
        assert_eq!(seq_of(b"short"), None);
    }

    #[test]
    fn hardening_turns_timestamps_on_and_never_raises_the_limit() {
        let mut c = zenoh::Config::default();
        harden(&mut c, 4096).expect("harden");
        assert_eq!(c.get_json("timestamping/enabled").expect("ts"), "true");
        assert_eq!(
            c.get_json("transport/link/rx/max_message_size")
                .expect("limit"),
            "4096"
        );
        let mut small = zenoh::Config::from_json5(
            "{ transport: { link: { rx: { max_message_size: 1000 } } } }",
        )
        .expect("config");
        harden(&mut small, 4096).expect("harden");
        assert_eq!(
            small
                .get_json("transport/link/rx/max_message_size")
                .expect("limit"),
            "1000"
        );
    }
}
