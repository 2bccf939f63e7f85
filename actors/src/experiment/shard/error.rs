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
    #[error(
        "missing shard(s) {missing} of {count} ({given} shard file(s) given): the merged study would lack \
         runs {runs}"
    )]
    Missing {
        /// The missing indices, e.g. "1, 3".
        missing: String,
        /// N.
        count: usize,
        /// The runs they hold, e.g. "2..4, 6..8".
        runs: String,
        /// How many shard files were given.
        given: usize,
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
    /// A path named like a shard file is not a regular file (a FIFO, a device, a folder, …).
    #[error("{path} is not a regular file ({kind}): merge reads only regular shard files")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// A shard file is larger than merge reads.
    #[error("{path} is larger than a shard file may be ({size}, the limit is {limit} bytes)")]
    TooLarge {
        /// The path.
        path: PathBuf,
        /// Its size ("N bytes", or "more than N bytes" when it grew while read).
        size: String,
        /// The limit, bytes.
        limit: u64,
    },
    /// The shards hold another number of runs than the study's options plan.
    #[error(
        "the shards hold {found} runs, but the study's options ({options}) plan {planned}: a shard from \
         another study, or altered"
    )]
    PlanSize {
        /// The runs the shards hold.
        found: usize,
        /// The runs the options plan ("more than the machine can count" when it overflows).
        planned: String,
        /// The options that decide it, e.g. "runs_per_policy 2".
        options: String,
    },
    /// A run is not the run the study's options plan at its position.
    #[error(
        "{path}: the run at position {position} has {what} {found}, but the study's options plan {what} \
         {expected} there: a run from another study, or altered"
    )]
    OffPlan {
        /// The file it came from.
        path: PathBuf,
        /// Its position in the plan.
        position: usize,
        /// "index", "mode", "seed", …
        what: &'static str,
        /// What the plan says.
        expected: String,
        /// What the run says.
        found: String,
    },
    /// The merged study's folder may not be written.
    #[error(transparent)]
    Results(#[from] crate::experiment::results::ResultsError),
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
