//! The stall experiment's statistics: per-policy mean ± SE of each metric, the relative change with
//! Welch's t-test, and the learning curve (over-current observations per window, mean over runs).

use pavlov::control::Mode;
use pavlov::stats::{Describe, WelchTest, describe, relative_change, welch};
use serde::{Deserialize, Serialize};

use super::run::RunResult;

/// The metrics compared between the policies: (key, label, unit).
pub const METRICS: [(&str, &str, &str); 6] = [
    (
        "overcurrent_observations",
        "over-current observations",
        "ticks",
    ),
    ("stall_events", "stall events", "count"),
    ("time_stalled_s", "time stalled", "s"),
    ("distance_m", "distance travelled", "m"),
    ("energy_j", "energy (Σ V·I·dt)", "J"),
    ("efficiency_m_per_kj", "efficiency", "m/kJ"),
];

/// One metric's value in a run (`None` for an efficiency without energy).
pub fn metric(r: &RunResult, key: &str) -> Option<f64> {
    let m = &r.metrics;
    match key {
        "overcurrent_observations" => Some(m.overcurrent_observations as f64),
        "stall_events" => Some(m.stall_events as f64),
        "time_stalled_s" => Some(m.time_stalled_s),
        "distance_m" => Some(m.distance_m),
        "energy_j" => Some(m.energy_j),
        "efficiency_m_per_kj" => m.efficiency_m_per_kj,
        _ => None,
    }
}

/// One metric compared between the policies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// The metric's key.
    pub metric: String,
    /// Human-readable name.
    pub label: String,
    /// Unit.
    pub unit: String,
    /// Over the reactive runs.
    pub reactive: Describe,
    /// Over the Pavlovian runs.
    pub pavlovian: Describe,
    /// (Pavlovian − reactive) / reactive.
    pub relative_change: Option<f64>,
    /// Welch's t-test of Pavlovian against reactive.
    pub welch: Option<WelchTest>,
}

/// One window of the learning curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Window index.
    pub window: usize,
    /// Window start, s.
    pub start_s: f64,
    /// Over-current observations in the window over the reactive runs.
    pub reactive: Describe,
    /// The same over the Pavlovian runs.
    pub pavlovian: Describe,
}

/// Everything the report shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Analysis {
    /// One per metric of [`METRICS`].
    pub comparisons: Vec<Comparison>,
    /// Over-current observations per window.
    pub learning_curve: Vec<CurvePoint>,
    /// The first window from which on the Pavlovian mean stays below the reactive mean (None: never).
    pub benefit_from_window: Option<usize>,
    /// When the Pavlovian runs first stopped on the prediction alone, s (over the runs that did).
    pub first_predictive_stop_s: Describe,
}

fn values(runs: &[RunResult], mode: Mode, key: &str) -> Vec<f64> {
    runs.iter()
        .filter(|r| r.mode == mode)
        .filter_map(|r| metric(r, key))
        .collect()
}

/// Analyses the runs; `window_s` is the learning curve's window length.
pub fn analyse(runs: &[RunResult], window_s: f64) -> Analysis {
    let comparisons = METRICS
        .iter()
        .map(|(key, label, unit)| {
            let a = values(runs, Mode::Reactive, key);
            let b = values(runs, Mode::Pavlovian, key);
            let (da, db) = (describe(&a), describe(&b));
            Comparison {
                metric: (*key).to_string(),
                label: (*label).to_string(),
                unit: (*unit).to_string(),
                reactive: da,
                pavlovian: db,
                relative_change: relative_change(da.mean, db.mean),
                welch: welch(&a, &b),
            }
        })
        .collect();
    let n_windows = runs.iter().map(|r| r.windows.len()).min().unwrap_or(0);
    let curve_for = |mode: Mode, w: usize| -> Describe {
        let xs: Vec<f64> = runs
            .iter()
            .filter(|r| r.mode == mode)
            .filter_map(|r| r.windows.get(w))
            .map(|c| c.overcurrent_observations as f64)
            .collect();
        describe(&xs)
    };
    let learning_curve: Vec<CurvePoint> = (0..n_windows)
        .map(|w| CurvePoint {
            window: w,
            start_s: w as f64 * window_s,
            reactive: curve_for(Mode::Reactive, w),
            pavlovian: curve_for(Mode::Pavlovian, w),
        })
        .collect();
    let benefit_from_window = (0..learning_curve.len()).find(|&w| {
        learning_curve
            .get(w..)
            .is_some_and(|rest| rest.iter().all(|p| p.pavlovian.mean < p.reactive.mean))
    });
    let firsts: Vec<f64> = runs
        .iter()
        .filter(|r| r.mode == Mode::Pavlovian)
        .filter_map(|r| r.first_predictive_stop_s)
        .collect();
    Analysis {
        comparisons,
        learning_curve,
        benefit_from_window,
        first_predictive_stop_s: describe(&firsts),
    }
}
