//! Sweeps on a cluster: run one slice of a study (`--shard I/N`) and merge the slices back into the study.
//!
//! A study plans its runs as a list; [`Shard::slice`] keeps the I-th of N contiguous, disjoint blocks of
//! that list, so the union of all N shards is the planned list and every run keeps the seed the unsharded
//! study gives it (seeds are derived from the run's index, never from the shard). Whatever the list holds
//! (e.g. several policies), the slicing is the same, so this composes with any planner.
//!
//! A shard writes what its runs produced into `shard-I-of-N.json` ([`ShardFile`]): the experiment, the
//! configuration and the study's options (as JSON, so any experiment's options fit), the number of planned
//! runs and the runs themselves. [`merge`] reads a set of those files and refuses, with an error naming
//! the files and the difference, shards of different experiments, configurations, options or shard counts,
//! a shard given twice, missing shards, and runs outside their shard's slice. What it returns is the runs
//! in planned order, from which the experiment computes the same summary, tables and figures as the
//! unsharded study.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use serde_json::Value;

/// The format tag of a shard file.
pub const SHARD_FORMAT: &str = "pavlov-shard/1";

/// The I-th (0-based) of N slices of a study.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which slice, 0-based.
    pub index: usize,
    /// How many slices.
    pub count: usize,
}

/// Why `--shard` was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ShardParseError {
    /// Not of the form I/N.
    #[error("--shard {0:?}: expected I/N, e.g. 0/4 (the first of four slices)")]
    Form(String),
    /// N is 0.
    #[error("--shard {0:?}: the number of shards N must be at least 1")]
    NoShards(String),
    /// I ≥ N.
    #[error("--shard {given:?}: the index I must be in 0..{count} (0-based; got {index})")]
    IndexOutOfRange {
        /// What was given.
        given: String,
        /// I.
        index: usize,
        /// N.
        count: usize,
    },
}

impl FromStr for Shard {
    type Err = ShardParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let form = || ShardParseError::Form(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(form)?;
        let index: usize = i.trim().parse().map_err(|_| form())?;
        let count: usize = n.trim().parse().map_err(|_| form())?;
        if count == 0 {
            return Err(ShardParseError::NoShards(s.to_string()));
        }
        if index >= count {
            return Err(ShardParseError::IndexOutOfRange {
                given: s.to_string(),
                index,
                count,
            });
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The whole study as one shard.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// The positions this shard holds in a plan of `planned` runs: the I-th of N contiguous blocks whose
    /// sizes differ by at most one (the first `planned % N` blocks are one longer).
    pub fn range(&self, planned: usize) -> Range<usize> {
        let count = self.count.max(1);
        let (base, extra) = (planned / count, planned % count);
        let start = self.index * base + self.index.min(extra);
        let len = base + usize::from(self.index < extra);
        start.min(planned)..(start + len).min(planned)
    }

    /// This shard's runs of the planned list.
    pub fn slice<T>(&self, planned: Vec<T>) -> Vec<T> {
        let range = self.range(planned.len());
        planned
            .into_iter()
            .enumerate()
            .filter(|(i, _)| range.contains(i))
            .map(|(_, t)| t)
            .collect()
    }

    /// The file a shard writes into its results directory.
    pub fn file_name(&self) -> String {
        format!("shard-{}-of-{}.json", self.index, self.count)
    }
}

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

/// Why shards could not be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("no shard files (shard-I-of-N.json) found in {0}")]
    NoShards(String),
    /// A directory or file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file is not a shard file of this format.
    #[error("{path} is not a {SHARD_FORMAT} shard file: {reason}")]
    Parse {
        /// The path.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// Two shards disagree on something that must be the same.
    #[error("{0}")]
    Mismatch(Box<Difference>),
    /// The same slice was given twice.
    #[error("shard {shard} given twice (overlapping runs): {a} and {b}")]
    Duplicate {
        /// The slice.
        shard: Shard,
        /// One file.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// Some slices are missing.
    #[error("missing shard(s) {missing} of {count}: the merged study would lack runs {runs}")]
    Missing {
        /// The missing indices, e.g. "1, 3".
        missing: String,
        /// N.
        count: usize,
        /// The runs they hold, e.g. "2..4, 6..8".
        runs: String,
    },
    /// A shard's runs are not the ones its slice holds.
    #[error(
        "{path}: shard {shard} of {planned} planned runs must hold positions {expected:?}, holds {found:?}"
    )]
    WrongRuns {
        /// The file.
        path: PathBuf,
        /// Its slice.
        shard: Shard,
        /// Planned runs.
        planned: usize,
        /// What it should hold.
        expected: Range<usize>,
        /// What it holds.
        found: Vec<usize>,
    },
}

/// Where two shards disagree.
#[derive(Debug, thiserror::Error)]
#[error("{what} differ at {key}: {a} has {va}, {b} has {vb}")]
pub struct Difference {
    /// "experiments", "configurations", "options", "shard counts or planned runs".
    pub what: &'static str,
    /// The first differing key (JSON path).
    pub key: String,
    /// One file.
    pub a: PathBuf,
    /// Its value.
    pub va: String,
    /// The other file.
    pub b: PathBuf,
    /// Its value.
    pub vb: String,
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

/// The shards of one study, checked and put together.
#[derive(Debug)]
pub struct Merged<R> {
    /// The configuration (as the first shard has it; all agree).
    pub config: Value,
    /// The options (as the first shard has them; all agree but in [`NOT_OUTCOME`]).
    pub options: Value,
    /// Every run, in planned order.
    pub runs: Vec<R>,
    /// The shards' wall-clock times added up, s.
    pub wall_s: f64,
}

/// The first place two JSON values differ: its path and the two values there.
pub fn first_difference(a: &Value, b: &Value, path: &str) -> Option<(String, String, String)> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            keys.into_iter().find_map(|k| {
                let sub = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(va), Some(vb)) => first_difference(va, vb, &sub),
                    (va, vb) => Some((sub, show(va), show(vb))),
                }
            })
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (va, vb))| first_difference(va, vb, &format!("{path}[{i}]"))),
        _ if a == b => None,
        _ => Some((
            if path.is_empty() {
                "(root)".into()
            } else {
                path.into()
            },
            a.to_string(),
            b.to_string(),
        )),
    }
}

fn show(v: Option<&Value>) -> String {
    v.map_or_else(|| "(absent)".into(), Value::to_string)
}

/// Checks that `shards` (with the paths they came from) are exactly the N slices of one study of
/// `experiment`, and returns its runs in planned order.
pub fn merge<R>(
    experiment: &str,
    shards: Vec<(PathBuf, ShardFile<R>)>,
) -> Result<Merged<R>, MergeError> {
    let Some((first_path, first)) = shards.first() else {
        return Err(MergeError::NoShards("(no paths)".into()));
    };
    let expected_experiment = Value::String(experiment.into());
    let first_head = head(first);
    let count = first.shard.count;
    let planned = first.planned_runs;
    let mut by_index: Vec<Option<&PathBuf>> = vec![None; count];
    for (path, s) in &shards {
        let mismatch = |what, (key, va, vb): (String, String, String)| {
            MergeError::Mismatch(Box::new(Difference {
                what,
                key,
                a: first_path.clone(),
                va,
                b: path.clone(),
                vb,
            }))
        };
        if let Some(d) = first_difference(
            &expected_experiment,
            &Value::String(s.experiment.clone()),
            "experiment",
        ) {
            return Err(mismatch("experiments", d));
        }
        if let Some(d) = first_difference(&first_head, &head(s), "") {
            return Err(mismatch("shard counts or planned runs", d));
        }
        if let Some(d) = first_difference(&first.config, &s.config, "config") {
            return Err(mismatch("configurations", d));
        }
        if let Some(d) = first_difference(
            &outcome_options(&first.options),
            &outcome_options(&s.options),
            "options",
        ) {
            return Err(mismatch("options", d));
        }
        let slot = by_index
            .get_mut(s.shard.index)
            .ok_or_else(|| MergeError::Parse {
                path: path.clone(),
                reason: format!(
                    "shard index {} is not below its count {count}",
                    s.shard.index
                ),
            })?;
        if let Some(other) = slot {
            return Err(MergeError::Duplicate {
                shard: s.shard,
                a: (*other).clone(),
                b: path.clone(),
            });
        }
        *slot = Some(path);
        let expected = s.shard.range(planned);
        if s.positions.len() != s.runs.len() || !s.positions.iter().copied().eq(expected.clone()) {
            return Err(MergeError::WrongRuns {
                path: path.clone(),
                shard: s.shard,
                planned,
                expected,
                found: s.positions.clone(),
            });
        }
    }
    let missing: Vec<usize> = (0..count).filter(|i| by_index[*i].is_none()).collect();
    if !missing.is_empty() {
        let ids: Vec<String> = missing.iter().map(usize::to_string).collect();
        let runs: Vec<String> = missing
            .iter()
            .map(|&index| {
                let r = Shard { index, count }.range(planned);
                format!("{}..{}", r.start, r.end)
            })
            .collect();
        return Err(MergeError::Missing {
            missing: ids.join(", "),
            count,
            runs: runs.join(", "),
        });
    }
    let (config, options) = (first.config.clone(), first.options.clone());
    let mut shards = shards;
    shards.sort_by_key(|(_, s)| s.shard.index);
    let wall_s = shards.iter().map(|(_, s)| s.wall_s).sum();
    let runs = shards.into_iter().flat_map(|(_, s)| s.runs).collect();
    Ok(Merged {
        config,
        options,
        runs,
        wall_s,
    })
}

/// Options that do not decide a study's outcome: shards may differ in them.
pub const NOT_OUTCOME: [&str; 2] = ["out", "threads"];

fn outcome_options(options: &Value) -> Value {
    let mut v = options.clone();
    if let Some(o) = v.as_object_mut() {
        for k in NOT_OUTCOME {
            o.remove(k);
        }
    }
    v
}

fn head<R>(s: &ShardFile<R>) -> Value {
    serde_json::json!({ "shard_count": s.shard.count, "planned_runs": s.planned_runs })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_refuse_with_the_bound() {
        assert_eq!("2/4".parse(), Ok(Shard { index: 2, count: 4 }));
        assert!(matches!(
            "4/4".parse::<Shard>(),
            Err(ShardParseError::IndexOutOfRange {
                index: 4,
                count: 4,
                ..
            })
        ));
        assert!(matches!(
            "0/0".parse::<Shard>(),
            Err(ShardParseError::NoShards(_))
        ));
        assert!(matches!(
            "3".parse::<Shard>(),
            Err(ShardParseError::Form(_))
        ));
        assert!(matches!(
            "-1/4".parse::<Shard>(),
            Err(ShardParseError::Form(_))
        ));
    }

    #[test]
    fn the_slices_are_disjoint_balanced_and_cover_the_plan() {
        for planned in 0..30 {
            for count in 1..9 {
                let mut all = Vec::new();
                let mut sizes = Vec::new();
                for index in 0..count {
                    let part = Shard { index, count }.slice((0..planned).collect::<Vec<_>>());
                    sizes.push(part.len());
                    all.extend(part);
                }
                assert_eq!(
                    all,
                    (0..planned).collect::<Vec<_>>(),
                    "{planned} in {count}"
                );
                let (lo, hi) = (sizes.iter().min(), sizes.iter().max());
                assert!(hi.zip(lo).is_some_and(|(h, l)| h - l <= 1), "{sizes:?}");
            }
        }
    }

    fn file(index: usize, count: usize, seed: u64) -> (PathBuf, ShardFile<usize>) {
        let shard = Shard { index, count };
        let positions: Vec<usize> = shard.range(8).collect();
        let f = ShardFile {
            format: SHARD_FORMAT.into(),
            experiment: "stall".into(),
            shard,
            planned_runs: 8,
            config: serde_json::json!({ "tick": { "period_ms": 20 } }),
            options: serde_json::json!({ "seed": seed, "minutes": 1.0 }),
            wall_s: 1.0,
            runs: positions.iter().map(|p| p * 10).collect(),
            positions,
        };
        (PathBuf::from(shard.file_name()), f)
    }

    #[test]
    fn a_complete_set_merges_in_planned_order_whatever_the_order_given() {
        let shards = vec![file(2, 3, 1), file(0, 3, 1), file(1, 3, 1)];
        let m = merge("stall", shards).unwrap();
        assert_eq!(m.runs, (0..8).map(|p| p * 10).collect::<Vec<_>>());
        assert_eq!(m.wall_s, 3.0);
    }

    #[test]
    fn bad_sets_are_refused_naming_the_difference() {
        let e = merge("stall", vec![file(0, 2, 1), file(1, 2, 2)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("options differ at options.seed")
                && e.contains("has 1")
                && e.contains("has 2"),
            "{e}"
        );
        let e = merge("stall", vec![file(0, 2, 1), file(0, 2, 1)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("shard 0/2 given twice"), "{e}");
        let e = merge("stall", vec![file(0, 4, 1), file(2, 4, 1)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("missing shard(s) 1, 3 of 4") && e.contains("2..4, 6..8"),
            "{e}"
        );
        let e = merge("stall", vec![file(0, 2, 1), file(1, 3, 1)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("shard_count"), "{e}");
        let (p, mut other) = file(1, 2, 1);
        other.config = serde_json::json!({ "tick": { "period_ms": 10 } });
        let e = merge("stall", vec![file(0, 2, 1), (p, other)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("configurations differ at config.tick.period_ms"),
            "{e}"
        );
        let (p, mut other) = file(1, 2, 1);
        other.experiment = "interaction".into();
        let e = merge("stall", vec![file(0, 2, 1), (p, other)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("experiments differ"), "{e}");
        let (p, mut wrong) = file(1, 2, 1);
        wrong.positions = vec![3, 4, 5, 6];
        let e = merge("stall", vec![file(0, 2, 1), (p, wrong)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("must hold positions 4..8"), "{e}");
    }
}
