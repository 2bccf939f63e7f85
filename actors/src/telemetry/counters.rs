//! The counters the actors keep as they run, shared with whoever reports them (the dashboard, `/metrics`,
//! the log line, the benchmarks) through [`super::Health`]. Each is written by one actor only; readers copy
//! them under a short lock or from a `watch`, never on the tick's critical path.
//!
//! The sets that `/metrics` reports (actuation, the dashboard, Foxglove, Zenoh) are each declared once
//! with [`counter_set!`](crate::bus::counter_set::counter_set): the copy, the atomic struct its writers count
//! in, `since`/`plus` and its Prometheus families all come from one declaration. (The storage failures'
//! set lives with the event log that counts them, `bus/storage_failures.rs`.)

use std::sync::{Arc, Mutex};

use crate::bus::counter_set::counter_set;

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

counter_set! {
    /// Actuation's counters (actuation counts them in its own copy and sends it on a `watch`).
    pub(crate) struct ActuationStats;
    "pavlov_actuation_commands_total" counter "Motor commands written by actuation." {
        /// Commands written.
        pub(crate) commands: u64,
    }
    "pavlov_actuation_pipeline_stalls_total" counter "Stops forced because no fresh decision arrived in time." {
        /// Stops forced because no fresh decision arrived.
        pub(crate) pipeline_stalls: u64,
    }
    "pavlov_actuation_stale_observations_total" counter "Stops forced because the observation was too old." {
        /// Stops forced by a stale observation.
        pub(crate) stale_observations: u64,
    }
    "pavlov_actuation_writer_full_total" counter "Motor commands the serial writer's queue could not take." {
        /// Commands the writer queue could not take.
        pub(crate) writer_full: u64,
    }
}

counter_set! {
    /// Counters of the endpoint, for tests, benchmarks and logs (gathered from the hub, the sessions, the
    /// TCP guard and the Horde feed by `dashboard::app_state::AppState::stats`).
    pub struct DashboardStats;
    "pavlov_ws_clients" gauge "Websocket clients connected now (operators and watchers)." {
        /// Websocket clients connected now (operators and watchers).
        pub clients: usize,
    }
    "pavlov_ws_watchers" gauge "Watch-only websocket clients connected now." {
        /// Watch-only websocket clients connected now.
        pub watchers: usize,
    }
    "pavlov_ws_history_ticks" gauge "Ticks the dashboard keeps to send a newly connected page ([dashboard] history_s)." {
        /// Ticks the dashboard's history holds now.
        pub history_ticks: usize,
    }
    "pavlov_ws_history_bytes" gauge "Bytes the dashboard's history of ticks holds (rows and predictions)." {
        /// Bytes the dashboard's history holds now (its rows and predictions).
        pub history_bytes: usize,
    }
    "pavlov_ws_pending_connections" gauge "TCP connections to the dashboard port that are not (yet) websockets, now." {
        /// TCP connections that are not (yet) websockets, now.
        pub pending: usize,
    }
    "pavlov_ws_connections_total" counter "Websocket connections accepted." {
        /// Websocket connections accepted so far.
        pub(crate) connections: u64,
    }
    "pavlov_ws_handshakes_rejected_total" counter "Websocket handshakes refused (origin, token, wrong-token throttle, no operator or watcher seat)." {
        /// Handshakes refused (origin, token, throttled, no seat).
        pub rejected: u64,
    }
    "pavlov_ws_telemetry_dropped_total" counter "Tick and status messages dropped for clients that did not keep up." {
        /// Telemetry messages dropped for slow clients (all clients).
        pub telemetry_dropped: u64,
    }
    "pavlov_ws_commands_total" counter "Control commands forwarded from websocket clients to the server." {
        /// Commands forwarded to the server.
        pub commands: u64,
    }
    "pavlov_ws_error_replies_total" counter "Error replies sent to websocket clients (rate_limited included)." {
        /// Error replies sent (including `rate_limited`).
        pub errors: u64,
    }
    "pavlov_ws_rate_limited_total" counter "Websocket messages refused with rate_limited and not processed." {
        /// Messages refused with `rate_limited`.
        pub rate_limited: u64,
    }
    "pavlov_ws_tcp_refused_total" counter "TCP connections closed on arrival because their address opened them faster than they were served." {
        /// TCP connections closed on arrival: their address was opening connections faster than they were
        /// served (past `max_pending_per_address`, all younger than `dashboard::pending::GRACE`).
        pub tcp_refused: u64,
    }
    "pavlov_ws_token_failures_total" counter "Websocket handshakes that presented a wrong token." {
        /// Handshakes that presented a wrong token.
        pub token_failures: u64,
    }
    "pavlov_ws_token_throttled_total" counter "Websocket handshakes answered 429 because their address had used up its wrong-token allowance." {
        /// Handshakes answered 429 because their address had no wrong-token allowance left.
        pub token_throttled: u64,
    }
    "pavlov_ws_hub_records_missed_total" counter "Tick records the dashboard hub missed because it fell behind the tick feed." {
        /// Tick records the hub missed.
        pub records_missed: u64,
    }
    "pavlov_ws_horde_values_total" counter "horde_values messages queued for websocket clients watching the Horde." {
        /// `horde_values` messages queued for the clients watching the Horde.
        pub horde_values: u64,
    }
    "pavlov_ws_horde_values_skipped_total" counter "Horde values not sent to a watching client because it had not yet taken the previous message." {
        /// Of the Horde's values a watching client asked for, those not sent because it had not yet taken
        /// the previous message (a slow client gets the newest, never a backlog).
        pub horde_values_skipped: u64,
    }
    "pavlov_ws_closed_total" counter "Connections the server closed: oversize (1009), protocol (1002), invalid_utf8 (1007), refusals_piled (1008: refused messages piled up behind the connection's waiting commands), unread_replies, write_stall, no_upgrade (plain HTTP too long), evicted (a pending connection closed to make room)." by "reason" {
        /// Connections closed with 1009 for an over-size message.
        pub closed_oversize: u64 = "oversize",
        /// Connections closed with 1002 for a websocket protocol violation.
        pub closed_protocol: u64 = "protocol",
        /// Connections closed with 1007 for a text message that is not UTF-8.
        pub closed_invalid_utf8: u64 = "invalid_utf8",
        /// Connections closed with 1008 because their refused messages piled up behind their waiting
        /// commands (`dashboard::waiting`).
        pub closed_refusals_piled: u64 = "refusals_piled",
        /// Connections dropped because their replies piled up unread.
        pub closed_unread: u64 = "unread_replies",
        /// Connections dropped because their socket accepted nothing for `dashboard::session::WRITE_STALL`.
        pub(crate) closed_write_stall: u64 = "write_stall",
        /// Connections closed because they stayed plain HTTP longer than
        /// `dashboard::guard::PRE_UPGRADE_LIMIT`.
        pub closed_no_upgrade: u64 = "no_upgrade",
        /// Pending (not yet websocket) connections closed to make room for a newer one.
        pub closed_evicted: u64 = "evicted",
    }
}

counter_set! {
    /// A copy of [`FoxgloveCounters`] at one moment.
    pub struct FoxgloveFigures;
    /// The Foxglove endpoint's counters (`serve --foxglove`), written by the endpoint and read by
    /// `/metrics`. Every server has one, so the figures read 0 when no Foxglove endpoint runs.
    atomic pub(crate) struct FoxgloveCounters;
    "pavlov_foxglove_clients" gauge "Foxglove clients connected now (serve --foxglove; 0 without it)." {
        /// Foxglove clients connected now (past the token check, handed to the SDK's server).
        pub clients: u64,
    }
    "pavlov_foxglove_connections_total" counter "Foxglove connections accepted and handed to the Foxglove server." {
        /// Connections handed to the SDK's server so far.
        pub connections: u64,
    }
    "pavlov_foxglove_refused_total" counter "Foxglove connections refused: token (missing or wrong, 401), busy (too many open, 503), address (the address has its share of the seats, 503), bad_request (not a websocket request, too large or too slow), write_stall (connected, then closed for taking none of the bytes waiting for it for 10 s)." by "reason" {
        /// Handshakes refused for a missing or wrong token (HTTP 401).
        pub refused_token: u64 = "token",
        /// Connections refused because `foxglove::gate::MAX_CONNECTIONS` were open (HTTP 503).
        pub refused_busy: u64 = "busy",
        /// Connections refused because `foxglove::gate::MAX_PER_ADDRESS` were open from their address (503).
        pub refused_address: u64 = "address",
        /// Clients closed because they read nothing for `foxglove::gate::STALL_LIMIT` while data waited.
        pub evicted_slow: u64 = "write_stall",
        /// Connections closed because their request was not a websocket request, too large, or too slow.
        pub refused_bad_request: u64 = "bad_request",
    }
    "pavlov_foxglove_missed_total" counter "Tick records and events the Foxglove publisher missed because it fell behind (never delays the tick)." by "stream" {
        /// Tick records the publisher missed because it fell behind the tick feed.
        pub ticks_missed: u64 = "ticks",
        /// Events the publisher missed because it fell behind the event log.
        pub events_missed: u64 = "events",
    }
}

counter_set! {
    /// A copy of [`ZenohCounters`] at one moment.
    pub struct ZenohFigures;
    /// The Zenoh bridge's counters (`serve --zenoh`), written by the bridge and read by `/metrics` and the
    /// bridge's status message. Every server has one, so the figures read 0 when no bridge runs.
    atomic pub(crate) struct ZenohCounters;
    // `bench --zenoh` subtracts and adds them.
    arithmetic #[cfg(feature = "zenoh")];
    "pavlov_zenoh_published_total" counter "Messages the Zenoh bridge published (serve --zenoh; 0 without it), by stream." by "stream" {
        /// Tick records published on `pavlov/v1/<robot>/tick`.
        pub ticks_published: u64 = "tick",
        /// Events published on `pavlov/v1/<robot>/event`.
        pub events_published: u64 = "event",
        /// Status messages published on `pavlov/v1/<robot>/status`.
        pub status_published: u64 = "status",
    }
    "pavlov_zenoh_missed_total" counter "Tick records and events the Zenoh publisher lost because it fell behind (its queue drops the oldest; never delays the tick)." by "stream" {
        /// Tick records the publisher lost because it fell behind (its queue dropped the oldest).
        pub ticks_missed: u64 = "tick",
        /// Events the publisher lost because it fell behind.
        pub events_missed: u64 = "event",
    }
    "pavlov_zenoh_put_errors_total" counter "Zenoh puts that failed (session closing, transport error)." {
        /// Puts Zenoh refused (the session closing, a transport error).
        pub put_errors: u64,
    }
    "pavlov_zenoh_oversized_dropped_total" counter "Incoming Zenoh messages dropped by Zenoh's transport before delivery for being larger than transport.link.rx.max_message_size (64 KiB on a robot)." {
        /// Messages Zenoh dropped for their size (read from its log: `telemetry::zenoh_drops`).
        pub oversized_dropped: u64,
    }
    "pavlov_zenoh_queries_total" counter "Zenoh queries answered on pavlov/v1/<robot>/config and pavlov/v1/<robot>/checkpoint." {
        /// Queries answered on `config` and `checkpoint`.
        pub queries: u64,
    }
    "pavlov_zenoh_commands_total" counter "Commands received over Zenoh by outcome: applied, refused_token (missing or wrong token), refused_off ([zenoh] commands = false), refused_invalid (not a command message), failed (the owner refused: busy, rejected, unavailable)." by "outcome" {
        /// Commands applied.
        pub commands_applied: u64 = "applied",
        /// Commands refused: the token missing or wrong.
        pub commands_refused_token: u64 = "refused_token",
        /// Commands refused: commands over Zenoh are off (`[zenoh] commands = false`).
        pub commands_refused_off: u64 = "refused_off",
        /// Commands refused: not a valid command message.
        pub commands_refused_invalid: u64 = "refused_invalid",
        /// Commands the server's owner refused (busy, rejected, unavailable).
        pub commands_failed: u64 = "failed",
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

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering;

    use super::*;
    use crate::telemetry::exposition::Exposition;

    /// The Foxglove set's `/metrics` text, written out by hand: the names, help, types, label values and
    /// their order are the ones `/metrics` had before the set was declared with `counter_set!`.
    #[test]
    fn the_foxglove_set_writes_the_metric_text_it_always_wrote() {
        let c = FoxgloveCounters::default();
        for (counter, n) in [
            (&c.clients, 1),
            (&c.connections, 2),
            (&c.refused_token, 3),
            (&c.refused_busy, 4),
            (&c.refused_address, 5),
            (&c.evicted_slow, 6),
            (&c.refused_bad_request, 7),
            (&c.ticks_missed, 8),
            (&c.events_missed, 9),
        ] {
            counter.fetch_add(n, Ordering::Relaxed);
        }
        let mut e = Exposition::default();
        c.figures().expose(&mut e);
        let expected = "\
# HELP pavlov_foxglove_clients Foxglove clients connected now (serve --foxglove; 0 without it).
# TYPE pavlov_foxglove_clients gauge
pavlov_foxglove_clients 1
# HELP pavlov_foxglove_connections_total Foxglove connections accepted and handed to the Foxglove server.
# TYPE pavlov_foxglove_connections_total counter
pavlov_foxglove_connections_total 2
# HELP pavlov_foxglove_refused_total Foxglove connections refused: token (missing or wrong, 401), \
busy (too many open, 503), address (the address has its share of the seats, 503), bad_request (not a \
websocket request, too large or too slow), write_stall (connected, then closed for taking none of the \
bytes waiting for it for 10 s).
# TYPE pavlov_foxglove_refused_total counter
pavlov_foxglove_refused_total{reason=\"token\"} 3
pavlov_foxglove_refused_total{reason=\"busy\"} 4
pavlov_foxglove_refused_total{reason=\"address\"} 5
pavlov_foxglove_refused_total{reason=\"write_stall\"} 6
pavlov_foxglove_refused_total{reason=\"bad_request\"} 7
# HELP pavlov_foxglove_missed_total Tick records and events the Foxglove publisher missed because it \
fell behind (never delays the tick).
# TYPE pavlov_foxglove_missed_total counter
pavlov_foxglove_missed_total{stream=\"ticks\"} 8
pavlov_foxglove_missed_total{stream=\"events\"} 9
";
        assert_eq!(e.into_text(), expected);
    }
}
