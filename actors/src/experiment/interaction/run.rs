//! One interaction run: the simulated operator's skeleton fed straight into the server's pose channel, and
//! what the study measures of the run's ticks against the operator's true commands.
//!
//! Runs alternate reactive / Pavlovian (config/interaction.toml: π = stay still, ϱ = spin left, E = left
//! elbow below 90°), each learning from scratch under tokio's paused clock. Run `i` uses robot seed
//! `Rng::new(seed).fork(i).next_u64()`; both runs of a pair (2k reactive, 2k + 1 Pavlovian) see the same
//! operator, seed `Rng::new(seed).fork(2k).fork(1).next_u64()`: the learner does not depend on the robot, so
//! the policies are compared on the same commands.
//! Per policy: when the response started relative to each ground-truth command onset
//! ([`pavlov::analysis::interaction`]), and the battery current and rotation averaged over the last
//! N observed command onsets of each run (`--commands`, the paper: 40; the paper's Figure 4).

use std::path::PathBuf;
use std::sync::Arc;

use pavlov::analysis::interaction::curve::{CommandResult, RunTimeline};
use pavlov::analysis::interaction::physical::{PhysicalLatency, PhysicalParams, measure_physical};
use pavlov::analysis::interaction::{
    CommandOutcome, CommandWindow, MatchParams, ResponseTiming, measure,
};
use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use pavlov::sim::human::{HumanParams, SimHuman};
use serde::{Deserialize, Serialize};
use tokio_util::sync::CancellationToken;

use super::reduce::{Fig3Tick, Reduced, RunReducer};
use crate::experiment::run_rng;
use crate::experiment::runner::{Collect, RunError, RunRequest, run_paused};
use crate::server::Server;

/// Aligned window: ticks before the onset.
pub(crate) const BEFORE_TICKS: i64 = 25;
/// Aligned window: ticks after the onset.
pub(crate) const AFTER_TICKS: i64 = 50;

/// One observed command onset's aligned window: per offset from [`BEFORE_TICKS`] before to [`AFTER_TICKS`]
/// after, the battery current (mA, `None` when not reported) and the rotation odometry reported (° per tick).
pub(crate) type AlignedWindow = Vec<(Option<f64>, f64)>;

/// One run's outcome (`summary.json` holds it but its aligned windows, timeline and what Figure 3 draws, which only a
/// shard file keeps: [`super::sharded`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InteractionRun {
    /// Position in the interleaved sequence.
    pub(crate) index: usize,
    /// Reactive or Pavlovian.
    pub mode: Mode,
    /// The simulated robot's seed.
    pub(crate) robot_seed: u64,
    /// The simulated operator's seed.
    pub(crate) human_seed: u64,
    /// Response timing against the ground-truth commands.
    pub metrics: ResponseTiming,
    /// The ground-truth commands.
    pub commands: Vec<CommandWindow>,
    /// Per command: when the battery current dropped and the wheels moved, relative to its onset
    /// ([`pavlov::analysis::interaction::physical`]).
    pub physical: Vec<PhysicalLatency>,
    /// Ticks of the observed command onsets used for the aligned averages.
    pub(crate) aligned_onsets: Vec<u64>,
    /// The aligned windows of those onsets (not serialised).
    #[serde(skip)]
    pub(crate) aligned_windows: Vec<AlignedWindow>,
    /// The run reduced for the time course ([`pavlov::analysis::interaction::curve`]; not serialised).
    #[serde(skip)]
    pub(crate) timeline: RunTimeline,
    /// The recording, if written.
    pub recording: Option<PathBuf>,
    /// Wall time, s.
    pub(crate) wall_s: f64,
    /// What Figure 3 draws of every tick, when the run was asked to keep it (the first run of each
    /// policy), else empty (not serialised).
    #[serde(skip)]
    pub figure3: Vec<Fig3Tick>,
}

/// The seeds of run `index`: (robot, operator). The operator is the pair's: runs 2k and 2k + 1 share it.
pub(crate) fn run_seeds(seed: u64, index: usize) -> (u64, u64) {
    let robot = run_rng(seed, index).next_u64();
    let operator = run_rng(seed, index - index % 2).fork(1).next_u64();
    (robot, operator)
}

/// What an interaction run keeps: its ticks reduced as they arrive ([`RunReducer`]), and the simulated
/// operator driving the pose channel.
struct InteractionCollector {
    human: Option<SimHuman>,
    driver: Option<tokio::task::JoinHandle<SimHuman>>,
    cancel: CancellationToken,
    reducer: RunReducer,
}

impl Collect for InteractionCollector {
    type Output = (Reduced, Vec<CommandWindow>);

    const DRIVES_THE_SERVER: bool = true;

    fn start(&mut self, server: &Server) {
        if let Some(human) = self.human.take() {
            self.driver = Some(tokio::spawn(crate::simulated::human::drive_pose(
                human,
                server.pose().clone(),
                server.started(),
                self.cancel.clone(),
            )));
        }
    }

    fn record(&mut self, record: Arc<TickRecord>) {
        self.reducer.push(&record);
    }

    async fn finish(self) -> Result<Self::Output, RunError> {
        self.cancel.cancel();
        let commands = match self.driver {
            Some(driver) => match driver.await {
                Ok(h) => h.commands().iter().map(|&c| c.into()).collect(),
                Err(e) => {
                    return Err(RunError::Collector(format!(
                        "the simulated operator failed: {e}"
                    )));
                }
            },
            None => Vec::new(),
        };
        Ok((self.reducer.finish(), commands))
    }
}

/// What one run is asked to do.
pub(crate) struct RunPlan {
    /// Position in the interleaved sequence.
    pub(crate) index: usize,
    /// Reactive or Pavlovian.
    pub(crate) mode: Mode,
    /// The study's seed.
    pub(crate) seed: u64,
    /// Ticks to run.
    pub(crate) ticks: usize,
    /// How many of the last observed onsets the aligned averages use.
    pub(crate) aligned_commands: usize,
    /// Record the run into this directory.
    pub(crate) record_dir: Option<PathBuf>,
    /// Keep what Figure 3 draws of every tick.
    pub(crate) keep_figure3: bool,
    /// The simulated operator.
    pub(crate) human: HumanParams,
    /// Keep only the response and physical samples (tens of bytes a tick): no aligned windows and
    /// nothing of Figure 3, for studies that need the timeline only.
    pub(crate) lean: bool,
}

/// Runs one interaction run.
pub(crate) fn run(base: &Config, plan: RunPlan) -> Result<InteractionRun, RunError> {
    let RunPlan {
        index,
        mode,
        seed,
        ticks,
        aligned_commands,
        record_dir,
        keep_figure3,
        human,
        lean,
    } = plan;
    let (robot_seed, human_seed) = run_seeds(seed, index);
    let mut config = base.clone();
    config.control.mode = mode;
    config.sim.seed = robot_seed;
    config.skeleton.enabled = Some(false);
    let request = RunRequest {
        config,
        ticks: ticks as u64,
        record: record_dir.map(|d| (d, format!("interaction run {index} {mode:?}"))),
    };
    let collector = InteractionCollector {
        human: Some(SimHuman::new(human, human_seed)),
        driver: None,
        cancel: CancellationToken::new(),
        reducer: if lean {
            RunReducer::new(ticks, 0, false)
        } else {
            RunReducer::new(ticks, aligned_commands, keep_figure3)
        },
    };
    let done = run_paused(request, collector)?;
    let (reduced, commands) = done.output;
    let Reduced {
        samples,
        physical: physical_samples,
        aligned_onsets,
        aligned_windows,
        figure3,
    } = reduced;
    let end_ms = samples.last().map_or(0.0, |r| r.t_ms);
    let commands: Vec<CommandWindow> = commands
        .into_iter()
        .filter(|c| c.onset_ms <= end_ms)
        .collect();
    let metrics = measure(&samples, &commands, &MatchParams::default());
    let physical = measure_physical(
        &physical_samples,
        &commands,
        &MatchParams::default(),
        &PhysicalParams::default(),
    );
    let timeline = RunTimeline {
        pavlovian: mode == Mode::Pavlovian,
        duration_ms: samples.len() as f64 * base.tick.period_ms.max(1) as f64,
        commands: commands
            .iter()
            .zip(&metrics.outcomes)
            .zip(&physical)
            .map(|((c, o), p)| CommandResult {
                onset_ms: c.onset_ms,
                decision_ms: match o {
                    CommandOutcome::Answered { latency_ms } => Some(*latency_ms),
                    _ => None,
                },
                current_ms: p.current_ms,
                motion_ms: p.motion_ms,
            })
            .collect(),
        false_starts_ms: metrics.false_starts_ms.clone(),
    };
    Ok(InteractionRun {
        index,
        mode,
        robot_seed,
        human_seed,
        metrics,
        commands,
        physical,
        aligned_onsets,
        aligned_windows,
        timeline,
        recording: done.recording,
        wall_s: done.wall_s,
        figure3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_runs_of_a_pair_see_the_same_operator_and_pairs_differ() {
        let (r0, h0) = run_seeds(1, 0);
        let (r1, h1) = run_seeds(1, 1);
        let (r2, h2) = run_seeds(1, 2);
        assert_ne!(r0, h0);
        assert_ne!(r0, r1);
        assert_eq!(
            h0, h1,
            "reactive and Pavlovian runs of a pair share the operator"
        );
        assert_ne!(h0, h2, "each pair has its own operator");
        assert_ne!(r1, r2);
        assert_eq!(run_seeds(1, 0), (r0, h0));
        assert_eq!(r0, crate::experiment::stall::run_seed(1, 0));
    }
}
