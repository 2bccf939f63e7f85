//! The checkpoint writer: a thread that writes the learning actor's checkpoints and saves, so the tick
//! path never touches the disk.
//!
//! Automatic checkpoints go into this run's folder, which is then pruned to `keep`; a periodic one that
//! finds the queue full is skipped (and logged), never waited for. Saves (`save_weights`) go into
//! `saved/` under its rules and quota ([`super::saves`]), one at a time: a save asked for while
//! another is pending is answered `busy`, so clients can neither fill the queue nor crowd out the
//! automatic checkpoints. A save's reply is sent once the file is on disk (or refused).

use pavlov::event::EventKind;

use crate::pipeline::events::EventLog;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use pavlov::learn::checkpoint::Checkpoint;

use super::layout::{encode, prune, write_atomic};
use super::saves::{SaveQuota, write_save};
use crate::command::{Applied, CommandError, Reply};

/// Where and how the writer writes.
#[derive(Debug, Clone)]
pub(crate) struct WriterSettings {
    /// This run's folder for automatic checkpoints (`None`: this writer only writes saves).
    pub(crate) run_dir: Option<PathBuf>,
    /// How many automatic checkpoints of this run to keep.
    pub(crate) keep: usize,
    /// The folder of saves.
    pub(crate) saved_dir: PathBuf,
    /// The saves' quota.
    pub(crate) quota: SaveQuota,
}

/// A save to write.
pub(crate) struct SaveJob {
    /// The file name in `saved/`.
    pub(crate) name: String,
    /// The server made the name up: add a suffix rather than refuse when it is taken.
    pub(crate) unique: bool,
    /// What to write.
    pub(crate) checkpoint: Checkpoint,
    /// Where the outcome goes.
    pub(crate) reply: Reply,
    /// Where a successful save is announced, and after which tick.
    pub(crate) announce: Option<(EventLog, Option<u64>)>,
}

enum Job {
    Auto(Checkpoint),
    Save(Box<SaveJob>),
}

/// A thread that writes checkpoints handed to it.
pub(crate) struct CheckpointWriter {
    queue: Option<SyncSender<Job>>,
    thread: Option<JoinHandle<()>>,
    save_pending: Arc<AtomicBool>,
}

impl CheckpointWriter {
    /// Starts the writer.
    pub(crate) fn spawn(settings: WriterSettings) -> std::io::Result<Self> {
        // Two automatic checkpoints and the one pending save.
        let (tx, rx) = sync_channel(3);
        let save_pending = Arc::new(AtomicBool::new(false));
        let pending = save_pending.clone();
        let thread = std::thread::Builder::new()
            .name("checkpoint-writer".into())
            .spawn(move || write_loop(&settings, &rx, &pending))?;
        Ok(CheckpointWriter {
            queue: Some(tx),
            thread: Some(thread),
            save_pending,
        })
    }

    /// Queues an automatic checkpoint without waiting; if the writer is behind, this one is dropped.
    pub(crate) fn submit(&self, checkpoint: Checkpoint) {
        let Some(q) = &self.queue else { return };
        match q.try_send(Job::Auto(checkpoint)) {
            Ok(()) => {}
            Err(TrySendError::Full(Job::Auto(c))) => tracing::warn!(
                tick = c.created_tick,
                "checkpoint writer is behind; a periodic checkpoint was skipped"
            ),
            Err(TrySendError::Full(_)) => {}
            Err(TrySendError::Disconnected(_)) => tracing::error!("checkpoint writer is gone"),
        }
    }

    /// Queues a save without waiting; answers `busy` at once while another save is pending.
    pub(crate) fn submit_save(&self, job: SaveJob) {
        let busy = CommandError::Busy("checkpoint writer");
        let Some(q) = &self.queue else {
            let _ = job.reply.send(Err(busy));
            return;
        };
        if self.save_pending.swap(true, Ordering::AcqRel) {
            let _ = job.reply.send(Err(busy));
            return;
        }
        if let Err(e) = q.try_send(Job::Save(Box::new(job))) {
            self.save_pending.store(false, Ordering::Release);
            let (job, err) = match e {
                TrySendError::Full(job) => (job, busy),
                TrySendError::Disconnected(job) => (
                    job,
                    CommandError::Unavailable("the checkpoint writer is gone".into()),
                ),
            };
            if let Job::Save(job) = job {
                let _ = job.reply.send(Err(err));
            }
        }
    }

    /// Queues `last` (waiting for room), then waits until everything queued is on disk. Blocking.
    pub(crate) fn finish(mut self, last: Option<Checkpoint>) {
        if let (Some(q), Some(c)) = (self.queue.take(), last)
            && q.send(Job::Auto(c)).is_err()
        {
            tracing::error!("checkpoint writer is gone; the final checkpoint was lost");
        }
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            tracing::error!("checkpoint writer panicked");
        }
    }
}

fn write_loop(settings: &WriterSettings, rx: &Receiver<Job>, save_pending: &AtomicBool) {
    while let Ok(job) = rx.recv() {
        match job {
            Job::Auto(c) => write_automatic(settings, &c),
            Job::Save(job) => {
                let outcome = save(settings, &job.name, job.unique, &job.checkpoint);
                save_pending.store(false, Ordering::Release);
                if let (Ok(Applied::Saved { path }), Some((events, after))) =
                    (&outcome, &job.announce)
                {
                    events.emit(*after, EventKind::WeightsSaved { path: path.clone() });
                }
                let _ = job.reply.send(outcome);
            }
        }
    }
}

fn write_automatic(settings: &WriterSettings, c: &Checkpoint) {
    let Some(run_dir) = &settings.run_dir else {
        tracing::error!(
            tick = c.created_tick,
            "an automatic checkpoint without a run folder was not written"
        );
        return;
    };
    match write_atomic(run_dir, c) {
        Ok(path) => tracing::info!(path = %path.display(), "checkpoint written"),
        Err(e) => tracing::error!(
            tick = c.created_tick,
            "cannot write a checkpoint into {}: {e}",
            run_dir.display()
        ),
    }
    if let Err(e) = prune(run_dir, settings.keep) {
        tracing::error!("cannot prune checkpoints in {}: {e}", run_dir.display());
    }
}

fn save(
    settings: &WriterSettings,
    name: &str,
    unique: bool,
    c: &Checkpoint,
) -> Result<Applied, CommandError> {
    // Refusals go back to the client (and are counted as error replies); a flood must not flood the log.
    let rejected = |e: String| {
        tracing::debug!("save_weights refused: {e}");
        CommandError::Rejected(e)
    };
    let bytes = encode(c, true).map_err(|e| rejected(format!("save_weights: {e}")))?;
    let path = write_save(&settings.saved_dir, name, unique, &bytes, settings.quota)
        .map_err(|e| rejected(e.to_string()))?;
    tracing::info!(path = %path.display(), "weights saved");
    Ok(Applied::Saved {
        path: path.display().to_string(),
    })
}
