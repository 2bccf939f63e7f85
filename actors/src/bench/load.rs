//! Dashboard load for `pavlov bench --ws-clients N [--stalled-client]`: runs the server with its dashboard
//! endpoint on an ephemeral loopback port, connects `N` websocket clients that read every message, plus
//! optionally one that never reads (with a tiny receive buffer, so its backlog reaches the server at
//! once), and measures tick lateness meanwhile. [`run_abuse_comparison`] runs the same load twice, the
//! second time with [`super::abuse`] clients attacking the endpoint, and reports both, with an operator's
//! e-stop latency ([`super::estop_probe`]) in each. The dashboard has a token in these runs, so that the
//! reading clients (which hold it) are operators and the floods' token-less clients are watchers.
//!
//! The clients run on their own single-threaded runtime in their own OS thread, like browsers in other
//! processes would: they compete for the CPU, not for the server's runtime. A benchmark, not a test: it
//! reports figures and asserts nothing about them.

use std::fmt;
use std::net::SocketAddr;
use std::time::Duration;

use futures_util::StreamExt;
use pavlov::config::Config;
use tokio::sync::watch;

use super::abuse::{Abuse, Thrown};
use super::estop_probe::{self, EstopLatency};
use super::reconnect::{self, Fetches};
use crate::bench::{BenchReport, measure};
use crate::dashboard::{Dashboard, DashboardError, DashboardStats, WebAssets};
use crate::server::{RobotTarget, Server, ServerError};

/// The operators' token in the benchmark's runs.
const BENCH_TOKEN: &str = "pavlov-bench-operator-token";
/// E-stops the operator latches in each abuse-comparison run.
const ESTOPS: usize = 20;

/// What to connect.
#[derive(Debug, Clone, Copy)]
pub struct Load {
    /// Clients that read everything.
    pub clients: usize,
    /// Whether to add one client that never reads.
    pub stalled: bool,
    /// With a value, the reading clients close and connect again this often, reading the server's history
    /// every time (`super::reconnect`).
    pub reconnect_every: Option<Duration>,
}

/// Errors of a load run.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The server did not start.
    #[error(transparent)]
    Server(#[from] ServerError),
    /// The dashboard did not start.
    #[error(transparent)]
    Dashboard(#[from] DashboardError),
    /// The client thread failed.
    #[error("websocket clients: {0}")]
    Clients(String),
}

/// What a load run measured.
#[derive(Debug, Clone)]
pub struct LoadReport {
    /// The load applied.
    pub(crate) load: Load,
    /// Tick figures while the clients were connected.
    pub bench: BenchReport,
    /// Ticks each reading client received, sorted.
    pub(crate) ticks_per_client: Vec<u64>,
    /// The endpoint's counters at the end.
    pub(crate) dashboard: DashboardStats,
    /// The operator's e-stop latency during the run (abuse comparisons only).
    pub(crate) estop: Option<EstopLatency>,
    /// The history each reconnecting client's connections received (with `reconnect_every`).
    pub(crate) history: Fetches,
}

impl fmt::Display for LoadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.bench)?;
        let n = self.ticks_per_client.len();
        if n > 0 {
            let sum: u64 = self.ticks_per_client.iter().sum();
            writeln!(
                f,
                "{n} reading clients: ticks received min {} / mean {:.0} / max {} (of {} records)",
                self.ticks_per_client.first().copied().unwrap_or(0),
                sum as f64 / n as f64,
                self.ticks_per_client.last().copied().unwrap_or(0),
                self.bench.records
            )?;
        }
        write!(f, "{}", self.history)?;
        writeln!(
            f,
            "stalled client: {}; telemetry dropped for slow clients: {}; clients connected at the end: {}",
            if self.load.stalled { "yes" } else { "no" },
            self.dashboard.telemetry_dropped,
            self.dashboard.clients
        )
    }
}

/// The same load without and with abuse.
#[derive(Debug, Clone)]
pub struct AbuseReport {
    /// The abuse applied.
    pub(crate) abuse: Abuse,
    /// The run without abuse.
    pub(crate) baseline: LoadReport,
    /// The run with abuse.
    pub(crate) abused: LoadReport,
    /// What the abusers threw and got back.
    pub(crate) thrown: Thrown,
}

impl fmt::Display for AbuseReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (b, a) = (&self.baseline, &self.abused);
        writeln!(
            f,
            "{:<34}{:>10}{:>10}{:>10}{:>10}",
            "tick lateness µs", "p50", "p99", "max", "skipped"
        )?;
        for (name, r) in [("without abuse", b), ("with abuse", a)] {
            writeln!(
                f,
                "{:<34}{:>10}{:>10}{:>10}{:>10}",
                name,
                r.bench.lateness.p50_us,
                r.bench.lateness.p99_us,
                r.bench.lateness.max_us,
                r.bench.skipped
            )?;
        }
        let per_second = |n: u64| n as f64 / a.bench.duration.as_secs_f64().max(1e-9);
        write!(f, "{}", self.thrown)?;
        writeln!(
            f,
            "rate thrown: {:.0} messages/s ({} flooders, {} malformed, {} never reading, storms of {})",
            per_second(self.thrown.valid + self.thrown.malformed),
            self.abuse.flooders,
            self.abuse.malformed,
            self.abuse.never_readers,
            self.abuse.storm
        )?;
        let d = &a.dashboard;
        writeln!(
            f,
            "server counted: {} rate_limited, {} errors, {} commands, {} handshakes refused, closed {} oversize / {} unread / {} stalled, {} telemetry dropped",
            d.rate_limited,
            d.errors,
            d.commands,
            d.rejected,
            d.closed_oversize,
            d.closed_unread,
            d.closed_write_stall,
            d.telemetry_dropped
        )?;
        writeln!(
            f,
            "pending connections: {} evicted, {} refused on arrival, {} out of time; {} watchers connected at the end (of {} clients)",
            d.closed_evicted, d.tcp_refused, d.closed_no_upgrade, d.watchers, d.clients
        )?;
        for (name, r) in [("without abuse", b), ("with abuse", a)] {
            if let Some(e) = &r.estop {
                writeln!(f, "operator e-stop send → ack, {name}: {e}")?;
            }
        }
        let min = |r: &LoadReport| r.ticks_per_client.first().copied().unwrap_or(0);
        writeln!(
            f,
            "reading clients, fewest ticks received: {} of {} without abuse, {} of {} with",
            min(b),
            b.bench.records,
            min(a),
            a.bench.records
        )
    }
}

/// Runs `load` for `duration` on a fresh server, then again on another with `abuse` added, and compares.
pub async fn run_abuse_comparison(
    config: Config,
    duration: Duration,
    assets: WebAssets,
    load: Load,
    abuse: Abuse,
) -> Result<AbuseReport, LoadError> {
    let (baseline, _) = run_with(
        config.clone(),
        duration,
        assets.clone(),
        load,
        Some(Abuse::none()),
    )
    .await?;
    let (abused, thrown) = run_with(config, duration, assets, load, Some(abuse)).await?;
    Ok(AbuseReport {
        abuse,
        baseline,
        abused,
        thrown: thrown.unwrap_or_default(),
    })
}

/// Runs the server on the simulated robot with its dashboard under `load` for `duration` of real time.
pub async fn run_realtime_with_clients(
    config: Config,
    duration: Duration,
    assets: WebAssets,
    load: Load,
) -> Result<LoadReport, LoadError> {
    run_with(config, duration, assets, load, None)
        .await
        .map(|(report, _)| report)
}

/// Starts the abusers on their own thread and runtime; they stop when `stop` turns true.
fn spawn_abusers(
    addr: std::net::SocketAddr,
    abuse: Abuse,
    config: &Config,
    stop: watch::Receiver<bool>,
) -> std::thread::JoinHandle<Result<Thrown, String>> {
    let control = serde_json::json!({"cmd": "set_mode", "mode": config.control.mode}).to_string();
    let max_message_bytes = config.dashboard.max_message_bytes;
    let token = config.dashboard.token.clone().unwrap_or_default();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| e.to_string())?;
        Ok(rt.block_on(super::abuse::run(
            addr,
            abuse,
            control,
            max_message_bytes,
            token,
            stop,
        )))
    })
}

async fn run_with(
    mut config: Config,
    duration: Duration,
    assets: WebAssets,
    load: Load,
    abuse: Option<Abuse>,
) -> Result<(LoadReport, Option<Thrown>), LoadError> {
    config.dashboard.bind = "127.0.0.1:0".into();
    config.dashboard.max_operators = match abuse {
        // Room for the abusers' long-lived operator connections and the e-stop probe.
        Some(a) => load.clients + 2 + a.connections() + 8,
        None => config.dashboard.max_operators.max(load.clients + 2),
    };
    let token = abuse.map(|_| BENCH_TOKEN.to_string());
    if let Some(t) = &token {
        config.dashboard.token = Some(t.clone());
    }
    let abuse_config = config.clone();
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await?;
    let dash = match Dashboard::start(&server, assets).await {
        Ok(d) => d,
        Err(e) => {
            server.shutdown().await;
            return Err(e.into());
        }
    };
    let addr = dash.local_addr();
    let (stop_tx, stop_rx) = watch::channel(false);
    let stop_rx_abuse = stop_rx.clone();
    let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
    let client_token = token.clone();
    let clients = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build();
        match rt {
            Ok(rt) => rt.block_on(run_clients(addr, load, client_token, stop_rx, ready_tx)),
            Err(e) => Err(e.to_string()),
        }
    });
    // Measure only once every client is connected.
    let connected = ready_rx
        .await
        .unwrap_or_else(|_| Err("the client thread ended".into()));
    let abusers = match (&connected, abuse) {
        (Ok(()), Some(abuse)) if abuse != Abuse::none() => {
            Some(spawn_abusers(addr, abuse, &abuse_config, stop_rx_abuse))
        }
        _ => None,
    };
    let probe = match (&connected, &token) {
        (Ok(()), Some(t)) => Some(spawn_probe(addr, t.clone(), duration)),
        _ => None,
    };
    let result = match connected {
        Ok(()) => {
            let bench = measure(&server, duration).await;
            let dashboard = dash.stats();
            let estop = match probe {
                Some(p) => tokio::task::spawn_blocking(move || p.join().ok())
                    .await
                    .ok()
                    .flatten(),
                None => None,
            };
            let _ = stop_tx.send(true);
            let thrown = match abusers {
                Some(t) => match tokio::task::spawn_blocking(move || t.join()).await {
                    Ok(Ok(Ok(thrown))) => Ok(Some(thrown)),
                    Ok(Ok(Err(e))) => Err(LoadError::Clients(e)),
                    _ => Err(LoadError::Clients("the abuse thread panicked".into())),
                },
                None => Ok(None),
            };
            match tokio::task::spawn_blocking(move || clients.join()).await {
                Ok(Ok(Ok(per_client))) => {
                    let (mut ticks_per_client, fetches): (Vec<u64>, Vec<_>) =
                        per_client.into_iter().unzip();
                    ticks_per_client.sort_unstable();
                    let history = Fetches(fetches.into_iter().flatten().collect());
                    thrown.map(|thrown| {
                        (
                            LoadReport {
                                load,
                                bench,
                                ticks_per_client,
                                dashboard,
                                estop,
                                history,
                            },
                            thrown,
                        )
                    })
                }
                Ok(Ok(Err(e))) => Err(LoadError::Clients(e)),
                _ => Err(LoadError::Clients("the client thread panicked".into())),
            }
        }
        Err(e) => {
            let _ = stop_tx.send(true);
            Err(LoadError::Clients(e))
        }
    };
    dash.shutdown().await;
    server.shutdown().await;
    result
}

/// Starts the e-stop probe on its own thread and runtime: [`ESTOPS`] e-stops spread over the middle of a
/// run of `duration`.
fn spawn_probe(
    addr: SocketAddr,
    token: String,
    duration: Duration,
) -> std::thread::JoinHandle<EstopLatency> {
    let start_after = duration / 10;
    let spacing = (duration * 7 / 10) / ESTOPS as u32;
    std::thread::spawn(move || {
        match tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
        {
            Ok(rt) => rt.block_on(estop_probe::probe(
                addr,
                token,
                ESTOPS,
                start_after,
                spacing,
            )),
            Err(e) => EstopLatency {
                refused: Some(e.to_string()),
                ..EstopLatency::default()
            },
        }
    })
}

async fn run_clients(
    addr: SocketAddr,
    load: Load,
    token: Option<String>,
    stop: watch::Receiver<bool>,
    ready: tokio::sync::oneshot::Sender<Result<(), String>>,
) -> Result<Vec<(u64, Vec<reconnect::Fetch>)>, String> {
    let url = match &token {
        Some(t) => format!("ws://{addr}/ws?token={t}"),
        None => format!("ws://{addr}/ws"),
    };
    let mut readers = Vec::with_capacity(load.clients);
    // Reconnecting clients connect by themselves.
    let persistent = if load.reconnect_every.is_some() {
        0
    } else {
        load.clients
    };
    let connected = async {
        let mut streams = Vec::new();
        for _ in 0..persistent {
            let (ws, _) = tokio_tungstenite::connect_async(url.as_str())
                .await
                .map_err(|e| format!("connect {url}: {e}"))?;
            streams.push(ws);
        }
        let stalled = if load.stalled {
            let sock = tokio::net::TcpSocket::new_v4().map_err(|e| e.to_string())?;
            sock.set_recv_buffer_size(4096).map_err(|e| e.to_string())?;
            let tcp = sock.connect(addr).await.map_err(|e| e.to_string())?;
            let (ws, _) = tokio_tungstenite::client_async(url.as_str(), tcp)
                .await
                .map_err(|e| format!("connect {url}: {e}"))?;
            Some(ws)
        } else {
            None
        };
        Ok::<_, String>((streams, stalled))
    }
    .await;
    let (streams, stalled) = match connected {
        Ok(c) => c,
        Err(e) => {
            let _ = ready.send(Err(e.clone()));
            return Err(e);
        }
    };
    for mut ws in streams {
        let mut stop = stop.clone();
        readers.push(tokio::spawn(async move {
            let mut ticks = 0u64;
            loop {
                tokio::select! {
                    _ = stop.changed() => break,
                    msg = ws.next() => match msg {
                        Some(Ok(tokio_tungstenite::tungstenite::Message::Text(t))) => {
                            if t.as_str().starts_with(r#"{"type":"tick""#) {
                                ticks += 1;
                            }
                        }
                        Some(Ok(_)) => {}
                        Some(Err(_)) | None => break,
                    },
                }
            }
            (ticks, Vec::new())
        }));
    }
    if let Some(every) = load.reconnect_every {
        for _ in 0..load.clients {
            readers.push(tokio::spawn(reconnect::reader(
                url.clone(),
                every,
                stop.clone(),
            )));
        }
    }
    let _ = ready.send(Ok(()));
    let mut stop = stop;
    let _ = stop.changed().await;
    drop(stalled);
    let mut counts = Vec::with_capacity(readers.len());
    for r in readers {
        counts.push(r.await.unwrap_or_default());
    }
    Ok(counts)
}
