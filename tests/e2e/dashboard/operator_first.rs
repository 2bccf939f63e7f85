//! The operator first, on its own connection and its own address: an `estop` sent behind a run of slow
//! commands on the same connection is in force before they are done, and an idle flood from the
//! operator's own address (127.0.0.1, as every local client of a loopback server) leaves the operator's
//! handshake and `/healthz` a way in. Real sockets to a real server on the simulated robot.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use futures_util::SinkExt;
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

use super::operator::idle_socket;
use super::rig::{Lab, TOKEN, WAIT, http_get_from, loopback, next_json, ws_from};

/// `save_weights` sent back to back before the `estop` (within the rate limit's burst of 40).
const SAVES: u64 = 30;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_estop_behind_its_own_connections_saves_is_in_force_before_they_are_done() {
    let weights = std::env::temp_dir().join(format!("pavlov-estop-first-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&weights);
    let dir = weights.display().to_string();
    let lab = Lab::start(move |c| c.checkpoint.dir = dir).await;
    // Some ticks first, so that the e-stopped tick has earlier ones to follow.
    let t0 = Instant::now();
    while lab.server.feed().last_seq().is_none_or(|s| s < 10) {
        assert!(t0.elapsed() < WAIT, "no ticks");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut records = lab.server.feed().subscribe();
    let (mut op, hello) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    assert_eq!(hello["can_command"], true);
    // Thirty saves, then the e-stop, in one burst; nothing is read until all are sent.
    for id in 1..=SAVES {
        let save = json!({"cmd": "save_weights", "id": id});
        op.feed(Message::text(save.to_string())).await.unwrap();
    }
    let estop_id = 1000;
    op.feed(Message::text(
        json!({"cmd": "estop", "id": estop_id}).to_string(),
    ))
    .await
    .unwrap();
    let sent = Instant::now();
    op.flush().await.unwrap();

    // The replies, in the order they come: the e-stop's must come before the last save's.
    let mut order = Vec::new();
    let mut estop_acked = None;
    let mut last_save_tick = None;
    while order.len() < SAVES as usize + 1 {
        let v = next_json(&mut op).await;
        if v["type"] != "ack" && v["type"] != "error" {
            continue;
        }
        let id = v["id"].as_u64().unwrap_or_default();
        if id == estop_id {
            assert_eq!(v["result"]["estop"], true, "{v}");
            estop_acked = Some((sent.elapsed(), order.len()));
            // Set already: actuation reads this latch on its next tick.
            assert!(lab.server.estop().latched());
        } else {
            assert_eq!(v["type"], "ack", "save {id}: {v}");
            if id == SAVES {
                last_save_tick = lab.server.feed().last_seq();
            }
        }
        order.push(id);
    }
    let (ack_latency, saves_before) = estop_acked.expect("the e-stop was answered");
    assert!(
        saves_before < SAVES as usize,
        "the e-stop was answered after all {SAVES} saves: {order:?}"
    );
    // The saves went on in their order.
    let saves: Vec<u64> = order.iter().copied().filter(|&i| i != estop_id).collect();
    assert_eq!(saves, (1..=SAVES).collect::<Vec<_>>());

    // The records say the same: the first tick stopped by the e-stop was made before the last save was
    // done (give or take the one tick in flight when the last save's answer was read).
    let last_save_tick =
        last_save_tick.expect("ticks were recorded before the last save was answered");
    let first_stopped = loop {
        let r = tokio::time::timeout(WAIT, records.recv())
            .await
            .expect("a record in time")
            .expect("the feed is open");
        if r.estop {
            break r;
        }
    };
    assert!(
        first_stopped.seq <= last_save_tick + 1,
        "first e-stopped tick {} after the last save's tick {last_save_tick}",
        first_stopped.seq
    );
    assert_eq!(
        (
            first_stopped.command.left_mm_s,
            first_stopped.command.right_mm_s
        ),
        (0, 0)
    );
    eprintln!(
        "e-stop behind {SAVES} saves: acked after {:.2} ms with {saves_before} saves done before it; \
         first stopped tick {} ≤ the last save's tick {last_save_tick}",
        ack_latency.as_secs_f64() * 1e3,
        first_stopped.seq
    );
    lab.stop().await;
    let _ = std::fs::remove_dir_all(&weights);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_release_sent_before_an_estop_that_overtook_it_does_not_undo_it() {
    let weights = std::env::temp_dir().join(format!("pavlov-release-first-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&weights);
    let dir = weights.display().to_string();
    let lab = Lab::start(move |c| c.checkpoint.dir = dir).await;
    let (mut op, _) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    // Saves, a release (waiting behind them), then an e-stop (applied at once, before the release).
    for (id, cmd) in (1..=10u64)
        .map(|id| (id, json!({"cmd": "save_weights"})))
        .chain([
            (11, json!({"cmd": "release"})),
            (12, json!({"cmd": "estop"})),
        ])
    {
        let mut m = cmd;
        m["id"] = json!(id);
        op.feed(Message::text(m.to_string())).await.unwrap();
    }
    op.flush().await.unwrap();
    let mut release = None;
    let mut estop_first = None;
    while release.is_none() {
        let v = next_json(&mut op).await;
        // Replies only: events carry an `id` of their own.
        if v["type"] != "ack" && v["type"] != "error" {
            continue;
        }
        match v["id"].as_u64() {
            Some(12) => estop_first = Some(release.is_none()),
            Some(11) => release = Some(v),
            _ => {}
        }
    }
    let release = release.unwrap_or_default();
    // Whatever the order the machine gave them, the e-stop was sent last, so it holds: a release that
    // reached the latch first was undone by it (acked), one the e-stop overtook is refused (superseded).
    // (Which reply comes first says little: the e-stop is acked by the reader at once, the release only
    // when the router has answered, so an applied release may be answered after the e-stop.)
    assert!(
        lab.server.estop().latched(),
        "the e-stop does not hold: {release}"
    );
    match release["type"].as_str() {
        Some("ack") => {}
        Some("error") => assert_eq!(release["code"], "superseded", "{release}"),
        _ => panic!("the release got neither an ack nor an error: {release}"),
    }
    eprintln!(
        "release before an e-stop: e-stop answered first: {estop_first:?}; release answered {}",
        if release["type"] == "ack" {
            "ack (applied before the e-stop)"
        } else {
            "superseded"
        }
    );
    lab.stop().await;
    let _ = std::fs::remove_dir_all(&weights);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_flood_from_the_operators_own_address_leaves_it_and_healthz_a_way_in() {
    let lab = Lab::start(|_| {}).await;
    let addr = lab.addr();
    let share = lab.server.config().dashboard.max_pending_per_address;
    let local = loopback(1);
    // Ten times the address's share of idle sockets from 127.0.0.1, each reopened as soon as it is closed.
    let flood = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("same-address-flood")
        .enable_all()
        .build()
        .unwrap();
    let opened = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    for _ in 0..share * 10 {
        flood.spawn(idle_socket(local, addr, opened.clone(), stop.clone()));
    }
    let t0 = Instant::now();
    while opened.load(Ordering::Relaxed) < (share * 20) as u64 {
        assert!(t0.elapsed() < WAIT, "the flood did not get going");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let stats = lab.dash.stats();
    assert!(stats.closed_evicted > 0, "{stats:?}");
    // From the same address: /healthz answers (a probe is a fresh connection; on a machine as busy as
    // this flood makes it, one that was cut is tried again, as a monitor or a browser would, at most twice)…
    // What the guard guarantees is that the flood cannot starve them: each gets in while the flood goes
    // on, within a failure deadline; how many tries that takes depends on the machine, and is printed.
    let mut first_try = 0;
    let mut most_tries = 0;
    for i in 0..20 {
        let started = Instant::now();
        let mut attempt = 0;
        loop {
            let probe = tokio::spawn(async move { http_get_from(local, addr, "/healthz").await });
            if let Ok((200, body)) = probe.await {
                assert_eq!(body, "ok");
                break;
            }
            attempt += 1;
            assert!(
                started.elapsed() < WAIT,
                "probe {i} got no answer in {attempt} tries"
            );
        }
        first_try += usize::from(attempt == 0);
        most_tries = most_tries.max(attempt + 1);
    }
    // …and the operator's handshakes succeed (likewise), and its e-stop latches.
    for i in 0..10 {
        let started = Instant::now();
        let mut tries = 0;
        let (mut op, hello) = loop {
            tries += 1;
            match ws_from(local, addr, Some(TOKEN)).await {
                Ok(connected) => break connected,
                Err(e) => assert!(
                    started.elapsed() < WAIT,
                    "operator handshake {i}: no way in after {tries} tries: {e}"
                ),
            }
        };
        most_tries = most_tries.max(tries);
        assert_eq!(hello["can_command"], true);
        if i == 9 {
            op.send(Message::text(json!({"cmd": "estop", "id": 1}).to_string()))
                .await
                .unwrap();
            loop {
                let v = next_json(&mut op).await;
                if v["id"] == 1 && v["type"] == "ack" {
                    assert_eq!(v["result"]["estop"], true, "{v}");
                    break;
                }
            }
        }
    }
    let stats = lab.dash.stats();
    eprintln!(
        "same-address idle flood: {} sockets opened in {:.1} s, {} evicted, {} refused at once; \
         20 /healthz ({first_try} at the first try) and 10 operator handshakes from 127.0.0.1 served \
         (at most {most_tries} tries for one)",
        opened.load(Ordering::Relaxed),
        t0.elapsed().as_secs_f64(),
        stats.closed_evicted,
        stats.tcp_refused
    );
    assert!(stats.pending <= lab.server.config().dashboard.max_pending);
    stop.store(true, Ordering::Relaxed);
    flood.shutdown_background();
    lab.stop().await;
}
