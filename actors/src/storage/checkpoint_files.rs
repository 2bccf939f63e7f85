//! Checkpoint files on disk: atomic writes off the tick path, pruning to the newest `keep`, and finding
//! and checking the newest one for `--resume`.
//!
//! A checkpoint is written to `<dir>/.checkpoint-<tick>.json.tmp`, fsynced, renamed to
//! `<dir>/checkpoint-<tick>.json` and the directory fsynced: a crash leaves either the old set of files
//! or the new one, plus at worst a hidden `.tmp` that nothing reads.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use pavlov::config::Config;
use pavlov::learn::checkpoint::{Checkpoint, CheckpointError};

/// Errors finding or reading a checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum ResumeError {
    #[error("cannot read the checkpoint directory {dir}: {source}")]
    Dir {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("no checkpoint (checkpoint-<tick>.json) in {0} to resume from")]
    None(PathBuf),
    #[error("cannot read checkpoint {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("checkpoint {path} is not valid: {source}")]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("checkpoint {path} cannot be resumed: {source}")]
    Refused {
        path: PathBuf,
        source: CheckpointError,
    },
}

/// The tick of a file named `checkpoint-<tick>.json`.
pub(crate) fn tick_of_file_name(name: &str) -> Option<u64> {
    name.strip_prefix("checkpoint-")?
        .strip_suffix(".json")?
        .parse()
        .ok()
}

/// The checkpoint files in `dir`, oldest first.
pub fn list(dir: &Path) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        if let Some(tick) = entry.file_name().to_str().and_then(tick_of_file_name) {
            found.push((tick, entry.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// Writes `checkpoint` atomically into `dir` and returns its path.
pub fn write_atomic(dir: &Path, checkpoint: &Checkpoint) -> std::io::Result<PathBuf> {
    use std::io::Write;
    std::fs::create_dir_all(dir)?;
    let name = format!("checkpoint-{}.json", checkpoint.created_tick);
    let tmp = dir.join(format!(".{name}.tmp"));
    let path = dir.join(&name);
    let json = serde_json::to_vec(checkpoint).map_err(std::io::Error::other)?;
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&json)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, &path)?;
    std::fs::File::open(dir)?.sync_all()?;
    Ok(path)
}

/// Deletes all but the newest `keep` checkpoint files in `dir`.
pub(crate) fn prune(dir: &Path, keep: usize) -> std::io::Result<()> {
    let files = list(dir)?;
    let excess = files.len().saturating_sub(keep);
    for (_, path) in files.into_iter().take(excess) {
        std::fs::remove_file(path)?;
    }
    Ok(())
}

/// The newest checkpoint in `config`'s directory, checked against `config`.
pub fn load_for_resume(config: &Config) -> Result<(PathBuf, Checkpoint), ResumeError> {
    let dir = PathBuf::from(&config.checkpoint.dir);
    let files = match list(&dir) {
        Ok(files) => files,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(ResumeError::None(dir)),
        Err(source) => return Err(ResumeError::Dir { dir, source }),
    };
    let Some((_, path)) = files.last().cloned() else {
        return Err(ResumeError::None(dir));
    };
    let text = std::fs::read(&path).map_err(|source| ResumeError::Read {
        path: path.clone(),
        source,
    })?;
    let checkpoint: Checkpoint =
        serde_json::from_slice(&text).map_err(|source| ResumeError::Parse {
            path: path.clone(),
            source,
        })?;
    checkpoint
        .check_against(config)
        .map_err(|source| ResumeError::Refused {
            path: path.clone(),
            source,
        })?;
    Ok((path, checkpoint))
}

/// A thread that writes checkpoints handed to it, so the tick path never touches the disk.
pub(crate) struct CheckpointWriter {
    queue: Option<SyncSender<Checkpoint>>,
    thread: Option<JoinHandle<()>>,
}

impl CheckpointWriter {
    /// Starts the writer for `dir`, keeping the newest `keep` files.
    pub(crate) fn spawn(dir: PathBuf, keep: usize) -> std::io::Result<Self> {
        let (tx, rx) = sync_channel(2);
        let thread = std::thread::Builder::new()
            .name("checkpoint-writer".into())
            .spawn(move || write_loop(&dir, keep, &rx))?;
        Ok(CheckpointWriter {
            queue: Some(tx),
            thread: Some(thread),
        })
    }

    /// Queues a checkpoint without waiting; if the writer is behind, this one is dropped.
    pub(crate) fn submit(&self, checkpoint: Checkpoint) {
        if let Some(q) = &self.queue {
            match q.try_send(checkpoint) {
                Ok(()) => {}
                Err(TrySendError::Full(c)) => tracing::warn!(
                    tick = c.created_tick,
                    "checkpoint writer is behind; a periodic checkpoint was skipped"
                ),
                Err(TrySendError::Disconnected(_)) => {
                    tracing::error!("checkpoint writer is gone")
                }
            }
        }
    }

    /// Queues `last` (waiting for room), then waits until everything queued is on disk. Blocking.
    pub(crate) fn finish(mut self, last: Option<Checkpoint>) {
        if let (Some(q), Some(c)) = (self.queue.take(), last)
            && q.send(c).is_err()
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

fn write_loop(dir: &Path, keep: usize, rx: &Receiver<Checkpoint>) {
    while let Ok(c) = rx.recv() {
        match write_atomic(dir, &c) {
            Ok(path) => tracing::info!(path = %path.display(), "checkpoint written"),
            Err(e) => tracing::error!("cannot write checkpoint into {}: {e}", dir.display()),
        }
        if let Err(e) = prune(dir, keep) {
            tracing::error!("cannot prune checkpoints in {}: {e}", dir.display());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_checkpoint_tick_json_names_count() {
        assert_eq!(tick_of_file_name("checkpoint-12.json"), Some(12));
        for bad in [
            ".checkpoint-12.json.tmp",
            "checkpoint-.json",
            "checkpoint-1x.json",
            "weights-tick3.json",
        ] {
            assert_eq!(tick_of_file_name(bad), None, "{bad}");
        }
    }
}
