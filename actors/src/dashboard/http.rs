//! The HTTP side of the dashboard endpoint: the page and its assets, `/healthz`, `/metrics`, and the `/ws`
//! handshake (origin, token and client-count checks before the upgrade).
//!
//! The page, its script and its style sheet are compiled into the binary. uPlot is not: it is an npm
//! dependency, served from `<web dir>/node_modules/uplot/dist/` at run time; when it is missing the
//! server answers 503 with the command that installs it, and the page says the same.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::DashboardStats;
use super::auth::{AccessPolicy, presented_token};
use super::hub::{HubCounters, HubHandle};
use super::messages::{Hello, Limits, Signals};
use super::protocol::SUBPROTOCOL;
use super::rate::RateLimit;
use super::session::{Session, SessionCounters};
use crate::command::ControlRequest;
use crate::telemetry::Health;
use crate::telemetry::prometheus::MetricsSnapshot;

const INDEX_HTML: &str = include_str!("../../../web/index.html");
const APP_JS: &str = include_str!("../../../web/app.js");
const LIB_JS: &str = include_str!("../../../web/lib.js");
const ELBOW_JS: &str = include_str!("../../../web/elbow.js");
const STYLE_CSS: &str = include_str!("../../../web/style.css");

/// The files of the uPlot package the page loads, relative to the web directory.
pub(crate) const UPLOT_DIST: &str = "node_modules/uplot/dist";
/// What to run when uPlot is missing.
pub(crate) const INSTALL_HINT: &str =
    "run `npm ci --prefix web` in the repository, then restart the server";

const CSP: &str = "default-src 'self'; connect-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; \
frame-ancestors 'none'; base-uri 'none'; form-action 'none'";

/// Shared by every request.
pub(crate) struct AppState {
    /// Origin and token rules.
    pub(crate) policy: AccessPolicy,
    /// Telemetry source.
    pub(crate) hub: HubHandle,
    /// The server's command inbox.
    pub(crate) commands: mpsc::Sender<ControlRequest>,
    /// The tick period, ms.
    pub(crate) tick_period_ms: u64,
    /// Announced signals.
    pub(crate) signals: Signals,
    /// The configuration in force, token redacted.
    pub(crate) config: serde_json::Value,
    /// Message size cap, bytes.
    pub(crate) max_message_bytes: usize,
    /// Per-client telemetry queue.
    pub(crate) client_queue: usize,
    /// Most clients at once.
    pub(crate) max_clients: usize,
    /// Each connection's message rate limit.
    pub(crate) rate: RateLimit,
    /// The server's health figures (for `/metrics`).
    pub(crate) health: Health,
    /// Where `node_modules/uplot` lives.
    pub(crate) web_dir: PathBuf,
    /// Connected clients (shared with the hub's status).
    pub(crate) hub_counters: Arc<HubCounters>,
    /// Session counters.
    pub(crate) session_counters: Arc<SessionCounters>,
    /// What the TCP guard refused.
    pub(crate) guard_counters: Arc<super::guard::GuardCounters>,
    /// Handshakes accepted.
    pub(crate) connections: AtomicU64,
    /// Handshakes refused (origin, token, too many clients).
    pub(crate) rejected: AtomicU64,
    /// Fires on shut-down.
    pub(crate) cancel: CancellationToken,
}

impl AppState {
    /// The endpoint's counters now.
    pub(crate) fn stats(&self) -> DashboardStats {
        let c = &self.session_counters;
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        DashboardStats {
            clients: self.hub_counters.clients.load(Ordering::Relaxed),
            connections: load(&self.connections),
            rejected: load(&self.rejected),
            telemetry_dropped: load(&c.telemetry_dropped),
            commands: load(&c.commands),
            errors: load(&c.errors),
            rate_limited: load(&c.rate_limited),
            closed_oversize: load(&c.closed_oversize),
            closed_unread: load(&c.closed_unread),
            closed_write_stall: load(&c.closed_write_stall),
            records_missed: load(&self.hub_counters.records_missed),
            tcp_refused: load(&self.guard_counters.refused),
            closed_no_upgrade: load(&self.guard_counters.timed_out),
        }
    }

    /// Everything `/metrics` reports, now.
    pub(crate) fn metrics(&self) -> MetricsSnapshot {
        MetricsSnapshot::read(&self.health, self.stats())
    }
}

/// `200 ok` while the tick loop runs and the robot link is up; `503` with the reason otherwise.
async fn healthz(State(state): State<Arc<AppState>>) -> Response {
    let verdict = state.health.verdict();
    let status = match verdict {
        crate::telemetry::Verdict::Ok => StatusCode::OK,
        _ => StatusCode::SERVICE_UNAVAILABLE,
    };
    let mut r = (status, verdict.describe()).into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    let text = crate::telemetry::prometheus::render(&state.metrics());
    let mut r = text.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(crate::telemetry::prometheus::CONTENT_TYPE),
    );
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// The router of the endpoint.
pub(crate) fn router(state: Arc<AppState>) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { asset("text/html; charset=utf-8", INDEX_HTML) }),
        )
        .route(
            "/app.js",
            get(|| async { asset("text/javascript; charset=utf-8", APP_JS) }),
        )
        .route(
            "/lib.js",
            get(|| async { asset("text/javascript; charset=utf-8", LIB_JS) }),
        )
        .route(
            "/elbow.js",
            get(|| async { asset("text/javascript; charset=utf-8", ELBOW_JS) }),
        )
        .route(
            "/style.css",
            get(|| async { asset("text/css; charset=utf-8", STYLE_CSS) }),
        )
        .route("/vendor/uplot.iife.min.js", get(uplot_js))
        .route("/vendor/uplot.min.css", get(uplot_css))
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/ws", get(ws_handler))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .with_state(state)
}

fn asset(content_type: &'static str, body: impl IntoResponse) -> Response {
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    r
}

/// Whether uPlot's files are where the server serves them from.
pub(crate) fn uplot_installed(web_dir: &std::path::Path) -> bool {
    web_dir.join(UPLOT_DIST).join("uPlot.iife.min.js").is_file()
}

async fn vendor(state: &AppState, file: &str, content_type: &'static str) -> Response {
    let path = state.web_dir.join(UPLOT_DIST).join(file);
    match tokio::fs::read(&path).await {
        Ok(bytes) => asset(content_type, bytes),
        Err(e) => {
            tracing::error!("cannot serve {}: {e}; {INSTALL_HINT}", path.display());
            (
                StatusCode::SERVICE_UNAVAILABLE,
                format!(
                    "uPlot is not installed ({}: {e}): {INSTALL_HINT}\n",
                    path.display()
                ),
            )
                .into_response()
        }
    }
}

async fn uplot_js(State(state): State<Arc<AppState>>) -> Response {
    vendor(
        &state,
        "uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
    )
    .await
}

async fn uplot_css(State(state): State<Arc<AppState>>) -> Response {
    vendor(&state, "uPlot.min.css", "text/css; charset=utf-8").await
}

/// Query parameters of `/ws`.
#[derive(Debug, Deserialize)]
pub(crate) struct WsQuery {
    /// The access token (alternatively sent as the subprotocol `token.<token>`).
    pub(crate) token: Option<String>,
}

/// Frees a client slot when the connection ends (or never starts).
struct ClientSlot(Arc<AppState>);

impl Drop for ClientSlot {
    fn drop(&mut self) {
        self.0.hub_counters.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

fn refuse(state: &AppState, status: StatusCode, why: String) -> Response {
    let n = state.rejected.fetch_add(1, Ordering::Relaxed) + 1;
    if super::session::worth_logging(n) {
        tracing::info!(%status, total = n, "websocket handshake refused: {why}");
    }
    (status, format!("{why}\n")).into_response()
}

async fn ws_handler(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    Query(query): Query<WsQuery>,
    ws: WebSocketUpgrade,
) -> Response {
    let origin = match headers.get(header::ORIGIN).map(|v| v.to_str()) {
        None => None,
        Some(Ok(o)) => Some(o),
        Some(Err(_)) => {
            return refuse(
                &state,
                StatusCode::FORBIDDEN,
                "the Origin header is not text".into(),
            );
        }
    };
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
    if let Err(denied) = state.policy.check_origin(origin, host) {
        return refuse(&state, StatusCode::FORBIDDEN, denied.to_string());
    }
    let query_token = query.token.as_deref();
    let access = {
        let protocols: Vec<&str> = ws
            .requested_protocols()
            .filter_map(|v| v.to_str().ok())
            .collect();
        state
            .policy
            .check_token(presented_token(query_token, protocols))
    };
    let access = match access {
        Ok(a) => a,
        Err(denied) => return refuse(&state, StatusCode::UNAUTHORIZED, denied.to_string()),
    };
    let before = state.hub_counters.clients.fetch_add(1, Ordering::Relaxed);
    let slot = ClientSlot(state.clone());
    if before >= state.max_clients {
        drop(slot);
        return refuse(
            &state,
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "too many websocket clients (the limit is {})",
                state.max_clients
            ),
        );
    }
    state.connections.fetch_add(1, Ordering::Relaxed);
    let hello = Hello::new(
        state.tick_period_ms,
        access == super::auth::Access::Command,
        state.signals.clone(),
        Limits {
            max_message_bytes: state.max_message_bytes,
            client_queue: state.client_queue,
            rate: state.rate,
        },
        state.config.clone(),
    )
    .to_json();
    let session = Session {
        hub: state.hub.clone(),
        commands: state.commands.clone(),
        access,
        hello,
        queue: state.client_queue,
        tick_hz: 1000.0 / state.tick_period_ms.max(1) as f64,
        rate: state.rate,
        counters: state.session_counters.clone(),
        cancel: state.cancel.clone(),
    };
    ws.protocols([SUBPROTOCOL])
        .max_message_size(state.max_message_bytes)
        .max_frame_size(state.max_message_bytes)
        .on_upgrade(move |socket| async move {
            let _slot = slot;
            session.run(socket).await;
        })
}
