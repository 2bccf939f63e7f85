//! Which timer drives the tick: the server started in real time ticks on its own timer thread (or on
//! tokio's interval when `[tick] timer = "tokio"`), and the server under tokio's paused clock keeps tokio's
//! interval, so virtual time stays deterministic.

use crate::common;

use pavlov::config::TickTimer;
use pavlov_actors::server::{RobotTarget, Server};

use common::{collect, run_sim, stall_config};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_real_time_server_ticks_on_the_timer_thread() {
    let (records, server) = run_sim(stall_config(), 10).await;
    assert_eq!(server.health().tick_timer(), TickTimer::Thread);
    // Ticks arrive in order from the thread (gaps would be skips, possible on a loaded machine).
    assert!(records.windows(2).all(|w| w[1].seq > w[0].seq));
    let report = server.shutdown().await;
    assert!(report.sim_robot.is_some(), "the server shut down in order");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn timer_tokio_keeps_tokios_interval_in_real_time() {
    let mut cfg = stall_config();
    cfg.tick.timer = TickTimer::Tokio;
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .expect("server starts");
    let mut rx = server.feed().subscribe();
    collect(&mut rx, 5).await;
    assert_eq!(server.health().tick_timer(), TickTimer::Tokio);
    server.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn a_paused_clock_server_keeps_tokios_interval() {
    // The configuration asks for the thread (the default); virtual time overrides it.
    let cfg = stall_config();
    assert_eq!(cfg.tick.timer, TickTimer::Thread);
    let (records, server) = run_sim(cfg, 200).await;
    assert_eq!(server.health().tick_timer(), TickTimer::Tokio);
    // Under the paused clock every tick fires, on time, in order.
    let seqs: Vec<u64> = records.iter().map(|r| r.seq).collect();
    assert_eq!(seqs, (0..200).collect::<Vec<u64>>());
    server.shutdown().await;
}
