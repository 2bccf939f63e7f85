//! One stall run: what the study keeps of its ticks — the run's metrics, the counts per learning-curve
//! window, the first prediction-driven stop and a short excerpt for Figure 1 — while the full record
//! stream goes to the recorder.

use std::path::PathBuf;
use std::sync::Arc;

use pavlov::analysis::run_counters::{RunCounters, RunTotals};
use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use crate::experiment::runner::{Collect, RunError, RunRequest, run_paused};

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
    pub(crate) window_ticks: u64,
    /// Keep the records from this tick on for the Figure 1 excerpt (None: keep none).
    pub(crate) excerpt_from_tick: Option<u64>,
    /// How many records the excerpt keeps.
    pub(crate) excerpt_len: usize,
    /// Where to record the run (None: no recording).
    pub(crate) record_dir: Option<PathBuf>,
    /// The policy's name in tables (`reactive`, `pavlovian`, `offpolicy`).
    pub(crate) policy: String,
    /// The prediction that drives the gate, when not the configuration's.
    pub(crate) gate_prediction: Option<String>,
    /// Score the on-policy and off-policy predictions (named) against π's return.
    pub(crate) score: Option<(String, String)>,
    /// The stochastic gate's ε (`offpolicy-stochastic`), when the run has one.
    pub(crate) epsilon: Option<f64>,
}

/// Counts over one window of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WindowCounts {
    /// Ticks with an over-current flag.
    pub(crate) overcurrent_observations: u64,
    /// Rising edges of the stimulus.
    pub(crate) stall_events: u64,
    /// Distance travelled, m.
    pub(crate) distance_m: f64,
    /// Energy drawn, J.
    pub(crate) energy_j: f64,
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
    pub metrics: RunTotals,
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
    pub(crate) wall_s: f64,
    /// When the response first engaged on the prediction alone (gate on, stimulus off), s.
    pub(crate) first_predictive_stop_s: Option<f64>,
    /// The policy's name (`reactive`, `pavlovian`, `offpolicy`).
    #[serde(default)]
    pub policy: String,
    /// The predictions' accuracy against π's return, when scored.
    #[serde(default)]
    pub accuracy: Option<super::accuracy::RunAccuracy>,
    /// The behaviour's coverage of π in the gate region (policy studies).
    #[serde(default)]
    pub coverage: Option<super::stochastic::Coverage>,
    /// The stochastic gate's ε, when the run had one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epsilon: Option<f64>,
    /// The Figure 1 excerpt (not serialised into the study).
    #[serde(skip)]
    pub(crate) excerpt: Vec<TickRecord>,
}

/// What a stall run keeps while it runs.
struct StallCollector<'a> {
    spec: &'a RunSpec,
    metrics: RunCounters,
    windows: Vec<WindowCounts>,
    excerpt: Vec<TickRecord>,
    first_predictive_stop_s: Option<f64>,
    returns: Option<super::accuracy::PiReturns>,
    coverage: Option<super::stochastic::Coverage>,
}

struct Kept {
    metrics: RunTotals,
    windows: Vec<WindowCounts>,
    excerpt: Vec<TickRecord>,
    first_predictive_stop_s: Option<f64>,
    accuracy: Option<super::accuracy::RunAccuracy>,
    coverage: Option<super::stochastic::Coverage>,
}

impl Collect for StallCollector<'_> {
    type Output = Kept;

    fn record(&mut self, record: Arc<TickRecord>) {
        if self.first_predictive_stop_s.is_none() && record.gate && !record.stimulus {
            self.first_predictive_stop_s = Some(record.t_ms / 1000.0);
        }
        if let Some(r) = &mut self.returns {
            r.observe(&record);
        }
        if let Some(c) = &mut self.coverage {
            c.observe(&record);
        }
        let before = self.metrics.totals();
        self.metrics.observe(&record);
        let w = usize::try_from(record.seq / self.spec.window_ticks.max(1)).unwrap_or(usize::MAX);
        if w >= self.windows.len() && w < 100_000 {
            self.windows.resize(w + 1, WindowCounts::default());
        }
        if let Some(win) = self.windows.get_mut(w) {
            let after = self.metrics.totals();
            win.overcurrent_observations +=
                after.overcurrent_observations - before.overcurrent_observations;
            win.stall_events += after.stall_events - before.stall_events;
            win.distance_m += after.distance_m - before.distance_m;
            win.energy_j += after.energy_j - before.energy_j;
        }
        if let Some(from) = self.spec.excerpt_from_tick
            && record.seq >= from
            && self.excerpt.len() < self.spec.excerpt_len
        {
            self.excerpt.push((*record).clone());
        }
    }

    async fn finish(self) -> Result<Kept, RunError> {
        Ok(Kept {
            metrics: self.metrics.totals(),
            windows: self.windows,
            excerpt: self.excerpt,
            first_predictive_stop_s: self.first_predictive_stop_s,
            accuracy: self
                .returns
                .as_ref()
                .map(super::accuracy::PiReturns::finish),
            coverage: self.coverage,
        })
    }
}

/// The configuration of run `spec`: `base` with its mode and seed, and, when the policy names the
/// prediction that gates, the paper's single rule on that prediction, whatever rule table `base` declares.
pub(crate) fn config_for(base: &Config, spec: &RunSpec) -> Config {
    let mut config = base.clone();
    config.control.mode = spec.mode;
    config.sim.seed = spec.seed;
    if let Some(g) = &spec.gate_prediction {
        config.control.gate_prediction = g.clone();
        config.rules.clear();
    }
    if let Some(eps) = spec.epsilon {
        super::stochastic::apply_stochastic_gate(&mut config, eps);
    }
    config
}

/// Runs `spec` with `base` (see [`config_for`]) and returns its result.
pub(crate) fn run(base: &Config, spec: &RunSpec) -> Result<RunResult, RunError> {
    let config = config_for(base, spec);
    let continuation = config
        .predictions
        .iter()
        .find(|p| Some(&p.name) == spec.score.as_ref().map(|s| &s.0))
        .map_or(0.96, |p| p.continuation());
    let period_ms = config.tick.period_ms as f64;
    let label = format!("run {} {:?} seed {}", spec.index, spec.mode, spec.seed);
    let request = RunRequest {
        config,
        ticks: spec.ticks,
        record: spec.record_dir.clone().map(|d| (d, label)),
    };
    let collector = StallCollector {
        spec,
        metrics: RunCounters::new(period_ms),
        windows: Vec::new(),
        excerpt: Vec::new(),
        first_predictive_stop_s: None,
        returns: spec
            .score
            .as_ref()
            .map(|(on, off)| super::accuracy::PiReturns::new(on, off, continuation)),
        coverage: spec
            .score
            .is_some()
            .then(super::stochastic::Coverage::default),
    };
    let done = run_paused(request, collector)?;
    let kept = done.output;
    Ok(RunResult {
        index: spec.index,
        mode: spec.mode,
        seed: spec.seed,
        metrics: kept.metrics,
        windows: kept.windows,
        recording: done.recording,
        recorded: done.recorded,
        recorder_dropped: done.recorder_dropped,
        lagged: done.lagged,
        wall_s: done.wall_s,
        first_predictive_stop_s: kept.first_predictive_stop_s,
        policy: spec.policy.clone(),
        accuracy: kept.accuracy,
        coverage: kept.coverage,
        epsilon: spec.epsilon,
        excerpt: kept.excerpt,
    })
}
