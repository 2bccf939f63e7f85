//! `pavlov sim --pty` and `pavlov serve --robot <that path>` as two real processes talking over a real
//! pseudo-terminal (tokio-serial on the server side): the server drives the simulated Create, and a SIGTERM
//! leaves it stopped and back in Passive. A simulator frozen with SIGSTOP is noticed, the server reopens the
//! serial device and resumes control when the robot is back; bad fault specifications are refused.
//!
//! Both processes share the machine with whatever else runs: the tests wait for what the server says it
//! has done (its log, its `/metrics`), under a generous wall-clock bound, rather than for fixed times.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
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

/// How long a step may take on a busy machine before the test gives up.
const PATIENCE: Duration = Duration::from_secs(120);

/// `pavlov serve`, its log read as it comes, and its dashboard's address.
struct Serve {
    child: Child,
    log: Arc<Mutex<String>>,
    reader: Option<std::thread::JoinHandle<()>>,
    bind: String,
}

impl Serve {
    /// Starts `pavlov serve` with `args`, its dashboard on a free loopback port.
    fn start(args: &[&str]) -> Serve {
        // A free loopback port for the dashboard, so this test never collides with another server.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("free port")
            .port();
        let bind = format!("127.0.0.1:{port}");
        let mut child = Command::new(PAVLOV)
            .arg("serve")
            .args(args)
            .args(["--bind", &bind])
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start pavlov serve");
        let stderr = child.stderr.take().expect("serve stderr");
        let log = Arc::new(Mutex::new(String::new()));
        let reader = {
            let log = log.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    let mut log = log.lock().unwrap();
                    log.push_str(&line);
                    log.push('\n');
                }
            })
        };
        Serve {
            child,
            log,
            reader: Some(reader),
            bind,
        }
    }

    fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    /// Waits until the log has said `needle` (as many times as it had before, plus one).
    fn wait_for_log(&mut self, needle: &str, before: usize) {
        self.wait_until(&format!("`{needle}` in the log"), |s| {
            s.log().matches(needle).count() > before
        });
    }

    /// Waits until `ok` holds, checking every 50 ms; fails naming `what` after [`PATIENCE`].
    fn wait_until(&mut self, what: &str, ok: impl Fn(&Serve) -> bool) {
        let deadline = Instant::now() + PATIENCE;
        while !ok(self) {
            assert!(
                self.child.try_wait().expect("poll").is_none(),
                "serve exited waiting for {what}:\n{}",
                self.log()
            );
            assert!(
                Instant::now() < deadline,
                "no {what} within {PATIENCE:?}:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The value of the sample `name` (no labels) on `/metrics`, if it is there.
    fn metric(&self, name: &str) -> Option<f64> {
        let mut s = std::net::TcpStream::connect(&self.bind).ok()?;
        s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
        write!(
            s,
            "GET /metrics HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            self.bind
        )
        .ok()?;
        let mut text = String::new();
        s.read_to_string(&mut text).ok()?;
        text.lines().find_map(|l| {
            let (n, v) = l.split_once(' ')?;
            (n == name).then(|| v.trim().parse().ok()).flatten()
        })
    }

    /// Motor commands actuation has written so far (0 before `/metrics` answers).
    fn commands(&self) -> f64 {
        self.metric("pavlov_actuation_commands_total")
            .unwrap_or(0.0)
    }

    /// SIGTERMs the server, checks it exits successfully, and returns its whole log.
    fn stop(mut self) -> String {
        terminate(&self.child);
        let status = wait_with_timeout(&mut self.child, Duration::from_secs(10));
        if let Some(reader) = self.reader.take() {
            reader.join().expect("the log reader");
        }
        let log = self.log();
        assert!(status.success(), "serve failed: {status}\n{log}");
        log
    }
}

#[test]
fn serve_drives_the_simulated_create_over_a_pty_and_stops_it_on_sigterm() {
    let (mut sim, mut sim_out, path) = start_sim("none");
    let mut serve = Serve::start(&["--robot", &path, "--mode", "reactive"]);
    // Let it drive: the default policy turns right for 150 ticks, then drives forward. 300 commands
    // written after the link came up: 150 of them forward, 3 s at 50 Hz (however long that takes).
    serve.wait_for_log("robot link up", 0);
    let at_link_up = serve.commands();
    serve.wait_until("300 motor commands", |s| s.commands() >= at_link_up + 300.0);
    let log = serve.stop();
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
    // The Drive Direct commands reached the robot, and it moved (at the policy's 100 mm/s or so for the 3 s
    // of forward commands, less whatever the simulator did not get the CPU for: 0.0985 m was seen after
    // 1 s of them at a load of 8 on 2 cores).
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
    let record = std::env::temp_dir().join(format!("pavlov-pty-reopen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&record);
    let record_arg = record.display().to_string();
    let mut serve = Serve::start(&[
        "--robot",
        &path,
        "--mode",
        "reactive",
        "--record",
        &record_arg,
    ]);
    // Driving first: the link up and 100 commands written.
    serve.wait_for_log("robot link up", 0);
    let at_link_up = serve.commands();
    serve.wait_until("100 motor commands", |s| s.commands() >= at_link_up + 100.0);
    // The robot's end of the line goes silent both ways: SIGSTOP freezes the simulator, until the server
    // has noticed and started reopening the port.
    let sim_pid = Pid::from_raw(sim.id() as i32);
    kill(sim_pid, Signal::SIGSTOP).expect("SIGSTOP");
    serve.wait_for_log("reopening serial port", 0);
    kill(sim_pid, Signal::SIGCONT).expect("SIGCONT");
    // Back: reopened, up again, and driving for another 100 commands.
    serve.wait_for_log("robot link up (was", 0);
    let at_back = serve.commands();
    serve.wait_until("100 motor commands after the reconnect", |s| {
        s.commands() >= at_back + 100.0
    });
    let log = serve.stop();
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
    // At least the 100 driving ticks before the freeze and the 100 after it (a tick whose decision came
    // too late is a watchdog stop with no record, so this is not the commands' count).
    assert!(records.len() > 100, "{} records", records.len());
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
    // Text went in between the frames all along (2 % of them: how many depends on how many frames the
    // run lasted, so the count is not fixed; the server's bad frames above show that it broke some).
    assert!(
        state["faults"]["text_lines"].as_u64().unwrap_or(0) > 0,
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
