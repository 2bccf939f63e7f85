//! A refused message's close frame reaches its client even while the rest of the message is still being
//! written (`actors/src/dashboard/linger.rs`). The server refuses an over-size message by its frame
//! header and closes the connection with 1009; the rest of the message is still on its way, and a socket
//! closed with bytes unread is reset: the client's write fails, and a close frame still in the server's
//! send queue is thrown away. A lingering close shuts down the server's write half and reads the rest dry
//! instead: the client's write of the whole message succeeds, and then it reads the close frame.
//!
//! The client speaks the websocket protocol by hand on a plain TCP socket, so that it can write a frame
//! whose header announces more than the limit and keep writing its payload after the server refused it.
//! Its send buffer is small and the message is larger than the server's receive buffer and the client's
//! send buffer together, so without the lingering close the write cannot complete before the reset.

use std::net::SocketAddr;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpSocket;
use tokio::net::tcp::OwnedReadHalf;

use super::rig::{Lab, TOKEN, WAIT, loopback};

/// The server's `max_message_bytes` in this test.
const LIMIT: usize = 4096;
/// The refused message's payload: far beyond the limit and the socket buffers in its way, within
/// what a lingering socket reads (`LINGER_BYTES`).
const DECLARED: usize = 768 * 1024;
/// The client's send buffer.
const CLIENT_SEND_BUFFER: u32 = 16 * 1024;
/// Close code for a message too big (RFC 6455, 7.4.1).
const MESSAGE_TOO_BIG: u16 = 1009;

/// Connects from 127.0.0.1 with a small send buffer and makes the websocket handshake (with the token);
/// returns the socket and the bytes read after the response's head.
async fn handshake(addr: SocketAddr) -> (tokio::net::TcpStream, Vec<u8>) {
    let sock = TcpSocket::new_v4().unwrap();
    sock.set_send_buffer_size(CLIENT_SEND_BUFFER).unwrap();
    sock.bind(SocketAddr::new(loopback(1), 0)).unwrap();
    let mut tcp = sock.connect(addr).await.unwrap();
    let request = format!(
        "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: pavlov.v1, token.{TOKEN}\r\n\r\n"
    );
    tcp.write_all(request.as_bytes()).await.unwrap();
    let mut got = Vec::new();
    let head_end = loop {
        if let Some(i) = got.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        let mut chunk = [0u8; 4096];
        let n = tcp.read(&mut chunk).await.unwrap();
        assert!(n > 0, "closed during the handshake");
        got.extend_from_slice(&chunk[..n]);
    };
    assert!(
        got.starts_with(b"HTTP/1.1 101"),
        "{}",
        String::from_utf8_lossy(&got[..head_end])
    );
    (tcp, got.split_off(head_end))
}

/// The header of a masked text frame announcing `len` bytes of payload.
fn masked_text_header(len: usize) -> Vec<u8> {
    let mut header = vec![0x81, 0x80 | 127];
    header.extend_from_slice(&(len as u64).to_be_bytes());
    header.extend_from_slice(&[0x11, 0x22, 0x33, 0x44]);
    header
}

/// Reads the server's frames until a close frame; its code (`None`: the connection ended first, or the
/// close frame had no code).
async fn close_code(rd: &mut OwnedReadHalf, mut buf: Vec<u8>) -> Option<u16> {
    loop {
        if let Some((opcode, payload, used)) = frame(&buf) {
            if opcode == 0x8 {
                return (payload.len() >= 2).then(|| u16::from_be_bytes([payload[0], payload[1]]));
            }
            buf.drain(..used);
            continue;
        }
        let mut chunk = [0u8; 16 * 1024];
        match rd.read(&mut chunk).await {
            Ok(0) => return None,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) => {
                eprintln!("reading the server's frames failed: {e}");
                return None;
            }
        }
    }
}

/// The first whole (unmasked, server-sent) frame in `buf`: its opcode, its payload and the bytes it takes.
fn frame(buf: &[u8]) -> Option<(u8, &[u8], usize)> {
    let (&b0, &b1) = (buf.first()?, buf.get(1)?);
    assert_eq!(b1 & 0x80, 0, "the server's frames are not masked");
    let (len, at) = match b1 & 0x7f {
        126 => (
            u16::from_be_bytes(buf.get(2..4)?.try_into().ok()?) as usize,
            4,
        ),
        127 => (
            u64::from_be_bytes(buf.get(2..10)?.try_into().ok()?) as usize,
            10,
        ),
        n => (n as usize, 2),
    };
    let payload = buf.get(at..at + len)?;
    Some((b0 & 0x0f, payload, at + len))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_over_size_message_whose_rest_is_still_arriving_gets_its_1009_close_frame() {
    let lab = Lab::start(|c| c.dashboard.max_message_bytes = LIMIT).await;
    let before = lab.dash.stats().closed_oversize;
    let (tcp, read_ahead) = handshake(lab.addr()).await;
    let (mut rd, mut wr) = tcp.into_split();

    // The header alone first: the server refuses the message by it, with all of the payload still to come.
    let writing = tokio::spawn(async move {
        wr.write_all(&masked_text_header(DECLARED)).await?;
        let payload = vec![0u8; 64 * 1024];
        for _ in 0..DECLARED / payload.len() {
            wr.write_all(&payload).await?;
        }
        Ok::<_, std::io::Error>(wr)
    });
    let written = tokio::time::timeout(WAIT, writing)
        .await
        .expect("the server neither took the rest of the message nor ended the connection")
        .expect("the writing task");
    let _wr = written.expect(
        "the whole message was taken (a connection closed with bytes unread is reset, failing the write)",
    );

    let code = tokio::time::timeout(WAIT, close_code(&mut rd, read_ahead))
        .await
        .expect("the connection ends");
    assert_eq!(code, Some(MESSAGE_TOO_BIG));
    assert_eq!(lab.dash.stats().closed_oversize, before + 1);
    lab.stop().await;
}
