//! `pavlov serve --foxglove [ADDR]`: the tick stream, the events and the configuration, live in Foxglove.
//!
//! The endpoint speaks the Foxglove WebSocket protocol through Foxglove's own SDK (the `foxglove` crate's
//! `WebSocketServer`), so the Foxglove app (app.foxglove.dev or the desktop app, "Open connection" →
//! "Foxglove WebSocket" → `ws://127.0.0.1:8765`) can plot any signal with its panels. A client offers the
//! published protocol's subprotocol `foxglove.websocket.v1` or the SDK's `foxglove.sdk.v1` (the gate
//! translates the first for the SDK). Four JSON channels
//! with JSON Schemas:
//! - `/pavlov/ticks`: every [`TickRecord`](pavlov::record::TickRecord), as the recorder writes it, logged
//!   at the tick's scheduled time;
//! - `/pavlov/signals`: the same tick flat, observations and predictions by name, flags as 0/1;
//! - `/pavlov/events`: every [`Event`](pavlov::event::Event) (a late subscriber gets the recent ones; file
//!   paths redacted when a client may connect without the token, as the dashboard does for a watcher);
//! - `/pavlov/config`: the configuration in force (token redacted; only what a watcher may see when a
//!   client may connect without the token), the program and the observation names.
//!
//! Foxglove clients only read. The endpoint advertises no capability to publish, set parameters or call
//! services, so the SDK refuses all of those, and nothing from Foxglove reaches `server.commands()`. The
//! dashboard's token decides who may watch (`access`): checked by the `gate` on the public port before
//! the websocket upgrade. It listens on loopback unless told otherwise, and any other address needs a
//! token.
//!
//! - `access`: the token rule, on the request head;
//! - `gate`: the public socket, its limits, the token check and the splice to the SDK's loopback port;
//! - `publish`: the task that reads the feed and the events and logs them;
//! - `schema`: the channels' JSON Schemas; `signals`: the flat tick message.
//!
//! Nothing here can delay the tick: the publisher reads lossy broadcasts and counts what it misses, the
//! SDK's per-client queues drop their oldest messages, and all of it runs on a runtime of its own (one
//! worker thread, `foxglove`).

pub(crate) mod access;
pub(crate) mod gate;
pub(crate) mod publish;
pub(crate) mod schema;
pub(crate) mod signals;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use foxglove::{Context, WebSocketServer, WebSocketServerHandle};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::server::Server;
use crate::telemetry::counters::{FoxgloveCounters, FoxgloveFigures};
use access::WatchPolicy;
use gate::Gate;
use publish::{Channels, Inputs, Publisher, RunClock};
pub use publish::{TOPIC_CONFIG, TOPIC_EVENTS, TOPIC_SIGNALS, TOPIC_TICKS};

/// Where `--foxglove` listens when no address is given (Foxglove's usual port, loopback).
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// Messages each client's queue in the SDK holds before it drops the oldest (about 10 s of ticks on two
/// channels).
const CLIENT_BACKLOG: usize = 1024;

/// Errors starting the endpoint.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveError {
    /// The address does not parse.
    #[error("--foxglove {0}: not an address like 127.0.0.1:8765")]
    BadAddress(String),
    /// A non-loopback address without a token, or with one shorter than the dashboard requires.
    #[error(
        "--foxglove {0}: listening on an address that is not loopback requires a strong token (at \
         least {min} characters and {bits} bits of variety; --token or [dashboard] token); clients then \
         connect to ws://HOST:PORT/?token=…",
        min = pavlov::config::MIN_PUBLIC_TOKEN_CHARS,
        bits = pavlov::config::MIN_PUBLIC_TOKEN_BITS
    )]
    TokenRequired(String),
    /// The address could not be bound.
    #[error("cannot listen on {addr} for Foxglove: {source}{}", bind_hint(source))]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// The endpoint's runtime could not be created.
    #[error("cannot start the Foxglove endpoint's runtime: {0}")]
    Runtime(std::io::Error),
    /// The SDK's server did not start.
    #[error("the Foxglove server did not start: {0}")]
    Sdk(String),
}

fn bind_hint(source: &std::io::Error) -> &'static str {
    match source.kind() {
        std::io::ErrorKind::AddrInUse => {
            " (in use: stop the other program or pass another address, e.g. --foxglove 127.0.0.1:8766)"
        }
        _ => "",
    }
}

/// The endpoint's public socket, bound before the robot is touched.
pub struct BoundFoxglove {
    listener: std::net::TcpListener,
    addr: SocketAddr,
    policy: WatchPolicy,
}

impl BoundFoxglove {
    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }
}

/// The running endpoint (see the module's documentation).
pub struct Foxglove {
    addr: SocketAddr,
    token_required: bool,
    cancel: CancellationToken,
    sdk: Option<WebSocketServerHandle>,
    tasks: Vec<JoinHandle<()>>,
    counters: Arc<FoxgloveCounters>,
    /// The SDK context the channels and the server live in (they close when it is dropped).
    _context: Arc<Context>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl Drop for Foxglove {
    fn drop(&mut self) {
        self.cancel.cancel();
        if let Some(sdk) = self.sdk.take() {
            // Dropping the shutdown handle aborts the SDK's client tasks.
            drop(sdk.stop());
        }
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_background();
        }
    }
}

/// The configuration as `/pavlov/config` carries it: when a client without the token may connect
/// (`watchers`), the watcher's reduced configuration (what the dashboard shows a watcher); otherwise every
/// client presented the token (or none is set, on loopback), and it gets the whole configuration with
/// its secrets redacted.
fn config_message(server: &Server, watchers: bool) -> Vec<u8> {
    let config = if watchers {
        crate::dashboard::watcher_config(server.config())
    } else {
        serde_json::to_value(server.config().redacted()).unwrap_or_default()
    };
    let message = serde_json::json!({
        "program": crate::provenance::BUILD.program(),
        "config": config,
        "obs_names": server.obs_names(),
    });
    serde_json::to_vec(&message).unwrap_or_default()
}

impl Foxglove {
    /// Binds `addr` (refusing a non-loopback address when the dashboard has no token).
    pub fn bind(
        addr: &str,
        dashboard: &pavlov::config::DashboardConfig,
    ) -> Result<BoundFoxglove, FoxgloveError> {
        let parsed: SocketAddr = addr
            .parse()
            .map_err(|_| FoxgloveError::BadAddress(addr.to_string()))?;
        let policy = WatchPolicy::new(dashboard);
        let strong_token = dashboard
            .token
            .as_deref()
            .is_some_and(|t| pavlov::config::public_token_problem(t).is_none());
        let allowed = parsed.ip().is_loopback() || (policy.has_token() && strong_token);
        if !allowed {
            return Err(FoxgloveError::TokenRequired(addr.to_string()));
        }
        let bind_error = |source| FoxgloveError::Bind {
            addr: addr.to_string(),
            source,
        };
        let listener = std::net::TcpListener::bind(parsed).map_err(bind_error)?;
        listener.set_nonblocking(true).map_err(bind_error)?;
        let addr = listener.local_addr().map_err(bind_error)?;
        Ok(BoundFoxglove {
            listener,
            addr,
            policy,
        })
    }

    /// Starts serving `server`'s ticks, events and configuration on `bound`.
    pub async fn serve(bound: BoundFoxglove, server: &Server) -> Result<Foxglove, FoxgloveError> {
        let BoundFoxglove {
            listener,
            addr,
            policy,
        } = bound;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("foxglove")
            .enable_all()
            .build()
            .map_err(FoxgloveError::Runtime)?;
        let counters = server.health().foxglove.clone();
        let token_required = policy.token_required();
        let ctx = Context::new();
        let mut endpoint = Foxglove {
            addr,
            token_required,
            cancel: CancellationToken::new(),
            sdk: None,
            tasks: Vec::new(),
            counters: counters.clone(),
            _context: ctx.clone(),
            runtime: None,
        };
        let predictions: Vec<String> = server
            .config()
            .predictions
            .iter()
            .map(|p| p.name.clone())
            .collect();
        let channels = Channels::new(&ctx, server.obs_names(), &predictions)
            .map_err(|e| FoxgloveError::Sdk(e.to_string()))?;
        let (listener_for_sdk, subscribed) = publish::subscribe_listener();
        // The SDK serves on a loopback port of its own, behind the gate; it starts on this runtime.
        let sdk = WebSocketServer::new()
            .name("pavlov")
            .bind("127.0.0.1", 0)
            .context(&ctx)
            .listener(listener_for_sdk)
            .message_backlog_size(CLIENT_BACKLOG);
        let started = runtime.spawn(sdk.start()).await;
        let sdk = match started {
            Ok(Ok(handle)) => handle,
            Ok(Err(e)) => {
                runtime.shutdown_background();
                return Err(FoxgloveError::Sdk(e.to_string()));
            }
            Err(e) => {
                runtime.shutdown_background();
                return Err(FoxgloveError::Sdk(e.to_string()));
            }
        };
        let upstream = SocketAddr::from(([127, 0, 0, 1], sdk.port()));
        endpoint.sdk = Some(sdk);
        let listener = {
            let _inside = runtime.enter();
            tokio::net::TcpListener::from_std(listener)
        };
        let listener = match listener {
            Ok(l) => l,
            Err(source) => {
                endpoint.runtime = Some(runtime);
                return Err(FoxgloveError::Bind {
                    addr: addr.to_string(),
                    source,
                });
            }
        };
        // A client may connect without the token: what every client gets is what a watcher may see.
        let watchers = policy.has_token() && !policy.token_required();
        let gate = Arc::new(Gate {
            policy,
            upstream,
            counters: counters.clone(),
            seats: Default::default(),
        });
        endpoint
            .tasks
            .push(runtime.spawn(gate::run(listener, gate, endpoint.cancel.clone())));
        let publisher = Publisher::new(
            channels,
            RunClock::new(server.started(), server.config().tick.period_ms),
            server.obs_names().to_vec(),
            config_message(server, watchers),
            watchers,
            counters,
        );
        let inputs = Inputs {
            ticks: server.feed().subscribe(),
            events: server.events().subscribe(),
            subscribed,
        };
        endpoint
            .tasks
            .push(runtime.spawn(publisher.run(inputs, endpoint.cancel.clone())));
        endpoint.runtime = Some(runtime);
        tracing::info!(%addr, token_required, "foxglove endpoint listening");
        Ok(endpoint)
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URL to open in Foxglove (with `?token=…` to add when a token is required).
    pub fn url(&self) -> String {
        let host = match self.addr {
            a if a.ip().is_unspecified() => "127.0.0.1".to_string(),
            SocketAddr::V4(a) => a.ip().to_string(),
            SocketAddr::V6(a) => format!("[{}]", a.ip()),
        };
        format!("ws://{host}:{}", self.addr.port())
    }

    /// Whether a client must present the token to connect.
    pub fn token_required(&self) -> bool {
        self.token_required
    }

    /// The endpoint's counters now.
    pub fn stats(&self) -> FoxgloveFigures {
        self.counters.figures()
    }

    /// Closes every connection and stops listening.
    pub async fn shutdown(mut self) {
        self.cancel.cancel();
        if let Some(sdk) = self.sdk.take() {
            let _ = tokio::time::timeout(Duration::from_secs(3), sdk.stop().wait()).await;
        }
        for task in std::mem::take(&mut self.tasks) {
            let _ = tokio::time::timeout(Duration::from_secs(3), task).await;
        }
    }
}
