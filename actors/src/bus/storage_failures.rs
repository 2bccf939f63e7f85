//! The count of storage failures among the events made: the event log counts them as it numbers each
//! event, and `/metrics` reads the figures.

use std::sync::atomic::Ordering;

use super::counter_set::counter_set;

counter_set! {
    /// A copy of [`StorageFailures`] at one moment.
    pub(crate) struct StorageFigures;
    /// Failures to write to storage, counted as their events are made (`recording_stopped` with a reason,
    /// `checkpoint_failed`; see [`pavlov::event::EventKind::effects`]) by the event log, which
    /// every writer announces through. Every server has one.
    atomic pub(crate) struct StorageFailures;
    "pavlov_recording_failures_total" counter "Recordings stopped because writing them failed (open, write, flush or finish; each sent a \
         recording_stopped event with the reason)." {
        /// Recordings stopped because a write (open, write, flush or finish) failed.
        pub(crate) recordings: u64,
    }
    "pavlov_checkpoint_failures_total" counter "Checkpoints and saves that could not be written (each sent a checkpoint_failed event with the \
         reason; its temporary file removed)." {
        /// Checkpoints and saves that could not be written.
        pub(crate) checkpoints: u64,
    }
}

impl StorageFailures {
    /// Counts `kind` if it reports a storage failure.
    pub(crate) fn count(&self, kind: &pavlov::event::EventKind) {
        use pavlov::event::StorageFailure;
        let counter = match kind.effects().storage_failure {
            Some(StorageFailure::Recording) => &self.recordings,
            Some(StorageFailure::Checkpoint) => &self.checkpoints,
            None => return,
        };
        counter.fetch_add(1, Ordering::Relaxed);
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
