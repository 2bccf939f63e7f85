//! The whole runtime (every actor, the in-process simulated Create) under tokio's paused clock:
//! determinism for a seed, a 6-minute run in seconds, e-stop, and a safe shut-down.

use crate::common;

use std::time::Instant as WallClock;

use pavlov::control::{Action, Mode};
use pavlov::record::SafetyStop;
use pavlov::sim::robot::OiMode;
use pavlov_actors::command::{
    ControlCommand, ControlRequest, GatingCommand, LatchCommand, LearningCommand,
};

use common::{collect, run_sim, stall_config};

#[tokio::test(start_paused = true)]
async fn same_seed_gives_identical_tick_records() {
    let mut cfg = stall_config();
    cfg.sim.seed = 7;
    let (a, sa) = run_sim(cfg.clone(), 1500).await;
    sa.shutdown().await;
    let (b, sb) = run_sim(cfg.clone(), 1500).await;
    sb.shutdown().await;
    assert_eq!(a.len(), 1500);
    assert_eq!(
        a, b,
        "two runs with the same seed must give identical records"
    );
    // Consecutive ticks, no gaps, and the robot actually moved and sensed.
    assert!(a.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    assert!(a.iter().any(|r| r.command != Action::STOP));
    assert!(a.iter().map(|r| r.sensors.distance_mm.abs()).sum::<i32>() > 100);
    cfg.sim.seed = 8;
    let (c, sc) = run_sim(cfg, 1500).await;
    sc.shutdown().await;
    assert_ne!(a, c, "another seed gives another run");
}

#[tokio::test(start_paused = true)]
async fn a_six_minute_run_completes_under_virtual_time() {
    let wall = WallClock::now();
    let (records, server) = run_sim(stall_config(), 6 * 60 * 50).await;
    let elapsed = wall.elapsed();
    println!(
        "6 simulated minutes (18000 ticks) took {:.2} s of wall time",
        elapsed.as_secs_f64()
    );
    let last = records.last().expect("records");
    assert_eq!(last.seq, 17_999);
    assert!((last.t_ms - 17_999.0 * 20.0).abs() < 1e-6);
    // The default policy drives into the enclosure's walls: the stall stimulus occurs and the robot
    // receives no stale-observation stops in a healthy run.
    assert!(records.iter().any(|r| r.stimulus), "no stall in 6 minutes");
    assert!(records.iter().skip(10).all(|r| r.safety_stop.is_none()));
    assert!(records.iter().all(|r| r.link.bad_frames == 0));
    let report = server.shutdown().await;
    let robot = report.sim_robot.expect("simulated robot");
    assert_eq!(robot.oi_mode(), OiMode::Passive);
}

#[tokio::test(start_paused = true)]
async fn estop_stops_the_wheels_until_released() {
    let mut cfg = stall_config();
    cfg.control.mode = Mode::Reactive;
    let (_, server) = run_sim(cfg, 200).await;
    let mut rx = server.feed().subscribe();
    let (req, reply) = ControlRequest::new(LatchCommand::Estop {});
    server.commands().send(req).await.unwrap();
    assert!(reply.await.unwrap().is_ok());
    let after = collect(&mut rx, 100).await;
    // From the first record produced after the latch, every command is a stop, flagged as the e-stop.
    let first = after
        .iter()
        .position(|r| r.estop)
        .expect("e-stop visible in the records");
    assert!(first <= 2);
    for r in &after[first..] {
        assert_eq!(r.command, Action::STOP);
        assert_eq!(r.safety_stop, Some(SafetyStop::EStop));
    }
    // After the wheels have spun down (well under a second), odometry reports no motion.
    assert!(
        after[first + 50..]
            .iter()
            .all(|r| r.sensors.distance_mm == 0 && r.sensors.angle_deg == 0)
    );
    let (req, reply) = ControlRequest::new(LatchCommand::Release {});
    server.commands().send(req).await.unwrap();
    assert!(reply.await.unwrap().is_ok());
    let released = collect(&mut rx, 20).await;
    assert!(
        released
            .iter()
            .any(|r| !r.estop && r.command != Action::STOP)
    );
    server.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn shutdown_leaves_the_simulated_wheels_stopped_in_passive() {
    // The fixed start pose (no lab variation), where the default policy is driving 6 s in.
    let mut config = stall_config();
    config.sim.lab_variation = false;
    let (records, server) = run_sim(config, 300).await;
    assert!(
        records.last().unwrap().command != Action::STOP,
        "driving when shut down"
    );
    let report = server.shutdown().await;
    let mut robot = report.sim_robot.expect("simulated robot");
    assert_eq!(robot.oi_mode(), OiMode::Passive);
    // Let the physical robot coast for a second: nothing drives the wheels any more.
    for _ in 0..67 {
        robot.step();
    }
    for side in 0..2 {
        assert_eq!(
            robot.world().wheel_speed_mm_s(side),
            0.0,
            "wheel {side} still turning"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn commands_are_acknowledged_or_refused_with_a_reason() {
    let (_, server) = run_sim(stall_config(), 10).await;
    let send = |c: ControlCommand| {
        let tx = server.commands().clone();
        async move {
            let (req, reply) = ControlRequest::new(c);
            tx.send(req).await.unwrap();
            reply.await.unwrap()
        }
    };
    let refused = send(
        GatingCommand::Teleop {
            left_mm_s: 100,
            right_mm_s: 100,
        }
        .into(),
    )
    .await;
    assert!(refused.unwrap_err().to_string().contains("manual"));
    assert!(
        send(GatingCommand::SetMode { mode: Mode::Manual }.into())
            .await
            .is_ok()
    );
    assert!(
        send(
            GatingCommand::Teleop {
                left_mm_s: 100,
                right_mm_s: 100
            }
            .into()
        )
        .await
        .is_ok()
    );
    assert!(
        send(
            GatingCommand::Teleop {
                left_mm_s: 900,
                right_mm_s: 0
            }
            .into()
        )
        .await
        .is_err()
    );
    let bad = send(
        LearningCommand::SetParams {
            prediction: None,
            alpha: Some(-1.0),
            lambda: None,
            threshold: None,
        }
        .into(),
    )
    .await;
    assert!(bad.is_err(), "negative alpha accepted");
    assert!(send(LearningCommand::ResetWeights {}.into()).await.is_ok());
    let mut rx = server.feed().subscribe();
    let manual = collect(&mut rx, 5).await;
    assert!(manual.iter().all(|r| r.mode == Mode::Manual));
    assert!(manual.iter().any(|r| r.command == Action::new(100, 100)));
    server.shutdown().await;
}
