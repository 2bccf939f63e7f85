//! `pavlov replay`'s exit status says which way a replay failed (issue 22, item 4): a torn recording (cut
//! by a crash, or copied while it was written) is status 3 and is not replayed unless `--allow-torn`, with
//! which it replays its complete ticks; a recording that differs is 1, one that cannot be read is 4, one
//! without a tick is 5 (never "identical"), a wrong command line is clap's 2. Through the real binary.

use std::path::Path;
use std::process::{Command, Output};

use pavlov_actors::storage::recording::{self, MCAP_FILE, Recording};

use super::fixtures::{fresh_dir, record_plain};
use crate::common::stall_config;

fn replay(args: &[&Path]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .arg("replay")
        .args(args)
        .output()
        .expect("run pavlov replay")
}

fn status(out: &Output) -> Option<i32> {
    out.status.code()
}

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn write(rec: &Recording, path: &Path) {
    let file = std::fs::File::create_new(path).unwrap();
    recording::write_recording(rec, file).expect("write the recording");
}

#[test]
fn replay_exits_with_a_distinct_status_for_torn_differing_unreadable_and_empty_recordings() {
    let dir = fresh_dir("replay-exit");
    let rec_dir = dir.join("rec");
    record_plain(stall_config(), "exit statuses", &rec_dir, 400);
    let whole = rec_dir.join(MCAP_FILE);
    let bytes = std::fs::read(&whole).unwrap();

    // The whole recording: identical, 0.
    let out = replay(&[&whole]);
    assert_eq!(status(&out), Some(0), "{}", text(&out));
    assert!(text(&out).contains("identical"), "{}", text(&out));

    // Cut (the last byte of its end magic, as a copy taken a moment too early or a crash while closing):
    // torn, 3, nothing replayed; with --allow-torn every complete tick replays exactly.
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() - 1]).unwrap();
    let read = recording::load(&cut).unwrap();
    assert!(read.torn_tail);
    let out = replay(&[&cut]);
    assert_eq!(status(&out), Some(3), "{}", text(&out));
    assert!(text(&out).contains("is torn"), "{}", text(&out));
    assert!(text(&out).contains("--allow-torn"), "{}", text(&out));
    assert!(!text(&out).contains("identical"), "{}", text(&out));
    let out = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["replay", "--allow-torn"])
        .arg(&cut)
        .output()
        .unwrap();
    assert_eq!(status(&out), Some(0), "{}", text(&out));
    assert!(
        text(&out).contains(&format!("replayed {} ticks", read.records.len())),
        "{}",
        text(&out)
    );
    assert!(text(&out).contains("identical"), "{}", text(&out));

    // Cut in the middle: torn again; with --allow-torn it replays what it holds, or says it holds no tick.
    let half = dir.join("half.mcap");
    std::fs::write(&half, &bytes[..bytes.len() / 2]).unwrap();
    let read = recording::load(&half).unwrap();
    assert!(read.torn_tail);
    assert_eq!(status(&replay(&[&half])), Some(3));
    let out = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["replay", "--allow-torn"])
        .arg(&half)
        .output()
        .unwrap();
    let want = if read.records.is_empty() { 5 } else { 0 };
    assert_eq!(status(&out), Some(want), "{}", text(&out));

    // A recording with no tick: 5, not "identical".
    let mut empty = recording::load(&whole).unwrap();
    empty.records.clear();
    empty.events.clear();
    let empty_file = dir.join("empty.mcap");
    write(&empty, &empty_file);
    let out = replay(&[&empty_file]);
    assert_eq!(status(&out), Some(5), "{}", text(&out));
    assert!(text(&out).contains("holds no tick"), "{}", text(&out));
    assert!(!text(&out).contains("identical"), "{}", text(&out));

    // A recording whose predictions were altered: the replay differs, 1.
    let mut altered = recording::load(&whole).unwrap();
    let tick = &mut altered.records[200];
    tick.predictions[0].value += 0.25;
    let altered_file = dir.join("altered.mcap");
    write(&altered, &altered_file);
    let out = replay(&[&altered_file]);
    assert_eq!(status(&out), Some(1), "{}", text(&out));
    assert!(text(&out).contains("mismatches"), "{}", text(&out));

    // Not a recording, or no file at all: 4.
    let garbage = dir.join("garbage.jsonl");
    std::fs::write(&garbage, "this is not a recording\n").unwrap();
    for path in [garbage.as_path(), dir.join("absent.mcap").as_path()] {
        let out = replay(&[path]);
        assert_eq!(status(&out), Some(4), "{}: {}", path.display(), text(&out));
        assert!(text(&out).contains("error:"), "{}", text(&out));
    }
    // A wrong command line: clap's 2.
    let out = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["replay", "--no-such-flag"])
        .output()
        .unwrap();
    assert_eq!(status(&out), Some(2), "{}", text(&out));
}
