//! Helpers shared by the end-to-end tests: configurations and record collection.
#![allow(dead_code)]

use std::sync::Arc;

use pavlov::config::Config;
use pavlov::record::TickRecord;
use pavlov_actors::server::Server;
use tokio::sync::broadcast;

/// The shipped stall configuration.
pub fn stall_config() -> Config {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .expect("config/stall.toml");
    Config::from_toml(&text).expect("valid stall config")
}

/// Collects every record until `n` have arrived (panics on a lagged subscriber: tests must see every tick).
pub async fn collect(rx: &mut broadcast::Receiver<Arc<TickRecord>>, n: usize) -> Vec<TickRecord> {
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        match rx.recv().await {
            Ok(r) => out.push((*r).clone()),
            Err(e) => panic!("tick feed: {e}"),
        }
    }
    out
}

/// Logs to the test's output when `RUST_LOG` is set.
pub fn init_logging() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
}

/// Starts the server on the simulator and collects `n` records.
pub async fn run_sim(config: Config, n: usize) -> (Vec<TickRecord>, Server) {
    init_logging();
    let server = Server::builder(config, pavlov_actors::server::RobotTarget::Simulated)
        .start()
        .await
        .expect("server starts");
    let mut rx = server.feed.subscribe();
    let records = collect(&mut rx, n).await;
    (records, server)
}
