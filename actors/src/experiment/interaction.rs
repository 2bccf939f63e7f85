//! The paper's interaction experiment ("Reducing Lag By Predicting the Next Command") on the simulated
//! Create, with the simulated operator's skeleton fed straight into the server's pose channel.
//!
//! Runs alternate reactive / Pavlovian (config/interaction.toml: π = stay still, ϱ = spin left, E = left
//! elbow below 90°), each learning from scratch under tokio's paused clock. Run `i` uses robot seed
//! `Rng::new(seed).fork(i).next_u64()` and operator seed `Rng::new(seed).fork(i).fork(1).next_u64()`.
//! Per policy: when the response started relative to each ground-truth command onset
//! ([`pavlov::interaction_metrics`]), and the battery current and rotation averaged over the last
//! N observed command onsets of each run (`--commands`, the paper: 40; the paper's Figure 4).

use std::path::PathBuf;
use std::sync::Arc;

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::interaction_metrics::live_physical::physical_sample;
use pavlov::interaction_metrics::physical::{PhysicalLatency, PhysicalParams, measure_physical};
use pavlov::interaction_metrics::{
    CommandWindow, InteractionMetrics, MatchParams, ResponseSample, measure,
};
use pavlov::record::TickRecord;
use pavlov::rng::Rng;
use pavlov::sim::human::{HumanParams, SimHuman};
use pavlov::stats::{Describe, WelchTest, describe, welch};
use serde::Serialize;
use tokio::sync::broadcast::error::RecvError;
use tokio_util::sync::CancellationToken;

use super::mode_name;
use super::run::RunError;
use crate::recorder::Recorder;
use crate::recording::RecordingHeader;
use crate::server::{RobotTarget, Server};

/// Aligned window: ticks before the onset.
pub const BEFORE_TICKS: i64 = 25;
/// Aligned window: ticks after the onset.
pub const AFTER_TICKS: i64 = 50;
/// An onset counts only after this many ticks without the stimulus (one gesture can flicker).
pub const DEBOUNCE_TICKS: usize = 50;

/// One run's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct InteractionRun {
    /// Position in the interleaved sequence.
    pub index: usize,
    /// Reactive or Pavlovian.
    pub mode: Mode,
    /// The simulated robot's seed.
    pub robot_seed: u64,
    /// The simulated operator's seed.
    pub human_seed: u64,
    /// Response timing against the ground-truth commands.
    pub metrics: InteractionMetrics,
    /// The ground-truth commands.
    pub commands: Vec<CommandWindow>,
    /// Per command: when the battery current dropped and the wheels moved, relative to its onset
    /// ([`pavlov::interaction_metrics::physical`]).
    pub physical: Vec<PhysicalLatency>,
    /// Ticks of the observed command onsets used for the aligned averages.
    pub aligned_onsets: Vec<u64>,
    /// The recording, if written.
    pub recording: Option<PathBuf>,
    /// Wall time, s.
    pub wall_s: f64,
    /// Every tick (not serialised).
    #[serde(skip)]
    pub records: Vec<Arc<TickRecord>>,
}

/// The seeds of run `index`: (robot, operator).
pub fn run_seeds(seed: u64, index: usize) -> (u64, u64) {
    let run = Rng::new(seed).fork(index as u64);
    (run.clone().next_u64(), run.fork(1).next_u64())
}

/// Runs one interaction run of `ticks` ticks.
pub fn run(
    base: &Config,
    index: usize,
    mode: Mode,
    seed: u64,
    ticks: usize,
    aligned_commands: usize,
    record_dir: Option<PathBuf>,
) -> Result<InteractionRun, RunError> {
    let wall = std::time::Instant::now();
    let (robot_seed, human_seed) = run_seeds(seed, index);
    let mut config = base.clone();
    config.control.mode = mode;
    config.sim.seed = robot_seed;
    config.skeleton.enabled = Some(false);
    let recorder = match &record_dir {
        Some(dir) => Some(
            Recorder::spawn(
                RecordingHeader::new(&config, format!("interaction run {index} {mode:?}")),
                Some(dir.clone()),
                dir.clone(),
                ticks + 64,
            )
            .map_err(RunError::Recorder)?,
        ),
        None => None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .map_err(RunError::Runtime)?;
    let link = recorder.as_ref().map(|r| r.link.clone());
    let outcome = rt.block_on(async move {
        let server = Server::start_with_recorder(config, RobotTarget::Simulated, link)
            .await
            .map_err(|e| RunError::Server(e.to_string()))?;
        let mut rx = server.feed.subscribe();
        let cancel = CancellationToken::new();
        let human = SimHuman::new(HumanParams::default(), human_seed);
        let driver = tokio::spawn(crate::human_sender::drive_pose(
            human,
            server.pose.clone(),
            server.started,
            cancel.clone(),
        ));
        let mut records = Vec::with_capacity(ticks);
        while records.len() < ticks {
            match rx.recv().await {
                Ok(r) => records.push(r),
                Err(RecvError::Lagged(_)) => {}
                Err(RecvError::Closed) => return Err(RunError::FeedClosed(records.len() as u64)),
            }
        }
        cancel.cancel();
        let commands: Vec<CommandWindow> = match driver.await {
            Ok(h) => h.commands().iter().map(|&c| c.into()).collect(),
            Err(e) => {
                return Err(RunError::Server(format!(
                    "the simulated operator failed: {e}"
                )));
            }
        };
        server.shutdown().await;
        Ok((records, commands))
    });
    drop(rt);
    let report = recorder.map(Recorder::join).unwrap_or_default();
    let (records, commands) = outcome?;
    let samples: Vec<ResponseSample> = records
        .iter()
        .map(|r| ResponseSample {
            t_ms: r.t_ms,
            responding: r.gate,
        })
        .collect();
    let end_ms = records.last().map_or(0.0, |r| r.t_ms);
    let commands: Vec<CommandWindow> = commands
        .into_iter()
        .filter(|c| c.onset_ms <= end_ms)
        .collect();
    let metrics = measure(&samples, &commands, &MatchParams::default());
    let physical_samples: Vec<_> = records.iter().map(|r| physical_sample(r)).collect();
    let physical = measure_physical(
        &physical_samples,
        &commands,
        &MatchParams::default(),
        &PhysicalParams::default(),
    );
    let aligned_onsets = observed_onsets(&records)
        .into_iter()
        .rev()
        .take(aligned_commands)
        .rev()
        .collect();
    Ok(InteractionRun {
        index,
        mode,
        robot_seed,
        human_seed,
        metrics,
        commands,
        physical,
        aligned_onsets,
        recording: report.files.first().cloned(),
        wall_s: wall.elapsed().as_secs_f64(),
        records,
    })
}

/// Ticks (indices into `records`) where the stimulus comes on after [`DEBOUNCE_TICKS`] without it, and
/// the aligned window fits.
pub fn observed_onsets(records: &[Arc<TickRecord>]) -> Vec<u64> {
    let mut out = Vec::new();
    let mut quiet = DEBOUNCE_TICKS;
    for (i, r) in records.iter().enumerate() {
        if r.stimulus {
            let fits = i as i64 >= BEFORE_TICKS && (i as i64 + AFTER_TICKS) < records.len() as i64;
            if quiet >= DEBOUNCE_TICKS && fits {
                out.push(i as u64);
            }
            quiet = 0;
        } else {
            quiet += 1;
        }
    }
    out
}

/// One aligned offset.
#[derive(Debug, Clone, Serialize)]
pub struct AlignedPoint {
    /// Ticks from the observed onset.
    pub offset: i64,
    /// Battery current, mA (negative = discharging), reactive.
    pub current_reactive: Describe,
    /// The same, Pavlovian.
    pub current_pavlovian: Describe,
    /// Welch's test of the current, Pavlovian vs reactive.
    pub current_welch: Option<WelchTest>,
    /// Rotation reported by odometry, degrees per tick, reactive.
    pub angle_reactive: Describe,
    /// The same, Pavlovian.
    pub angle_pavlovian: Describe,
    /// Welch's test of the rotation.
    pub angle_welch: Option<WelchTest>,
}

fn aligned_values(
    runs: &[InteractionRun],
    mode: Mode,
    offset: i64,
    value: fn(&TickRecord) -> Option<f64>,
) -> Vec<f64> {
    runs.iter()
        .filter(|r| r.mode == mode)
        .flat_map(|r| {
            r.aligned_onsets.iter().filter_map(move |&i| {
                let k = usize::try_from(i as i64 + offset).ok()?;
                r.records.get(k).and_then(|t| value(t))
            })
        })
        .collect()
}

fn current(r: &TickRecord) -> Option<f64> {
    r.sensors.battery_current_ma.map(f64::from)
}

fn angle(r: &TickRecord) -> Option<f64> {
    Some(f64::from(r.sensors.angle_deg))
}

/// The aligned averages of every offset.
pub fn aligned(runs: &[InteractionRun]) -> Vec<AlignedPoint> {
    (-BEFORE_TICKS..=AFTER_TICKS)
        .map(|offset| {
            let cr = aligned_values(runs, Mode::Reactive, offset, current);
            let cp = aligned_values(runs, Mode::Pavlovian, offset, current);
            let ar = aligned_values(runs, Mode::Reactive, offset, angle);
            let ap = aligned_values(runs, Mode::Pavlovian, offset, angle);
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
    /// Commands answered before their onset.
    pub anticipated: usize,
    /// Commands with no response.
    pub missed: usize,
    /// Response onsets outside every command window, per minute.
    pub false_starts_per_minute: f64,
    /// Time the response ran outside every command window, s per minute.
    pub responding_outside_s_per_minute: f64,
}

/// The timing figures of `mode`'s runs.
pub fn timing(runs: &[InteractionRun], mode: Mode) -> PolicyTiming {
    let mine: Vec<&InteractionRun> = runs.iter().filter(|r| r.mode == mode).collect();
    let latencies: Vec<f64> = mine.iter().flat_map(|r| r.metrics.latencies_ms()).collect();
    let physical = |pick: fn(&PhysicalLatency) -> Option<f64>| -> Vec<f64> {
        mine.iter()
            .flat_map(|r| r.physical.iter().filter_map(pick))
            .collect()
    };
    let minutes: f64 = mine.iter().map(|r| r.metrics.duration_ms / 60_000.0).sum();
    let per_min = |x: f64| if minutes > 0.0 { x / minutes } else { 0.0 };
    PolicyTiming {
        policy: mode_name(mode).into(),
        commands: mine.iter().map(|r| r.commands.len()).sum(),
        latency_ms: describe(&latencies),
        current_latency_ms: describe(&physical(|l| l.current_ms)),
        motion_latency_ms: describe(&physical(|l| l.motion_ms)),
        anticipated: mine.iter().map(|r| r.metrics.anticipated()).sum(),
        missed: mine.iter().map(|r| r.metrics.missed()).sum(),
        false_starts_per_minute: per_min(mine.iter().map(|r| r.metrics.false_starts as f64).sum()),
        responding_outside_s_per_minute: per_min(
            mine.iter()
                .map(|r| r.metrics.responding_outside_ms / 1000.0)
                .sum(),
        ),
    }
}

/// Latencies of both policies compared.
pub fn latency_test(runs: &[InteractionRun]) -> Option<WelchTest> {
    let lat = |m: Mode| -> Vec<f64> {
        runs.iter()
            .filter(|r| r.mode == m)
            .flat_map(|r| r.metrics.latencies_ms())
            .collect()
    };
    welch(&lat(Mode::Reactive), &lat(Mode::Pavlovian))
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
    fn run_seeds_differ_between_runs_and_between_robot_and_operator() {
        let (r0, h0) = run_seeds(1, 0);
        let (r1, h1) = run_seeds(1, 1);
        assert_ne!(r0, h0);
        assert_ne!(r0, r1);
        assert_ne!(h0, h1);
        assert_eq!(run_seeds(1, 0), (r0, h0));
        assert_eq!(r0, crate::experiment::run_seed(1, 0));
    }
}
