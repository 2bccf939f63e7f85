//! The fleet page's HTTP side: `/` (web/fleet.html), `/fleet.js`, `/api/robots` (the table as JSON) and
//! `POST /api/command/<robot>`, which forwards its body (`{"token": …, "command": {…}}`) as a Zenoh query
//! to `pavlov/v1/<robot>/command` and answers with the robot's reply: 200 with `{"ok": true, …}`, 403 for a
//! refusal of the token or of commands being off, 400 for another refusal, 504 when no robot answered.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Router;
use axum::body::Bytes;
use axum::extract::Path;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use tokio_util::sync::CancellationToken;

use super::table::RobotTable;
use crate::zenoh_bridge::key;

/// How long the fleet waits for a robot's answer to a command.
pub(crate) const COMMAND_TIMEOUT: Duration = Duration::from_secs(3);
/// The largest command body, bytes.
const MAX_BODY: usize = 4096;

const PAGE: &str = include_str!("../../../web/fleet.html");
const SCRIPT: &str = include_str!("../../../web/fleet.js");

/// What the handlers share.
#[derive(Clone)]
pub(crate) struct State {
    /// The robots.
    pub(crate) table: Arc<Mutex<RobotTable>>,
    /// The fleet's Zenoh session.
    pub(crate) session: zenoh::Session,
}

fn json(status: StatusCode, body: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn robots(state: State) -> Response {
    let body = state.table.lock().map_or_else(
        |_| "{}".to_string(),
        |t| t.to_json(super::now_ms()).to_string(),
    );
    json(StatusCode::OK, body)
}

/// Forwards a command to `robot` and relays its answer.
pub(crate) async fn forward(
    session: &zenoh::Session,
    robot: &str,
    body: &[u8],
) -> (StatusCode, String) {
    let refuse = |status, code: &str, message: String| {
        (
            status,
            serde_json::json!({ "ok": false, "error": code, "message": message }).to_string(),
        )
    };
    if let Err(why) = pavlov::config::check_robot_name(robot) {
        return refuse(
            StatusCode::BAD_REQUEST,
            "robot",
            format!("robot name: {why}"),
        );
    }
    if body.len() > MAX_BODY {
        return refuse(
            StatusCode::PAYLOAD_TOO_LARGE,
            "invalid",
            format!("the body is {} bytes, more than {MAX_BODY}", body.len()),
        );
    }
    let k = key(robot, "command");
    let replies = match session
        .get(k.clone())
        .payload(body.to_vec())
        .timeout(COMMAND_TIMEOUT)
        .await
    {
        Ok(r) => r,
        Err(e) => return refuse(StatusCode::BAD_GATEWAY, "zenoh", format!("query {k}: {e}")),
    };
    match replies.recv_async().await {
        Ok(reply) => match reply.result() {
            Ok(sample) => (
                StatusCode::OK,
                String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned(),
            ),
            Err(err) => {
                let text = String::from_utf8_lossy(&err.payload().to_bytes()).into_owned();
                let code = serde_json::from_str::<serde_json::Value>(&text)
                    .ok()
                    .and_then(|v| v["error"].as_str().map(str::to_string));
                let status = match code.as_deref() {
                    Some("token") | Some("off") => StatusCode::FORBIDDEN,
                    _ => StatusCode::BAD_REQUEST,
                };
                (status, text)
            }
        },
        Err(_) => refuse(
            StatusCode::GATEWAY_TIMEOUT,
            "no_answer",
            format!("no robot answered on {k} within {COMMAND_TIMEOUT:?}"),
        ),
    }
}

/// Serves the page until `cancel`.
pub(crate) async fn serve(
    listener: tokio::net::TcpListener,
    state: State,
    cancel: CancellationToken,
) {
    let s1 = state.clone();
    let s2 = state;
    let app = Router::new()
        .route(
            "/",
            get(|| async { ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE) }),
        )
        .route(
            "/fleet.js",
            get(|| async { ([(header::CONTENT_TYPE, "text/javascript")], SCRIPT) }),
        )
        .route("/api/robots", get(move || robots(s1.clone())))
        .route(
            "/api/command/{robot}",
            post(move |Path(robot): Path<String>, body: Bytes| {
                let s = s2.clone();
                async move {
                    let (status, text) = forward(&s.session, &robot, &body).await;
                    json(status, text)
                }
            }),
        );
    let served = axum::serve(listener, app).with_graceful_shutdown(async move {
        cancel.cancelled().await;
    });
    if let Err(e) = served.await {
        tracing::warn!("fleet page: {e}");
    }
}
