//! The dashboard endpoint: one HTTP port that serves the browser dashboard (`/`), a health check
//! (`/healthz`), Prometheus metrics (`/metrics`) and the websocket (`/ws`) that streams every tick and
//! takes commands.
//!
//! - `protocol`: the client commands (see `web/PROTOCOL.md`), parsed with precise errors, and the replies;
//! - `messages`: the server's `hello`, `tick` and `status` messages;
//! - `hub`: serialises each tick and event once and fans them out, and keeps the run counters, the
//!   `history` (sent to a new client as `history_messages`) and the `learning` figures;
//! - `horde_feed`: the Horde's names and values for the clients that ask (`horde_watch`);
//! - `out_queue`: each client's bounded, drop-oldest queue and its tick-rate decimation;
//! - [`session`]: one connection's reader, writer and forwarder; `waiting`: the line of its messages
//!   waiting for its worker, in the order they were read, refusals included; `socket_buffers`: the websocket
//!   library's read and write buffers, sized for this protocol;
//! - [`rate`]: the per-connection message rate limit;
//! - `/metrics` is served here; its text is written in `crate::telemetry::prometheus` (with
//!   `crate::telemetry::exposition`), and `crate::telemetry::prometheus_check` is a strict reader of it for tests;
//! - `auth`: the handshake's Origin and token checks, and [`token_throttle`], the per-address limit on
//!   wrong tokens;
//! - `admission`: operator and watcher seats, counted apart (and watchers per address);
//! - [`guard`]: the pool of connections that are not yet websockets (`pending`, bounded in total and per
//!   `source` address, evicting the oldest of the busiest address) and their deadline to become one;
//!   `linger`: a closed websocket's socket shut down for writing and read dry before it is closed, so
//!   that its close frame is not lost to a reset;
//! - `strict_json`: client messages parsed with duplicate keys refused;
//! - `hello_config`: what of the configuration operators and watchers see;
//! - [`assets`]: the page's files, built into the binary (or read from `--web-dir`);
//! - `http`: routes, static files and the handshake; `download`: the recording being written,
//!   finished for the download by `download_copy`;
//! - the websocket load behind `pavlov bench --ws-clients` is [`crate::bench::load`], its abusive clients
//!   [`crate::bench::abuse`].
//!
//! Nothing here can delay the tick: the hub reads the tick feed's lossy broadcast, every client reads the
//! hub's lossy broadcast into its own bounded queue, and only the client's own writer waits on its socket.
//! All of it runs on a separate single-worker runtime, so it never occupies the control actors' workers.

pub(crate) mod admission;
pub(crate) mod app_state;
pub mod assets;
pub(crate) mod auth;
pub(crate) mod download;
pub(crate) mod download_copy;
pub mod guard;
pub(crate) mod hello_config;
pub(crate) mod history;
pub(crate) mod history_messages;
pub(crate) mod horde_feed;
pub(crate) mod http;
pub(crate) mod hub;
pub(crate) mod learning;
pub(crate) mod linger;
pub(crate) mod messages;
pub(crate) mod out_queue;
pub(crate) mod pending;
pub(crate) mod protocol;
pub mod rate;
pub mod session;
pub(crate) mod socket_buffers;
pub(crate) mod source;
pub(crate) mod strict_json;
pub mod token_throttle;
pub(crate) mod waiting;

pub use assets::WebAssets;
pub use auth::generate_token;
/// The watcher's reduced configuration and event view, for the other endpoints that may have watchers.
pub(crate) use hello_config::for_watcher as watcher_config;
pub(crate) use history_messages::for_watcher as event_for_watcher;

use std::net::SocketAddr;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::serve::ListenerExt;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::server::Server;
pub(crate) use crate::telemetry::counters::DashboardStats;
use auth::AccessPolicy;
use history::History;
use hub::{Hub, HubCounters, HubInputs};
use messages::{HelloRun, LearningBounds, RobotInfo, Signals};
use session::SessionCounters;

/// Kernel send buffer of each client socket. Kept small so that a slow client's backlog sits in its
/// drop-oldest queue (where it is bounded and counted) rather than in the kernel.
const CLIENT_SEND_BUFFER: usize = 64 * 1024;

/// Errors starting the endpoint.
#[derive(Debug, thiserror::Error)]
pub enum DashboardError {
    /// The dashboard's runtime could not be created.
    #[error("cannot start the dashboard's runtime: {0}")]
    Runtime(std::io::Error),
    /// The listen address could not be bound.
    #[error("{}", bind_message(addr, source))]
    Bind {
        /// The address from `[dashboard] bind` / `--bind`.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
}

fn bind_message(addr: &str, source: &std::io::Error) -> String {
    match source.kind() {
        std::io::ErrorKind::AddrInUse => format!(
            "{addr} is in use: stop the other server or pass --bind (e.g. --bind 127.0.0.1:8081)"
        ),
        std::io::ErrorKind::AddrNotAvailable => format!(
            "cannot listen on {addr}: no such address on this machine; pass --bind with one of its addresses"
        ),
        std::io::ErrorKind::PermissionDenied => format!(
            "cannot listen on {addr}: permission denied (ports below 1024 need privileges); pass --bind"
        ),
        _ => format!("cannot listen on {addr} for the dashboard: {source}"),
    }
}

/// An id of this server run for `hello.run`: the start time and the process, enough to tell a page that
/// the server it reconnected to is not the one it knew.
fn run_id() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    format!("{nanos:x}-{:x}", std::process::id())
}

/// The running endpoint. It runs on its own single-worker tokio runtime (thread `dashboard`), so that
/// websocket work can neither occupy the control actors' runtime workers nor take more than one core.
pub struct Dashboard {
    addr: SocketAddr,
    state: Arc<app_state::AppState>,
    cancel: CancellationToken,
    http: Option<JoinHandle<()>>,
    hub: Option<JoinHandle<()>>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl Drop for Dashboard {
    fn drop(&mut self) {
        self.cancel.cancel();
        if let Some(rt) = self.runtime.take() {
            // Allowed inside an async context, unlike dropping the runtime.
            rt.shutdown_background();
        }
    }
}

/// The dashboard's listening socket, bound before anything else starts (so a busy port stops the start-up
/// before the robot is touched).
pub struct BoundDashboard {
    listener: std::net::TcpListener,
    addr: SocketAddr,
}

impl BoundDashboard {
    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Dashboard {
    /// Binds `[dashboard] bind`.
    pub fn bind(
        config: &pavlov::config::DashboardConfig,
    ) -> Result<BoundDashboard, DashboardError> {
        let bind_error = |source| DashboardError::Bind {
            addr: config.bind.clone(),
            source,
        };
        let listener = std::net::TcpListener::bind(&config.bind).map_err(bind_error)?;
        listener.set_nonblocking(true).map_err(bind_error)?;
        let addr = listener.local_addr().map_err(bind_error)?;
        Ok(BoundDashboard { listener, addr })
    }

    /// Binds `[dashboard] bind` and starts serving the dashboard of `server` (see [`Dashboard::serve`]).
    pub async fn start(server: &Server, assets: WebAssets) -> Result<Dashboard, DashboardError> {
        let bound = Self::bind(&server.config().dashboard)?;
        Self::serve(bound, server, assets).await
    }

    /// Starts serving the dashboard of `server` on `bound`, its page from `assets` (built into the binary,
    /// or a directory).
    pub async fn serve(
        bound: BoundDashboard,
        server: &Server,
        assets: WebAssets,
    ) -> Result<Dashboard, DashboardError> {
        let cfg = &server.config().dashboard;
        let BoundDashboard {
            listener: std_listener,
            addr,
        } = bound;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("dashboard")
            .enable_all()
            .build()
            .map_err(DashboardError::Runtime)?;
        let listener = {
            let _inside = runtime.enter();
            tokio::net::TcpListener::from_std(std_listener)
        };
        let listener = match listener {
            Ok(l) => l,
            Err(source) => {
                // A runtime may not be dropped inside an async context.
                runtime.shutdown_background();
                return Err(DashboardError::Bind {
                    addr: cfg.bind.clone(),
                    source,
                });
            }
        };
        for missing in assets.missing() {
            tracing::error!(
                "the dashboard's file {} is missing (--web-dir); {}",
                missing.display(),
                assets::INSTALL_HINT
            );
        }
        let cancel = CancellationToken::new();
        let period_ms = server.config().tick.period_ms;
        let gesture_commands = matches!(
            server.config().control.stimulus,
            pavlov::config::StimulusSpec::LeftElbow { .. }
        );
        let history = History::new(
            cfg.history_s,
            period_ms,
            server.config().control.mode,
            server.params_at_start.iter().map(Into::into).collect(),
        );
        let (hub, hub_handle) = Hub::new(period_ms, gesture_commands, history);
        let hub = hub.with_learning(&server.config().predictions);
        let hub_counters = Arc::new(HubCounters::default());
        let guard_counters = Arc::new(guard::GuardCounters::default());
        let pending = Arc::new(Mutex::new(pending::PendingPool::new(
            cfg.max_pending,
            cfg.max_pending_per_address,
        )));
        let state = Arc::new(app_state::AppState {
            policy: AccessPolicy::new(cfg, addr),
            hub: hub_handle,
            commands: server.commands().clone(),
            estop: server.estop().clone(),
            tick_period_ms: period_ms,
            signals: Signals {
                obs: server.obs_names().to_vec(),
                predictions: server
                    .config()
                    .predictions
                    .iter()
                    .map(|p| p.name.clone())
                    .collect(),
                gate_prediction: server.config().control.gate_prediction.clone(),
                bounds: LearningBounds::for_config(server.config()),
                horde_predictions: server.horde().as_ref().map_or(0, |h| h.names.len()),
            },
            operator_config: hello_config::for_operator(server.config()),
            watcher_config: hello_config::for_watcher(server.config()),
            hello_run: HelloRun {
                run: run_id(),
                robot: RobotInfo::new(server.config().robot.model, &server.robot),
                history_s: cfg.history_s,
            },
            max_message_bytes: cfg.max_message_bytes,
            client_queue: cfg.client_queue,
            admission: Arc::new(admission::Admission::new(cfg, hub_counters.clients.clone())),
            throttle: Mutex::new(token_throttle::TokenThrottle::default()),
            pending: pending.clone(),
            rate: rate::DEFAULT_RATE_LIMIT,
            health: server.health(),
            assets,
            hub_counters: hub_counters.clone(),
            session_counters: Arc::new(SessionCounters::default()),
            guard_counters: guard_counters.clone(),
            connections: AtomicU64::new(0),
            rejected: AtomicU64::new(0),
            token_failures: AtomicU64::new(0),
            token_throttled: AtomicU64::new(0),
            cancel: cancel.clone(),
            horde: server
                .horde()
                .as_ref()
                .map(|view| Arc::new(horde_feed::HordeFeed::new(view))),
            downloads: Arc::new(tokio::sync::Semaphore::new(download::AT_ONCE)),
        });
        let (earlier_events, events) = server.events().subscribe_with_recent();
        let hub = runtime.spawn(hub::run(
            hub,
            HubInputs {
                feed: server.feed().subscribe(),
                earlier_events,
                events,
            },
            server.health(),
            hub_counters,
            cancel.clone(),
        ));
        let listener = listener.tap_io(|tcp| {
            let _ = tcp.set_nodelay(true);
            let _ = socket2::SockRef::from(&*tcp).set_send_buffer_size(CLIENT_SEND_BUFFER);
        });
        let listener = guard::GuardedListener::new(
            listener,
            pending,
            guard::PRE_UPGRADE_LIMIT,
            guard_counters,
        );
        let app = http::router(state.clone()).into_make_service_with_connect_info::<guard::Peer>();
        let shutdown = cancel.clone();
        let http = runtime.spawn(async move {
            let serve =
                axum::serve(listener, app).with_graceful_shutdown(shutdown.cancelled_owned());
            if let Err(e) = serve.await {
                tracing::error!("the dashboard endpoint failed: {e}");
            }
        });
        tracing::info!(%addr, token = state.policy.token_required(), "dashboard endpoint listening");
        Ok(Dashboard {
            addr,
            state,
            cancel,
            http: Some(http),
            hub: Some(hub),
            runtime: Some(runtime),
        })
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's URL.
    pub fn url(&self) -> String {
        let host = if self.addr.ip().is_unspecified() {
            "127.0.0.1".to_string()
        } else {
            match self.addr {
                SocketAddr::V4(a) => a.ip().to_string(),
                SocketAddr::V6(a) => format!("[{}]", a.ip()),
            }
        };
        format!("http://{host}:{}/", self.addr.port())
    }

    /// The endpoint's counters now.
    pub fn stats(&self) -> DashboardStats {
        self.state.stats()
    }

    /// Telemetry dropped so far for the websocket client connected from `client` (its local address),
    /// `None` when no such client is connected: a slow client's losses are its own, and a test can tell
    /// them from another client's.
    pub fn telemetry_dropped_for(&self, client: SocketAddr) -> Option<u64> {
        self.state.session_counters.telemetry_dropped_for(client)
    }

    /// Closes every connection (code 1001) and stops listening.
    pub async fn shutdown(mut self) {
        self.cancel.cancel();
        if let Some(http) = self.http.take() {
            let _ = tokio::time::timeout(Duration::from_secs(3), http).await;
        }
        if let Some(hub) = self.hub.take() {
            let _ = tokio::time::timeout(Duration::from_secs(3), hub).await;
        }
    }
}
