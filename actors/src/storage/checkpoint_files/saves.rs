//! `save_weights`: the user's own checkpoints, in `<dir>/saved/`, apart from the automatic ones.
//!
//! A save is a whole checkpoint (the same format as the automatic ones, so `pavlov serve --resume-from`
//! can continue from it). Its name is a plain name ([`crate::storage::names`]) that is not of the
//! automatic checkpoints' form (`checkpoint-<tick>.json`); a save never replaces an existing file, is
//! never pruned, and the folder is held to a quota: at most `[checkpoint] max_saves` files and
//! `max_saves_mb` MiB, the new save included. Every refusal names its rule.

use std::path::{Path, PathBuf};

use super::layout::{SAVED_DIR, tick_of_file_name, write_new};
use crate::storage::names::{NAME_RULES, check_plain_name};

/// The limits on `saved/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SaveQuota {
    /// The most files `saved/` may hold.
    pub(crate) max_files: usize,
    /// The most bytes `saved/` may hold.
    pub(crate) max_bytes: u64,
}

impl SaveQuota {
    /// The quota of `[checkpoint]`.
    pub(crate) fn of(c: &pavlov::config::CheckpointConfig) -> Self {
        SaveQuota {
            max_files: c.max_saves,
            max_bytes: c.max_saves_mb.saturating_mul(1024 * 1024),
        }
    }
}

/// Why a save was refused.
#[derive(Debug, thiserror::Error)]
pub(crate) enum SaveError {
    #[error("save_weights takes {NAME_RULES}; {0}")]
    Name(crate::storage::names::NameError),
    #[error(
        "save_weights: `{0}` has the form of the automatic checkpoints (checkpoint-<tick>.json), which is reserved for them; choose another name"
    )]
    Reserved(String),
    #[error(
        "save_weights never overwrites a save: {} already exists; choose another name",
        .0.display()
    )]
    Exists(PathBuf),
    #[error(
        "save_weights refused by the quota [checkpoint] max_saves = {max}: {} already holds {held} saves; delete some",
        .dir.display()
    )]
    TooMany {
        dir: PathBuf,
        held: usize,
        max: usize,
    },
    #[error(
        "save_weights refused by the quota [checkpoint] max_saves_mb = {max_mb}: {} holds {held} bytes and this save is {size} more; delete some",
        .dir.display()
    )]
    TooLarge {
        dir: PathBuf,
        held: u64,
        size: u64,
        max_mb: u64,
    },
    #[error("save_weights: {0}")]
    Encode(std::io::Error),
    #[error("save_weights: cannot write {}: {source}", .path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Checks a name a client gave `save_weights`.
pub(crate) fn check_save_name(name: &str) -> Result<(), SaveError> {
    check_plain_name(name).map_err(SaveError::Name)?;
    if tick_of_file_name(name).is_some() {
        return Err(SaveError::Reserved(name.to_string()));
    }
    Ok(())
}

/// The folder of saves in `[checkpoint] dir`.
pub(crate) fn saved_dir(checkpoint_dir: &Path) -> PathBuf {
    checkpoint_dir.join(SAVED_DIR)
}

/// The files (not hidden) in `dir` and their total size.
fn held(dir: &Path) -> std::io::Result<(usize, u64)> {
    let (mut count, mut bytes) = (0, 0);
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        let meta = entry.metadata()?;
        if meta.is_file() {
            count += 1;
            bytes += meta.len();
        }
    }
    Ok((count, bytes))
}

/// Writes `bytes` as the save `name` into `dir` under `quota`. With `unique`, a taken name gets a
/// `-2`, `-3`, … before its extension instead of being refused (for names the server made up).
pub(crate) fn write_save(
    dir: &Path,
    name: &str,
    unique: bool,
    bytes: &[u8],
    quota: SaveQuota,
) -> Result<PathBuf, SaveError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SaveError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let (count, total) = held(dir).map_err(io(dir))?;
    if count >= quota.max_files {
        return Err(SaveError::TooMany {
            dir: dir.to_path_buf(),
            held: count,
            max: quota.max_files,
        });
    }
    let size = bytes.len() as u64;
    if total.saturating_add(size) > quota.max_bytes {
        return Err(SaveError::TooLarge {
            dir: dir.to_path_buf(),
            held: total,
            size,
            max_mb: quota.max_bytes / (1024 * 1024),
        });
    }
    let (stem, ext) = match name.rsplit_once('.') {
        Some((s, e)) if !s.is_empty() => (s, format!(".{e}")),
        _ => (name, String::new()),
    };
    for n in 1u32.. {
        let path = if n == 1 {
            dir.join(name)
        } else {
            dir.join(format!("{stem}-{n}{ext}"))
        };
        match write_new(&path, bytes) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                if !unique || n >= 1000 {
                    return Err(SaveError::Exists(path));
                }
            }
            Err(e) => return Err(io(&path)(e)),
        }
    }
    Err(SaveError::Exists(dir.join(name)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("pavlov-saves-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    const ROOMY: SaveQuota = SaveQuota {
        max_files: 10,
        max_bytes: 1 << 20,
    };

    #[test]
    fn the_automatic_checkpoints_names_are_reserved() {
        let msg = check_save_name("checkpoint-99999999990.json")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("reserved"), "{msg}");
        assert!(check_save_name("checkpoint-final.json").is_ok());
        let msg = check_save_name("../x").unwrap_err().to_string();
        assert!(
            msg.contains("plain name") && msg.contains("separator"),
            "{msg}"
        );
    }

    #[test]
    fn a_save_is_never_replaced_and_server_names_are_made_unique() {
        let dir = temp("exists");
        let first = write_save(&dir, "w.json", false, b"one", ROOMY).unwrap();
        let err = write_save(&dir, "w.json", false, b"two", ROOMY).unwrap_err();
        assert!(matches!(&err, SaveError::Exists(p) if *p == first), "{err}");
        assert!(err.to_string().contains("never overwrites"), "{err}");
        assert_eq!(std::fs::read(&first).unwrap(), b"one");
        let second = write_save(&dir, "w.json", true, b"two", ROOMY).unwrap();
        assert_eq!(second, dir.join("w-2.json"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_quota_counts_files_and_bytes() {
        let dir = temp("quota");
        let quota = SaveQuota {
            max_files: 2,
            max_bytes: 10,
        };
        write_save(&dir, "a", false, b"12345", quota).unwrap();
        let err = write_save(&dir, "b", false, b"123456", quota).unwrap_err();
        assert!(err.to_string().contains("max_saves_mb"), "{err}");
        write_save(&dir, "b", false, b"12345", quota).unwrap();
        let err = write_save(&dir, "c", false, b"", quota).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("max_saves = 2") && msg.contains("holds 2"),
            "{msg}"
        );
        assert!(!dir.join("c").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
