//! [`LinkMonitor`]: the link's state machine. It is told about every valid frame, every lost link and every
//! reopen, is asked once per tick what to do, and answers with at most one [`LinkAction`].
//!
//! ```text
//!            no valid frame for stale_ms                 resync_attempts × resync_wait_ms without a frame
//!   Up ─────────────────────────────────────► Stale ────────────────────────────────────────────► Reconnecting
//!   ▲  ▲   (re-send Start, mode, Stream)        │  (re-send again every resync_wait_ms)   EOF / I/O error │
//!   │  └──────────── a valid frame ─────────────┘                                          ────────────────┤
//!   │                                                         reopen the port; on failure wait the backoff │
//!   └──────────────────────────────── a valid frame ◄──────────────── (doubling up to backoff_max_ms) ────┘
//!   Up ── frame shows Passive while the host asked for Safe/Full ──► Tripped ── operator `rearm` ──► Up
//! ```
//!
//! A trip is the robot's own decision (cliff, wheel drop, charger [C1 p6; C2 p7]): the monitor reports it
//! with its cause and never re-enters Safe by itself; while tripped, a re-sync sends Start and Stream only.
//! Every time is in milliseconds on the caller's clock, which only has to be monotonic.

use crate::oi::SensorValues;
use crate::oi::packets::id;

use super::mode::{ModeQuirk, ModeReader, code};
use super::{LinkState, TripCause};

/// The supervisor's timing, from `[link]` in the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonitorConfig {
    /// No valid frame for longer than this, ms, and the stream is stale (the stream period is 15 ms).
    pub stale_ms: u64,
    /// How long to wait for a frame after re-sending Start and Stream, ms.
    pub resync_wait_ms: u64,
    /// Re-syncs tried before the port is reopened.
    pub resync_attempts: u32,
    /// First wait between reopen attempts, ms; it doubles on each failure.
    pub backoff_initial_ms: u64,
    /// Longest wait between reopen attempts, ms.
    pub backoff_max_ms: u64,
    /// After the host sends a mode command, reported modes are not judged for this long, ms.
    pub mode_grace_ms: u64,
}

impl Default for MonitorConfig {
    fn default() -> Self {
        MonitorConfig {
            stale_ms: 150,
            resync_wait_ms: 500,
            resync_attempts: 2,
            backoff_initial_ms: 250,
            backoff_max_ms: 5000,
            mode_grace_ms: 100,
        }
    }
}

/// What the runtime should do now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkAction {
    /// Re-send Start and Stream, and the commanded mode when `with_mode` (not while tripped).
    Resync {
        /// Whether to send Safe/Full after Start.
        with_mode: bool,
    },
    /// Close the port and open it again; report with [`LinkMonitor::reopened`] or
    /// [`LinkMonitor::reopen_failed`], then send the start-up sequence on the new port.
    Reopen,
    /// Send the commanded mode (the operator re-armed after a trip).
    SendMode,
}

/// The link's state machine.
#[derive(Debug, Clone)]
pub struct LinkMonitor {
    cfg: MonitorConfig,
    commanded: u8,
    modes: ModeReader,
    state: LinkState,
    mode: Option<u8>,
    trip: Option<TripCause>,
    last_frame_ms: u64,
    outage_start_ms: Option<u64>,
    next_try_ms: u64,
    resyncs: u32,
    reopen_attempt: u32,
    reopen_pending: bool,
    grace_until_ms: u64,
    passive_frames: u32,
    counters: MonitorCounters,
}

/// Consecutive frames that must show Passive before a trip is declared: a single frame that slipped past
/// the checksum with a wrong mode byte must not stop the robot until the operator comes.
pub const TRIP_CONFIRM_FRAMES: u32 = 2;

/// The first reopen attempt (counted since the last frame) that starts with a baud rescue; then every
/// other one.
pub const RESCUE_FROM_ATTEMPT: u32 = 2;

/// What the monitor has counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MonitorCounters {
    /// Times the stream went stale.
    pub stale_events: u64,
    /// Successful reopens of the port.
    pub reconnects: u64,
    /// Failed reopen attempts.
    pub reopen_failures: u64,
    /// Trips to Passive seen.
    pub trips: u64,
    /// Outages that ended with frames flowing again.
    pub recoveries: u64,
    /// The last outage's length, from the last good frame before it to the first after it, ms.
    pub last_outage_ms: Option<u64>,
}

impl LinkMonitor {
    /// A monitor for a link whose start-up sequence (asking for `commanded`, Safe or Full) was sent at `now_ms`.
    pub fn new(cfg: MonitorConfig, commanded: u8, quirk: ModeQuirk, now_ms: u64) -> Self {
        LinkMonitor {
            cfg,
            commanded,
            modes: ModeReader::new(quirk),
            state: LinkState::Up,
            mode: None,
            trip: None,
            last_frame_ms: now_ms,
            outage_start_ms: None,
            next_try_ms: 0,
            resyncs: 0,
            reopen_attempt: 0,
            reopen_pending: false,
            grace_until_ms: now_ms + cfg.mode_grace_ms,
            passive_frames: 0,
            counters: MonitorCounters::default(),
        }
    }

    /// The state now.
    pub fn state(&self) -> LinkState {
        self.state
    }

    /// The robot's mode from the newest frame that carried packet 35, corrected for the quirk.
    pub fn mode(&self) -> Option<u8> {
        self.mode
    }

    /// Why the robot tripped, while it stays tripped.
    pub fn trip(&self) -> Option<TripCause> {
        self.trip
    }

    /// The counters.
    pub fn counters(&self) -> MonitorCounters {
        self.counters
    }

    /// Reopens (successful or not) since the last valid frame.
    pub fn reopen_attempt(&self) -> u32 {
        self.reopen_attempt
    }

    /// When the reopen about to run should first try to bring a robot back from another baud rate, the
    /// number of this rescue since the last frame (which rates to try: `oi::handshake::baud_rescue_batch`):
    /// after two reopens that brought no frame, and after every other one from then on.
    pub fn rescue_due(&self) -> Option<u32> {
        let attempt = self.reopen_attempt;
        (attempt >= RESCUE_FROM_ATTEMPT && attempt % 2 == 0)
            .then(|| (attempt - RESCUE_FROM_ATTEMPT) / 2)
    }

    /// True when the firmware's mode-plus-one quirk is being corrected.
    pub fn quirk_active(&self) -> bool {
        self.modes.quirk_active()
    }

    /// A valid frame arrived at `now_ms`.
    pub fn on_frame(&mut self, now_ms: u64, values: &SensorValues) {
        self.last_frame_ms = now_ms;
        if let Some(start) = self.outage_start_ms.take() {
            let length = now_ms.saturating_sub(start);
            self.counters.recoveries += 1;
            self.counters.last_outage_ms = Some(length);
        }
        self.resyncs = 0;
        self.reopen_attempt = 0;
        self.reopen_pending = false;
        if let Some(raw) = values.get(id::OI_MODE) {
            self.mode = self.modes.read(raw, self.commanded);
        }
        let in_grace = now_ms < self.grace_until_ms;
        if self.mode == Some(code::PASSIVE) && !in_grace {
            self.passive_frames = self.passive_frames.saturating_add(1);
        } else {
            self.passive_frames = 0;
        }
        match (self.mode, self.trip) {
            (Some(code::PASSIVE), None) if self.passive_frames >= TRIP_CONFIRM_FRAMES => {
                let cause = trip_cause(values);
                self.trip = Some(cause);
                self.counters.trips += 1;
            }
            (Some(m), Some(_)) if m == self.commanded => self.trip = None,
            _ => {}
        }
        self.state = if self.trip.is_some() {
            LinkState::Tripped
        } else {
            LinkState::Up
        };
    }

    /// The link failed (end of file or an I/O error) at `now_ms`: reopen it as soon as possible.
    pub fn on_link_lost(&mut self, now_ms: u64) {
        if self.state == LinkState::Down {
            return;
        }
        self.begin_outage();
        self.state = LinkState::Reconnecting;
        self.reopen_pending = false;
        self.next_try_ms = now_ms;
    }

    /// The port was reopened at `now_ms` (the caller sends the start-up sequence right after).
    pub fn reopened(&mut self, now_ms: u64) {
        self.counters.reconnects += 1;
        self.reopen_pending = false;
        self.reopen_attempt = self.reopen_attempt.saturating_add(1);
        self.grace_until_ms = now_ms + self.cfg.mode_grace_ms;
        // Wait for a frame; if none comes, reopen again after the longer of the re-sync wait and the backoff.
        self.next_try_ms = now_ms + self.cfg.resync_wait_ms.max(self.backoff_ms());
    }

    /// Reopening failed at `now_ms`: try again after the backoff.
    pub fn reopen_failed(&mut self, now_ms: u64) {
        self.counters.reopen_failures += 1;
        self.reopen_pending = false;
        self.reopen_attempt = self.reopen_attempt.saturating_add(1);
        self.next_try_ms = now_ms + self.backoff_ms();
    }

    /// The link ended for good (shut-down, or it cannot be reopened).
    pub fn close(&mut self) {
        self.state = LinkState::Down;
    }

    /// The operator re-arms after a trip: answer with the mode command to send, if tripped.
    pub fn rearm(&mut self, now_ms: u64) -> Option<LinkAction> {
        self.trip?;
        self.grace_until_ms = now_ms + self.cfg.mode_grace_ms;
        Some(LinkAction::SendMode)
    }

    /// Called once per tick at `now_ms`.
    pub fn on_tick(&mut self, now_ms: u64) -> Option<LinkAction> {
        match self.state {
            LinkState::Down => None,
            LinkState::Up | LinkState::Tripped => {
                if now_ms.saturating_sub(self.last_frame_ms) <= self.cfg.stale_ms {
                    return None;
                }
                self.counters.stale_events += 1;
                self.begin_outage();
                self.state = LinkState::Stale;
                Some(self.resync(now_ms))
            }
            LinkState::Stale => {
                if now_ms < self.next_try_ms {
                    None
                } else if self.resyncs < self.cfg.resync_attempts {
                    Some(self.resync(now_ms))
                } else {
                    self.state = LinkState::Reconnecting;
                    self.reopen_pending = true;
                    Some(LinkAction::Reopen)
                }
            }
            LinkState::Reconnecting => {
                if self.reopen_pending || now_ms < self.next_try_ms {
                    None
                } else {
                    self.reopen_pending = true;
                    Some(LinkAction::Reopen)
                }
            }
        }
    }

    fn resync(&mut self, now_ms: u64) -> LinkAction {
        self.resyncs += 1;
        self.next_try_ms = now_ms + self.cfg.resync_wait_ms;
        self.grace_until_ms = now_ms + self.cfg.mode_grace_ms;
        LinkAction::Resync {
            with_mode: self.trip.is_none(),
        }
    }

    fn begin_outage(&mut self) {
        if self.outage_start_ms.is_none() {
            self.outage_start_ms = Some(self.last_frame_ms);
        }
    }

    fn backoff_ms(&self) -> u64 {
        let doublings = self.reopen_attempt.saturating_sub(1).min(20);
        self.cfg
            .backoff_initial_ms
            .saturating_mul(1u64 << doublings)
            .min(self.cfg.backoff_max_ms)
    }
}

/// The cause of a trip, from the frame that showed Passive: wheel drops (packet 7 bits 2–4), cliffs
/// (packets 9–12), a charging source (packet 34), in that order.
pub fn trip_cause(values: &SensorValues) -> TripCause {
    let wheel_drop = values
        .get(id::BUMPS_WHEEL_DROPS)
        .is_some_and(|b| b & 0b1_1100 != 0);
    let cliff = [
        id::CLIFF_LEFT,
        id::CLIFF_FRONT_LEFT,
        id::CLIFF_FRONT_RIGHT,
        id::CLIFF_RIGHT,
    ]
    .iter()
    .any(|&p| values.get(p).is_some_and(|v| v != 0));
    let charger = values.get(id::CHARGING_SOURCES).is_some_and(|v| v != 0);
    if wheel_drop {
        TripCause::WheelDrop
    } else if cliff {
        TripCause::Cliff
    } else if charger {
        TripCause::Charger
    } else {
        TripCause::Unknown
    }
}

#[cfg(test)]
mod tests;
