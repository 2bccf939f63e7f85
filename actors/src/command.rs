//! Commands injected into the running server (by the websocket, tests or experiments), and their routing.
//!
//! A [`ControlRequest`] carries a [`ControlCommand`] and a one-shot reply channel. The router sends each
//! command to the actor that owns the state it changes; that actor applies it between ticks and replies,
//! so an `ack` means the change is in force from the next tick on. The e-stop is also latched straight into
//! actuation, which is the only writer of motion commands, so it takes effect even if gating has stalled.

use pavlov::control::{Action, Mode};
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, oneshot, watch};

/// A command to the running server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// Argument-less commands are empty struct variants (`Estop {}`), so that unknown fields are rejected for
// them too: serde ignores extra fields on unit variants of an internally tagged enum.
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControlCommand {
    /// Switch between reactive, Pavlovian and manual control.
    SetMode {
        /// The new mode.
        mode: Mode,
    },
    /// Latch the emergency stop: the wheels stop and stay stopped until `release`.
    Estop {},
    /// Release a latched emergency stop.
    Release {},
    /// Drive the wheels directly (manual mode only). Expires after `teleop_hold_ms` without a refresh.
    Teleop {
        /// Left wheel, mm/s.
        left_mm_s: i16,
        /// Right wheel, mm/s.
        right_mm_s: i16,
    },
    /// Inject a human command request, as if the gesture had been seen, for `duration_ms`.
    HumanRequest {
        /// How long the request stays on, ms.
        #[serde(default = "default_request_ms")]
        duration_ms: u64,
    },
    /// Change learning parameters of the gating prediction (or of `prediction`, by name).
    SetParams {
        /// Which prediction; default: the one that drives the gate.
        #[serde(default)]
        prediction: Option<String>,
        /// Step size α.
        #[serde(default)]
        alpha: Option<f64>,
        /// Trace decay λ.
        #[serde(default)]
        lambda: Option<f64>,
        /// Gate threshold θ.
        #[serde(default)]
        threshold: Option<f64>,
    },
    /// Reset every prediction's weights and traces to their initial values.
    ResetWeights {},
    /// Save the weights to a checkpoint file.
    SaveWeights {
        /// Where; default: the server's checkpoint directory.
        #[serde(default)]
        path: Option<String>,
    },
    /// Start recording ticks into a directory.
    StartRecording {
        /// The directory; default: a timestamped one under the server's recording root.
        #[serde(default)]
        dir: Option<String>,
    },
    /// Stop recording.
    StopRecording {},
    /// Resume Safe/Full control after the robot tripped to Passive (cliff, wheel drop, charger).
    Rearm {},
}

fn default_request_ms() -> u64 {
    500
}

/// The outcome of a command: `Ok(detail)` or an error message for the sender.
pub type CommandResult = Result<serde_json::Value, String>;

/// A command with the channel its outcome goes back on.
#[derive(Debug)]
pub struct ControlRequest {
    /// The command.
    pub command: ControlCommand,
    /// Where the outcome goes.
    pub reply: oneshot::Sender<CommandResult>,
}

impl ControlRequest {
    /// A request and the receiver of its reply.
    pub fn new(command: ControlCommand) -> (Self, oneshot::Receiver<CommandResult>) {
        let (reply, rx) = oneshot::channel();
        (ControlRequest { command, reply }, rx)
    }
}

/// Commands gating applies.
#[derive(Debug)]
pub enum GatingCommand {
    /// Set the mode.
    Mode(Mode, oneshot::Sender<CommandResult>),
    /// Latch or release the e-stop in gating's view.
    Estop(bool),
    /// Manual drive.
    Teleop(Action, oneshot::Sender<CommandResult>),
}

/// Commands learning applies.
#[derive(Debug)]
pub enum LearningCommand {
    /// A command learning owns (params, reset, save, human request).
    Apply(ControlCommand, oneshot::Sender<CommandResult>),
}

/// Where the router sends things.
pub struct CommandRoutes {
    /// Gating's inbox.
    pub gating: mpsc::Sender<GatingCommand>,
    /// Learning's inbox.
    pub learning: mpsc::Sender<LearningCommand>,
    /// The e-stop latch that actuation watches.
    pub estop: watch::Sender<bool>,
    /// Link supervision's inbox (re-arm after a trip).
    pub link: mpsc::Sender<crate::link::supervisor::LinkCommand>,
    /// The recorder's inbox, when recording is available.
    pub recorder: Option<mpsc::Sender<(ControlCommand, oneshot::Sender<CommandResult>)>>,
}

/// Routes requests until the inbox closes or `cancel` fires.
pub async fn route(
    mut inbox: mpsc::Receiver<ControlRequest>,
    routes: CommandRoutes,
    cancel: tokio_util::sync::CancellationToken,
) {
    loop {
        let next = tokio::select! {
            _ = cancel.cancelled() => None,
            r = inbox.recv() => r,
        };
        let Some(ControlRequest { command, reply }) = next else {
            break;
        };
        match command {
            ControlCommand::SetMode { mode } => {
                forward(&routes.gating, GatingCommand::Mode(mode, reply)).await
            }
            ControlCommand::Estop {} => {
                routes.estop.send_replace(true);
                let _ = routes.gating.send(GatingCommand::Estop(true)).await;
                tracing::warn!("e-stop latched");
                let _ = reply.send(Ok(serde_json::json!({"estop": true})));
            }
            ControlCommand::Release {} => {
                routes.estop.send_replace(false);
                let _ = routes.gating.send(GatingCommand::Estop(false)).await;
                tracing::info!("e-stop released");
                let _ = reply.send(Ok(serde_json::json!({"estop": false})));
            }
            ControlCommand::Teleop {
                left_mm_s,
                right_mm_s,
            } => {
                if !(-500..=500).contains(&left_mm_s) || !(-500..=500).contains(&right_mm_s) {
                    let _ = reply.send(Err(format!(
                        "teleop wheel speeds must be within ±500 mm/s, got left {left_mm_s}, right {right_mm_s}"
                    )));
                    continue;
                }
                let action = Action {
                    left_mm_s,
                    right_mm_s,
                };
                forward(&routes.gating, GatingCommand::Teleop(action, reply)).await
            }
            c @ (ControlCommand::HumanRequest { .. }
            | ControlCommand::SetParams { .. }
            | ControlCommand::ResetWeights {}
            | ControlCommand::SaveWeights { .. }) => {
                forward(&routes.learning, LearningCommand::Apply(c, reply)).await
            }
            ControlCommand::Rearm {} => {
                let (tx, rx) = oneshot::channel();
                if routes
                    .link
                    .send(crate::link::supervisor::LinkCommand::Rearm(tx))
                    .await
                    .is_err()
                {
                    let _ = reply.send(Err("the robot link is not running".into()));
                    continue;
                }
                let _ = reply.send(
                    rx.await
                        .unwrap_or_else(|_| Err("the robot link stopped".into())),
                );
            }
            c @ (ControlCommand::StartRecording { .. } | ControlCommand::StopRecording {}) => {
                match &routes.recorder {
                    Some(tx) => {
                        if let Err(mpsc::error::SendError((_, reply))) = tx.send((c, reply)).await {
                            let _ = reply.send(Err("the recorder is not running".into()));
                        }
                    }
                    None => {
                        let _ = reply.send(Err("recording is not available in this server".into()));
                    }
                }
            }
        }
    }
}

async fn forward<T>(to: &mpsc::Sender<T>, msg: T) {
    if to.send(msg).await.is_err() {
        tracing::warn!("a command arrived after its actor stopped");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_from_json() {
        let c: ControlCommand =
            serde_json::from_str(r#"{"cmd":"set_mode","mode":"reactive"}"#).unwrap();
        assert_eq!(
            c,
            ControlCommand::SetMode {
                mode: Mode::Reactive
            }
        );
        let c: ControlCommand = serde_json::from_str(r#"{"cmd":"human_request"}"#).unwrap();
        assert_eq!(c, ControlCommand::HumanRequest { duration_ms: 500 });
        assert!(serde_json::from_str::<ControlCommand>(r#"{"cmd":"fly"}"#).is_err());
        assert!(serde_json::from_str::<ControlCommand>(r#"{"cmd":"estop","x":1}"#).is_err());
    }
}
