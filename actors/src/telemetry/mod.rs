//! How the server is doing: tick timing, tick-to-command latency and the counters of every part, read
//! through one [`Health`] handle by the dashboard's status messages, `/metrics`, the periodic log line
//! and the benchmarks.
//!
//! - `counters`: the counters each actor keeps (one writer each);
//! - `histogram`: the allocation-free latency histogram that sits on the tick path;
//! - `exposition`: a writer of the Prometheus text format; `prometheus`: the `/metrics` text;
//!   [`prometheus_check`]: a strict reader of that format, for tests;
//! - `sim_status`, `horde_status`: what the simulator and the Horde report, read by [`Health`];
//! - `health_log`: the tick-health line logged once a minute;
//! - [`logging`]: logging that never blocks or fails the caller (a queue and a writer thread).

pub(crate) mod counters;
pub(crate) mod exposition;
pub(crate) mod health_log;
pub(crate) mod histogram;
pub mod horde_status;
pub mod logging;
pub(crate) mod prometheus;
/// A strict reader of the `/metrics` text, for the end-to-end tests (always built: a feature for it put
/// the package into its own dev-dependencies, which turned `--features pavlov-actors/zenoh` into a no-op
/// for the binary).
#[doc(hidden)]
pub mod prometheus_check;
pub mod sim_status;
pub mod zenoh_drops;

use pavlov::config::TickTimer;
use pavlov::record::LinkStatus;
use serde::Serialize;
use tokio::sync::watch;

use crate::bus::recorder_queue::RecorderGauge;
use crate::bus::storage_failures::StorageFailures;
use counters::{
    ActuationStats, FoxgloveCounters, SharedTickStats, SharedWriterStats, ZenohCounters,
};
use histogram::{LatencyHistogram, LatencyQuantiles};

use sim_status::SimStatus;

/// One handle on every health figure of a running server. Cheap to clone; reading never blocks the tick
/// for longer than copying a histogram under its lock.
#[derive(Clone)]
pub struct Health {
    pub(crate) ticks: SharedTickStats,
    pub(crate) timer: TickTimer,
    pub(crate) writer: SharedWriterStats,
    pub(crate) actuation: watch::Receiver<ActuationStats>,
    pub(crate) sim: Option<watch::Receiver<SimStatus>>,
    pub(crate) recorder: RecorderGauge,
    pub(crate) link: watch::Receiver<Option<LinkStatus>>,
    /// The Foxglove endpoint's counters (all zero without `serve --foxglove`).
    pub(crate) foxglove: std::sync::Arc<FoxgloveCounters>,
    /// The Zenoh bridge's counters (all zero without `serve --zenoh`).
    pub(crate) zenoh: std::sync::Arc<ZenohCounters>,
    /// The Horde's figures, when there is a Horde.
    pub(crate) horde: Option<watch::Receiver<horde_status::HordeStatus>>,
    /// Failures to write recordings and checkpoints (the event log's count).
    pub(crate) storage: std::sync::Arc<StorageFailures>,
}

/// The recorder queue's figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub(crate) struct RecorderFigures {
    /// Records queued and not yet written.
    pub(crate) backlog: u64,
    /// Records dropped because the queue was full.
    pub(crate) dropped: u64,
}

/// The health figures at one moment.
#[derive(Debug, Clone, Default, Serialize)]
pub struct HealthFigures {
    /// Ticks fired since start.
    pub ticks_fired: u64,
    /// Ticks skipped because the ticker woke too late.
    pub ticks_skipped: u64,
    /// Tick lateness (fired − deadline).
    pub(crate) lateness: LatencyQuantiles,
    /// Tick deadline → motor command written.
    pub(crate) tick_to_command: LatencyQuantiles,
    /// Serial write errors.
    pub(crate) write_errors: u64,
    /// Actuation's counters.
    pub(crate) actuation: ActuationStats,
    /// The link as the newest tick record saw it (`None` before the first tick).
    pub(crate) link: Option<LinkStatus>,
    /// The recorder's queue (`None` without a recorder).
    pub(crate) recorder: Option<RecorderFigures>,
}

/// Longest silence of the tick loop that still counts as running: 50 ticks at 50 Hz.
pub const TICK_STALL: std::time::Duration = std::time::Duration::from_secs(1);

/// Whether the server is doing its job, for `/healthz` and `/metrics`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// The tick loop runs and the robot link is up.
    Ok,
    /// The tick loop runs but the robot link is not up (stale, reconnecting, tripped, down).
    LinkNotUp(String),
    /// The tick loop has not fired for longer than [`TICK_STALL`] (or never has).
    TickStalled(String),
}

impl Verdict {
    /// The one-line text `/healthz` answers.
    pub fn describe(&self) -> String {
        match self {
            Verdict::Ok => "ok".into(),
            Verdict::LinkNotUp(why) | Verdict::TickStalled(why) => why.clone(),
        }
    }
}

impl Health {
    /// The timer that drives the tick: the timer thread in real time (unless `[tick] timer = "tokio"`),
    /// tokio's interval under a paused clock.
    pub fn tick_timer(&self) -> TickTimer {
        self.timer
    }

    /// Time since the newest tick fired (`None` before the first).
    pub fn tick_age(&self) -> Option<std::time::Duration> {
        let last = self.ticks.lock().ok()?.last_taken?;
        Some(tokio::time::Instant::now().saturating_duration_since(last))
    }

    /// Judges the tick loop and the robot link now.
    pub fn verdict(&self) -> Verdict {
        match self.tick_age() {
            None => return Verdict::TickStalled("the tick loop has not started".into()),
            Some(age) if age > TICK_STALL => {
                return Verdict::TickStalled(format!(
                    "the tick loop is stalled: no tick for {} ms",
                    age.as_millis()
                ));
            }
            Some(_) => {}
        }
        match *self.link.borrow() {
            Some(l) if l.state == pavlov::supervision::LinkState::Up => Verdict::Ok,
            Some(l) => Verdict::LinkNotUp(match l.trip {
                Some(cause) => format!(
                    "the robot link is {}: the robot tripped ({}); send rearm",
                    l.state.name(),
                    cause.describe()
                ),
                None => format!("the robot link is {}", l.state.name()),
            }),
            None => Verdict::LinkNotUp("no tick record yet".into()),
        }
    }

    /// The figures now.
    pub fn figures(&self) -> HealthFigures {
        let mut f = HealthFigures::default();
        if let Ok(t) = self.ticks.lock() {
            f.ticks_fired = t.fired;
            f.ticks_skipped = t.skipped;
            f.lateness = t.lateness.quantiles();
        }
        if let Ok(w) = self.writer.lock() {
            f.tick_to_command = w.tick_to_command.quantiles();
            f.write_errors = w.errors;
        }
        f.actuation = *self.actuation.borrow();
        f.link = *self.link.borrow();
        f.recorder = self.recorder.attached().then(|| RecorderFigures {
            backlog: self.recorder.backlog() as u64,
            dropped: self.recorder.dropped(),
        });
        f
    }

    /// Copies of the tick-lateness and tick-to-command histograms (taken under their locks, read outside).
    pub(crate) fn histograms(&self) -> (LatencyHistogram, LatencyHistogram) {
        let ticks = self
            .ticks
            .lock()
            .map(|t| t.lateness.clone())
            .unwrap_or_default();
        let writer = self
            .writer
            .lock()
            .map(|w| w.tick_to_command.clone())
            .unwrap_or_default();
        (ticks, writer)
    }

    /// The simulated robot's state after its newest step (`None` on a real robot).
    pub fn sim_status(&self) -> Option<watch::Receiver<SimStatus>> {
        self.sim.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::record::LinkStatus;
    use pavlov::supervision::{LinkState, TripCause};

    fn health(last_taken_ago: Option<std::time::Duration>, link: Option<LinkStatus>) -> Health {
        let ticks = SharedTickStats::default();
        if let Some(ago) = last_taken_ago {
            ticks.lock().unwrap().last_taken = Some(tokio::time::Instant::now() - ago);
        }
        Health {
            ticks,
            timer: TickTimer::Thread,
            writer: SharedWriterStats::default(),
            actuation: watch::channel(ActuationStats::default()).1,
            sim: None,
            recorder: RecorderGauge::new(None, Default::default()),
            link: watch::channel(link).1,
            foxglove: Default::default(),
            zenoh: Default::default(),
            horde: None,
            storage: Default::default(),
        }
    }

    fn link(state: LinkState, trip: Option<TripCause>) -> Option<LinkStatus> {
        Some(LinkStatus {
            state,
            trip,
            ..LinkStatus::default()
        })
    }

    #[test]
    fn the_verdict_judges_the_tick_loop_first_then_the_link() {
        let ms = std::time::Duration::from_millis;
        assert!(matches!(
            health(None, None).verdict(),
            Verdict::TickStalled(_)
        ));
        let stalled = health(Some(ms(1500)), link(LinkState::Up, None)).verdict();
        assert!(
            stalled
                .describe()
                .starts_with("the tick loop is stalled: no tick for 15"),
            "{stalled:?}"
        );
        let ok = health(Some(ms(5)), link(LinkState::Up, None)).verdict();
        assert_eq!(ok, Verdict::Ok);
        let down = health(Some(ms(5)), link(LinkState::Reconnecting, None)).verdict();
        assert_eq!(down.describe(), "the robot link is reconnecting");
        let tripped = health(
            Some(ms(5)),
            link(LinkState::Tripped, Some(TripCause::Cliff)),
        );
        assert!(tripped.verdict().describe().contains("send rearm"));
    }
}
