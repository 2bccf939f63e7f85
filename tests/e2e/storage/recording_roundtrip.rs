//! The recorder on the real runtime: what the feed streamed is what the recording reads back, and
//! `pavlov replay` reproduces the recorded predictions and actions exactly, in both control modes.

use crate::common;

use pavlov::control::Mode;
use pavlov_actors::storage::recording;
use pavlov_actors::storage::replay;

fn record_run(mode: Mode, ticks: usize, dir: &std::path::Path) -> Vec<pavlov::record::TickRecord> {
    record_run_with(mode, ticks, dir, "none")
}

fn record_run_with(
    mode: Mode,
    ticks: usize,
    dir: &std::path::Path,
    faults: &str,
) -> Vec<pavlov::record::TickRecord> {
    let mut cfg = common::stall_config();
    cfg.control.mode = mode;
    cfg.sim.faults = faults.into();
    cfg.sim.seed = 11;
    super::fixtures::record_plain(cfg, "roundtrip", dir, ticks)
}

fn json(r: &pavlov::record::TickRecord) -> serde_json::Value {
    serde_json::to_value(r).unwrap()
}

#[test]
fn a_recording_equals_the_stream_and_replays_exactly() {
    for mode in [Mode::Reactive, Mode::Pavlovian] {
        let dir = std::env::temp_dir().join(format!("pavlov-rt-{mode:?}-{}", std::process::id()));
        let streamed = record_run(mode, 4000, &dir);
        let rec = recording::load(&dir).expect("reads back");
        assert!(!rec.torn_tail);
        assert_eq!(rec.header.config.control.mode, mode);
        // The recording holds every streamed tick (and possibly a few after the last one collected).
        assert!(rec.records.len() >= streamed.len());
        for (a, b) in streamed.iter().zip(&rec.records) {
            // Compared as JSON: the first ticks carry NaN observations (no frame yet), and NaN != NaN.
            assert_eq!(json(a), json(b), "tick {}", a.seq);
        }
        let report = replay::replay(&rec).expect("replay");
        assert!(report.exact(), "{}", replay::describe(&report));
        assert_eq!(report.ticks, rec.records.len());
        assert!(report.commands_compared > 3000);
        if mode == Mode::Pavlovian {
            // The replay checked ticks on which the prediction, not the stimulus, engaged the response.
            assert!(rec.records.iter().any(|r| r.gate && !r.stimulus));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_run_with_link_faults_replays_exactly() {
    // Stale streams, reconnects and trips: ticks the learning actor skipped (stale observation, link not
    // up) must be skipped by the replay too.
    let dir = std::env::temp_dir().join(format!("pavlov-rt-faults-{}", std::process::id()));
    let streamed = record_run_with(Mode::Pavlovian, 6000, &dir, "all");
    let rec = recording::load(&dir).expect("reads back");
    let not_up = streamed
        .iter()
        .filter(|r| r.link.state != pavlov::supervision::LinkState::Up)
        .count();
    assert!(not_up > 20, "only {not_up} ticks without an up link");
    let report = replay::replay(&rec).expect("replay");
    assert!(report.exact(), "{}", replay::describe(&report));
    // Safety stops and commands are checked on every tick, the stopped ones included.
    assert_eq!(report.stops_compared, rec.records.len());
    let stopped: Vec<usize> = (0..rec.records.len())
        .filter(|&i| rec.records[i].safety_stop.is_some())
        .collect();
    assert!(stopped.len() >= not_up, "{} stopped ticks", stopped.len());
    assert_eq!(report.commands_compared, rec.records.len());
    // A stopped tick recorded as moving, or recorded without its stop, is a mismatch.
    let at = stopped[stopped.len() / 2];
    let mut moving = rec.clone();
    moving.records[at].command = pavlov::control::Action::new(100, 100);
    let report = replay::replay(&moving).unwrap();
    assert_eq!(report.mismatch_count, 1, "{}", replay::describe(&report));
    assert_eq!(report.mismatches[0].field, "command");
    let mut unstopped = rec.clone();
    unstopped.records[at].safety_stop = None;
    let report = replay::replay(&unstopped).unwrap();
    assert_eq!(report.mismatches[0].field, "safety_stop");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_torn_recording_still_loads_and_a_tampered_one_fails_replay() {
    let dir = std::env::temp_dir().join(format!("pavlov-rt-torn-{}", std::process::id()));
    record_run(Mode::Pavlovian, 600, &dir);
    let bytes = std::fs::read(dir.join(recording::MCAP_FILE)).unwrap();
    let whole = recording::load(&dir).unwrap();
    assert!(!whole.torn_tail);
    // A kill after the last chunk was written, before the summary and footer: every tick is there.
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a finished file has a summary");
    let last = summary.chunk_indexes.last().expect("chunks");
    let end = usize::try_from(last.chunk_start_offset + last.chunk_length).unwrap();
    let rec = recording::from_bytes(&bytes[..end]).expect("torn recording loads");
    assert!(rec.torn_tail);
    assert_eq!(rec.records.len(), whole.records.len());
    assert!(rec.records.len() >= 600);
    assert!(replay::replay(&rec).unwrap().exact());
    // A kill inside the last chunk loses that chunk, and only it.
    let start = usize::try_from(last.chunk_start_offset).unwrap();
    let cut = recording::from_bytes(&bytes[..(start + end) / 2]).expect("a cut chunk loads");
    assert!(cut.torn_tail);
    assert_eq!(
        cut.records.len(),
        whole.records.len() - ticks_in_last_chunk(&bytes, last)
    );
    // Change one recorded prediction: replay must notice.
    let mut bad = rec.clone();
    if let Some(p) = bad.records[300].predictions.first_mut() {
        p.value += 1e-9;
    }
    let report = replay::replay(&bad).unwrap();
    assert_eq!(report.mismatch_count, 1);
    assert_eq!(report.mismatches[0].seq, bad.records[300].seq);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The tick messages in a chunk, read through the crate's own chunk reader.
fn ticks_in_last_chunk(bytes: &[u8], index: &mcap::records::ChunkIndex) -> usize {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let ticks = summary
        .channels
        .values()
        .find(|c| c.topic == recording::schema::TICKS)
        .unwrap()
        .id;
    summary
        .stream_chunk(bytes, index)
        .unwrap()
        .filter(|m| m.as_ref().unwrap().channel.id == ticks)
        .count()
}

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

#[test]
fn pavlov_serve_record_then_pavlov_replay() {
    let dir = std::env::temp_dir().join(format!("pavlov-serve-rec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut child = std::process::Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0", "--record"])
        .arg(&dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("pavlov serve");
    // At least a second of real-time ticks on disk (the recorder finishes a chunk every second; the file
    // is read while it is being written, as a killed one would be).
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while recording::load(&dir).map_or(0, |r| r.records.len()) < 60
        && std::time::Instant::now() < deadline
    {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    assert!(child.wait().unwrap().success());
    let rec = recording::load(&dir).expect("recording");
    assert!(rec.records.len() >= 50, "{} ticks", rec.records.len());
    assert_eq!(rec.header.label, "pavlov serve");
    let out = std::process::Command::new(PAVLOV)
        .arg("replay")
        .arg(&dir)
        .output()
        .expect("pavlov replay");
    let stdout = String::from_utf8_lossy(&out.stdout);
    // In real time, a loaded machine may skip ticks or drop one between learning and gating (the record
    // then never exists, though learning saw the tick); replay must be exact whenever no tick is missing.
    let gapless = stdout.contains(" 0 seq gaps");
    if gapless {
        assert!(out.status.success(), "{stdout}");
        assert!(stdout.contains("identical"), "{stdout}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
