//! `[link]`: how the robot link is supervised: when the stream counts as stale, how often Start and
//! Stream are re-sent, how the port is reopened, and whether the firmware reports the OI mode one too high.

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};
use crate::supervision::mode::ModeQuirk;
use crate::supervision::monitor::MonitorConfig;

/// `[link]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// No valid frame for this long, ms, and the stream is stale: Start and Stream are re-sent (the
    /// stream period is 15 ms; drivers use 100–200 ms, e.g. \[CR\]'s 0.2 s latch).
    pub stale_ms: u64,
    /// How long to wait for a frame after each re-sync, ms (libcreate waits 500 ms).
    pub resync_wait_ms: u64,
    /// Re-syncs before the port is closed and reopened.
    pub resync_attempts: u32,
    /// First wait between reopen attempts, ms; doubles on each failure.
    pub backoff_initial_ms: u64,
    /// Longest wait between reopen attempts, ms.
    pub backoff_max_ms: u64,
    /// `auto`, `on` or `off`: whether packet 35 reads mode + 1 (a Create 2 firmware quirk).
    pub mode_quirk: ModeQuirk,
}

impl Default for LinkConfig {
    fn default() -> Self {
        let m = MonitorConfig::default();
        LinkConfig {
            stale_ms: m.stale_ms,
            resync_wait_ms: m.resync_wait_ms,
            resync_attempts: m.resync_attempts,
            backoff_initial_ms: m.backoff_initial_ms,
            backoff_max_ms: m.backoff_max_ms,
            mode_quirk: ModeQuirk::Auto,
        }
    }
}

impl LinkConfig {
    /// The monitor's timing.
    pub fn monitor(&self) -> MonitorConfig {
        MonitorConfig {
            stale_ms: self.stale_ms,
            resync_wait_ms: self.resync_wait_ms,
            resync_attempts: self.resync_attempts,
            backoff_initial_ms: self.backoff_initial_ms,
            backoff_max_ms: self.backoff_max_ms,
            ..MonitorConfig::default()
        }
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(45..=10_000).contains(&self.stale_ms) {
            return Err(invalid(
                "link.stale_ms",
                "must be between 45 (three stream periods) and 10000",
            ));
        }
        if !(50..=60_000).contains(&self.resync_wait_ms) {
            return Err(invalid(
                "link.resync_wait_ms",
                "must be between 50 and 60000",
            ));
        }
        if self.resync_attempts > 100 {
            return Err(invalid("link.resync_attempts", "must be at most 100"));
        }
        if !(10..=600_000).contains(&self.backoff_initial_ms) {
            return Err(invalid(
                "link.backoff_initial_ms",
                "must be between 10 and 600000",
            ));
        }
        if self.backoff_max_ms < self.backoff_initial_ms || self.backoff_max_ms > 600_000 {
            return Err(invalid(
                "link.backoff_max_ms",
                format!(
                    "must be between backoff_initial_ms ({}) and 600000",
                    self.backoff_initial_ms
                ),
            ));
        }
        Ok(())
    }
}
