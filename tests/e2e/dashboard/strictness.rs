//! What the server refuses to guess and what it keeps to itself: a message with a key given twice is
//! refused (it never latches the e-stop by its last value), a connection that breaks the websocket
//! protocol is closed with the code RFC 6455 gives (1007 for text that is not UTF-8, 1002 for reserved
//! bits or an unmasked client frame), and a watcher's `hello` carries none of the configuration's
//! secrets or paths. The protocol violations are sent as raw bytes over TCP, since no websocket client
//! library will produce them.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use super::rig::{Lab, TOKEN, WAIT, command, loopback, next_json, ws_from};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_key_given_twice_is_refused_and_never_latches_the_estop() {
    let lab = Lab::start(|_| {}).await;
    let (mut op, _) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    let cases = [
        (r#"{"id":1,"cmd":"ping","cmd":"estop"}"#, r#""cmd""#),
        (r#"{"id":2,"cmd":"estop","cmd":"ping"}"#, r#""cmd""#),
        (
            r#"{"id":3,"cmd":"set_params","alpha":0.1,"alpha":0.9}"#,
            r#""alpha""#,
        ),
        (r#"{"id":4,"cmd":"estop","x":{"a":1,"a":2}}"#, r#""a" in x"#),
    ];
    for (i, (text, named)) in cases.iter().enumerate() {
        send_text(&mut op, text).await;
        let reply = super::rig::reply_to(&mut op, i as u64 + 1).await;
        assert_eq!(reply["type"], "error", "{text} → {reply}");
        assert_eq!(reply["code"], "duplicate_key", "{text} → {reply}");
        let message = reply["message"].as_str().unwrap();
        assert!(message.contains(named), "{text} → {message}");
    }
    // Nothing was latched: the next ticks still drive, and the e-stop was never on.
    let mut seen = 0;
    while seen < 25 {
        let t = next_json(&mut op).await;
        if t["type"] == "tick" {
            assert_eq!(t["estop"], false, "{t}");
            seen += 1;
        }
    }
    // The connection stays open and a well-formed e-stop still works.
    let ack = command(&mut op, json!({"cmd": "estop"}), 9).await;
    assert_eq!(ack["result"]["estop"], true, "{ack}");
    assert!(lab.dash.stats().commands == 1);
    lab.stop().await;
}

async fn send_text(ws: &mut super::rig::Ws, text: &str) {
    use futures_util::SinkExt;
    ws.send(tokio_tungstenite::tungstenite::Message::text(text))
        .await
        .unwrap();
}

/// A websocket connection made by hand: the handshake, then raw frames.
async fn raw_websocket(addr: SocketAddr) -> TcpStream {
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!(
            "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
             Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    let mut head = Vec::new();
    while !head.ends_with(b"\r\n\r\n") {
        let mut byte = [0u8; 1];
        let n = tokio::time::timeout(WAIT, s.read(&mut byte))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(n, 1, "the server closed during the handshake");
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    s
}

/// One frame: `first` is the FIN/RSV/opcode byte; masked with a fixed key when `masked`.
fn frame(first: u8, payload: &[u8], masked: bool) -> Vec<u8> {
    assert!(payload.len() < 126);
    let mut f = vec![first, payload.len() as u8 | if masked { 0x80 } else { 0 }];
    if masked {
        let key = [0x12, 0x34, 0x56, 0x78];
        f.extend_from_slice(&key);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ key[i % 4]));
    } else {
        f.extend_from_slice(payload);
    }
    f
}

/// Reads the server's frames until its close frame: its code (`None` if the connection ended without one).
async fn close_code(s: &mut TcpStream) -> Option<u16> {
    let deadline = Instant::now() + WAIT;
    loop {
        assert!(Instant::now() < deadline, "no close within {WAIT:?}");
        let mut head = [0u8; 2];
        s.read_exact(&mut head).await.ok()?;
        let len = match head[1] & 0x7f {
            126 => {
                let mut l = [0u8; 2];
                s.read_exact(&mut l).await.ok()?;
                u64::from(u16::from_be_bytes(l))
            }
            127 => {
                let mut l = [0u8; 8];
                s.read_exact(&mut l).await.ok()?;
                u64::from_be_bytes(l)
            }
            n => u64::from(n),
        };
        assert_eq!(head[1] & 0x80, 0, "server frames are never masked");
        let mut payload = vec![0u8; len as usize];
        s.read_exact(&mut payload).await.ok()?;
        if head[0] & 0x0f == 0x8 {
            return payload.get(..2).map(|c| u16::from_be_bytes([c[0], c[1]]));
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protocol_violations_close_with_the_codes_rfc_6455_gives() {
    let lab = Lab::start(|_| {}).await;
    let cases: [(&str, Vec<u8>, u16); 4] = [
        (
            "text that is not UTF-8",
            frame(0x81, &[0xff, 0xfe, 0x7b], true),
            1007,
        ),
        (
            "UTF-8 cut in the middle of a character",
            frame(
                0x81,
                "{\"cmd\":\"é".as_bytes().split_last().unwrap().1,
                true,
            ),
            1007,
        ),
        (
            "a reserved bit set",
            frame(0x81 | 0x40, br#"{"cmd":"ping"}"#, true),
            1002,
        ),
        (
            "an unmasked client frame",
            frame(0x81, br#"{"cmd":"ping"}"#, false),
            1002,
        ),
    ];
    for (what, bytes, code) in &cases {
        let mut s = raw_websocket(lab.addr()).await;
        s.write_all(bytes).await.unwrap();
        assert_eq!(close_code(&mut s).await, Some(*code), "{what}");
    }
    // A well-formed frame by hand is answered as usual.
    let mut s = raw_websocket(lab.addr()).await;
    s.write_all(&frame(0x81, br#"{"cmd":"ping","id":7}"#, true))
        .await
        .unwrap();
    let mut got = Vec::new();
    let deadline = Instant::now() + WAIT;
    while !String::from_utf8_lossy(&got).contains(r#""type":"ack","id":7"#) {
        assert!(Instant::now() < deadline, "no ack");
        let mut buf = [0u8; 4096];
        let n = s.read(&mut buf).await.unwrap();
        assert!(n > 0, "closed");
        got.extend_from_slice(&buf[..n]);
    }
    let stats = lab.dash.stats();
    assert_eq!(
        (stats.closed_invalid_utf8, stats.closed_protocol),
        (2, 2),
        "{stats:?}"
    );
    lab.stop().await;
}

fn keys(v: &Value) -> Vec<&str> {
    v.as_object().unwrap().keys().map(String::as_str).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watchers_hello_shows_what_the_page_draws_and_nothing_else() {
    let secret_dir = "/srv/lab/private-weights";
    let lab = Lab::start(|c| {
        c.checkpoint.dir = secret_dir.into();
        c.sim.seed = 424242;
    })
    .await;
    let (_watcher, hello) = ws_from(loopback(1), lab.addr(), None).await.unwrap();
    assert_eq!(hello["can_command"], false);
    let config = &hello["config"];
    assert_eq!(keys(config), ["control", "predictions", "robot", "tick"]);
    assert_eq!(config["robot"], json!({"model": "create1"}));
    assert_eq!(config["tick"], json!({"period_ms": 20}));
    assert_eq!(config["control"]["mode"], "pavlovian");
    assert_eq!(config["control"]["stimulus"]["kind"], "stall");
    assert_eq!(
        config["predictions"],
        json!([{"name": "stall", "threshold": 0.5}])
    );
    let text = hello.to_string();
    for hidden in [TOKEN, "redacted", secret_dir, "424242", "127.0.0.1", "bind"] {
        assert!(!text.contains(hidden), "a watcher sees {hidden}: {text}");
    }
    // What the page draws is still there.
    assert_eq!(hello["tick_period_ms"], 20);
    assert_eq!(hello["signals"]["predictions"], json!(["stall"]));
    assert!(!hello["signals"]["obs"].as_array().unwrap().is_empty());
    // An operator sees the whole configuration, its token redacted.
    let (_op, hello) = ws_from(loopback(1), lab.addr(), Some(TOKEN)).await.unwrap();
    assert_eq!(hello["config"]["checkpoint"]["dir"], secret_dir);
    assert_eq!(hello["config"]["dashboard"]["token"], "<redacted>");
    assert!(!hello.to_string().contains(TOKEN));
    tokio::time::sleep(Duration::from_millis(10)).await;
    lab.stop().await;
}
