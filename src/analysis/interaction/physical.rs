//! Physical response onsets of the gesture-command experiment: when the battery current and the wheels
//! answered each command, rather than the control decision (the gate).
//!
//! Inputs are per-tick [`PhysicalSample`]s (battery current, mA, negative = discharging, as the Create
//! reports it; whether the odometry reported motion) and a command's window `[lo, hi]` (for ground-truth
//! commands the window of [`super::measure`]).
//!
//! Definitions:
//! - The *baseline* current is the mean of the currents of the ticks in `[lo − baseline_ms, lo)`.
//! - The *current onset* is the first tick in `[lo, hi]` whose current lies more than `current_drop_ma`
//!   below the baseline (more discharge). No baseline (no current samples before the window) = no onset.
//! - The *motion onset* is the first tick in `[lo, hi]` that reports motion (non-zero angle or distance
//!   since the previous tick) after a tick that did not; motion already under way when the window opens
//!   does not count until it stops and starts again, as for the gate's onsets.
//! - A *latency* is the onset minus the command onset, ms (negative = anticipated).
//!
//! The threshold: the simulator's current sensor noise is 6 mA (SD) on top of a 150 mA idle draw, and the
//! baseline averages 10 ticks, so a 50 mA drop is over 8 SDs of one reading: noise alone essentially never
//! crosses it, while a spin draws several hundred mA more than idling. It is fixed, not fitted to any policy.

use serde::{Deserialize, Serialize};

use super::{CommandWindow, MatchParams, window};

/// The physical state at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhysicalSample {
    /// Time of the tick, ms.
    pub t_ms: f64,
    /// Battery current, mA (negative = discharging); `None` when not reported.
    pub current_ma: Option<f64>,
    /// Whether the odometry reported motion since the previous tick.
    pub moving: bool,
}

/// Thresholds of the onset detection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhysicalParams {
    /// Length of the baseline before the window, ms.
    pub baseline_ms: f64,
    /// How far below the baseline the current must drop, mA.
    pub current_drop_ma: f64,
}

/// The default current drop, mA (see the module documentation).
pub const CURRENT_DROP_MA: f64 = 50.0;

impl Default for PhysicalParams {
    /// A 200 ms baseline and a [`CURRENT_DROP_MA`] drop.
    fn default() -> Self {
        PhysicalParams {
            baseline_ms: 200.0,
            current_drop_ma: CURRENT_DROP_MA,
        }
    }
}

/// The physical onsets of one command, relative to its onset, ms (`None`: no onset in its window).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PhysicalLatency {
    /// Current onset minus command onset.
    pub current_ms: Option<f64>,
    /// Motion onset minus command onset.
    pub motion_ms: Option<f64>,
}

/// The physical onsets in `[lo, hi]` relative to `onset_ms`; `samples` in time order.
pub fn onsets_in_window(
    samples: &[PhysicalSample],
    lo: f64,
    hi: f64,
    onset_ms: f64,
    p: &PhysicalParams,
) -> PhysicalLatency {
    let baseline: Vec<f64> = samples
        .iter()
        .filter(|s| s.t_ms >= lo - p.baseline_ms && s.t_ms < lo)
        .filter_map(|s| s.current_ma)
        .collect();
    let base = (!baseline.is_empty()).then(|| baseline.iter().sum::<f64>() / baseline.len() as f64);
    let inside = || samples.iter().filter(|s| s.t_ms >= lo && s.t_ms <= hi);
    let current_ms = base.and_then(|b| {
        inside()
            .find(|s| s.current_ma.is_some_and(|c| c < b - p.current_drop_ma))
            .map(|s| s.t_ms - onset_ms)
    });
    let mut was_moving = samples
        .iter()
        .take_while(|s| s.t_ms < lo)
        .last()
        .is_some_and(|s| s.moving);
    let mut motion_ms = None;
    for s in inside() {
        if s.moving && !was_moving {
            motion_ms = Some(s.t_ms - onset_ms);
            break;
        }
        was_moving = s.moving;
    }
    PhysicalLatency {
        current_ms,
        motion_ms,
    }
}

/// The physical onsets of every command, in the windows [`super::measure`] uses.
pub fn measure_physical(
    samples: &[PhysicalSample],
    commands: &[CommandWindow],
    matching: &MatchParams,
    p: &PhysicalParams,
) -> Vec<PhysicalLatency> {
    commands
        .iter()
        .map(|c| {
            let (lo, hi) = window(c, matching);
            onsets_in_window(samples, lo, hi, c.onset_ms, p)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// 20 ms ticks to `end_ms`: idle −150 mA with 6 mA noise, −600 mA and moving inside the `[from, to)` spans
    /// (the current may lag the motion by `current_lag_ms`).
    fn series(end_ms: f64, on: &[(f64, f64)], current_lag_ms: f64) -> Vec<PhysicalSample> {
        let mut rng = Rng::new(7);
        (0..)
            .map(|k| f64::from(k) * 20.0)
            .take_while(|&t| t <= end_ms)
            .map(|t| {
                let drawing = on
                    .iter()
                    .any(|&(a, b)| t >= a + current_lag_ms && t < b + current_lag_ms);
                let level = if drawing { -600.0 } else { -150.0 };
                PhysicalSample {
                    t_ms: t,
                    current_ma: Some(level + rng.normal(0.0, 6.0)),
                    moving: on.iter().any(|&(a, b)| t >= a && t < b),
                }
            })
            .collect()
    }

    fn cmd(onset_ms: f64, end_ms: f64) -> CommandWindow {
        CommandWindow { onset_ms, end_ms }
    }

    #[test]
    fn drops_and_motion_at_known_ticks_give_their_latencies() {
        // Motion from 2.1 s (100 ms late) and from 5.8 s (200 ms early); the current follows 40 ms later.
        let s = series(10_000.0, &[(2100.0, 3000.0), (5800.0, 7000.0)], 40.0);
        let l = measure_physical(
            &s,
            &[cmd(2000.0, 3000.0), cmd(6000.0, 7000.0)],
            &MatchParams::default(),
            &PhysicalParams::default(),
        );
        assert_eq!(l[0].motion_ms, Some(100.0));
        assert_eq!(l[0].current_ms, Some(140.0));
        assert_eq!(l[1].motion_ms, Some(-200.0));
        assert_eq!(l[1].current_ms, Some(-160.0));
    }

    #[test]
    fn baseline_noise_alone_is_no_onset_and_a_command_without_response_has_none() {
        let s = series(10_000.0, &[(2100.0, 3000.0)], 0.0);
        let l = measure_physical(
            &s,
            &[cmd(2000.0, 3000.0), cmd(7000.0, 8000.0)],
            &MatchParams::default(),
            &PhysicalParams::default(),
        );
        assert_eq!(l[0].motion_ms, Some(100.0));
        assert_eq!(l[1], PhysicalLatency::default());
    }

    #[test]
    fn the_drop_is_measured_from_the_baseline_not_from_zero() {
        // A steady −400 mA before and through the window, then −430 mA: 30 mA is under the threshold.
        let s: Vec<PhysicalSample> = (0..100)
            .map(|k| {
                let t = f64::from(k) * 20.0;
                PhysicalSample {
                    t_ms: t,
                    current_ma: Some(if t >= 1000.0 { -430.0 } else { -400.0 }),
                    moving: false,
                }
            })
            .collect();
        let p = PhysicalParams::default();
        assert_eq!(
            onsets_in_window(&s, 800.0, 1500.0, 1000.0, &p).current_ms,
            None
        );
        let lower = PhysicalParams {
            current_drop_ma: 20.0,
            ..p
        };
        assert_eq!(
            onsets_in_window(&s, 800.0, 1500.0, 1000.0, &lower).current_ms,
            Some(0.0)
        );
    }

    #[test]
    fn motion_under_way_at_the_window_start_is_no_onset_and_no_baseline_is_no_current_onset() {
        let s = series(4000.0, &[(0.0, 3000.0)], 0.0);
        // The window opens at 1 s with the wheels turning since 0: no new motion onset; no samples before 0.
        let l = onsets_in_window(&s, 1000.0, 2500.0, 2000.0, &PhysicalParams::default());
        assert_eq!(l.motion_ms, None);
        assert_eq!(
            onsets_in_window(&s, 0.0, 500.0, 100.0, &PhysicalParams::default()).current_ms,
            None
        );
    }
}
