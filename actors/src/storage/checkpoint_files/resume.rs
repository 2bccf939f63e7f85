//! Finding the checkpoint `--resume` continues from: the newest valid one of this configuration, over
//! every run in `[checkpoint] dir`, with the reason for every newer one it skipped.
//!
//! Candidates are every run's automatic checkpoints (`runs/<run id>/checkpoint-<tick>.json`) and the
//! flat `checkpoint-<tick>.json` files of earlier versions, which count as one run older than all
//! others. Newest means the latest run (run ids begin with the run's UTC start time), then the highest
//! tick; folders in `runs/` not named like a run id are not searched. Saves (`saved/`) are never candidates: `--resume-from FILE` names one. A candidate is skipped
//! when it cannot be read, is not JSON (a torn write), is not a checkpoint, holds a non-finite number
//! (serde_json writes NaN as `null`), belongs to another configuration (the differences are named), or
//! the learner refuses to restore it. With no candidate at all, or none valid, resuming is refused
//! (never silently started fresh).

use std::path::{Path, PathBuf};

use pavlov::checkpoint::{Checkpoint, CheckpointError, ParamOverride, check_finite};
use pavlov::config::Config;

use super::layout::{RUNS_DIR, is_run_id, list};

/// Why a checkpoint file was not resumed from.
#[derive(Debug, thiserror::Error)]
pub enum SkipReason {
    /// The file could not be read.
    #[error("unreadable: {0}")]
    Unreadable(std::io::Error),
    /// The file is not JSON (e.g. cut short by a crash).
    #[error("not JSON (truncated or damaged): {0}")]
    NotJson(serde_json::Error),
    /// The file is JSON but not a checkpoint.
    #[error("not a checkpoint: {0}")]
    NotACheckpoint(serde_json::Error),
    /// A weight or trace is NaN or infinite (written as `null`).
    #[error("non-finite weights: prediction `{prediction}`: {field} is not a finite number")]
    NonFinite {
        /// The prediction.
        prediction: String,
        /// The value (`weights[12]`).
        field: String,
    },
    /// The checkpoint was made for another configuration, is of another format, or was edited.
    #[error("{}", refused_text(.0))]
    Refused(CheckpointError),
    /// The learner refused to restore it.
    #[error("cannot be restored: {0}")]
    NotRestorable(String),
}

fn refused_text(e: &CheckpointError) -> String {
    match e {
        CheckpointError::Mismatch { differences } => {
            format!("another configuration: {}", differences.join("; "))
        }
        other => other.to_string(),
    }
}

/// A checkpoint that was passed over, and why.
#[derive(Debug)]
pub struct Skipped {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub reason: SkipReason,
}

impl std::fmt::Display for Skipped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.reason)
    }
}

/// Errors finding a checkpoint to resume from.
#[derive(Debug, thiserror::Error)]
pub enum ResumeError {
    /// The checkpoint directory could not be read.
    #[error("cannot read the checkpoint directory {dir}: {source}")]
    Dir {
        /// The directory.
        dir: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// There is no automatic checkpoint at all.
    #[error(
        "no checkpoint (runs/<run id>/checkpoint-<tick>.json or checkpoint-<tick>.json) in {0} to resume from"
    )]
    None(PathBuf),
    /// Every checkpoint was skipped.
    #[error("no valid checkpoint in {dir} to resume from; {} skipped: {}", .skipped.len(), list_skipped(.skipped))]
    NoneValid {
        /// The directory.
        dir: PathBuf,
        /// Every checkpoint, newest first, with its reason.
        skipped: Vec<Skipped>,
    },
    /// The file named by `--resume-from` cannot be resumed.
    #[error("cannot resume from {}: {reason}", .path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: SkipReason,
    },
}

fn list_skipped(skipped: &[Skipped]) -> String {
    skipped
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(" | ")
}

/// The checkpoint resumed from, and what was learned on the way.
#[derive(Debug)]
pub struct Resumed {
    /// The file.
    pub path: PathBuf,
    /// The lifelong tick it was taken at.
    pub tick: u64,
    /// Newer checkpoints passed over, newest first.
    pub skipped: Vec<Skipped>,
    /// Learning parameters the checkpoint carries that differ from the configuration's; the
    /// checkpoint's are in force.
    pub overrides: Vec<ParamOverride>,
}

impl Resumed {
    /// What to tell the operator, one line each: the checkpoint, every one skipped, every override.
    pub fn report_lines(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "resuming from {} (tick {})",
            self.path.display(),
            self.tick
        )];
        lines.extend(
            self.skipped
                .iter()
                .map(|s| format!("skipped the newer checkpoint {s}")),
        );
        lines.extend(self.overrides.iter().map(|o| format!("resumed {o}")));
        lines
    }
}

/// An automatic checkpoint file found in `[checkpoint] dir`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Candidate {
    /// The run's folder name; `None` for the flat files of earlier versions (older than every run).
    pub run: Option<String>,
    /// The lifelong tick in its name.
    pub tick: u64,
    /// The file.
    pub path: PathBuf,
}

/// Every automatic checkpoint in `dir`, oldest first (by run, then tick).
pub fn candidates(dir: &Path) -> Result<Vec<Candidate>, ResumeError> {
    let dir_error = |dir: &Path| {
        let dir = dir.to_path_buf();
        move |source| ResumeError::Dir { dir, source }
    };
    let legacy = match list(dir) {
        Ok(files) => files,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(dir_error(dir)(e)),
    };
    let mut found: Vec<Candidate> = legacy
        .into_iter()
        .map(|(tick, path)| Candidate {
            run: None,
            tick,
            path,
        })
        .collect();
    let runs = dir.join(RUNS_DIR);
    let entries = match std::fs::read_dir(&runs) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(found),
        Err(e) => return Err(dir_error(&runs)(e)),
    };
    for entry in entries {
        let entry = entry.map_err(dir_error(&runs))?;
        let Some(name) = entry.file_name().to_str().map(str::to_string) else {
            continue;
        };
        if !is_run_id(&name) || !entry.path().is_dir() {
            continue;
        }
        for (tick, path) in list(&entry.path()).map_err(dir_error(&entry.path()))? {
            found.push(Candidate {
                run: Some(name.clone()),
                tick,
                path,
            });
        }
    }
    found.sort();
    Ok(found)
}

/// The first non-finite (`null`) weight or trace in a checkpoint's JSON, if any.
fn null_in_state(value: &serde_json::Value) -> Option<SkipReason> {
    let predictions = value.get("state")?.get("predictions")?.as_array()?;
    for p in predictions {
        let name = p.get("name").and_then(|n| n.as_str()).unwrap_or("?");
        for what in ["weights", "traces"] {
            let Some(values) = p.get(what).and_then(|v| v.as_array()) else {
                continue;
            };
            if let Some(i) = values.iter().position(serde_json::Value::is_null) {
                return Some(SkipReason::NonFinite {
                    prediction: name.to_string(),
                    field: format!("{what}[{i}]"),
                });
            }
        }
    }
    None
}

/// Reads `path` and checks it may be resumed under `config` (not yet restored).
pub fn load_checked(config: &Config, path: &Path) -> Result<Checkpoint, SkipReason> {
    let bytes = std::fs::read(path).map_err(SkipReason::Unreadable)?;
    let value: serde_json::Value = serde_json::from_slice(&bytes).map_err(SkipReason::NotJson)?;
    if let Some(reason) = null_in_state(&value) {
        return Err(reason);
    }
    let checkpoint: Checkpoint =
        serde_json::from_value(value).map_err(SkipReason::NotACheckpoint)?;
    check_finite(&checkpoint.state).map_err(|e| match e {
        CheckpointError::NonFinite {
            prediction, field, ..
        } => SkipReason::NonFinite { prediction, field },
        other => SkipReason::Refused(other),
    })?;
    checkpoint
        .check_against(config)
        .map_err(SkipReason::Refused)?;
    Ok(checkpoint)
}

/// Restores the newest valid checkpoint in `config`'s `[checkpoint] dir` with `restore` (which must
/// leave the learner untouched when it fails), falling back to older ones.
pub fn resume_newest(
    config: &Config,
    mut restore: impl FnMut(&Checkpoint) -> Result<(), String>,
) -> Result<Resumed, ResumeError> {
    let dir = PathBuf::from(&config.checkpoint.dir);
    let found = candidates(&dir)?;
    if found.is_empty() {
        return Err(ResumeError::None(dir));
    }
    let mut skipped = Vec::new();
    for c in found.into_iter().rev() {
        let loaded = load_checked(config, &c.path).and_then(|cp| {
            restore(&cp).map_err(SkipReason::NotRestorable)?;
            Ok(cp)
        });
        match loaded {
            Ok(checkpoint) => {
                return Ok(Resumed {
                    overrides: checkpoint.param_overrides(config),
                    path: c.path,
                    tick: checkpoint.created_tick,
                    skipped,
                });
            }
            Err(reason) => skipped.push(Skipped {
                path: c.path,
                reason,
            }),
        }
    }
    Err(ResumeError::NoneValid { dir, skipped })
}

/// Restores the checkpoint file `path` (an automatic checkpoint or a save) with `restore`; no fallback.
pub fn resume_file(
    config: &Config,
    path: &Path,
    restore: impl FnOnce(&Checkpoint) -> Result<(), String>,
) -> Result<Resumed, ResumeError> {
    let file_error = |reason| ResumeError::File {
        path: path.to_path_buf(),
        reason,
    };
    let checkpoint = load_checked(config, path).map_err(file_error)?;
    restore(&checkpoint).map_err(|e| file_error(SkipReason::NotRestorable(e)))?;
    Ok(Resumed {
        overrides: checkpoint.param_overrides(config),
        path: path.to_path_buf(),
        tick: checkpoint.created_tick,
        skipped: Vec::new(),
    })
}

/// The checkpoint `--resume` would take (the newest valid one, or `[checkpoint] resume_from`), checked
/// against `config` but not restored: to refuse early, before anything is started.
pub fn load_for_resume(config: &Config) -> Result<(Resumed, Checkpoint), ResumeError> {
    let mut taken = None;
    let keep = |cp: &Checkpoint| {
        taken = Some(cp.clone());
        Ok(())
    };
    let resumed = match &config.checkpoint.resume_from {
        Some(file) => resume_file(config, Path::new(file), keep)?,
        None => resume_newest(config, keep)?,
    };
    match taken {
        Some(cp) => Ok((resumed, cp)),
        None => Err(ResumeError::None(PathBuf::from(&config.checkpoint.dir))),
    }
}
