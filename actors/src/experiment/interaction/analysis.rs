//! The interaction study's statistics over its runs: per-policy response timing, the aligned averages of
//! battery current and rotation around the observed command onsets (Figure 4), and Welch's tests.

use pavlov::analysis::interaction::physical::PhysicalLatency;
use pavlov::analysis::stats::{Describe, WelchTest, describe, welch};
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use serde::Serialize;

use super::run::{AFTER_TICKS, BEFORE_TICKS, InteractionRun};
use crate::experiment::mode_name;

/// One aligned offset.
#[derive(Debug, Clone, Serialize)]
pub struct AlignedPoint {
    /// Ticks from the observed onset.
    pub(crate) offset: i64,
    /// Battery current, mA (negative = discharging), reactive.
    pub(crate) current_reactive: Describe,
    /// The same, Pavlovian.
    pub(crate) current_pavlovian: Describe,
    /// Welch's test of the current, Pavlovian vs reactive.
    pub(crate) current_welch: Option<WelchTest>,
    /// Rotation reported by odometry, degrees per tick, reactive.
    pub(crate) angle_reactive: Describe,
    /// The same, Pavlovian.
    pub(crate) angle_pavlovian: Describe,
    /// Welch's test of the rotation.
    pub(crate) angle_welch: Option<WelchTest>,
}

fn aligned_values(
    runs: &[InteractionRun],
    mode: Mode,
    offset: i64,
    value: fn(&TickRecord) -> Option<f64>,
) -> Vec<f64> {
    runs.iter()
        .filter(|r| r.mode == mode)
        .flat_map(|r| {
            r.aligned_onsets.iter().filter_map(move |&i| {
                let k = usize::try_from(i as i64 + offset).ok()?;
                r.records.get(k).and_then(|t| value(t))
            })
        })
        .collect()
}

fn current(r: &TickRecord) -> Option<f64> {
    r.sensors.battery_current_ma.map(f64::from)
}

fn angle(r: &TickRecord) -> Option<f64> {
    Some(f64::from(r.sensors.angle_deg))
}

/// The aligned averages of every offset.
pub(crate) fn aligned(runs: &[InteractionRun]) -> Vec<AlignedPoint> {
    (-BEFORE_TICKS..=AFTER_TICKS)
        .map(|offset| {
            let cr = aligned_values(runs, Mode::Reactive, offset, current);
            let cp = aligned_values(runs, Mode::Pavlovian, offset, current);
            let ar = aligned_values(runs, Mode::Reactive, offset, angle);
            let ap = aligned_values(runs, Mode::Pavlovian, offset, angle);
            AlignedPoint {
                offset,
                current_reactive: describe(&cr),
                current_pavlovian: describe(&cp),
                current_welch: welch(&cr, &cp),
                angle_reactive: describe(&ar),
                angle_pavlovian: describe(&ap),
                angle_welch: welch(&ar, &ap),
            }
        })
        .collect()
}

/// Per-policy figures of the response timing.
#[derive(Debug, Clone, Serialize)]
pub struct PolicyTiming {
    /// "reactive" or "pavlovian".
    pub policy: String,
    /// Ground-truth commands over the policy's runs.
    pub commands: usize,
    /// Latency of the response onset from the command onset, ms (answered commands).
    pub latency_ms: Describe,
    /// Latency of the battery current's drop from the command onset, ms (commands with one).
    pub current_latency_ms: Describe,
    /// Latency of the wheels' motion onset from the command onset, ms (commands with one).
    pub motion_latency_ms: Describe,
    /// Commands answered before their onset.
    pub anticipated: usize,
    /// Commands with no response.
    pub missed: usize,
    /// Response onsets outside every command window, per minute.
    pub false_starts_per_minute: f64,
    /// Time the response ran outside every command window, s per minute.
    pub(crate) responding_outside_s_per_minute: f64,
}

/// The timing figures of `mode`'s runs.
pub(crate) fn timing(runs: &[InteractionRun], mode: Mode) -> PolicyTiming {
    let mine: Vec<&InteractionRun> = runs.iter().filter(|r| r.mode == mode).collect();
    let latencies: Vec<f64> = mine.iter().flat_map(|r| r.metrics.latencies_ms()).collect();
    let physical = |pick: fn(&PhysicalLatency) -> Option<f64>| -> Vec<f64> {
        mine.iter()
            .flat_map(|r| r.physical.iter().filter_map(pick))
            .collect()
    };
    let minutes: f64 = mine.iter().map(|r| r.metrics.duration_ms / 60_000.0).sum();
    let per_min = |x: f64| if minutes > 0.0 { x / minutes } else { 0.0 };
    PolicyTiming {
        policy: mode_name(mode).into(),
        commands: mine.iter().map(|r| r.commands.len()).sum(),
        latency_ms: describe(&latencies),
        current_latency_ms: describe(&physical(|l| l.current_ms)),
        motion_latency_ms: describe(&physical(|l| l.motion_ms)),
        anticipated: mine.iter().map(|r| r.metrics.anticipated()).sum(),
        missed: mine.iter().map(|r| r.metrics.missed()).sum(),
        false_starts_per_minute: per_min(mine.iter().map(|r| r.metrics.false_starts as f64).sum()),
        responding_outside_s_per_minute: per_min(
            mine.iter()
                .map(|r| r.metrics.responding_outside_ms / 1000.0)
                .sum(),
        ),
    }
}

/// Latencies of both policies compared.
pub(crate) fn latency_test(runs: &[InteractionRun]) -> Option<WelchTest> {
    let lat = |m: Mode| -> Vec<f64> {
        runs.iter()
            .filter(|r| r.mode == m)
            .flat_map(|r| r.metrics.latencies_ms())
            .collect()
    };
    welch(&lat(Mode::Reactive), &lat(Mode::Pavlovian))
}
