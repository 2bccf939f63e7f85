//! One learner's row of the `--learners` table, from its runs' timelines (pure: the same runs give the same
//! row). Both runs of pair k answered the same operator, so their commands are the same, one for one; every
//! figure is taken within the pair first and then summarised over the pairs (the operators):
//!
//! - **anticipated command**: the Pavlovian run's decision onset came before the true onset *and* before the
//!   reactive run's decision onset on the same command (the reactive run can "anticipate" by sensor noise,
//!   and then the Pavlovian run does too; only responding earlier than that is learned);
//! - **first anticipated command**: its number (1 = the run's first command) and its onset, minutes;
//! - **anticipation holds** (the one rule): from the first command k such that every block of
//!   [`BLOCK`] consecutive commands starting at k or later has a positive mean decision lead (reactive −
//!   Pavlovian decision onset, over the commands both runs answered); never when the last block's is not;
//! - those four are summarised by their median over pairs with a 95 % percentile bootstrap interval over
//!   pairs ([`median_interval`]), a pair where it never happened counting as later than every other;
//! - **decision and current lead at T min**: the window [T − 5, T) (0–3 min for T = 3), per pair the reactive
//!   run's mean minus the Pavlovian run's, then the mean over pairs with the percentile bootstrap over pairs
//!   ([`paired_mean_difference`], the curve's `pair_leads`);
//! - **anticipated excess**: per pair the Pavlovian run's fraction of commands whose decision came before the
//!   true onset minus the reactive run's, over the first 3 minutes and the whole run, paired the same way;
//! - **false starts per minute**: the Pavlovian run's (a mean over pairs), and its excess over the reactive
//!   run of the same pair with the paired interval, over the first 3 minutes and the whole run.

use pavlov::analysis::bootstrap::{MeanDifference, RESAMPLES, paired_mean_difference};
use pavlov::analysis::interaction::curve::{CommandResult, RunTimeline, pair_leads, pairs};
use pavlov::rng::Rng;
use serde::Serialize;

/// Commands per block of the rule "anticipation holds".
pub const BLOCK: usize = 20;

/// Commands per point of the figure (`by_command`).
pub const FIG_BLOCK: usize = 10;

/// The moments, minutes, at which the leads are given (those within the runs).
pub const LEAD_AT_MIN: [f64; 4] = [3.0, 10.0, 30.0, 60.0];

/// Length of the window ending at each moment, minutes.
pub const LEAD_WINDOW_MIN: f64 = 5.0;

/// The first minutes (the paper's "less than 3 minutes").
pub const FIRST_MIN: f64 = 3.0;

/// A median over pairs with its 95 % percentile-bootstrap interval over pairs; `f64::INFINITY` stands for
/// "never in the run".
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MedianInterval {
    /// The median.
    pub median: f64,
    /// Lower end of the interval.
    pub lo: f64,
    /// Upper end of the interval.
    pub hi: f64,
    /// Pairs in which it never happened.
    pub never: usize,
    /// Pairs.
    pub n: usize,
}

fn median(sorted: &[f64]) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => sorted[n / 2],
        n => {
            let (a, b) = (sorted[n / 2 - 1], sorted[n / 2]);
            if a.is_infinite() || b.is_infinite() {
                a.max(b)
            } else {
                (a + b) / 2.0
            }
        }
    }
}

/// The median of `xs` (infinite = never) with a 95 % percentile-bootstrap interval from `RESAMPLES`
/// resamples of the pairs drawn with `seed`.
pub fn median_interval(xs: &[f64], seed: u64) -> MedianInterval {
    let mut sorted = xs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = xs.len();
    let mut rng = Rng::new(seed);
    let mut medians: Vec<f64> = (0..if n < 2 { 0 } else { RESAMPLES })
        .map(|_| {
            let mut r: Vec<f64> = (0..n).map(|_| xs[rng.below(n as u64) as usize]).collect();
            r.sort_by(f64::total_cmp);
            median(&r)
        })
        .collect();
    medians.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let i = ((medians.len().max(1) - 1) as f64 * q).round() as usize;
        medians.get(i).copied().unwrap_or(f64::NAN)
    };
    MedianInterval {
        median: median(&sorted),
        lo: at(0.025),
        hi: at(0.975),
        never: xs.iter().filter(|x| x.is_infinite()).count(),
        n,
    }
}

/// A rate with the paired excess over the reactive run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FalseStarts {
    /// The Pavlovian runs' false starts per minute, mean over pairs.
    pub pavlovian_per_min: f64,
    /// Pavlovian − reactive false starts per minute, paired over pairs.
    pub excess: Option<MeanDifference>,
}

/// A lead at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LeadAt {
    /// The moment, minutes (the window is [max(0, T − 5), T)).
    pub at_min: f64,
    /// Reactive − Pavlovian decision onset, ms, paired over pairs.
    pub decision: Option<MeanDifference>,
    /// Reactive − Pavlovian battery-current onset, ms, paired over pairs.
    pub current: Option<MeanDifference>,
}

/// One learner's row (see the module documentation).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearnerRow {
    /// The learner's name.
    pub learner: String,
    /// Pairs of runs (operators).
    pub pairs: usize,
    /// Commands per minute the operators gave (Pavlovian runs).
    pub commands_per_min: f64,
    /// The first anticipated command: its number.
    pub first_commands: MedianInterval,
    /// The first anticipated command: its onset, minutes.
    pub first_min: MedianInterval,
    /// Anticipation holds from: the command's number.
    pub holds_commands: MedianInterval,
    /// Anticipation holds from: its onset, minutes.
    pub holds_min: MedianInterval,
    /// The leads at [`LEAD_AT_MIN`] (those within the runs).
    pub leads: Vec<LeadAt>,
    /// Anticipated excess over the first [`FIRST_MIN`] minutes (fraction).
    pub anticipated_first: Option<MeanDifference>,
    /// Anticipated excess over the whole run (fraction).
    pub anticipated: Option<MeanDifference>,
    /// False starts over the first [`FIRST_MIN`] minutes.
    pub false_starts_first: FalseStarts,
    /// False starts over the whole run.
    pub false_starts: FalseStarts,
    /// For the figure: (block's last command number, mean over pairs of the block's decision lead, of its
    /// current lead), ms, per block of [`FIG_BLOCK`] commands.
    pub by_command: Vec<(usize, f64, f64)>,
}

/// The commands of a pair, matched one for one (same onset).
fn matched<'a>(
    r: &'a RunTimeline,
    p: &'a RunTimeline,
) -> impl Iterator<Item = (&'a CommandResult, &'a CommandResult)> {
    r.commands
        .iter()
        .zip(&p.commands)
        .filter(|(a, b)| (a.onset_ms - b.onset_ms).abs() < 1.0)
}

/// Whether the Pavlovian run anticipated the command (see the module documentation).
pub fn anticipated(reactive: &CommandResult, pavlovian: &CommandResult) -> bool {
    pavlovian
        .decision_ms
        .is_some_and(|d| d < 0.0 && reactive.decision_ms.is_none_or(|r| d < r))
}

/// (number, onset in minutes) of the pair's first anticipated command.
pub fn first_anticipated(r: &RunTimeline, p: &RunTimeline) -> Option<(usize, f64)> {
    matched(r, p)
        .enumerate()
        .find(|(_, (a, b))| anticipated(a, b))
        .map(|(i, (_, b))| (i + 1, b.onset_ms / 60_000.0))
}

/// (number, onset in minutes) of the command from which anticipation holds (the rule of the module
/// documentation), or `None`.
pub fn holds_from(r: &RunTimeline, p: &RunTimeline) -> Option<(usize, f64)> {
    let leads: Vec<(usize, f64, f64)> = matched(r, p)
        .enumerate()
        .filter_map(|(i, (a, b))| {
            Some((
                i + 1,
                b.onset_ms / 60_000.0,
                a.decision_ms? - b.decision_ms?,
            ))
        })
        .collect();
    if leads.len() < BLOCK {
        return None;
    }
    let starts = leads.len() - BLOCK + 1;
    let holds = |j: usize| leads[j..j + BLOCK].iter().map(|l| l.2).sum::<f64>() > 0.0;
    let from = match (0..starts).rev().find(|&j| !holds(j)) {
        None => 0,
        Some(j) if j + 1 < starts => j + 1,
        Some(_) => return None,
    };
    leads.get(from).map(|l| (l.0, l.1))
}

fn in_window(c: &CommandResult, from_min: f64, to_min: f64) -> bool {
    let m = c.onset_ms / 60_000.0;
    m >= from_min && m < to_min
}

/// Per pair, the Pavlovian minus the reactive fraction of commands in [from, to) decided before the onset.
fn anticipated_excess(
    runs: &[RunTimeline],
    from: f64,
    to: f64,
    seed: u64,
) -> Option<MeanDifference> {
    let early = |c: &CommandResult| {
        in_window(c, from, to).then(|| f64::from(u8::from(c.decision_ms.is_some_and(|d| d < 0.0))))
    };
    let excess: Vec<f64> = pair_leads(runs, early).into_iter().map(|d| -d).collect();
    paired_mean_difference(&excess, RESAMPLES, seed)
}

fn false_starts(runs: &[RunTimeline], to_min: f64, seed: u64) -> FalseStarts {
    let rate = |r: &RunTimeline| {
        let minutes = to_min.min(r.duration_ms / 60_000.0).max(1e-9);
        r.false_starts_ms
            .iter()
            .filter(|&&t| t < to_min * 60_000.0)
            .count() as f64
            / minutes
    };
    let pav: Vec<f64> = pairs(runs).map(|(_, p)| rate(p)).collect();
    let excess: Vec<f64> = pairs(runs).map(|(r, p)| rate(p) - rate(r)).collect();
    FalseStarts {
        pavlovian_per_min: pav.iter().sum::<f64>() / pav.len().max(1) as f64,
        excess: paired_mean_difference(&excess, RESAMPLES, seed),
    }
}

/// One command's decision and current leads within its pair.
type Leads = (Option<f64>, Option<f64>);

fn by_command(runs: &[RunTimeline]) -> Vec<(usize, f64, f64)> {
    let per_pair: Vec<Vec<Leads>> = pairs(runs)
        .map(|(r, p)| {
            matched(r, p)
                .map(|(a, b)| {
                    let d = a.decision_ms.zip(b.decision_ms).map(|(x, y)| x - y);
                    let c = a.current_ms.zip(b.current_ms).map(|(x, y)| x - y);
                    (d, c)
                })
                .collect()
        })
        .collect();
    let shortest = per_pair.iter().map(Vec::len).min().unwrap_or(0);
    let mean = |xs: Vec<f64>| {
        if xs.is_empty() {
            f64::NAN
        } else {
            xs.iter().sum::<f64>() / xs.len() as f64
        }
    };
    (0..shortest / FIG_BLOCK)
        .map(|b| {
            let block = |pick: fn(&Leads) -> Option<f64>| {
                mean(
                    per_pair
                        .iter()
                        .filter_map(|pp| {
                            let xs: Vec<f64> = pp[b * FIG_BLOCK..(b + 1) * FIG_BLOCK]
                                .iter()
                                .filter_map(pick)
                                .collect();
                            (!xs.is_empty()).then(|| mean(xs))
                        })
                        .collect(),
                )
            };
            ((b + 1) * FIG_BLOCK, block(|x| x.0), block(|x| x.1))
        })
        .collect()
}

/// The row of learner `learner` from its runs (planned order), with bootstrap seeds from `seed`.
pub fn row(learner: &str, runs: &[RunTimeline], seed: u64) -> LearnerRow {
    let never =
        |x: Option<(usize, f64)>| x.map_or((f64::INFINITY, f64::INFINITY), |(k, m)| (k as f64, m));
    let first: Vec<(f64, f64)> = pairs(runs)
        .map(|(r, p)| never(first_anticipated(r, p)))
        .collect();
    let holds: Vec<(f64, f64)> = pairs(runs).map(|(r, p)| never(holds_from(r, p))).collect();
    let col = |v: &[(f64, f64)], k: usize| -> Vec<f64> {
        v.iter().map(|x| if k == 0 { x.0 } else { x.1 }).collect()
    };
    let minutes = runs
        .iter()
        .map(|r| r.duration_ms / 60_000.0)
        .fold(f64::INFINITY, f64::min);
    let leads = LEAD_AT_MIN
        .iter()
        .enumerate()
        .filter(|(_, t)| **t <= minutes + 1e-9)
        .map(|(i, &t)| {
            let from = (t - LEAD_WINDOW_MIN).max(0.0);
            let s = seed ^ (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let lead = |pick: fn(&CommandResult) -> Option<f64>, s: u64| {
                let leads = pair_leads(runs, |c| pick(c).filter(|_| in_window(c, from, t)));
                paired_mean_difference(&leads, RESAMPLES, s)
            };
            LeadAt {
                at_min: t,
                decision: lead(|c| c.decision_ms, s),
                current: lead(|c| c.current_ms, s ^ 1),
            }
        })
        .collect();
    let pav_runs: Vec<&RunTimeline> = runs.iter().filter(|r| r.pavlovian).collect();
    let commands: usize = pav_runs.iter().map(|r| r.commands.len()).sum();
    let pav_minutes: f64 = pav_runs.iter().map(|r| r.duration_ms / 60_000.0).sum();
    LearnerRow {
        learner: learner.to_string(),
        pairs: pairs(runs).count(),
        commands_per_min: commands as f64 / pav_minutes.max(1e-9),
        first_commands: median_interval(&col(&first, 0), seed ^ 11),
        first_min: median_interval(&col(&first, 1), seed ^ 11),
        holds_commands: median_interval(&col(&holds, 0), seed ^ 12),
        holds_min: median_interval(&col(&holds, 1), seed ^ 12),
        leads,
        anticipated_first: anticipated_excess(runs, 0.0, FIRST_MIN, seed ^ 13),
        anticipated: anticipated_excess(runs, 0.0, f64::INFINITY, seed ^ 14),
        false_starts_first: false_starts(runs, FIRST_MIN, seed ^ 15),
        false_starts: false_starts(runs, f64::INFINITY, seed ^ 16),
        by_command: by_command(runs),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A command every 10 s; the reactive run decides at +40 ms (−20 ms on every 5th command: sensor noise,
    /// the Pavlovian run then too), the Pavlovian run at `pav(k)` for command k (1-based).
    fn pair(n: usize, pav: impl Fn(usize) -> f64, false_starts: Vec<f64>) -> [RunTimeline; 2] {
        let run = |pavlovian: bool| RunTimeline {
            pavlovian,
            duration_ms: n as f64 * 10_000.0,
            commands: (1..=n)
                .map(|k| {
                    let noise = k % 5 == 0;
                    let decision = if noise {
                        -20.0
                    } else if pavlovian {
                        pav(k)
                    } else {
                        40.0
                    };
                    CommandResult {
                        onset_ms: k as f64 * 10_000.0,
                        decision_ms: Some(decision),
                        current_ms: Some(decision + 150.0),
                        motion_ms: None,
                    }
                })
                .collect(),
            false_starts_ms: if pavlovian {
                false_starts.clone()
            } else {
                vec![]
            },
        };
        [run(false), run(true)]
    }

    #[test]
    fn the_first_anticipated_command_ignores_the_noise_the_reactive_run_shares() {
        // Commands 5, 10, … are "anticipated" by both runs (noise): not learned. The Pavlovian run
        // anticipates from command 23 on.
        let [r, p] = pair(60, |k| if k >= 23 { -100.0 } else { 40.0 }, vec![]);
        assert_eq!(first_anticipated(&r, &p), Some((23, 23.0 * 10.0 / 60.0)));
        assert_eq!(holds_from(&r, &p), Some((4, 40.0 / 60.0)));
        // Never: identical decisions.
        let [r, p] = pair(60, |_| 40.0, vec![]);
        assert_eq!(first_anticipated(&r, &p), None);
        assert_eq!(holds_from(&r, &p), None);
    }

    #[test]
    fn anticipation_holds_only_when_every_later_block_leads() {
        // Leads of 140 ms from command 30 on, but 40 commands at the end with no lead: never holds.
        let lapse = pair(
            100,
            |k| if (30..60).contains(&k) { -100.0 } else { 40.0 },
            vec![],
        );
        assert_eq!(holds_from(&lapse[0], &lapse[1]), None);
        // Leads from command 30 to the end (30 itself is noise: no lead): the first block with a positive
        // mean is commands 12–31, and every later one leads too.
        let late = pair(100, |k| if k >= 30 { -100.0 } else { 40.0 }, vec![]);
        assert_eq!(holds_from(&late[0], &late[1]).map(|h| h.0), Some(12));
    }

    #[test]
    fn the_row_pairs_each_figure_within_its_operator() {
        // Three pairs anticipating from commands 11, 21 and never (60 commands = 10 min each).
        let mut runs = Vec::new();
        for from in [11, 21, usize::MAX] {
            runs.extend(pair(
                60,
                move |k| if k >= from { -100.0 } else { 40.0 },
                vec![30_000.0],
            ));
        }
        let row = row("x", &runs, 1);
        assert_eq!(row.pairs, 3);
        assert!((row.commands_per_min - 6.0).abs() < 1e-9);
        assert_eq!(row.first_commands.median, 21.0);
        assert_eq!(row.first_commands.never, 1);
        assert!(row.first_commands.hi.is_infinite());
        assert!((row.first_min.median - 3.5).abs() < 1e-9);
        // Leads at 3 and 10 minutes (the runs are 10 min long): at 3 min (0–3 min, commands 1–17) only
        // pair 1 leads, by 140 ms on commands 11–17 except 15 (noise): 6 of its 17 commands.
        assert_eq!(row.leads.len(), 2);
        let d3 = row.leads[0].decision.unwrap();
        assert!(
            (d3.difference - 140.0 * 6.0 / 17.0 / 3.0).abs() < 1e-9,
            "{d3:?}"
        );
        assert_eq!(row.leads[0].current.unwrap().difference, d3.difference);
        // One false start in the first minute of every Pavlovian run: 1/3 a minute over 0–3 min.
        assert!((row.false_starts_first.pavlovian_per_min - 1.0 / 3.0).abs() < 1e-12);
        let fs = row.false_starts_first.excess.unwrap();
        assert!((fs.lo - 1.0 / 3.0).abs() < 1e-12 && (fs.hi - 1.0 / 3.0).abs() < 1e-12);
        assert!((row.false_starts.pavlovian_per_min - 0.1).abs() < 1e-12);
        assert_eq!(row.by_command.len(), 6);
        assert_eq!(row.by_command[0].0, FIG_BLOCK);
        // Block 2 (commands 11–20) of pair 1 leads by 140 ms on 8 of its 10 commands (15 and 20 are
        // noise); the other pairs' by 0.
        assert!((row.by_command[1].1 - 140.0 * 0.8 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn the_median_interval_counts_never_as_latest() {
        let m = median_interval(&[1.0, 2.0, 3.0, f64::INFINITY], 1);
        assert_eq!((m.median, m.never, m.n), (2.5, 1, 4));
        assert!(m.lo >= 1.0 && m.hi.is_infinite());
        let all = median_interval(&[f64::INFINITY; 5], 1);
        assert!(all.median.is_infinite() && all.lo.is_infinite());
        assert!(median_interval(&[], 1).median.is_nan());
    }
}
