//! A run under the stochastic gate (`[control] gate = "stochastic"`) replays bit for bit: the gate's
//! draws come from the recorded configuration's seed and the tick, every record carries the behaviour
//! probability b of its command, and the off-policy prediction learns with ρ = 1/b on π's action. The
//! recording starts mid-run, so nothing before it is needed; a different seed, or the ratios taken as
//! certain, does not replay.

use pavlov::control::Mode;
use pavlov_actors::command::{ControlCommand, ControlRequest, Outcome, RecorderCommand};
use pavlov_actors::experiment::stall::{policies, stochastic};
use pavlov_actors::server::Server;
use pavlov_actors::storage::recording;
use pavlov_actors::storage::replay;

use super::fixtures::{fresh_dir, with_recorded_server};
use crate::common;

const EPSILON: f64 = 0.35;

async fn send(server: &Server, command: impl Into<ControlCommand>) -> Outcome {
    let (req, reply) = ControlRequest::new(command);
    server.commands().send(req).await.expect("router up");
    reply.await.expect("a reply")
}

#[test]
fn a_stochastic_gate_run_replays_bit_for_bit() {
    let root = fresh_dir("replay-stochastic");
    let base = policies::with_offpolicy_prediction(&common::stall_config())
        .expect("the off-policy prediction fits");
    let mut cfg = stochastic::with_stochastic_gate(&base, EPSILON).expect("the bound holds");
    cfg.control.gate_prediction = "stall_pi".into();
    cfg.control.mode = Mode::Pavlovian;
    cfg.sim.seed = 11;
    let body = async |server: &Server| {
        let mut rx = server.feed().subscribe();
        common::collect(&mut rx, 1000).await;
        let started = send(
            server,
            RecorderCommand::StartRecording {
                dir: Some("stochastic".into()),
            },
        )
        .await;
        assert!(started.is_ok(), "{started:?}");
        common::collect(&mut rx, 2000).await;
        let stopped = send(server, RecorderCommand::StopRecording {}).await;
        assert!(stopped.is_ok(), "{stopped:?}");
    };
    with_recorded_server(cfg, "stochastic", None, &root, 20_000, body);
    let rec = recording::load(&root.join("stochastic")).expect("reads back");
    assert!(rec.header.start.is_some(), "started mid-run");

    // Both draws occur, each logged with its probability; every other command is certain.
    let b = |p: f64| rec.records.iter().filter(|r| r.behaviour_prob == p).count();
    let (pi, response) = (b(EPSILON), b(1.0 - EPSILON));
    assert!(
        pi > 0 && response > 0,
        "{pi} draws of π, {response} of the response"
    );
    assert_eq!(pi + response + b(1.0), rec.records.len());
    for r in rec.records.iter().filter(|r| r.behaviour_prob == EPSILON) {
        assert_eq!(
            r.command, r.default_action,
            "tick {}: b = ε on π's action",
            r.seq
        );
        assert!(!r.gate && r.rule.as_deref() == Some("stall_pi"));
    }
    // The next tick's inputs carry that b: ρ = 1/ε reaches the learner.
    let inputs = |r: &pavlov::record::TickRecord| r.inputs.clone().expect("inputs");
    assert!(rec.records.iter().any(|r| {
        let i = inputs(r);
        i.previous_followed_default && i.previous_behaviour_prob == EPSILON
    }));

    let exact = replay::replay(&rec).expect("replay runs");
    assert!(exact.exact(), "{}", replay::describe(&exact));
    assert_eq!(exact.behaviour_compared, rec.records.len());
    assert_eq!(exact.commands_compared, rec.records.len());

    // Another seed draws otherwise: the commands (and b) no longer match.
    let mut reseeded = rec.clone();
    reseeded.header.config.sim.seed += 1;
    assert!(!replay::replay(&reseeded).expect("replay runs").exact());
    // The ratios taken as certain (ρ = 1 instead of 1/ε): the off-policy prediction drifts.
    let mut certain = rec.clone();
    for r in &mut certain.records {
        if let Some(i) = r.inputs.as_mut() {
            i.previous_behaviour_prob = 1.0;
        }
    }
    let drifted = replay::replay(&certain).expect("replay runs");
    assert!(
        drifted
            .mismatches
            .iter()
            .any(|m| m.field == "prediction stall_pi"),
        "{}",
        replay::describe(&drifted)
    );
    let _ = std::fs::remove_dir_all(&root);
}
