//! Lifelong weights: periodic and shut-down checkpoints written atomically with their configuration,
//! `--resume` continuing from the newest one, and refusal of a checkpoint from another configuration.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use pavlov::agent::{LearnInput, LearningStage};
use pavlov::config::Config;
use pavlov::learn::checkpoint::{Checkpoint, config_fingerprint};
use pavlov::record::TickRecord;
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::checkpoint_files::{list, write_atomic};

use common::{run_sim, stall_config};

/// A fresh, empty directory for one test.
fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pavlov-checkpoint-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn config_in(dir: &Path) -> Config {
    let mut cfg = stall_config();
    cfg.checkpoint.dir = dir.display().to_string();
    cfg.checkpoint.every_s = 2;
    cfg.checkpoint.keep = 2;
    cfg.checkpoint.autosave = true;
    cfg
}

fn read(path: &Path) -> Checkpoint {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// The predictions a stage restored from `cp` makes on `record`'s inputs.
fn predictions_from(cfg: &Config, cp: Option<&Checkpoint>, record: &TickRecord) -> Vec<f64> {
    let mut stage = LearningStage::new(cfg).unwrap();
    if let Some(cp) = cp {
        stage.restore(&cp.state).unwrap();
    }
    let inputs = record
        .inputs
        .clone()
        .expect("live records carry their inputs");
    let out = stage.act(LearnInput {
        values: inputs.values.as_ref(),
        elbow: None,
        forced_stimulus: inputs.forced_stimulus,
    });
    out.predictions.iter().map(|p| p.value).collect()
}

#[tokio::test(start_paused = true)]
async fn checkpoints_are_periodic_pruned_final_and_resumable() {
    let dir = fresh_dir("lifelong");
    let cfg = config_in(&dir);
    // 5 s of ticks at 20 ms: periodic checkpoints at ticks 100 and 200, a final one at shutdown.
    let (records, server) = run_sim(cfg.clone(), 250).await;
    server.shutdown().await;
    let files = list(&dir).unwrap();
    assert_eq!(files.len(), 2, "keep = 2 leaves two of three: {files:?}");
    let fingerprint = config_fingerprint(&cfg).unwrap();
    for (tick, path) in &files {
        let cp = read(path);
        assert_eq!(cp.created_tick, *tick);
        assert_eq!(cp.config_fingerprint, fingerprint);
        cp.check_against(&cfg).unwrap();
    }
    let (periodic_tick, periodic_path) = &files[0];
    let (final_tick, final_path) = &files[1];
    assert_eq!(*periodic_tick, 200, "the tick-100 checkpoint was pruned");
    let last_seq = records.last().unwrap().seq;
    assert!(
        *final_tick >= last_seq,
        "final {final_tick} < last record {last_seq}"
    );
    let final_cp = read(final_path);
    assert_ne!(
        read(periodic_path).state,
        final_cp.state,
        "learning went on after the periodic checkpoint"
    );
    // No temporary file is left behind by a complete write.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // A crash mid-write leaves a hidden .tmp with a higher tick: --resume must ignore it.
    std::fs::write(
        dir.join(".checkpoint-999999.json.tmp"),
        b"{\"format\": \"pavl",
    )
    .unwrap();

    let mut resumed = cfg.clone();
    resumed.checkpoint.resume = true;
    resumed.checkpoint.every_s = 0;
    let (records, server) = run_sim(resumed.clone(), 5).await;
    server.shutdown().await;
    let first = &records[0];
    assert_eq!(first.seq, 0);
    let got: Vec<f64> = first.predictions.iter().map(|p| p.value).collect();
    let expected = predictions_from(&cfg, Some(&final_cp), first);
    assert_eq!(
        got, expected,
        "the resumed server predicts with the final weights"
    );
    let fresh = predictions_from(&cfg, None, first);
    assert_ne!(got, fresh, "a fresh learner would predict otherwise");
    // Ticks count on across runs: the resumed run's checkpoint is the newest.
    let newest = list(&dir).unwrap().last().cloned().unwrap();
    assert!(newest.0 > *final_tick, "{newest:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Writes a checkpoint of a fresh stall learner into `dir`.
fn write_stall_checkpoint(dir: &Path, tick: u64) {
    let cfg = stall_config();
    let stage = LearningStage::new(&cfg).unwrap();
    let cp = Checkpoint::new(&cfg, tick, stage.snapshot()).unwrap();
    write_atomic(dir, &cp).unwrap();
}

#[tokio::test(start_paused = true)]
async fn a_checkpoint_of_another_configuration_is_refused() {
    let dir = fresh_dir("mismatch");
    let mut cfg = config_in(&dir.join("absent"));
    cfg.checkpoint.resume = true;
    let err = Server::builder(cfg.clone(), RobotTarget::Simulated)
        .start()
        .await
        .err()
        .expect("no checkpoint directory to resume from")
        .to_string();
    assert!(err.contains("no checkpoint"), "{err}");
    cfg.checkpoint.dir = dir.display().to_string();
    let err = Server::builder(cfg.clone(), RobotTarget::Simulated)
        .start()
        .await
        .err()
        .expect("no checkpoint to resume")
        .to_string();
    assert!(err.contains("no checkpoint"), "{err}");

    write_stall_checkpoint(&dir, 10);
    let name = cfg.predictions[0].name.clone();
    cfg.predictions[0].lambda = 0.125;
    let err = Server::builder(cfg.clone(), RobotTarget::Simulated)
        .start()
        .await
        .err()
        .expect("a different lambda is refused")
        .to_string();
    assert!(err.contains(&format!("({name}).lambda")), "{err}");
    assert!(err.contains("0.125"), "{err}");
    assert!(err.contains("checkpoint-10.json"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn serve_resume_with_a_mismatching_checkpoint_exits_naming_it() {
    let dir = fresh_dir("cli");
    write_stall_checkpoint(&dir, 3);
    let stall =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .unwrap();
    assert!(stall.contains("lambda = 0.5"));
    let text = format!(
        "{}\n[checkpoint]\ndir = \"{}\"\n",
        stall.replacen("lambda = 0.5", "lambda = 0.75", 1),
        dir.display()
    );
    let config = dir.join("other.toml");
    std::fs::write(&config, text).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["serve", "--resume", "--bind", "127.0.0.1:0", "-c"])
        .arg(&config)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("pavlov serve --resume did not refuse the checkpoint");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("lambda"), "{stderr}");
    assert!(stderr.contains("0.75"), "{stderr}");
    assert!(stderr.contains("checkpoint-3.json"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
