//! Why a set of shard files could not be merged: [`MergeError`], and [`Difference`] for two shards that
//! disagree (the first differing key). Reading a shard file and merging a set both report these.

use std::ops::Range;
use std::path::PathBuf;

use super::SHARD_FORMAT;
use super::Shard;

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
    /// The merged options are not the experiment's options.
    #[error("the shards' options are not {experiment} options: {reason}")]
    Options {
        /// The experiment.
        experiment: String,
        /// Why.
        reason: String,
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
