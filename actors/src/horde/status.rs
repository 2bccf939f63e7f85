//! What the Horde thread reports: its shape, how it keeps up, and its checkpoints.

use std::sync::atomic::{AtomicU64, Ordering};

pub use crate::telemetry::horde_status::HordeStatus;

/// Counters written by learning's task and read by the Horde thread.
#[derive(Debug, Default)]
pub(crate) struct OfferCounters {
    /// Ticks learning offered.
    pub(crate) offered: AtomicU64,
    /// Of those, offered while the queue was full.
    pub(crate) skipped_busy: AtomicU64,
}

impl OfferCounters {
    pub(crate) fn skipped(&self) -> u64 {
        self.skipped_busy.load(Ordering::Relaxed)
    }
}
