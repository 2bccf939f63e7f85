//! What every request of the endpoint shares: the state ([`AppState`]: the access policy, the hub, the
//! seats, the counters), and the refusals and checks that the routes (`http.rs`, `download.rs`) make
//! alike: counting a refusal, refusing a foreign host or origin, checking a token against the wrong-token
//! allowance.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::DashboardStats;
use super::admission::Admission;
use super::auth::{Access, AccessPolicy, Denied};
use super::guard::SharedPool;
use super::hub::{HubCounters, HubHandle};
use super::messages::{HelloRun, Signals};
use super::rate::RateLimit;
use super::session::SessionCounters;
use super::source::Source;
use super::token_throttle::{FAILURE_REFILL, TokenThrottle};
use crate::command::ControlRequest;
use crate::telemetry::Health;
use crate::telemetry::prometheus::MetricsSnapshot;

/// Shared by every request.
pub(crate) struct AppState {
    /// Origin and token rules.
    pub(crate) policy: AccessPolicy,
    /// Telemetry source.
    pub(crate) hub: HubHandle,
    /// The server's command inbox.
    pub(crate) commands: mpsc::Sender<ControlRequest>,
    /// The e-stop latch, which an operator's connection sets ahead of its own earlier commands.
    pub(crate) estop: crate::pipeline::latch::EstopLatch,
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
    /// Where the page's files come from.
    pub(crate) assets: super::assets::WebAssets,
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
            closed_refusals_piled: load(&c.closed_refusals_piled),
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
pub(crate) fn header_text(
    headers: &HeaderMap,
    name: header::HeaderName,
) -> Result<Option<&str>, String> {
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

/// Checks the token presented by a client from `source`, always, in constant time: the right token is
/// admitted whatever else its address has sent, so a guesser sharing the operator's address (every local
/// client on a loopback server) cannot lock the operator out. Only failures are throttled: a wrong token is
/// 401 (and one allowance less) while its address has allowance left, 429 once it has used it up. The error
/// is the refusal's status and reason.
pub(crate) fn check_token(
    state: &AppState,
    presented: Option<&str>,
    source: Source,
) -> Result<Access, (StatusCode, String)> {
    let denied = match state.policy.check_token(presented) {
        Ok(access) => return Ok(access),
        Err(denied) => denied,
    };
    if denied != Denied::WrongToken {
        return Err((StatusCode::UNAUTHORIZED, denied.to_string()));
    }
    let now = std::time::Instant::now();
    let mut throttle = state
        .throttle
        .lock()
        .unwrap_or_else(PoisonError::into_inner);
    if !throttle.allows(source, now) {
        state.token_throttled.fetch_add(1, Ordering::Relaxed);
        return Err((
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "too many wrong tokens from {source}: one more wrong try is answered every {} s",
                FAILURE_REFILL.as_secs().max(1)
            ),
        ));
    }
    throttle.failed(source, now);
    state.token_failures.fetch_add(1, Ordering::Relaxed);
    Err((StatusCode::UNAUTHORIZED, denied.to_string()))
}
