//! The real-time benchmark behind `pavlov bench`: runs the whole server on the simulated robot for a span of
//! wall-clock time and reports tick lateness and tick-to-command latency. A benchmark, not a test: it
//! prints figures and asserts nothing about them.
//!
//! - [`load`]: websocket clients reading the dashboard stream during the run;
//! - [`abuse`]: abusive clients (floods, storms, never-reading sockets) for `--ws-abuse`, and `floods`,
//!   its watcher and idle-socket floods;
//! - [`estop_probe`]: the operator's e-stop, timed from send to ack, during the run;
//! - [`foxglove_load`]: Foxglove clients subscribed to every channel, for `--foxglove-clients`;
//! - [`timers`]: the timer thread against tokio's interval, interleaved in one invocation.
//! - [`horde`]: the server with a Horde against the same server without one, interleaved.
//! - `reconnect`: clients that reconnect again and again, timing the history each connection gets.
//! - `zenoh_load`: the Zenoh bridge on and off, interleaved, for `--zenoh`.
//! - [`study`]: the stall study in virtual time, CPU and wall time per simulated tick, for
//!   `--virtual-time`.

pub mod abuse;
pub mod estop_probe;
pub(crate) mod floods;
pub mod foxglove_load;
pub mod horde;
pub mod load;
pub(crate) mod reconnect;
pub mod study;
pub mod timers;
#[cfg(feature = "zenoh")]
pub mod zenoh_load;

use std::fmt;
use std::time::Duration;

use pavlov::config::Config;

use crate::server::{RobotTarget, Server, ServerError};
use crate::telemetry::histogram::LatencyQuantiles;

/// What a benchmark run measured.
#[derive(Debug, Clone)]
pub struct BenchReport {
    /// Wall-clock duration of the run.
    pub(crate) duration: Duration,
    /// Ticks fired.
    pub(crate) ticks: u64,
    /// Ticks skipped.
    pub(crate) skipped: u64,
    /// Lateness of each tick.
    pub lateness: LatencyQuantiles,
    /// Tick deadline to motor command written.
    pub(crate) tick_to_command: LatencyQuantiles,
    /// Records published.
    pub(crate) records: u64,
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "ran {:.1} s: {} ticks fired, {} skipped, {} tick records",
            self.duration.as_secs_f64(),
            self.ticks,
            self.skipped,
            self.records
        )?;
        writeln!(
            f,
            "{:<28}{:>10}{:>10}{:>10}{:>10}",
            "µs", "p50", "p99", "max", "mean"
        )?;
        for (name, s) in [
            ("tick lateness", &self.lateness),
            ("tick → command written", &self.tick_to_command),
        ] {
            writeln!(
                f,
                "{:<28}{:>10}{:>10}{:>10}{:>10.1}",
                name, s.p50_us, s.p99_us, s.max_us, s.mean_us
            )?;
        }
        Ok(())
    }
}

/// Runs the server on the simulated robot for `duration` of real time.
pub async fn run_realtime(config: Config, duration: Duration) -> Result<BenchReport, ServerError> {
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await?;
    let report = measure(&server, duration).await;
    server.shutdown().await;
    Ok(report)
}

/// Measures a running server for `duration` of real time (the histograms cover the whole run so far).
pub(crate) async fn measure(server: &Server, duration: Duration) -> BenchReport {
    let mut feed = server.feed().subscribe();
    let records = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let count = records.clone();
    let counter = tokio::spawn(async move {
        loop {
            let n = match feed.recv().await {
                Ok(_) => 1,
                Err(tokio::sync::broadcast::error::RecvError::Lagged(k)) => k,
                Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
            };
            count.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        }
    });
    let start = std::time::Instant::now();
    tokio::time::sleep(duration).await;
    let elapsed = start.elapsed();
    let f = server.health().figures();
    counter.abort();
    BenchReport {
        duration: elapsed,
        ticks: f.ticks_fired,
        skipped: f.ticks_skipped,
        lateness: f.lateness,
        tick_to_command: f.tick_to_command,
        records: records.load(std::sync::atomic::Ordering::Relaxed),
    }
}

/// The 1-minute load average (Linux), which the benchmarks print beside their figures.
pub(crate) fn load_average() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    text.split_whitespace().next()?.parse().ok()
}
