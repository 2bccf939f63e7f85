//! Helpers shared by the end-to-end tests: configurations and record collection.
#![allow(dead_code)]

use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use pavlov::config::Config;
use pavlov::record::TickRecord;
use pavlov_actors::server::Server;
use tokio::sync::broadcast;

/// A fresh, empty folder under the system's temporary folder for one test, removed when dropped (also
/// when the test fails and unwinds), so runs of the suite leave nothing behind.
pub struct TestDir(PathBuf);

impl TestDir {
    /// `pavlov-<name>-<pid>-<n>`, `n` counting the folders of this process (so two tests never share
    /// one), emptied first.
    pub fn new(name: &str) -> TestDir {
        static MADE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = MADE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("pavlov-{name}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        TestDir(dir)
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

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
    let mut rx = server.feed().subscribe();
    let records = collect(&mut rx, n).await;
    (records, server)
}
