//! The paper's stall experiment, reproduced on the simulated Create through the real actor runtime.
//!
//! `2 × runs_per_policy` runs are interleaved: run 0 reactive, run 1 Pavlovian, run 2 reactive, … Each
//! run starts a fresh server (learning from scratch) on a simulator whose seed is derived from the
//! experiment's seed: `Rng::new(seed).fork(index).next_u64()`. Runs go on `threads` OS threads, each run in
//! its own paused-clock runtime, so the results do not depend on the scheduling.
//!
//! - [`run`]: one run; [`analysis`]: the statistics; [`report`]: files and the terminal table;
//!   [`plots`]: the SVG figures.

pub mod analysis;
pub mod cli;
pub mod interaction;
pub mod interaction_plots;
pub mod interaction_report;
pub mod plots;
pub mod report;
pub mod run;
pub mod stall;

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::rng::Rng;
use serde::{Deserialize, Serialize};

pub use analysis::{Analysis, analyse};
pub use run::{RunError, RunResult, RunSpec};

/// Length of a learning-curve window, seconds.
pub const WINDOW_S: f64 = 30.0;

/// When the Figure 1 excerpt may start: after 2.5 minutes of learning.
pub const EXCERPT_AFTER_S: f64 = 150.0;

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
    Rng::new(seed).fork(index as u64).next_u64()
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
            let mode = if index % 2 == 0 {
                Mode::Reactive
            } else {
                Mode::Pavlovian
            };
            let name = format!("{index:02}-{}", mode_name(mode));
            RunSpec {
                index,
                mode,
                seed: run_seed(opts.seed, index),
                ticks,
                window_ticks,
                excerpt_from_tick: (ticks > excerpt_from).then_some(excerpt_from),
                excerpt_len,
                record_dir: opts.record.then(|| opts.out.join("runs").join(name)),
            }
        })
        .collect()
}

/// The policy's name in file names and tables.
pub fn mode_name(mode: Mode) -> &'static str {
    match mode {
        Mode::Reactive => "reactive",
        Mode::Pavlovian => "pavlovian",
        Mode::Manual => "manual",
    }
}

/// Runs every spec on `threads` threads; `progress(done, total, result)` is called as runs finish.
pub fn run_all(
    config: &Config,
    specs: &[RunSpec],
    threads: usize,
    progress: &(dyn Fn(usize, usize, &RunResult) + Sync),
) -> Result<Vec<RunResult>, RunError> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<RunResult, RunError>>>> =
        Mutex::new((0..specs.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, specs.len().max(1)) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(spec) = specs.get(i) else { break };
                    // The servers' own logs (start-up, tick health) would drown the progress bar.
                    let outcome = tracing::subscriber::with_default(
                        tracing::subscriber::NoSubscriber::default(),
                        || run::run(config, spec),
                    );
                    if let Ok(r) = &outcome {
                        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                        progress(d, specs.len(), r);
                    }
                    if let Ok(mut all) = results.lock()
                        && let Some(slot) = all.get_mut(i)
                    {
                        *slot = Some(outcome);
                    }
                    // A failed run stops the others from starting more.
                    if results
                        .lock()
                        .map(|all| all.iter().flatten().any(Result::is_err))
                        .unwrap_or(true)
                    {
                        next.store(specs.len(), Ordering::Relaxed);
                    }
                }
            });
        }
    });
    let all = results.into_inner().unwrap_or_default();
    let mut out = Vec::with_capacity(all.len());
    for r in all {
        match r {
            Some(Ok(r)) => out.push(r),
            Some(Err(e)) => return Err(e),
            None => {}
        }
    }
    Ok(out)
}

/// The progress bar both studies show on stderr (hidden when `visible` is false).
pub fn progress_bar(runs: usize, visible: bool) -> indicatif::ProgressBar {
    let bar = if visible {
        indicatif::ProgressBar::new(runs as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}
