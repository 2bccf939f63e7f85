//! The session's tests: a client's drops are its own, and replies leave in the order of the messages they
//! answer even while the worker is held on a command (a real socket to one session, whose command inbox the
//! test holds, so the worker waits exactly as long as the test wants and nothing depends on timing).
use super::*;

#[test]
fn a_clients_drops_are_read_by_its_address_while_it_is_connected() {
    let counters = Arc::new(SessionCounters::default());
    let (a, b): (SocketAddr, SocketAddr) = (
        "127.0.0.1:4000".parse().unwrap(),
        "127.0.0.1:4001".parse().unwrap(),
    );
    let slow = Arc::new(OutQueue::new(1));
    let fast = Arc::new(OutQueue::new(1));
    let slow_seat = counters.register(a, &slow);
    let fast_seat = counters.register(b, &fast);
    for _ in 0..3 {
        slow.push_telemetry(Out::Text(Utf8Bytes::from_static("tick")));
    }
    assert_eq!(counters.telemetry_dropped_for(a), Some(2));
    assert_eq!(counters.telemetry_dropped_for(b), Some(0));
    // A later connection from the same address replaces the entry; the earlier one's end leaves it.
    let again = Arc::new(OutQueue::new(1));
    let again_seat = counters.register(a, &again);
    drop(slow_seat);
    assert_eq!(counters.telemetry_dropped_for(a), Some(0));
    drop((again_seat, fast_seat));
    assert_eq!(counters.telemetry_dropped_for(a), None);
    assert_eq!(counters.telemetry_dropped_for(b), None);
}
mod held_worker {
    use std::sync::{Arc, Mutex};

    use axum::extract::ws::WebSocketUpgrade;
    use futures_util::{SinkExt, StreamExt};
    use serde_json::{Value, json};
    use tokio::sync::{mpsc, watch};
    use tokio_tungstenite::tungstenite::Message as WsMessage;
    use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
    use tokio_util::sync::CancellationToken;

    use super::super::{MAX_REFUSALS, MAX_REQUESTS, Session, SessionCounters};
    use crate::command::{Applied, ControlRequest};
    use crate::dashboard::auth::Access;
    use crate::dashboard::history::History;
    use crate::dashboard::hub::Hub;
    use crate::dashboard::messages::{Hello, HelloRun, Limits, RobotInfo, Signals};
    use crate::dashboard::rate::RateLimit;
    use crate::pipeline::latch::EstopLatch;

    type Client = tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >;

    /// One operator session served on a real socket; the test holds its command inbox.
    struct Rig {
        client: Client,
        inbox: mpsc::Receiver<ControlRequest>,
        cancel: CancellationToken,
        _hub: Hub,
    }

    async fn start(rate: RateLimit) -> Rig {
        const PERIOD_MS: u64 = 20;
        let history = History::new(1, PERIOD_MS, pavlov::control::Mode::Reactive, Vec::new());
        let (hub, hub_handle) = Hub::new(PERIOD_MS, false, history);
        let (commands, inbox) = mpsc::channel(8);
        let cancel = CancellationToken::new();
        let limits = Limits {
            max_message_bytes: 65_536,
            client_queue: 64,
            rate,
        };
        let run = HelloRun {
            run: "test".into(),
            robot: RobotInfo {
                model: pavlov::oi::model::Model::Create2,
                link: "simulated",
                port: None,
            },
            history_s: 1,
        };
        let hello = Hello::new(
            PERIOD_MS,
            true,
            Signals {
                obs: Vec::new(),
                predictions: Vec::new(),
                gate_prediction: String::new(),
                bounds: Default::default(),
                horde_predictions: 0,
            },
            limits,
            json!({}),
            &run,
        );
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let session = Session {
            peer: addr,
            hub: hub_handle,
            commands,
            estop: EstopLatch::new(watch::channel(false).0, None),
            access: Access::Command,
            history_message_bytes: 32_768,
            period_ms: PERIOD_MS,
            queue: 64,
            tick_hz: 1000.0 / PERIOD_MS as f64,
            rate,
            counters: Arc::new(SessionCounters::default()),
            cancel: cancel.clone(),
            horde: None,
        };
        let once = Arc::new(Mutex::new(Some((session, hello))));
        let app = axum::Router::new().route(
            "/ws",
            axum::routing::get(move |ws: WebSocketUpgrade| async move {
                let taken = once.lock().unwrap().take();
                let (session, hello) = taken.expect("one connection");
                ws.on_upgrade(move |socket| session.run(socket, hello))
            }),
        );
        let served = cancel.clone();
        tokio::spawn(async move {
            let _ = axum::serve(listener, app)
                .with_graceful_shutdown(served.cancelled_owned())
                .await;
        });
        let (client, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws"))
            .await
            .unwrap();
        Rig {
            client,
            inbox,
            cancel,
            _hub: hub,
        }
    }

    /// The next reply (`ack` or `error`), skipping the rest (hello, history); `Err` with the close code
    /// when the connection closes instead.
    async fn next_reply(client: &mut Client) -> Result<Value, Option<CloseCode>> {
        loop {
            match client.next().await {
                Some(Ok(WsMessage::Text(t))) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    if v["type"] == "ack" || v["type"] == "error" {
                        return Ok(v);
                    }
                }
                Some(Ok(WsMessage::Close(frame))) => return Err(frame.map(|f| f.code)),
                Some(Ok(_)) => {}
                Some(Err(_)) | None => return Err(None),
            }
        }
    }

    fn text(v: Value) -> WsMessage {
        WsMessage::text(v.to_string())
    }

    const ESTOP_ID: u64 = 1_000_000;

    /// Sends a command the worker takes to the inbox and holds there, then `more`, then an `estop`; returns
    /// the held command once every reply that came before the estop's is collected.
    async fn hold_then_send(rig: &mut Rig, more: Vec<WsMessage>) -> (ControlRequest, Vec<Value>) {
        rig.client
            .send(text(json!({"id": 0, "cmd": "set_mode", "mode": "manual"})))
            .await
            .unwrap();
        // The worker has taken it off the line and waits for its answer.
        let held = rig
            .inbox
            .recv()
            .await
            .expect("the command reaches the inbox");
        for m in more {
            rig.client.feed(m).await.unwrap();
        }
        // The reader reads in order: once the estop is answered, everything before it has been read.
        rig.client
            .send(text(json!({"id": ESTOP_ID, "cmd": "estop"})))
            .await
            .unwrap();
        let mut before = Vec::new();
        loop {
            let v = next_reply(&mut rig.client).await.expect("the estop's ack");
            if v["id"] == ESTOP_ID {
                assert_eq!(v["result"]["estop"], true, "{v}");
                return (held, before);
            }
            before.push(v);
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn refusals_read_while_the_worker_is_held_are_answered_in_their_turn() {
        // Within the limit: the held command, a full line of pings and one more; the next is over it.
        let burst = 1 + MAX_REQUESTS as u32 + 1;
        let mut rig = start(RateLimit {
            burst,
            per_second: 0.001,
        })
        .await;
        let last = MAX_REQUESTS as u64 + 2;
        let more = (1..=last)
            .map(|id| text(json!({"id": id, "cmd": "ping"})))
            .collect();
        let (held, before) = hold_then_send(&mut rig, more).await;
        assert!(
            before.is_empty(),
            "replies overtook the held command's (only the estop may): {before:?}"
        );
        let _ = held.reply.send(Ok(Applied::Mode {
            mode: pavlov::control::Mode::Manual,
        }));
        for id in 0..=last {
            let v = next_reply(&mut rig.client).await.expect("a reply");
            assert_eq!(v["id"], id, "replies out of order: {v}");
            let expected = match id {
                // Answered, or `timeout` had the test been held up for the command timeout.
                0 if v["type"] == "error" => Some("timeout"),
                0 => None,
                id if id <= MAX_REQUESTS as u64 => None,
                id if id == MAX_REQUESTS as u64 + 1 => Some("busy"),
                _ => Some("rate_limited"),
            };
            match expected {
                None => assert_eq!(v["type"], "ack", "{v}"),
                Some(code) => assert_eq!(v["code"], code, "{v}"),
            }
        }
        rig.cancel.cancel();
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_connection_whose_refusals_fill_their_room_behind_a_held_command_is_closed_1008() {
        let mut rig = start(RateLimit {
            burst: 10_000,
            per_second: 0.001,
        })
        .await;
        // A full line of requests, then as many refusals (binary frames) as may wait.
        let mut more: Vec<WsMessage> = (1..=MAX_REQUESTS as u64)
            .map(|id| text(json!({"id": id, "cmd": "ping"})))
            .collect();
        more.extend((0..MAX_REFUSALS).map(|_| WsMessage::binary(vec![1u8, 2, 3])));
        let (_held, before) = hold_then_send(&mut rig, more).await;
        assert!(
            before.is_empty(),
            "{} replies overtook the held command's, the first {:?}",
            before.len(),
            before.first()
        );
        // One refusal more has no room: the connection is closed with 1008, the held command unanswered.
        rig.client.send(WsMessage::binary(vec![1u8])).await.unwrap();
        assert_eq!(
            next_reply(&mut rig.client).await,
            Err(Some(CloseCode::Policy))
        );
        rig.cancel.cancel();
    }
}
