//! Checkpoints of different runs never destroy each other, and `--resume` takes the newest valid one.
//!
//! A fresh run starts at tick 0: it once wrote `checkpoint-<tick>.json` beside an older run's
//! higher-numbered files and pruned its own as soon as it wrote them. Now every run writes into its own
//! folder and prunes only that. `--resume` searches every run (and the flat files of earlier versions),
//! newest first, and falls back past a torn file, NaN weights and another configuration, naming each.

use pavlov::config::Config;
use pavlov_actors::storage::checkpoint_files::{RUNS_DIR, list};

use super::fixtures::{
    config_in, fresh_checkpoint, fresh_dir, serve, snapshot_files, write_torn,
    write_with_nan_weight,
};
use crate::common::{run_sim, stall_config};
use pavlov_actors::storage::checkpoint_files::write_atomic;

#[tokio::test(start_paused = true)]
async fn a_fresh_run_keeps_its_checkpoints_and_leaves_older_runs_alone() {
    let dir = fresh_dir("fresh-run");
    let cfg = config_in(&dir);
    // An older server, flat layout, far into its life; and an older run in the new layout.
    let old_flat: Vec<_> = [9_000_000, 9_000_100, 9_000_200]
        .into_iter()
        .map(|t| write_atomic(&dir, &fresh_checkpoint(&cfg, t)).unwrap())
        .collect();
    let old_run = dir.join(RUNS_DIR).join("20200101T000000Z-0abc");
    for t in [5_000_000, 5_000_100, 5_000_200] {
        write_atomic(&old_run, &fresh_checkpoint(&cfg, t)).unwrap();
    }
    let before = snapshot_files(&dir);
    // 7 s of ticks: periodic checkpoints at ticks 100, 200 and 300, and a final one; keep = 2.
    let (records, server) = run_sim(cfg.clone(), 350).await;
    let run_dir = server.checkpoints().run_dir.clone().unwrap();
    server.shutdown().await;
    let ours = list(&run_dir).unwrap();
    let ticks: Vec<u64> = ours.iter().map(|(t, _)| *t).collect();
    assert_eq!(ticks.len(), 2, "{ours:?}");
    assert_eq!(
        ticks[0], 300,
        "the newest periodic checkpoint is kept: {ticks:?}"
    );
    assert!(ticks[1] >= records.last().unwrap().seq, "{ticks:?}");
    let after: Vec<_> = snapshot_files(&dir)
        .into_iter()
        .filter(|(p, _)| !p.starts_with(&run_dir))
        .collect();
    assert_eq!(after, before, "the older runs' files are untouched");
    assert_eq!(old_flat.len(), 3);

    // --resume takes the newest run's newest checkpoint, not the higher-numbered older ones.
    let mut resume = cfg.clone();
    resume.checkpoint.resume = true;
    resume.checkpoint.autosave = false;
    let (_, server) = run_sim(resume, 3).await;
    let resumed = server.checkpoints().resumed.as_ref().unwrap();
    assert_eq!(resumed.path, ours[1].1);
    assert_eq!(resumed.tick, ticks[1]);
    server.shutdown().await;
    let _ = std::fs::remove_dir_all(&dir);
}

/// `config` as a TOML file in `dir` with `[checkpoint] dir = <dir>/weights`.
fn config_file(dir: &std::path::Path, edit: impl FnOnce(&str) -> String) -> String {
    let stall =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .unwrap();
    let text = format!(
        "{}\n[checkpoint]\ndir = \"{}\"\n",
        edit(&stall),
        dir.join("weights").display()
    );
    let path = dir.join("serve.toml");
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

#[test]
fn resume_falls_back_past_a_torn_a_nan_and_a_foreign_checkpoint_naming_each() {
    let dir = fresh_dir("fallback");
    let runs = dir.join("weights").join(RUNS_DIR);
    let cfg = stall_config();
    // Oldest to newest: a valid one whose α was changed at run time, another configuration's, NaN
    // weights, a torn write.
    let mut valid = fresh_checkpoint(&cfg, 100);
    valid.state.predictions[0].alpha = 0.01;
    if let Some(exact) = &mut valid.state.predictions[0].state {
        exact.alphas = vec![0.01];
    }
    let valid_path = write_atomic(&runs.join("20240101T000000Z-0001"), &valid).unwrap();
    let mut other: Config = cfg.clone();
    other.predictions[0].lambda = 0.25;
    let foreign = write_atomic(
        &runs.join("20240102T000000Z-0002"),
        &fresh_checkpoint(&other, 150),
    )
    .unwrap();
    let nan = write_with_nan_weight(
        &runs.join("20240103T000000Z-0003"),
        &fresh_checkpoint(&cfg, 200),
        5,
    );
    let torn = write_torn(
        &runs.join("20240104T000000Z-0004"),
        &fresh_checkpoint(&cfg, 300),
    );
    let config = config_file(&dir, str::to_string);
    let out = serve(&dir, &["--resume", "-c", &config], "pavlov is driving");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let both = format!("stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(
        stdout.contains(&format!(
            "resuming from {} (tick 100)",
            valid_path.display()
        )),
        "{both}"
    );
    for (path, reason) in [
        (&torn, "not JSON (truncated or damaged)".to_string()),
        (
            &nan,
            "non-finite weights: prediction `stall`: weights[5]".to_string(),
        ),
        (
            &foreign,
            "another configuration: predictions[0] (stall).lambda is 0.25 in the checkpoint, 0.5 in the configuration"
                .to_string(),
        ),
    ] {
        let line = format!("skipped the newer checkpoint {}: {reason}", path.display());
        assert!(stdout.contains(&line), "printed: {line}\n{both}");
        assert!(
            stderr.contains("skipped a newer checkpoint") && stderr.contains(&reason),
            "logged: {reason}\n{both}"
        );
    }
    // The checkpoint's α (set at run time) wins over the configuration's, and says so.
    let alpha = cfg.predictions[0].alpha;
    let line = format!(
        "prediction `stall`: alpha is 0.01 in the checkpoint, {alpha} in the configuration; the checkpoint's 0.01 is in force"
    );
    assert!(stdout.contains(&line), "printed: {line}\n{both}");
    assert!(
        stderr
            .lines()
            .any(|l| l.contains(&line) && l.contains("INFO")),
        "logged at INFO: {line}\n{both}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
