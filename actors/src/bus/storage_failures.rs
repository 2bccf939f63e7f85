//! The count of storage failures among the events made: the event log counts them as it numbers each
//! event, and `/metrics` reads the figures.

use std::sync::atomic::{AtomicU64, Ordering};

/// Failures to write to storage, counted as their events are made (`recording_stopped` with a reason,
/// `checkpoint_failed`; see [`pavlov::event::EventKind::is_storage_failure`]) by the event log, which every
/// writer announces through. Every server has one.
#[derive(Debug, Default)]
pub(crate) struct StorageFailures {
    /// Recordings stopped because a write (open, write, flush or finish) failed.
    recordings: AtomicU64,
    /// Checkpoints and saves that could not be written.
    checkpoints: AtomicU64,
}

/// A copy of [`StorageFailures`] at one moment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub(crate) struct StorageFigures {
    /// Recordings stopped by a write error.
    pub(crate) recordings: u64,
    /// Checkpoints and saves that could not be written.
    pub(crate) checkpoints: u64,
}

impl StorageFailures {
    /// Counts `kind` if it reports a storage failure.
    pub(crate) fn count(&self, kind: &pavlov::event::EventKind) {
        use pavlov::event::EventKind;
        if !kind.is_storage_failure() {
            return;
        }
        let counter = match kind {
            EventKind::CheckpointFailed { .. } => &self.checkpoints,
            _ => &self.recordings,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// The figures now.
    pub(crate) fn figures(&self) -> StorageFigures {
        StorageFigures {
            recordings: self.recordings.load(Ordering::Relaxed),
            checkpoints: self.checkpoints.load(Ordering::Relaxed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::event::EventKind;

    #[test]
    fn only_failures_are_counted_each_in_its_own_counter() {
        let c = StorageFailures::default();
        let stopped = |reason: Option<&str>| EventKind::RecordingStopped {
            path: "r".into(),
            reason: reason.map(str::to_string),
        };
        c.count(&stopped(None));
        c.count(&EventKind::WeightsReset);
        assert_eq!(c.figures(), StorageFigures::default());
        c.count(&stopped(Some("File too large (os error 27)")));
        c.count(&EventKind::CheckpointFailed {
            path: "w".into(),
            reason: "No space left on device (os error 28)".into(),
        });
        c.count(&EventKind::CheckpointFailed {
            path: "w".into(),
            reason: "No space left on device (os error 28)".into(),
        });
        assert_eq!(
            c.figures(),
            StorageFigures {
                recordings: 1,
                checkpoints: 2
            }
        );
    }
}
