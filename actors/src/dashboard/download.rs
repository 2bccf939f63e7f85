//! `GET /recording`: the recording being written, as a finished MCAP file any reader opens, for an
//! operator to download.
//!
//! Only an operator may have it (the token as `?token=`, checked and throttled like a websocket handshake's;
//! anyone on a server without a token, which binds loopback only): a recording holds the whole
//! configuration. `Host` and `Origin` are checked first, as for `/metrics` ([`refuse_foreign`]),
//! so a DNS-rebinding page cannot fetch it. The file is the one the recorder announced in its last
//! `recording_started` event.
//!
//! The live file has no summary or footer until its recording stops, so it is not sent as it is: a copy
//! is finished on a blocking thread ([`super::download_copy`]) with every complete chunk of the live
//! file, and sent with its `Content-Length`. The copy holds every tick up to the newest one the dashboard
//! had received when the request came (header `X-Pavlov-Through-Tick`): the recorder got that tick
//! before the dashboard did, and finishes a chunk at least once a second, so the copy waits for that
//! flush (at most [`super::download_copy::PATIENCE`]; what it holds is in `X-Pavlov-Ticks` and
//! `X-Pavlov-Last-Tick`). The recorder never waits: the copy only reads the file.
//!
//! [`AT_ONCE`] download is prepared or sent at a time (another request is answered `503` busy). The
//! response is long, so its connection is told so ([`super::guard::LongResponse`]): the deadline for
//! request heads no longer applies, and the connection ends only when the client takes no bytes for
//! [`super::guard::STALL_LIMIT`]; it closes after the response.

use std::path::Path;
use std::sync::Arc;

use axum::body::{Body, Bytes};
use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::io::AsyncReadExt;

use super::app_state::{AppState, WsQuery, check_token, refuse, refuse_foreign};
use super::auth::Access;
use super::download_copy::{PATIENCE, prepare};
use super::guard::Peer;
use super::source::Source;

/// Bytes read from the copy at a time.
const PIECE: usize = 64 * 1024;
/// Downloads prepared or sent at a time.
pub(crate) const AT_ONCE: usize = 1;
/// What a client is told to wait before trying again when a download is busy, seconds.
const RETRY_AFTER_S: u64 = 5;

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
    ConnectInfo(Peer(peer, long)): ConnectInfo<Peer>,
    headers: HeaderMap,
    Query(query): Query<WsQuery>,
) -> Response {
    if let Some(refused) = refuse_foreign(&state, &headers) {
        return refused;
    }
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
        return plain(
            StatusCode::NOT_FOUND,
            "no recording is being written\n".into(),
        );
    };
    let Ok(permit) = state.downloads.clone().try_acquire_owned() else {
        let mut r = plain(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "busy: another download of the recording is being prepared or sent ({AT_ONCE} at a time); try again when it has ended\n"
            ),
        );
        r.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(RETRY_AFTER_S));
        return r;
    };
    // From here the response may take long to make and to send.
    long.begin();
    let through = state.hub.history().snapshot().last_seq;
    let path = std::path::PathBuf::from(path);
    let live = path.clone();
    let cancel = state.cancel.clone();
    // The permit goes with the job: a client that leaves early does not free it before the job ends.
    let job = tokio::task::spawn_blocking(move || {
        let prepared = prepare(&live, through, &|| cancel.is_cancelled());
        (prepared, permit)
    });
    let (prepared, permit) = match job.await {
        Ok((Ok(prepared), permit)) => (prepared, permit),
        Ok((Err(e), _)) => {
            tracing::warn!("cannot prepare the recording's download: {e}");
            return closing(plain(
                StatusCode::SERVICE_UNAVAILABLE,
                format!("the recording cannot be read now: {e}\n"),
            ));
        }
        Err(e) => {
            tracing::error!("the recording's download failed: {e}");
            return closing(plain(
                StatusCode::INTERNAL_SERVER_ERROR,
                "the download failed; see the server's log\n".into(),
            ));
        }
    };
    let copied = &prepared.copied;
    if !copied.reached {
        tracing::warn!(
            last_tick = ?copied.last_tick,
            through = ?through,
            "the recording's download holds the ticks on disk after {} s, not every tick made before it was asked for (is the recorder behind?)",
            PATIENCE.as_secs()
        );
    }
    let len = prepared.len;
    let (ticks, last_tick) = (copied.ticks, copied.last_tick);
    let file = tokio::fs::File::from_std(prepared.file);
    let pieces =
        futures_util::stream::unfold((file.take(len), permit), |(mut file, permit)| async move {
            let mut buf = vec![0u8; PIECE];
            match file.read(&mut buf).await {
                Ok(0) => None,
                Ok(n) => {
                    buf.truncate(n);
                    Some((Ok::<_, std::io::Error>(Bytes::from(buf)), (file, permit)))
                }
                Err(e) => Some((Err(e), (file, permit))),
            }
        });
    let mut r = closing(Body::from_stream(pieces).into_response());
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
    h.insert("x-pavlov-ticks", HeaderValue::from(ticks));
    if let Some(last) = last_tick {
        h.insert("x-pavlov-last-tick", HeaderValue::from(last));
    }
    if let Some(through) = through {
        h.insert("x-pavlov-through-tick", HeaderValue::from(through));
    }
    r
}

/// `response`, closing its connection after it (a long response's connection is not reused).
fn closing(mut response: Response) -> Response {
    response
        .headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}

fn plain(status: StatusCode, text: String) -> Response {
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
