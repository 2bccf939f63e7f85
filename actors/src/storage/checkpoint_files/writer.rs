//! The checkpoint writer: a thread that writes the learning actor's checkpoints and saves, so the tick
//! path never touches the disk.
//!
//! Automatic checkpoints go into this run's folder, which is then pruned to `keep`; a periodic one that
//! finds the queue full is skipped (and logged), never waited for. Saves (`save_weights`) go into
//! `saved/` under its rules and quota ([`super::saves`]), one at a time: a save asked for while
//! another is pending is answered `busy`, so clients can neither fill the queue nor crowd out the
//! automatic checkpoints. A save's reply is sent once the file is on disk (or refused).
//!
//! A checkpoint or save the disk refuses (full, a file-size limit, a permission) is a `checkpoint_failed`
//! event naming the file it was to become and the OS's reason (counted in `/metrics` by the event log);
//! its temporary file is removed ([`super::layout`]), and a save's client is answered with the same
//! error. Refusals by rule (a name, the quota) are answered to the client only.

use pavlov::event::EventKind;

use crate::bus::EventLog;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use pavlov::checkpoint::Checkpoint;

use super::layout::{encode, file_name, prune, write_atomic};
use super::saves::{SaveError, SaveQuota, write_save};
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
    /// Where the outcome (saved, or failed) is announced, and after which tick.
    pub(crate) announce: Option<Announce>,
}

/// Where the writer announces what it did, and the tick after which it took effect.
pub(crate) type Announce = (EventLog, Option<u64>);

enum Job {
    Auto(Checkpoint, Option<Announce>),
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

    /// Queues an automatic checkpoint without waiting; if the writer is behind, this one is dropped. A
    /// failure to write it is announced on `announce`.
    pub(crate) fn submit(&self, checkpoint: Checkpoint, announce: Option<Announce>) {
        let Some(q) = &self.queue else { return };
        match q.try_send(Job::Auto(checkpoint, announce)) {
            Ok(()) => {}
            Err(TrySendError::Full(Job::Auto(c, _))) => tracing::warn!(
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
    pub(crate) fn finish(mut self, last: Option<(Checkpoint, Option<Announce>)>) {
        if let (Some(q), Some((c, announce))) = (self.queue.take(), last)
            && q.send(Job::Auto(c, announce)).is_err()
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
            Job::Auto(c, announce) => write_automatic(settings, &c, announce.as_ref()),
            Job::Save(job) => {
                let outcome = save(settings, &job.name, job.unique, &job.checkpoint);
                save_pending.store(false, Ordering::Release);
                let outcome = match outcome {
                    Ok(path) => {
                        let path = path.display().to_string();
                        tell(
                            &job.announce,
                            EventKind::WeightsSaved { path: path.clone() },
                        );
                        Ok(Applied::Saved { path })
                    }
                    Err(e) => {
                        if let SaveError::Io { path, source } = &e {
                            tell(&job.announce, failed(path, source));
                        }
                        Err(CommandError::Rejected(e.to_string()))
                    }
                };
                let _ = job.reply.send(outcome);
            }
        }
    }
}

/// Announces `kind` on `announce`, if there is somewhere to.
fn tell(announce: &Option<Announce>, kind: EventKind) {
    if let Some((events, after)) = announce {
        events.emit(*after, kind);
    }
}

/// The event of a checkpoint meant to become `path` that could not be written.
fn failed(path: &Path, e: &std::io::Error) -> EventKind {
    EventKind::CheckpointFailed {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

fn write_automatic(settings: &WriterSettings, c: &Checkpoint, announce: Option<&Announce>) {
    let Some(run_dir) = &settings.run_dir else {
        tracing::error!(
            tick = c.created_tick,
            "an automatic checkpoint without a run folder was not written"
        );
        return;
    };
    match write_atomic(run_dir, c) {
        Ok(path) => tracing::info!(path = %path.display(), "checkpoint written"),
        Err(e) => {
            tracing::error!(
                tick = c.created_tick,
                "cannot write a checkpoint into {}: {e}",
                run_dir.display()
            );
            // A non-finite state is refused before anything is written (and logged as such); any other
            // error is the disk's.
            if e.kind() != std::io::ErrorKind::InvalidData {
                let path = run_dir.join(file_name(c.created_tick));
                tell(&announce.cloned(), failed(&path, &e));
            }
        }
    }
    if let Err(e) = prune(run_dir, settings.keep) {
        tracing::error!("cannot prune checkpoints in {}: {e}", run_dir.display());
    }
}

/// Writes a save; the error says whether it was refused by a rule or by the disk ([`SaveError::Io`]).
fn save(
    settings: &WriterSettings,
    name: &str,
    unique: bool,
    c: &Checkpoint,
) -> Result<PathBuf, SaveError> {
    // Refusals go back to the client (and are counted as error replies); a flood must not flood the log.
    let bytes = encode(c, true).map_err(SaveError::Encode)?;
    let path =
        write_save(&settings.saved_dir, name, unique, &bytes, settings.quota).inspect_err(|e| {
            match e {
                SaveError::Io { .. } => tracing::error!("{e}"),
                _ => tracing::debug!("save_weights refused: {e}"),
            }
        })?;
    tracing::info!(path = %path.display(), "weights saved");
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::agent::LearningStage;
    use pavlov::config::Config;

    fn checkpoint(tick: u64) -> Checkpoint {
        let cfg = Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap();
        let stage = LearningStage::new(&cfg).unwrap();
        Checkpoint::new(&cfg, tick, stage.snapshot()).unwrap()
    }

    fn temp(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("pavlov-ckwriter-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn hidden(dir: &Path) -> Vec<std::ffi::OsString> {
        std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .filter(|n| n.to_string_lossy().starts_with('.'))
            .collect()
    }

    #[test]
    fn a_save_and_a_checkpoint_the_disk_refuses_are_announced_with_the_reason_and_leave_no_temporary_file()
     {
        let root = temp("full");
        let (run_dir, saved_dir) = (root.join("run"), root.join("saved"));
        std::fs::create_dir_all(&run_dir).unwrap();
        std::fs::create_dir_all(&saved_dir).unwrap();
        // The temporary files' names lead to /dev/full: writing them fails with ENOSPC, as on a full disk.
        for tmp in [
            run_dir.join(".checkpoint-9.json.tmp"),
            saved_dir.join(".w.json.tmp"),
        ] {
            std::os::unix::fs::symlink("/dev/full", tmp).unwrap();
        }
        let writer = CheckpointWriter::spawn(WriterSettings {
            run_dir: Some(run_dir.clone()),
            keep: 5,
            saved_dir: saved_dir.clone(),
            quota: SaveQuota {
                max_files: 10,
                max_bytes: 1 << 20,
            },
        })
        .unwrap();
        let events = EventLog::new();
        let mut live = events.subscribe();
        let (reply, answer) = tokio::sync::oneshot::channel();
        writer.submit_save(SaveJob {
            name: "w.json".into(),
            unique: false,
            checkpoint: checkpoint(9),
            reply,
            announce: Some((events.clone(), Some(8))),
        });
        let refused = answer.blocking_recv().unwrap().unwrap_err().to_string();
        assert!(refused.contains("No space left on device"), "{refused}");
        writer.finish(Some((checkpoint(9), Some((events.clone(), Some(8))))));

        let mut failed = Vec::new();
        while let Ok(e) = live.try_recv() {
            if let EventKind::CheckpointFailed { path, reason } = &e.kind {
                assert_eq!(e.after, Some(8));
                assert!(reason.contains("No space left on device"), "{reason}");
                failed.push(PathBuf::from(path));
            }
        }
        assert_eq!(
            failed,
            [saved_dir.join("w.json"), run_dir.join("checkpoint-9.json")]
        );
        assert_eq!(events.storage_failures().figures().checkpoints, 2);
        for dir in [&run_dir, &saved_dir] {
            assert!(
                hidden(dir).is_empty(),
                "{:?} in {}",
                hidden(dir),
                dir.display()
            );
            assert_eq!(std::fs::read_dir(dir).unwrap().count(), 0);
        }
        let _ = std::fs::remove_dir_all(&root);
    }
}
