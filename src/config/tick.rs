//! `[tick]`: the control clock: its period, which timer drives it in real time, and how long that timer
//! spins before a deadline.
//!
//! The timer is a choice only in real time: under tokio's paused clock (tests, experiments) the shell
//! always uses tokio's interval, so virtual time stays deterministic.

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};

/// Longest allowed spin before a deadline, µs.
pub const MAX_SPIN_US: u32 = 1000;

/// Which timer drives the tick in real time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TickTimer {
    /// A dedicated OS thread sleeping to absolute deadlines (`clock_nanosleep`, `TIMER_ABSTIME`).
    #[default]
    Thread,
    /// tokio's interval (its timer wheel has millisecond granularity).
    Tokio,
}

impl TickTimer {
    /// The name used in the configuration and in reports.
    pub fn name(self) -> &'static str {
        match self {
            TickTimer::Thread => "thread",
            TickTimer::Tokio => "tokio",
        }
    }
}

impl std::fmt::Display for TickTimer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// `[tick]`: the control clock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TickConfig {
    /// Tick period in milliseconds (the paper: 20).
    pub period_ms: u64,
    /// Which timer drives the tick in real time.
    pub timer: TickTimer,
    /// With the thread timer: wake this many µs before each deadline and spin until it (0: no spin).
    pub spin_us: u32,
}

impl Default for TickConfig {
    fn default() -> Self {
        TickConfig {
            period_ms: 20,
            timer: TickTimer::Thread,
            spin_us: 0,
        }
    }
}

impl TickConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1..=1000).contains(&self.period_ms) {
            return Err(invalid("tick.period_ms", "must be between 1 and 1000"));
        }
        // A spin burns a core for its length on every tick: at most half of the period, at most 1 ms.
        let half_period_us = self.period_ms * 500;
        let max = u64::from(MAX_SPIN_US).min(half_period_us);
        if u64::from(self.spin_us) > max {
            return Err(invalid(
                "tick.spin_us",
                format!(
                    "must be between 0 and {max} µs (at most {MAX_SPIN_US} µs and half the {} ms period), got {}",
                    self.period_ms, self.spin_us
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<TickConfig, String> {
        let c: TickConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        c.validate().map_err(|e| e.to_string())?;
        Ok(c)
    }

    #[test]
    fn the_thread_timer_is_the_default_and_both_names_parse() {
        let d = parse("").unwrap();
        assert_eq!(
            (d.period_ms, d.timer, d.spin_us),
            (20, TickTimer::Thread, 0)
        );
        assert_eq!(parse("timer = \"tokio\"").unwrap().timer, TickTimer::Tokio);
        assert_eq!(
            parse("timer = \"thread\"").unwrap().timer,
            TickTimer::Thread
        );
        let e = parse("timer = \"wheel\"").unwrap_err();
        assert!(e.contains("wheel") && e.contains("thread"), "{e}");
    }

    #[test]
    fn the_spin_is_bounded_by_a_millisecond_and_half_the_period() {
        assert_eq!(parse("spin_us = 1000").unwrap().spin_us, 1000);
        let e = parse("spin_us = 1001").unwrap_err();
        assert!(
            e.starts_with("tick.spin_us: must be between 0 and 1000"),
            "{e}"
        );
        let e = parse("period_ms = 1\nspin_us = 501").unwrap_err();
        assert!(
            e.starts_with("tick.spin_us: must be between 0 and 500"),
            "{e}"
        );
        assert_eq!(parse("period_ms = 1\nspin_us = 500").unwrap().spin_us, 500);
    }

    #[test]
    fn the_period_is_checked_first() {
        let e = parse("period_ms = 0").unwrap_err();
        assert!(e.starts_with("tick.period_ms"), "{e}");
    }
}
