//! The `pavlov serve` process at its edges: a busy dashboard port stops the start-up with a message that
//! says what to do, before the robot is touched; and a closed stderr (`pavlov serve 2>&1 | tee log` with
//! `tee` gone) changes nothing for control: commands, the e-stop among them, are still applied.

use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use super::serial_pty::{start_sim, terminate, wait_with_timeout};

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

#[test]
fn a_busy_port_is_named_and_the_robot_is_never_touched() {
    let (sim, mut sim_out, path) = start_sim("none");
    let holder = std::net::TcpListener::bind("127.0.0.1:0").expect("hold a port");
    let bind = holder.local_addr().unwrap().to_string();
    let out = Command::new(PAVLOV)
        .args(["serve", "--robot", &path, "--bind", &bind])
        .output()
        .expect("run pavlov serve");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{bind} is in use: stop the other server or pass --bind"
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    // The simulated robot heard nothing: no command, still in its power-on mode, wheels still.
    terminate(&sim);
    let mut sim = sim;
    assert!(wait_with_timeout(&mut sim, Duration::from_secs(10)).success());
    let mut last = String::new();
    sim_out.read_to_string(&mut last).expect("sim summary");
    let state: Value = serde_json::from_str(last.trim()).expect("final state JSON");
    assert_eq!(state["commands"], 0, "{state}");
    assert_ne!(state["oi_mode"], 2, "{state}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_closed_stderr_does_not_stop_commands_or_control() {
    let mut serve = Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0"])
        .env("RUST_LOG", "debug")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pavlov serve");
    let mut stdout = BufReader::new(serve.stdout.take().expect("stdout"));
    let url = loop {
        let mut line = String::new();
        assert!(
            stdout.read_line(&mut line).expect("read") > 0,
            "no URL printed"
        );
        if let Some(url) = line.trim().strip_prefix("dashboard: ") {
            break url.trim_end_matches('/').to_string();
        }
    };
    // `tee` dies: nobody reads stderr any more, and writes to it fail.
    drop(serve.stderr.take());
    let ws_url = url.replace("http://", "ws://") + "/ws";
    let (mut ws, _) = tokio_tungstenite::connect_async(ws_url.as_str())
        .await
        .expect("websocket");
    for (id, cmd) in [(1, "estop"), (2, "release"), (3, "estop")] {
        ws.send(Message::text(json!({"cmd": cmd, "id": id}).to_string()))
            .await
            .expect("send");
        let reply = loop {
            let msg = tokio::time::timeout(Duration::from_secs(5), ws.next())
                .await
                .expect("a reply within 5 s")
                .expect("connection open")
                .expect("a message");
            let Message::Text(text) = msg else { continue };
            let v: Value = serde_json::from_str(&text).unwrap();
            if v["type"] == "ack" || v["type"] == "error" {
                break v;
            }
        };
        assert_eq!(reply["type"], "ack", "{cmd}: {reply}");
        assert_eq!(reply["result"]["estop"], cmd == "estop", "{reply}");
    }
    // Ticks keep flowing with the e-stop latched, for several seconds of debug logging into the void.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(3);
    let mut latched_ticks = 0;
    while tokio::time::Instant::now() < deadline {
        if let Ok(Some(Ok(Message::Text(text)))) =
            tokio::time::timeout(Duration::from_secs(1), ws.next()).await
        {
            let v: Value = serde_json::from_str(&text).unwrap();
            if v["type"] == "tick" && v["estop"] == true {
                assert_eq!(v["command"], json!({"left": 0, "right": 0}), "{v}");
                latched_ticks += 1;
            }
        }
    }
    assert!(
        latched_ticks > 50,
        "only {latched_ticks} ticks with the e-stop"
    );
    assert!(serve.try_wait().expect("poll").is_none(), "serve exited");
    terminate(&serve);
    let status = wait_with_timeout(&mut serve, Duration::from_secs(10));
    assert!(status.success(), "{status}");
}
