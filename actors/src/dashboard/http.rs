//! The HTTP side of the dashboard endpoint: the page and its assets, `/healthz`, `/metrics`, `/recording`
//! ([`super::download`]), and the `/ws` handshake: the origin, then the wrong-token throttle (429), the
//! token (401), then a seat as operator or watcher (503), all before the upgrade. `/metrics` and
//! `/recording` check `Host` and `Origin` first ([`refuse_foreign`]: 403, counted as a refusal).
//!
//! The page, its script and its style sheet are compiled into the binary. uPlot is not: it is an npm
//! dependency, served from `<web dir>/node_modules/uplot/dist/` at run time; when it is missing the
//! server answers 503 with the command that installs it, and the page says the same.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::DashboardStats;
use super::admission::Admission;
use super::auth::{Access, AccessPolicy, Denied, presented_token};
use super::guard::{Peer, SharedPool};
use super::hub::{HubCounters, HubHandle};
use super::messages::{Hello, HelloRun, Limits, Signals};
use super::protocol::SUBPROTOCOL;
use super::rate::RateLimit;
use super::session::{Session, SessionCounters};
use super::source::Source;
use super::token_throttle::{FAILURE_REFILL, TokenThrottle};
use crate::command::ControlRequest;
use crate::telemetry::Health;
use crate::telemetry::prometheus::MetricsSnapshot;

const INDEX_HTML: &str = include_str!("../../../web/index.html");
const STYLE_CSS: &str = include_str!("../../../web/style.css");
/// The page's modules, by path.
const SCRIPTS: [(&str, &str); 9] = [
    ("/app.js", include_str!("../../../web/app.js")),
    ("/lib.js", include_str!("../../../web/lib.js")),
    ("/timeline.js", include_str!("../../../web/timeline.js")),
    ("/charts.js", include_str!("../../../web/charts.js")),
    ("/controls.js", include_str!("../../../web/controls.js")),
    ("/panels.js", include_str!("../../../web/panels.js")),
    ("/elbow.js", include_str!("../../../web/elbow.js")),
    ("/learning.js", include_str!("../../../web/learning.js")),
    ("/learnlib.js", include_str!("../../../web/learnlib.js")),
];

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
    /// The configuration an operator's `hello` carries (all of it, token redacted).
    pub(crate) operator_config: serde_json::Value,
    /// The configuration a watcher's `hello` carries (what the page draws).
    pub(crate) watcher_config: serde_json::Value,
    /// What every `hello` says of this run (its id, the robot, the history's length).
    pub(crate) hello_run: HelloRun,
    /// Message size cap, bytes.
    pub(crate) max_message_bytes: usize,
    /// Per-client telemetry queue.
    pub(crate) client_queue: usize,
    /// The operator and watcher seats.
    pub(crate) admission: Arc<Admission>,
    /// Each source's wrong-token allowance.
    pub(crate) throttle: Mutex<TokenThrottle>,
    /// The connections that are not (yet) websockets.
    pub(crate) pending: SharedPool,
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
    /// Handshakes refused (origin, token, throttled, no seat).
    pub(crate) rejected: AtomicU64,
    /// Handshakes that presented a wrong token.
    pub(crate) token_failures: AtomicU64,
    /// Handshakes answered 429 because their source had no wrong-token allowance left.
    pub(crate) token_throttled: AtomicU64,
    /// Fires on shut-down.
    pub(crate) cancel: CancellationToken,
    /// The Horde's names and values for the clients that watch it (`None`: no `[horde]`).
    pub(crate) horde: Option<Arc<super::horde_feed::HordeFeed>>,
    /// Downloads of the recording being prepared or sent: [`super::download::AT_ONCE`] permits.
    pub(crate) downloads: Arc<tokio::sync::Semaphore>,
}

impl AppState {
    /// The endpoint's counters now.
    pub(crate) fn stats(&self) -> DashboardStats {
        let c = &self.session_counters;
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let (_, watchers) = self.admission.held();
        let pending = self
            .pending
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len();
        let (history_ticks, history_bytes) = self.hub.history().footprint();
        DashboardStats {
            history_ticks,
            history_bytes,
            clients: self.hub_counters.clients.load(Ordering::Relaxed),
            watchers,
            pending,
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
            closed_protocol: load(&c.closed_protocol),
            closed_invalid_utf8: load(&c.closed_invalid_utf8),
            tcp_refused: load(&self.guard_counters.refused),
            closed_evicted: load(&self.guard_counters.evicted),
            closed_no_upgrade: load(&self.guard_counters.timed_out),
            token_failures: load(&self.token_failures),
            token_throttled: load(&self.token_throttled),
            horde_values: self
                .horde
                .as_ref()
                .map_or(0, |h| load(&h.counters.frames_sent)),
            horde_values_skipped: self
                .horde
                .as_ref()
                .map_or(0, |h| load(&h.counters.frames_skipped)),
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

async fn metrics(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Response {
    if let Some(refused) = refuse_foreign(&state, &headers) {
        return refused;
    }
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
    let mut router = Router::new();
    for (path, text) in SCRIPTS {
        router = router.route(
            path,
            get(move || async move { asset("text/javascript; charset=utf-8", text) }),
        );
    }
    router
        .route(
            "/",
            get(|| async { asset("text/html; charset=utf-8", INDEX_HTML) }),
        )
        .route(
            "/style.css",
            get(|| async { asset("text/css; charset=utf-8", STYLE_CSS) }),
        )
        .route("/vendor/uplot.iife.min.js", get(uplot_js))
        .route("/vendor/uplot.min.css", get(uplot_css))
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/recording", get(super::download::recording))
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

/// Refuses a request (a handshake, a download, `/metrics`) with `status` and `why`, and counts it.
pub(crate) fn refuse(state: &AppState, status: StatusCode, why: String) -> Response {
    let n = state.rejected.fetch_add(1, Ordering::Relaxed) + 1;
    if super::session::worth_logging(n) {
        tracing::info!(%status, total = n, "dashboard request refused: {why}");
    }
    let mut r = (status, format!("{why}\n")).into_response();
    if status == StatusCode::TOO_MANY_REQUESTS {
        r.headers_mut().insert(
            header::RETRY_AFTER,
            HeaderValue::from(FAILURE_REFILL.as_secs().max(1)),
        );
    }
    r
}

/// A header as text (`None`: absent); the error names a header that is not text.
fn header_text(headers: &HeaderMap, name: header::HeaderName) -> Result<Option<&str>, String> {
    match headers.get(&name).map(|v| v.to_str()) {
        None => Ok(None),
        Some(Ok(v)) => Ok(Some(v)),
        Some(Err(_)) => Err(format!("the {name} header is not text")),
    }
}

/// For the routes a page could fetch without a handshake (`/metrics`, `/recording`): `Host` must be a
/// name of this server and `Origin`, when present, allowed, as in the websocket's handshake
/// ([`AccessPolicy::check_host`], [`AccessPolicy::check_origin`]). `Some` is the 403 refusal, counted.
pub(crate) fn refuse_foreign(state: &AppState, headers: &HeaderMap) -> Option<Response> {
    let checked = header_text(headers, header::HOST).and_then(|host| {
        let origin = header_text(headers, header::ORIGIN)?;
        state
            .policy
            .check_host(host)
            .and_then(|()| state.policy.check_origin(origin, host))
            .map_err(|denied| denied.to_string())
    });
    checked
        .err()
        .map(|why| refuse(state, StatusCode::FORBIDDEN, why))
}

/// Checks the token presented by a client from `source`: 429 without looking at it when the source has
/// used up its wrong-token allowance, 401 (and one allowance less) when it is wrong. The error is the
/// refusal's status and reason.
pub(crate) fn check_token(
    state: &AppState,
    presented: Option<&str>,
    source: Source,
) -> Result<Access, (StatusCode, String)> {
    let now = std::time::Instant::now();
    let guessing = presented.is_some() && state.policy.token_required();
    if guessing
        && !state
            .throttle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .allows(source, now)
    {
        state.token_throttled.fetch_add(1, Ordering::Relaxed);
        return Err((
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "too many wrong tokens from {source}: one more try is allowed every {} s",
                FAILURE_REFILL.as_secs().max(1)
            ),
        ));
    }
    match state.policy.check_token(presented) {
        Ok(access) => Ok(access),
        Err(denied) => {
            if denied == Denied::WrongToken {
                state.token_failures.fetch_add(1, Ordering::Relaxed);
                state
                    .throttle
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .failed(source, now);
            }
            Err((StatusCode::UNAUTHORIZED, denied.to_string()))
        }
    }
}

async fn ws_handler(
    State(state): State<Arc<AppState>>,
    ConnectInfo(Peer(peer, _)): ConnectInfo<Peer>,
    headers: HeaderMap,
    Query(query): Query<WsQuery>,
    ws: WebSocketUpgrade,
) -> Response {
    let origin = match header_text(&headers, header::ORIGIN) {
        Ok(o) => o,
        Err(refused) => return refuse(&state, StatusCode::FORBIDDEN, refused),
    };
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
    if let Err(denied) = state.policy.check_origin(origin, host) {
        return refuse(&state, StatusCode::FORBIDDEN, denied.to_string());
    }
    let source = Source::of(peer.ip());
    let query_token = query.token.as_deref();
    let access = {
        let protocols: Vec<&str> = ws
            .requested_protocols()
            .filter_map(|v| v.to_str().ok())
            .collect();
        check_token(&state, presented_token(query_token, protocols), source)
    };
    let access = match access {
        Ok(a) => a,
        Err((status, why)) => return refuse(&state, status, why),
    };
    let seat = match state.admission.seat(access, source) {
        Ok(seat) => seat,
        Err(full) => return refuse(&state, StatusCode::SERVICE_UNAVAILABLE, full.to_string()),
    };
    state.connections.fetch_add(1, Ordering::Relaxed);
    let can_command = access == Access::Command;
    let hello = Hello::new(
        state.tick_period_ms,
        can_command,
        state.signals.clone(),
        Limits {
            max_message_bytes: state.max_message_bytes,
            client_queue: state.client_queue,
            rate: state.rate,
        },
        if can_command {
            state.operator_config.clone()
        } else {
            state.watcher_config.clone()
        },
        &state.hello_run,
    );
    let session = Session {
        peer,
        hub: state.hub.clone(),
        commands: state.commands.clone(),
        access,
        hello,
        history_message_bytes: state
            .max_message_bytes
            .min(super::history_messages::HISTORY_MESSAGE_BYTES),
        period_ms: state.tick_period_ms,
        queue: state.client_queue,
        tick_hz: 1000.0 / state.tick_period_ms.max(1) as f64,
        rate: state.rate,
        counters: state.session_counters.clone(),
        cancel: state.cancel.clone(),
        horde: state.horde.clone(),
    };
    ws.protocols([SUBPROTOCOL])
        .max_message_size(state.max_message_bytes)
        .max_frame_size(state.max_message_bytes)
        .on_upgrade(move |socket| async move {
            let _seat = seat;
            session.run(socket).await;
        })
}
