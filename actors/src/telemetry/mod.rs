//! How the server is doing: tick timing, tick-to-command latency and the counters of every part, read
//! through one [`Health`] handle by the dashboard's status messages, `/metrics`, the periodic log line
//! and the benchmarks.
//!
//! - [`counters`]: the counters each actor keeps (one writer each);
//! - [`histogram`]: the allocation-free latency histogram that sits on the tick path;
//! - [`exposition`]: a writer of the Prometheus text format; [`prometheus`]: the `/metrics` text;
//!   [`prometheus_check`]: a strict reader of that format, for tests;
//! - [`health_log`]: the tick-health line logged once a minute.

pub(crate) mod counters;
pub(crate) mod exposition;
pub(crate) mod health_log;
pub(crate) mod histogram;
pub(crate) mod prometheus;
#[cfg(any(test, feature = "test-support"))]
pub mod prometheus_check;

use pavlov::record::LinkStatus;
use serde::Serialize;
use tokio::sync::watch;

use counters::{ActuationStats, RecorderGauge, SharedTickStats, SharedWriterStats};
use histogram::{LatencyHistogram, LatencyQuantiles};

use crate::simulated::SimStatus;

/// One handle on every health figure of a running server. Cheap to clone; reading never blocks the tick
/// for longer than copying a histogram under its lock.
#[derive(Clone)]
pub struct Health {
    pub(crate) ticks: SharedTickStats,
    pub(crate) writer: SharedWriterStats,
    pub(crate) actuation: watch::Receiver<ActuationStats>,
    pub(crate) sim: Option<watch::Receiver<SimStatus>>,
    pub(crate) recorder: RecorderGauge,
    pub(crate) link: watch::Receiver<Option<LinkStatus>>,
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

impl Health {
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
