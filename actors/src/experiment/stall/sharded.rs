//! The stall study in shards: [`run_shard`] runs one slice of the plan and writes `shard-I-of-N.json`;
//! [`merge`] reads the shards back and writes the same summary, tables and figures as [`super::run_and_report`]
//! (the wall-clock fields aside: the merged `wall_s` is the shards' wall times added up).
//!
//! A shard keeps, besides each run's result, the Figure 1 excerpt of the first run of each policy that has
//! one; the unsharded study draws the first such run of each policy, which is always one of those.

use std::ops::Range;
use std::path::PathBuf;

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use super::report;
use super::{RunResult, StallOptions, assemble, plan, run_runs, run_seed};
use crate::experiment::interleaved_mode;
use crate::experiment::results::Placement;
use crate::experiment::shard::{self, MergeError, PlannedRun, Shard};

/// The experiment's name in shard files.
pub const EXPERIMENT: &str = "stall";

/// One run as a shard file keeps it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardRun {
    /// The run's result.
    pub result: RunResult,
    /// Its Figure 1 excerpt (empty unless it is the shard's first run of its policy with one).
    pub excerpt: Vec<TickRecord>,
}

/// Runs slice `shard` of the study and writes `opts.out/shard-I-of-N.json` (and the runs' recordings under
/// `opts.out/runs/`); returns the shard file's path and a one-line summary.
pub fn run_shard(
    base: &Config,
    opts: &StallOptions,
    shard: Shard,
    progress: bool,
) -> anyhow::Result<(PathBuf, String)> {
    shard::run_slice(
        EXPERIMENT,
        shard,
        plan(base, opts),
        &base.redacted(),
        opts,
        &opts.out,
        |specs| {
            let mut seen: Vec<Mode> = Vec::new();
            let runs = run_runs(base, specs, opts, progress)?;
            Ok(runs
                .into_iter()
                .map(|mut r| {
                    let keep = !r.excerpt.is_empty() && !seen.contains(&r.mode);
                    if keep {
                        seen.push(r.mode);
                    }
                    let excerpt = if keep {
                        std::mem::take(&mut r.excerpt)
                    } else {
                        Vec::new()
                    };
                    ShardRun { result: r, excerpt }
                })
                .collect::<Vec<_>>())
        },
    )
}

/// Reads the shard files `files`, checks they are exactly the slices of one stall study and that every run
/// is the one its options plan (index, policy, simulator seed), and writes the study as the unsharded run
/// would have produced it where `place` says (default: a new `results/stall-<UTC time>-seed<S>/`, as the
/// unsharded study's); returns the terminal table.
pub fn merge(files: &[PathBuf], place: &Placement) -> anyhow::Result<String> {
    let m = shard::merge_study::<StallOptions, ShardRun>(EXPERIMENT, files, place, check_plan)?;
    let runs = m
        .runs
        .into_iter()
        .map(|r| RunResult {
            excerpt: r.excerpt,
            ..r.result
        })
        .collect();
    let mut study = assemble(m.options, runs, m.wall_s);
    study.provenance = Some(m.provenance);
    report::write_all(&m.out.path, &study)?;
    Ok(
        report::table(&study)
            + &shard::merged_note(files.len(), &m.out.path)
            + &m.out.finish_note(),
    )
}

/// Checks the merged runs against [`plan`]'s: `2 × runs_per_policy` runs, run `i` of policy
/// [`interleaved_mode`]`(i)` with simulator seed [`run_seed`]`(seed, i)`.
fn check_plan(
    opts: &StallOptions,
    runs: &[ShardRun],
    sources: &[(Range<usize>, PathBuf)],
) -> Result<(), MergeError> {
    let key = |index, mode: Mode, seed| PlannedRun {
        index,
        mode: mode.name(),
        seeds: vec![("seed", seed)],
    };
    shard::check_plan(
        runs,
        sources,
        opts.runs_per_policy.checked_mul(2),
        &format!("runs_per_policy {}", opts.runs_per_policy),
        |i| key(i, interleaved_mode(i), run_seed(opts.seed, i)),
        |r| key(r.result.index, r.result.mode, r.result.seed),
    )
}
