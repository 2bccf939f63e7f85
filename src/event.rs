//! [`Event`]: a change made at run time to what the robot does or what it learns, as data.
//!
//! Ticks say what happened on every tick; events say what changed between them and why: an operator's
//! command (mode, e-stop, teleop, a human request, learning parameters, a weight reset or save, a
//! recording started or stopped) or something the link went through (a trip, a reconnect). Each carries
//! `after`, the last tick its owner had handled when the change took effect (`None`: before the first
//! tick), so it applies from that owner's next tick on: that is what lets replay reproduce a run with
//! changes in it exactly. Events are numbered in the order they were made (`id`), so a recording that
//! starts from a snapshot of the learner can tell which events the snapshot already includes.

use serde::{Deserialize, Serialize};

use crate::control::{Action, Mode};
use crate::oi::mode::DriveMode;
use crate::supervision::{LinkState, TripCause};

/// One change, with when it took effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// Position in the order events were made (1, 2, …).
    pub id: u64,
    /// The last tick the event's owner had handled when it took effect (`None`: before the first).
    pub after: Option<u64>,
    /// What changed.
    #[serde(flatten)]
    pub kind: EventKind,
}

/// What changed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EventKind {
    /// Gating switched mode.
    ModeSet {
        /// The new mode.
        mode: Mode,
    },
    /// Gating took a teleop command (manual mode).
    Teleop {
        /// The wheel speeds.
        action: Action,
    },
    /// The e-stop was latched (`true`) or released.
    EStop {
        /// Latched.
        latched: bool,
    },
    /// The operator re-armed the robot after a trip.
    Rearm {
        /// What had tripped it.
        cause: TripCause,
        /// The mode sent.
        mode: DriveMode,
    },
    /// An injected human request holds the stimulus on until this tick.
    HumanRequest {
        /// The first tick without the request.
        until_tick: u64,
    },
    /// A prediction's learning parameters changed; the values now in force.
    ParamsSet {
        /// The prediction.
        prediction: String,
        /// Step size α.
        alpha: f64,
        /// Trace decay λ.
        lambda: f64,
        /// Gate threshold θ.
        threshold: f64,
    },
    /// Every weight and trace went back to its initial value.
    WeightsReset,
    /// The weights were saved to a file.
    WeightsSaved {
        /// The file.
        path: String,
    },
    /// A recording started.
    RecordingStarted {
        /// Its path.
        path: String,
    },
    /// A recording stopped: asked to, or because writing it failed (`reason`). What was written before
    /// a failure stays readable.
    RecordingStopped {
        /// Its path.
        path: String,
        /// Why it stopped when nobody asked it to: the error, as the OS gave it (absent for a stop asked for).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
    },
    /// Writing a checkpoint or a save failed; its temporary file was removed, and the file it was to
    /// become is as it was before.
    CheckpointFailed {
        /// The file it was to become.
        path: String,
        /// The error, as the OS gave it.
        reason: String,
    },
    /// The robot link changed state (stale, reconnecting, tripped, up again, down).
    Link {
        /// The new state.
        state: LinkState,
        /// Why the robot tripped, while it is tripped.
        trip: Option<TripCause>,
        /// Port reopens so far.
        reconnects: u64,
    },
    /// Actuation stopped the wheels because no decision arrived in time (a stalled pipeline).
    PipelineStall {
        /// Ticks without a decision.
        ticks: u32,
    },
}

impl EventKind {
    /// Whether the event comes often enough to belong at DEBUG rather than INFO in the log (teleop
    /// commands arrive five times a second while an operator drives).
    pub fn is_frequent(&self) -> bool {
        matches!(self, EventKind::Teleop { .. })
    }

    /// Whether replay must apply the event to the learning stage.
    pub fn changes_learning(&self) -> bool {
        matches!(self, EventKind::ParamsSet { .. } | EventKind::WeightsReset)
    }

    /// Whether replay must apply the event to the gating stage.
    pub fn changes_gating(&self) -> bool {
        matches!(self, EventKind::ModeSet { .. } | EventKind::Teleop { .. })
    }

    /// Whether the event reports a failure to write to storage: a recording stopped by an error, or a
    /// checkpoint that could not be written (what `/metrics` counts).
    pub fn is_storage_failure(&self) -> bool {
        matches!(
            self,
            EventKind::RecordingStopped {
                reason: Some(_),
                ..
            } | EventKind::CheckpointFailed { .. }
        )
    }

    /// A short name of the kind, as serialised (`mode_set`, `e_stop`, …).
    pub fn name(&self) -> &'static str {
        match self {
            EventKind::ModeSet { .. } => "mode_set",
            EventKind::Teleop { .. } => "teleop",
            EventKind::EStop { .. } => "e_stop",
            EventKind::Rearm { .. } => "rearm",
            EventKind::HumanRequest { .. } => "human_request",
            EventKind::ParamsSet { .. } => "params_set",
            EventKind::WeightsReset => "weights_reset",
            EventKind::WeightsSaved { .. } => "weights_saved",
            EventKind::RecordingStarted { .. } => "recording_started",
            EventKind::RecordingStopped { .. } => "recording_stopped",
            EventKind::CheckpointFailed { .. } => "checkpoint_failed",
            EventKind::Link { .. } => "link",
            EventKind::PipelineStall { .. } => "pipeline_stall",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_serialise_flat_with_their_kind_and_read_back() {
        let e = Event {
            id: 7,
            after: Some(120),
            kind: EventKind::ParamsSet {
                prediction: "stall".into(),
                alpha: 0.01,
                lambda: 0.5,
                threshold: 0.5,
            },
        };
        let json = serde_json::to_value(&e).unwrap();
        assert_eq!(json["kind"], "params_set");
        assert_eq!(json["after"], 120);
        assert_eq!(json["alpha"], 0.01);
        assert_eq!(serde_json::from_value::<Event>(json).unwrap(), e);
        let reset = Event {
            id: 8,
            after: None,
            kind: EventKind::WeightsReset,
        };
        let text = serde_json::to_string(&reset).unwrap();
        assert_eq!(text, r#"{"id":8,"after":null,"kind":"weights_reset"}"#);
        assert_eq!(serde_json::from_str::<Event>(&text).unwrap(), reset);
        assert_eq!(reset.kind.name(), "weights_reset");
    }

    #[test]
    fn a_stop_without_a_reason_reads_as_before_and_failures_are_storage_failures() {
        let asked: Event =
            serde_json::from_str(r#"{"id":3,"after":9,"kind":"recording_stopped","path":"r"}"#)
                .unwrap();
        assert_eq!(
            asked.kind,
            EventKind::RecordingStopped {
                path: "r".into(),
                reason: None
            }
        );
        assert!(!asked.kind.is_storage_failure());
        let text = serde_json::to_string(&asked).unwrap();
        assert!(!text.contains("reason"), "{text}");
        let failed = EventKind::RecordingStopped {
            path: "r".into(),
            reason: Some("No space left on device (os error 28)".into()),
        };
        assert!(failed.is_storage_failure());
        let json = serde_json::to_value(&failed).unwrap();
        assert_eq!(json["reason"], "No space left on device (os error 28)");
        let checkpoint = EventKind::CheckpointFailed {
            path: "w/saved/a.json".into(),
            reason: "No space left on device (os error 28)".into(),
        };
        assert!(checkpoint.is_storage_failure());
        assert_eq!(checkpoint.name(), "checkpoint_failed");
        assert_eq!(
            serde_json::to_value(&checkpoint).unwrap()["kind"],
            "checkpoint_failed"
        );
    }

    #[test]
    fn only_learning_and_gating_changes_are_replayed() {
        assert!(EventKind::WeightsReset.changes_learning());
        assert!(EventKind::ModeSet { mode: Mode::Manual }.changes_gating());
        assert!(!EventKind::EStop { latched: true }.changes_learning());
        assert!(!EventKind::EStop { latched: true }.changes_gating());
        assert!(
            EventKind::Teleop {
                action: Action::STOP
            }
            .is_frequent()
        );
    }
}
