//! [`Event`]: a change made at run time to what the robot does or what it learns, as data.
//!
//! Ticks say what happened on every tick; events say what changed between them and why: an operator's
//! command (mode, e-stop, teleop, a human request, learning parameters, a weight reset or save, a
//! recording started or stopped) or something the link went through (a trip, a reconnect). Each carries
//! `after`, the last tick its owner had handled when the change took effect (`None`: before the first
//! tick), so it applies from that owner's next tick on: that is what lets replay reproduce a run with
//! changes in it exactly. Events are numbered in the order they were made (`id`), so a recording that
//! starts from a snapshot of the learner can tell which events the snapshot already includes.
//!
//! **The kinds are defined once, here.** Their names and their list ([`EventKindName`], derived from
//! [`EventKind`] with strum, named as serde names them), one example of each ([`EventKind::example`]),
//! and everything the rest of the program asks of a kind — what it changes in learning, gating or the
//! recording in force ([`EventKind::effects`]), which of its text is private
//! ([`EventKind::private_text_mut`]) — are answered by exhaustive matches in this file. A new kind does
//! not compile until each of them says what it does; the shell (schemas, replay, the dashboard's history,
//! the watcher redaction) matches only on the small enums below, never on the kind.

use serde::{Deserialize, Serialize};
use strum::{EnumDiscriminants, EnumIter, IntoEnumIterator, IntoStaticStr, VariantNames};

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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, EnumDiscriminants)]
#[serde(tag = "kind", rename_all = "snake_case")]
#[strum_discriminants(
    name(EventKindName),
    derive(EnumIter, IntoStaticStr, VariantNames, Hash, PartialOrd, Ord),
    strum(serialize_all = "snake_case"),
    doc = "An event's kind without its data: its name as serialised (`mode_set`, `e_stop`, …: \
           `EventKindName::VARIANTS`, `<&str>::from`) and the list of every kind (`EventKindName::iter`)."
)]
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

/// A change to learning that replay applies to the learning stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LearningChange<'a> {
    /// A prediction's parameters now in force.
    Params {
        /// The prediction.
        prediction: &'a str,
        /// Step size α.
        alpha: f64,
        /// Trace decay λ.
        lambda: f64,
        /// Gate threshold θ.
        threshold: f64,
    },
    /// Every weight and trace back to its initial value.
    Reset,
}

/// A change to gating that replay applies to the gating stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GatingChange {
    /// The mode switched.
    Mode(Mode),
    /// A teleop command was taken (at the event's `after`).
    Teleop(Action),
}

/// A change to the recording in force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecordingChange<'a> {
    /// This recording is now being written.
    Started(&'a str),
    /// This recording is no longer written (asked to stop, or writing it failed).
    Stopped(&'a str),
}

/// A failure to write to storage, by what could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageFailure {
    /// A recording stopped because a write failed.
    Recording,
    /// A checkpoint or a save could not be written.
    Checkpoint,
}

/// What one kind of event means to the rest of the program: everything it is asked about, decided in
/// one exhaustive match ([`EventKind::effects`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Effects<'a> {
    /// It comes often enough to belong at DEBUG rather than INFO in the log, and out of the dashboard's
    /// history (teleop commands arrive five times a second while an operator drives).
    pub frequent: bool,
    /// The failure to write to storage it reports (what `/metrics` counts).
    pub storage_failure: Option<StorageFailure>,
    /// What replay applies to the learning stage.
    pub learning: Option<LearningChange<'a>>,
    /// What replay applies to the gating stage.
    pub gating: Option<GatingChange>,
    /// What it changes in the recording in force.
    pub recording: Option<RecordingChange<'a>>,
}

impl EventKind {
    /// Everything the program asks of this kind. The one place that decides it: the match has no
    /// wildcard, so a new kind must say here what it changes.
    pub fn effects(&self) -> Effects<'_> {
        let none = Effects::default();
        match self {
            EventKind::ModeSet { mode } => Effects {
                gating: Some(GatingChange::Mode(*mode)),
                ..none
            },
            EventKind::Teleop { action } => Effects {
                frequent: true,
                gating: Some(GatingChange::Teleop(*action)),
                ..none
            },
            EventKind::ParamsSet {
                prediction,
                alpha,
                lambda,
                threshold,
            } => Effects {
                learning: Some(LearningChange::Params {
                    prediction,
                    alpha: *alpha,
                    lambda: *lambda,
                    threshold: *threshold,
                }),
                ..none
            },
            EventKind::WeightsReset => Effects {
                learning: Some(LearningChange::Reset),
                ..none
            },
            EventKind::RecordingStarted { path } => Effects {
                recording: Some(RecordingChange::Started(path)),
                ..none
            },
            EventKind::RecordingStopped { path, reason } => Effects {
                storage_failure: reason.as_ref().map(|_| StorageFailure::Recording),
                recording: Some(RecordingChange::Stopped(path)),
                ..none
            },
            EventKind::CheckpointFailed { .. } => Effects {
                storage_failure: Some(StorageFailure::Checkpoint),
                ..none
            },
            EventKind::EStop { .. }
            | EventKind::Rearm { .. }
            | EventKind::HumanRequest { .. }
            | EventKind::WeightsSaved { .. }
            | EventKind::Link { .. }
            | EventKind::PipelineStall { .. } => none,
        }
    }

    /// Whether the event comes often enough to belong at DEBUG rather than INFO in the log (teleop
    /// commands arrive five times a second while an operator drives).
    pub fn is_frequent(&self) -> bool {
        self.effects().frequent
    }

    /// Whether replay must apply the event to the learning stage.
    pub fn changes_learning(&self) -> bool {
        self.effects().learning.is_some()
    }

    /// Whether replay must apply the event to the gating stage.
    pub fn changes_gating(&self) -> bool {
        self.effects().gating.is_some()
    }

    /// Whether the event reports a failure to write to storage: a recording stopped by an error, or a
    /// checkpoint that could not be written (what `/metrics` counts).
    pub fn is_storage_failure(&self) -> bool {
        self.effects().storage_failure.is_some()
    }

    /// The event's private text, for hiding from a watcher: the file path it names, and a message that may
    /// quote that path (`None` for a kind that names no file).
    pub fn private_text_mut(&mut self) -> Option<(&mut String, Option<&mut String>)> {
        match self {
            EventKind::WeightsSaved { path } | EventKind::RecordingStarted { path } => {
                Some((path, None))
            }
            EventKind::RecordingStopped { path, reason } => Some((path, reason.as_mut())),
            EventKind::CheckpointFailed { path, reason } => Some((path, Some(reason))),
            EventKind::ModeSet { .. }
            | EventKind::Teleop { .. }
            | EventKind::EStop { .. }
            | EventKind::Rearm { .. }
            | EventKind::HumanRequest { .. }
            | EventKind::ParamsSet { .. }
            | EventKind::WeightsReset
            | EventKind::Link { .. }
            | EventKind::PipelineStall { .. } => None,
        }
    }

    /// A short name of the kind, as serialised (`mode_set`, `e_stop`, …).
    pub fn name(&self) -> &'static str {
        EventKindName::from(self).into()
    }

    /// One event of this kind, with every field present (an `Option` is `Some`): what the schemas'
    /// checks and the tests take as the kind's shape.
    pub fn example(kind: EventKindName) -> EventKind {
        let path = || "recordings/run.mcap".to_string();
        let reason = || "No space left on device (os error 28)".to_string();
        match kind {
            EventKindName::ModeSet => EventKind::ModeSet { mode: Mode::Manual },
            EventKindName::Teleop => EventKind::Teleop {
                action: Action {
                    left_mm_s: 100,
                    right_mm_s: -100,
                },
            },
            EventKindName::EStop => EventKind::EStop { latched: true },
            EventKindName::Rearm => EventKind::Rearm {
                cause: TripCause::Cliff,
                mode: DriveMode::Full,
            },
            EventKindName::HumanRequest => EventKind::HumanRequest { until_tick: 90 },
            EventKindName::ParamsSet => EventKind::ParamsSet {
                prediction: "stall".into(),
                alpha: 0.1,
                lambda: 0.5,
                threshold: 0.6,
            },
            EventKindName::WeightsReset => EventKind::WeightsReset,
            EventKindName::WeightsSaved => EventKind::WeightsSaved { path: path() },
            EventKindName::RecordingStarted => EventKind::RecordingStarted { path: path() },
            EventKindName::RecordingStopped => EventKind::RecordingStopped {
                path: path(),
                reason: Some(reason()),
            },
            EventKindName::CheckpointFailed => EventKind::CheckpointFailed {
                path: path(),
                reason: reason(),
            },
            EventKindName::Link => EventKind::Link {
                state: LinkState::Reconnecting,
                trip: Some(TripCause::Charger),
                reconnects: 3,
            },
            EventKindName::PipelineStall => EventKind::PipelineStall { ticks: 4 },
        }
    }

    /// One example of every kind, in the enum's order.
    pub fn examples() -> impl Iterator<Item = EventKind> {
        EventKindName::iter().map(EventKind::example)
    }

    /// The name of every kind, as serialised, in the enum's order.
    pub const NAMES: &'static [&'static str] = EventKindName::VARIANTS;
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
    fn every_kind_has_an_example_named_as_serde_names_it() {
        let examples: Vec<EventKind> = EventKind::examples().collect();
        assert_eq!(examples.len(), EventKind::NAMES.len());
        for (kind, name) in examples.iter().zip(EventKind::NAMES) {
            assert_eq!(kind.name(), *name);
            let json = serde_json::to_value(kind).unwrap();
            assert_eq!(json["kind"], *name, "{json}");
            // Every field present, so a schema can be checked against the example.
            assert!(json.as_object().unwrap().values().all(|v| !v.is_null()));
            assert_eq!(&serde_json::from_value::<EventKind>(json).unwrap(), kind);
        }
    }

    #[test]
    fn private_text_is_the_path_and_a_message_that_may_quote_it() {
        for mut kind in EventKind::examples() {
            let names_a_file = serde_json::to_value(&kind).unwrap().get("path").is_some();
            assert_eq!(kind.private_text_mut().is_some(), names_a_file, "{kind:?}");
        }
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
