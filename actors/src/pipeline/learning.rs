//! The learning actor: a thin shell over [`pavlov::agent::LearningStage`].
//!
//! For each [`Observation`] it reads the newest pose, acts first (stimulus and predictions go to gating at
//! once) and then learns (the TD(λ) update runs after the prediction has left), but only from a fresh
//! observation ([`pavlov::agent::safety::observation_is_fresh`]). It applies learning's commands
//! (parameters, reset, save, injected human requests) and checkpoints the weights periodically.

use pavlov::agent::learning::request_end;
use pavlov::agent::safety::observation_is_fresh;
use pavlov::agent::{LearnInput, LearnOutput, LearningStage};
use pavlov::config::Config;
use pavlov::learn::LearnError;
use pavlov::learn::checkpoint::Checkpoint;
use pavlov::skeleton::{ElbowFeatureTracker, PoseTracker};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::sensor_ingest::Observation;
use crate::command::{Applied, CommandError, Envelope, Inbox, LearningCommand, Outcome};
use crate::storage::checkpoint_files::CheckpointWriter;

/// Learning's output for one tick.
#[derive(Debug, Clone)]
pub(crate) struct Learned {
    /// The observation it was computed from.
    pub(crate) observation: Observation,
    /// The tick's scheduled time since the run started, ms.
    pub(crate) t_ms: f64,
    /// Stimulus, predictions and the gate's inputs.
    pub(crate) output: LearnOutput,
    /// Whether an injected human request forced the stimulus on (recorded for replay).
    pub(crate) forced_stimulus: bool,
}

/// Learning's state.
pub(crate) struct Learning {
    stage: LearningStage,
    elbows: Option<ElbowFeatureTracker>,
    request_until: u64,
    period_ms: u64,
    checkpoint_dir: std::path::PathBuf,
    autosave: Option<Autosave>,
    /// Ticks learned before this run (from a resumed checkpoint): checkpoints count lifelong ticks.
    tick_offset: u64,
    /// Observations older than this many ticks are not learned from.
    max_obs_age_ticks: u32,
    /// Ticks not learned from because the observation was stale or the link not up.
    skipped_stale: u64,
}

/// Periodic and final checkpoints of the learned state.
struct Autosave {
    config: Config,
    every_ticks: u64,
    last_seq: u64,
    writer: CheckpointWriter,
}

/// True for a bare file name: no directories, no `..`, nothing hidden.
fn is_plain_file_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 128
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
}

impl Learning {
    /// Learning for `config`.
    pub(crate) fn new(config: &Config) -> Result<Self, LearnError> {
        let uses_skeleton = matches!(
            config.control.stimulus,
            pavlov::config::StimulusSpec::LeftElbow { .. }
        );
        Ok(Learning {
            stage: LearningStage::new(config)?,
            elbows: uses_skeleton.then(ElbowFeatureTracker::new),
            request_until: 0,
            period_ms: config.tick.period_ms.max(1),
            checkpoint_dir: config.checkpoint.dir.clone().into(),
            autosave: None,
            tick_offset: 0,
            max_obs_age_ticks: config.safety.max_obs_age_ticks,
            skipped_stale: 0,
        })
    }

    /// Checkpoints into `[checkpoint] dir` every `every_s` seconds of ticks and when the loop ends.
    pub(crate) fn with_autosave(mut self, config: &Config) -> std::io::Result<Self> {
        let c = &config.checkpoint;
        let writer = CheckpointWriter::spawn(c.dir.clone().into(), c.keep)?;
        self.autosave = Some(Autosave {
            config: config.clone(),
            every_ticks: (c.every_s * 1000).div_ceil(self.period_ms),
            last_seq: 0,
            writer,
        });
        Ok(self)
    }

    /// Continues from `checkpoint` (already checked against the configuration).
    pub(crate) fn resume(&mut self, checkpoint: &Checkpoint) -> Result<(), LearnError> {
        self.stage.restore(&checkpoint.state)?;
        self.tick_offset = checkpoint.created_tick;
        Ok(())
    }

    /// A checkpoint of the current state at this run's tick `seq`.
    fn checkpoint(&self, config: &Config, seq: u64) -> Option<Checkpoint> {
        Checkpoint::new(config, self.tick_offset + seq, self.stage.snapshot())
            .map_err(|e| tracing::error!("cannot build a checkpoint: {e}"))
            .ok()
    }

    /// Hands a periodic checkpoint to the writer when one is due.
    fn autosave_if_due(&mut self, seq: u64) {
        let Some(a) = &self.autosave else { return };
        if a.every_ticks == 0 || seq < a.last_seq + a.every_ticks {
            return;
        }
        if let Some(c) = self.checkpoint(&a.config, seq) {
            a.writer.submit(c);
        }
        if let Some(a) = &mut self.autosave {
            a.last_seq = seq;
        }
    }

    /// Writes the final checkpoint and waits until every checkpoint is on disk.
    async fn finish(mut self, seq: u64) {
        let divergences = self.stage.divergences();
        if divergences > 0 {
            tracing::warn!(
                divergences,
                "predictions stopped learning because they diverged"
            );
        }
        if self.skipped_stale > 0 {
            tracing::info!(
                ticks = self.skipped_stale,
                "ticks not learned from: stale observation or link not up"
            );
        }
        let Some(a) = self.autosave.take() else {
            return;
        };
        let last = self.checkpoint(&a.config, seq);
        let writer = a.writer;
        if tokio::task::spawn_blocking(move || writer.finish(last))
            .await
            .is_err()
        {
            tracing::error!("the final checkpoint write panicked");
        }
    }

    /// Names of the observation vector's dimensions.
    pub(crate) fn obs_names(&self) -> Vec<String> {
        self.stage.layout().names().map(str::to_string).collect()
    }

    fn apply(&mut self, cmd: LearningCommand, seq: u64) -> Outcome {
        let rejected = |e: String| CommandError::Rejected(e);
        match cmd {
            LearningCommand::HumanRequest { duration_ms } => {
                // At most MAX_REQUEST_MS: a request forces the stimulus, and so the response, on.
                self.request_until = request_end(seq, duration_ms, self.period_ms)
                    .map_err(|e| rejected(e.to_string()))?;
                Ok(Applied::Request {
                    request_until_tick: self.request_until,
                })
            }
            LearningCommand::SetParams {
                prediction,
                alpha,
                lambda,
                threshold,
            } => self
                .stage
                .set_params(prediction.as_deref(), alpha, lambda, threshold)
                .map(|p| Applied::Params {
                    prediction: p.prediction,
                    alpha: p.alpha,
                    lambda: p.lambda,
                    threshold: p.threshold,
                })
                .map_err(|e| rejected(e.to_string())),
            LearningCommand::ResetWeights {} => {
                self.stage.reset();
                Ok(Applied::Reset { reset: true })
            }
            LearningCommand::SaveWeights { path } => {
                // A client names a file, never a place: it is written inside `[checkpoint] dir`.
                let name = path.unwrap_or_else(|| format!("weights-tick{seq}.json"));
                if !is_plain_file_name(&name) {
                    return Err(rejected(format!(
                        "save_weights takes a file name (letters, digits, '.', '_', '-'; not starting with '.'), \
                         written into the checkpoint directory `{}`; got `{name}`",
                        self.checkpoint_dir.display()
                    )));
                }
                let path = self.checkpoint_dir.join(&name);
                let snapshot = self.stage.snapshot();
                let json =
                    serde_json::to_vec_pretty(&snapshot).map_err(|e| rejected(e.to_string()))?;
                // The disk is not touched on the tick path: the write happens on the blocking pool.
                let (dir, p) = (self.checkpoint_dir.clone(), path.clone());
                tokio::task::spawn_blocking(move || {
                    if let Err(e) =
                        std::fs::create_dir_all(&dir).and_then(|()| std::fs::write(&p, json))
                    {
                        tracing::error!("could not save weights to {}: {e}", p.display());
                    }
                });
                Ok(Applied::Saved {
                    path: path.display().to_string(),
                })
            }
        }
    }
}

/// The channels learning reads and writes.
pub(crate) struct LearningChannels {
    /// Sensor ingest's observations.
    pub(crate) observations: mpsc::Receiver<Observation>,
    /// The newest pose from skeleton ingest.
    pub(crate) pose: watch::Receiver<PoseTracker>,
    /// Learning's commands.
    pub(crate) commands: Inbox<LearningCommand>,
    /// Where each tick's output goes (to gating).
    pub(crate) out: mpsc::Sender<Learned>,
}

/// Runs until `cancel` fires or observations stop.
pub(crate) async fn run(
    mut learning: Learning,
    started: Instant,
    channels: LearningChannels,
    cancel: CancellationToken,
) {
    let LearningChannels {
        mut observations,
        pose,
        mut commands,
        out,
    } = channels;
    let mut seq = 0;
    loop {
        tokio::select! {
            biased;
            _ = cancel.cancelled() => break,
            Some(Envelope { command, reply }) = commands.recv() => {
                let _ = reply.send(learning.apply(command, seq));
            }
            o = observations.recv() => {
                let Some(obs) = o else { break };
                seq = obs.tick.seq;
                let since = obs.tick.deadline.saturating_duration_since(started);
                let now_ms = since.as_millis() as u64;
                let elbow = learning.elbows.as_mut().map(|t| t.step(&pose.borrow(), now_ms));
                let forced_stimulus = seq < learning.request_until;
                let output = learning.stage.act(LearnInput {
                    values: obs.values.as_ref(),
                    elbow,
                    forced_stimulus,
                });
                let fresh = observation_is_fresh(obs.link.state, obs.age_ticks, learning.max_obs_age_ticks);
                let p = Learned {
                    t_ms: since.as_secs_f64() * 1000.0,
                    observation: obs,
                    output,
                    forced_stimulus,
                };
                if out.try_send(p).is_err() {
                    tracing::debug!("gating is behind; a prediction was dropped");
                }
                if fresh {
                    match learning.stage.learn() {
                        Ok(report) => {
                            for name in &report.newly_diverged {
                                tracing::error!(
                                    prediction = %name,
                                    divergences = report.divergences,
                                    "prediction `{name}` diverged: its weights were about to become \
                                     non-finite, so it stopped learning, keeps its last finite weights and \
                                     no longer drives the gate (the stimulus alone does) until reset_weights"
                                );
                            }
                        }
                        Err(e) => tracing::error!("learning step failed: {e}"),
                    }
                } else {
                    learning.skipped_stale += 1;
                }
                learning.autosave_if_due(seq);
            }
        }
    }
    learning.finish(seq).await;
}

#[cfg(test)]
mod tests {
    use super::is_plain_file_name;

    #[test]
    fn only_plain_file_names_are_accepted() {
        for ok in ["w.json", "run-3_weights.json", "a"] {
            assert!(is_plain_file_name(ok), "{ok}");
        }
        for bad in [
            "",
            "../x.json",
            "/etc/passwd",
            "a/b.json",
            ".hidden",
            "..",
            "x y",
            "ü.json",
        ] {
            assert!(!is_plain_file_name(bad), "{bad}");
        }
    }
}
