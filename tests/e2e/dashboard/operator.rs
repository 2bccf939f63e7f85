//! The operator always wins: however many watchers connect, however many idle sockets an abuser holds
//! open (reopening each as soon as it is closed), whatever tokens are guessed, an operator with the
//! token gets in and latches the e-stop, and `/healthz` answers. Every client below is a real socket to a
//! real server (simulated robot); abusers connect from other loopback addresses (127.0.0.0/8), like other
//! machines, and run on their own runtime.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use pavlov_actors::dashboard::token_throttle::FAILURE_BURST;
use serde_json::json;
use tokio::io::AsyncReadExt;

use super::rig::{
    Lab, TOKEN, WAIT, command, http_get_from, loopback, next_json, refusal, tcp_from, timed_estop,
    ws_from,
};

/// The bound on send → ack of an e-stop asserted here: the ack itself (`estop: true`, not a timeout error)
/// shows that the router latched it without waiting for a stalled owner. How fast is a timing target (the
/// issue asks for 50 ms), measured by `pavlov bench` (`bench/estop_probe.rs`) and printed here; on a
/// machine busy with other work the scheduler decides it, so the test only bounds it by the router's own
/// timeouts (a command stuck behind a full inbox waits 1 s, then 3 s for its owner).
const ESTOP_BOUND: Duration = Duration::from_secs(4);

fn runtime(name: &str) -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name(name)
        .enable_all()
        .build()
        .unwrap()
}

/// Latches and releases the e-stop `n` times; every latch must be acked with `estop: true` within
/// [`ESTOP_BOUND`]. Returns the latencies, sorted.
async fn estops(ws: &mut super::rig::Ws, n: u64) -> Vec<Duration> {
    let mut latencies = Vec::new();
    for i in 0..n {
        let (latency, ack) = timed_estop(ws, 2 * i + 1).await;
        assert_eq!(ack["type"], "ack", "{ack}");
        assert_eq!(ack["result"]["estop"], true, "{ack}");
        assert!(latency < ESTOP_BOUND, "e-stop {i} took {latency:?}");
        latencies.push(latency);
        let release = command(ws, json!({"cmd": "release"}), 2 * i + 2).await;
        assert_eq!(release["result"]["estop"], false, "{release}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    latencies.sort();
    latencies
}

fn summary(l: &[Duration]) -> String {
    format!(
        "p50 {:.2} ms, max {:.2} ms over {}",
        l[l.len() / 2].as_secs_f64() * 1e3,
        l[l.len() - 1].as_secs_f64() * 1e3,
        l.len()
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hundred_watchers_leave_the_operator_a_seat_and_the_estop_latches_at_once() {
    let lab = Lab::start(|_| {}).await;
    let addr = lab.addr();
    let cfg = lab.server.config().dashboard.clone();
    let readers = runtime("watchers");
    let mut admitted = 0usize;
    let mut refused = Vec::new();
    // 100 watchers: 20 from one address, then 10 from each of 8 others.
    let sources = (0..100).map(|i| {
        if i < 20 {
            loopback(30)
        } else {
            loopback(10 + (i - 20) / 10)
        }
    });
    for source in sources {
        match ws_from(source, addr, None).await {
            Ok((mut ws, hello)) => {
                assert_eq!(hello["can_command"], false, "{hello}");
                admitted += 1;
                // Watchers read everything, like browsers.
                readers.spawn(async move { while let Some(Ok(_)) = ws.next().await {} });
            }
            Err(e) => refused.push((source, refusal(&e))),
        }
    }
    // The operator gets in, however many watchers there are…
    let (mut op, hello) = ws_from(loopback(1), addr, Some(TOKEN)).await.unwrap();
    assert_eq!(hello["can_command"], true, "{hello}");
    // …while the watchers got as many seats as the limits give, and no more from anywhere.
    assert_eq!(admitted, cfg.max_watchers, "{refused:?}");
    assert!(
        refused.iter().all(|(_, status)| *status == 503),
        "{refused:?}"
    );
    let from_the_busy_one = refused.iter().filter(|(s, _)| *s == loopback(30)).count();
    assert_eq!(from_the_busy_one, 20 - cfg.max_watchers_per_address);
    let e = ws_from(loopback(1), addr, None).await.unwrap_err();
    assert_eq!(refusal(&e), 503);
    let stats = lab.dash.stats();
    assert_eq!(
        (stats.clients, stats.watchers),
        (cfg.max_watchers + 1, cfg.max_watchers)
    );
    let latencies = estops(&mut op, 20).await;
    eprintln!(
        "e-stop send → ack with {} watchers connected: {}",
        cfg.max_watchers,
        summary(&latencies)
    );
    // The tick stream shows it latched.
    let (latency, _) = timed_estop(&mut op, 1000).await;
    assert!(latency < ESTOP_BOUND);
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        let t = next_json(&mut op).await;
        if t["type"] == "tick" && t["estop"] == true && t["command"] == json!({"left":0,"right":0})
        {
            break;
        }
        assert!(Instant::now() < deadline, "no stopped tick within 2 s");
    }
    readers.shutdown_background();
    lab.stop().await;
}

/// Holds one idle socket from `source` open, and opens a new one as soon as the server closes it (the
/// flood tests here and in `operator_first.rs`).
pub(super) async fn idle_socket(
    source: std::net::IpAddr,
    addr: std::net::SocketAddr,
    opened: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) {
    while !stop.load(Ordering::Relaxed) {
        match tcp_from(source, addr).await {
            Ok(mut s) => {
                opened.fetch_add(1, Ordering::Relaxed);
                let mut buf = [0u8; 64];
                while let Ok(n) = s.read(&mut buf).await {
                    if n == 0 {
                        break;
                    }
                }
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(5)).await,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_hundred_reopened_idle_sockets_leave_healthz_and_the_operator_a_way_in() {
    let lab = Lab::start(|_| {}).await;
    let addr = lab.addr();
    let max_pending = lab.server.config().dashboard.max_pending;
    // The flood: 200 idle sockets from 20 addresses, each reopened as soon as it is closed. It keeps a core
    // busy for the few seconds of the test (reopening as fast as the server closes is a busy loop).
    let flood = runtime("idle-flood");
    let opened = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    for i in 0..200u8 {
        flood.spawn(idle_socket(
            loopback(40 + i % 20),
            addr,
            opened.clone(),
            stop.clone(),
        ));
    }
    let t0 = Instant::now();
    while opened.load(Ordering::Relaxed) < 400 {
        assert!(t0.elapsed() < WAIT, "the flood did not get going");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(
        lab.dash.stats().closed_evicted > 0,
        "{:?}",
        lab.dash.stats()
    );
    // Meanwhile /healthz answers every time…
    for i in 0..20 {
        let (status, body) = http_get_from(loopback(1), addr, "/healthz").await;
        assert_eq!((status, body.as_str()), (200, "ok"), "probe {i}");
        assert!(lab.dash.stats().pending <= max_pending);
    }
    // …the operator's handshake succeeds and the e-stop latches at once…
    let (mut op, hello) = ws_from(loopback(1), addr, Some(TOKEN)).await.unwrap();
    assert_eq!(hello["can_command"], true);
    let latencies = estops(&mut op, 10).await;
    // …and so does a watcher's.
    let (_watcher, hello) = ws_from(loopback(2), addr, None).await.unwrap();
    assert_eq!(hello["can_command"], false);
    let stats = lab.dash.stats();
    let churn = opened.load(Ordering::Relaxed);
    eprintln!(
        "idle flood: {churn} sockets opened in {:.1} s, {} evicted, {} timed out; e-stop send → ack: {}",
        t0.elapsed().as_secs_f64(),
        stats.closed_evicted,
        stats.closed_no_upgrade,
        summary(&latencies)
    );
    assert!(stats.pending <= max_pending, "{stats:?}");
    stop.store(true, Ordering::Relaxed);
    flood.shutdown_background();
    lab.stop().await;
}

/// `pavlov serve` with `args`; stopped with SIGTERM when dropped.
struct Serve(Child);

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.0.id().to_string())
            .status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn serve(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pavlov"));
    c.arg("serve").args(args).env("RUST_LOG", "warn");
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn weak_tokens_are_refused_guessing_is_throttled_and_the_right_token_always_gets_in() {
    // A 2-letter token on a public bind stops the start-up, naming the key and the bound.
    let mut weak = serve(&["--bind", "0.0.0.0:0", "--token", "ab"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = weak.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = weak.kill();
            panic!("the server started with a 2-letter token on 0.0.0.0");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut weak.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(!status.success(), "{stderr}");
    assert!(
        stderr.contains("dashboard.token") && stderr.contains("16 characters"),
        "{stderr}"
    );

    // No token on a public bind: a random one is generated and printed with the URL.
    let mut child = serve(&["--bind", "0.0.0.0:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let _serve = Serve(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(url) = line.strip_prefix("operator page: ") {
                let _ = tx.send(url.trim().to_string());
            }
        }
    });
    let url = rx.recv_timeout(Duration::from_secs(30)).unwrap();
    let (page, token) = url.split_once("#token=").unwrap();
    assert_eq!(token.len(), 32, "{url}");
    assert!(token.bytes().all(|b| b.is_ascii_hexdigit()), "{url}");
    let port: u16 = page
        .trim_end_matches('/')
        .rsplit(':')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let generated = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let (_, hello) = ws_from(loopback(1), generated, Some(token)).await.unwrap();
    assert_eq!(hello["can_command"], true);
    let (_, hello) = ws_from(loopback(1), generated, None).await.unwrap();
    assert_eq!(hello["can_command"], false);

    // Guessing: a burst of wrong tokens from one address gets 401 for the allowance, then 429.
    let lab = Lab::start(|_| {}).await;
    let addr = lab.addr();
    let guesser = loopback(50);
    let t0 = Instant::now();
    let mut statuses = Vec::new();
    for i in 0..30 {
        let e = ws_from(guesser, addr, Some(&format!("guess{i}")))
            .await
            .unwrap_err();
        statuses.push(refusal(&e));
    }
    let burst_secs = t0.elapsed().as_secs_f64();
    let wrong = statuses.iter().filter(|&&s| s == 401).count();
    let throttled = statuses.iter().filter(|&&s| s == 429).count();
    assert_eq!(wrong + throttled, statuses.len(), "{statuses:?}");
    assert!(
        statuses[..FAILURE_BURST as usize].iter().all(|&s| s == 401),
        "{statuses:?}"
    );
    // One more guess a second at most (the burst took {burst_secs} s).
    assert!(
        wrong as f64 <= f64::from(FAILURE_BURST) + burst_secs + 1.0,
        "{statuses:?} in {burst_secs} s"
    );
    // …and every other one throttled (at least 30 − the bound above).
    assert!(
        throttled as f64 >= 30.0 - (f64::from(FAILURE_BURST) + burst_secs + 1.0),
        "{statuses:?} in {burst_secs} s"
    );
    // The right token works at once from another address, and from the throttled one too (only failures
    // are throttled: an operator sharing the guesser's address is not locked out)…
    let (_, hello) = ws_from(loopback(1), addr, Some(TOKEN)).await.unwrap();
    assert_eq!(hello["can_command"], true);
    // A wrong guess answered 429 shows the address is throttled right now (a guess let through by a refill,
    // on a machine that stalled the test for a second, is one more 401), and the right token right after it
    // is admitted.
    let (mut wrong, mut throttled) = (wrong, throttled);
    loop {
        let e = ws_from(guesser, addr, Some("guess-again"))
            .await
            .unwrap_err();
        match refusal(&e) {
            429 => {
                throttled += 1;
                break;
            }
            401 => wrong += 1,
            other => panic!("a wrong guess answered {other}"),
        }
    }
    let (_, hello) = ws_from(guesser, addr, Some(TOKEN)).await.unwrap();
    assert_eq!(hello["can_command"], true);
    let stats = lab.dash.stats();
    assert_eq!(stats.token_failures, wrong as u64, "{stats:?}");
    assert_eq!(stats.token_throttled, throttled as u64, "{stats:?}");
    let (_, metrics) = http_get_from(loopback(1), addr, "/metrics").await;
    assert!(
        metrics.contains(&format!("pavlov_ws_token_throttled_total {throttled}")),
        "{metrics}"
    );
    lab.stop().await;
}
