//! The gating actor: a thin shell over [`pavlov::agent::GatingStage`].
//!
//! It turns each [`Prediction`] into a [`Decision`] for actuation and applies mode, e-stop and teleop
//! commands between ticks.

use pavlov::agent::{GateOutput, GatingStage};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::command::GatingCommand;
use crate::learning::Prediction;

/// What gating decided on one tick, with everything learning produced for it.
#[derive(Debug, Clone)]
pub struct Decision {
    /// Learning's output for the tick.
    pub prediction: Prediction,
    /// The gate's output.
    pub gate: GateOutput,
}

fn apply(stage: &mut GatingStage, cmd: GatingCommand, seq: u64) {
    match cmd {
        GatingCommand::Mode(mode, reply) => {
            stage.set_mode(mode);
            tracing::info!(?mode, "control mode changed");
            let _ = reply.send(Ok(serde_json::json!({ "mode": mode })));
        }
        GatingCommand::Estop(on) => stage.set_estop(on),
        GatingCommand::Teleop(action, reply) => {
            let _ = reply.send(
                stage
                    .teleop(action, seq)
                    .map(|()| serde_json::json!({ "teleop": action }))
                    .map_err(|e| e.to_string()),
            );
        }
    }
}

/// Runs until its input closes or `cancel` fires.
pub async fn run(
    mut stage: GatingStage,
    mut predictions: mpsc::Receiver<Prediction>,
    mut commands: mpsc::Receiver<GatingCommand>,
    out: mpsc::Sender<Decision>,
    cancel: CancellationToken,
) {
    let mut last_seq = 0;
    loop {
        tokio::select! {
            biased;
            _ = cancel.cancelled() => break,
            Some(cmd) = commands.recv() => apply(&mut stage, cmd, last_seq),
            p = predictions.recv() => {
                let Some(p) = p else { break };
                last_seq = p.observation.tick.seq;
                let gate = stage.decide(last_seq, p.learned.stimulus, p.learned.gate_value, p.learned.gate_threshold);
                if out.try_send(Decision { prediction: p, gate }).is_err() {
                    tracing::debug!("actuation is behind; a decision was dropped");
                }
            }
        }
    }
}
