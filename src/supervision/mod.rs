//! Link supervision: what the host knows about the robot link, and the pure state machine that decides
//! when the link is stale, when to re-send Start and Stream, when to reopen the port, and when the robot
//! has tripped out of Safe mode on its own.
//!
//! - [`LinkState`]: up, stale, reconnecting, tripped to Passive, or down for good.
//! - [`TripCause`]: why the robot left Safe for Passive, read from the frame that showed the trip.
//! - [`mode`]: reading the OI mode (packet 35), including the firmware's mode-plus-one quirk.
//! - [`monitor`]: [`monitor::LinkMonitor`], the state machine that turns frames and ticks into actions.
//!
//! The runtime (actors/) calls into this once per received frame and once per tick; nothing here reads a
//! clock or a socket.

pub mod mode;
pub mod monitor;

use serde::{Deserialize, Serialize};

/// The robot link as the host sees it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkState {
    /// Valid frames arrive and the robot is in the mode the host asked for.
    #[default]
    Up,
    /// No valid frame for longer than the stale limit; Start and Stream have been re-sent.
    Stale,
    /// The port is being closed and reopened (with backoff) until frames come back.
    Reconnecting,
    /// Frames arrive but the robot left Safe for Passive by itself (cliff, wheel drop, charger): the host
    /// reports it and waits for the operator; it never re-enters Safe on its own.
    Tripped,
    /// The link ended and will not be reopened (shut-down, or no way to reopen it).
    Down,
}

impl LinkState {
    /// The lower-case name used in the protocol and in metrics.
    pub fn name(self) -> &'static str {
        match self {
            LinkState::Up => "up",
            LinkState::Stale => "stale",
            LinkState::Reconnecting => "reconnecting",
            LinkState::Tripped => "tripped",
            LinkState::Down => "down",
        }
    }

    /// Every state, in a fixed order (for metrics).
    pub const ALL: [LinkState; 5] = [
        LinkState::Up,
        LinkState::Stale,
        LinkState::Reconnecting,
        LinkState::Tripped,
        LinkState::Down,
    ];
}

/// Why the robot tripped from Safe to Passive [C1 p6; C2 p7].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TripCause {
    /// A wheel dropped (packet 7 bits 2–4).
    WheelDrop,
    /// A cliff sensor fired (packets 9–12).
    Cliff,
    /// A charging source is present (packet 34).
    Charger,
    /// Passive with none of the above visible (e.g. a button, or the condition cleared before the frame).
    Unknown,
}

impl TripCause {
    /// A short human-readable phrase.
    pub fn describe(self) -> &'static str {
        match self {
            TripCause::WheelDrop => "wheel drop",
            TripCause::Cliff => "cliff",
            TripCause::Charger => "charger",
            TripCause::Unknown => "unknown cause",
        }
    }
}
