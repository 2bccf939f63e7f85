//! The recorder's queue: what goes through it ([`RecorderInput`]: ticks, events, and the attachment that
//! tells the recorder where to ask for the learner's state), what a recording starts from
//! ([`StartState`]), and a read-only gauge on the queue for `/metrics` (`RecorderGauge`).
//!
//! The tick feed and the event log put into this queue, and the recorder (`storage::recorder`) takes from
//! it; it lives on the bus, below both, so that neither reaches into the other. The queue's item is
//! defined beside the event log ([`super::events`]), because each holds the other: the log sends events
//! into the queue, and the queue's attachment carries the log.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::sync::mpsc;

pub(crate) use super::events::SnapshotSource;
pub use super::events::{RecorderInput, StartState};

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
