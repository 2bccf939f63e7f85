//! The stall experiment's statistics: per-policy mean ± SE, the spread across runs (SD, range) of each metric,
//! the relative change with a 95 % bootstrap interval and Welch's t-test, and the learning curve
//! (over-current observations per window, mean over runs).

use pavlov::analysis::bootstrap::{RESAMPLES, ratio_of_means};
use pavlov::analysis::stats::{Describe, WelchTest, describe, relative_change, welch};
use pavlov::control::Mode;
use serde::{Deserialize, Serialize};

use super::run::RunResult;

/// The metrics compared between the policies: (key, label, unit).
pub const TOTALS: [(&str, &str, &str); 6] = [
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
pub(crate) fn total(r: &RunResult, key: &str) -> Option<f64> {
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
    pub(crate) label: String,
    /// Unit.
    pub(crate) unit: String,
    /// Over the reactive runs.
    pub reactive: Describe,
    /// Over the Pavlovian runs.
    pub pavlovian: Describe,
    /// (Pavlovian − reactive) / reactive.
    pub(crate) relative_change: Option<f64>,
    /// 95 % percentile-bootstrap interval of the relative change: the ratio of the resampled means, minus 1
    /// (≥ −100 % for a non-negative metric); NaN bounds for one run a side (no spread).
    #[serde(default)]
    pub(crate) relative_change_ci: Option<(f64, f64)>,
    /// Smallest and largest value over the reactive runs.
    #[serde(default)]
    pub(crate) reactive_range: Option<(f64, f64)>,
    /// The same over the Pavlovian runs.
    #[serde(default)]
    pub(crate) pavlovian_range: Option<(f64, f64)>,
    /// Welch's t-test of Pavlovian against reactive.
    pub(crate) welch: Option<WelchTest>,
}

/// One window of the learning curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CurvePoint {
    /// Window index.
    pub(crate) window: usize,
    /// Window start, s.
    pub(crate) start_s: f64,
    /// Over-current observations in the window over the reactive runs.
    pub(crate) reactive: Describe,
    /// The same over the Pavlovian runs.
    pub(crate) pavlovian: Describe,
}

/// Everything the report shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Analysis {
    /// One per metric of [`TOTALS`].
    pub comparisons: Vec<Comparison>,
    /// Over-current observations per window.
    pub(crate) learning_curve: Vec<CurvePoint>,
    /// The first window from which on the Pavlovian mean stays below the reactive mean (None: never).
    pub(crate) benefit_from_window: Option<usize>,
    /// The first window whose Pavlovian mean is below the reactive mean (None: none).
    #[serde(default)]
    pub(crate) first_below_window: Option<usize>,
    /// When the Pavlovian runs first stopped on the prediction alone, s (over the runs that did).
    pub(crate) first_predictive_stop_s: Describe,
}

fn values(runs: &[RunResult], mode: Mode, key: &str) -> Vec<f64> {
    runs.iter()
        .filter(|r| r.mode == mode)
        .filter_map(|r| total(r, key))
        .collect()
}

/// Analyses the runs; `window_s` is the learning curve's window length.
pub(crate) fn analyse(runs: &[RunResult], window_s: f64) -> Analysis {
    let comparisons = TOTALS
        .iter()
        .map(|(key, label, unit)| {
            let a = values(runs, Mode::Reactive, key);
            let b = values(runs, Mode::Pavlovian, key);
            let (da, db) = (describe(&a), describe(&b));
            let range = |xs: &[f64]| {
                (!xs.is_empty()).then(|| {
                    xs.iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                            (l.min(x), h.max(x))
                        })
                })
            };
            let relative_change_ci = ratio_of_means(&b, &a, RESAMPLES, 1).map(|r| (r.lo, r.hi));
            Comparison {
                metric: (*key).to_string(),
                label: (*label).to_string(),
                unit: (*unit).to_string(),
                reactive: da,
                pavlovian: db,
                relative_change: relative_change(da.mean, db.mean),
                relative_change_ci,
                reactive_range: range(&a),
                pavlovian_range: range(&b),
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
    let first_below_window = learning_curve
        .iter()
        .position(|p| p.pavlovian.mean < p.reactive.mean);
    let firsts: Vec<f64> = runs
        .iter()
        .filter(|r| r.mode == Mode::Pavlovian)
        .filter_map(|r| r.first_predictive_stop_s)
        .collect();
    Analysis {
        comparisons,
        learning_curve,
        benefit_from_window,
        first_below_window,
        first_predictive_stop_s: describe(&firsts),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::stall::run::WindowCounts;
    use pavlov::analysis::run_counters::RunTotals;

    fn run(index: usize, mode: Mode, oc: u64, windows: &[u64]) -> RunResult {
        RunResult {
            index,
            mode,
            seed: index as u64,
            metrics: RunTotals {
                ticks: 100,
                elapsed_s: 2.0,
                overcurrent_observations: oc,
                stall_events: oc / 10,
                time_stalled_s: oc as f64 * 0.02,
                distance_m: 1.0,
                energy_j: 1000.0 + oc as f64,
                efficiency_m_per_kj: Some(1.0 / (1.0 + oc as f64 / 1000.0)),
            },
            windows: windows
                .iter()
                .map(|&w| WindowCounts {
                    overcurrent_observations: w,
                    ..WindowCounts::default()
                })
                .collect(),
            recording: None,
            recorded: 0,
            recorder_dropped: 0,
            lagged: 0,
            wall_s: 0.0,
            first_predictive_stop_s: (mode == Mode::Pavlovian).then_some(4.0 + index as f64),
            policy: String::new(),
            accuracy: None,
            coverage: None,
            epsilon: None,
            excerpt: Vec::new(),
        }
    }

    #[test]
    fn comparisons_curve_and_benefit_follow_the_runs() {
        let runs = vec![
            run(0, Mode::Reactive, 100, &[50, 50, 60]),
            run(1, Mode::Pavlovian, 60, &[55, 20, 30]),
            run(2, Mode::Reactive, 110, &[50, 60, 50]),
            run(3, Mode::Pavlovian, 50, &[60, 30, 20]),
        ];
        let a = analyse(&runs, 30.0);
        let oc = &a.comparisons[0];
        assert_eq!(oc.metric, "overcurrent_observations");
        assert_eq!((oc.reactive.mean, oc.pavlovian.mean), (105.0, 55.0));
        assert!((oc.relative_change.unwrap() + 50.0 / 105.0).abs() < 1e-12);
        assert!(oc.welch.unwrap().t < 0.0);
        assert_eq!(a.learning_curve.len(), 3);
        assert_eq!(a.learning_curve[1].start_s, 30.0);
        assert_eq!(a.learning_curve[0].pavlovian.mean, 57.5);
        // Window 0: Pavlovian above reactive; from window 1 on, below.
        assert_eq!(a.benefit_from_window, Some(1));
        assert_eq!(a.first_below_window, Some(1));
        assert_eq!(oc.reactive_range, Some((100.0, 110.0)));
        assert_eq!(oc.pavlovian_range, Some((50.0, 60.0)));
        let (lo, hi) = oc.relative_change_ci.unwrap();
        assert!(
            lo >= -1.0 && lo <= oc.relative_change.unwrap() && oc.relative_change.unwrap() <= hi
        );
        assert_eq!(a.first_predictive_stop_s.n, 2);
        assert_eq!(a.first_predictive_stop_s.mean, 6.0);
        assert_eq!(total(&runs[0], "nope"), None);
    }

    #[test]
    fn runs_csv_names_each_runs_own_policy() {
        let mut runs = vec![
            run(0, Mode::Reactive, 100, &[1]),
            run(1, Mode::Pavlovian, 60, &[1]),
            run(2, Mode::Pavlovian, 50, &[1]),
        ];
        runs[1].policy = "pavlovian".into();
        runs[2].policy = "offpolicy".into();
        let csv = crate::experiment::stall::report::runs_csv(&runs);
        let labels: Vec<&str> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(1).unwrap())
            .collect();
        assert_eq!(labels, ["reactive", "pavlovian", "offpolicy"]);
        let w = crate::experiment::stall::report::windows_csv(&runs);
        assert!(w.lines().nth(3).unwrap().starts_with("2,offpolicy,"));
    }
}
