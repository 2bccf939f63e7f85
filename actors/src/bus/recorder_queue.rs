//! The recorder's queue: what goes through it ([`RecorderInput`]: ticks, events, and the attachment that
//! tells the recorder where to ask for the learner's state), what a recording starts from
//! ([`StartState`]), and a read-only gauge on the queue for `/metrics` ([`RecorderGauge`]).
//!
//! The tick feed and the event log put into this queue, and the recorder (`storage::recorder`) takes from
//! it; it lives here, below both, so that neither reaches into the other.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use pavlov::agent::StageSnapshot;
use pavlov::event::Event;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, oneshot};

use super::events::EventLog;

/// How a recording asks the learning actor for the learner's state between two ticks.
pub(crate) type SnapshotSource = mpsc::Sender<oneshot::Sender<StartState>>;

/// What goes through the recorder's queue.
#[derive(Debug)]
pub enum RecorderInput {
    /// A tick's record.
    Tick(Arc<TickRecord>),
    /// A change made at run time.
    Event(Arc<Event>),
    /// The running server: where to ask for the learner's state, and where to announce recordings.
    Attach {
        /// The learning actor's snapshot requests.
        snapshots: SnapshotSource,
        /// The event log (for `recording_started` / `recording_stopped`).
        events: EventLog,
        /// The learner's state before the first tick, where a recording asked for at spawn begins.
        initial: Box<StartState>,
    },
}

/// Where the run stood when a recording began.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartState {
    /// The last tick the learner had handled (`None`: the recording begins with the run); the recording
    /// holds the ticks after it.
    pub after: Option<u64>,
    /// Events with a smaller id happened before the recording (the learner's state includes them).
    pub events_before: u64,
    /// The learner's complete state: weights, traces, parameters in force, previous step, stall level.
    pub learner: StageSnapshot,
}

/// The recorder queue's figures, readable without keeping the queue open.
#[derive(Clone)]
pub(crate) struct RecorderGauge {
    queue: Option<mpsc::WeakSender<RecorderInput>>,
    dropped: Arc<AtomicU64>,
}

impl RecorderGauge {
    /// A gauge on a recorder queue (`None`: no recorder) and its drop counter.
    pub(crate) fn new(
        queue: Option<mpsc::WeakSender<RecorderInput>>,
        dropped: Arc<AtomicU64>,
    ) -> Self {
        RecorderGauge { queue, dropped }
    }

    /// Whether the feed has a recorder attached.
    pub(crate) fn attached(&self) -> bool {
        self.queue.is_some()
    }

    /// Records queued and not yet taken by the recorder (0 once the feed is gone).
    pub(crate) fn backlog(&self) -> usize {
        self.queue
            .as_ref()
            .and_then(|weak| weak.upgrade())
            .map_or(0, |tx| tx.max_capacity().saturating_sub(tx.capacity()))
    }

    /// Records the recorder could not take because its queue was full.
    pub(crate) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}
