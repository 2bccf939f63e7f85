//! The counters the actors keep as they run, shared with whoever reports them (the dashboard, `/metrics`,
//! the log line, the benchmarks) through [`super::Health`]. Each is written by one actor only; readers copy
//! them under a short lock or from a `watch`, never on the tick's critical path.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use super::histogram::LatencyHistogram;

/// Tick health shared with the metrics reporter.
#[derive(Default)]
pub(crate) struct TickStats {
    /// Lateness of every fired tick.
    pub(crate) lateness: LatencyHistogram,
    /// Ticks fired.
    pub(crate) fired: u64,
    /// Ticks skipped because the ticker was woken too late.
    pub(crate) skipped: u64,
    /// When sensor ingest, on the async runtime, last took a tick: the tick loop's heartbeat. Not when
    /// the ticker fired: the timer thread keeps firing while the runtime is stuck, and then nothing of the
    /// tick loop runs.
    pub(crate) last_taken: Option<tokio::time::Instant>,
}

/// Shared handle on the tick statistics.
pub(crate) type SharedTickStats = Arc<Mutex<TickStats>>;

/// Counters of the writer.
#[derive(Default)]
pub(crate) struct WriterStats {
    /// Time from the tick's deadline to the motor command written to the OS.
    pub(crate) tick_to_command: LatencyHistogram,
    /// Write errors seen.
    pub(crate) errors: u64,
    /// Bytes written.
    pub(crate) bytes: u64,
    /// Writes abandoned after [`crate::link::writer::WRITE_TIMEOUT`].
    pub(crate) timeouts: u64,
    /// Ports switched to after a reopen.
    pub(crate) replaced: u64,
}

/// Shared handle on the writer's statistics.
pub(crate) type SharedWriterStats = Arc<Mutex<WriterStats>>;

/// Actuation's counters.
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub(crate) struct ActuationStats {
    /// Commands written.
    pub(crate) commands: u64,
    /// Stops forced because no fresh decision arrived.
    pub(crate) pipeline_stalls: u64,
    /// Stops forced by a stale observation.
    pub(crate) stale_observations: u64,
    /// Commands the writer queue could not take.
    pub(crate) writer_full: u64,
}

/// Counters of the endpoint, for tests, benchmarks and logs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DashboardStats {
    /// Websocket clients connected now (operators and watchers).
    pub clients: usize,
    /// Watch-only websocket clients connected now.
    pub watchers: usize,
    /// TCP connections that are not (yet) websockets, now.
    pub pending: usize,
    /// Websocket connections accepted so far.
    pub(crate) connections: u64,
    /// Handshakes refused (origin, token, throttled, no seat).
    pub rejected: u64,
    /// Telemetry messages dropped for slow clients (all clients).
    pub telemetry_dropped: u64,
    /// Commands forwarded to the server.
    pub commands: u64,
    /// Error replies sent (including `rate_limited`).
    pub errors: u64,
    /// Messages refused with `rate_limited`.
    pub rate_limited: u64,
    /// Connections closed with 1009 for an over-size message.
    pub closed_oversize: u64,
    /// Connections closed with 1002 for a websocket protocol violation.
    pub closed_protocol: u64,
    /// Connections closed with 1007 for a text message that is not UTF-8.
    pub closed_invalid_utf8: u64,
    /// Connections dropped because their replies piled up unread.
    pub closed_unread: u64,
    /// Connections dropped because their socket accepted nothing for `dashboard::session::WRITE_STALL`.
    pub(crate) closed_write_stall: u64,
    /// Tick records the hub missed.
    pub records_missed: u64,
    /// Ticks the dashboard's history holds now.
    pub history_ticks: usize,
    /// Bytes the dashboard's history holds now (its rows and predictions).
    pub history_bytes: usize,
    /// TCP connections closed on arrival: their address was opening connections faster than they were
    /// served (past `max_pending_per_address`, all younger than `dashboard::pending::GRACE`).
    pub tcp_refused: u64,
    /// Pending (not yet websocket) connections closed to make room for a newer one.
    pub closed_evicted: u64,
    /// Connections closed because they stayed plain HTTP longer than `dashboard::guard::PRE_UPGRADE_LIMIT`.
    pub closed_no_upgrade: u64,
    /// Handshakes that presented a wrong token.
    pub token_failures: u64,
    /// Handshakes answered 429 because their address had no wrong-token allowance left.
    pub token_throttled: u64,
    /// `horde_values` messages queued for the clients watching the Horde.
    pub horde_values: u64,
    /// Of the Horde's values a watching client asked for, those not sent because it had not yet taken the
    /// previous message (a slow client gets the newest, never a backlog).
    pub horde_values_skipped: u64,
}

/// The Foxglove endpoint's counters (`serve --foxglove`), written by the endpoint and read by `/metrics`.
/// Every server has one, so the figures read 0 when no Foxglove endpoint runs.
#[derive(Debug, Default)]
pub(crate) struct FoxgloveCounters {
    /// Foxglove clients connected now (past the token check, handed to the SDK's server).
    pub(crate) clients: AtomicU64,
    /// Connections handed to the SDK's server so far.
    pub(crate) connections: AtomicU64,
    /// Handshakes refused for a missing or wrong token (HTTP 401).
    pub(crate) refused_token: AtomicU64,
    /// Connections refused because `foxglove::gate::MAX_CONNECTIONS` were open (HTTP 503).
    pub(crate) refused_busy: AtomicU64,
    /// Connections refused because `foxglove::gate::MAX_PER_ADDRESS` were open from their address (503).
    pub(crate) refused_address: AtomicU64,
    /// Connections closed because their request was not a websocket request, too large, or too slow.
    pub(crate) refused_bad_request: AtomicU64,
    /// Clients closed because they read nothing for `foxglove::gate::STALL_LIMIT` while data waited.
    pub(crate) evicted_slow: AtomicU64,
    /// Tick records the publisher missed because it fell behind the tick feed.
    pub(crate) ticks_missed: AtomicU64,
    /// Events the publisher missed because it fell behind the event log.
    pub(crate) events_missed: AtomicU64,
}

/// A copy of [`FoxgloveCounters`] at one moment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct FoxgloveFigures {
    /// Foxglove clients connected now.
    pub clients: u64,
    /// Connections handed to the SDK's server so far.
    pub connections: u64,
    /// Handshakes refused for a missing or wrong token.
    pub refused_token: u64,
    /// Connections refused because too many were open.
    pub refused_busy: u64,
    /// Connections refused because their address had its share of the seats.
    pub refused_address: u64,
    /// Connections closed for a bad, over-size or slow request.
    pub refused_bad_request: u64,
    /// Clients evicted because they stopped reading.
    pub evicted_slow: u64,
    /// Tick records the publisher missed.
    pub ticks_missed: u64,
    /// Events the publisher missed.
    pub events_missed: u64,
}

impl FoxgloveCounters {
    /// The figures now.
    pub(crate) fn figures(&self) -> FoxgloveFigures {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        FoxgloveFigures {
            clients: get(&self.clients),
            connections: get(&self.connections),
            refused_token: get(&self.refused_token),
            refused_busy: get(&self.refused_busy),
            refused_address: get(&self.refused_address),
            refused_bad_request: get(&self.refused_bad_request),
            evicted_slow: get(&self.evicted_slow),
            ticks_missed: get(&self.ticks_missed),
            events_missed: get(&self.events_missed),
        }
    }
}

/// The Zenoh bridge's counters (`serve --zenoh`), written by the bridge and read by `/metrics` and the
/// bridge's status message. Every server has one, so the figures read 0 when no bridge runs.
#[derive(Debug, Default)]
pub(crate) struct ZenohCounters {
    /// Tick records published on `pavlov/<robot>/tick`.
    pub(crate) ticks_published: AtomicU64,
    /// Events published on `pavlov/<robot>/event`.
    pub(crate) events_published: AtomicU64,
    /// Status messages published on `pavlov/<robot>/status`.
    pub(crate) status_published: AtomicU64,
    /// Tick records the publisher lost because it fell behind (its queue dropped the oldest).
    pub(crate) ticks_missed: AtomicU64,
    /// Events the publisher lost because it fell behind.
    pub(crate) events_missed: AtomicU64,
    /// Puts Zenoh refused (the session closing, a transport error).
    pub(crate) put_errors: AtomicU64,
    /// Queries answered on `config` and `checkpoint`.
    pub(crate) queries: AtomicU64,
    /// Commands applied.
    pub(crate) commands_applied: AtomicU64,
    /// Commands refused: the token missing or wrong.
    pub(crate) commands_refused_token: AtomicU64,
    /// Commands refused: commands over Zenoh are off (`[zenoh] commands = false`).
    pub(crate) commands_refused_off: AtomicU64,
    /// Commands refused: not a valid command message.
    pub(crate) commands_refused_invalid: AtomicU64,
    /// Commands the server's owner refused (busy, rejected, unavailable).
    pub(crate) commands_failed: AtomicU64,
}

/// A copy of [`ZenohCounters`] at one moment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ZenohFigures {
    /// Tick records published.
    pub ticks_published: u64,
    /// Events published.
    pub events_published: u64,
    /// Status messages published.
    pub status_published: u64,
    /// Tick records lost by the publisher.
    pub ticks_missed: u64,
    /// Events lost by the publisher.
    pub events_missed: u64,
    /// Puts Zenoh refused.
    pub put_errors: u64,
    /// Queries answered.
    pub queries: u64,
    /// Commands applied.
    pub commands_applied: u64,
    /// Commands refused for the token.
    pub commands_refused_token: u64,
    /// Commands refused because commands are off.
    pub commands_refused_off: u64,
    /// Commands refused as invalid.
    pub commands_refused_invalid: u64,
    /// Commands the owner refused.
    pub commands_failed: u64,
}

/// Figures are counts since the server started, so two can be subtracted (what happened between them)
/// and added (two runs as one); `bench --zenoh` does both.
#[cfg(feature = "zenoh")]
impl ZenohFigures {
    /// Each count combined with the same count of `other` by `f`.
    fn zip_with(self, other: ZenohFigures, f: impl Fn(u64, u64) -> u64) -> ZenohFigures {
        ZenohFigures {
            ticks_published: f(self.ticks_published, other.ticks_published),
            events_published: f(self.events_published, other.events_published),
            status_published: f(self.status_published, other.status_published),
            ticks_missed: f(self.ticks_missed, other.ticks_missed),
            events_missed: f(self.events_missed, other.events_missed),
            put_errors: f(self.put_errors, other.put_errors),
            queries: f(self.queries, other.queries),
            commands_applied: f(self.commands_applied, other.commands_applied),
            commands_refused_token: f(self.commands_refused_token, other.commands_refused_token),
            commands_refused_off: f(self.commands_refused_off, other.commands_refused_off),
            commands_refused_invalid: f(
                self.commands_refused_invalid,
                other.commands_refused_invalid,
            ),
            commands_failed: f(self.commands_failed, other.commands_failed),
        }
    }

    /// What was counted after `earlier`, a copy of the same counters.
    pub(crate) fn since(self, earlier: ZenohFigures) -> ZenohFigures {
        self.zip_with(earlier, u64::saturating_sub)
    }

    /// The counts of both.
    pub(crate) fn plus(self, other: ZenohFigures) -> ZenohFigures {
        self.zip_with(other, u64::saturating_add)
    }
}

impl ZenohCounters {
    /// The figures now.
    pub(crate) fn figures(&self) -> ZenohFigures {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        ZenohFigures {
            ticks_published: get(&self.ticks_published),
            events_published: get(&self.events_published),
            status_published: get(&self.status_published),
            ticks_missed: get(&self.ticks_missed),
            events_missed: get(&self.events_missed),
            put_errors: get(&self.put_errors),
            queries: get(&self.queries),
            commands_applied: get(&self.commands_applied),
            commands_refused_token: get(&self.commands_refused_token),
            commands_refused_off: get(&self.commands_refused_off),
            commands_refused_invalid: get(&self.commands_refused_invalid),
            commands_failed: get(&self.commands_failed),
        }
    }
}

#[cfg(all(test, feature = "zenoh"))]
mod zenoh_figures_tests {
    use super::*;

    #[test]
    fn figures_subtract_and_add_count_by_count() {
        let earlier = ZenohFigures {
            ticks_published: 10,
            put_errors: 1,
            commands_failed: 2,
            ..ZenohFigures::default()
        };
        let later = ZenohFigures {
            ticks_published: 35,
            put_errors: 1,
            commands_failed: 5,
            queries: 4,
            ..ZenohFigures::default()
        };
        let between = later.since(earlier);
        assert_eq!(between.ticks_published, 25);
        assert_eq!(between.put_errors, 0);
        assert_eq!(between.commands_failed, 3);
        assert_eq!(between.queries, 4);
        assert_eq!(between.plus(earlier), later);
        assert_eq!(earlier.since(later).ticks_published, 0);
    }
}
