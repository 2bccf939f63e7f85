//! The event log: every change made at run time (see [`pavlov::event`]) goes out from here, numbered, to
//! the log (once, at INFO with its arguments; teleop at DEBUG), to live subscribers (the dashboard hub,
//! tests) and to the recorder, without ever blocking the actor that made it. It also keeps the last
//! `RECENT_CAPACITY` events (teleop aside), so that a subscriber that starts late (the dashboard hub starts
//! after a recording begun with `--record`) still learns what happened before it.
//!
//! The recorder's queue item ([`RecorderInput`]) is defined here too: the log sends into that queue, and
//! the queue's attachment carries the log (the rest of the queue is in [`super::recorder_queue`]).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use pavlov::agent::StageSnapshot;
use pavlov::event::{Event, EventKind};
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};
use tokio::sync::{broadcast, mpsc, oneshot};

use super::storage_failures::StorageFailures;

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

/// Capacity of the live broadcast, in events.
pub(crate) const LIVE_CAPACITY: usize = 256;
/// Events kept for late subscribers ([`EventLog::subscribe_with_recent`]); frequent ones (teleop) are not.
pub(crate) const RECENT_CAPACITY: usize = 256;

/// The publishing side of the event log; cheap to clone, one per emitting actor.
#[derive(Clone)]
pub struct EventLog {
    next_id: Arc<AtomicU64>,
    live: broadcast::Sender<Arc<Event>>,
    /// The newest events but frequent ones; locked while an event is kept and sent, so that a late
    /// subscriber sees each event exactly once, in the list or on its receiver.
    recent: Arc<Mutex<VecDeque<Arc<Event>>>>,
    recorder: Option<mpsc::Sender<RecorderInput>>,
    dropped: Arc<AtomicU64>,
    /// Storage failures among the events made (for `/metrics`).
    storage_failures: Arc<StorageFailures>,
}

impl EventLog {
    /// A log with no recorder attached.
    pub(crate) fn new() -> Self {
        let (live, _) = broadcast::channel(LIVE_CAPACITY);
        EventLog {
            next_id: Arc::new(AtomicU64::new(1)),
            live,
            recent: Arc::default(),
            recorder: None,
            dropped: Arc::new(AtomicU64::new(0)),
            storage_failures: Arc::default(),
        }
    }

    /// Also hands every event to the recorder's queue, counting what it cannot take in `dropped` (the
    /// tick feed's counter: one queue, one count).
    pub(crate) fn with_recorder(
        mut self,
        recorder: mpsc::Sender<RecorderInput>,
        dropped: Arc<AtomicU64>,
    ) -> Self {
        self.recorder = Some(recorder);
        self.dropped = dropped;
        self
    }

    /// Records that `kind` took effect after tick `after` (the emitting actor's last tick) and returns
    /// the event.
    pub(crate) fn emit(&self, after: Option<u64>, kind: EventKind) -> Arc<Event> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let event = Arc::new(Event { id, after, kind });
        self.storage_failures.count(&event.kind);
        let args = serde_json::to_string(&event.kind).unwrap_or_default();
        if event.kind.is_frequent() {
            tracing::debug!(id, after = ?event.after, event = %args, "event");
        } else {
            tracing::info!(id, after = ?event.after, event = %args, "event");
        }
        if let Some(rec) = &self.recorder
            && rec.try_send(RecorderInput::Event(event.clone())).is_err()
        {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        let mut recent = self.recent.lock().unwrap_or_else(PoisonError::into_inner);
        if !event.kind.is_frequent() {
            if recent.len() == RECENT_CAPACITY {
                recent.pop_front();
            }
            recent.push_back(event.clone());
        }
        // An error only means nobody is subscribed right now.
        let _ = self.live.send(event.clone());
        drop(recent);
        event
    }

    /// The same log without the recorder's queue: for the recorder's own announcements, which it writes
    /// itself (holding its own queue's sender would keep the recorder from ever seeing the end).
    pub(crate) fn detached(&self) -> Self {
        EventLog {
            recorder: None,
            ..self.clone()
        }
    }

    /// The count of storage failures among the events made (shared by every clone of the log).
    pub(crate) fn storage_failures(&self) -> Arc<StorageFailures> {
        self.storage_failures.clone()
    }

    /// The id the next event will get: every event with a smaller id has already been made.
    pub(crate) fn next_id(&self) -> u64 {
        self.next_id.load(Ordering::Relaxed)
    }

    /// A new live subscription, starting with the next event.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<Event>> {
        self.live.subscribe()
    }

    /// The events kept so far (at most [`RECENT_CAPACITY`], oldest first, teleop left out) and a live
    /// subscription starting with the next event: together, every event once.
    pub(crate) fn subscribe_with_recent(
        &self,
    ) -> (Vec<Arc<Event>>, broadcast::Receiver<Arc<Event>>) {
        let recent = self.recent.lock().unwrap_or_else(PoisonError::into_inner);
        (recent.iter().cloned().collect(), self.live.subscribe())
    }

    /// Events the recorder's queue could not take.
    #[cfg(test)]
    pub(crate) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

impl std::fmt::Debug for EventLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventLog")
            .field("next_id", &self.next_id())
            .field("recorder", &self.recorder.is_some())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::Mode;

    #[test]
    fn events_are_numbered_in_order_and_reach_subscribers_and_the_recorder() {
        let (tx, mut rx) = mpsc::channel(1);
        let log = EventLog::new().with_recorder(tx, Arc::default());
        let mut live = log.subscribe();
        assert_eq!(log.next_id(), 1);
        let a = log.emit(None, EventKind::WeightsReset);
        let b = log.emit(Some(3), EventKind::ModeSet { mode: Mode::Manual });
        assert_eq!((a.id, b.id, log.next_id()), (1, 2, 3));
        assert_eq!(live.try_recv().unwrap().id, 1);
        assert_eq!(live.try_recv().unwrap().after, Some(3));
        // The recorder's queue holds one: the second event was dropped and counted, never waited for.
        assert!(matches!(rx.try_recv(), Ok(RecorderInput::Event(e)) if e.id == 1));
        assert_eq!(log.dropped(), 1);
    }

    #[test]
    fn a_late_subscriber_gets_the_recent_events_then_the_live_ones_without_teleop() {
        let log = EventLog::new();
        for _ in 0..RECENT_CAPACITY + 5 {
            log.emit(Some(1), EventKind::WeightsReset);
        }
        log.emit(
            Some(2),
            EventKind::Teleop {
                action: pavlov::control::Action::STOP,
            },
        );
        let (recent, mut live) = log.subscribe_with_recent();
        assert_eq!(recent.len(), RECENT_CAPACITY);
        assert_eq!(recent[0].id, 6, "the oldest were let go");
        assert_eq!(recent.last().unwrap().id, RECENT_CAPACITY as u64 + 5);
        assert!(live.try_recv().is_err(), "nothing emitted since");
        let next = log.emit(Some(3), EventKind::ModeSet { mode: Mode::Manual });
        assert_eq!(live.try_recv().unwrap().id, next.id);
    }
}
