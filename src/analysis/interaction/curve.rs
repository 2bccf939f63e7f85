//! The time course of the gesture-command experiment: how anticipation builds up over minutes of learning,
//! from runs of both policies that saw the same operators.
//!
//! Each run is reduced to a [`RunTimeline`]: its ground-truth commands with the decision latency (the
//! debounced gate onset, [`super::measure`]) and the physical latencies (battery current, motion,
//! [`super::physical`]), and its false starts. [`curve`] bins the commands by their onset into windows of
//! learning time, pooling the runs of each policy (several seeds), and gives per window:
//! - the *decision lead*: the reactive runs' mean decision latency minus the Pavlovian runs' (positive = the
//!   Pavlovian control responded earlier). It depends on the operator and the learner only, not on the robot;
//! - the *current lead* and *motion lead*: the same for the physical onsets (positive = the Pavlovian robot
//!   drew current / moved earlier). These also carry the robots' own differences: with lab variation each
//!   run's robot has its own friction and charge, which shift its lags by tens of ms;
//!
//! Every interval is a 95 % two-stage bootstrap over runs, then commands within them
//! ([`crate::analysis::bootstrap::mean_difference_clustered`]), so it carries the spread between runs (robots
//! and operators); with a single run per policy it cannot, and a physical lead then mixes the policy with the
//! two robots' own differences.
//! - the *anticipated fraction* of each policy (decision onset before the true onset) and its difference,
//!   Pavlovian minus reactive, with a bootstrap interval: the reactive policy "anticipates" some commands
//!   too, because sensor noise can take the observed elbow past 90° before the true one, so only the
//!   difference is the learned anticipation;
//! - *false starts per minute* of each policy, with a 95 % interval from the normal approximation to the
//!   Poisson count (0 to 3/minutes for a count of 0).
//!
//! The runs are paired (both runs of a pair, 2k reactive and 2k + 1 Pavlovian, see the same operator), so
//! each window also has a *paired* decision lead ([`CurvePoint::decision_lead_paired`]): per pair, the
//! reactive run's mean decision latency minus the Pavlovian run's, then the mean over pairs with a 95 %
//! percentile bootstrap over pairs ([`crate::analysis::bootstrap::paired_mean_difference`]).
//!
//! **The rule.** *Anticipation holds from* the first window from which the **decision lead**'s 95 % interval
//! lies wholly above 0 in that window and in every later one ([`holds_from`]; the decision lead, not the
//! current lead, because it does not depend on the robot). The window depends on the interval method, so it
//! is computed with both — the two-stage bootstrap ([`holds_from`]) and the paired one
//! ([`holds_from_paired`]) — and the report prints both when they differ. With few pairs the paired interval
//! is too narrow (see [`crate::analysis::bootstrap::FEW_PAIRS`]).

use serde::{Deserialize, Serialize};

use crate::analysis::bootstrap::{
    MeanDifference, RESAMPLES, mean_difference_clustered, paired_mean_difference,
};

/// One ground-truth command and what each measurement made of it (latencies from its onset, ms).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CommandResult {
    /// The true onset, ms from the run's start.
    pub onset_ms: f64,
    /// The debounced gate onset minus the command onset (`None`: missed or already responding).
    pub decision_ms: Option<f64>,
    /// The battery current's onset minus the command onset.
    pub current_ms: Option<f64>,
    /// The motion onset minus the command onset.
    pub motion_ms: Option<f64>,
}

/// One run, reduced.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunTimeline {
    /// Pavlovian (true) or reactive.
    pub pavlovian: bool,
    /// How long the run lasted, ms.
    pub duration_ms: f64,
    /// Its commands in onset order.
    pub commands: Vec<CommandResult>,
    /// Its false starts, ms from the start.
    pub false_starts_ms: Vec<f64>,
}

/// Events per minute with a 95 % interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rate {
    /// Events counted.
    pub count: usize,
    /// Minutes of run they were counted over.
    pub minutes: f64,
    /// count / minutes.
    pub per_minute: f64,
    /// Lower end of the interval.
    pub lo: f64,
    /// Upper end of the interval.
    pub hi: f64,
}

impl Rate {
    /// `count` events in `minutes` (normal approximation to the Poisson count; 0 to 3/minutes for 0).
    pub fn of(count: usize, minutes: f64) -> Self {
        let m = minutes.max(f64::MIN_POSITIVE);
        let c = count as f64;
        let (lo, hi) = if count == 0 {
            (0.0, 3.0 / m)
        } else {
            let half = 1.96 * c.sqrt();
            (((c - half) / m).max(0.0), (c + half) / m)
        };
        Rate {
            count,
            minutes,
            per_minute: c / m,
            lo,
            hi,
        }
    }
}

/// One window of learning time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurvePoint {
    /// Window start, minutes of learning.
    pub from_min: f64,
    /// Window end.
    pub to_min: f64,
    /// Commands in the window over the reactive runs.
    pub commands_reactive: usize,
    /// The same over the Pavlovian runs.
    pub commands_pavlovian: usize,
    /// Reactive minus Pavlovian mean decision latency, ms (positive = Pavlovian earlier).
    pub decision_lead: Option<MeanDifference>,
    /// The decision lead over pairs: per pair (runs 2k, 2k + 1 of `runs`), reactive minus Pavlovian mean
    /// decision latency in the window, then the mean over the pairs with a percentile bootstrap over pairs.
    #[serde(default)]
    pub decision_lead_paired: Option<MeanDifference>,
    /// Reactive minus Pavlovian mean current latency, ms (positive = Pavlovian earlier).
    pub current_lead: Option<MeanDifference>,
    /// Reactive minus Pavlovian mean motion latency, ms.
    pub motion_lead: Option<MeanDifference>,
    /// Fraction of the reactive runs' commands whose decision onset came before the true onset.
    pub anticipated_reactive: f64,
    /// The same for the Pavlovian runs.
    pub anticipated_pavlovian: f64,
    /// Pavlovian minus reactive anticipated fraction.
    pub anticipated_difference: Option<MeanDifference>,
    /// False starts per minute, reactive.
    pub false_starts_reactive: Rate,
    /// False starts per minute, Pavlovian.
    pub false_starts_pavlovian: Rate,
}

fn in_window(t: f64, from_ms: f64, to_ms: f64) -> bool {
    t >= from_ms && t < to_ms
}

/// Per-window figures over `runs` with windows of `window_min` minutes, up to the end of the shortest run;
/// `seed` fixes the bootstrap.
pub fn curve(runs: &[RunTimeline], window_min: f64, seed: u64) -> Vec<CurvePoint> {
    let window_ms = window_min.max(1e-3) * 60_000.0;
    let shortest = runs
        .iter()
        .map(|r| r.duration_ms)
        .fold(f64::INFINITY, f64::min);
    if !shortest.is_finite() {
        return Vec::new();
    }
    let windows = (shortest / window_ms + 1e-9).floor() as usize;
    (0..windows)
        .map(|w| {
            let (from, to) = (w as f64 * window_ms, (w + 1) as f64 * window_ms);
            // Per run of a policy, its commands in the window.
            let commands = |pavlovian: bool| -> Vec<Vec<&CommandResult>> {
                runs.iter()
                    .filter(|r| r.pavlovian == pavlovian)
                    .map(|r| {
                        r.commands
                            .iter()
                            .filter(|c| in_window(c.onset_ms, from, to))
                            .collect()
                    })
                    .collect()
            };
            let (rc, pc) = (commands(false), commands(true));
            let pick = |runs: &[Vec<&CommandResult>],
                        f: fn(&CommandResult) -> Option<f64>|
             -> Vec<Vec<f64>> {
                runs.iter()
                    .map(|cs| cs.iter().filter_map(|c| f(c)).collect())
                    .collect()
            };
            let anticipated = |c: &CommandResult| -> Option<f64> {
                Some(if c.decision_ms.is_some_and(|l| l < 0.0) {
                    1.0
                } else {
                    0.0
                })
            };
            let s = seed ^ (w as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let (ar, ap) = (pick(&rc, anticipated), pick(&pc, anticipated));
            let fraction = |xs: &[Vec<f64>]| {
                let n: usize = xs.iter().map(Vec::len).sum();
                if n == 0 {
                    f64::NAN
                } else {
                    xs.iter().flatten().sum::<f64>() / n as f64
                }
            };
            let rate = |pavlovian: bool| {
                let count = runs
                    .iter()
                    .filter(|r| r.pavlovian == pavlovian)
                    .flat_map(|r| r.false_starts_ms.iter())
                    .filter(|&&t| in_window(t, from, to))
                    .count();
                let n = runs.iter().filter(|r| r.pavlovian == pavlovian).count();
                Rate::of(count, window_min * n as f64)
            };
            CurvePoint {
                from_min: w as f64 * window_min,
                to_min: (w + 1) as f64 * window_min,
                commands_reactive: rc.iter().map(Vec::len).sum(),
                commands_pavlovian: pc.iter().map(Vec::len).sum(),
                decision_lead: mean_difference_clustered(
                    &pick(&rc, |c| c.decision_ms),
                    &pick(&pc, |c| c.decision_ms),
                    RESAMPLES,
                    s ^ 3,
                ),
                decision_lead_paired: paired_mean_difference(
                    &pair_leads(runs, |c| {
                        c.decision_ms.filter(|_| in_window(c.onset_ms, from, to))
                    }),
                    RESAMPLES,
                    s ^ 4,
                ),
                current_lead: mean_difference_clustered(
                    &pick(&rc, |c| c.current_ms),
                    &pick(&pc, |c| c.current_ms),
                    RESAMPLES,
                    s,
                ),
                motion_lead: mean_difference_clustered(
                    &pick(&rc, |c| c.motion_ms),
                    &pick(&pc, |c| c.motion_ms),
                    RESAMPLES,
                    s ^ 1,
                ),
                anticipated_reactive: fraction(&ar),
                anticipated_pavlovian: fraction(&ap),
                anticipated_difference: mean_difference_clustered(&ap, &ar, RESAMPLES, s ^ 2),
                false_starts_reactive: rate(false),
                false_starts_pavlovian: rate(true),
            }
        })
        .collect()
}

/// The pairs of `runs` in planned order: runs 2k (reactive) and 2k + 1 (Pavlovian); a chunk that is not
/// such a pair is skipped.
pub fn pairs(runs: &[RunTimeline]) -> impl Iterator<Item = (&RunTimeline, &RunTimeline)> {
    runs.chunks_exact(2).filter_map(|c| match c {
        [r, p] if !r.pavlovian && p.pavlovian => Some((r, p)),
        _ => None,
    })
}

/// Per pair, the reactive run's mean of `pick` over its commands minus the Pavlovian run's (positive = the
/// Pavlovian run earlier); a pair where either run has no value is left out.
pub fn pair_leads(runs: &[RunTimeline], pick: impl Fn(&CommandResult) -> Option<f64>) -> Vec<f64> {
    let mean = |r: &RunTimeline| {
        let xs: Vec<f64> = r.commands.iter().filter_map(&pick).collect();
        (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64)
    };
    pairs(runs)
        .filter_map(|(r, p)| Some(mean(r)? - mean(p)?))
        .collect()
}

/// The rule (module doc): the first window from which the two-stage decision lead's interval lies above 0
/// in that and every later window.
pub fn holds_from(points: &[CurvePoint]) -> Option<usize> {
    holds_from_by(points, |p| p.decision_lead)
}

/// The same rule on the paired decision lead's interval.
pub fn holds_from_paired(points: &[CurvePoint]) -> Option<usize> {
    holds_from_by(points, |p| p.decision_lead_paired)
}

fn holds_from_by(
    points: &[CurvePoint],
    lead: impl Fn(&CurvePoint) -> Option<MeanDifference>,
) -> Option<usize> {
    let holds = |p: &CurvePoint| lead(p).is_some_and(|d| d.above_zero());
    let last_failure = points.iter().rposition(|p| !holds(p));
    match last_failure {
        None if !points.is_empty() => Some(0),
        None => None,
        Some(i) if i + 1 < points.len() => Some(i + 1),
        Some(_) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run with a command every 10 s for `minutes`, each answered by the gate at `decision(t)` and by the
    /// current at `current(t)` ms after its onset (t = minutes into the run).
    fn run(
        pavlovian: bool,
        minutes: f64,
        decision: impl Fn(f64) -> f64,
        current: impl Fn(f64) -> f64,
    ) -> RunTimeline {
        let n = (minutes * 6.0) as usize;
        RunTimeline {
            pavlovian,
            duration_ms: minutes * 60_000.0,
            commands: (0..n)
                .map(|k| {
                    let onset_ms = 5_000.0 + k as f64 * 10_000.0;
                    let t = onset_ms / 60_000.0;
                    CommandResult {
                        onset_ms,
                        decision_ms: Some(decision(t)),
                        current_ms: Some(current(t)),
                        motion_ms: Some(current(t) + 150.0),
                    }
                })
                .collect(),
            false_starts_ms: if pavlovian {
                vec![61_000.0, 62_000.0]
            } else {
                vec![]
            },
        }
    }

    #[test]
    fn anticipation_builds_up_and_holds_from_the_window_where_the_lead_is_clear() {
        // Reactive: decision at +20 (every 4th at −20, sensor noise), current at +150 ± 10 ms. Pavlovian: the
        // same for the first 4 minutes, then 100 ms earlier.
        let jitter = |t: f64| ((t * 600.0).round() % 3.0 - 1.0) * 10.0;
        let reactive_decision = |t: f64| {
            if ((t * 6.0).round() as i64) % 4 == 0 {
                -20.0
            } else {
                20.0
            }
        };
        let runs = vec![
            run(false, 10.0, reactive_decision, |t| 150.0 + jitter(t)),
            run(
                true,
                10.0,
                move |t| reactive_decision(t) - if t >= 4.0 { 100.0 } else { 0.0 },
                move |t| 150.0 + jitter(t) - if t >= 4.0 { 100.0 } else { 0.0 },
            ),
        ];
        let c = curve(&runs, 2.0, 7);
        assert_eq!(c.len(), 5);
        assert_eq!((c[0].commands_reactive, c[0].commands_pavlovian), (12, 12));
        let lead0 = c[0].current_lead.unwrap();
        assert!(lead0.lo <= 0.0 && lead0.hi >= 0.0, "{lead0:?}");
        let lead4 = c[4].current_lead.unwrap();
        assert!((lead4.difference - 100.0).abs() < 1e-9 && lead4.above_zero());
        assert!(c[0].decision_lead.unwrap().difference.abs() < 1e-9);
        assert!((c[4].decision_lead.unwrap().difference - 100.0).abs() < 1e-9);
        assert_eq!(holds_from(&c), Some(2));
        // The reactive baseline anticipates a quarter of its commands; only the Pavlovian excess counts.
        assert!((c[0].anticipated_reactive - 0.25).abs() < 0.1, "{:?}", c[0]);
        assert!(c[0].anticipated_difference.unwrap().difference.abs() < 1e-9);
        assert!(c[4].anticipated_difference.unwrap().above_zero());
        // Two Pavlovian false starts in minute 1: window 0 (2 minutes of one run).
        assert_eq!(c[0].false_starts_pavlovian.count, 2);
        assert_eq!(c[0].false_starts_pavlovian.per_minute, 1.0);
        assert_eq!(c[1].false_starts_pavlovian.count, 0);
        assert_eq!(c[1].false_starts_pavlovian.hi, 1.5);
    }

    #[test]
    fn anticipation_that_lapses_at_the_end_does_not_hold_and_no_runs_give_no_curve() {
        let runs = vec![
            run(false, 6.0, |t| 20.0 + (t * 100.0).sin(), |_| 150.0),
            run(
                true,
                6.0,
                |t| 20.0 + (t * 100.0).sin() - if t < 4.0 { 80.0 } else { 0.0 },
                |_| 100.0,
            ),
        ];
        let c = curve(&runs, 2.0, 1);
        assert!(c[0].decision_lead.unwrap().above_zero());
        // The physical lead alone does not make anticipation hold.
        assert!(c[2].current_lead.unwrap().above_zero());
        assert_eq!(holds_from(&c), None);
        assert!(curve(&[], 2.0, 1).is_empty());
        assert_eq!(holds_from(&[]), None);
    }

    #[test]
    fn paired_leads_take_differences_within_pairs_and_the_rule_is_computed_both_ways() {
        // Four pairs; each pair's operator shifts both of its runs by a large amount (±80 ms), and the
        // Pavlovian run is exactly 30 ms earlier than its reactive partner. Within pairs the lead is 30 ms
        // every time; unpaired, the operators' spread swamps it.
        let offsets = [0.0, 80.0, -80.0, 40.0];
        let mut runs = Vec::new();
        for o in offsets {
            runs.push(run(false, 4.0, move |_| 100.0 + o, |_| 150.0));
            runs.push(run(true, 4.0, move |_| 70.0 + o, |_| 150.0));
        }
        let leads = pair_leads(&runs, |c| c.decision_ms);
        assert_eq!(leads, vec![30.0; 4]);
        let c = curve(&runs, 2.0, 5);
        let paired = c[0].decision_lead_paired.unwrap();
        assert_eq!(
            (paired.difference, paired.lo, paired.hi),
            (30.0, 30.0, 30.0)
        );
        assert_eq!(paired.n_minuend, 4);
        let clustered = c[0].decision_lead.unwrap();
        assert!((clustered.difference - 30.0).abs() < 1e-9);
        assert!(clustered.lo < 0.0, "{clustered:?}");
        assert_eq!(holds_from_paired(&c), Some(0));
        assert_eq!(holds_from(&c), None);
        // Runs out of pair order are not paired.
        let swapped = [runs[1].clone(), runs[0].clone()];
        assert!(pair_leads(&swapped, |c| c.decision_ms).is_empty());
        // One pair: a lead with no spread, and no window where it "holds".
        let one = curve(&runs[..2], 2.0, 5);
        let p = one[0].decision_lead_paired.unwrap();
        assert!(p.difference == 30.0 && p.lo.is_nan() && !p.above_zero());
        assert_eq!(holds_from_paired(&one), None);
    }
}
