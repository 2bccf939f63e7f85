//! The interaction study in shards: [`run_shard`] runs one slice of the plan and writes
//! `shard-I-of-N.json`; [`merge`] reads the shards back and writes the same summary, tables and figures as
//! the unsharded study (the wall-clock fields aside: the merged `wall_s` is the shards' wall times added up).
//!
//! `summary.json` holds each run without what only the analysis reads (its aligned windows, its timeline and
//! what Figure 3 draws of its ticks); a shard keeps those too (`ShardRun`), so the merged study computes
//! its statistics and figures from the same numbers. Figure 3's ticks are kept only by the runs that keep
//! them in the unsharded study (runs 0 and 1, which the Figure 3 analogue draws), so other shards stay
//! small.

use std::ops::Range;
use std::path::PathBuf;

use pavlov::analysis::interaction::curve::RunTimeline;
use pavlov::config::Config;
use pavlov::control::Mode;
use serde::{Deserialize, Serialize};

use super::reduce::Fig3Tick;
use super::run::{AlignedWindow, InteractionRun, run_seeds};
use super::{InteractionOptions, assemble, plan, report, run_runs};
use crate::experiment::interleaved_mode;
use crate::experiment::results::Placement;
use crate::experiment::shard::{self, MergeError, PlannedRun, Shard};

/// The experiment's name in shard files.
pub const EXPERIMENT: &str = "interaction";

/// One run as a shard file keeps it: the run as `summary.json` has it, and what the analysis reads of it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct ShardRun {
    /// The run (without the fields below, which it does not serialise).
    run: InteractionRun,
    /// Its aligned windows (Figure 4).
    aligned_windows: Vec<AlignedWindow>,
    /// Its timeline (the time course).
    timeline: RunTimeline,
    /// What Figure 3 draws of its ticks, when the study keeps it (runs 0 and 1); else empty.
    figure3: Vec<Fig3Tick>,
}

impl From<InteractionRun> for ShardRun {
    fn from(mut run: InteractionRun) -> Self {
        ShardRun {
            aligned_windows: std::mem::take(&mut run.aligned_windows),
            timeline: std::mem::take(&mut run.timeline),
            figure3: std::mem::take(&mut run.figure3),
            run,
        }
    }
}

impl From<ShardRun> for InteractionRun {
    fn from(s: ShardRun) -> Self {
        InteractionRun {
            aligned_windows: s.aligned_windows,
            timeline: s.timeline,
            figure3: s.figure3,
            ..s.run
        }
    }
}

/// Runs slice `shard` of the study and writes `opts.out/shard-I-of-N.json` (and, when recording, the runs'
/// recordings under `opts.out/runs/`); returns the shard file's path and a one-line summary.
pub fn run_shard(
    base: &Config,
    opts: &InteractionOptions,
    shard: Shard,
    progress: bool,
) -> anyhow::Result<(PathBuf, String)> {
    shard::run_slice(
        EXPERIMENT,
        shard,
        plan(opts),
        &base.redacted(),
        opts,
        &opts.out,
        |specs| {
            let runs = run_runs(base, opts, specs, progress)?;
            Ok(runs.into_iter().map(ShardRun::from).collect::<Vec<_>>())
        },
    )
}

/// Reads the shard files `files`, checks they are exactly the slices of one interaction study and that
/// every run is the one its options plan (index, policy, robot and operator seeds), and writes the study as
/// the unsharded run would have produced it where `place` says (default: a new
/// `results/interaction-<UTC time>-seed<S>/`); returns the terminal table.
pub fn merge(files: &[PathBuf], place: &Placement) -> anyhow::Result<String> {
    let m =
        shard::merge_study::<InteractionOptions, ShardRun>(EXPERIMENT, files, place, check_plan)?;
    let runs = m.runs.into_iter().map(InteractionRun::from).collect();
    let mut study = assemble(m.options, runs, m.wall_s);
    study.provenance = m.provenance;
    report::write_all(&m.out.path, &study)?;
    Ok(
        report::table(&study)
            + &shard::merged_note(files.len(), &m.out.path)
            + &m.out.finish_note(),
    )
}

/// Checks the merged runs against [`plan`]'s: `2 × runs_per_policy` runs, run `i` of policy
/// [`interleaved_mode`]`(i)` with the seeds [`run_seeds`]`(seed, i)`.
fn check_plan(
    opts: &InteractionOptions,
    runs: &[ShardRun],
    sources: &[(Range<usize>, PathBuf)],
) -> Result<(), MergeError> {
    let key = |index, mode: Mode, (robot, operator)| PlannedRun {
        index,
        mode: mode.name(),
        seeds: vec![("robot seed", robot), ("operator seed", operator)],
    };
    shard::check_plan(
        runs,
        sources,
        opts.runs_per_policy.checked_mul(2),
        &format!("runs_per_policy {}", opts.runs_per_policy),
        |i| key(i, interleaved_mode(i), run_seeds(opts.seed, i)),
        |r| {
            key(
                r.run.index,
                r.run.mode,
                (r.run.robot_seed, r.run.human_seed),
            )
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::analysis::interaction::curve::CommandResult;
    use pavlov::analysis::interaction::{CommandOutcome, CommandWindow, ResponseTiming};
    use pavlov::record::TickRecord;

    fn run() -> InteractionRun {
        InteractionRun {
            index: 1,
            mode: Mode::Pavlovian,
            robot_seed: 11,
            human_seed: 12,
            metrics: ResponseTiming {
                outcomes: vec![CommandOutcome::Answered { latency_ms: -0.1 }],
                false_starts: 1,
                false_starts_ms: vec![1234.5],
                responding_outside_ms: 0.1 + 0.2,
                duration_ms: 60_000.0,
            },
            commands: vec![CommandWindow {
                onset_ms: 100.0,
                end_ms: 900.0,
            }],
            physical: Vec::new(),
            aligned_onsets: vec![40],
            aligned_windows: vec![vec![(Some(-1234.25), 0.1 + 0.7), (None, -3.0)]],
            timeline: RunTimeline {
                pavlovian: true,
                duration_ms: 60_000.0,
                commands: vec![CommandResult {
                    onset_ms: 100.0,
                    decision_ms: Some(-0.1),
                    current_ms: None,
                    motion_ms: Some(1.0 / 3.0),
                }],
                false_starts_ms: vec![1234.5],
            },
            recording: None,
            wall_s: 0.5,
            figure3: vec![Fig3Tick::of(&TickRecord::at_rest(
                7,
                140.0,
                Mode::Pavlovian,
            ))],
        }
    }

    #[test]
    fn a_run_travels_through_a_shard_file_exactly() {
        let before = run();
        let json = serde_json::to_string(&ShardRun::from(before.clone())).unwrap();
        let after = InteractionRun::from(serde_json::from_str::<ShardRun>(&json).unwrap());
        // What summary.json shows, and what only the analysis reads, bit for bit.
        assert_eq!(
            serde_json::to_value(&before).unwrap(),
            serde_json::to_value(&after).unwrap()
        );
        assert_eq!(before.aligned_windows, after.aligned_windows);
        assert_eq!(before.timeline, after.timeline);
        assert_eq!(before.figure3, after.figure3);
    }

    #[test]
    fn merged_runs_are_checked_against_the_plan_of_their_options() {
        let opts = InteractionOptions::new(3, 1, 1.0, PathBuf::new());
        let planned = |index: usize| {
            let mut r = run();
            r.index = index;
            r.mode = interleaved_mode(index);
            (r.robot_seed, r.human_seed) = run_seeds(3, index);
            ShardRun::from(r)
        };
        let sources = vec![(0..2, PathBuf::from("shard-0-of-1.json"))];
        let mut runs = vec![planned(0), planned(1)];
        assert!(check_plan(&opts, &runs, &sources).is_ok());
        runs[1].run.human_seed ^= 1;
        let e = check_plan(&opts, &runs, &sources).unwrap_err().to_string();
        assert!(
            e.contains("shard-0-of-1.json: the run at position 1 has operator seed"),
            "{e}"
        );
        runs[1] = planned(1);
        runs[0].run.mode = Mode::Pavlovian;
        let e = check_plan(&opts, &runs, &sources).unwrap_err().to_string();
        assert!(e.contains("position 0 has mode pavlovian"), "{e}");
        let e = check_plan(&opts, &runs[..1], &sources)
            .unwrap_err()
            .to_string();
        assert!(e.contains("hold 1 runs") && e.contains("plan 2"), "{e}");
    }

    #[test]
    fn a_run_that_keeps_no_figure3_ticks_writes_none() {
        let mut r = run();
        r.figure3.clear();
        let v = serde_json::to_value(ShardRun::from(r)).unwrap();
        assert_eq!(v["figure3"], serde_json::json!([]));
        assert!(v["run"].get("figure3").is_none(), "not twice");
    }
}
