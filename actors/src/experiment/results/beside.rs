//! Where a run's recording goes when its folder already holds one: beside it. A study records run `NN` into
//! `runs/NN-<policy>/`; when that folder holds a recording already (an earlier study's, written with
//! `--force` into the same `--out`, or one a user converted there, `ticks.jsonl`), the run records into the
//! first of `runs/NN-<policy>-2/`, `-3/`, … that holds none. No recording is ever replaced or deleted; the
//! study's `summary.json` names the folder each run recorded into.

use std::path::{Path, PathBuf};

use crate::storage::recording::{MCAP_FILE, TICKS_FILE};

/// How many other names are tried before giving up (the recorder then refuses the last one).
const TRIES: usize = 1000;

/// Whether `dir` holds a recording, in either format.
fn holds_recording(dir: &Path) -> bool {
    [MCAP_FILE, TICKS_FILE]
        .iter()
        .any(|f| std::fs::symlink_metadata(dir.join(f)).is_ok())
}

/// `dir` when it holds no recording, else the first of `dir-2`, `dir-3`, … that holds none.
pub fn recording_dir(dir: &Path) -> PathBuf {
    if !holds_recording(dir) {
        return dir.to_path_buf();
    }
    let name = dir
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let candidate = |k: usize| dir.with_file_name(format!("{name}-{k}"));
    (2..TRIES + 2)
        .map(candidate)
        .find(|d| !holds_recording(d))
        .unwrap_or_else(|| candidate(TRIES + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_holding_a_recording_in_either_format_is_passed_by() {
        let root = std::env::temp_dir().join(format!("pavlov-beside-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let run = root.join("01-pavlovian");
        assert_eq!(recording_dir(&run), run, "absent");
        std::fs::create_dir_all(&run).unwrap();
        std::fs::write(run.join("notes.txt"), "mine").unwrap();
        assert_eq!(recording_dir(&run), run, "no recording in it");
        std::fs::write(run.join(TICKS_FILE), "{}").unwrap();
        assert_eq!(recording_dir(&run), root.join("01-pavlovian-2"));
        std::fs::create_dir_all(root.join("01-pavlovian-2")).unwrap();
        std::fs::write(root.join("01-pavlovian-2").join(MCAP_FILE), "").unwrap();
        assert_eq!(recording_dir(&run), root.join("01-pavlovian-3"));
        let _ = std::fs::remove_dir_all(root);
    }
}
