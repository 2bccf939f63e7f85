//! The actuation actor: the only writer of motion commands, and the robot's last line of safety.
//!
//! For each decision it writes Drive Direct (right wheel first) through the link writer, unless the core's
//! safety predicate ([`pavlov::agent::safety::stop_reason`]) says stop: the e-stop is latched, the robot
//! has tripped to Passive, the link is not up, or the observation behind the decision is stale. On every
//! tick it also checks that a fresh decision has arrived; after `max_action_age_ticks` ticks without one
//! (a stalled pipeline) it stops the wheels by itself and counts it. It then assembles the tick's
//! [`TickRecord`] ([`pavlov::agent::tick_record`]) and publishes it to the feed (dashboard, recorder,
//! metrics).

use std::sync::Arc;

use pavlov::agent::learning::followed_default;
use pavlov::agent::safety;
use pavlov::agent::tick_record::{self, Actuated, Sensed};
use pavlov::config::SafetyConfig;
use pavlov::control::Action;
use pavlov::oi::Model;
use pavlov::oi::command::Command;
use pavlov::record::TickRecord;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use pavlov::event::EventKind;

use super::gating::Decision;
use super::ticker::Tick;
use crate::bus::{EventLog, TickFeed};
use crate::link::writer::WriteRequest;
use crate::telemetry::counters::ActuationStats;

/// Actuation's state.
pub(crate) struct Actuation {
    model: Model,
    safety: SafetyConfig,
    last_decision_seq: Option<u64>,
    last_written: Option<Action>,
    last_stop: Option<pavlov::record::SafetyStop>,
    stats: ActuationStats,
    /// The command being written, encoded (one buffer, reused).
    encoded: Vec<u8>,
}

impl Actuation {
    /// Actuation for `model` with the given safety limits.
    pub(crate) fn new(model: Model, safety: SafetyConfig) -> Self {
        Actuation {
            model,
            safety,
            last_decision_seq: None,
            last_written: None,
            last_stop: None,
            stats: ActuationStats::default(),
            encoded: Vec::with_capacity(8),
        }
    }

    fn write(&mut self, action: Action, tick: Option<&Tick>, writer: &mut impl CommandQueue) {
        let cmd = Command::DriveDirect {
            right: action.right_mm_s,
            left: action.left_mm_s,
        };
        self.encoded.clear();
        match cmd.encode_into(self.model, &mut self.encoded) {
            Ok(()) => {
                if !writer.offer(&self.encoded, tick.map(|t| t.deadline)) {
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
    pub(crate) fn on_decision(
        &mut self,
        d: Decision,
        estop: bool,
        writer: &mut impl CommandQueue,
    ) -> TickRecord {
        let obs = &d.learned.observation;
        let stop = safety::stop_reason(
            estop,
            obs.link.state,
            obs.age_ticks,
            self.safety.max_obs_age_ticks,
        );
        if stop == Some(pavlov::record::SafetyStop::StaleObservation) {
            self.stats.stale_observations += 1;
        }
        if stop != self.last_stop {
            tracing::debug!(tick = obs.tick.seq, from = ?self.last_stop, to = ?stop, "safety stop changed");
            self.last_stop = stop;
        }
        let command = if stop.is_some() {
            Action::STOP
        } else {
            d.gate.action
        };
        let tick = obs.tick;
        self.last_decision_seq = Some(tick.seq);
        self.write(command, Some(&tick), writer);
        let learned = d.learned;
        let obs = learned.observation;
        let sensed = Sensed {
            seq: tick.seq,
            t_ms: learned.t_ms,
            lateness_us: tick.lateness().as_micros().min(u32::MAX as u128) as u32,
            values: obs.values,
            age_ticks: obs.age_ticks,
            distance_mm: obs.distance_mm,
            angle_deg: obs.angle_deg,
            link: obs.link,
        };
        let actuated = Actuated {
            command,
            safety_stop: stop,
            estop,
        };
        tick_record::assemble(
            sensed,
            learned.output,
            learned.forced_stimulus,
            d.gate,
            actuated,
        )
    }

    /// Called on every tick: stops the wheels when the pipeline has not delivered a decision in time.
    pub(crate) fn on_tick(&mut self, tick: &Tick, writer: &mut impl CommandQueue) -> bool {
        let behind = safety::pipeline_stalled(
            tick.seq,
            self.last_decision_seq,
            self.safety.max_action_age_ticks,
        );
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

    /// The watchdog on tick `tick` ([`Actuation::on_tick`]), announcing a stall it detects on `events`;
    /// true when it counted a new stall.
    pub(crate) fn watchdog(
        &mut self,
        tick: &Tick,
        writer: &mut impl CommandQueue,
        events: &EventLog,
    ) -> bool {
        let stalls = self.stats.pipeline_stalls;
        self.on_tick(tick, writer);
        let stalled = self.stats.pipeline_stalls > stalls;
        if stalled {
            events.emit(
                self.last_decision_seq,
                EventKind::PipelineStall {
                    ticks: self.safety.max_action_age_ticks,
                },
            );
        }
        stalled
    }

    /// Counters so far.
    pub(crate) fn stats(&self) -> ActuationStats {
        self.stats
    }
}

/// Where actuation's commands go: the link writer's queue in the actors, the simulated robot's input in
/// the stepped virtual-time driver ([`crate::experiment::stepped`]).
pub(crate) trait CommandQueue {
    /// Takes the encoded command `bytes` (of the tick due at `tick_deadline`, if a tick's) without
    /// waiting; false when it cannot be taken now (the command is lost and counted).
    fn offer(&mut self, bytes: &[u8], tick_deadline: Option<Instant>) -> bool;
}

impl CommandQueue for mpsc::Sender<WriteRequest> {
    fn offer(&mut self, bytes: &[u8], tick_deadline: Option<Instant>) -> bool {
        let req = WriteRequest {
            bytes: bytes.to_vec(),
            tick_deadline,
        };
        self.try_send(req).is_ok()
    }
}

/// What learning needs of `record` on the next tick: its tick, whether its command was the default
/// policy's, and its behaviour probability.
pub(crate) fn followed_of(record: &TickRecord) -> (u64, bool, f64) {
    (
        record.seq,
        followed_default(record.command, record.default_action),
        record.behaviour_prob,
    )
}

/// The channels actuation reads and writes.
pub(crate) struct ActuationChannels {
    /// Gating's decisions.
    pub(crate) decisions: mpsc::Receiver<Decision>,
    /// The ticker, for the stalled-pipeline watchdog.
    pub(crate) ticks: watch::Receiver<Option<Tick>>,
    /// The e-stop latch.
    pub(crate) estop: watch::Receiver<bool>,
    /// The link writer's queue.
    pub(crate) writer: mpsc::Sender<WriteRequest>,
    /// Where tick records go.
    pub(crate) feed: TickFeed,
    /// Actuation's counters, published after each decision.
    pub(crate) stats: watch::Sender<ActuationStats>,
    /// Where a pipeline stall is announced.
    pub(crate) events: EventLog,
    /// The last record's tick, whether its command was the default policy's and its behaviour
    /// probability b, for learning's off-policy ratio on the next tick.
    pub(crate) followed: watch::Sender<Option<(u64, bool, f64)>>,
}

/// Runs until `cancel` fires or the decision channel closes; the writer then sends the shut-down sequence.
pub(crate) async fn run(
    mut actuation: Actuation,
    channels: ActuationChannels,
    cancel: CancellationToken,
) {
    let ActuationChannels {
        mut decisions,
        mut ticks,
        mut estop,
        mut writer,
        feed,
        stats,
        events,
        followed,
    } = channels;
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            d = decisions.recv() => {
                let Some(d) = d else { break };
                let latched = *estop.borrow();
                let record = actuation.on_decision(d, latched, &mut writer);
                followed.send_replace(Some(followed_of(&record)));
                feed.publish(Arc::new(record));
                stats.send_replace(actuation.stats());
            }
            changed = estop.changed() => {
                if changed.is_err() { break; }
                if *estop.borrow_and_update() {
                    // Do not wait for the next decision: stop the wheels the moment the e-stop latches.
                    actuation.write(Action::STOP, None, &mut writer);
                }
            }
            changed = ticks.changed() => {
                if changed.is_err() { break; }
                let tick = *ticks.borrow_and_update();
                if let Some(tick) = tick
                    && actuation.watchdog(&tick, &mut writer, &events)
                {
                    stats.send_replace(actuation.stats());
                }
            }
        }
    }
    // Stop now; the writer adds pause + Passive when its queue closes.
    actuation.write(Action::STOP, None, &mut writer);
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (mut tx, mut rx) = mpsc::channel(16);
        let mut a = Actuation::new(Model::Create1, SafetyConfig::default());
        a.write(Action::new(100, 100), None, &mut tx);
        a.last_decision_seq = Some(10);
        assert_eq!(rx.recv().await.unwrap().bytes, vec![145, 0, 100, 0, 100]);
        assert!(
            !a.on_tick(&tick(13), &mut tx),
            "3 ticks without a decision is still in time"
        );
        assert!(rx.try_recv().is_err());
        assert!(a.on_tick(&tick(14), &mut tx));
        assert_eq!(rx.try_recv().unwrap().bytes, vec![145, 0, 0, 0, 0]);
        assert!(a.on_tick(&tick(15), &mut tx));
        assert!(
            rx.try_recv().is_err(),
            "the stop is written once, not flooded"
        );
        assert_eq!(a.stats().pipeline_stalls, 1);
    }

    #[tokio::test]
    async fn no_decision_at_all_also_counts_as_stalled() {
        let (mut tx, mut rx) = mpsc::channel(16);
        let mut a = Actuation::new(Model::Create2, SafetyConfig::default());
        assert!(!a.on_tick(&tick(2), &mut tx));
        assert!(a.on_tick(&tick(3), &mut tx));
        assert_eq!(rx.try_recv().unwrap().bytes, vec![145, 0, 0, 0, 0]);
    }
}
