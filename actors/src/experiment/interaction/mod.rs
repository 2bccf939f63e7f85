//! The paper's interaction experiment ("Reducing Lag By Predicting the Next Command") on the simulated
//! Create: a simulated operator commands a left spin with the left elbow; runs alternate reactive /
//! Pavlovian (config/interaction.toml: π = stay still, ϱ = spin left, E = left elbow below 90°), each
//! learning from scratch through the one `super::runner`. Run `i` draws its robot seed and its pair's operator seed
//! from `super::run_rng`. Per policy: when the response started relative to each ground-truth command
//! onset ([`pavlov::analysis::interaction`]), and the battery current and rotation averaged over the last
//! N observed command onsets of each run (`--commands`, the paper: 40; the paper's Figure 4); the leads of
//! the physical and decision onsets (positive = Pavlovian earlier), paired within pairs of runs that saw the
//! same operator, with bootstrap intervals over pairs; and the time course over windows of learning
//! ([`pavlov::analysis::interaction::curve`]), from which the Figure 3 analogue takes its moment: when
//! anticipation first holds, or the end of the run.
//!
//! - `run`: one run, its ticks reduced as they arrive (`reduce`: the run keeps a few dozen bytes a
//!   tick, never its records); `analysis`: the statistics; [`report`]: files and the terminal table;
//!   `plots`: the Figure 3 and Figure 4 analogues and the time course; [`sensitivity`]: the study over
//!   operator and learner variants; [`sharded`]: one slice of the study (`--shard I/N`), and merging the
//!   slices back (`assemble` makes the study from its runs, whoever ran them).

pub(crate) mod analysis;
pub(crate) mod plots;
pub(crate) mod reduce;
pub mod report;
pub(crate) mod run;
pub mod sensitivity;
pub mod sharded;

use std::path::PathBuf;

use pavlov::analysis::interaction::curve::{CurvePoint, curve, holds_from, holds_from_paired};
use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::sim::human::HumanParams;
use serde::{Deserialize, Serialize};

use analysis::{AlignedPoint, PolicyTiming, Shifts, aligned, shifts, timing};
use run::{InteractionRun, RunPlan};

use super::interleaved_mode;
use super::runner::{RunError, run_all};

/// The study's settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InteractionOptions {
    /// Runs per policy (the paper: 1).
    pub runs_per_policy: usize,
    /// Minutes per run (the paper: under 10).
    pub minutes: f64,
    /// How many of each run's last observed commands the aligned averages use (the paper: 40).
    pub aligned_commands: usize,
    /// The experiment's seed.
    pub seed: u64,
    /// Record every run.
    pub record: bool,
    /// OS threads.
    pub threads: usize,
    /// Results directory.
    pub out: PathBuf,
    /// Length of a window of the time course, minutes.
    pub window_min: f64,
    /// The simulated operator.
    pub human: HumanParams,
}

impl InteractionOptions {
    /// `runs_per_policy` pairs of `minutes` each, 40 aligned commands, 5-minute windows, the default
    /// operator, not recorded.
    pub fn new(seed: u64, runs_per_policy: usize, minutes: f64, out: PathBuf) -> Self {
        InteractionOptions {
            runs_per_policy,
            minutes,
            aligned_commands: 40,
            seed,
            record: false,
            threads: 2,
            out,
            window_min: 5.0,
            human: HumanParams::default(),
        }
    }
}

/// Everything `summary.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct InteractionStudy {
    /// The settings.
    pub(crate) options: InteractionOptions,
    /// How the seeds are derived.
    pub(crate) seed_derivation: String,
    /// Every run.
    pub runs: Vec<InteractionRun>,
    /// Per-policy response timing.
    pub timing: Vec<PolicyTiming>,
    /// The headline leads (reactive − Pavlovian, positive = Pavlovian earlier), paired within pairs.
    pub shifts: Shifts,
    /// The time course over windows of learning.
    pub curve: Vec<CurvePoint>,
    /// The window from which anticipation holds: the decision lead's two-stage interval above 0 there and in
    /// every later window ([`holds_from`]).
    pub holds_from_window: Option<usize>,
    /// The same rule on the paired decision lead's interval ([`holds_from_paired`]): the rule's sensitivity
    /// to the interval method.
    pub holds_from_window_paired: Option<usize>,
    /// Where the Figure 3 analogue is drawn, minutes into the runs: the middle of the first window from
    /// which anticipation holds, or the end of the run.
    pub fig3_at_min: f64,
    /// Aligned averages around the observed command onsets.
    pub aligned: Vec<AlignedPoint>,
    /// Wall time, s.
    pub(crate) wall_s: f64,
    /// The build and invocation that made the study, and the hash of its configuration.
    pub provenance: crate::provenance::Provenance,
}

/// Runs every run (alternating reactive / Pavlovian) on `threads` threads, with no progress bar.
pub fn run_study(base: &Config, o: &InteractionOptions) -> Result<InteractionStudy, RunError> {
    run_study_with_progress(base, o, false)
}

/// [`run_study`], with a progress bar on stderr when `progress`.
pub fn run_study_with_progress(
    base: &Config,
    o: &InteractionOptions,
    progress: bool,
) -> Result<InteractionStudy, RunError> {
    let wall = std::time::Instant::now();
    let runs = run_runs(base, o, plan(o), progress)?;
    let mut study = assemble(o.clone(), runs, wall.elapsed().as_secs_f64());
    study.provenance = crate::provenance::Provenance::of(base);
    Ok(study)
}

/// The interleaved run list: run `i` and its policy, for `2 × runs_per_policy` runs.
pub(crate) fn plan(o: &InteractionOptions) -> Vec<(usize, Mode)> {
    (0..2 * o.runs_per_policy)
        .map(|i| (i, interleaved_mode(i)))
        .collect()
}

/// Runs the planned runs `specs` (any part of [`plan`]) on `o.threads` threads, in order.
pub(crate) fn run_runs(
    base: &Config,
    o: &InteractionOptions,
    specs: Vec<(usize, Mode)>,
    progress: bool,
) -> Result<Vec<InteractionRun>, RunError> {
    let period_s = base.tick.period_ms.max(1) as f64 / 1000.0;
    let ticks = (o.minutes * 60.0 / period_s).round().max(1.0) as usize;
    let bar = super::progress_bar(specs.len(), progress);
    bar.set_message(format!("{} min each", o.minutes));
    bar.tick();
    let one = |&(i, m): &(usize, Mode)| {
        let dir = o
            .record
            .then(|| o.out.join("runs").join(format!("{i:02}-{}", m.name())));
        run::run(
            base,
            RunPlan {
                index: i,
                mode: m,
                seed: o.seed,
                ticks,
                aligned_commands: o.aligned_commands,
                record_dir: dir,
                // The Figure 3 analogue draws the first run of each policy.
                keep_figure3: i < 2,
                human: o.human.clone(),
            },
        )
    };
    let on_done = |r: &InteractionRun| {
        bar.inc(1);
        bar.set_message(format!(
            "run {} {}: mean latency {} ms, {:.1} s wall",
            r.index,
            r.mode.name(),
            r.metrics
                .mean_latency_ms()
                .map_or("–".into(), |x| format!("{x:.0}")),
            r.wall_s
        ));
    };
    let runs = run_all(&specs, o.threads, &one, &on_done)?;
    bar.finish_and_clear();
    Ok(runs)
}

/// The study from its runs (every planned run, in planned order): the statistics and the bookkeeping. Pure:
/// the same runs give the same study, whichever processes ran them.
pub(crate) fn assemble(
    o: InteractionOptions,
    runs: Vec<InteractionRun>,
    wall_s: f64,
) -> InteractionStudy {
    let timelines: Vec<_> = runs.iter().map(|r| r.timeline.clone()).collect();
    let curve = curve(&timelines, o.window_min, o.seed);
    let holds_from_window = holds_from(&curve);
    let holds_from_window_paired = holds_from_paired(&curve);
    let fig3_at_min = holds_from_window
        .and_then(|w| curve.get(w))
        .map_or(o.minutes, |p| (p.from_min + p.to_min) / 2.0);
    InteractionStudy {
        seed_derivation: "run i (even = reactive, odd = Pavlovian): robot seed \
                          Rng::new(seed).fork(i).next_u64(), operator seed of the pair Rng::new(seed).fork(i - i % 2).fork(1).next_u64() \
                          (both runs of a pair see the same operator)"
            .into(),
        timing: vec![timing(&runs, Mode::Reactive), timing(&runs, Mode::Pavlovian)],
        shifts: shifts(&runs, o.seed),
        curve,
        holds_from_window,
        holds_from_window_paired,
        fig3_at_min,
        aligned: aligned(&runs),
        runs,
        wall_s,
        options: o,
        provenance: crate::provenance::Provenance::of_process(),
    }
}
