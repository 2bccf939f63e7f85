//! The operator cannot make learning diverge: `set_params` with a step size beyond α·‖x‖² ≤ 1 (α = 1,
//! α = 1e308) is refused over the websocket with the bound in the message and changes nothing, α at the
//! bound is accepted, `hello` announces the bounds, `human_request` is bounded to 10 s; and over thousands
//! of ticks after such refusals (the paused clock, through the same command path) every prediction and
//! every weight stays finite.

use crate::common;

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use pavlov::checkpoint::Checkpoint;
use pavlov_actors::command::{ControlCommand, ControlRequest, LearningCommand};
use pavlov_actors::dashboard::{Dashboard, WebAssets};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::checkpoint_files::list;
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

use common::{collect, run_sim, stall_config};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

const WAIT: Duration = Duration::from_secs(5);

async fn next_json(ws: &mut Ws) -> Value {
    loop {
        let msg = tokio::time::timeout(WAIT, ws.next())
            .await
            .expect("no message within 5 s")
            .expect("the connection ended")
            .expect("a websocket error");
        if let Message::Text(t) = msg {
            return serde_json::from_str(&t).unwrap();
        }
    }
}

/// Sends `msg` with `id` and returns its reply, skipping telemetry (and collecting the ticks seen).
async fn command(ws: &mut Ws, mut msg: Value, id: u64, ticks: &mut Vec<Value>) -> Value {
    msg["id"] = json!(id);
    ws.send(Message::text(msg.to_string())).await.unwrap();
    loop {
        let v = next_json(ws).await;
        if (v["type"] == "ack" || v["type"] == "error") && v["id"] == json!(id) {
            return v;
        }
        if v["type"] == "tick" {
            ticks.push(v);
        }
    }
}

fn assert_refused(reply: &Value, words: &[&str]) {
    assert_eq!(reply["type"], "error", "{reply}");
    assert_eq!(reply["code"], "rejected", "{reply}");
    let message = reply["message"].as_str().unwrap();
    for w in words {
        assert!(message.contains(w), "`{w}` not in {message}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn divergent_step_sizes_and_long_requests_are_refused_over_the_websocket() {
    let mut cfg = stall_config();
    cfg.dashboard.bind = "127.0.0.1:0".into();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let dash = Dashboard::start(&server, WebAssets::Embedded)
        .await
        .unwrap();
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{}/ws", dash.local_addr()))
        .await
        .unwrap();
    let hello = next_json(&mut ws).await;
    assert_eq!(hello["type"], "hello");
    let bounds = &hello["signals"]["bounds"];
    assert_eq!(bounds["max_request_ms"], 10_000, "{bounds}");
    let stall = &bounds["predictions"][0];
    assert_eq!(stall["name"], "stall");
    assert_eq!(stall["active_features"], 44);
    let max_alpha = stall["max_alpha"].as_f64().unwrap();
    assert_eq!(max_alpha, 1.0 / 44.0);

    let mut ticks = Vec::new();
    let mut id = 0;
    let mut next_id = || {
        id += 1;
        id
    };
    let alpha_words = ["alpha", "exceeds 1/44 = 0.0227", "44 active features"];
    let r = command(
        &mut ws,
        json!({"cmd":"set_params","alpha":1.0}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_refused(&r, &alpha_words);
    let r = command(
        &mut ws,
        json!({"cmd":"set_params","alpha":1e308}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_refused(&r, &alpha_words);
    // Refused as a whole: the threshold next to the bad α is not applied either.
    let r = command(
        &mut ws,
        json!({"cmd":"set_params","alpha":1.0,"threshold":0.123}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_refused(&r, &alpha_words);
    let r = command(
        &mut ws,
        json!({"cmd":"set_params","lambda":1.5}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_refused(&r, &["lambda", "[0, 1]"]);
    let r = command(
        &mut ws,
        json!({"cmd":"human_request","duration_ms":1_000_000_000u64}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_refused(&r, &["duration_ms", "10000"]);
    // At the bounds: accepted.
    let r = command(
        &mut ws,
        json!({"cmd":"set_params","alpha":max_alpha,"lambda":1.0}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_eq!(r["type"], "ack", "{r}");
    assert_eq!(r["result"]["alpha"], max_alpha, "{r}");
    let r = command(
        &mut ws,
        json!({"cmd":"human_request","duration_ms":10_000}),
        next_id(),
        &mut ticks,
    )
    .await;
    assert_eq!(r["type"], "ack", "{r}");
    while ticks.len() < 100 {
        let v = next_json(&mut ws).await;
        if v["type"] == "tick" {
            ticks.push(v);
        }
    }
    for t in &ticks {
        let p = &t["predictions"][0];
        assert!(p["value"].as_f64().is_some_and(f64::is_finite), "{t}");
        assert_ne!(p["threshold"], 0.123, "a refused set_params changed θ");
    }
    dash.shutdown().await;
    server.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn learning_stays_finite_for_thousands_of_ticks_after_refused_step_sizes() {
    let dir = std::env::temp_dir().join(format!("pavlov-bounds-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut cfg = stall_config();
    cfg.checkpoint.dir = dir.display().to_string();
    cfg.checkpoint.every_s = 0;
    cfg.checkpoint.autosave = true;
    let (_, server) = run_sim(cfg, 10).await;
    let send = |c: ControlCommand| {
        let tx = server.commands().clone();
        async move {
            let (req, reply) = ControlRequest::new(c);
            tx.send(req).await.unwrap();
            reply.await.unwrap()
        }
    };
    let set_alpha = |alpha| LearningCommand::SetParams {
        prediction: None,
        alpha: Some(alpha),
        lambda: None,
        threshold: None,
    };
    for alpha in [1.0, 1e308] {
        let e = send(set_alpha(alpha).into()).await.unwrap_err().to_string();
        assert!(e.contains("exceeds 1/44"), "{e}");
    }
    let mut rx = server.feed().subscribe();
    // Before the bound, α = 1 reached 1e241 within 750 ticks and α = 1e308 NaN within 75.
    let refused = collect(&mut rx, 3000).await;
    assert!(send(set_alpha(1.0 / 44.0).into()).await.is_ok());
    let at_bound = collect(&mut rx, 3000).await;
    for r in refused.iter().chain(&at_bound) {
        let v = r.predictions[0].value;
        assert!(v.is_finite() && v.abs() < 10.0, "tick {}: {v}", r.seq);
    }
    assert!(
        refused.iter().chain(&at_bound).any(|r| r.stimulus),
        "no stall: nothing was learned"
    );
    drop(rx);
    let run_dir = server
        .checkpoints()
        .run_dir
        .clone()
        .expect("autosave has a run folder");
    server.shutdown().await;
    let files = list(&run_dir).unwrap();
    let (_, last) = files.last().expect("a shut-down checkpoint");
    let cp: Checkpoint = serde_json::from_slice(&std::fs::read(last).unwrap()).unwrap();
    let weights = &cp.state.predictions[0].weights;
    assert!(weights.iter().all(|w| w.is_finite()));
    assert!(weights.iter().any(|&w| w != 0.0), "the weights never moved");
    let _ = std::fs::remove_dir_all(&dir);
}
