//! The actuation actor: the only writer of motion commands, and the robot's last line of safety.
//!
//! For each decision it writes Drive Direct (right wheel first) through the link writer, unless the e-stop is
//! latched, the observation behind the decision is stale, the link is not up (stale, reconnecting) or the
//! robot has tripped to Passive — then it writes a stop. On
//! every tick it also checks that a fresh decision has arrived; after `max_action_age_ticks` ticks without
//! one (a stalled pipeline) it stops the wheels by itself. It then assembles the tick's [`TickRecord`] and
//! publishes it to the feed (dashboard, recorder, metrics).

use std::sync::Arc;

use pavlov::config::SafetyConfig;
use pavlov::control::Action;
use pavlov::oi::Model;
use pavlov::oi::command::Command;
use pavlov::record::{SafetyStop, TickRecord};
use pavlov::supervision::LinkState;
use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;

use crate::feed::TickFeed;
use crate::gating::Decision;
use crate::link::writer::WriteRequest;
use crate::ticker::Tick;

/// Actuation's counters.
#[derive(Debug, Default, Clone, Copy, serde::Serialize)]
pub struct ActuationStats {
    /// Commands written.
    pub commands: u64,
    /// Stops forced because no fresh decision arrived.
    pub pipeline_stalls: u64,
    /// Stops forced by a stale observation.
    pub stale_observations: u64,
    /// Commands the writer queue could not take.
    pub writer_full: u64,
}

/// Actuation's state.
pub struct Actuation {
    model: Model,
    safety: SafetyConfig,
    last_decision_seq: Option<u64>,
    last_written: Option<Action>,
    stats: ActuationStats,
}

impl Actuation {
    /// Actuation for `model` with the given safety limits.
    pub fn new(model: Model, safety: SafetyConfig) -> Self {
        Actuation {
            model,
            safety,
            last_decision_seq: None,
            last_written: None,
            stats: ActuationStats::default(),
        }
    }

    /// The safety override for a decision, if any.
    fn safety_stop(&self, d: &Decision, estop: bool) -> Option<SafetyStop> {
        let obs = &d.prediction.observation;
        if estop {
            Some(SafetyStop::EStop)
        } else if obs.link.state == LinkState::Tripped {
            Some(SafetyStop::RobotTripped)
        } else if obs.link.state != LinkState::Up {
            Some(SafetyStop::LinkDown)
        } else if obs
            .age_ticks
            .is_none_or(|age| age > self.safety.max_obs_age_ticks)
        {
            Some(SafetyStop::StaleObservation)
        } else {
            None
        }
    }

    fn write(&mut self, action: Action, tick: Option<&Tick>, writer: &mpsc::Sender<WriteRequest>) {
        let cmd = Command::DriveDirect {
            right: action.right_mm_s,
            left: action.left_mm_s,
        };
        match cmd.encode(self.model) {
            Ok(bytes) => {
                let req = WriteRequest {
                    bytes,
                    tick_deadline: tick.map(|t| t.deadline),
                };
                if writer.try_send(req).is_err() {
                    self.stats.writer_full += 1;
                } else {
                    self.stats.commands += 1;
                    self.last_written = Some(action);
                }
            }
            Err(e) => tracing::error!("cannot encode {action:?}: {e}"),
        }
    }

    /// Handles one decision: writes the command and returns the tick's record.
    pub fn on_decision(
        &mut self,
        d: Decision,
        estop: bool,
        writer: &mpsc::Sender<WriteRequest>,
    ) -> TickRecord {
        let stop = self.safety_stop(&d, estop);
        if stop == Some(SafetyStop::StaleObservation) {
            self.stats.stale_observations += 1;
        }
        let command = if stop.is_some() {
            Action::STOP
        } else {
            d.gate.action
        };
        let tick = d.prediction.observation.tick;
        self.last_decision_seq = Some(tick.seq);
        self.write(command, Some(&tick), writer);
        d.into_record(command, stop, estop)
    }

    /// Called on every tick: stops the wheels when the pipeline has not delivered a decision in time.
    pub fn on_tick(&mut self, tick: &Tick, writer: &mpsc::Sender<WriteRequest>) -> bool {
        let behind = match self.last_decision_seq {
            Some(seq) => tick.seq.saturating_sub(seq) > self.safety.max_action_age_ticks as u64,
            None => tick.seq >= self.safety.max_action_age_ticks as u64,
        };
        if behind && self.last_written != Some(Action::STOP) {
            tracing::warn!(
                tick = tick.seq,
                "no fresh action for {} ticks: stopping the wheels",
                self.safety.max_action_age_ticks
            );
            self.stats.pipeline_stalls += 1;
            self.write(Action::STOP, Some(tick), writer);
        }
        behind
    }

    /// Counters so far.
    pub fn stats(&self) -> ActuationStats {
        self.stats
    }
}

impl Decision {
    fn into_record(
        self,
        command: Action,
        safety_stop: Option<SafetyStop>,
        estop: bool,
    ) -> TickRecord {
        let p = self.prediction;
        let obs = p.observation;
        let inputs = pavlov::record::TickInputs {
            values: obs.values,
            forced_stimulus: p.forced_stimulus,
        };
        TickRecord {
            seq: obs.tick.seq,
            t_ms: p.t_ms,
            mode: self.gate.mode,
            obs_age_ticks: obs.age_ticks,
            sensors: p.sensors,
            obs: p.learned.obs_vector,
            elbow: p.learned.elbow,
            stimulus: p.learned.stimulus,
            predictions: p.learned.predictions,
            gate: self.gate.gate,
            default_action: self.gate.default_action,
            command,
            safety_stop,
            estop,
            lateness_us: obs.tick.lateness().as_micros().min(u32::MAX as u128) as u32,
            link: obs.link,
            inputs: Some(inputs),
        }
    }
}

/// The channels actuation reads and writes.
pub struct ActuationChannels {
    /// Gating's decisions.
    pub decisions: mpsc::Receiver<Decision>,
    /// The ticker, for the stalled-pipeline watchdog.
    pub ticks: watch::Receiver<Option<Tick>>,
    /// The e-stop latch.
    pub estop: watch::Receiver<bool>,
    /// The link writer's queue.
    pub writer: mpsc::Sender<WriteRequest>,
    /// Where tick records go.
    pub feed: TickFeed,
    /// Actuation's counters, published after each decision.
    pub stats: watch::Sender<ActuationStats>,
}

/// Runs until `cancel` fires or the decision channel closes; the writer then sends the shut-down sequence.
pub async fn run(mut actuation: Actuation, channels: ActuationChannels, cancel: CancellationToken) {
    let ActuationChannels {
        mut decisions,
        mut ticks,
        mut estop,
        writer,
        feed,
        stats,
    } = channels;
    loop {
        tokio::select! {
            biased;
            _ = cancel.cancelled() => break,
            d = decisions.recv() => {
                let Some(d) = d else { break };
                let latched = *estop.borrow();
                let record = actuation.on_decision(d, latched, &writer);
                feed.publish(Arc::new(record));
                stats.send_replace(actuation.stats());
            }
            changed = estop.changed() => {
                if changed.is_err() { break; }
                if *estop.borrow_and_update() {
                    // Do not wait for the next decision: stop the wheels the moment the e-stop latches.
                    actuation.write(Action::STOP, None, &writer);
                }
            }
            changed = ticks.changed() => {
                if changed.is_err() { break; }
                let tick = *ticks.borrow_and_update();
                if let Some(tick) = tick {
                    actuation.on_tick(&tick, &writer);
                }
            }
        }
    }
    // Stop now; the writer adds pause + Passive when its queue closes.
    actuation.write(Action::STOP, None, &writer);
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::time::Instant;

    fn tick(seq: u64) -> Tick {
        let now = Instant::now();
        Tick {
            seq,
            deadline: now,
            fired: now,
        }
    }

    #[tokio::test]
    async fn a_stalled_pipeline_stops_the_wheels_once_after_three_ticks() {
        let (tx, mut rx) = mpsc::channel(16);
        let mut a = Actuation::new(Model::Create1, SafetyConfig::default());
        a.write(Action::new(100, 100), None, &tx);
        a.last_decision_seq = Some(10);
        assert_eq!(rx.recv().await.unwrap().bytes, vec![145, 0, 100, 0, 100]);
        assert!(
            !a.on_tick(&tick(13), &tx),
            "3 ticks without a decision is still in time"
        );
        assert!(rx.try_recv().is_err());
        assert!(a.on_tick(&tick(14), &tx));
        assert_eq!(rx.try_recv().unwrap().bytes, vec![145, 0, 0, 0, 0]);
        assert!(a.on_tick(&tick(15), &tx));
        assert!(
            rx.try_recv().is_err(),
            "the stop is written once, not flooded"
        );
        assert_eq!(a.stats().pipeline_stalls, 1);
    }

    #[tokio::test]
    async fn no_decision_at_all_also_counts_as_stalled() {
        let (tx, mut rx) = mpsc::channel(16);
        let mut a = Actuation::new(Model::Create2, SafetyConfig::default());
        assert!(!a.on_tick(&tick(2), &tx));
        assert!(a.on_tick(&tick(3), &tx));
        assert_eq!(rx.try_recv().unwrap().bytes, vec![145, 0, 0, 0, 0]);
    }
}
