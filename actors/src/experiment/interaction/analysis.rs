//! The interaction study's statistics over its runs: per-policy response timing, the headline leads
//! (reactive minus Pavlovian onset, positive = the Pavlovian response earlier; taken within each pair of runs
//! that saw the same operator, then over pairs, with 95 % bootstrap intervals over pairs: the physical onsets
//! of current and motion, the debounced decision onset; and the anticipated fraction's excess over the
//! reactive baseline), the aligned averages of
//! battery current and rotation around the observed command onsets (Figure 4), and Welch's tests.

use pavlov::analysis::bootstrap::{MeanDifference, RESAMPLES, paired_mean_difference};
use pavlov::analysis::interaction::curve::{CommandResult, RunTimeline, pair_leads, pairs};
use pavlov::analysis::interaction::physical::PhysicalLatency;
use pavlov::analysis::stats::{Describe, WelchTest, describe, paired_t, welch};
use pavlov::control::Mode;
use serde::Serialize;

use super::run::{BEFORE_TICKS, InteractionRun};

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
    bin: usize,
    value: fn(&(Option<f64>, f64)) -> Option<f64>,
) -> Vec<f64> {
    runs.iter()
        .filter(|r| r.mode == mode)
        .flat_map(|r| r.aligned_windows.iter())
        .filter_map(|w| w.get(bin).and_then(value))
        .filter(|v| v.is_finite())
        .collect()
}

fn current(p: &(Option<f64>, f64)) -> Option<f64> {
    p.0
}

fn angle(p: &(Option<f64>, f64)) -> Option<f64> {
    Some(p.1)
}

/// The aligned averages of every offset.
pub(crate) fn aligned(runs: &[InteractionRun]) -> Vec<AlignedPoint> {
    let bins = runs
        .iter()
        .flat_map(|r| r.aligned_windows.iter().map(Vec::len))
        .max()
        .unwrap_or(0);
    (0..bins)
        .map(|bin| {
            let offset = bin as i64 - BEFORE_TICKS;
            let cr = aligned_values(runs, Mode::Reactive, bin, current);
            let cp = aligned_values(runs, Mode::Pavlovian, bin, current);
            let ar = aligned_values(runs, Mode::Reactive, bin, angle);
            let ap = aligned_values(runs, Mode::Pavlovian, bin, angle);
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
    /// Commands answered before their onset (the debounced decision onset).
    pub anticipated: usize,
    /// `anticipated` over `commands`.
    pub anticipated_fraction: f64,
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
    let commands: usize = mine.iter().map(|r| r.commands.len()).sum();
    let anticipated: usize = mine.iter().map(|r| r.metrics.anticipated()).sum();
    PolicyTiming {
        policy: mode.name().into(),
        commands,
        latency_ms: describe(&latencies),
        current_latency_ms: describe(&physical(|l| l.current_ms)),
        motion_latency_ms: describe(&physical(|l| l.motion_ms)),
        anticipated,
        anticipated_fraction: if commands > 0 {
            anticipated as f64 / commands as f64
        } else {
            f64::NAN
        },
        missed: mine.iter().map(|r| r.metrics.missed()).sum(),
        false_starts_per_minute: per_min(mine.iter().map(|r| r.metrics.false_starts as f64).sum()),
        responding_outside_s_per_minute: per_min(
            mine.iter()
                .map(|r| r.metrics.responding_outside_ms / 1000.0)
                .sum(),
        ),
    }
}

/// The headline leads, paired: both runs of a pair (2k reactive, 2k + 1 Pavlovian) see the same operator, so
/// each is taken within the pair first — the reactive run's mean latency minus the Pavlovian run's (a
/// **lead**: positive = the Pavlovian response came earlier) — and then averaged over the pairs, with a 95 %
/// percentile bootstrap over pairs and a paired t-test. With one pair there is no spread and no interval;
/// with fewer than [`pavlov::analysis::bootstrap::FEW_PAIRS`] pairs the interval is printed with a warning that it is unreliable.
#[derive(Debug, Clone, Serialize)]
pub struct Shifts {
    /// Pairs with both runs.
    pub pairs: usize,
    /// Battery current onset lead, ms: the headline (the robot's physical response, not the control decision).
    pub current_lead_ms: Option<MeanDifference>,
    /// Motion onset (odometry) lead, ms.
    pub motion_lead_ms: Option<MeanDifference>,
    /// The debounced decision (gate) onset lead, ms.
    pub decision_lead_ms: Option<MeanDifference>,
    /// Paired t-test of the decision lead over pairs.
    pub decision_lead_t: Option<WelchTest>,
    /// Fraction of commands whose decision onset came before the true onset: the Pavlovian run's excess
    /// over its reactive partner's (the reactive policy "anticipates" some commands through sensor noise).
    pub anticipated_excess: Option<MeanDifference>,
}

/// The paired leads over the study's runs (in planned order); `seed` fixes the bootstrap.
pub(crate) fn shifts(runs: &[InteractionRun], seed: u64) -> Shifts {
    let timelines: Vec<RunTimeline> = runs.iter().map(|r| r.timeline.clone()).collect();
    let lead = |pick: fn(&CommandResult) -> Option<f64>, s: u64| {
        paired_mean_difference(&pair_leads(&timelines, pick), RESAMPLES, s)
    };
    let anticipated = |c: &CommandResult| {
        Some(if c.decision_ms.is_some_and(|l| l < 0.0) {
            1.0
        } else {
            0.0
        })
    };
    // The excess is Pavlovian − reactive: minus the "lead" of the anticipated indicator.
    let excess: Vec<f64> = pair_leads(&timelines, anticipated)
        .iter()
        .map(|d| 0.0 - d) // not -d: a zero excess prints +0.0, not −0.0
        .collect();
    Shifts {
        pairs: pairs(&timelines).count(),
        current_lead_ms: lead(|c| c.current_ms, seed),
        motion_lead_ms: lead(|c| c.motion_ms, seed ^ 1),
        decision_lead_ms: lead(|c| c.decision_ms, seed ^ 2),
        decision_lead_t: paired_t(&pair_leads(&timelines, |c| c.decision_ms)),
        anticipated_excess: paired_mean_difference(&excess, RESAMPLES, seed ^ 3),
    }
}
