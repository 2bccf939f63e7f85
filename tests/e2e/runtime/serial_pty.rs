//! `pavlov sim --pty` and `pavlov serve --robot <that path>` as two real processes talking over a real
//! pseudo-terminal (tokio-serial on the server side): the server drives the simulated Create, and a SIGTERM
//! leaves it stopped and back in Passive. A simulator frozen with SIGSTOP is noticed, the server reopens the
//! serial device and resumes control when the robot is back; bad fault specifications are refused.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use pavlov::supervision::LinkState;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

pub(super) fn terminate(child: &Child) {
    kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM).expect("send SIGTERM");
}

pub(super) fn wait_with_timeout(child: &mut Child, limit: Duration) -> std::process::ExitStatus {
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

/// SIGTERMs `serve`, checks it exits successfully, and returns its log.
fn stop_serve(serve: &mut Child) -> String {
    terminate(serve);
    let status = wait_with_timeout(serve, Duration::from_secs(10));
    let mut log = String::new();
    serve
        .stderr
        .take()
        .expect("serve stderr")
        .read_to_string(&mut log)
        .expect("read serve log");
    assert!(status.success(), "serve failed: {status}\n{log}");
    log
}

#[test]
fn serve_drives_the_simulated_create_over_a_pty_and_stops_it_on_sigterm() {
    let (mut sim, mut sim_out, path) = start_sim("none");

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
    let log = stop_serve(&mut serve);
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
    // About 50 Drive Direct commands a second reached the robot, and it moved (how far depends on how
    // much CPU the simulator got on a shared machine: 0.0985 m was seen at a load of 8 on 2 cores).
    assert!(state["commands"].as_u64().unwrap_or(0) > 100, "{state}");
    assert!(
        state["odometer_m"].as_f64().unwrap_or(0.0) > 0.05,
        "{state}"
    );
}

/// Starts `pavlov sim --pty` with `faults` and returns the process, its stdout and the device path.
pub(super) fn start_sim(faults: &str) -> (Child, BufReader<std::process::ChildStdout>, String) {
    let mut sim = Command::new(PAVLOV)
        .args(["sim", "--pty", "--model", "create1", "--seed", "4"])
        .args(["--faults", faults])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start pavlov sim");
    let mut out = BufReader::new(sim.stdout.take().expect("sim stdout"));
    let mut path = String::new();
    out.read_line(&mut path).expect("read the PTY path");
    let path = path.trim().to_string();
    assert!(path.starts_with("/dev/"), "unexpected PTY path `{path}`");
    (sim, out, path)
}

#[test]
fn a_frozen_robot_is_detected_and_its_serial_port_reopened() {
    // Text lines between and inside frames, and dropped bytes, the whole time.
    let (sim, mut sim_out, path) = start_sim("text=0.02,inside=0.01,drop=2e-4");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("free port")
        .port();
    let record = std::env::temp_dir().join(format!("pavlov-pty-reopen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&record);
    let mut serve = Command::new(PAVLOV)
        .args(["serve", "--robot", &path, "--mode", "reactive"])
        .args(["--bind", &format!("127.0.0.1:{port}")])
        .arg("--record")
        .arg(&record)
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pavlov serve");
    std::thread::sleep(Duration::from_secs(2));
    // The robot's end of the line goes silent both ways for 2.5 s: SIGSTOP freezes the simulator.
    let sim_pid = Pid::from_raw(sim.id() as i32);
    kill(sim_pid, Signal::SIGSTOP).expect("SIGSTOP");
    std::thread::sleep(Duration::from_millis(2500));
    kill(sim_pid, Signal::SIGCONT).expect("SIGCONT");
    std::thread::sleep(Duration::from_secs(3));
    assert!(serve.try_wait().expect("poll").is_none(), "serve exited");
    let log = stop_serve(&mut serve);
    for needle in [
        "robot stream stale",
        "reopening serial port",
        "robot link reopened",
        "robot link up (was",
    ] {
        assert!(
            log.contains(needle),
            "`{needle}` missing from the log:\n{log}"
        );
    }

    let run = pavlov_actors::storage::recording::load(&record).expect("recording loads");
    let records = &run.records;
    assert!(records.len() > 300, "{} records", records.len());
    let last = records.last().expect("records");
    assert!(last.link.reconnects >= 1, "no reconnect recorded");
    assert!(last.link.bad_frames > 0, "the injected text broke no frame");
    let mut outage = false;
    let mut moved_after = false;
    for r in records {
        if r.link.state != LinkState::Up {
            outage = true;
            assert_eq!(
                (r.command.left_mm_s, r.command.right_mm_s),
                (0, 0),
                "tick {} moves with the link {:?}",
                r.seq,
                r.link.state
            );
        } else if outage && r.command.left_mm_s != 0 {
            moved_after = true;
        }
    }
    assert!(outage, "the frozen robot was never noticed");
    assert!(moved_after, "control did not resume after the reconnect");

    terminate(&sim);
    let status = wait_with_timeout(&mut { sim }, Duration::from_secs(10));
    assert!(status.success());
    let mut summary = String::new();
    sim_out
        .read_to_string(&mut summary)
        .expect("read sim summary");
    let state: serde_json::Value = serde_json::from_str(summary.trim()).expect("final state JSON");
    assert!(
        state["faults"]["text_lines"].as_u64().unwrap_or(0) > 10,
        "{state}"
    );
    assert_eq!(state["wheel_speed_mm_s"][0].as_f64(), Some(0.0), "{state}");
    let _ = std::fs::remove_dir_all(&record);
}

#[test]
fn a_bad_fault_spec_is_refused_with_the_key() {
    let out = Command::new(PAVLOV)
        .args(["sim", "--pty", "--faults", "drop=0.1,wobble=2"])
        .output()
        .expect("run pavlov sim");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("unknown fault `wobble`"), "{err}");
    let out = Command::new(PAVLOV)
        .args(["serve", "--faults", "drop=2"])
        .output()
        .expect("run pavlov serve");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("sim.faults") && err.contains("drop"), "{err}");
    // Faults are for the simulator: asking for them on a real serial device is refused, not ignored.
    let out = Command::new(PAVLOV)
        .args(["serve", "--robot", "/dev/null", "--faults", "all"])
        .output()
        .expect("run pavlov serve");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("simulated Create"), "{err}");
}
