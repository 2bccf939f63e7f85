//! The learning actor: a thin shell over [`pavlov::agent::LearningStage`].
//!
//! For each [`Observation`] it reads the newest pose, acts first (stimulus and predictions go to gating at
//! once) and then learns (the TD(λ) update runs after the prediction has left), but only from a fresh
//! observation ([`pavlov::agent::safety::observation_is_fresh`]). It applies learning's commands
//! (parameters, reset, save, injected human requests) and checkpoints the weights periodically.
//!
//! Checkpoints and saves are built here (a copy of the state, between two ticks) and written by the
//! checkpoint writer's thread: automatic ones into this run's folder, saves into `saved/`
//! ([`crate::storage::checkpoint_files`]). A state holding a NaN or an infinity is never checkpointed:
//! the refusal is logged with the prediction's name and counted.

use pavlov::agent::learning::request_end;
use pavlov::agent::safety::observation_is_fresh;
use pavlov::agent::{LearnInput, LearnOutput, LearningStage};
use pavlov::checkpoint::{Checkpoint, CheckpointError};
use pavlov::config::Config;
use pavlov::event::EventKind;
use pavlov::learn::LearnError;
use pavlov::skeleton::{ElbowFeatureTracker, PoseTracker};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::sensor_ingest::Observation;
use crate::bus::EventLog;
use crate::bus::StartState;
use crate::command::{Applied, CommandError, Envelope, Inbox, LearningCommand, Outcome, Reply};
use crate::horde::{HordeHandle, HordeView};
use crate::storage::checkpoint_files::{Announce, CheckpointFiles, SaveJob};

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
    /// The configuration checkpoints are made for.
    config: Config,
    /// Where checkpoints and saves go, and when (the policy is storage's).
    files: CheckpointFiles,
    /// Ticks learned before this run (from a resumed checkpoint): checkpoints count lifelong ticks.
    tick_offset: u64,
    /// Checkpoints and saves refused because a weight, trace or parameter was not finite.
    refused_non_finite: u64,
    /// Observations older than this many ticks are not learned from.
    max_obs_age_ticks: u32,
    /// Ticks not learned from because the observation was stale or the link not up.
    skipped_stale: u64,
    /// The last tick handled (`None` before the first): changes take effect after it.
    after: Option<u64>,
    /// Where changes are announced.
    events: Option<EventLog>,
    /// The Horde, learning `[horde]`'s predictions on its own thread from the ticks offered to it.
    horde: Option<HordeHandle>,
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
            config: config.clone(),
            files: CheckpointFiles::new(&config.checkpoint, config.tick.period_ms),
            tick_offset: 0,
            refused_non_finite: 0,
            max_obs_age_ticks: config.safety.max_obs_age_ticks,
            skipped_stale: 0,
            after: None,
            events: None,
            horde: None,
        })
    }

    /// Offers every tick learned from to `horde` as well.
    pub(crate) fn with_horde(mut self, horde: Option<HordeHandle>) -> Self {
        self.horde = horde;
        self
    }

    /// The Horde's figures, values and names, when there is a Horde.
    pub(crate) fn horde_view(&self) -> Option<HordeView> {
        self.horde.as_ref().map(|h| HordeView {
            status: h.status(),
            values: h.values(),
            names: h.names(),
        })
    }

    /// The lifelong tick this run's tick 0 continues (from a resumed checkpoint).
    pub(crate) fn tick_offset(&self) -> u64 {
        self.tick_offset
    }

    /// Checkpoints into a new run folder, `[checkpoint] dir/runs/<run id>/`, every `every_s` seconds of
    /// ticks and when the loop ends.
    pub(crate) fn with_autosave(mut self) -> std::io::Result<Self> {
        self.files.start_autosave()?;
        Ok(self)
    }

    /// This run's folder of automatic checkpoints (with autosave).
    pub(crate) fn run_dir(&self) -> Option<&std::path::Path> {
        self.files.run_dir()
    }

    /// Continues from `checkpoint` (already checked against the configuration).
    pub(crate) fn resume(&mut self, checkpoint: &Checkpoint) -> Result<(), LearnError> {
        self.stage.restore(&checkpoint.state)?;
        self.tick_offset = checkpoint.created_tick;
        Ok(())
    }

    /// A checkpoint of the current state at this run's tick `seq`. A state with a non-finite number is
    /// refused: logged with the prediction's name, and counted.
    fn checkpoint(&mut self, seq: u64) -> Result<Checkpoint, CheckpointError> {
        let tick = self.tick_offset + seq;
        Checkpoint::new(&self.config, tick, self.stage.snapshot()).inspect_err(|e| {
            if matches!(e, CheckpointError::NonFinite { .. }) {
                self.refused_non_finite += 1;
            }
            tracing::error!(
                tick,
                refused_non_finite = self.refused_non_finite,
                "no checkpoint written: {e}"
            );
        })
    }

    /// Hands a periodic checkpoint to the writer when one is due.
    fn autosave_if_due(&mut self, seq: u64) {
        let Some(run_dir) = self.files.due(seq) else {
            return;
        };
        if let Ok(c) = self.checkpoint(seq) {
            self.files.submit(c, self.announcer());
        }
        if let Some(h) = &self.horde {
            h.checkpoint(&run_dir, self.files.keep());
        }
    }

    /// `save_weights`: checks the name at once, then hands the save to the writer, which answers
    /// `reply` when the file is on disk or refused.
    fn save_weights(&mut self, name: Option<String>, seq: u64, reply: Reply) {
        let rejected = |e: String| Err(CommandError::Rejected(e));
        // A client names a file, never a place: it is written into `[checkpoint] dir/saved/`.
        let (name, unique) = match CheckpointFiles::save_name(name, self.tick_offset + seq) {
            Ok(named) => named,
            Err(e) => {
                let _ = reply.send(rejected(e));
                return;
            }
        };
        let checkpoint = match self.checkpoint(seq) {
            Ok(c) => c,
            Err(e) => {
                let _ = reply.send(rejected(format!("save_weights: {e}")));
                return;
            }
        };
        let announce = self.announcer();
        self.files.save(SaveJob {
            name,
            unique,
            checkpoint,
            reply,
            announce,
        });
    }

    /// Where the checkpoint writer announces what it did (a save, a failure), after the last tick handled.
    fn announcer(&self) -> Option<Announce> {
        self.events.clone().map(|e| (e, self.after))
    }

    /// Announces a change that took effect after the last tick handled.
    fn announce(&self, kind: EventKind) {
        if let Some(events) = &self.events {
            events.emit(self.after, kind);
        }
    }

    /// The learner's state before the first tick, for a recording that begins with the run.
    pub(crate) fn initial_start_state(&self, events: &EventLog) -> StartState {
        StartState {
            after: None,
            events_before: events.next_id(),
            learner: self.stage.stage_snapshot(),
        }
    }

    /// The learner's complete state now, between two ticks, for a recording that begins here.
    pub(crate) fn start_state(&self) -> StartState {
        StartState {
            after: self.after,
            events_before: self.events.as_ref().map_or(0, EventLog::next_id),
            learner: self.stage.stage_snapshot(),
        }
    }

    /// Applies `command`; a save is answered later, by the writer.
    fn command(&mut self, command: LearningCommand, seq: u64, reply: Reply) {
        match command {
            LearningCommand::SaveWeights { path } => self.save_weights(path, seq, reply),
            other => {
                let _ = reply.send(self.apply(other, seq));
            }
        }
    }

    /// Writes the final checkpoint and waits until every checkpoint is on disk.
    pub(crate) async fn finish(mut self, seq: u64) {
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
        if self.stage.skipped_missing_elbow() > 0 {
            tracing::info!(
                ticks = self.stage.skipped_missing_elbow(),
                "ticks not learned from: an elbow angle missing or stale"
            );
        }
        let target = self.files.end_autosave();
        let last = match &target {
            Some(_) => self.checkpoint(seq).ok().map(|c| (c, self.announcer())),
            None => None,
        };
        if let Some(horde) = self.horde.take() {
            // The last Horde checkpoint is copied at once (nothing is learned any more) and written.
            let finished = tokio::task::spawn_blocking(move || {
                horde.finish(target.as_ref().map(|(dir, keep)| (dir.as_path(), *keep)));
            })
            .await;
            if finished.is_err() {
                tracing::error!("the Horde's last checkpoint panicked");
            }
        }
        if self.refused_non_finite > 0 {
            tracing::error!(
                checkpoints = self.refused_non_finite,
                "checkpoints not written in this run because a weight, trace or parameter was not finite"
            );
        }
        if !self.files.writing() {
            return;
        }
        let files = self.files;
        if tokio::task::spawn_blocking(move || files.finish(last))
            .await
            .is_err()
        {
            tracing::error!("the final checkpoint write panicked");
        }
    }

    /// Every prediction's learning parameters in force now (after any checkpoint resumed), in order.
    pub(crate) fn params_in_force(&self) -> Vec<pavlov::agent::learning::ParamsInForce> {
        self.stage
            .predictions()
            .specs()
            .filter_map(|s| self.stage.params(Some(&s.name)))
            .collect()
    }

    /// Names of the observation vector's dimensions.
    pub(crate) fn obs_names(&self) -> Vec<String> {
        self.stage.layout().names().map(str::to_string).collect()
    }

    /// Announces changes on `events` from now on (the Horde too).
    pub(crate) fn attach_events(&mut self, events: EventLog) {
        if let Some(horde) = &self.horde {
            horde.attach_events(events.clone());
        }
        self.events = Some(events);
    }

    /// Acts on `obs`: the tick's stimulus and predictions for gating, and whether the observation is
    /// fresh enough to learn from ([`Learning::learn`], called after the output has gone on). `pose` is
    /// the newest skeleton (read only when the stimulus is an elbow's); `followed` is actuation's last record (its tick, whether its command was the
    /// default policy's, its behaviour probability). The actor and the stepped virtual-time driver
    /// ([`crate::experiment::stepped`]) both call it, so there is one per-tick path.
    pub(crate) fn act(
        &mut self,
        obs: Observation,
        started: Instant,
        pose: &watch::Receiver<PoseTracker>,
        followed: Option<(u64, bool, f64)>,
    ) -> (Learned, bool) {
        let seq = obs.tick.seq;
        self.after = Some(seq);
        let since = obs.tick.deadline.saturating_duration_since(started);
        let now_ms = since.as_millis() as u64;
        let elbow = self.elbows.as_mut().map(|t| t.step(&pose.borrow(), now_ms));
        let forced_stimulus = seq < self.request_until;
        // ρ of the transition into this tick: the previous tick's record, if actuation made one, says
        // whether π was followed; no record (a dropped decision, the watchdog's stop) means it was not.
        let (previous_followed_default, previous_behaviour_prob) = match followed {
            Some((s, true, b)) if s.checked_add(1) == Some(seq) => (true, b),
            _ => (false, 1.0),
        };
        let output = self.stage.act(LearnInput {
            values: obs.values.as_ref(),
            elbow,
            forced_stimulus,
            previous_followed_default,
            previous_behaviour_prob,
        });
        let fresh = observation_is_fresh(obs.link.state, obs.age_ticks, self.max_obs_age_ticks);
        let p = Learned {
            t_ms: since.as_secs_f64() * 1000.0,
            observation: obs,
            output,
            forced_stimulus,
        };
        (p, fresh)
    }

    /// Learns from tick `seq` (when its observation was `fresh`) and checkpoints when one is due.
    pub(crate) fn learn(&mut self, seq: u64, fresh: bool) {
        if fresh {
            if let Some(h) = &mut self.horde {
                h.offer(seq, &self.stage.signals());
            }
            match self.stage.learn() {
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
            self.skipped_stale += 1;
            tracing::debug!(
                tick = seq,
                "not learning from a stale observation or a link that is not up"
            );
        }
        self.autosave_if_due(seq);
    }

    fn apply(&mut self, cmd: LearningCommand, seq: u64) -> Outcome {
        let rejected = |e: String| CommandError::Rejected(e);
        match cmd {
            LearningCommand::HumanRequest { duration_ms } => {
                // At most MAX_REQUEST_MS: a request forces the stimulus, and so the response, on.
                self.request_until = request_end(seq, duration_ms, self.period_ms)
                    .map_err(|e| rejected(e.to_string()))?;
                self.announce(EventKind::HumanRequest {
                    until_tick: self.request_until,
                });
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
                .map(|p| {
                    self.announce(EventKind::ParamsSet {
                        prediction: p.prediction.clone(),
                        alpha: p.alpha,
                        lambda: p.lambda,
                        threshold: p.threshold,
                    });
                    Applied::Params {
                        prediction: p.prediction,
                        alpha: p.alpha,
                        lambda: p.lambda,
                        threshold: p.threshold,
                    }
                })
                .map_err(|e| rejected(e.to_string())),
            LearningCommand::ResetWeights {} => {
                self.stage.reset();
                if let Some(h) = &self.horde {
                    h.reset();
                }
                self.announce(EventKind::WeightsReset);
                Ok(Applied::Reset { reset: true })
            }
            // `command` hands saves to the writer, which answers them; this arm is never reached.
            LearningCommand::SaveWeights { .. } => Err(CommandError::Unavailable(
                "save_weights is answered by the checkpoint writer".into(),
            )),
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
    /// Where changes are announced.
    pub(crate) events: EventLog,
    /// Requests for the learner's state between two ticks (a recording begins).
    pub(crate) snapshots: mpsc::Receiver<oneshot::Sender<StartState>>,
    /// Actuation's last record: its tick and whether its command was the default policy's.
    pub(crate) followed: watch::Receiver<Option<(u64, bool, f64)>>,
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
        events,
        mut snapshots,
        followed,
    } = channels;
    learning.attach_events(events);
    let mut seq = 0;
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            Some(Envelope { command, reply }) = commands.recv() => {
                learning.command(command, seq, reply);
            }
            Some(request) = snapshots.recv() => {
                let _ = request.send(learning.start_state());
            }
            o = observations.recv() => {
                let Some(obs) = o else { break };
                seq = obs.tick.seq;
                let followed = *followed.borrow();
                let (p, fresh) = learning.act(obs, started, &pose, followed);
                if out.try_send(p).is_err() {
                    tracing::debug!("gating is behind; a prediction was dropped");
                }
                learning.learn(seq, fresh);
            }
        }
    }
    learning.finish(seq).await;
}
