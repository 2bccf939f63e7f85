//! The paper's stall experiment ("Reducing Motor Stalls") on the simulated Create.
//!
//! `2 × runs_per_policy` runs are interleaved: run 0 reactive, run 1 Pavlovian, run 2 reactive, … Each run
//! starts a fresh server (learning from scratch) on a simulator whose seed is drawn from the study's seed
//! (`super::run_rng`), through the one `super::runner`.
//!
//! - `run`: what one run keeps (metrics, per-window counts, the Figure 1 excerpt);
//! - [`analysis`]: the statistics; [`report`]: files and the terminal table; `plots`: the SVG figures;
//! - `variations`: the same study under plausible variations (`--variations`), with its forest plot.

pub(crate) mod accuracy;
pub mod analysis;
pub(crate) mod plots;
pub mod policies;
pub mod report;
pub(crate) mod run;
pub mod sharded;
pub mod stochastic;
pub mod variations;
pub(crate) mod variations_forest;

use std::path::PathBuf;
use std::time::Instant;

use pavlov::config::Config;
use serde::{Deserialize, Serialize};

pub(crate) use analysis::analyse;
pub(crate) use report::StallStudy;
pub(crate) use run::{RunResult, RunSpec};

use super::{interleaved_mode, run_all, run_rng};

/// Length of a learning-curve window, seconds.
pub(crate) const WINDOW_S: f64 = 30.0;

/// When the Figure 1 excerpt may start: after 2.5 minutes of learning.
pub(crate) const EXCERPT_AFTER_S: f64 = 150.0;

/// The experiment's settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StallOptions {
    /// Runs per policy (the paper: 10).
    pub runs_per_policy: usize,
    /// Minutes per run (the paper: 6).
    pub minutes: f64,
    /// The experiment's seed; each run's simulator seed is derived from it.
    pub seed: u64,
    /// Write a per-tick recording of every run.
    pub record: bool,
    /// OS threads to run on.
    pub threads: usize,
    /// The results directory.
    pub out: PathBuf,
}

/// The simulator seed of run `index` of an experiment with seed `seed`.
pub fn run_seed(seed: u64, index: usize) -> u64 {
    run_rng(seed, index).next_u64()
}

/// The interleaved run list.
pub fn plan(config: &Config, opts: &StallOptions) -> Vec<RunSpec> {
    let period_s = config.tick.period_ms.max(1) as f64 / 1000.0;
    let ticks = (opts.minutes * 60.0 / period_s).round().max(1.0) as u64;
    let window_ticks = (WINDOW_S / period_s).round().max(1.0) as u64;
    let excerpt_from = (EXCERPT_AFTER_S / period_s).round() as u64;
    // Keep 40 s after 2.5 min: two full policy cycles, enough to find a push against a wall.
    let excerpt_len = (40.0 / period_s) as usize;
    (0..2 * opts.runs_per_policy)
        .map(|index| {
            let mode = interleaved_mode(index);
            let name = format!("{index:02}-{}", mode.name());
            RunSpec {
                index,
                mode,
                seed: run_seed(opts.seed, index),
                ticks,
                window_ticks,
                excerpt_from_tick: (ticks > excerpt_from).then_some(excerpt_from),
                excerpt_len,
                record_dir: opts.record.then(|| opts.out.join("runs").join(name)),
                policy: mode.name().to_string(),
                gate_prediction: None,
                score: None,
                epsilon: None,
            }
        })
        .collect()
}

/// Runs the whole study with `base` as the configuration; `progress` shows a progress bar on stderr.
pub fn run_study(base: &Config, opts: &StallOptions, progress: bool) -> anyhow::Result<StallStudy> {
    let wall = Instant::now();
    let runs = run_runs(base, plan(base, opts), opts, progress)?;
    let mut study = assemble(opts.clone(), runs, wall.elapsed().as_secs_f64());
    study.provenance = Some(crate::provenance::Provenance::of(base));
    Ok(study)
}

/// Runs `specs` on `opts.threads` threads, in order.
fn run_runs(
    base: &Config,
    specs: Vec<RunSpec>,
    opts: &StallOptions,
    progress: bool,
) -> anyhow::Result<Vec<RunResult>> {
    let bar = super::progress_bar(specs.len(), progress);
    let on_done = |r: &RunResult| {
        bar.inc(1);
        bar.set_message(format!(
            "run {} {}: {} over-current, {:.1} s wall",
            r.index,
            r.mode.name(),
            r.metrics.overcurrent_observations,
            r.wall_s
        ));
    };
    let runs = run_all(&specs, opts.threads, &|spec| run::run(base, spec), &on_done)?;
    bar.finish_and_clear();
    Ok(runs)
}

/// The study from its runs (in planned order): the statistics and the bookkeeping.
fn assemble(options: StallOptions, runs: Vec<RunResult>, wall_s: f64) -> StallStudy {
    let analysis = analyse(&runs, WINDOW_S);
    let simulated_s: f64 = runs.iter().map(|r| r.metrics.elapsed_s).sum();
    StallStudy {
        experiment: "stall".into(),
        options,
        seed_derivation: "run i (0-based, even = reactive, odd = Pavlovian) uses simulator seed \
                          Rng::new(seed).fork(i).next_u64() (pavlov::rng: SplitMix64 seeding, xoshiro256++)"
            .into(),
        runs,
        analysis,
        wall_s,
        simulated_s,
        speedup: if wall_s > 0.0 { simulated_s / wall_s } else { 0.0 },
        provenance: Some(crate::provenance::Provenance::of_process()),
    }
}

/// Runs the study, writes every output into `opts.out` and returns the terminal table.
pub fn run_and_report(
    base: &Config,
    opts: &StallOptions,
    progress: bool,
) -> anyhow::Result<String> {
    let study = run_study(base, opts, progress)?;
    report::write_all(&opts.out, &study)?;
    let mut table = report::table(&study);
    table.push_str(&format!("results: {}\n", opts.out.display()));
    for r in &study.runs {
        if r.recorder_dropped > 0 || r.lagged > 0 {
            table.push_str(&format!(
                "warning: run {}: {} records dropped by the recorder queue, {} missed by the analysis\n",
                r.index, r.recorder_dropped, r.lagged
            ));
        }
    }
    Ok(table)
}
