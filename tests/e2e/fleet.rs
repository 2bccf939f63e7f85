//! A lab on Zenoh, through the real binary: two `pavlov serve --zenoh` processes (robots `alpha` and
//! `beta`, each with its own token, on `pavlov/v1/<robot>/…`) and one `pavlov fleet`, in Zenoh peer mode with no router, every
//! endpoint pinned on 127.0.0.1 and scouting off so the topology is fixed. The fleet sees both robots'
//! ticks and status; a command with alpha's token reaches alpha and only alpha; a command without a
//! token, or with another robot's token, is refused with a precise answer and counted in `/metrics`; beta
//! (commands off) refuses every command, saying so. Then the fleet page itself, in headless Chromium
//! (`web/tests/fleet.e2e.mjs`): the live table, a command sent from the page with the typed token, a wrong
//! token refused, and a hostile peer's status (a `javascript:` dashboard URL) shown without its link
//! (`target/fleet.png`).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");
/// Start-up of a server process includes building its learning and opening Zenoh; generous for a loaded
/// CI machine (a bound on waiting, not a performance target).
const WAIT: Duration = Duration::from_secs(60);

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// A Zenoh peer configuration: listen on `listen`, connect to `connect`, no scouting.
fn zenoh_config(dir: &Path, name: &str, listen: &[String], connect: &[String]) -> PathBuf {
    let path = dir.join(format!("{name}.json5"));
    let text = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": listen },
        "connect": { "endpoints": connect },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    std::fs::write(&path, text.to_string()).expect("zenoh config");
    path
}

/// A process whose stdout lines arrive on a channel; killed when dropped.
struct Proc {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.child.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn(args: &[&str], cwd: &Path) -> Proc {
    let mut child = Command::new(PAVLOV)
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn pavlov");
    let stdout: ChildStdout = child.stdout.take().expect("stdout");
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    Proc { child, lines }
}

impl Proc {
    /// Waits for a stdout line starting with `prefix` and returns the rest of it.
    fn wait_line(&self, prefix: &str) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => {
                    return line[prefix.len()..].trim().to_string();
                }
                Ok(_) => {}
                Err(e) => panic!("no line starting {prefix:?}: {e}"),
            }
        }
    }
}

/// One HTTP/1.1 request; the status code and the body.
fn http(addr: &str, method: &str, path: &str, body: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .expect("send");
    let mut text = String::new();
    s.read_to_string(&mut text).expect("read");
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .expect("a status line");
    let body = text
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_string();
    (status, body)
}

fn robots(fleet: &str) -> Vec<Value> {
    let (status, body) = http(fleet, "GET", "/api/robots", "");
    assert_eq!(status, 200, "{body}");
    let v: Value = serde_json::from_str(&body).expect("robots json");
    v["robots"].as_array().cloned().unwrap_or_default()
}

fn row<'a>(rows: &'a [Value], name: &str) -> Option<&'a Value> {
    rows.iter().find(|r| r["robot"] == name)
}

/// Polls the fleet until `done` holds of its rows.
fn until(fleet: &str, what: &str, done: impl Fn(&[Value]) -> bool) -> Vec<Value> {
    let deadline = Instant::now() + WAIT;
    loop {
        let rows = robots(fleet);
        if done(&rows) {
            return rows;
        }
        assert!(Instant::now() < deadline, "{what}: {rows:#?}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A sample of `/metrics` with these labels.
fn metric(dashboard: &str, name: &str, label: &str) -> f64 {
    let (_, body) = http(dashboard, "GET", "/metrics", "");
    let prefix = format!("{name}{{{label}}} ");
    body.lines()
        .find_map(|l| l.strip_prefix(&prefix))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no {prefix} in /metrics"))
}

fn serve(dir: &Path, robot: &str, token: &str, commands: bool, zenoh: &Path) -> (Proc, String) {
    let cfg = dir.join(format!("{robot}.toml"));
    let base =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .expect("config/stall.toml");
    std::fs::write(
        &cfg,
        format!(
            "{base}\n[zenoh]\nrobot = \"{robot}\"\ncommands = {commands}\nstatus_every_ms = 200\n"
        ),
    )
    .expect("config");
    let work = dir.join(robot);
    std::fs::create_dir_all(&work).expect("dir");
    let p = spawn(
        &[
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--token",
            token,
            "--config",
            cfg.to_str().expect("utf-8"),
            "--zenoh",
            zenoh.to_str().expect("utf-8"),
        ],
        &work,
    );
    let url = p.wait_line("dashboard: ");
    p.wait_line("zenoh: publishing");
    let addr = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    (p, addr)
}

#[test]
fn the_fleet_sees_two_robots_and_commands_need_each_robots_token() {
    let dir = std::env::temp_dir().join(format!("pavlov-fleet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (pa, pb) = (free_port(), free_port());
    let ep = |p: u16| format!("tcp/127.0.0.1:{p}");
    let za = zenoh_config(&dir, "alpha", &[ep(pa)], &[]);
    let zb = zenoh_config(&dir, "beta", &[ep(pb)], &[]);
    let zf = zenoh_config(&dir, "fleet", &[ep(free_port())], &[ep(pa), ep(pb)]);
    let (alpha_token, beta_token) = ("alpha-token-0123456789", "beta-token-9876543210");
    let (_alpha, alpha_dash) = serve(&dir, "alpha", alpha_token, true, &za);
    let (_beta, beta_dash) = serve(&dir, "beta", beta_token, false, &zb);
    let fleet = spawn(
        &[
            "fleet",
            "--listen",
            "127.0.0.1:0",
            "--zenoh",
            zf.to_str().expect("utf-8"),
        ],
        &dir,
    );
    let fleet_addr = fleet
        .wait_line("fleet: ")
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();

    // Both robots' ticks and status arrive.
    let rows = until(&fleet_addr, "both robots ticking, with status", |rows| {
        ["alpha", "beta"].iter().all(|n| {
            row(rows, n).is_some_and(|r| {
                r["ticks_received"].as_u64().unwrap_or(0) > 50 && r["status"]["robot"] == *n
            })
        })
    });
    for (name, dash) in [("alpha", &alpha_dash), ("beta", &beta_dash)] {
        let r = row(&rows, name).expect("row");
        assert_eq!(r["mode"], "pavlovian", "{name}");
        // Present by their liveliness tokens, their samples stamped by Zenoh's clock.
        assert_eq!(r["presence"], "alive", "{name}: {r}");
        assert!(r["last_timestamp"].is_string(), "{name}: {r}");
        assert_eq!(
            r["status"]["dashboard_url"]
                .as_str()
                .map(|u| u.contains(dash.as_str())),
            Some(true),
            "{name}: {r}"
        );
        assert!(r["status"]["ticks"]["ticks_fired"].as_u64().unwrap_or(0) > 0);
    }
    let (page_status, page) = http(&fleet_addr, "GET", "/", "");
    assert_eq!(page_status, 200);
    assert!(page.contains("fleet.js"));

    // With alpha's token, the command reaches alpha.
    let manual = |token: Option<&str>| {
        let mut m = serde_json::json!({ "command": { "cmd": "set_mode", "mode": "manual" } });
        if let Some(t) = token {
            m["token"] = Value::from(t);
        }
        m.to_string()
    };
    let (status, body) = http(
        &fleet_addr,
        "POST",
        "/api/command/alpha",
        &manual(Some(alpha_token)),
    );
    assert_eq!(status, 200, "{body}");
    let answer: Value = serde_json::from_str(&body).expect("answer");
    assert_eq!(answer["ok"], true);
    assert_eq!(answer["result"]["mode"], "manual");

    // Without a token, or with another robot's token: refused, precisely.
    let (status, body) = http(&fleet_addr, "POST", "/api/command/alpha", &manual(None));
    assert_eq!(status, 403, "{body}");
    let refusal: Value = serde_json::from_str(&body).expect("refusal");
    assert_eq!(refusal["error"], "token");
    assert!(
        refusal["message"]
            .as_str()
            .is_some_and(|m| m.contains("no token")),
        "{body}"
    );
    let (status, body) = http(
        &fleet_addr,
        "POST",
        "/api/command/alpha",
        &manual(Some(beta_token)),
    );
    assert_eq!(status, 403, "{body}");
    assert!(body.contains("the token is wrong"), "{body}");
    // Beta takes no commands over Zenoh, even with its own token.
    let (status, body) = http(
        &fleet_addr,
        "POST",
        "/api/command/beta",
        &manual(Some(beta_token)),
    );
    assert_eq!(status, 403, "{body}");
    assert!(
        body.contains("\"off\"") && body.contains("[zenoh] commands = false"),
        "{body}"
    );
    // A robot nobody runs: no answer.
    let (status, body) = http(
        &fleet_addr,
        "POST",
        "/api/command/gamma",
        &manual(Some(alpha_token)),
    );
    assert_eq!(status, 504, "{body}");

    // Alpha is in manual mode, beta is not: seen in their ticks.
    until(&fleet_addr, "alpha manual, beta still pavlovian", |rows| {
        row(rows, "alpha").is_some_and(|r| r["mode"] == "manual")
            && row(rows, "beta").is_some_and(|r| r["mode"] == "pavlovian")
    });
    // And counted where each robot counts.
    let commands = "pavlov_zenoh_commands_total";
    let count =
        |dash: &str, outcome: &str| metric(dash, commands, &format!("outcome=\"{outcome}\""));
    assert_eq!(count(&alpha_dash, "applied"), 1.0);
    assert_eq!(count(&alpha_dash, "refused_token"), 2.0);
    assert_eq!(count(&beta_dash, "applied"), 0.0);
    assert_eq!(count(&beta_dash, "refused_off"), 1.0);
    assert_eq!(count(&beta_dash, "refused_token"), 0.0);
    assert!(
        metric(
            &alpha_dash,
            "pavlov_zenoh_published_total",
            "stream=\"tick\""
        ) > 50.0
    );

    // A hostile peer publishes a status for a robot "mallory" whose dashboard link is a script.
    let mallory = hostile_peer(&zf, &dir);
    until(&fleet_addr, "mallory's status", |rows| {
        row(rows, "mallory").is_some()
    });
    let (_, body) = http(&fleet_addr, "GET", "/api/robots", "");
    let table: Value = serde_json::from_str(&body).expect("robots json");
    let m = row(table["robots"].as_array().expect("rows"), "mallory").expect("mallory");
    assert_eq!(m["status"]["dashboard_url"], Value::Null, "{m}");
    // Never seen with a liveliness token: an unknown name, in the pool of its own.
    assert_eq!(m["presence"], "unknown", "{m}");
    assert!(table["dashboard_urls_removed"].as_u64().unwrap_or(0) >= 1);

    // The page, in a browser: the same robots, a command from its form, a wrong token refused.
    browser_check(&fleet_addr, alpha_token);
    assert_eq!(count(&alpha_dash, "applied"), 2.0);
    assert_eq!(count(&alpha_dash, "refused_token"), 3.0);
    until(&fleet_addr, "alpha reactive, not e-stopped", |rows| {
        row(rows, "alpha").is_some_and(|r| r["mode"] == "reactive" && r["estop"] == false)
    });

    drop(mallory);
    drop(fleet);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A Zenoh peer that publishes a hostile status for `mallory` every 500 ms until dropped.
struct HostilePeer {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for HostilePeer {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Connects where the fleet listens (its `fleet_config`) and starts publishing.
fn hostile_peer(fleet_config: &Path, dir: &Path) -> HostilePeer {
    use zenoh::Wait;
    let text = std::fs::read_to_string(fleet_config).expect("fleet config");
    let fleet: Value = serde_json::from_str(&text).expect("json");
    let listen: Vec<String> =
        serde_json::from_value(fleet["listen"]["endpoints"].clone()).expect("endpoints");
    let config = zenoh_config(dir, "mallory", &[], &listen);
    let config = zenoh::Config::from_file(&config).expect("zenoh config");
    let session = zenoh::open(config).wait().expect("a zenoh session");
    let status = serde_json::json!({
        "robot": "mallory",
        "dashboard_url": "javascript:alert(document.cookie)",
        "ok": true,
        "health": "ok",
    })
    .to_string();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let thread = std::thread::spawn({
        let stop = stop.clone();
        move || {
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let _ = session
                    .put("pavlov/v1/mallory/status", status.clone())
                    .wait();
                std::thread::sleep(Duration::from_millis(500));
            }
            let _ = session.close().wait();
        }
    });
    HostilePeer {
        stop,
        thread: Some(thread),
    }
}

/// Runs `web/tests/fleet.e2e.mjs` against the fleet page with the dashboard tests' harness; fails the
/// test when it fails.
fn browser_check(fleet_addr: &str, token: &str) {
    use crate::dashboard::browser::{preflight, run_browser_script_with, target_dir};
    preflight();
    let screenshot = target_dir().join("fleet.png");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime for the browser script");
    runtime.block_on(run_browser_script_with(
        "fleet.e2e.mjs",
        &format!("http://{fleet_addr}/"),
        &screenshot,
        &[("FLEET_TOKEN", token)],
    ));
    assert!(
        screenshot.is_file(),
        "no screenshot at {}",
        screenshot.display()
    );
}

/// `pavlov serve` with `args` in `dir`; its exit code and stderr (it must stop by itself).
fn serve_refused(dir: &Path, args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(PAVLOV)
        .arg("serve")
        .args(["--bind", "127.0.0.1:0"])
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("run pavlov");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_zenoh_settings_stop_start_up_naming_the_problem() {
    let dir = std::env::temp_dir().join(format!("pavlov-zenoh-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let base =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .expect("config/stall.toml");
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p.to_str().expect("utf-8").to_string()
    };
    // A Zenoh file that is not valid: the file and Zenoh's reason.
    let bad_json = write("bad.json5", "{ mode: \"peer\", listen: { endpoints: 7 } }");
    let (code, err) = serve_refused(&dir, &["--zenoh", &bad_json]);
    assert_ne!(code, Some(0));
    assert!(
        err.contains("--zenoh") && err.contains("bad.json5"),
        "{err}"
    );
    // A missing file.
    let (code, err) = serve_refused(&dir, &["--zenoh", "/nonexistent/z.json5"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("/nonexistent/z.json5"), "{err}");
    // A robot name that is not one key-expression chunk.
    let slash = write("slash.toml", &format!("{base}\n[zenoh]\nrobot = \"a/b\"\n"));
    let (code, err) = serve_refused(&dir, &["--config", &slash, "--zenoh"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("zenoh.robot") && err.contains("'/'"), "{err}");
    // Commands over Zenoh without a token.
    let open = write(
        "open.toml",
        &format!("{base}\n[zenoh]\nrobot = \"r\"\ncommands = true\n"),
    );
    let (code, err) = serve_refused(&dir, &["--config", &open, "--zenoh"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("commands = true needs a token"), "{err}");
    // Commands over Zenoh with a token short enough to guess.
    let (code, err) = serve_refused(
        &dir,
        &["--config", &open, "--token", "short-token", "--zenoh"],
    );
    assert_ne!(code, Some(0));
    assert!(
        err.contains("needs a token of at least 16 characters, got 11"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
