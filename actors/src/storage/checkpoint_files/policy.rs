//! A run's checkpoint-file policy, for the learning actor: where the automatic checkpoints of this run
//! go (a new `[checkpoint] dir/runs/<run id>/` folder), how often one is due (`every_s` in ticks), what a
//! save is called when the client names none, and when the writer's thread is started (with autosave, or
//! at the first save). The actor builds the checkpoints between two ticks and hands them here; nothing in
//! this file waits, but [`CheckpointFiles::finish`], which the actor runs off the runtime.

use std::path::{Path, PathBuf};

use pavlov::checkpoint::Checkpoint;
use pavlov::config::CheckpointConfig;

use super::layout::create_run_dir;
use super::saves::{SaveQuota, check_save_name, saved_dir};
use super::writer::{Announce, CheckpointWriter, SaveJob, WriterSettings};
use crate::command::{CommandError, Reply};
use crate::storage::utc;

/// Periodic and final checkpoints of the learned state, into this run's folder.
struct Autosave {
    every_ticks: u64,
    last_seq: u64,
    run_dir: PathBuf,
}

/// The checkpoint files of one run: the writer (started with autosave, or at the first save) and the
/// autosave schedule.
pub(crate) struct CheckpointFiles {
    config: CheckpointConfig,
    period_ms: u64,
    writer: Option<CheckpointWriter>,
    autosave: Option<Autosave>,
}

impl CheckpointFiles {
    /// No autosave and no writer yet, for `config` at a tick of `period_ms`.
    pub(crate) fn new(config: &CheckpointConfig, period_ms: u64) -> Self {
        CheckpointFiles {
            config: config.clone(),
            period_ms: period_ms.max(1),
            writer: None,
            autosave: None,
        }
    }

    /// Where the writer puts the checkpoints and saves.
    fn settings(&self, run_dir: Option<PathBuf>) -> WriterSettings {
        WriterSettings {
            run_dir,
            keep: self.config.keep,
            saved_dir: saved_dir(Path::new(&self.config.dir)),
            quota: SaveQuota::of(&self.config),
        }
    }

    /// Checkpoints into a new run folder, `[checkpoint] dir/runs/<run id>/`, every `every_s` seconds of
    /// ticks and when the run ends.
    pub(crate) fn start_autosave(&mut self) -> std::io::Result<()> {
        let run_dir = create_run_dir(Path::new(&self.config.dir))?;
        let every_ticks = (self.config.every_s * 1000).div_ceil(self.period_ms);
        if let Some(old) = self.writer.take() {
            old.finish(None);
        }
        self.writer = Some(CheckpointWriter::spawn(
            self.settings(Some(run_dir.clone())),
        )?);
        self.autosave = Some(Autosave {
            every_ticks,
            last_seq: 0,
            run_dir,
        });
        Ok(())
    }

    /// This run's folder of automatic checkpoints (with autosave).
    pub(crate) fn run_dir(&self) -> Option<&Path> {
        self.autosave.as_ref().map(|a| a.run_dir.as_path())
    }

    /// How many automatic checkpoints of this run are kept.
    pub(crate) fn keep(&self) -> usize {
        self.config.keep
    }

    /// Whether a periodic checkpoint is due at tick `seq`; if so, it is counted as made, and this run's
    /// folder is returned.
    pub(crate) fn due(&mut self, seq: u64) -> Option<PathBuf> {
        let a = self.autosave.as_mut()?;
        if a.every_ticks == 0 || seq < a.last_seq + a.every_ticks {
            return None;
        }
        a.last_seq = seq;
        Some(a.run_dir.clone())
    }

    /// Hands a periodic checkpoint to the writer, without waiting.
    pub(crate) fn submit(&self, checkpoint: Checkpoint, announce: Option<Announce>) {
        if let Some(w) = &self.writer {
            w.submit(checkpoint, announce);
        }
    }

    /// The file name of a save: the client's (`name`, checked: a plain name that is not an automatic
    /// checkpoint's), or `weights-<UTC stamp>-tick<tick>.json`, which the writer makes unique. The flag
    /// says which.
    pub(crate) fn save_name(name: Option<String>, tick: u64) -> Result<(String, bool), String> {
        let (name, unique) = match name {
            Some(name) => (name, false),
            None => {
                let stamp = utc::stamp(std::time::SystemTime::now());
                (format!("weights-{stamp}-tick{tick}.json"), true)
            }
        };
        check_save_name(&name).map_err(|e| e.to_string())?;
        Ok((name, unique))
    }

    /// Hands a save to the writer (starting it if need be), which answers `job.reply` when the file is
    /// on disk or refused.
    pub(crate) fn save(&mut self, job: SaveJob) {
        if self.writer.is_none() {
            match CheckpointWriter::spawn(self.settings(None)) {
                Ok(w) => self.writer = Some(w),
                Err(e) => {
                    let reply: Reply = job.reply;
                    let _ = reply.send(Err(CommandError::Unavailable(format!(
                        "cannot start the checkpoint writer: {e}"
                    ))));
                    return;
                }
            }
        }
        if let Some(w) = &self.writer {
            w.submit_save(job);
        }
    }

    /// Ends autosave: this run's folder and how many checkpoints it keeps, if autosave was on (the
    /// final checkpoint and the Horde's last one go there).
    pub(crate) fn end_autosave(&mut self) -> Option<(PathBuf, usize)> {
        self.autosave.take().map(|a| (a.run_dir, self.config.keep))
    }

    /// Queues `last` and waits until every checkpoint is on disk. Blocking.
    pub(crate) fn finish(mut self, last: Option<(Checkpoint, Option<Announce>)>) {
        if let Some(writer) = self.writer.take() {
            writer.finish(last);
        }
    }

    /// Whether there is a writer to finish.
    pub(crate) fn writing(&self) -> bool {
        self.writer.is_some()
    }
}
