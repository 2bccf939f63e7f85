//! The HTTP side of the dashboard endpoint: the page and its assets, `/healthz`, `/metrics`, `/recording`
//! ([`super::download`]), and the `/ws` handshake: the origin, then the wrong-token throttle (429), the
//! token (401), then a seat as operator or watcher (503), all before the upgrade. `/metrics` and
//! `/recording` check `Host` and `Origin` first ([`refuse_foreign`]: 403, counted as a refusal).
//!
//! The page, its scripts, its style sheet and uPlot come from [`super::assets`]: built into the binary, or
//! read from `--web-dir` at each request; a file missing from that directory is answered 503 with what to
//! do (for uPlot, the command that installs it), and the page says the same.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;

use super::app_state::{AppState, WsQuery, check_token, header_text, refuse, refuse_foreign};
use super::assets::{INSTALL_HINT, Route};
use super::auth::{Access, presented_token};
use super::guard::Peer;
use super::messages::{Hello, Limits};
use super::protocol::SUBPROTOCOL;
use super::session::Session;
use super::source::Source;

const CSP: &str = "default-src 'self'; connect-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; \
frame-ancestors 'none'; base-uri 'none'; form-action 'none'";

/// `200 ok` while the tick loop runs and the robot link is up; `503` with the reason otherwise.
///
/// The probe's connection leaves the pending pool as soon as its request is read, and closes after the
/// answer, so a probe never holds a pending place as an idle keep-alive connection.
async fn healthz(
    State(state): State<Arc<AppState>>,
    ConnectInfo(Peer(_, connection)): ConnectInfo<Peer>,
) -> Response {
    connection.begin();
    let verdict = state.health.verdict();
    let status = match verdict {
        crate::telemetry::Verdict::Ok => StatusCode::OK,
        _ => StatusCode::SERVICE_UNAVAILABLE,
    };
    let mut r = (status, verdict.describe()).into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r.headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
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
pub(crate) fn router(state: Arc<AppState>) -> Router<()> {
    let mut router = Router::new();
    for route in super::assets::routes() {
        let url = route.url.clone();
        router = router.route(
            &url,
            get(
                move |State(state): State<Arc<AppState>>| async move { file(&state, &route).await },
            ),
        );
    }
    router
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/recording", get(super::download::recording))
        .route("/ws", get(ws_handler))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .with_state(state)
}

/// One of the page's files, from where the endpoint's assets come from.
async fn file(state: &AppState, route: &Route) -> Response {
    match state.assets.read(route.file).await {
        Ok(bytes) => asset(route.content_type, bytes.into_owned()),
        Err(e) => {
            let hint = if route.file.starts_with("node_modules/") {
                INSTALL_HINT
            } else {
                "point --web-dir at the repository's web/ folder, or leave it out"
            };
            tracing::error!("cannot serve {}: {e}; {hint}", route.url);
            (
                StatusCode::SERVICE_UNAVAILABLE,
                format!("{} is missing ({e}): {hint}\n", route.file),
            )
                .into_response()
        }
    }
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
        estop: state.estop.clone(),
        access,
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
        .read_buffer_size(super::socket_buffers::READ_BUFFER_BYTES)
        .write_buffer_size(super::socket_buffers::WRITE_BUFFER_BYTES)
        .on_upgrade(move |socket| async move {
            let _seat = seat;
            session.run(socket, hello).await;
        })
}
