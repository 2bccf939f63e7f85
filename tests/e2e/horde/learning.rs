//! A server with a small `[horde]` learns: its ticks learned grow, `/metrics` serves every
//! `pavlov_horde_*` family with values that fit the run (predictions as configured, no more ticks learned
//! or skipped than fired, step quantiles ordered, no checkpoint errors), and a plain server serves none.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::Duration;

use pavlov::config::Config;
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::telemetry::prometheus_check::{Family, parse};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::{LEARNING_PATIENCE, learned, small_horde, stall_with};

const HORDE_FAMILIES: [(&str, &str); 9] = [
    ("pavlov_horde_predictions", "gauge"),
    ("pavlov_horde_ticks_learned_total", "counter"),
    ("pavlov_horde_skipped_total", "counter"),
    ("pavlov_horde_chain_breaks_total", "counter"),
    ("pavlov_horde_step_p50_seconds", "gauge"),
    ("pavlov_horde_step_p99_seconds", "gauge"),
    ("pavlov_horde_step_max_seconds", "gauge"),
    ("pavlov_horde_checkpoints_written_total", "counter"),
    ("pavlov_horde_checkpoint_errors_total", "counter"),
];

async fn scrape(addr: SocketAddr) -> BTreeMap<String, Family> {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!("GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let text = String::from_utf8(buf).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    parse(body).unwrap_or_else(|e| panic!("{e}\n{body}"))
}

fn value(families: &BTreeMap<String, Family>, name: &str) -> f64 {
    families
        .get(name)
        .and_then(|f| f.samples.first())
        .unwrap_or_else(|| panic!("no {name}"))
        .value
}

async fn start(cfg: Config) -> (Server, Dashboard) {
    let mut cfg = cfg;
    cfg.dashboard.bind = "127.0.0.1:0".into();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    (server, dash)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_horde_learns_and_metrics_show_it() {
    let cfg = stall_with(&small_horde("[2.0, 10.0]"));
    let (server, dash) = start(cfg).await;
    let view = server.horde().cloned().expect("[horde] has families");
    assert_eq!(view.names.len(), (44 + 2) * 2);
    assert!(view.names.contains(&"probe/bias@10".to_string()));
    let mut status = view.status.clone();
    // The Horde publishes its figures every 25 ticks learned; under SCHED_IDLE on a busy machine it learns
    // slowly, so the test waits for ticks learned, not for time.
    learned(&mut status, 50).await;

    let first = scrape(dash.local_addr()).await;
    for (name, kind) in HORDE_FAMILIES {
        let f = first.get(name).unwrap_or_else(|| panic!("{name} missing"));
        assert_eq!(f.kind, kind, "{name}");
    }
    let fired = value(&first, "pavlov_ticks_fired_total");
    let learned_then = value(&first, "pavlov_horde_ticks_learned_total");
    let skipped = value(&first, "pavlov_horde_skipped_total");
    assert_eq!(value(&first, "pavlov_horde_predictions"), 92.0);
    assert!(learned_then >= 50.0, "{learned_then}");
    assert!(
        learned_then + skipped <= fired,
        "{learned_then} + {skipped} > {fired}"
    );
    // A chain breaks at a skipped tick or one learning did not offer (a stale observation).
    assert!(value(&first, "pavlov_horde_chain_breaks_total") <= fired);
    let (p50, p99, max) = (
        value(&first, "pavlov_horde_step_p50_seconds"),
        value(&first, "pavlov_horde_step_p99_seconds"),
        value(&first, "pavlov_horde_step_max_seconds"),
    );
    assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{p50} {p99} {max}");
    assert_eq!(value(&first, "pavlov_horde_checkpoint_errors_total"), 0.0);
    // The values are published too, and they move: a bias at τ = 10 learns towards Σγᵏ = 10. (A tick
    // learned after a skipped one only starts a new chain, so how far it has come after a number of ticks
    // learned depends on how many were skipped: the test waits for the value.)
    assert_eq!(view.values.borrow().values.len(), 92);
    let bias = view
        .names
        .iter()
        .position(|n| n == "probe/bias@10")
        .unwrap();
    let mut values = view.values.clone();
    tokio::time::timeout(LEARNING_PATIENCE, async {
        while values.borrow_and_update().values[bias] <= 0.5 {
            values.changed().await.unwrap();
        }
    })
    .await
    .unwrap_or_else(|_| panic!("the bias stayed at {}", values.borrow().values[bias]));

    // Learning goes on.
    learned(&mut status, learned_then as u64 + 50).await;
    let second = scrape(dash.local_addr()).await;
    assert!(value(&second, "pavlov_horde_ticks_learned_total") >= learned_then + 50.0);
    dash.shutdown().await;
    server.shutdown().await;

    // Without [horde]: no Horde, and no pavlov_horde_* family.
    let (server, dash) = start(super::stall_with("")).await;
    assert!(server.horde().is_none());
    let mut feed = server.feed().subscribe();
    feed.recv().await.unwrap();
    let plain = scrape(dash.local_addr()).await;
    assert!(
        plain.keys().all(|k| !k.starts_with("pavlov_horde_")),
        "{:?}",
        plain.keys().collect::<Vec<_>>()
    );
    dash.shutdown().await;
    server.shutdown().await;
}
