//! `/metrics`: the server's figures in the Prometheus text exposition format, version 0.0.4.
//!
//! [`render`] is a pure function of a [`MetricsSnapshot`] (tick timing, the robot link as the newest tick
//! record saw it, the websocket endpoint's counters, the recorder's queue and actuation's safety counters),
//! so the format is tested without a server; [`crate::dashboard::http`] takes the snapshot and serves the text with
//! [`CONTENT_TYPE`]. Every metric is listed in the book's dashboard chapter (`docs/src/dashboard.md`).

use pavlov::config::TickTimer;
use pavlov::record::LinkStatus;
use pavlov::supervision::{LinkState, TripCause};

use super::counters::{ActuationStats, DashboardStats, FoxgloveFigures, ZenohFigures};
use super::exposition::Exposition;
pub(crate) use super::exposition::HistogramSample;
use super::horde_status::HordeStatus;
use super::{Health, RecorderFigures};
use crate::bus::storage_failures::StorageFigures;

/// The Content-Type of the exposition.
pub(crate) const CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

/// Upper bounds of the tick histograms' buckets, µs (the `le` labels are these in seconds).
pub(crate) const TICK_BUCKETS_US: [u64; 13] = [
    50, 100, 250, 500, 1_000, 2_500, 5_000, 10_000, 20_000, 50_000, 100_000, 250_000, 1_000_000,
];

/// Everything `/metrics` reports, read at one moment.
#[derive(Debug, Clone, Default)]
pub(crate) struct MetricsSnapshot {
    /// The timer that drives the tick.
    pub(crate) timer: TickTimer,
    /// Ticks fired since start.
    pub(crate) ticks_fired: u64,
    /// Ticks skipped because the ticker woke too late.
    pub(crate) ticks_skipped: u64,
    /// Tick lateness (fired − deadline).
    pub(crate) tick_lateness: HistogramSample,
    /// Tick deadline → motor command written.
    pub(crate) tick_to_command: HistogramSample,
    /// Serial write errors.
    pub(crate) write_errors: u64,
    /// The link as the newest tick record saw it (`None` before the first tick).
    pub(crate) link: Option<LinkStatus>,
    /// The websocket endpoint's counters.
    pub(crate) ws: DashboardStats,
    /// The recorder's queue (`None` without a recorder).
    pub(crate) recorder: Option<RecorderFigures>,
    /// Actuation's safety counters.
    pub(crate) actuation: ActuationStats,
    /// Seconds since the newest tick fired (`None` before the first).
    pub(crate) tick_age_seconds: Option<f64>,
    /// 1 while the tick loop runs and the link is up (what `/healthz` answers 200 for).
    pub(crate) healthy: bool,
    /// What the simulated robot's fault injector has done (`None` on a real robot).
    pub(crate) sim_faults: Option<pavlov::sim::faults::FaultCounters>,
    /// The Foxglove endpoint's counters (zero without one).
    pub(crate) foxglove: FoxgloveFigures,
    /// The Zenoh bridge's counters (zero without one).
    pub(crate) zenoh: ZenohFigures,
    /// The Horde's figures (`None` without `[horde]`).
    pub(crate) horde: Option<HordeStatus>,
    /// Failures to write recordings and checkpoints.
    pub(crate) storage: StorageFigures,
}

impl MetricsSnapshot {
    /// Reads everything from the server's `health` and the endpoint's counters `ws`.
    pub(crate) fn read(health: &Health, ws: DashboardStats) -> Self {
        let f = health.figures();
        let (lateness, to_command) = health.histograms();
        MetricsSnapshot {
            timer: health.timer,
            ticks_fired: f.ticks_fired,
            ticks_skipped: f.ticks_skipped,
            tick_lateness: HistogramSample::from_histogram(&lateness, &TICK_BUCKETS_US),
            tick_to_command: HistogramSample::from_histogram(&to_command, &TICK_BUCKETS_US),
            write_errors: f.write_errors,
            link: f.link,
            ws,
            recorder: f.recorder,
            actuation: f.actuation,
            sim_faults: health.sim.as_ref().map(|s| s.borrow().faults.clone()),
            tick_age_seconds: health.tick_age().map(|d| d.as_secs_f64()),
            healthy: health.verdict() == super::Verdict::Ok,
            foxglove: health.foxglove.figures(),
            zenoh: health.zenoh.figures(),
            horde: health.horde.as_ref().map(|h| h.borrow().clone()),
            storage: health.storage.figures(),
        }
    }
}

/// The name of a trip cause in the `cause` label.
fn cause_name(cause: TripCause) -> &'static str {
    match cause {
        TripCause::WheelDrop => "wheel_drop",
        TripCause::Cliff => "cliff",
        TripCause::Charger => "charger",
        TripCause::Unknown => "unknown",
    }
}

const TRIP_CAUSES: [TripCause; 4] = [
    TripCause::WheelDrop,
    TripCause::Cliff,
    TripCause::Charger,
    TripCause::Unknown,
];

fn link_metrics(e: &mut Exposition, link: &LinkStatus) {
    e.gauge(
        "pavlov_link_up",
        "1 while the robot link is open, 0 once it has failed or closed.",
        f64::from(u8::from(link.up)),
    );
    e.family(
        "pavlov_link_state",
        "gauge",
        "The supervisor's view of the robot link: 1 for the current state, 0 for the others.",
    );
    for state in LinkState::ALL {
        e.sample(
            "pavlov_link_state",
            &[("state", state.name())],
            f64::from(u8::from(state == link.state)),
        );
    }
    e.family(
        "pavlov_link_tripped",
        "gauge",
        "1 for the cause while the robot has tripped from Safe to Passive by itself, else 0.",
    );
    for cause in TRIP_CAUSES {
        e.sample(
            "pavlov_link_tripped",
            &[("cause", cause_name(cause))],
            f64::from(u8::from(link.trip == Some(cause))),
        );
    }
    if let Some(mode) = link.mode {
        e.gauge(
            "pavlov_oi_mode",
            "The robot's Open Interface mode from packet 35: 0 off, 1 passive, 2 safe, 3 full.",
            f64::from(mode),
        );
    }
    let counters: [(&str, &str, u64); 5] = [
        (
            "pavlov_link_good_frames_total",
            "Sensor stream frames that passed every check.",
            link.good_frames,
        ),
        (
            "pavlov_link_bad_frames_total",
            "Candidate sensor frames rejected (length, packet ids or checksum).",
            link.bad_frames,
        ),
        (
            "pavlov_link_skipped_bytes_total",
            "Bytes skipped while searching for a sensor frame.",
            link.skipped_bytes,
        ),
        (
            "pavlov_link_reconnects_total",
            "Times the serial port was reopened.",
            link.reconnects,
        ),
        (
            "pavlov_link_stale_events_total",
            "Times the sensor stream went stale.",
            link.stale_events,
        ),
    ];
    for (name, help, value) in counters {
        e.counter(name, help, value);
    }
}

fn horde_metrics(e: &mut Exposition, h: &HordeStatus) {
    e.gauge(
        "pavlov_horde_predictions",
        "Predictions the Horde learns ([horde]).",
        h.predictions as f64,
    );
    e.counter(
        "pavlov_horde_ticks_learned_total",
        "Ticks the Horde learned from.",
        h.ticks_learned,
    );
    e.counter(
        "pavlov_horde_skipped_total",
        "Ticks the Horde did not learn from because it was still busy with earlier ones (never delays the tick).",
        h.skipped_busy,
    );
    e.counter(
        "pavlov_horde_chain_breaks_total",
        "Times the Horde's chain of ticks broke (a skipped or stale tick) and its traces were cleared.",
        h.chain_breaks,
    );
    for (suffix, us, what) in [
        ("p50", h.step.p50_us, "median"),
        ("p99", h.step.p99_us, "99th percentile"),
        ("max", h.step.max_us, "longest"),
    ] {
        e.gauge(
            &format!("pavlov_horde_step_{suffix}_seconds"),
            &format!("The {what} time of one Horde step (every prediction, then every update)."),
            us as f64 * 1e-6,
        );
    }
    e.counter(
        "pavlov_horde_checkpoints_written_total",
        "Horde checkpoints written.",
        h.checkpoints_written,
    );
    e.counter(
        "pavlov_horde_checkpoint_errors_total",
        "Horde checkpoints refused or failed.",
        h.checkpoint_errors,
    );
}

/// The exposition text of `s`.
pub(crate) fn render(s: &MetricsSnapshot) -> String {
    let mut e = Exposition::default();
    e.histogram(
        "pavlov_tick_lateness_seconds",
        "How late each tick fired after its deadline.",
        &s.tick_lateness,
    );
    e.counter("pavlov_ticks_fired_total", "Ticks fired.", s.ticks_fired);
    e.family(
        "pavlov_tick_timer",
        "gauge",
        "The timer that drives the tick: 1 for the one in use (thread: the timer thread; tokio: tokio's interval).",
    );
    for timer in [TickTimer::Thread, TickTimer::Tokio] {
        e.sample(
            "pavlov_tick_timer",
            &[("timer", timer.name())],
            f64::from(u8::from(timer == s.timer)),
        );
    }
    if let Some(age) = s.tick_age_seconds {
        e.gauge(
            "pavlov_tick_age_seconds",
            "Seconds since the tick loop last took a tick on the async runtime (grows when it stalls).",
            age,
        );
    }
    e.gauge(
        "pavlov_healthy",
        "1 while the tick loop runs and the robot link is up (what /healthz answers 200 for), else 0.",
        f64::from(u8::from(s.healthy)),
    );
    e.counter(
        "pavlov_ticks_skipped_total",
        "Ticks skipped because the ticker woke too late.",
        s.ticks_skipped,
    );
    e.histogram(
        "pavlov_tick_to_command_seconds",
        "Time from a tick's deadline to its motor command written to the serial port.",
        &s.tick_to_command,
    );
    e.counter(
        "pavlov_serial_write_errors_total",
        "Serial write errors.",
        s.write_errors,
    );
    if let Some(link) = &s.link {
        link_metrics(&mut e, link);
    }
    s.ws.expose(&mut e);
    s.foxglove.expose(&mut e);
    s.zenoh.expose(&mut e);
    if let Some(h) = &s.horde {
        horde_metrics(&mut e, h);
    }
    if let Some(r) = s.recorder {
        e.gauge(
            "pavlov_recorder_backlog",
            "Tick records queued for the recorder and not yet written.",
            r.backlog as f64,
        );
        e.counter(
            "pavlov_recorder_dropped_total",
            "Tick records the recorder dropped because its queue was full.",
            r.dropped,
        );
    }
    s.storage.expose(&mut e);
    s.actuation.expose(&mut e);
    if let Some(faults) = &s.sim_faults
        && let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(faults)
    {
        let name = "pavlov_sim_faults_total";
        e.family(
            name,
            "counter",
            "What the simulated Create's fault injector has done (--faults), by kind: bytes for *_bytes and \
             host_*, events otherwise.",
        );
        for (kind, value) in fields {
            if let Some(v) = value.as_u64() {
                e.sample(name, &[("kind", &kind)], v as f64);
            }
        }
    }
    e.into_text()
}

#[cfg(test)]
mod tests {
    use super::super::prometheus_check::{Family, parse};
    use super::*;
    use crate::telemetry::histogram::LatencyHistogram;
    use std::time::Duration;

    fn histogram(us: &[u64]) -> LatencyHistogram {
        let mut h = LatencyHistogram::new();
        for &u in us {
            h.record(Duration::from_micros(u));
        }
        h
    }

    fn snapshot() -> MetricsSnapshot {
        MetricsSnapshot {
            zenoh: ZenohFigures {
                ticks_published: 11,
                ticks_missed: 2,
                commands_refused_token: 3,
                ..ZenohFigures::default()
            },
            timer: TickTimer::Tokio,
            ticks_fired: 1000,
            ticks_skipped: 3,
            tick_lateness: HistogramSample::from_histogram(
                &histogram(&[10, 40, 120, 900, 3000, 70_000_000]),
                &TICK_BUCKETS_US,
            ),
            tick_to_command: HistogramSample::from_histogram(
                &histogram(&[300, 400, 2000]),
                &TICK_BUCKETS_US,
            ),
            write_errors: 1,
            link: Some(LinkStatus {
                up: true,
                good_frames: 990,
                bad_frames: 2,
                skipped_bytes: 17,
                state: LinkState::Tripped,
                mode: Some(1),
                trip: Some(TripCause::Cliff),
                reconnects: 4,
                stale_events: 5,
            }),
            ws: DashboardStats {
                clients: 2,
                connections: 9,
                rejected: 7,
                watchers: 1,
                pending: 5,
                rate_limited: 11,
                closed_oversize: 1,
                tcp_refused: 6,
                closed_evicted: 4,
                closed_invalid_utf8: 2,
                token_failures: 8,
                token_throttled: 3,
                ..DashboardStats::default()
            },
            recorder: Some(RecorderFigures {
                backlog: 12,
                dropped: 0,
            }),
            actuation: ActuationStats {
                commands: 990,
                pipeline_stalls: 6,
                ..ActuationStats::default()
            },
            tick_age_seconds: Some(0.004),
            healthy: false,
            sim_faults: Some(pavlov::sim::faults::FaultCounters {
                hangs: 3,
                flipped_bytes: 8,
                ..Default::default()
            }),
            foxglove: FoxgloveFigures {
                clients: 3,
                refused_token: 2,
                ticks_missed: 5,
                ..FoxgloveFigures::default()
            },
            horde: Some(HordeStatus {
                predictions: 11_748,
                ticks_learned: 2900,
                skipped_busy: 4,
                chain_breaks: 5,
                ..HordeStatus::default()
            }),
            storage: StorageFigures {
                recordings: 2,
                checkpoints: 3,
            },
        }
    }

    #[test]
    fn every_family_is_valid_and_carries_its_figures() {
        let text = render(&snapshot());
        let families = parse(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
        let value = |name: &str, labels: &[(&str, &str)]| {
            families
                .values()
                .flat_map(|f: &Family| f.samples.iter())
                .find(|s| {
                    s.name == name
                        && labels
                            .iter()
                            .all(|(k, v)| s.labels.get(*k).map(String::as_str) == Some(*v))
                })
                .map(|s| s.value)
                .unwrap_or_else(|| panic!("no {name} {labels:?} in\n{text}"))
        };
        assert_eq!(value("pavlov_ticks_fired_total", &[]), 1000.0);
        assert_eq!(value("pavlov_tick_timer", &[("timer", "tokio")]), 1.0);
        assert_eq!(value("pavlov_tick_timer", &[("timer", "thread")]), 0.0);
        assert_eq!(value("pavlov_ticks_skipped_total", &[]), 3.0);
        assert_eq!(
            value("pavlov_zenoh_published_total", &[("stream", "tick")]),
            11.0
        );
        assert_eq!(
            value("pavlov_zenoh_missed_total", &[("stream", "tick")]),
            2.0
        );
        assert_eq!(
            value(
                "pavlov_zenoh_commands_total",
                &[("outcome", "refused_token")]
            ),
            3.0
        );
        assert_eq!(
            value("pavlov_zenoh_commands_total", &[("outcome", "applied")]),
            0.0
        );
        assert_eq!(value("pavlov_link_bad_frames_total", &[]), 2.0);
        assert_eq!(value("pavlov_link_skipped_bytes_total", &[]), 17.0);
        assert_eq!(value("pavlov_link_reconnects_total", &[]), 4.0);
        assert_eq!(value("pavlov_link_stale_events_total", &[]), 5.0);
        assert_eq!(value("pavlov_link_state", &[("state", "tripped")]), 1.0);
        assert_eq!(value("pavlov_link_state", &[("state", "up")]), 0.0);
        assert_eq!(value("pavlov_link_tripped", &[("cause", "cliff")]), 1.0);
        assert_eq!(value("pavlov_oi_mode", &[]), 1.0);
        assert_eq!(value("pavlov_ws_rate_limited_total", &[]), 11.0);
        assert_eq!(
            value("pavlov_ws_closed_total", &[("reason", "oversize")]),
            1.0
        );
        assert_eq!(value("pavlov_ws_handshakes_rejected_total", &[]), 7.0);
        assert_eq!(
            value("pavlov_ws_closed_total", &[("reason", "evicted")]),
            4.0
        );
        assert_eq!(
            value("pavlov_ws_closed_total", &[("reason", "invalid_utf8")]),
            2.0
        );
        assert_eq!(value("pavlov_ws_token_failures_total", &[]), 8.0);
        assert_eq!(value("pavlov_ws_token_throttled_total", &[]), 3.0);
        assert_eq!(value("pavlov_ws_watchers", &[]), 1.0);
        assert_eq!(value("pavlov_ws_pending_connections", &[]), 5.0);
        assert_eq!(value("pavlov_ws_tcp_refused_total", &[]), 6.0);
        assert_eq!(value("pavlov_recorder_backlog", &[]), 12.0);
        assert_eq!(value("pavlov_recording_failures_total", &[]), 2.0);
        assert_eq!(value("pavlov_checkpoint_failures_total", &[]), 3.0);
        assert_eq!(value("pavlov_actuation_pipeline_stalls_total", &[]), 6.0);
        assert_eq!(value("pavlov_serial_write_errors_total", &[]), 1.0);
        assert_eq!(value("pavlov_sim_faults_total", &[("kind", "hangs")]), 3.0);
        assert_eq!(
            value("pavlov_sim_faults_total", &[("kind", "flipped_bytes")]),
            8.0
        );
        assert_eq!(value("pavlov_foxglove_clients", &[]), 3.0);
        assert_eq!(value("pavlov_horde_predictions", &[]), 11_748.0);
        assert_eq!(value("pavlov_horde_skipped_total", &[]), 4.0);
        assert_eq!(
            value("pavlov_foxglove_refused_total", &[("reason", "token")]),
            2.0
        );
        assert_eq!(
            value("pavlov_foxglove_missed_total", &[("stream", "ticks")]),
            5.0
        );
        assert_eq!(
            value("pavlov_foxglove_missed_total", &[("stream", "events")]),
            0.0
        );
        let states = families["pavlov_link_state"].samples.len();
        assert_eq!(states, LinkState::ALL.len());
        assert_eq!(families["pavlov_tick_lateness_seconds"].kind, "histogram");
    }

    #[test]
    fn histograms_are_cumulative_and_end_at_the_count() {
        let text = render(&snapshot());
        let families = parse(&text).unwrap();
        let h = &families["pavlov_tick_lateness_seconds"];
        let buckets: Vec<(String, f64)> = h
            .samples
            .iter()
            .filter(|s| s.name.ends_with("_bucket"))
            .map(|s| (s.labels["le"].clone(), s.value))
            .collect();
        assert_eq!(buckets.len(), TICK_BUCKETS_US.len() + 1);
        // 10 and 40 µs ≤ 50 µs; 120 ≤ 250 µs; 900 ≤ 1 ms; 3000 ≤ 5 ms; 70 s only in +Inf.
        assert_eq!(buckets[0], ("0.00005".into(), 2.0));
        assert_eq!(buckets[2], ("0.00025".into(), 3.0));
        assert_eq!(buckets[4], ("0.001".into(), 4.0));
        assert_eq!(buckets[6], ("0.005".into(), 5.0));
        assert_eq!(buckets[12], ("1".into(), 5.0));
        assert_eq!(buckets[13], ("+Inf".into(), 6.0));
        let sum = h
            .samples
            .iter()
            .find(|s| s.name == "pavlov_tick_lateness_seconds_sum")
            .unwrap()
            .value;
        assert!((sum - 70.00407).abs() < 1e-9, "{sum}");
    }

    #[test]
    fn before_the_first_tick_and_without_a_recorder_those_families_are_absent() {
        let s = MetricsSnapshot::default();
        let text = render(&s);
        let families = parse(&text).unwrap();
        assert!(!families.contains_key("pavlov_link_state"));
        assert!(!families.contains_key("pavlov_recorder_backlog"));
        assert!(!families.contains_key("pavlov_sim_faults_total"));
        assert!(families.contains_key("pavlov_ws_clients"));
        let h = &families["pavlov_tick_to_command_seconds"];
        assert!(h.samples.iter().all(|s| s.value == 0.0));
    }
}
