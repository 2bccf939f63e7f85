//! `pavlov bench --zenoh`: what publishing on Zenoh costs the tick. Runs a fresh server on the simulated
//! Create without and with the Zenoh bridge, interleaved (`ORDER`: off, on, on, off, twice; each an
//! eighth of the time), and with the bridge a second Zenoh session on loopback subscribed to
//! `pavlov/v1/<robot>/**`, so every tick and status really crosses a TCP link. Reports ticks skipped and
//! tick → command for both, and what the bridge published, lost, and the subscriber received.
//!
//! Each run measures the steady state: the first `WARM_UP` after the server (and the bridge, and the
//! subscriber) started is left out of the figures, in both arms alike, and reported on its own line, so a
//! one-time start-up (Zenoh spawning its threads, the session handshake) is seen but not mistaken for the
//! cost of publishing at 50 Hz. A benchmark, not a test: it asserts nothing.

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use pavlov::config::Config;

use crate::server::{RobotTarget, Server};
use crate::telemetry::counters::ZenohFigures;
use crate::telemetry::histogram::LatencyHistogram;
use crate::zenoh_bridge::{KEY_ROOT, ZenohBridge};

/// The arms in run order (true: with the bridge). Interleaved so a drift of the machine falls on both.
const ORDER: [bool; 8] = [false, true, true, false, false, true, true, false];

/// An arm's name.
fn arm(with: bool) -> &'static str {
    if with { "on" } else { "off" }
}

/// What each run leaves out of its figures before measuring.
const WARM_UP: Duration = Duration::from_secs(3);

/// One side's runs, merged.
#[derive(Clone, Default)]
pub struct Side {
    duration: Duration,
    ticks: u64,
    skipped: u64,
    lateness: LatencyHistogram,
    to_command: LatencyHistogram,
    zenoh: ZenohFigures,
    received: u64,
    /// During the warm-ups (left out of the figures above): ticks skipped and tick → command.
    warm_skipped: u64,
    warm_to_command: LatencyHistogram,
}

/// Without and with the bridge.
pub struct ZenohComparison {
    off: Side,
    on: Side,
    /// Each run in order: with the bridge or not, its tick → command p99 (µs), its skipped ticks.
    runs: Vec<(bool, u64, u64)>,
}

/// A loopback-only Zenoh peer configuration: listen on `listen`, connect to `connect`, no scouting.
fn loopback(listen: &[String], connect: &[String]) -> Result<zenoh::Config, String> {
    let text = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": listen },
        "connect": { "endpoints": connect },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    zenoh::Config::from_json5(&text.to_string()).map_err(|e| e.to_string())
}

fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| e.to_string())
}

/// Runs the comparison for `duration` in all.
pub async fn run_zenoh_comparison(
    config: Config,
    duration: Duration,
) -> anyhow::Result<ZenohComparison> {
    let each = duration / ORDER.len() as u32;
    let (mut off, mut on) = (Side::default(), Side::default());
    let mut runs = Vec::new();
    for with in ORDER {
        let run = run_one(&config, with, each).await?;
        runs.push((with, run.to_command.quantiles().p99_us, run.skipped));
        let side = if with { &mut on } else { &mut off };
        side.duration += run.duration;
        side.ticks += run.ticks;
        side.skipped += run.skipped;
        side.lateness.merge(&run.lateness);
        side.to_command.merge(&run.to_command);
        side.received += run.received;
        side.warm_skipped += run.warm_skipped;
        side.warm_to_command.merge(&run.warm_to_command);
        side.zenoh = side.zenoh.plus(run.zenoh);
    }
    Ok(ZenohComparison { off, on, runs })
}

async fn run_one(config: &Config, with: bool, duration: Duration) -> anyhow::Result<Side> {
    let mut config = config.clone();
    config.zenoh.robot = "bench".into();
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await?;
    let mut bridge = None;
    let mut subscriber = None;
    let received = Arc::new(AtomicU64::new(0));
    if with {
        let port = free_port().map_err(anyhow::Error::msg)?;
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let bridge_config =
            loopback(std::slice::from_ref(&endpoint), &[]).map_err(anyhow::Error::msg)?;
        bridge = Some(
            ZenohBridge::start(bridge_config, &server, "http://127.0.0.1/bench".into()).await?,
        );
        let sub_config = loopback(&[], &[endpoint]).map_err(anyhow::Error::msg)?;
        let session = zenoh::open(sub_config)
            .await
            .map_err(|e| anyhow::anyhow!("subscriber session: {e}"))?;
        let sub = session
            .declare_subscriber(format!("{KEY_ROOT}/bench/**"))
            .await
            .map_err(|e| anyhow::anyhow!("subscriber: {e}"))?;
        let count = received.clone();
        let task = tokio::spawn(async move {
            while sub.recv_async().await.is_ok() {
                count.fetch_add(1, Ordering::Relaxed);
            }
        });
        subscriber = Some((session, task));
    }
    let health = server.health();
    tokio::time::sleep(WARM_UP).await;
    let warm = health.figures();
    let (warm_lateness, warm_to_command) = health.histograms();
    let warm_zenoh = health.zenoh.figures();
    let warm_received = received.load(Ordering::Relaxed);
    let start = std::time::Instant::now();
    tokio::time::sleep(duration).await;
    let figures = health.figures();
    let (lateness, to_command) = health.histograms();
    let zenoh = health.zenoh.figures();
    let side = Side {
        duration: start.elapsed(),
        ticks: figures.ticks_fired - warm.ticks_fired,
        skipped: figures.ticks_skipped - warm.ticks_skipped,
        lateness: lateness.since(&warm_lateness),
        to_command: to_command.since(&warm_to_command),
        zenoh: zenoh.since(warm_zenoh),
        received: received.load(Ordering::Relaxed) - warm_received,
        warm_skipped: warm.ticks_skipped,
        warm_to_command,
    };
    if let Some((session, task)) = subscriber {
        task.abort();
        let _ = session.close().await;
    }
    if let Some(b) = bridge {
        b.shutdown().await;
    }
    server.shutdown().await;
    Ok(side)
}

impl fmt::Display for ZenohComparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "Zenoh bridge, interleaved ({}); on = publishing every tick, event and status to a subscriber \
             on loopback TCP; each run's first {} s left out",
            ORDER.map(arm).join(", "),
            WARM_UP.as_secs()
        )?;
        for (name, s) in [("off", &self.off), ("on", &self.on)] {
            writeln!(
                f,
                "{name:>4}: {:.1} s, {} ticks fired, {} skipped",
                s.duration.as_secs_f64(),
                s.ticks,
                s.skipped
            )?;
        }
        let z = &self.on.zenoh;
        writeln!(
            f,
            "  on: published {} ticks, {} status, {} events; missed {} ticks, {} events; {} put errors; \
             the subscriber received {}",
            z.ticks_published,
            z.status_published,
            z.events_published,
            z.ticks_missed,
            z.events_missed,
            z.put_errors,
            self.on.received
        )?;
        writeln!(f, "{:<26}{:>10}{:>10}{:>12}", "µs", "off", "on", "on / off")?;
        let (ol, nl) = (self.off.lateness.quantiles(), self.on.lateness.quantiles());
        let (oc, nc) = (
            self.off.to_command.quantiles(),
            self.on.to_command.quantiles(),
        );
        for (name, a, b) in [
            ("tick lateness p50", ol.p50_us, nl.p50_us),
            ("tick lateness p99", ol.p99_us, nl.p99_us),
            ("tick → command p50", oc.p50_us, nc.p50_us),
            ("tick → command p99", oc.p99_us, nc.p99_us),
            ("tick → command max", oc.max_us, nc.max_us),
        ] {
            let ratio = if a == 0 {
                "–".to_string()
            } else {
                format!("{:.2}", b as f64 / a as f64)
            };
            writeln!(f, "{name:<26}{a:>10}{b:>10}{ratio:>12}")?;
        }
        let (ow, nw) = (
            self.off.warm_to_command.quantiles(),
            self.on.warm_to_command.quantiles(),
        );
        writeln!(
            f,
            "left out, the warm-ups: off {} skipped, tick → command p99 {} µs, max {} µs; on {} skipped, \
             p99 {} µs, max {} µs",
            self.off.warm_skipped, ow.p99_us, ow.max_us, self.on.warm_skipped, nw.p99_us, nw.max_us
        )?;
        self.fmt_goal(f)
    }
}

impl ZenohComparison {
    /// Each run's p99, the spread between the runs without the bridge (the measurement's own noise),
    /// and the goal: no skipped tick added and p99 on / off ≤ 1.10.
    fn fmt_goal(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let each: Vec<String> = self
            .runs
            .iter()
            .map(|(with, p99, skipped)| format!("{} {p99} µs ({skipped} skipped)", arm(*with)))
            .collect();
        writeln!(f, "tick → command p99 of each run: {}", each.join(", "))?;
        let offs: Vec<u64> = self.runs.iter().filter(|r| !r.0).map(|r| r.1).collect();
        if let (Some(&lo), Some(&hi)) = (offs.iter().min(), offs.iter().max())
            && lo > 0
        {
            writeln!(
                f,
                "the runs without the bridge differ by up to {:.0} % in p99: the noise of this measurement",
                (hi as f64 / lo as f64 - 1.0) * 100.0
            )?;
        }
        let (off, on) = (
            self.off.to_command.quantiles().p99_us,
            self.on.to_command.quantiles().p99_us,
        );
        let ratio = if off == 0 {
            f64::NAN
        } else {
            on as f64 / off as f64
        };
        let met = self.on.skipped <= self.off.skipped && ratio <= 1.10;
        writeln!(
            f,
            "goal no skipped tick added and tick → command p99 on / off ≤ 1.10: {ratio:.2}, {}",
            if met { "met" } else { "MISSED" }
        )
    }
}
