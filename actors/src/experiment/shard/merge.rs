//! Merging shards: [`merge`] checks that a set of shard files are exactly the N slices of one study and
//! puts their runs back in planned order; every refusal names the files and what is wrong
//! ([`MergeError`], [`Difference`] with the first differing key from [`first_difference`]).

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde_json::Value;

use super::Shard;
pub use super::error::{Difference, MergeError};
use super::file::{ShardFile, load};
use crate::experiment::results::{Folder, Placement};

/// The shards of one study, checked and put together.
#[derive(Debug)]
pub struct Merged<R> {
    /// The configuration (as the first shard has it; all agree).
    pub config: Value,
    /// The options: all shards agree but in [`NOT_OUTCOME`]; `threads` is the largest of the shards' (the
    /// most any one shard ran on), the rest as the first shard has them.
    pub options: Value,
    /// Every run, in planned order.
    pub runs: Vec<R>,
    /// The shards' wall-clock times added up, s.
    pub wall_s: f64,
    /// Which file each block of positions came from, in planned order.
    pub sources: Vec<(Range<usize>, PathBuf)>,
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
/// `experiment`, and returns its runs in planned order. Nothing is sized by a count a file states: the
/// slices are kept in a map of the files given, and only the first few missing ones are listed.
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
    // The count a file states is checked against the files given before anything else.
    if count > shards.len() {
        let mut present: BTreeMap<usize, &PathBuf> = BTreeMap::new();
        for (path, s) in &shards {
            if s.shard.count == count
                && s.shard.index < count
                && let Some(other) = present.insert(s.shard.index, path)
            {
                return Err(MergeError::Duplicate {
                    shard: s.shard,
                    a: other.clone(),
                    b: path.clone(),
                });
            }
        }
        return Err(missing(&present, count, planned, shards.len()));
    }
    let mut by_index: BTreeMap<usize, &PathBuf> = BTreeMap::new();
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
        if s.shard.index >= count {
            return Err(MergeError::Parse {
                path: path.clone(),
                reason: format!(
                    "shard index {} is not below its count {count}",
                    s.shard.index
                ),
            });
        }
        if let Some(other) = by_index.insert(s.shard.index, path) {
            return Err(MergeError::Duplicate {
                shard: s.shard,
                a: other.clone(),
                b: path.clone(),
            });
        }
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
    // Every index is below the count and none is repeated, so the count is met exactly when as many
    // files were given.
    if by_index.len() < count {
        return Err(missing(&by_index, count, planned, shards.len()));
    }
    let (config, mut options) = (first.config.clone(), first.options.clone());
    let threads = shards
        .iter()
        .filter_map(|(_, s)| s.options.get("threads").and_then(Value::as_u64))
        .max();
    if let (Some(o), Some(threads)) = (options.as_object_mut(), threads) {
        o.insert("threads".into(), threads.into());
    }
    let mut shards = shards;
    shards.sort_by_key(|(_, s)| s.shard.index);
    let wall_s = shards.iter().map(|(_, s)| s.wall_s).sum();
    let sources = shards
        .iter()
        .map(|(p, s)| (s.shard.range(planned), p.clone()))
        .collect();
    let runs = shards.into_iter().flat_map(|(_, s)| s.runs).collect();
    Ok(Merged {
        config,
        options,
        runs,
        wall_s,
        sources,
    })
}

/// How many missing shards a refusal lists.
const LISTED: usize = 10;

/// The refusal for a set that lacks some of its `count` slices (the first [`LISTED`] named).
fn missing(
    present: &BTreeMap<usize, &PathBuf>,
    count: usize,
    planned: usize,
    given: usize,
) -> MergeError {
    let absent: Vec<usize> = (0..count)
        .filter(|i| !present.contains_key(i))
        .take(LISTED)
        .collect();
    let more = count - present.len() - absent.len();
    let etc = |mut v: Vec<String>| {
        if more > 0 {
            v.push(format!("… and {more} more"));
        }
        v.join(", ")
    };
    let runs = absent
        .iter()
        .map(|&index| {
            let r = Shard { index, count }.range(planned);
            format!("{}..{}", r.start, r.end)
        })
        .collect();
    MergeError::Missing {
        missing: etc(absent.iter().map(usize::to_string).collect()),
        count,
        runs: etc(runs),
        given,
    }
}

/// Reads the shard files `files` of `experiment` and [`merge`]s them.
pub fn merge_files<R: DeserializeOwned>(
    experiment: &str,
    files: &[PathBuf],
) -> Result<Merged<R>, MergeError> {
    let mut shards = Vec::with_capacity(files.len());
    for f in files {
        shards.push((f.clone(), load::<R>(f)?));
    }
    merge(experiment, shards)
}

/// The line a merge adds to the study's terminal table.
pub fn merged_note(files: usize, out: &Path) -> String {
    format!("merged {files} shard file(s) into {}\n", out.display())
}

/// A study put together from its shards, ready for its experiment to check against its plan and assemble.
#[derive(Debug)]
pub struct MergedStudy<O, R> {
    /// Where the merged study goes.
    pub out: Folder,
    /// Its options (with `out` as the results directory; `threads` as [`Merged::options`] says).
    pub options: O,
    /// Every run, in planned order.
    pub runs: Vec<R>,
    /// The shards' wall-clock times added up, s.
    pub wall_s: f64,
    /// This process's build and invocation, with the hash of the shards' (common) configuration.
    pub provenance: crate::provenance::Provenance,
    /// Which file each block of positions came from.
    pub sources: Vec<(Range<usize>, PathBuf)>,
}

/// Reads and [`merge`]s the shard files `files` of `experiment`, with the options as `O`, checks the runs
/// with `check` (the options, the runs, and where they came from: the experiment's [`super::check_plan`]),
/// and only then finds the folder the study goes into, where `place` says (by default a new
/// `results/<experiment>-<UTC time>-seed<S>/`, as the unsharded study's).
pub fn merge_study<O: DeserializeOwned, R: DeserializeOwned>(
    experiment: &str,
    files: &[PathBuf],
    place: &Placement,
    check: impl FnOnce(&O, &[R], &[(Range<usize>, PathBuf)]) -> Result<(), MergeError>,
) -> Result<MergedStudy<O, R>, MergeError> {
    let merged = merge_files::<R>(experiment, files)?;
    let seed = merged
        .options
        .get("seed")
        .and_then(Value::as_u64)
        .unwrap_or(0);
    let options: O = merged.options_as(experiment, Path::new(""))?;
    check(&options, &merged.runs, &merged.sources)?;
    let out = place.study(experiment, seed)?;
    Ok(MergedStudy {
        options: merged.options_as(experiment, &out.path)?,
        out,
        runs: merged.runs,
        wall_s: merged.wall_s,
        provenance: crate::provenance::Provenance::of_json_config(&merged.config),
        sources: merged.sources,
    })
}

impl<R> Merged<R> {
    /// The merged options as `experiment`'s options type, with `out` as the results directory.
    pub fn options_as<O: DeserializeOwned>(
        &self,
        experiment: &str,
        out: &Path,
    ) -> Result<O, MergeError> {
        let mut options = self.options.clone();
        let reason = |e: serde_json::Error| MergeError::Options {
            experiment: experiment.into(),
            reason: e.to_string(),
        };
        if let Some(o) = options.as_object_mut() {
            o.insert("out".into(), serde_json::to_value(out).map_err(reason)?);
        }
        serde_json::from_value(options).map_err(reason)
    }
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
    use super::super::SHARD_FORMAT;
    use super::*;

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
            provenance: None,
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
    fn the_merged_threads_are_the_most_any_shard_ran_on() {
        let with_threads = |index, threads: u64| {
            let (p, mut f) = file(index, 3, 1);
            f.options["threads"] = threads.into();
            (p, f)
        };
        // The first shard given ran on 1 thread; another on 4.
        let m = merge(
            "stall",
            vec![with_threads(0, 1), with_threads(1, 4), with_threads(2, 2)],
        )
        .unwrap();
        assert_eq!(m.options["threads"], 4);
        assert_eq!(m.options["seed"], 1);
    }

    #[test]
    fn the_merged_options_take_the_results_directory() {
        #[derive(serde::Deserialize)]
        struct Opts {
            seed: u64,
            minutes: f64,
            out: PathBuf,
        }
        let m = merge("stall", vec![file(0, 1, 7)]).unwrap();
        let o: Opts = m.options_as("stall", Path::new("merged")).unwrap();
        assert_eq!(
            (o.seed, o.minutes, o.out),
            (7, 1.0, PathBuf::from("merged"))
        );
        #[derive(Debug, serde::Deserialize)]
        #[allow(dead_code)]
        struct Other {
            window_min: f64,
        }
        let e = m
            .options_as::<Other>("interaction", Path::new("x"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("not interaction options") && e.contains("window_min"),
            "{e}"
        );
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
        let e = merge("stall", vec![file(0, 4, 1), file(0, 4, 1)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("shard 0/4 given twice"), "{e}");
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
