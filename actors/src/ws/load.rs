//! Dashboard load for `pavlov bench --ws-clients N [--stalled-client]`: runs the server with its dashboard
//! endpoint on an ephemeral loopback port, connects `N` websocket clients that read every message, plus
//! optionally one that never reads (with a tiny receive buffer, so its backlog reaches the server at
//! once), and measures tick lateness meanwhile.
//!
//! The clients run on their own single-threaded runtime in their own OS thread, like browsers in other
//! processes would: they compete for the CPU, not for the server's runtime. A benchmark, not a test: it
//! reports figures and asserts nothing about them.

use std::fmt;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use futures_util::StreamExt;
use pavlov::config::Config;
use tokio::sync::watch;

use super::{Dashboard, DashboardError, DashboardStats};
use crate::bench::{BenchReport, measure};
use crate::server::{RobotTarget, Server, ServerError};

/// What to connect.
#[derive(Debug, Clone, Copy)]
pub struct Load {
    /// Clients that read everything.
    pub clients: usize,
    /// Whether to add one client that never reads.
    pub stalled: bool,
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
    pub load: Load,
    /// Tick figures while the clients were connected.
    pub bench: BenchReport,
    /// Ticks each reading client received, sorted.
    pub ticks_per_client: Vec<u64>,
    /// The endpoint's counters at the end.
    pub dashboard: DashboardStats,
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
        writeln!(
            f,
            "stalled client: {}; telemetry dropped for slow clients: {}; clients connected at the end: {}",
            if self.load.stalled { "yes" } else { "no" },
            self.dashboard.telemetry_dropped,
            self.dashboard.clients
        )
    }
}

/// Runs the server on the simulated robot with its dashboard under `load` for `duration` of real time.
pub async fn run_realtime_with_clients(
    mut config: Config,
    duration: Duration,
    web_dir: PathBuf,
    load: Load,
) -> Result<LoadReport, LoadError> {
    config.dashboard.bind = "127.0.0.1:0".into();
    config.dashboard.max_clients = config.dashboard.max_clients.max(load.clients + 2);
    let server = Server::start(config, RobotTarget::Simulated).await?;
    let dash = match Dashboard::start(&server, web_dir).await {
        Ok(d) => d,
        Err(e) => {
            server.shutdown().await;
            return Err(e.into());
        }
    };
    let addr = dash.local_addr();
    let (stop_tx, stop_rx) = watch::channel(false);
    let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
    let clients = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build();
        match rt {
            Ok(rt) => rt.block_on(run_clients(addr, load, stop_rx, ready_tx)),
            Err(e) => Err(e.to_string()),
        }
    });
    // Measure only once every client is connected.
    let connected = ready_rx
        .await
        .unwrap_or_else(|_| Err("the client thread ended".into()));
    let result = match connected {
        Ok(()) => {
            let bench = measure(&server, duration).await;
            let dashboard = dash.stats();
            let _ = stop_tx.send(true);
            match tokio::task::spawn_blocking(move || clients.join()).await {
                Ok(Ok(Ok(mut ticks_per_client))) => {
                    ticks_per_client.sort_unstable();
                    Ok(LoadReport {
                        load,
                        bench,
                        ticks_per_client,
                        dashboard,
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

async fn run_clients(
    addr: SocketAddr,
    load: Load,
    stop: watch::Receiver<bool>,
    ready: tokio::sync::oneshot::Sender<Result<(), String>>,
) -> Result<Vec<u64>, String> {
    let url = format!("ws://{addr}/ws");
    let mut readers = Vec::with_capacity(load.clients);
    let connected = async {
        let mut streams = Vec::new();
        for _ in 0..load.clients {
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
            ticks
        }));
    }
    let _ = ready.send(Ok(()));
    let mut stop = stop;
    let _ = stop.changed().await;
    drop(stalled);
    let mut counts = Vec::with_capacity(readers.len());
    for r in readers {
        counts.push(r.await.unwrap_or(0));
    }
    Ok(counts)
}
