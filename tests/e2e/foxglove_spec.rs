//! `--foxglove` as the published protocol describes it (foxglove/ws-protocol, its docs/spec.md): a client
//! written here from the spec alone, on tokio-tungstenite (neither Foxglove's client libraries nor this
//! project's own code), offers the subprotocol `foxglove.websocket.v1`, reads `serverInfo` and
//! `advertise`, subscribes to `/pavlov/ticks` and decodes the binary `messageData` frames (opcode 0x01,
//! subscription id u32 LE, log time u64 LE, payload). And the gate's seats: an address's share, the head
//! deadline, and the eviction of clients that stop reading. Each client binds its own loopback source
//! address (127.0.0.N: the whole 127/8 range is loopback on Linux) to stand for a different host.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov::config::Config;
use pavlov_actors::foxglove::{Foxglove, TOPIC_TICKS};
use pavlov_actors::server::{RobotTarget, Server};
use serde_json::{Value, json};
use tokio::io::AsyncReadExt;
use tokio::net::{TcpSocket, TcpStream};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::tungstenite::{Error as WsError, Message};

use crate::common::{init_logging, stall_config};

/// The subprotocol the spec names.
const SPEC: &str = "foxglove.websocket.v1";
/// The spec's binary opcode for a message on a subscription.
const MESSAGE_DATA: u8 = 0x01;
/// The subscription id this client chooses for `/pavlov/ticks`.
const SUBSCRIPTION: u32 = 7;
/// A generous wait for any one step on a busy machine.
const STEP: Duration = Duration::from_secs(40);

fn host(n: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))
}

async fn start(config: Config) -> (Server, Foxglove) {
    init_logging();
    let bound = Foxglove::bind("127.0.0.1:0", &config.dashboard).unwrap();
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let fox = Foxglove::serve(bound, &server).await.unwrap();
    (server, fox)
}

/// A TCP connection to `to` from the loopback address `from` (with a small receive buffer, for a client
/// that will stop reading).
async fn tcp_from(from: IpAddr, to: SocketAddr, small_receive_buffer: bool) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(from, 0)).unwrap();
    if small_receive_buffer {
        socket.set_recv_buffer_size(4096).unwrap();
    }
    tokio::time::timeout(STEP, socket.connect(to))
        .await
        .expect("connect within the step")
        .unwrap()
}

/// One spec client, after a successful handshake.
struct SpecClient {
    ws: WebSocketStream<TcpStream>,
    /// The subprotocol the server chose.
    protocol: Option<String>,
}

/// Opens a websocket to the endpoint from `from`, offering `protocols` (the `Sec-WebSocket-Protocol`
/// header's value) at `path` (e.g. `/?token=…`). An HTTP refusal is `Err(status)`.
async fn open(
    fox: &Foxglove,
    from: IpAddr,
    path: &str,
    protocols: &str,
    small_receive_buffer: bool,
) -> Result<SpecClient, u16> {
    let to = fox.local_addr();
    let tcp = tcp_from(from, to, small_receive_buffer).await;
    let mut request = format!("ws://{to}{path}").into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_str(protocols).unwrap(),
    );
    let handshake = tokio::time::timeout(STEP, tokio_tungstenite::client_async(request, tcp))
        .await
        .expect("a handshake answer within the step");
    match handshake {
        Ok((ws, response)) => {
            let protocol = response
                .headers()
                .get("sec-websocket-protocol")
                .and_then(|v| v.to_str().ok())
                .map(str::to_string);
            Ok(SpecClient { ws, protocol })
        }
        Err(WsError::Http(response)) => Err(response.status().as_u16()),
        Err(e) => panic!("handshake failed without an HTTP answer: {e}"),
    }
}

/// What the server announced on connecting.
struct Announced {
    server_info: Value,
    channels: Vec<Value>,
}

impl SpecClient {
    async fn next(&mut self) -> Message {
        tokio::time::timeout(STEP, self.ws.next())
            .await
            .expect("a message within the step")
            .expect("the connection is open")
            .expect("a websocket message")
    }

    /// Reads `serverInfo` (the first message, per the spec) and `advertise` messages until
    /// `/pavlov/ticks` has been advertised.
    async fn announced(&mut self) -> Announced {
        let first = self.next().await;
        let Message::Text(text) = first else {
            panic!("the first message is not serverInfo: {first:?}");
        };
        let server_info: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(server_info["op"], "serverInfo", "{server_info}");
        let mut channels: Vec<Value> = Vec::new();
        while !channels.iter().any(|c| c["topic"] == TOPIC_TICKS) {
            if let Message::Text(text) = self.next().await {
                let message: Value = serde_json::from_str(&text).unwrap();
                if message["op"] == "advertise" {
                    channels.extend(message["channels"].as_array().unwrap().iter().cloned());
                }
            }
        }
        Announced {
            server_info,
            channels,
        }
    }

    /// Subscribes to the channel of `/pavlov/ticks` under [`SUBSCRIPTION`].
    async fn subscribe_ticks(&mut self, announced: &Announced) {
        let ticks = announced
            .channels
            .iter()
            .find(|c| c["topic"] == TOPIC_TICKS)
            .unwrap();
        let subscribe = json!({
            "op": "subscribe",
            "subscriptions": [{"id": SUBSCRIPTION, "channelId": ticks["id"]}],
        });
        self.ws
            .send(Message::text(subscribe.to_string()))
            .await
            .unwrap();
    }

    /// Decodes `messageData` frames until `n` ticks have arrived: (seq, log time) of each.
    async fn ticks(&mut self, n: usize) -> Vec<(u64, u64)> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let Message::Binary(frame) = self.next().await else {
                continue;
            };
            assert!(
                frame.len() >= 13,
                "a messageData frame is 13 bytes and more"
            );
            assert_eq!(frame[0], MESSAGE_DATA);
            let subscription = u32::from_le_bytes(frame[1..5].try_into().unwrap());
            assert_eq!(subscription, SUBSCRIPTION);
            let log_time = u64::from_le_bytes(frame[5..13].try_into().unwrap());
            let tick: Value = serde_json::from_slice(&frame[13..]).unwrap();
            out.push((tick["seq"].as_u64().unwrap(), log_time));
        }
        out
    }
}

/// Connects from `from` with the spec's subprotocol, subscribes to the ticks and checks that `n` arrive
/// in order.
async fn receives_ticks(fox: &Foxglove, from: IpAddr, n: usize) {
    let mut client = open(fox, from, "/", SPEC, false)
        .await
        .unwrap_or_else(|status| panic!("{from}: refused with {status}"));
    assert_eq!(client.protocol.as_deref(), Some(SPEC));
    let announced = client.announced().await;
    client.subscribe_ticks(&announced).await;
    assert_increasing(&client.ticks(n).await);
}

fn assert_increasing(ticks: &[(u64, u64)]) {
    for pair in ticks.windows(2) {
        assert!(
            pair[1].0 > pair[0].0 && pair[1].1 > pair[0].1,
            "seq and log time must increase: {pair:?}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_written_from_the_spec_receives_ticks_under_foxglove_websocket_v1() {
    let (server, fox) = start(stall_config()).await;
    let mut client = open(&fox, host(1), "/", SPEC, false).await.unwrap();
    // The server chose the subprotocol the client offered, by the spec's name.
    assert_eq!(client.protocol.as_deref(), Some(SPEC));
    let announced = client.announced().await;
    assert_eq!(announced.server_info["name"], "pavlov");
    assert!(announced.server_info["capabilities"].is_array());
    let ticks = announced
        .channels
        .iter()
        .find(|c| c["topic"] == TOPIC_TICKS)
        .unwrap();
    assert_eq!(ticks["encoding"], "json");
    assert_eq!(ticks["schemaEncoding"], "jsonschema");
    let schema: Value = serde_json::from_str(ticks["schema"].as_str().unwrap()).unwrap();
    assert_eq!(schema["type"], "object");
    client.subscribe_ticks(&announced).await;
    let received = client.ticks(50).await;
    assert_eq!(received.len(), 50);
    assert_increasing(&received);
    // The SDK's own name still works, and is answered as offered.
    let sdk = open(&fox, host(1), "/", "foxglove.sdk.v1", false)
        .await
        .unwrap();
    assert_eq!(sdk.protocol.as_deref(), Some("foxglove.sdk.v1"));
    drop((client, sdk));
    fox.shutdown().await;
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_token_as_a_subprotocol_entry_beside_the_specs_name_is_checked_then_withheld() {
    let mut config = stall_config();
    config.dashboard.token = Some("s3cret".into());
    config.dashboard.watch_without_token = false;
    let (server, fox) = start(config).await;
    let offers = [
        (format!("{SPEC}, token.s3cret"), None),
        (format!("token.s3cret, {SPEC}"), None),
        (SPEC.to_string(), Some(401)),
        (format!("{SPEC}, token.wrong"), Some(401)),
        // The right token and no subprotocol the endpoint speaks: a bad request, named as such.
        ("token.s3cret".to_string(), Some(400)),
    ];
    for (offer, refused) in offers {
        match open(&fox, host(1), "/", &offer, false).await {
            Ok(mut client) => {
                assert_eq!(refused, None, "{offer}: admitted");
                assert_eq!(client.protocol.as_deref(), Some(SPEC), "{offer}");
                let announced = client.announced().await;
                client.subscribe_ticks(&announced).await;
                assert_increasing(&client.ticks(10).await);
            }
            Err(status) => assert_eq!(Some(status), refused, "{offer}"),
        }
    }
    let stats = fox.stats();
    assert_eq!((stats.refused_token, stats.refused_bad_request), (2, 1));
    fox.shutdown().await;
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_sockets_from_one_address_leave_another_address_a_seat() {
    let (server, fox) = start(stall_config()).await;
    // 40 sockets from 127.0.0.1 that never send a request head.
    let mut idle = Vec::new();
    for _ in 0..40 {
        idle.push(tcp_from(host(1), fox.local_addr(), false).await);
    }
    // A client from another address gets a seat and its ticks meanwhile.
    receives_ticks(&fox, host(2), 25).await;
    // Each idle socket either held one of its address's seats until the head deadline closed it without
    // an answer, or was refused at once for its address's share.
    let mut refused = 0u64;
    let mut closed_silently = 0u64;
    for mut socket in idle {
        let mut answer = Vec::new();
        tokio::time::timeout(STEP, socket.read_to_end(&mut answer))
            .await
            .expect("the gate answers or closes every idle socket")
            .ok();
        let answer = String::from_utf8_lossy(&answer);
        if answer.is_empty() {
            closed_silently += 1;
        } else {
            assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
            assert!(answer.contains("per address"), "{answer}");
            refused += 1;
        }
    }
    assert_eq!(refused + closed_silently, 40);
    assert!(closed_silently >= 8, "the first 8 held their seats");
    assert!(refused >= 1, "40 sockets from one address all got seats");
    let stats = fox.stats();
    assert_eq!(stats.refused_address, refused);
    assert_eq!(stats.refused_busy, 0);
    fox.shutdown().await;
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_that_stop_reading_are_evicted_and_a_reader_then_gets_a_seat() {
    let (server, fox) = start(stall_config()).await;
    // 32 clients, 8 from each of four addresses, subscribe to the ticks and then never read again.
    let mut stalled = Vec::new();
    for h in 1..=4 {
        for _ in 0..8 {
            let mut client = open(&fox, host(h), "/", SPEC, true).await.unwrap();
            let announced = client.announced().await;
            client.subscribe_ticks(&announced).await;
            stalled.push(client);
        }
    }
    // Every seat is taken: a fifth address is refused for now.
    let full = open(&fox, host(5), "/", SPEC, false).await.err();
    assert_eq!(full, Some(503), "all 32 seats should be held");
    assert_eq!(fox.stats().refused_busy, 1);
    // The gate evicts each of them once it has held bytes for it that it would not take.
    let evicted = tokio::time::timeout(Duration::from_secs(180), async {
        while fox.stats().evicted_slow < 32 {
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
    })
    .await;
    assert!(
        evicted.is_ok(),
        "evicted {} of 32 non-reading clients",
        fox.stats().evicted_slow
    );
    // Now a reader gets a seat and its ticks.
    receives_ticks(&fox, host(5), 25).await;
    assert_eq!(fox.stats().evicted_slow, 32);
    drop(stalled);
    fox.shutdown().await;
    server.shutdown().await;
}
