//! A shard file (`shard-I-of-N.json`): what one slice of a study wrote, and how it is found, read and
//! written. [`experiment_of`] reads only a file's head, so the binary can pick the experiment's merger
//! before it parses the runs.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::SHARD_FORMAT;
use super::Shard;
use super::error::{Difference, MergeError};
use crate::provenance::Provenance;

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
    /// The study's configuration, its secrets redacted.
    pub config: Value,
    /// The study's options, all but where it writes its results (`out`).
    pub options: Value,
    /// Wall-clock time of this shard, s.
    pub wall_s: f64,
    /// Position in the plan of each run, in order (the same length as `runs`).
    pub positions: Vec<usize>,
    /// The runs, in planned order.
    pub runs: Vec<R>,
    /// The build and invocation that ran this shard, with the hash of `config` (`None`: a shard file
    /// written before provenance).
    #[serde(default)]
    pub provenance: Option<Provenance>,
}

impl<R> ShardFile<R> {
    /// What slice `shard` of a study of `planned_runs` runs of `experiment` writes: `runs` are the
    /// slice's, in planned order; the options are kept but for `out` (each shard writes somewhere else).
    pub fn new(
        experiment: &str,
        shard: Shard,
        planned_runs: usize,
        config: &impl Serialize,
        options: &impl Serialize,
        wall_s: f64,
        runs: Vec<R>,
    ) -> serde_json::Result<Self> {
        let mut options = serde_json::to_value(options)?;
        if let Some(o) = options.as_object_mut() {
            o.remove("out");
        }
        let config = serde_json::to_value(config)?;
        let provenance = Provenance::of_json_config(&config);
        Ok(ShardFile {
            provenance: Some(provenance),
            format: SHARD_FORMAT.into(),
            experiment: experiment.into(),
            shard,
            planned_runs,
            config,
            options,
            wall_s,
            positions: shard.range(planned_runs).collect(),
            runs,
        })
    }

    /// One line for the terminal: which runs this shard ran and how long it took.
    pub fn describe(&self) -> String {
        format!(
            "shard {}: runs {:?} of {} in {:.1} s wall",
            self.shard,
            self.shard.range(self.planned_runs),
            self.planned_runs,
            self.wall_s
        )
    }
}

/// Runs slice `shard` of the `planned` runs of a study of `experiment` with `run` (which gets the slice's
/// runs and returns their results in the same order), and writes the shard file into `out`; returns its
/// path and [`ShardFile::describe`]'s line.
pub fn run_slice<S, R: Serialize, E>(
    experiment: &str,
    shard: Shard,
    planned: Vec<S>,
    config: &impl Serialize,
    options: &impl Serialize,
    out: &Path,
    run: impl FnOnce(Vec<S>) -> Result<Vec<R>, E>,
) -> Result<(PathBuf, String), E>
where
    E: From<serde_json::Error> + From<std::io::Error>,
{
    let wall = std::time::Instant::now();
    let planned_runs = planned.len();
    let runs = run(shard.slice(planned))?;
    let wall_s = wall.elapsed().as_secs_f64();
    let file = ShardFile::new(
        experiment,
        shard,
        planned_runs,
        config,
        options,
        wall_s,
        runs,
    )?;
    let path = write(out, &file)?;
    Ok((path, file.describe()))
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

/// The one experiment every file of `files` belongs to; refuses, naming both files, a set that mixes
/// experiments (before any run is parsed, so the refusal does not depend on which experiment comes first).
pub fn experiment_of_all(files: &[PathBuf]) -> Result<String, MergeError> {
    let mut first: Option<(&PathBuf, String)> = None;
    for f in files {
        let experiment = experiment_of(f)?;
        match &first {
            None => first = Some((f, experiment)),
            Some((a, va)) if *va != experiment => {
                return Err(MergeError::Mismatch(Box::new(Difference {
                    what: "experiments",
                    key: "experiment".into(),
                    a: (*a).clone(),
                    va: format!("{va:?}"),
                    b: f.clone(),
                    vb: format!("{experiment:?}"),
                })));
            }
            Some(_) => {}
        }
    }
    first
        .map(|(_, e)| e)
        .ok_or_else(|| MergeError::NoShards("(no paths)".into()))
}

/// The largest shard file merge reads, bytes (1 GiB; the largest the README describes, the one holding
/// runs 0 and 1 of `interaction --curve`, is about 490 MB).
pub const MAX_SHARD_BYTES: u64 = 1 << 30;

/// A shard file's text: only a regular file (opened without blocking, so a FIFO named like a shard is
/// refused rather than waited on; a symbolic link is followed, and what it points to must be a regular
/// file), and at most [`MAX_SHARD_BYTES`].
fn read(path: &Path) -> Result<String, MergeError> {
    read_at_most(path, MAX_SHARD_BYTES)
}

/// [`read`] with the limit `limit`, bytes.
pub(crate) fn read_at_most(path: &Path, limit: u64) -> Result<String, MergeError> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let failed = |source| MergeError::Read {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(failed)?;
    let meta = file.metadata().map_err(failed)?;
    if !meta.is_file() {
        return Err(MergeError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(&meta.file_type()),
        });
    }
    let too_large = |size| MergeError::TooLarge {
        path: path.to_path_buf(),
        size,
        limit,
    };
    if meta.len() > limit {
        return Err(too_large(format!("{} bytes", meta.len())));
    }
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(failed)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(format!("more than {limit} bytes")));
    }
    String::from_utf8(bytes).map_err(|e| MergeError::Parse {
        path: path.to_path_buf(),
        reason: format!("not UTF-8 text: {e}"),
    })
}

/// What a file that is not a regular file is, for the refusal.
fn kind_of(t: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

fn check_format(path: &Path, format: &str) -> Result<(), MergeError> {
    if format == SHARD_FORMAT {
        Ok(())
    } else {
        Err(MergeError::Parse {
            path: path.to_path_buf(),
            reason: format!(
                "format is {format:?}; this pavlov merges {SHARD_FORMAT:?} (run the shards again with it)"
            ),
        })
    }
}

/// Reads one shard file (`read`'s checks, then [`parse`]).
pub fn load<R: for<'de> Deserialize<'de>>(path: &Path) -> Result<ShardFile<R>, MergeError> {
    parse(path, &read(path)?)
}

/// A shard file from its text (`path` names it in errors); any text gives a shard file or an error.
pub fn parse<R: for<'de> Deserialize<'de>>(
    path: &Path,
    text: &str,
) -> Result<ShardFile<R>, MergeError> {
    let file: ShardFile<R> = serde_json::from_str(text).map_err(|e| MergeError::Parse {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Opts {
        seed: u64,
        out: PathBuf,
    }

    /// A fresh directory, and options that write into it.
    fn setup(name: &str) -> (PathBuf, Opts) {
        let dir =
            std::env::temp_dir().join(format!("pavlov-shard-file-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let opts = Opts {
            seed: 3,
            out: dir.clone(),
        };
        (dir, opts)
    }

    #[test]
    fn a_slice_run_and_written_reads_back_without_its_results_directory() {
        let (dir, opts) = setup("roundtrip");
        let shard = Shard { index: 1, count: 3 };
        let planned: Vec<f64> = (0..7).map(|i| f64::from(i) / 10.0).collect();
        let (path, line) = run_slice("stall", shard, planned, &1u8, &opts, &dir, |slice| {
            Ok::<_, std::io::Error>(slice.into_iter().map(|x| x + 0.1).collect::<Vec<f64>>())
        })
        .unwrap();
        assert_eq!(path, dir.join("shard-1-of-3.json"));
        assert!(line.starts_with("shard 1/3: runs 3..5 of 7"), "{line}");
        let back: ShardFile<f64> = load(&path).unwrap();
        assert_eq!(back.positions, vec![3, 4]);
        assert_eq!(back.runs, vec![0.3 + 0.1, 0.4 + 0.1]);
        assert_eq!(back.options, serde_json::json!({ "seed": 3 }));
        assert_eq!(experiment_of(&path).unwrap(), "stall");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn a_set_mixing_experiments_is_refused_naming_both_files() {
        let (dir, opts) = setup("mixed");
        let stall = ShardFile::new("stall", Shard::WHOLE, 1, &1u8, &opts, 0.5, vec![1u8]).unwrap();
        let a = write(&dir.join("a"), &stall).unwrap();
        let other =
            ShardFile::new("interaction", Shard::WHOLE, 1, &1u8, &opts, 0.5, vec![1u8]).unwrap();
        let b = write(&dir.join("b"), &other).unwrap();
        assert_eq!(experiment_of_all(&[a.clone(), a.clone()]).unwrap(), "stall");
        let e = experiment_of_all(&[a.clone(), b.clone()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("experiments differ")
                && e.contains(&a.display().to_string())
                && e.contains(&b.display().to_string())
                && e.contains("\"interaction\""),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(dir);
    }
}
