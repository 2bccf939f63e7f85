//! The gating actor: a thin shell over [`pavlov::agent::GatingStage`].
//!
//! It turns each [`Learned`] tick into a [`Decision`] for actuation and applies gating's commands (mode,
//! teleop) between ticks. It follows the e-stop latch the router sets, so a teleop command is refused
//! while the e-stop is latched.

use pavlov::agent::{GateOutput, GatingStage};
use pavlov::control::Action;
use tokio::sync::{mpsc, watch};
use tokio_util::sync::CancellationToken;

use pavlov::event::EventKind;

use super::learning::Learned;
use crate::bus::EventLog;
use crate::command::{Applied, CommandError, Envelope, GatingCommand, Inbox, Outcome};

/// What gating decided on one tick, with everything learning produced for it.
#[derive(Debug, Clone)]
pub(crate) struct Decision {
    /// Learning's output for the tick.
    pub(crate) learned: Learned,
    /// The gate's output.
    pub(crate) gate: GateOutput,
}

/// Applies `cmd` after tick `after` (`None`: before the first) and announces what changed. A teleop
/// command may ask for wheel speeds up to `max_speed_mm_s` (the model's
/// [`ModelSpec::max_wheel_speed_mm_s`](pavlov::oi::spec::ModelSpec::max_wheel_speed_mm_s)).
fn apply(
    stage: &mut GatingStage,
    cmd: GatingCommand,
    after: Option<u64>,
    events: &EventLog,
    max_speed_mm_s: i16,
) -> Outcome {
    let seq = after.unwrap_or(0);
    match cmd {
        GatingCommand::SetMode { mode } => {
            stage.set_mode(mode);
            events.emit(after, EventKind::ModeSet { mode });
            Ok(Applied::Mode { mode })
        }
        GatingCommand::Teleop {
            left_mm_s,
            right_mm_s,
        } => {
            let limit = -max_speed_mm_s..=max_speed_mm_s;
            if !limit.contains(&left_mm_s) || !limit.contains(&right_mm_s) {
                return Err(CommandError::Rejected(format!(
                    "teleop wheel speeds must be within ±{max_speed_mm_s} mm/s, got left {left_mm_s}, right {right_mm_s}"
                )));
            }
            let action = Action {
                left_mm_s,
                right_mm_s,
            };
            stage
                .teleop(action, seq)
                .map_err(|e| CommandError::Rejected(e.to_string()))?;
            events.emit(after, EventKind::Teleop { action });
            Ok(Applied::Teleop { teleop: action })
        }
    }
}

/// Gating's decision on learning's output `p`; `engaged` is whether the fixed response held the previous
/// tick (a change is logged). The actor and the stepped virtual-time driver ([`crate::experiment::stepped`])
/// both call it, so there is one per-tick path.
pub(crate) fn decide(stage: &mut GatingStage, p: Learned, engaged: &mut bool) -> Decision {
    let last_seq = p.observation.tick.seq;
    let o = &p.output;
    let gate = stage.decide(last_seq, o.stimulus, &o.gate_inputs);
    if gate.gate != *engaged {
        *engaged = gate.gate;
        tracing::debug!(
            tick = last_seq, engaged = gate.gate, stimulus = o.stimulus, prediction = ?o.gate_value,
            threshold = o.gate_threshold, rule = ?gate.rule, "the fixed response {}",
            if gate.gate { "took over" } else { "let go" }
        );
    }
    Decision { learned: p, gate }
}

/// The channels gating reads and writes.
pub(crate) struct GatingChannels {
    /// Learning's output.
    pub(crate) learned: mpsc::Receiver<Learned>,
    /// Gating's commands.
    pub(crate) commands: Inbox<GatingCommand>,
    /// The e-stop latch.
    pub(crate) estop: watch::Receiver<bool>,
    /// Where decisions go (to actuation).
    pub(crate) out: mpsc::Sender<Decision>,
    /// Where changes are announced.
    pub(crate) events: EventLog,
}

/// Runs until its input closes or `cancel` fires.
pub(crate) async fn run(
    mut stage: GatingStage,
    model: pavlov::oi::model::Model,
    channels: GatingChannels,
    cancel: CancellationToken,
) {
    let GatingChannels {
        mut learned,
        mut commands,
        mut estop,
        out,
        events,
    } = channels;
    let mut after = None;
    let mut engaged = false;
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            changed = estop.changed() => {
                if changed.is_err() {
                    break;
                }
                stage.set_estop(*estop.borrow_and_update());
            }
            Some(Envelope { command, reply }) = commands.recv() => {
                let _ = reply.send(apply(
                    &mut stage,
                    command,
                    after,
                    &events,
                    model.spec().max_wheel_speed_mm_s,
                ));
            }
            p = learned.recv() => {
                let Some(p) = p else { break };
                after = Some(p.observation.tick.seq);
                if out.try_send(decide(&mut stage, p, &mut engaged)).is_err() {
                    tracing::debug!("actuation is behind; a decision was dropped");
                }
            }
        }
    }
}
