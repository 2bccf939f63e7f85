//! Where checkpoints live inside `[checkpoint] dir`, and writing them so that a crash leaves either the
//! old file or the new one:
//!
//! ```text
//! <dir>/runs/<run id>/checkpoint-<lifelong tick>.json   one server run's automatic checkpoints
//! <dir>/saved/<name>                                    save_weights (see `saves.rs`)
//! <dir>/checkpoint-<tick>.json                          automatic checkpoints of earlier versions
//! ```
//!
//! A run id is the run's UTC start time and four random hex digits (`20261124T013000Z-3fa2`); its folder
//! is created exclusively, so two servers started in the same second never share one, and pruning
//! touches only the folder of the run that prunes.

use std::io::Write;
use std::path::{Path, PathBuf};

use pavlov::checkpoint::{Checkpoint, check_finite};

use crate::storage::utc;

/// The folder (inside `[checkpoint] dir`) that holds one folder per server run.
pub const RUNS_DIR: &str = "runs";

/// The folder (inside `[checkpoint] dir`) that `save_weights` writes into.
pub const SAVED_DIR: &str = "saved";

/// The tick of a file named `checkpoint-<tick>.json`.
pub(crate) fn tick_of_file_name(name: &str) -> Option<u64> {
    let digits = name.strip_prefix("checkpoint-")?.strip_suffix(".json")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// The automatic checkpoint files (`checkpoint-<tick>.json`) directly in `dir`, oldest first.
pub fn list(dir: &Path) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        if let Some(tick) = entry.file_name().to_str().and_then(tick_of_file_name)
            && entry.file_type()?.is_file()
        {
            found.push((tick, entry.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// Whether `name` has the form of a run id (`YYYYMMDDTHHMMSSZ-hhhh`).
pub(crate) fn is_run_id(name: &str) -> bool {
    let b = name.as_bytes();
    b.len() == 21
        && b[..8].iter().all(u8::is_ascii_digit)
        && b[8] == b'T'
        && b[9..15].iter().all(u8::is_ascii_digit)
        && b[15] == b'Z'
        && b[16] == b'-'
        && b[17..]
            .iter()
            .all(|c| matches!(c, b'0'..=b'9' | b'a'..=b'f'))
}

/// Four random hex digits.
fn random_hex4() -> String {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.write_u32(std::process::id());
    format!("{:04x}", h.finish() & 0xffff)
}

/// Creates a new run's folder `<dir>/runs/<run id>` (never one that exists) and returns it.
pub(crate) fn create_run_dir(dir: &Path) -> std::io::Result<PathBuf> {
    let runs = dir.join(RUNS_DIR);
    std::fs::create_dir_all(&runs)?;
    let started = utc::stamp(std::time::SystemTime::now());
    let mut last = None;
    for _ in 0..64 {
        let path = runs.join(format!("{started}-{}", random_hex4()));
        match std::fs::create_dir(&path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or_else(|| std::io::Error::other("no free run id")))
}

/// `checkpoint` as JSON, refused (as `InvalidData`) if any of its numbers is not finite.
pub(crate) fn encode(checkpoint: &Checkpoint, pretty: bool) -> std::io::Result<Vec<u8>> {
    check_finite(&checkpoint.state)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    let json = if pretty {
        serde_json::to_vec_pretty(checkpoint)
    } else {
        serde_json::to_vec(checkpoint)
    };
    json.map_err(std::io::Error::other)
}

/// The file name of the automatic checkpoint of lifelong tick `tick`.
pub(crate) fn file_name(tick: u64) -> String {
    format!("checkpoint-{tick}.json")
}

/// Writes `bytes` to the hidden `.<name>.tmp` beside `path` and fsyncs it; returns the temporary path.
/// When writing fails (a full disk), the temporary file is removed again.
fn write_temporary(path: &Path, bytes: &[u8]) -> std::io::Result<PathBuf> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp"));
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    match written {
        Ok(()) => Ok(tmp),
        Err(e) => Err(removing(&tmp, e)),
    }
}

/// `e`, after removing the temporary file `tmp` of the write it failed (a failure to remove it is
/// logged: the error that matters is the write's).
pub(crate) fn removing(tmp: &Path, e: std::io::Error) -> std::io::Error {
    match std::fs::remove_file(tmp) {
        Ok(()) => {}
        Err(r) if r.kind() == std::io::ErrorKind::NotFound => {}
        Err(r) => tracing::warn!("cannot remove {}: {r}", tmp.display()),
    }
    e
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    std::fs::File::open(dir)?.sync_all()
}

/// Writes `checkpoint` atomically into `dir` as `checkpoint-<created_tick>.json` and returns its path:
/// to a hidden `.tmp`, fsynced, renamed over the name, and the folder fsynced. A checkpoint holding a
/// non-finite number is refused (`InvalidData`) and nothing is written; a write that fails leaves no
/// temporary file.
pub fn write_atomic(dir: &Path, checkpoint: &Checkpoint) -> std::io::Result<PathBuf> {
    let json = encode(checkpoint, false)?;
    std::fs::create_dir_all(dir)?;
    let path = dir.join(file_name(checkpoint.created_tick));
    let tmp = write_temporary(&path, &json)?;
    std::fs::rename(&tmp, &path).map_err(|e| removing(&tmp, e))?;
    sync_dir(dir)?;
    Ok(path)
}

/// Writes `bytes` to `path` atomically, failing with `AlreadyExists` (and leaving it alone) if `path`
/// exists: the temporary file is hard-linked to the name, which never replaces a file.
pub(crate) fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = write_temporary(path, bytes)?;
    let linked = std::fs::hard_link(&tmp, path);
    let removed = std::fs::remove_file(&tmp);
    linked?;
    removed?;
    sync_dir(path.parent().unwrap_or(Path::new(".")))
}

/// Deletes all but the newest `keep` automatic checkpoints in `run_dir` (one run's folder: nothing
/// else is ever pruned).
pub(crate) fn prune(run_dir: &Path, keep: usize) -> std::io::Result<()> {
    let files = list(run_dir)?;
    let excess = files.len().saturating_sub(keep);
    for (_, path) in files.into_iter().take(excess) {
        std::fs::remove_file(path)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::agent::LearningStage;
    use pavlov::config::Config;

    fn temp(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("pavlov-layout-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn checkpoint(tick: u64) -> Checkpoint {
        let cfg = Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap();
        let stage = LearningStage::new(&cfg).unwrap();
        Checkpoint::new(&cfg, tick, stage.snapshot()).unwrap()
    }

    #[test]
    fn only_checkpoint_tick_json_names_count() {
        assert_eq!(tick_of_file_name("checkpoint-12.json"), Some(12));
        for bad in [
            ".checkpoint-12.json.tmp",
            "checkpoint-.json",
            "checkpoint-1x.json",
            "checkpoint-+1.json",
            "weights-tick3.json",
        ] {
            assert_eq!(tick_of_file_name(bad), None, "{bad}");
        }
    }

    #[test]
    fn run_folders_are_new_and_named_by_time() {
        let dir = temp("runs");
        let a = create_run_dir(&dir).unwrap();
        let b = create_run_dir(&dir).unwrap();
        assert_ne!(a, b, "two runs in one second get two folders");
        for p in [&a, &b] {
            let name = p.file_name().unwrap().to_str().unwrap();
            assert!(is_run_id(name), "{name}");
            assert_eq!(p.parent().unwrap(), dir.join(RUNS_DIR));
        }
        assert!(!is_run_id("20261124T013000Z-3fA2"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_non_finite_checkpoint_is_never_written() {
        let dir = temp("nan");
        let mut cp = checkpoint(5);
        cp.state.predictions[0].weights[3] = f64::NAN;
        let err = write_atomic(&dir, &cp).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        let msg = err.to_string();
        assert!(msg.contains(&cp.state.predictions[0].name), "{msg}");
        assert!(msg.contains("weights[3] is NaN"), "{msg}");
        assert!(!dir.exists() || list(&dir).unwrap().is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn write_new_never_replaces_and_pruning_keeps_the_newest() {
        let dir = temp("new");
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("w.json");
        write_new(&path, b"first").unwrap();
        let err = write_new(&path, b"second").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read(&path).unwrap(), b"first");
        for tick in [1, 2, 3] {
            write_atomic(&dir, &checkpoint(tick)).unwrap();
        }
        prune(&dir, 2).unwrap();
        let ticks: Vec<u64> = list(&dir).unwrap().into_iter().map(|(t, _)| t).collect();
        assert_eq!(ticks, [2, 3]);
        assert!(path.exists(), "pruning touches only checkpoint-<tick>.json");
        let hidden: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
            .collect();
        assert!(hidden.is_empty(), "{hidden:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The hidden files in `dir`.
    fn hidden(dir: &Path) -> Vec<std::ffi::OsString> {
        std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .filter(|n| n.to_string_lossy().starts_with('.'))
            .collect()
    }

    #[test]
    fn a_write_the_disk_refuses_leaves_no_temporary_file() {
        let dir = temp("full");
        std::fs::create_dir_all(&dir).unwrap();
        // The temporary files' names lead to /dev/full: writing them fails with ENOSPC, as on a full disk.
        let full = |name: &str| {
            std::os::unix::fs::symlink("/dev/full", dir.join(format!(".{name}.tmp"))).unwrap()
        };
        full("checkpoint-5.json");
        let err = write_atomic(&dir, &checkpoint(5)).unwrap_err();
        assert_eq!(err.raw_os_error(), Some(28), "{err}");
        assert!(hidden(&dir).is_empty(), "{:?}", hidden(&dir));
        assert!(list(&dir).unwrap().is_empty());
        full("w.json");
        let err = write_new(&dir.join("w.json"), b"weights").unwrap_err();
        assert_eq!(err.raw_os_error(), Some(28), "{err}");
        assert!(hidden(&dir).is_empty(), "{:?}", hidden(&dir));
        assert!(!dir.join("w.json").exists());
        // With room again, both are written.
        write_atomic(&dir, &checkpoint(5)).unwrap();
        write_new(&dir.join("w.json"), b"weights").unwrap();
        assert!(hidden(&dir).is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
