//! A shard file (`shard-I-of-N.json`): what one slice of a study wrote, and how it is found, read and
//! written. [`experiment_of`] reads only a file's head, so the binary can pick the experiment's merger
//! before it parses the runs.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::Shard;
use super::merge::MergeError;

/// The format tag of a shard file.
pub const SHARD_FORMAT: &str = "pavlov-shard/1";

/// What one shard wrote: enough to check it belongs with the others, and its runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardFile<R> {
    /// Always [`SHARD_FORMAT`].
    pub format: String,
    /// The experiment ("stall", "interaction").
    pub experiment: String,
    /// Which slice.
    pub shard: Shard,
    /// How many runs the whole study plans.
    pub planned_runs: usize,
    /// The study's configuration.
    pub config: Value,
    /// The study's options that decide its outcome (not where it writes or how many threads it uses).
    pub options: Value,
    /// Wall-clock time of this shard, s.
    pub wall_s: f64,
    /// Position in the plan of each run, in order (the same length as `runs`).
    pub positions: Vec<usize>,
    /// The runs, in planned order.
    pub runs: Vec<R>,
}

/// The shard files in `paths`: a directory contributes every `shard-*-of-*.json` in it, a file itself.
pub fn shard_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>, MergeError> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let entries = std::fs::read_dir(p).map_err(|source| MergeError::Read {
                path: p.clone(),
                source,
            })?;
            let mut here: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                        n.starts_with("shard-") && n.contains("-of-") && n.ends_with(".json")
                    })
                })
                .collect();
            here.sort();
            files.extend(here);
        } else {
            files.push(p.clone());
        }
    }
    if files.is_empty() {
        let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
        return Err(MergeError::NoShards(names.join(", ")));
    }
    Ok(files)
}

/// The experiment a shard file belongs to (read before its runs, to pick the experiment's merger).
pub fn experiment_of(path: &Path) -> Result<String, MergeError> {
    #[derive(Deserialize)]
    struct Head {
        format: String,
        experiment: String,
    }
    let head: Head = serde_json::from_str(&read(path)?).map_err(|e| MergeError::Parse {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    check_format(path, &head.format)?;
    Ok(head.experiment)
}

fn read(path: &Path) -> Result<String, MergeError> {
    std::fs::read_to_string(path).map_err(|source| MergeError::Read {
        path: path.to_path_buf(),
        source,
    })
}

fn check_format(path: &Path, format: &str) -> Result<(), MergeError> {
    if format == SHARD_FORMAT {
        Ok(())
    } else {
        Err(MergeError::Parse {
            path: path.to_path_buf(),
            reason: format!("format is {format:?}"),
        })
    }
}

/// Reads one shard file.
pub fn load<R: for<'de> Deserialize<'de>>(path: &Path) -> Result<ShardFile<R>, MergeError> {
    let file: ShardFile<R> = serde_json::from_str(&read(path)?).map_err(|e| MergeError::Parse {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    check_format(path, &file.format)?;
    Ok(file)
}

/// Writes `file` as `dir/shard-I-of-N.json` and returns the path.
pub fn write<R: Serialize>(dir: &Path, file: &ShardFile<R>) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(file.shard.file_name());
    let json = serde_json::to_string(file).map_err(std::io::Error::other)?;
    std::fs::write(&path, json)?;
    Ok(path)
}
