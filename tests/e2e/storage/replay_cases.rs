//! `pavlov replay` reproduces every recording exactly, wherever it was started from and whatever changed
//! during it: a recording started from the dashboard mid-run, with learning parameters changed, the
//! weights reset and the mode switched while it ran; and a recording of a run resumed from a checkpoint.
//! Each case also shows that the recorded start state and events are what make it exact.

use std::path::Path;

use pavlov::control::Mode;
use pavlov::event::EventKind;
use pavlov_actors::command::{
    ControlCommand, ControlRequest, GatingCommand, LearningCommand, Outcome, RecorderCommand,
};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recorder::Recorder;
use pavlov_actors::storage::recording::{self, Recording, RecordingHeader};
use pavlov_actors::storage::replay;

use super::fixtures::{config_in, fresh_dir, with_recorded_server};
use crate::common;

async fn send(server: &Server, command: impl Into<ControlCommand>) -> Outcome {
    let (req, reply) = ControlRequest::new(command);
    server.commands().send(req).await.expect("router up");
    reply.await.expect("a reply")
}

async fn ticks(server: &Server, n: usize) {
    let mut rx = server.feed().subscribe();
    common::collect(&mut rx, n).await;
}

fn replay_exact(rec: &Recording) -> replay::ReplayReport {
    let report = replay::replay(rec).expect("replay runs");
    assert!(report.exact(), "{}", replay::describe(&report));
    report
}

#[test]
fn a_recording_started_mid_run_with_changes_during_it_replays_exactly() {
    let root = fresh_dir("replay-midrun");
    let mut cfg = common::stall_config();
    cfg.sim.seed = 5;
    let recorder = Recorder::spawn(
        RecordingHeader::new(&cfg, "mid-run"),
        None,
        root.to_path_buf(),
        20_000,
    )
    .expect("recorder");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let link = recorder.link.clone();
    rt.block_on(async move {
        let server = Server::builder(cfg, RobotTarget::Simulated)
            .recorder(link)
            .start()
            .await
            .expect("server");
        // Learn for 20 s before the recording starts: its start state is far from the initial one.
        ticks(&server, 1000).await;
        let started = send(
            &server,
            RecorderCommand::StartRecording {
                dir: Some("mid".into()),
            },
        )
        .await;
        assert!(started.is_ok(), "{started:?}");
        ticks(&server, 400).await;
        let params = LearningCommand::SetParams {
            prediction: None,
            alpha: Some(0.01),
            lambda: Some(0.9),
            threshold: Some(0.3),
        };
        assert!(send(&server, params).await.is_ok());
        ticks(&server, 400).await;
        assert!(
            send(&server, LearningCommand::ResetWeights {})
                .await
                .is_ok()
        );
        ticks(&server, 300).await;
        let reactive = GatingCommand::SetMode {
            mode: Mode::Reactive,
        };
        assert!(send(&server, reactive).await.is_ok());
        ticks(&server, 300).await;
        let stopped = send(&server, RecorderCommand::StopRecording {}).await;
        assert!(stopped.is_ok(), "{stopped:?}");
        server.shutdown().await;
    });
    drop(rt);
    let report = recorder.join();
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    let rec = recording::load(&root.join("mid")).expect("reads back");
    let start = rec.header.start.as_ref().expect("a start state");
    assert!(start.after.unwrap_or(0) >= 999, "{:?}", start.after);
    assert_eq!(
        rec.records.first().map(|r| r.seq),
        start.after.map(|a| a + 1)
    );
    let kinds: Vec<&str> = rec.events.iter().map(|e| e.kind.name()).collect();
    for kind in [
        "recording_started",
        "params_set",
        "weights_reset",
        "mode_set",
        "recording_stopped",
    ] {
        assert!(kinds.contains(&kind), "no {kind} in {kinds:?}");
    }
    let report = replay_exact(&rec);
    // The recording begins when learning answers the recorder's request for its state: under the
    // paused clock the runtime may run some ticks while the recorder's thread asks.
    assert!(report.ticks >= 1000, "{}", report.ticks);
    assert_eq!(report.events_applied, 3);
    assert!(rec.records.iter().any(|r| r.mode == Mode::Reactive));
    // Without its start state, or without its events, the same recording does not replay.
    let mut no_start = rec.clone();
    no_start.header.start = None;
    assert!(!replay::replay(&no_start).unwrap().exact());
    let mut no_events = rec.clone();
    no_events.events.retain(|e| {
        !matches!(
            e.kind,
            EventKind::ParamsSet { .. } | EventKind::WeightsReset
        )
    });
    assert!(!replay::replay(&no_events).unwrap().exact());
    let _ = std::fs::remove_dir_all(&root);
}

/// Runs a server of `cfg` for `n` ticks under the paused clock, recording into `dir` when given.
fn run(cfg: pavlov::config::Config, n: usize, dir: Option<&Path>) {
    let recorder = dir.map(|d| {
        Recorder::spawn(
            RecordingHeader::new(&cfg, "resumed"),
            Some(d.to_path_buf()),
            d.to_path_buf(),
            n + 64,
        )
        .expect("recorder")
    });
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let link = recorder.as_ref().map(|r| r.link.clone());
    rt.block_on(async move {
        let mut builder = Server::builder(cfg, RobotTarget::Simulated);
        if let Some(link) = link {
            builder = builder.recorder(link);
        }
        let server = builder.start().await.expect("server");
        ticks(&server, n).await;
        server.shutdown().await;
    });
    drop(rt);
    if let Some(r) = recorder {
        let report = r.join();
        assert!(report.errors.is_empty(), "{:?}", report.errors);
    }
}

#[test]
fn a_recording_of_a_resumed_run_replays_exactly() {
    let dir = fresh_dir("replay-resume");
    let mut cfg = config_in(&dir.join("weights"));
    cfg.sim.seed = 6;
    // A first run learns for a minute and leaves its final checkpoint.
    run(cfg.clone(), 3000, None);
    // The second run resumes from it and is recorded.
    cfg.checkpoint.resume = true;
    let rec_dir = dir.join("rec");
    run(cfg, 1500, Some(&rec_dir));
    let rec = recording::load(&rec_dir).expect("reads back");
    let start = rec.header.start.as_ref().expect("a start state");
    assert_eq!(start.after, None, "the recording begins with the run");
    let learned: f64 = start.learner.predictions.predictions[0]
        .weights
        .iter()
        .map(|w| w.abs())
        .sum();
    assert!(learned > 0.0, "the start state holds the resumed weights");
    replay_exact(&rec);
    // Replayed from fresh weights instead, it does not match: the start state is what makes it exact.
    let mut fresh = rec.clone();
    fresh.header.start = None;
    assert!(!replay::replay(&fresh).unwrap().exact());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 14: a recording of a run with an off-policy (GTD(λ)) prediction, started mid-run, replays
/// exactly: its start state carries the secondary weights, and each tick's inputs the ratio ρ of the
/// transition into it. The run is reactive for 30 s (π is followed except while stalled, so both ratios
/// occur), then Pavlovian on the off-policy prediction. Without the recorded ρ (every tick claimed to
/// follow π) it does not replay.
#[test]
fn a_recording_with_an_off_policy_prediction_replays_exactly() {
    let root = fresh_dir("replay-gtd");
    let mut cfg = pavlov_actors::experiment::stall::policies::with_offpolicy_prediction(
        &common::stall_config(),
    )
    .expect("the off-policy prediction fits");
    cfg.control.gate_prediction = "stall_pi".into();
    cfg.control.mode = Mode::Reactive;
    cfg.sim.seed = 7;
    let body = async |server: &Server| {
        ticks(server, 1000).await;
        let started = send(
            server,
            RecorderCommand::StartRecording {
                dir: Some("gtd".into()),
            },
        )
        .await;
        assert!(started.is_ok(), "{started:?}");
        ticks(server, 500).await;
        let pavlovian = GatingCommand::SetMode {
            mode: Mode::Pavlovian,
        };
        assert!(send(server, pavlovian).await.is_ok());
        ticks(server, 1000).await;
        let stopped = send(server, RecorderCommand::StopRecording {}).await;
        assert!(stopped.is_ok(), "{stopped:?}");
    };
    with_recorded_server(cfg, "gtd", None, &root, 20_000, body);
    let rec = recording::load(&root.join("gtd")).expect("reads back");
    let start = rec.header.start.as_ref().expect("a start state");
    let gtd = &start.learner.predictions.predictions[1];
    assert_eq!(gtd.name, "stall_pi");
    let secondary = gtd
        .secondary
        .as_ref()
        .expect("secondary weights in the start state");
    assert!(
        secondary.iter().any(|&w| w != 0.0),
        "learned before the recording"
    );
    let inputs = |r: &pavlov::record::TickRecord| r.inputs.clone().expect("inputs");
    let followed = rec
        .records
        .iter()
        .filter(|r| inputs(r).previous_followed_default)
        .count();
    assert!(
        followed > 0 && followed < rec.records.len(),
        "both ratios occur: {followed} of {}",
        rec.records.len()
    );
    assert!(
        rec.records
            .iter()
            .any(|r| r.mode == Mode::Pavlovian && r.gate && !r.stimulus),
        "the off-policy prediction drove the gate"
    );
    replay_exact(&rec);
    let mut all_followed = rec.clone();
    for r in &mut all_followed.records {
        if let Some(i) = r.inputs.as_mut() {
            i.previous_followed_default = true;
        }
    }
    assert!(!replay::replay(&all_followed).unwrap().exact());
    let _ = std::fs::remove_dir_all(&root);
}
