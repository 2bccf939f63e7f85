//! `GET /recording`: the recording being written, as far as it is on disk, for an operator to download.
//!
//! Only an operator may have it (the token as `?token=`, checked and throttled like a websocket handshake's;
//! anyone on a server without a token, which binds loopback only): a recording holds the whole
//! configuration. The file is the one the recorder announced in its last `recording_started` event; it is
//! opened read-only and sent up to the length it had when the request came, in pieces, so a long recording
//! costs a buffer of memory and the recorder never waits.

use std::path::Path;
use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::io::AsyncReadExt;

use super::auth::Access;
use super::guard::Peer;
use super::http::{AppState, WsQuery, check_token, refuse};
use super::source::Source;

/// Bytes read from the file at a time.
const PIECE: usize = 64 * 1024;

/// A file name for the download: the recording's folder and file, in characters any system accepts.
pub(crate) fn download_name(path: &Path) -> String {
    let part = |p: Option<&std::ffi::OsStr>| p.map(|s| s.to_string_lossy().into_owned());
    let folder = part(path.parent().and_then(Path::file_name));
    let file = part(path.file_name()).unwrap_or_else(|| "recording".into());
    let name = match folder {
        Some(folder) if !folder.is_empty() => format!("{folder}-{file}"),
        _ => file,
    };
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `GET /recording[?token=…]`.
pub(crate) async fn recording(
    State(state): State<Arc<AppState>>,
    ConnectInfo(Peer(peer)): ConnectInfo<Peer>,
    Query(query): Query<WsQuery>,
) -> Response {
    let source = Source::of(peer.ip());
    match check_token(&state, query.token.as_deref(), source) {
        Ok(Access::Command) => {}
        Ok(Access::Watch) => {
            return refuse(
                &state,
                StatusCode::FORBIDDEN,
                "only an operator may download the recording: add ?token=<token>".into(),
            );
        }
        Err((status, why)) => return refuse(&state, status, why),
    }
    let Some(path) = state.hub.history().recording() else {
        return plain(StatusCode::NOT_FOUND, "no recording is being written\n");
    };
    let path = std::path::PathBuf::from(path);
    let file = match tokio::fs::File::open(&path).await {
        Ok(f) => f,
        Err(e) => {
            tracing::warn!(path = %path.display(), "cannot open the recording for download: {e}");
            return plain(
                StatusCode::SERVICE_UNAVAILABLE,
                "the recording cannot be read now\n",
            );
        }
    };
    let len = match file.metadata().await {
        Ok(m) => m.len(),
        Err(_) => 0,
    };
    let pieces = futures_util::stream::unfold(file.take(len), |mut file| async move {
        let mut buf = vec![0u8; PIECE];
        match file.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok::<_, std::io::Error>(Bytes::from(buf)), file))
            }
            Err(e) => Some((Err(e), file)),
        }
    });
    let mut r = Body::from_stream(pieces).into_response();
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    let disposition = format!("attachment; filename=\"{}\"", download_name(&path));
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    r
}

fn plain(status: StatusCode, text: &'static str) -> Response {
    let mut r = (status, text).into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_download_is_named_after_the_recording_in_plain_characters() {
        assert_eq!(
            download_name(Path::new("recordings/run-3/ticks.jsonl")),
            "run-3-ticks.jsonl"
        );
        assert_eq!(
            download_name(Path::new("/tmp/a b\"c/x.mcap")),
            "a_b_c-x.mcap"
        );
        assert_eq!(download_name(Path::new("x.mcap")), "x.mcap");
    }
}
