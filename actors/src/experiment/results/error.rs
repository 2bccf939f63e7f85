//! Why a study may not write where it was asked to: [`ResultsError`].

use std::path::PathBuf;

/// Why a results folder was refused or could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// `--out` holds files already, and `--force` was not given.
    #[error(
        "{0} is not empty: a study never writes over earlier results; choose a new --out, or add --force to \
         write into it (--force replaces only the files the study itself writes, and deletes nothing)"
    )]
    NotEmpty(PathBuf),
    /// This shard's file is there already, and `--force` was not given.
    #[error(
        "{0} exists: a shard never writes over an earlier shard file; choose a new --out, or add --force to \
         replace it"
    )]
    ShardExists(PathBuf),
    /// `--out` names something that is not a folder.
    #[error("{0} is not a folder: --out names the folder the study writes into")]
    NotAFolder(PathBuf),
    /// A folder could not be read or made.
    #[error("cannot use {path}: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// No new default folder could be made (every candidate name was taken).
    #[error("no new results folder could be made: {0} and the next {1} names are taken")]
    Taken(PathBuf, usize),
}

impl ResultsError {
    /// An I/O error about `path`.
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> ResultsError {
        let path = path.into();
        move |source| ResultsError::Io { path, source }
    }
}
