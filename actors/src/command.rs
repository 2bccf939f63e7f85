//! The one command vocabulary of the running server (the router that hands each command to its owner is
//! `crate::pipeline::router`).
//!
//! Every command a client (the websocket, a test, an experiment) can send is a variant of exactly one
//! owner's enum below, and [`ControlCommand`] is the union of those enums: the wire names (`"cmd"`) come
//! from the variants themselves (serde and strum, snake_case), so nothing else lists them. Each owner has
//! one narrow inbox that carries only its own commands, and applies them between ticks, so an ack means
//! the change is in force from the next tick on:
//!
//! - the e-stop latch ([`LatchCommand`]) is applied by the router itself, straight into the `watch` that
//!   actuation (the only writer of motion commands) and gating read, so it works even if they stalled;
//! - gating ([`GatingCommand`]), learning ([`LearningCommand`]), link supervision ([`LinkCommand`]) and
//!   the recorder ([`RecorderCommand`]) get theirs through their inboxes.
//!
//! The router never waits: it forwards each command with its reply channel and goes on to the next, and a
//! full inbox is answered `busy` at once. The owner answers with a typed [`Outcome`].
//!
//! Adding a command: a variant in its owner's enum here, its handling in the owner, and a line in
//! `web/PROTOCOL.md`.

use pavlov::control::{Action, Mode};
use pavlov::oi::mode::DriveMode;
use pavlov::supervision::TripCause;
use serde::{Deserialize, Deserializer, Serialize};
use strum::VariantNames;
use tokio::sync::{mpsc, oneshot};

// Argument-less commands are empty struct variants (`Estop {}`), so that unknown fields are rejected for
// them too: serde ignores extra fields on unit variants of an internally tagged enum.

/// Commands the router applies itself: the emergency stop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, VariantNames)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
#[strum(serialize_all = "snake_case")]
pub enum LatchCommand {
    /// Latch the emergency stop: the wheels stop and stay stopped until `release`.
    Estop {},
    /// Release a latched emergency stop.
    Release {},
}

/// Commands gating applies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, VariantNames)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
#[strum(serialize_all = "snake_case")]
pub enum GatingCommand {
    /// Switch between reactive, Pavlovian and manual control.
    SetMode {
        /// The new mode.
        mode: Mode,
    },
    /// Drive the wheels directly (manual mode only). Expires after half a second without a refresh.
    Teleop {
        /// Left wheel, mm/s.
        left_mm_s: i16,
        /// Right wheel, mm/s.
        right_mm_s: i16,
    },
}

/// Commands learning applies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, VariantNames)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
#[strum(serialize_all = "snake_case")]
pub enum LearningCommand {
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
    /// Save the weights to a file.
    SaveWeights {
        /// The file's name; default: one made from the tick.
        #[serde(default)]
        path: Option<String>,
    },
}

/// Commands link supervision applies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, VariantNames)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
#[strum(serialize_all = "snake_case")]
pub enum LinkCommand {
    /// Resume Safe/Full control after the robot tripped to Passive (cliff, wheel drop, charger).
    Rearm {},
}

/// Commands the recorder applies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, VariantNames)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
#[strum(serialize_all = "snake_case")]
pub enum RecorderCommand {
    /// Start recording ticks.
    StartRecording {
        /// The recording's name; default: one made from the time.
        #[serde(default)]
        dir: Option<String>,
    },
    /// Stop recording.
    StopRecording {},
}

fn default_request_ms() -> u64 {
    500
}

/// A command to the running server: one owner's command.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ControlCommand {
    /// The e-stop latch.
    Latch(LatchCommand),
    /// Gating's.
    Gating(GatingCommand),
    /// Learning's.
    Learning(LearningCommand),
    /// Link supervision's.
    Link(LinkCommand),
    /// The recorder's.
    Recorder(RecorderCommand),
}

impl ControlCommand {
    /// Every command's wire name, by owner.
    pub(crate) fn names() -> impl Iterator<Item = &'static str> {
        [
            LatchCommand::VARIANTS,
            GatingCommand::VARIANTS,
            LearningCommand::VARIANTS,
            LinkCommand::VARIANTS,
            RecorderCommand::VARIANTS,
        ]
        .into_iter()
        .flatten()
        .copied()
    }

    /// Whether `name` is a command's wire name.
    pub(crate) fn is_name(name: &str) -> bool {
        Self::names().any(|n| n == name)
    }
}

impl<'de> Deserialize<'de> for ControlCommand {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let value = serde_json::Value::deserialize(d)?;
        let name = value
            .get("cmd")
            .and_then(serde_json::Value::as_str)
            .ok_or_else(|| D::Error::missing_field("cmd"))?
            .to_string();
        let name = name.as_str();
        if !Self::is_name(name) {
            return Err(D::Error::unknown_variant(name, &[]));
        }
        let parsed = if LatchCommand::VARIANTS.contains(&name) {
            serde_json::from_value(value).map(ControlCommand::Latch)
        } else if GatingCommand::VARIANTS.contains(&name) {
            serde_json::from_value(value).map(ControlCommand::Gating)
        } else if LearningCommand::VARIANTS.contains(&name) {
            serde_json::from_value(value).map(ControlCommand::Learning)
        } else if LinkCommand::VARIANTS.contains(&name) {
            serde_json::from_value(value).map(ControlCommand::Link)
        } else {
            serde_json::from_value(value).map(ControlCommand::Recorder)
        };
        parsed.map_err(D::Error::custom)
    }
}

macro_rules! into_control {
    ($($owner:ident => $variant:ident),*) => {$(
        impl From<$owner> for ControlCommand {
            fn from(c: $owner) -> Self {
                ControlCommand::$variant(c)
            }
        }
    )*};
}
into_control!(LatchCommand => Latch, GatingCommand => Gating, LearningCommand => Learning,
    LinkCommand => Link, RecorderCommand => Recorder);

/// What a command did, as the owner reports it (the `result` of the websocket's `ack`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Applied {
    /// The e-stop is now latched (`true`) or released.
    Estop {
        /// Latched.
        estop: bool,
    },
    /// The mode in force.
    Mode {
        /// The mode.
        mode: Mode,
    },
    /// The teleop command in force.
    Teleop {
        /// The wheel speeds.
        teleop: Action,
    },
    /// The injected request lasts until this tick.
    Request {
        /// The first tick without the request.
        request_until_tick: u64,
    },
    /// A prediction's learning parameters in force.
    Params {
        /// The prediction.
        prediction: String,
        /// Step size α.
        alpha: f64,
        /// Trace decay λ.
        lambda: f64,
        /// Gate threshold θ.
        threshold: f64,
    },
    /// Every weight and trace is back at its initial value.
    Reset {
        /// Always true.
        reset: bool,
    },
    /// The weights are being written to this file.
    Saved {
        /// The file.
        path: String,
    },
    /// A recording is open.
    Recording {
        /// Its path.
        recording: String,
    },
    /// The recording was closed.
    Stopped {
        /// Its path.
        stopped: String,
    },
    /// The robot was re-armed after a trip.
    Rearmed {
        /// What had tripped it.
        rearmed: TripCause,
        /// The mode sent.
        mode: DriveMode,
    },
}

/// Why a command was not applied.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// The owner refused it (a precondition or a bound); the message says which.
    #[error("{0}")]
    Rejected(String),
    /// The owner's inbox is full.
    #[error("the {0}'s command queue is full; try again")]
    Busy(&'static str),
    /// The owner is not running (shutting down, or not part of this server).
    #[error("{0}")]
    Unavailable(String),
}

impl CommandError {
    /// The machine-readable code of the websocket's error reply.
    pub(crate) fn code(&self) -> &'static str {
        match self {
            CommandError::Rejected(_) => "rejected",
            CommandError::Busy(_) => "busy",
            CommandError::Unavailable(_) => "unavailable",
        }
    }
}

/// The outcome of a command.
pub type Outcome = Result<Applied, CommandError>;

/// Where an owner sends a command's outcome.
pub(crate) type Reply = oneshot::Sender<Outcome>;

/// A command with the channel its outcome goes back on.
#[derive(Debug)]
pub struct ControlRequest {
    /// The command.
    pub(crate) command: ControlCommand,
    /// Where the outcome goes.
    pub(crate) reply: Reply,
}

impl ControlRequest {
    /// A request and the receiver of its reply.
    pub fn new(command: impl Into<ControlCommand>) -> (Self, oneshot::Receiver<Outcome>) {
        let (reply, rx) = oneshot::channel();
        (
            ControlRequest {
                command: command.into(),
                reply,
            },
            rx,
        )
    }
}

/// One owner's command with its reply channel: what an inbox carries.
#[derive(Debug)]
pub(crate) struct Envelope<C> {
    /// The command.
    pub(crate) command: C,
    /// Where the outcome goes.
    pub(crate) reply: Reply,
}

impl<C> Envelope<C> {
    /// Sends the outcome (a requester that has gone away is not an error).
    pub(crate) fn answer(self, outcome: Outcome) {
        let _ = self.reply.send(outcome);
    }
}

/// An owner's inbox.
pub(crate) type Inbox<C> = mpsc::Receiver<Envelope<C>>;

/// Capacity of each owner's inbox.
pub(crate) const INBOX_CAPACITY: usize = 16;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_from_json_into_their_owner() {
        let c: ControlCommand =
            serde_json::from_str(r#"{"cmd":"set_mode","mode":"reactive"}"#).unwrap();
        assert_eq!(
            c,
            GatingCommand::SetMode {
                mode: Mode::Reactive
            }
            .into()
        );
        let c: ControlCommand = serde_json::from_str(r#"{"cmd":"human_request"}"#).unwrap();
        assert_eq!(c, LearningCommand::HumanRequest { duration_ms: 500 }.into());
        let c: ControlCommand = serde_json::from_str(r#"{"cmd":"estop"}"#).unwrap();
        assert_eq!(c, LatchCommand::Estop {}.into());
        assert!(serde_json::from_str::<ControlCommand>(r#"{"cmd":"fly"}"#).is_err());
        assert!(serde_json::from_str::<ControlCommand>(r#"{"cmd":"estop","x":1}"#).is_err());
    }

    #[test]
    fn every_name_is_unique_and_round_trips() {
        let names: Vec<&str> = ControlCommand::names().collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), names.len(), "{names:?}");
        assert!(names.contains(&"estop") && names.contains(&"start_recording"));
        let c: ControlCommand = LinkCommand::Rearm {}.into();
        assert_eq!(serde_json::to_string(&c).unwrap(), r#"{"cmd":"rearm"}"#);
    }
}
