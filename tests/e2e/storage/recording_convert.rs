//! `pavlov convert` rewrites a recording in the other format without losing anything, and `pavlov replay`
//! reads both: MCAP → JSON Lines → MCAP gives back the same header, ticks and events, each replays
//! exactly, and an existing file is never overwritten.

use std::path::Path;
use std::process::Command;

use pavlov_actors::storage::recording::{self, MCAP_FILE, Recording, TICKS_FILE};

use super::fixtures::{fresh_dir, record_with_changes};

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn pavlov(args: &[&str]) -> (bool, String) {
    let out = Command::new(PAVLOV)
        .args(args)
        .output()
        .expect("run pavlov");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// Ticks and events as JSON (NaN observations compare equal that way), the header apart from its
/// format tag.
fn same(a: &Recording, b: &Recording) {
    let json = |r: &Recording| {
        serde_json::json!({
            "records": r.records,
            "events": r.events,
            "config": r.header.config,
            "start": r.header.start,
            "program": r.header.program,
            "provenance": r.header.provenance,
            "label": r.header.label,
            "started_utc": r.header.started_utc,
        })
    };
    assert!(json(a) == json(b), "the recordings differ");
    assert_eq!(a.torn_tail, b.torn_tail);
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn convert_round_trips_between_mcap_and_json_lines_and_replay_reads_both() {
    let dir = fresh_dir("convert");
    let rec_dir = dir.join("rec");
    record_with_changes(&rec_dir, 1200);
    let original = recording::load(&rec_dir).unwrap();

    // MCAP → JSON Lines beside it.
    let (ok, text) = pavlov(&["convert", path(&rec_dir), "--to", "jsonl"]);
    assert!(ok, "{text}");
    let jsonl = rec_dir.join(TICKS_FILE);
    assert!(text.contains(&jsonl.display().to_string()), "{text}");
    let as_jsonl = recording::load(&jsonl).unwrap();
    same(&original, &as_jsonl);
    let first_line = std::fs::read_to_string(&jsonl).unwrap();
    // One format version across MCAP and JSON Lines, and the provenance carried over.
    assert!(first_line.starts_with("{\"format\":\"pavlov-recording/3\""));
    assert_eq!(as_jsonl.header.provenance, original.header.provenance);
    let provenance = original.header.provenance.as_ref().expect("provenance");
    let build = pavlov_actors::provenance::BUILD;
    assert_eq!(
        (provenance.commit.as_str(), provenance.dirty.as_str()),
        (build.commit, build.dirty),
        "the recording names the commit it was made by, and whether the tree was dirty"
    );
    assert!(provenance.config_sha256.starts_with("sha256:"));
    // Made in this test process: its command line.
    assert!(!provenance.command_line.is_empty());

    // A directory holding both is read from its MCAP file.
    assert!(recording::recording_file(&rec_dir).ends_with(MCAP_FILE));

    // JSON Lines → MCAP elsewhere.
    let back = dir.join("back.mcap");
    let (ok, text) = pavlov(&[
        "convert",
        path(&jsonl),
        "--to",
        "mcap",
        "--out",
        path(&back),
    ]);
    assert!(ok, "{text}");
    let as_mcap = recording::load(&back).unwrap();
    same(&original, &as_mcap);

    // Replay reads each, and each is exact.
    for p in [rec_dir.as_path(), jsonl.as_path(), back.as_path()] {
        let (ok, text) = pavlov(&["replay", path(p)]);
        assert!(ok, "{}: {text}", p.display());
        assert!(text.contains("identical"), "{text}");
        assert!(
            text.contains(&format!("replayed {} ticks", original.records.len())),
            "{text}"
        );
    }

    // Never over an existing file.
    let before = std::fs::read(&back).unwrap();
    let (ok, text) = pavlov(&[
        "convert",
        path(&jsonl),
        "--to",
        "mcap",
        "--out",
        path(&back),
    ]);
    assert!(!ok);
    assert!(text.contains("never overwritten"), "{text}");
    assert_eq!(std::fs::read(&back).unwrap(), before);
    let _ = std::fs::remove_dir_all(&dir);
}
