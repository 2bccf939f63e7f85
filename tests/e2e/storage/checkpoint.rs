//! Lifelong weights: periodic and shut-down checkpoints written atomically with their configuration into
//! the run's own folder, `--resume` continuing from the newest one, and refusal of a checkpoint from
//! another configuration (naming the difference), as a library call and from `pavlov serve`.

use crate::common;

use pavlov::agent::{LearnInput, LearningStage};
use pavlov::checkpoint::{Checkpoint, config_fingerprint};
use pavlov::config::Config;
use pavlov::record::TickRecord;
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::checkpoint_files::{RUNS_DIR, list};

use super::fixtures::{config_in, fresh_dir, read, serve, write_stall_checkpoint, write_torn};
use common::{run_sim, stall_config};

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
        previous_followed_default: inputs.previous_followed_default,
        previous_behaviour_prob: inputs.previous_behaviour_prob,
    });
    out.predictions.iter().map(|p| p.value).collect()
}

#[tokio::test(start_paused = true)]
async fn checkpoints_are_periodic_pruned_final_and_resumable() {
    let dir = fresh_dir("lifelong");
    let cfg = config_in(&dir);
    // 5 s of ticks at 20 ms: periodic checkpoints at ticks 100 and 200, a final one at shutdown.
    let (records, server) = run_sim(cfg.clone(), 250).await;
    let run_dir = server
        .checkpoints()
        .run_dir
        .clone()
        .expect("autosave has a run folder");
    assert_eq!(run_dir.parent().unwrap(), dir.join(RUNS_DIR));
    server.shutdown().await;
    let files = list(&run_dir).unwrap();
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
    let leftovers: Vec<_> = std::fs::read_dir(&run_dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // A crash mid-write leaves a hidden .tmp with a higher tick: --resume must ignore it.
    std::fs::write(
        run_dir.join(".checkpoint-999999.json.tmp"),
        b"{\"format\": \"pavl",
    )
    .unwrap();

    let mut resumed = cfg.clone();
    resumed.checkpoint.resume = true;
    resumed.checkpoint.every_s = 0;
    let (records, server) = run_sim(resumed.clone(), 5).await;
    let report = server.checkpoints().resumed.as_ref().expect("resumed");
    assert_eq!(&report.path, final_path);
    assert!(report.skipped.is_empty(), "{:?}", report.skipped);
    let second_run = server.checkpoints().run_dir.clone().unwrap();
    assert_ne!(second_run, run_dir, "every run has its own folder");
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
    let newest = list(&second_run).unwrap().last().cloned().unwrap();
    assert!(newest.0 > *final_tick, "{newest:?}");
    assert_eq!(
        list(&run_dir).unwrap(),
        files,
        "the first run's files are untouched"
    );
    let _ = std::fs::remove_dir_all(&dir);
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
    // With a torn newer one as well, the refusal gives every reason.
    let torn = write_torn(
        &dir,
        &super::fixtures::fresh_checkpoint(&stall_config(), 20),
    );
    let err = Server::builder(cfg.clone(), RobotTarget::Simulated)
        .start()
        .await
        .err()
        .expect("nothing valid")
        .to_string();
    assert!(err.contains("no valid checkpoint"), "{err}");
    assert!(
        err.contains(&format!("{}: not JSON", torn.display())),
        "{err}"
    );
    assert!(
        err.contains("checkpoint-10.json: another configuration"),
        "{err}"
    );
    // Nothing was started, so no run folder was made.
    assert!(!dir.join(RUNS_DIR).exists());
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
    let config = config.display().to_string();
    let out = serve(&dir, &["--resume", "-c", &config], "pavlov is driving");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("lambda"), "{stderr}");
    assert!(stderr.contains("0.75"), "{stderr}");
    assert!(stderr.contains("checkpoint-3.json"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
