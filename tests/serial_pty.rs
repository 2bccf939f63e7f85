//! `pavlov sim --pty` and `pavlov serve --robot <that path>` as two real processes talking over a real
//! pseudo-terminal (tokio-serial on the server side): the server drives the simulated Create, and a SIGTERM
//! leaves it stopped and back in Passive.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn terminate(child: &Child) {
    kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM).expect("send SIGTERM");
}

fn wait_with_timeout(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("process did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn serve_drives_the_simulated_create_over_a_pty_and_stops_it_on_sigterm() {
    let mut sim = Command::new(PAVLOV)
        .args(["sim", "--pty", "--model", "create1", "--seed", "3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start pavlov sim");
    let mut sim_out = BufReader::new(sim.stdout.take().expect("sim stdout"));
    let mut path = String::new();
    sim_out.read_line(&mut path).expect("read the PTY path");
    let path = path.trim().to_string();
    assert!(path.starts_with("/dev/"), "unexpected PTY path `{path}`");

    // A free loopback port for the dashboard, so this test never collides with another server.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("free port")
        .port();
    let bind = format!("127.0.0.1:{port}");
    let mut serve = Command::new(PAVLOV)
        .args([
            "serve", "--robot", &path, "--mode", "reactive", "--bind", &bind,
        ])
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pavlov serve");
    // Let it drive for a while: the default policy turns right for 3 s, then drives forward.
    std::thread::sleep(Duration::from_secs(4));
    assert!(
        serve.try_wait().expect("poll").is_none(),
        "serve exited early"
    );
    terminate(&serve);
    let status = wait_with_timeout(&mut serve, Duration::from_secs(10));
    let mut log = String::new();
    serve
        .stderr
        .take()
        .expect("serve stderr")
        .read_to_string(&mut log)
        .expect("read serve log");
    assert!(status.success(), "serve failed: {status}\n{log}");
    assert!(log.contains("robot link up"), "{log}");
    assert!(
        log.contains("robot stopped, stream paused, OI back in Passive"),
        "{log}"
    );

    // Let the wheels spin down, then ask the simulator how the robot was left.
    std::thread::sleep(Duration::from_millis(500));
    terminate(&sim);
    let status = wait_with_timeout(&mut sim, Duration::from_secs(10));
    assert!(status.success());
    let mut last = String::new();
    sim_out.read_to_string(&mut last).expect("read sim summary");
    let state: serde_json::Value = serde_json::from_str(last.trim()).expect("final state JSON");
    assert_eq!(
        state["oi_mode"], 1,
        "robot not returned to Passive: {state}"
    );
    assert_eq!(state["wheel_speed_mm_s"][0].as_f64(), Some(0.0), "{state}");
    assert_eq!(state["wheel_speed_mm_s"][1].as_f64(), Some(0.0), "{state}");
    // About 50 Drive Direct commands a second reached the robot, and it moved.
    assert!(state["commands"].as_u64().unwrap_or(0) > 100, "{state}");
    assert!(state["odometer_m"].as_f64().unwrap_or(0.0) > 0.1, "{state}");
}
