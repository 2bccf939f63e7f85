//! One experiment run: the real server on the simulated Create, under tokio's paused clock.
//!
//! Each run gets its own single-threaded runtime with the clock paused, so a 6-minute run takes as long
//! as the computation does, and the same seed always gives the same ticks. The run's records are consumed
//! as they are published: the metrics, the per-window counts and a short excerpt for Figure 1 are kept;
//! the full record stream goes to the recorder (the same one `pavlov serve --record` uses).

use std::path::PathBuf;
use std::sync::Arc;

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::metrics::{MetricsSummary, RunMetrics};
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};
use tokio::sync::broadcast::error::RecvError;

use crate::recorder::{Recorder, RecorderReport};
use crate::recording::RecordingHeader;
use crate::server::{RobotTarget, Server};

/// What to run.
#[derive(Debug, Clone)]
pub struct RunSpec {
    /// Position in the interleaved sequence (0-based).
    pub index: usize,
    /// Reactive or Pavlovian.
    pub mode: Mode,
    /// The simulator's seed for this run.
    pub seed: u64,
    /// Ticks to run.
    pub ticks: u64,
    /// Length of a learning-curve window, in ticks.
    pub window_ticks: u64,
    /// Keep the records from this tick on for the Figure 1 excerpt (None: keep none).
    pub excerpt_from_tick: Option<u64>,
    /// How many records the excerpt keeps.
    pub excerpt_len: usize,
    /// Where to record the run (None: no recording).
    pub record_dir: Option<PathBuf>,
}

/// Counts over one window of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WindowCounts {
    /// Ticks with an over-current flag.
    pub overcurrent_observations: u64,
    /// Rising edges of the stimulus.
    pub stall_events: u64,
    /// Distance travelled, m.
    pub distance_m: f64,
    /// Energy drawn, J.
    pub energy_j: f64,
}

/// The outcome of one run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunResult {
    /// Position in the sequence.
    pub index: usize,
    /// Reactive or Pavlovian.
    pub mode: Mode,
    /// The simulator's seed.
    pub seed: u64,
    /// The run's metrics.
    pub metrics: MetricsSummary,
    /// Per-window counts, in order.
    pub windows: Vec<WindowCounts>,
    /// The recording, if one was written.
    pub recording: Option<PathBuf>,
    /// Records the recorder wrote.
    pub recorded: u64,
    /// Records the feed could not hand to the recorder (queue full).
    pub recorder_dropped: u64,
    /// Records the experiment's own subscription missed (should be 0).
    pub lagged: u64,
    /// Wall-clock time the run took, s.
    pub wall_s: f64,
    /// When the response first engaged on the prediction alone (gate on, stimulus off), s.
    pub first_predictive_stop_s: Option<f64>,
    /// The Figure 1 excerpt (not serialised into the summary).
    #[serde(skip)]
    pub excerpt: Vec<TickRecord>,
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The runtime could not be built.
    #[error("cannot build the runtime: {0}")]
    Runtime(std::io::Error),
    /// The recorder could not start.
    #[error("cannot start the recorder: {0}")]
    Recorder(std::io::Error),
    /// The server could not start.
    #[error("cannot start the server: {0}")]
    Server(String),
    /// The feed closed before the run was complete.
    #[error("the tick feed closed after {0} records")]
    FeedClosed(u64),
}

/// Runs `spec` with `base` (mode and seed are overridden) and returns its result.
pub fn run(base: &Config, spec: &RunSpec) -> Result<RunResult, RunError> {
    let wall = std::time::Instant::now();
    let mut config = base.clone();
    config.control.mode = spec.mode;
    config.sim.seed = spec.seed;
    let recorder = match &spec.record_dir {
        Some(dir) => {
            let header = RecordingHeader::new(
                &config,
                format!("run {} {:?} seed {}", spec.index, spec.mode, spec.seed),
            );
            // The queue holds the whole run, so the recording is complete however the threads are scheduled.
            let capacity = usize::try_from(spec.ticks)
                .unwrap_or(usize::MAX)
                .saturating_add(64);
            Some(
                Recorder::spawn(header, Some(dir.clone()), dir.clone(), capacity)
                    .map_err(RunError::Recorder)?,
            )
        }
        None => None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .map_err(RunError::Runtime)?;
    let link = recorder.as_ref().map(|r| r.link.clone());
    let outcome = rt.block_on(collect(config, spec, link));
    drop(rt);
    let report = recorder
        .map(Recorder::join)
        .unwrap_or_else(RecorderReport::default);
    let c = outcome?;
    Ok(RunResult {
        index: spec.index,
        mode: spec.mode,
        seed: spec.seed,
        metrics: c.metrics,
        windows: c.windows,
        recording: report.files.first().cloned(),
        recorded: report.written,
        recorder_dropped: c.dropped,
        lagged: c.lagged,
        wall_s: wall.elapsed().as_secs_f64(),
        first_predictive_stop_s: c.first_predictive_stop_s,
        excerpt: c.excerpt,
    })
}

struct Collected {
    metrics: MetricsSummary,
    windows: Vec<WindowCounts>,
    excerpt: Vec<TickRecord>,
    dropped: u64,
    lagged: u64,
    first_predictive_stop_s: Option<f64>,
}

async fn collect(
    config: Config,
    spec: &RunSpec,
    recorder: Option<crate::recorder::RecorderLink>,
) -> Result<Collected, RunError> {
    let period_ms = config.tick.period_ms as f64;
    let server = Server::start_with_recorder(config, RobotTarget::Simulated, recorder)
        .await
        .map_err(|e| RunError::Server(e.to_string()))?;
    let mut rx = server.feed.subscribe();
    let mut metrics = RunMetrics::new(period_ms);
    let mut windows: Vec<WindowCounts> = Vec::new();
    let mut excerpt = Vec::new();
    let mut seen = 0u64;
    let mut lagged = 0u64;
    let mut first_predictive_stop_s = None;
    let window_ticks = spec.window_ticks.max(1);
    while seen < spec.ticks {
        let record: Arc<TickRecord> = match rx.recv().await {
            Ok(r) => r,
            Err(RecvError::Lagged(n)) => {
                lagged += n;
                continue;
            }
            Err(RecvError::Closed) => return Err(RunError::FeedClosed(seen)),
        };
        seen += 1;
        if first_predictive_stop_s.is_none() && record.gate && !record.stimulus {
            first_predictive_stop_s = Some(record.t_ms / 1000.0);
        }
        let before = metrics.summary();
        metrics.observe(&record);
        let w = usize::try_from(record.seq / window_ticks).unwrap_or(usize::MAX);
        if w >= windows.len() && w < 100_000 {
            windows.resize(w + 1, WindowCounts::default());
        }
        if let Some(win) = windows.get_mut(w) {
            let after = metrics.summary();
            win.overcurrent_observations +=
                after.overcurrent_observations - before.overcurrent_observations;
            win.stall_events += after.stall_events - before.stall_events;
            win.distance_m += after.distance_m - before.distance_m;
            win.energy_j += after.energy_j - before.energy_j;
        }
        if let Some(from) = spec.excerpt_from_tick
            && record.seq >= from
            && excerpt.len() < spec.excerpt_len
        {
            excerpt.push((*record).clone());
        }
    }
    let dropped = server.feed.recorder_dropped();
    server.shutdown().await;
    Ok(Collected {
        metrics: metrics.summary(),
        windows,
        excerpt,
        dropped,
        lagged,
        first_predictive_stop_s,
    })
}
