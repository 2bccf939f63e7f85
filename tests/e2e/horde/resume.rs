//! Horde checkpoints: autosave writes `horde-<tick>.bin` into the run's folder beside the control
//! checkpoints, `--resume` continues the Horde from it (its values go on from where they were, not
//! from their initial weights), a Horde of other families starts afresh while the control predictions
//! are resumed, and a corrupted file is refused naming the file and the fault while `pavlov serve` runs
//! on.
//!
//! The Horde runs under `SCHED_IDLE` here as everywhere (the default): on a busy machine it gets almost
//! no CPU, and under the paused clock the server outruns it, so every tick it does get to starts a new
//! chain and it may learn nothing at all in a run. What these tests check is what a checkpoint holds and
//! what a resume restores, so the learned Horde they resume from is learned by the test itself (the core's
//! Horde, stepped on every tick of the first run, as the server's Horde would have been had it kept up)
//! and written in the run's folder as the newest checkpoint, with the same writer the server uses.

use std::path::{Path, PathBuf};

use pavlov::config::Config;
use pavlov::learn::{Horde, HordeSnapshot, TickSignals};
use pavlov::record::TickRecord;
use pavlov_actors::storage::checkpoint_files::list;
use pavlov_actors::storage::horde_file;

use super::{probe_value, small_horde, stall_with};
use crate::common::run_sim;
use crate::storage::fixtures::{fresh_dir, serve};

/// The stall configuration with the small Horde at `taus`, checkpointing into `dir` every 2 s.
fn config_in(dir: &Path, taus: &str) -> Config {
    let mut cfg = stall_with(&small_horde(taus));
    cfg.checkpoint.dir = dir.display().to_string();
    cfg.checkpoint.every_s = 2;
    cfg.checkpoint.keep = 2;
    cfg.checkpoint.autosave = true;
    cfg
}

/// Runs `cfg` for `ticks` records under the paused clock; returns the run's folder once shut down, and
/// the records.
pub(super) async fn run_with_records(cfg: Config, ticks: usize) -> (PathBuf, Vec<TickRecord>) {
    let (records, server) = run_sim(cfg, ticks).await;
    let run_dir = server.checkpoints().run_dir.clone().expect("autosave");
    server.shutdown().await;
    (run_dir, records)
}

/// Runs `cfg` for `ticks` records under the paused clock; returns the run's folder once shut down.
pub(super) async fn run(cfg: Config, ticks: usize) -> PathBuf {
    run_with_records(cfg, ticks).await.0
}

pub(super) fn horde_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            name.starts_with("horde-") && name.ends_with(".bin")
        })
        .collect();
    files.sort_by_key(|p| horde_file::read::<f32>(p).map(|(t, _)| t).unwrap_or(0));
    files
}

const BIAS: &str = "probe/bias@10";

/// A Horde of `cfg`'s families that has learned every one of `records` in a row (what the server's
/// Horde learns when it keeps up).
pub(super) fn learned_snapshot(cfg: &Config, records: &[TickRecord]) -> HordeSnapshot<f32> {
    let mut horde: Horde<f32> =
        Horde::new(cfg.horde.families.clone(), &cfg.signal_names()).unwrap();
    for r in records {
        let obs: Vec<f64> = r.obs.iter().map(|&v| f64::from(v)).collect();
        horde.step(&TickSignals {
            obs: &obs,
            raw: &obs,
            extra: &[],
            stimuli: &[r.stimulus],
        });
    }
    assert!(horde.begin_snapshot());
    while !horde.advance_snapshot(1024) {}
    horde.take_snapshot().expect("a complete snapshot")
}

#[tokio::test(start_paused = true)]
async fn horde_checkpoints_are_written_with_the_run_and_resumed() {
    let dir = fresh_dir("horde-resume");
    let cfg = config_in(&dir, "[2.0, 10.0]");
    // 5 s of ticks: periodic checkpoints at 2 s and 4 s, and a last one at shut-down.
    let (first_run, records) = run_with_records(cfg.clone(), 250).await;
    let files = horde_files(&first_run);
    assert!(!files.is_empty(), "no Horde checkpoint in {first_run:?}");
    assert!(files.len() <= 2, "keep = 2: {files:?}");
    let newest = files.last().unwrap();
    let (tick, written) = horde_file::read::<f32>(newest).unwrap();
    assert_eq!(written.families, cfg.horde.families);
    let control_ticks: Vec<u64> = list(&first_run).unwrap().iter().map(|(t, _)| *t).collect();
    // Named by the ticks it has seen (the next tick), as the control checkpoints are by their last. (On a
    // busy machine the Horde may have seen none of them: then it is named 0.)
    assert!(
        tick <= *control_ticks.last().unwrap() + 1,
        "{tick} {control_ticks:?}"
    );
    // The newest checkpoint replaced by a Horde that has learned its bias (see the module's note).
    let learned = learned_snapshot(&cfg, &records);
    horde_file::write_atomic(&first_run, tick, &learned).unwrap();
    let fresh = probe_value::<f32>(&cfg, None, BIAS);
    let before = probe_value(&cfg, Some(&learned), BIAS);
    assert!(
        before > fresh + 1.0,
        "the test's Horde learned its bias: {fresh} → {before}"
    );

    // --resume: the Horde continues from the newest file of the resumed run's folder.
    let mut resumed = cfg.clone();
    resumed.checkpoint.resume = true;
    resumed.checkpoint.every_s = 0;
    let second_run = run(resumed.clone(), 3).await;
    assert_ne!(second_run, first_run);
    let after = horde_files(&second_run);
    let (tick2, continued) =
        horde_file::read::<f32>(after.last().expect("a last checkpoint")).unwrap();
    // (The resumed Horde may not have learned one of the 3 ticks before it stopped.)
    assert!(tick2 >= tick, "lifelong ticks go on: {tick} → {tick2}");
    let value = probe_value(&resumed, Some(&continued), BIAS);
    assert!(
        (value - before).abs() < 0.25 * before,
        "resumed, not reset: {before} → {value} (fresh {fresh})"
    );

    // Another Horde (a timescale changed): the control predictions are resumed, the Horde starts
    // afresh instead of failing the start.
    let mut other = config_in(&dir, "[3.0, 10.0]");
    other.checkpoint.resume = true;
    other.checkpoint.every_s = 0;
    let (_, server) = run_sim(other.clone(), 3).await;
    assert!(server.checkpoints().resumed.is_some(), "control is resumed");
    assert!(server.horde().is_some(), "the Horde runs");
    let third_run = server.checkpoints().run_dir.clone().unwrap();
    server.shutdown().await;
    let (_, restarted) =
        horde_file::read::<f32>(horde_files(&third_run).last().expect("a last checkpoint"))
            .unwrap();
    let value = probe_value(&other, Some(&restarted), BIAS);
    assert!(
        value < 0.5 * before,
        "a Horde of other families starts from its initial weights: {value} (learned {before})"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_corrupted_or_mismatching_horde_checkpoint_is_refused_and_serve_runs_on() {
    let dir = fresh_dir("horde-corrupt");
    let horde = small_horde("[2.0, 10.0]");
    let cfg = config_in(&dir, "[2.0, 10.0]");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let run_dir = rt.block_on(run(cfg, 120));
    let file = horde_files(&run_dir).pop().expect("a Horde checkpoint");
    let write_config = |name: &str, horde: &str| {
        let text = format!(
            "{}\n[checkpoint]\ndir = \"{}\"\n{horde}",
            super::stall_text(),
            dir.display()
        );
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path.display().to_string()
    };
    // A Horde of other families (killed at once, the process leaves no checkpoint of its own).
    let other = write_config("other.toml", &small_horde("[3.0, 10.0]"));
    let out = serve(&dir, &["--resume", "-c", &other], "pavlov is driving");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stdout.contains("pavlov is driving"), "{stdout}\n{stderr}");
    assert!(stderr.contains("other families"), "{stderr}");
    assert!(stderr.contains("initial weights"), "{stderr}");

    // One bit flipped in the middle of the weights.
    let mut bytes = std::fs::read(&file).unwrap();
    let mid = bytes.len() * 3 / 4;
    bytes[mid] ^= 0x10;
    std::fs::write(&file, &bytes).unwrap();

    let same = write_config("same.toml", &horde);
    let out = serve(&dir, &["--resume", "-c", &same], "pavlov is driving");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stdout.contains("pavlov is driving"), "{stdout}\n{stderr}");
    assert!(stderr.contains("cannot resume the Horde from"), "{stderr}");
    assert!(
        stderr.contains(&file.file_name().unwrap().to_string_lossy().into_owned()),
        "names the file: {stderr}"
    );
    assert!(stderr.contains("checksum does not match"), "{stderr}");
    assert!(stderr.contains("initial weights"), "{stderr}");

    let _ = std::fs::remove_dir_all(&dir);
}
