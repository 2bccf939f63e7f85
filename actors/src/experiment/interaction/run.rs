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
use pavlov::analysis::interaction::debounce::{self, COMMAND};
use pavlov::analysis::interaction::live_physical::physical_sample;
use pavlov::analysis::interaction::physical::{
    PhysicalLatency, PhysicalParams, PhysicalSample, measure_physical,
};
use pavlov::analysis::interaction::{
    CommandOutcome, CommandWindow, MatchParams, ResponseSample, ResponseTiming, measure,
};
use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use pavlov::sim::human::{HumanParams, SimHuman};
use serde::{Deserialize, Serialize};
use tokio_util::sync::CancellationToken;

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

/// One run's outcome (`summary.json` holds it but its aligned windows, timeline and records, which only a
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
    /// Every tick when the run was asked to keep them (the runs the Figure 3 analogue draws), else empty
    /// (not serialised).
    #[serde(skip)]
    pub records: Vec<Arc<TickRecord>>,
}

/// The seeds of run `index`: (robot, operator). The operator is the pair's: runs 2k and 2k + 1 share it.
pub(crate) fn run_seeds(seed: u64, index: usize) -> (u64, u64) {
    let robot = run_rng(seed, index).next_u64();
    let operator = run_rng(seed, index - index % 2).fork(1).next_u64();
    (robot, operator)
}

/// What an interaction run keeps: each tick reduced to its response and physical samples as it arrives,
/// every record too unless the run is lean, and the simulated operator driving the pose channel.
struct InteractionCollector {
    human: Option<SimHuman>,
    driver: Option<tokio::task::JoinHandle<SimHuman>>,
    cancel: CancellationToken,
    records: Vec<Arc<TickRecord>>,
    keep_records: bool,
    samples: Vec<ResponseSample>,
    physical: Vec<PhysicalSample>,
}

/// What the collector hands back: the records (empty for a lean run), the samples, the commands.
type Collected = (
    Vec<Arc<TickRecord>>,
    Vec<ResponseSample>,
    Vec<PhysicalSample>,
    Vec<CommandWindow>,
);

impl Collect for InteractionCollector {
    type Output = Collected;

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
        self.samples.push(ResponseSample {
            t_ms: record.t_ms,
            responding: record.gate,
        });
        self.physical.push(physical_sample(&record));
        if self.keep_records {
            self.records.push(record);
        }
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
        Ok((self.records, self.samples, self.physical, commands))
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
    /// Keep every tick record in the result (for the Figure 3 analogue).
    pub(crate) keep_records: bool,
    /// The simulated operator.
    pub(crate) human: HumanParams,
    /// Keep no tick record (only the response and physical samples, tens of bytes a tick): no aligned
    /// windows and no records, for studies that need the timeline only.
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
        keep_records,
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
        records: Vec::with_capacity(if lean { 0 } else { ticks }),
        keep_records: !lean,
        samples: Vec::with_capacity(ticks),
        physical: Vec::with_capacity(ticks),
    };
    let done = run_paused(request, collector)?;
    let (records, samples, physical_samples, commands) = done.output;
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
    let aligned_onsets: Vec<u64> = observed_onsets(&records)
        .into_iter()
        .rev()
        .take(aligned_commands)
        .rev()
        .collect();
    let aligned_windows = aligned_onsets
        .iter()
        .map(|&i| aligned_window(&records, i))
        .collect();
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
        records: if keep_records && !lean {
            records
        } else {
            Vec::new()
        },
    })
}

fn aligned_window(records: &[Arc<TickRecord>], onset: u64) -> AlignedWindow {
    (-BEFORE_TICKS..=AFTER_TICKS)
        .map(|offset| {
            let r = usize::try_from(onset as i64 + offset)
                .ok()
                .and_then(|k| records.get(k));
            (
                r.and_then(|t| t.sensors.battery_current_ma.map(f64::from)),
                r.map_or(f64::NAN, |t| f64::from(t.sensors.angle_deg)),
            )
        })
        .collect()
}

/// Ticks (indices into `records`) of the observed command onsets, debounced ([`debounce::COMMAND`]: the
/// stimulus was off for more than a second before), where the aligned window fits.
pub(crate) fn observed_onsets(records: &[Arc<TickRecord>]) -> Vec<u64> {
    let period = match records {
        [a, b, ..] => b.t_ms - a.t_ms,
        _ => 20.0,
    };
    let mut commands = debounce::Debouncer::new(COMMAND, period);
    let mut out = Vec::new();
    for (i, r) in records.iter().enumerate() {
        if commands.step(r.t_ms, r.stimulus).is_some() {
            let fits = i as i64 >= BEFORE_TICKS && (i as i64 + AFTER_TICKS) < records.len() as i64;
            if fits {
                out.push(i as u64);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(seq: u64, stimulus: bool) -> Arc<TickRecord> {
        Arc::new(TickRecord {
            stimulus,
            gate: stimulus,
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        })
    }

    #[test]
    fn onsets_are_debounced_and_need_room_for_the_aligned_window() {
        // Stimulus at 10 (too early for the window), 100..110, a flicker at 115 (debounced), 200..205,
        // and 300 (too late: the run ends at 320).
        let on = |i: u64| {
            i == 10 || (100..110).contains(&i) || i == 115 || (200..205).contains(&i) || i == 300
        };
        let records: Vec<Arc<TickRecord>> = (0..320).map(|i| rec(i, on(i))).collect();
        assert_eq!(observed_onsets(&records), vec![100, 200]);
    }

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
