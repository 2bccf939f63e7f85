//! Where a study writes its results, so that results are never overwritten.
//!
//! - Without `--out`, a study gets a new folder of its own, `results/<name>-<UTC time>-seed<S>/` (then
//!   `-2`, `-3`, … for a second invocation within the same second: the folder is made with `create_dir`, so
//!   two processes never share one), and once it has written everything, `results/<name>-latest` points to
//!   it ([`latest`]). The folder is made before the study runs (so the name is its own); a study that
//!   fails leaves it, possibly empty, and `-latest` where it was.
//! - `--out DIR` is used when it is absent or empty; a non-empty one is refused ([`ResultsError::NotEmpty`])
//!   unless `--force`, and even then the study only writes its own files (it deletes nothing; a run whose
//!   recording folder holds a recording already records beside it, [`beside`]).
//! - The shards of one study share a folder: `--shard I/N` writes into `--out` (default
//!   `results/<name>-seed<S>-shards/`) whatever else it holds, but refuses to replace a
//!   `shard-I-of-N.json` already there ([`ResultsError::ShardExists`]) unless `--force`.

pub mod beside;
mod error;
pub mod latest;

use std::path::{Path, PathBuf};
use std::time::SystemTime;

pub use error::ResultsError;

use crate::experiment::shard::Shard;
use crate::storage::utc;

/// The folder default results folders are made in (relative to the working directory).
pub const ROOT: &str = "results";

/// How many names a new default folder tries within one second.
const TRIES: usize = 10_000;

/// What the command line says about where a study writes.
#[derive(Debug, Clone)]
pub struct Placement {
    /// `--out`.
    pub out: Option<PathBuf>,
    /// `--force`: write into a non-empty `--out` (only the study's own files are replaced).
    pub force: bool,
    /// Where default folders are made ([`ROOT`]).
    pub root: PathBuf,
}

/// A folder a study may write into.
#[derive(Debug, Clone)]
pub struct Folder {
    /// The folder.
    pub path: PathBuf,
    /// For a default folder: the kind of study and the folder's name, for `<name>-latest`.
    latest: Option<(String, String)>,
    root: PathBuf,
}

impl Placement {
    /// `--out` and `--force` as given, default folders in [`ROOT`].
    pub fn new(out: Option<PathBuf>, force: bool) -> Self {
        Placement {
            out,
            force,
            root: PathBuf::from(ROOT),
        }
    }

    /// The folder a whole study named `name` (`stall`, `interaction-curve`, …) with seed `seed` writes
    /// into: `--out` if it may be written (absent, empty, or `--force`), else a new default folder.
    pub fn study(&self, name: &str, seed: u64) -> Result<Folder, ResultsError> {
        match &self.out {
            Some(out) => {
                check_given(out, self.force)?;
                Ok(Folder {
                    path: out.clone(),
                    latest: None,
                    root: self.root.clone(),
                })
            }
            None => new_default(&self.root, name, seed),
        }
    }

    /// The folder shard `shard` of a study named `name` with seed `seed` writes into: `--out`, or
    /// `results/<name>-seed<S>-shards/`, shared by the study's shards; refuses it when this shard's file is
    /// there already (unless `--force`).
    pub fn shard(&self, name: &str, seed: u64, shard: Shard) -> Result<PathBuf, ResultsError> {
        let dir = self
            .out
            .clone()
            .unwrap_or_else(|| self.root.join(format!("{name}-seed{seed}-shards")));
        if std::fs::metadata(&dir).is_ok_and(|m| !m.is_dir()) {
            return Err(ResultsError::NotAFolder(dir));
        }
        let file = dir.join(shard.file_name());
        if !self.force && std::fs::symlink_metadata(&file).is_ok() {
            return Err(ResultsError::ShardExists(file));
        }
        Ok(dir)
    }
}

impl Folder {
    /// Once the study has written everything: points `<name>-latest` at a default folder (nothing for a
    /// folder given with `--out`); returns the link.
    pub fn finish(&self) -> Result<Option<PathBuf>, ResultsError> {
        match &self.latest {
            Some((name, dir)) => latest::point(&self.root, name, dir).map(Some),
            None => Ok(None),
        }
    }
}

impl Folder {
    /// [`Folder::finish`], as a line for the terminal: where `<name>-latest` now points, a warning when it
    /// could not be pointed (the study is written all the same), or nothing for a folder given with `--out`.
    pub fn finish_note(&self) -> String {
        match self.finish() {
            Ok(Some(link)) => format!("latest: {} -> {}\n", link.display(), self.path.display()),
            Ok(None) => String::new(),
            Err(e) => format!("warning: the study is written, but not marked as the latest: {e}\n"),
        }
    }
}

/// Refuses `out` when it is not a folder, or is a non-empty one and `force` is off.
fn check_given(out: &Path, force: bool) -> Result<(), ResultsError> {
    match std::fs::metadata(out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(ResultsError::io(out)(e)),
        Ok(m) if !m.is_dir() => Err(ResultsError::NotAFolder(out.to_path_buf())),
        Ok(_) => {
            let mut entries = std::fs::read_dir(out).map_err(ResultsError::io(out))?;
            if entries.next().is_none() || force {
                Ok(())
            } else {
                Err(ResultsError::NotEmpty(out.to_path_buf()))
            }
        }
    }
}

/// Makes `root/<name>-<UTC time>-seed<S>` (or `…-2`, `…-3`, … if taken).
fn new_default(root: &Path, name: &str, seed: u64) -> Result<Folder, ResultsError> {
    std::fs::create_dir_all(root).map_err(ResultsError::io(root))?;
    let base = format!("{name}-{}-seed{seed}", utc::stamp(SystemTime::now()));
    for k in 1..=TRIES {
        let dir = if k == 1 {
            base.clone()
        } else {
            format!("{base}-{k}")
        };
        let path = root.join(&dir);
        match std::fs::create_dir(&path) {
            Ok(()) => {
                return Ok(Folder {
                    path,
                    latest: Some((name.to_string(), dir)),
                    root: root.to_path_buf(),
                });
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(ResultsError::io(path)(e)),
        }
    }
    Err(ResultsError::Taken(root.join(base), TRIES - 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root(name: &str) -> PathBuf {
        let r = std::env::temp_dir().join(format!("pavlov-results-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&r);
        r
    }

    #[test]
    fn default_folders_are_new_each_time_and_latest_follows() {
        let r = root("default");
        let p = Placement {
            out: None,
            force: false,
            root: r.clone(),
        };
        let a = p.study("stall", 1).unwrap();
        let b = p.study("stall", 1).unwrap();
        assert_ne!(a.path, b.path);
        assert!(a.path.is_dir() && b.path.is_dir());
        let name = |f: &Folder| f.path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name(&a).starts_with("stall-") && name(&a).ends_with("-seed1"));
        a.finish().unwrap();
        let link = b.finish().unwrap().unwrap();
        assert_eq!(link, r.join("stall-latest"));
        assert_eq!(std::fs::read_link(&link).unwrap(), PathBuf::from(name(&b)));
        let _ = std::fs::remove_dir_all(r);
    }

    #[test]
    fn a_given_folder_must_be_absent_or_empty_unless_forced() {
        let r = root("given");
        let out = r.join("out");
        let given = |force| Placement::new(Some(out.clone()), force);
        assert!(given(false).study("stall", 1).is_ok(), "absent");
        std::fs::create_dir_all(&out).unwrap();
        assert!(given(false).study("stall", 1).is_ok(), "empty");
        std::fs::write(out.join("summary.json"), "{}").unwrap();
        let e = given(false).study("stall", 1).unwrap_err().to_string();
        assert!(e.contains("not empty") && e.contains("--force"), "{e}");
        let f = given(true).study("stall", 1).unwrap();
        assert_eq!(f.finish().unwrap(), None, "no -latest for --out");
        let e = Placement::new(Some(out.join("summary.json")), true)
            .study("stall", 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a folder"), "{e}");
        let _ = std::fs::remove_dir_all(r);
    }

    #[test]
    fn shards_share_a_folder_but_never_replace_a_shard_file_unless_forced() {
        let r = root("shards");
        let p = |force| Placement {
            out: None,
            force,
            root: r.clone(),
        };
        let zero = Shard { index: 0, count: 2 };
        let one = Shard { index: 1, count: 2 };
        let dir = p(false).shard("stall", 3, zero).unwrap();
        assert_eq!(dir, r.join("stall-seed3-shards"));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(zero.file_name()), "{}").unwrap();
        assert_eq!(p(false).shard("stall", 3, one).unwrap(), dir);
        let e = p(false).shard("stall", 3, zero).unwrap_err().to_string();
        assert!(
            e.contains("shard-0-of-2.json exists") && e.contains("--force"),
            "{e}"
        );
        assert!(p(true).shard("stall", 3, zero).is_ok());
        let _ = std::fs::remove_dir_all(r);
    }
}
