//! Sweeps on a cluster: run one slice of a study (`--shard I/N`) and merge the slices back into the study.
//!
//! A study plans its runs as a list; [`Shard::slice`] keeps the I-th of N contiguous, disjoint blocks of
//! that list, so the union of all N shards is the planned list and every run keeps the seed the unsharded
//! study gives it (seeds are derived from the run's index, never from the shard). Whatever the list holds
//! (e.g. several policies), the slicing is the same, so this composes with any planner.
//!
//! A shard writes what its runs produced into `shard-I-of-N.json` ([`ShardFile`]): the experiment, the
//! configuration and the study's options (as JSON, so any experiment's options fit), the number of planned
//! runs and the runs themselves. [`merge()`] reads a set of those files and refuses, with an error naming
//! the files and the difference, shards of different experiments, configurations, options or shard counts,
//! a shard given twice, missing shards, and runs outside their shard's slice. What it returns is the runs
//! in planned order; the experiment checks each against the run its options plan there ([`check_plan`])
//! and computes from them the same summary, tables and figures as the unsharded study.
//!
//! - this file: [`Shard`], parsing `--shard I/N` and slicing a plan;
//! - [`mod@file`]: the shard file, finding, reading and writing it;
//! - [`mod@merge`]: checking a set of shards and putting their runs together;
//! - [`mod@plan`]: checking each merged run against the run the study's options plan at its position.
//!
//! Shard files are untrusted input: merge reads only regular files of at most [`MAX_SHARD_BYTES`], sizes
//! nothing by a count a file states, and ends every bad file with an error, never a panic.

pub mod file;
pub mod merge;
pub mod plan;

use std::ops::Range;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

mod error;
#[cfg(test)]
mod robustness;

/// The format tag of a shard file. Version 2: an interaction shard keeps its runs' reduced samples and
/// only Figure 3's fields (`figure3`), not their tick records; a version-1 shard is refused by name.
pub const SHARD_FORMAT: &str = "pavlov-shard/2";

pub use file::{
    MAX_SHARD_BYTES, ShardFile, experiment_of, experiment_of_all, load, parse, run_slice,
    shard_files, write,
};
pub use merge::{
    Difference, MergeError, Merged, MergedStudy, NOT_OUTCOME, first_difference, merge, merge_files,
    merge_study, merged_note,
};
pub use plan::{PlannedRun, check_plan};

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
        // Saturating: a shard read from a file may state any index (one past its count gives an empty range).
        let start = self
            .index
            .saturating_mul(base)
            .saturating_add(self.index.min(extra));
        let len = base + usize::from(self.index < extra);
        start.min(planned)..start.saturating_add(len).min(planned)
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
}
