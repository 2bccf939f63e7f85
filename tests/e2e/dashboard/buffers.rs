//! The websocket's read buffer is 4 KiB (`actors/src/dashboard/socket_buffers.rs`), far below the largest
//! message a client may send: a message of exactly `max_message_bytes` must still be read whole and
//! answered, one byte more must close the connection with 1009 and be counted as oversize, and a client
//! on another connection must not notice either.

use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

use super::rig::{Lab, TOKEN, WAIT, command, loopback, ws_from};

/// Eight times the read buffer.
const LIMIT: usize = 32 * 1024;

/// A `ping` of exactly `bytes` bytes of JSON (its padding in a field the server refuses by name, so the
/// reply shows the whole message was read and parsed).
fn ping_of(bytes: usize, id: u64) -> String {
    let head = format!(r#"{{"id":{id},"cmd":"ping","pad":""#);
    let tail = r#""}"#;
    let pad = "x".repeat(bytes - head.len() - tail.len());
    let text = format!("{head}{pad}{tail}");
    assert_eq!(text.len(), bytes);
    text
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_message_at_the_limit_is_read_whole_and_one_byte_over_is_refused_and_counted() {
    let lab = Lab::start(|c| c.dashboard.max_message_bytes = LIMIT).await;
    let addr = lab.addr();
    let (mut other, _) = ws_from(loopback(1), addr, Some(TOKEN)).await.unwrap();
    let (mut ws, _) = ws_from(loopback(1), addr, Some(TOKEN)).await.unwrap();
    let before = lab.dash.stats().closed_oversize;

    ws.send(Message::text(ping_of(LIMIT, 7))).await.unwrap();
    let reply = super::rig::reply_to(&mut ws, 7).await;
    assert_eq!(reply["id"], 7, "{reply}");
    assert!(
        reply["type"] == "error" || reply["type"] == "ack",
        "answered, not closed: {reply}"
    );
    assert_eq!(lab.dash.stats().closed_oversize, before);

    ws.send(Message::text(ping_of(LIMIT + 1, 8))).await.unwrap();
    let closed = tokio::time::timeout(WAIT, async {
        while let Some(msg) = ws.next().await {
            if let Ok(Message::Close(frame)) = msg {
                return frame.map(|f| f.code);
            }
        }
        None
    })
    .await
    .expect("closed in time");
    assert_eq!(closed, Some(CloseCode::Size));
    assert_eq!(lab.dash.stats().closed_oversize, before + 1);

    // The other connection is untouched and answers.
    let pong = command(&mut other, json!({"cmd": "ping"}), 9).await;
    assert_eq!(pong["type"], "ack", "{pong}");
    lab.stop().await;
}
