//! The learning view's messages over a real websocket: `learning` (every tick's TD error and every value
//! paired with its realised return, checked against the same quantities recomputed from the ticks the
//! client received), and the Horde on request (`horde_watch`: names once, values at a bounded rate, a
//! window, `horde_unwatch`), with bad arguments refused precisely, counted, and the connection kept.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use pavlov::config::Config;
use serde_json::{Value, json};

use super::rig::{Lab, Ws, command, loopback, next_json, ws_from};

/// The paper's stall prediction: τ = 25, so γ = 0.96 and the horizon is 113 ticks.
const CONTINUATION: f64 = 0.96;
const HORIZON: u64 = 113;

/// A small Horde: every observation dimension at three timescales (44 × 3 = 132 predictions).
const HORDE: &str = r#"
[horde]
precision = "f32"
[[horde.families]]
name = "nexting"
cumulants = ["obs/*"]
taus = [2.0, 10.0, 50.0]
lambda = 0.9
alpha = 0.01
features = { kind = "one_dim", all_obs = true, tiles = 4 }
"#;

fn with_horde(cfg: &mut Config) {
    let stall = include_str!("../../../config/stall.toml");
    cfg.horde = Config::from_toml(&format!("{stall}\n{HORDE}"))
        .unwrap()
        .horde;
}

/// Reads messages for `how_long`, keeping every tick (by seq) and every message of `kinds`.
async fn gather(
    ws: &mut Ws,
    how_long: Duration,
    kinds: &[&str],
) -> (BTreeMap<u64, Value>, Vec<Value>) {
    let mut ticks = BTreeMap::new();
    let mut kept = Vec::new();
    let end = Instant::now() + how_long;
    while Instant::now() < end {
        let v = next_json(ws).await;
        if v["type"] == "tick" {
            ticks.insert(v["seq"].as_u64().unwrap(), v);
        } else if kinds.iter().any(|k| v["type"] == *k) {
            kept.push(v);
        }
    }
    (ticks, kept)
}

/// How long a test waits, in wall-clock time, for what it needs to have arrived. The Horde runs under
/// `SCHED_IDLE` (the default): on a busy machine it learns, and so publishes new values, only when a core
/// has nothing else to do, so a test waits for the values it needs rather than for a fixed time.
const PATIENCE: Duration = Duration::from_secs(180);

/// Reads messages until `enough` says the kept messages of `kinds` suffice (or [`PATIENCE`] is out: then it
/// fails, naming `what`); returns them.
async fn gather_until(
    ws: &mut Ws,
    kinds: &[&str],
    what: &str,
    enough: impl Fn(&[Value]) -> bool,
) -> Vec<Value> {
    let mut kept = Vec::new();
    let end = Instant::now() + PATIENCE;
    while !enough(&kept) {
        assert!(
            Instant::now() < end,
            "{what}: only {} messages in {PATIENCE:?}",
            kept.len()
        );
        let v = next_json(ws).await;
        if kinds.iter().any(|k| v["type"] == *k) {
            kept.push(v);
        }
    }
    kept
}

fn stall_value(tick: &Value) -> f64 {
    tick["predictions"][0]["value"].as_f64().unwrap()
}

fn cumulant_and_discount(tick: &Value) -> (f64, f64) {
    if tick["stimulus"].as_bool().unwrap() {
        (1.0, 0.0)
    } else {
        (0.0, CONTINUATION)
    }
}

/// Checks every TD error and every realised return of `learning` that the ticks received allow
/// (recomputed from them); returns how many of each were checked.
fn check_learning(ticks: &BTreeMap<u64, Value>, learning: &[Value]) -> (usize, usize) {
    let mut td_checked = 0;
    let mut returns_checked = 0;
    for m in learning {
        let p = &m["predictions"][0];
        assert_eq!(p["name"], "stall", "{m}");
        assert_eq!(p["tau"], 25.0);
        assert_eq!(p["horizon"], HORIZON);
        assert!(p["tail_bound"].as_f64().unwrap() < 0.01);
        assert_eq!(
            p["learner"], "paper",
            "the learner by name, for the Learning card"
        );
        // The message comes on every tenth tick and carries the TD errors up to it.
        let seq = m["seq"].as_u64().unwrap();
        assert_eq!(seq % 10, 0, "{m}");
        let td = p["td"].as_array().unwrap();
        assert_eq!(td.last().unwrap()[0].as_u64(), Some(seq), "{m}");
        for entry in td {
            let s = entry[0].as_u64().unwrap();
            let (Some(now), Some(before)) = (ticks.get(&s), ticks.get(&(s.wrapping_sub(1)))) else {
                continue;
            };
            let (r, gamma) = cumulant_and_discount(now);
            let want = r + gamma * stall_value(now) - stall_value(before);
            let got = entry[1].as_f64().unwrap();
            assert!(
                (got - want).abs() <= 1e-6 + 1e-6 * want.abs(),
                "δ at {s}: {got} vs {want}"
            );
            td_checked += 1;
        }
        for pair in p["realised"].as_array().unwrap() {
            let s = pair[0].as_u64().unwrap();
            // Recompute the return from the ticks, when they are all here.
            let mut ret = 0.0;
            let mut discount = 1.0;
            let mut complete = false;
            let mut all_here = true;
            for k in 1..=HORIZON {
                let Some(t) = ticks.get(&(s + k)) else {
                    all_here = false;
                    break;
                };
                let (r, gamma) = cumulant_and_discount(t);
                ret += discount * r;
                discount *= gamma;
                if discount == 0.0 {
                    complete = true;
                    break;
                }
            }
            if !all_here || !ticks.contains_key(&s) {
                continue;
            }
            let value = pair[1].as_f64().unwrap();
            assert!((value - stall_value(&ticks[&s])).abs() < 1e-6, "{pair}");
            assert!(
                (pair[2].as_f64().unwrap() - ret).abs() < 1e-6,
                "{pair} vs {ret}"
            );
            assert_eq!(pair[3].as_u64(), Some(u64::from(complete)), "{pair}");
            returns_checked += 1;
        }
        assert!(p["error"]["pairs"].as_u64().is_some(), "{m}");
    }
    (td_checked, returns_checked)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn learning_messages_carry_td_errors_and_returns_that_the_ticks_confirm() {
    let lab = Lab::start(|_| {}).await;
    let (mut ws, hello) = ws_from(loopback(2), lab.addr(), None).await.unwrap();
    assert_eq!(hello["signals"]["predictions"], json!(["stall"]));
    // 5 s at 50 Hz give about 250 δ and the returns of the ticks more than a horizon old; on a busy
    // machine the ticker may skip ticks (a return needs a horizon of them in a row), so the test reads
    // on until it has checked as many, rather than for a fixed time.
    let mut ticks = BTreeMap::new();
    let mut learning = Vec::new();
    let end = Instant::now() + PATIENCE;
    let (td_checked, returns_checked) = loop {
        let (more_ticks, more) = gather(&mut ws, Duration::from_secs(5), &["learning"]).await;
        ticks.extend(more_ticks);
        learning.extend(more);
        let (td, returns) = check_learning(&ticks, &learning);
        if (td >= 150 && returns >= 50) || Instant::now() > end {
            break (td, returns);
        }
    };
    assert!(learning.len() >= 10, "{} learning messages", learning.len());
    assert!(td_checked >= 150, "{td_checked} TD errors checked");
    assert!(returns_checked >= 50, "{returns_checked} returns checked");
    let last = &learning.last().unwrap()["predictions"][0]["error"];
    assert!(
        last["pairs"].as_u64().unwrap() >= returns_checked as u64,
        "{last}"
    );
    assert!(last["rmse"].as_f64().unwrap() >= last["mean_abs"].as_f64().unwrap() - 1e-6);

    // A client joining now gets the recent `learning` messages after its history, before the live ticks,
    // oldest first, and then the live ones without a repeat.
    let mut feed = lab.server.feed().subscribe();
    let (mut late, _) = ws_from(loopback(3), lab.addr(), None).await.unwrap();
    let mut recent = Vec::new();
    let first_tick = loop {
        let v = next_json(&mut late).await;
        match v["type"].as_str() {
            Some("learning") => recent.push(v["seq"].as_u64().unwrap()),
            Some("tick") => break v["seq"].as_u64().unwrap(),
            _ => {}
        }
    };
    // The hub keeps the last 150; every one the first client got is among them, and more since.
    assert!(
        recent.len() >= learning.len().min(150),
        "{} recent after {} live: {recent:?}",
        recent.len(),
        learning.len()
    );
    assert!(
        recent.windows(2).all(|w| w[1] > w[0] && w[1] % 10 == 0),
        "{recent:?}"
    );
    // The newest: the hub makes one on every tenth tick, and no such tick was made between the last of
    // them and the client's first live tick (on a busy machine the ticker may skip ticks, so this asks
    // the feed which ticks were made rather than counting on every tenth one).
    let newest_recent = *recent.last().unwrap();
    loop {
        let seq = feed.recv().await.unwrap().seq;
        if seq >= first_tick {
            break;
        }
        assert!(
            seq % 10 != 0 || seq <= newest_recent,
            "tick {seq} was made after the newest recent learning message {newest_recent} and before \
             the first live tick {first_tick}: {recent:?}"
        );
    }
    let next_live = loop {
        let v = next_json(&mut late).await;
        if v["type"] == "learning" {
            break v["seq"].as_u64().unwrap();
        }
    };
    assert!(
        next_live > *recent.last().unwrap(),
        "{next_live} after {recent:?}"
    );
    lab.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_horde_horde_watch_is_refused_and_the_connection_stays() {
    let lab = Lab::start(|_| {}).await;
    let (mut ws, hello) = ws_from(loopback(2), lab.addr(), None).await.unwrap();
    let commands = hello["commands"].as_array().unwrap();
    assert!(commands.contains(&json!("horde_watch")), "{hello}");
    let errors_before = lab.dash.stats().errors;
    let r = command(&mut ws, json!({"cmd": "horde_watch"}), 1).await;
    assert_eq!(r["type"], "error", "{r}");
    assert_eq!(r["code"], "no_horde", "{r}");
    assert!(
        r["message"]
            .as_str()
            .unwrap()
            .contains("[[horde.families]]"),
        "{r}"
    );
    assert_eq!(lab.dash.stats().errors, errors_before + 1);
    assert_eq!(
        command(&mut ws, json!({"cmd": "ping"}), 2).await["type"],
        "ack"
    );
    lab.stop().await;
}

/// Decodes a `horde_values` message's values.
fn decode(m: &Value) -> Vec<f32> {
    use base64_decode as b64;
    let bytes = b64(m["values"].as_str().unwrap());
    bytes
        .chunks(2)
        .map(|c| f32::from_bits(u32::from(u16::from_le_bytes([c[0], c[1]])) << 16))
        .collect()
}

/// Standard base64 with padding, decoded (the test's own, independent of the server's encoder).
fn base64_decode(text: &str) -> Vec<u8> {
    let digit = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        other => panic!("not base64: {other}"),
    };
    let mut out = Vec::new();
    for quad in text.as_bytes().chunks(4) {
        let pad = quad.iter().filter(|&&c| c == b'=').count();
        let mut n = 0u32;
        for &c in quad {
            n = (n << 6) | u32::from(if c == b'=' { 0 } else { digit(c) });
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        out.extend_from_slice(&bytes[..3 - pad]);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_watches_the_horde_at_a_bounded_rate_and_bad_requests_are_refused() {
    let lab = Lab::start(with_horde).await;
    let names = lab.server.horde().as_ref().unwrap().names.clone();
    assert_eq!(names.len(), 132);
    let (mut ws, _) = ws_from(loopback(2), lab.addr(), None).await.unwrap();
    let errors_before = lab.dash.stats().errors;
    // Bad requests: each refused with the bound, counted, and the connection stays open.
    for (id, cmd, says) in [
        (
            1,
            json!({"cmd": "horde_watch", "hz": 50}),
            "`hz` must be in [0.1, 10]",
        ),
        (
            2,
            json!({"cmd": "horde_watch", "from": 132}),
            "below the Horde's 132 predictions, got 132",
        ),
        (
            3,
            json!({"cmd": "horde_watch", "from": 100, "count": 40}),
            "at most the Horde's 132 predictions, got 140",
        ),
        (
            4,
            json!({"cmd": "horde_watch", "count": "all"}),
            "`count` must be a non-negative integer",
        ),
        (
            5,
            json!({"cmd": "horde_watch", "count": 100000}),
            "`count` must be in [1, 16384]",
        ),
    ] {
        let r = command(&mut ws, cmd, id).await;
        assert_eq!(r["type"], "error", "{r}");
        assert_eq!(r["code"], "bad_arguments", "{r}");
        assert!(r["message"].as_str().unwrap().contains(says), "{r}");
    }
    assert_eq!(lab.dash.stats().errors, errors_before + 5);
    assert_eq!(
        command(&mut ws, json!({"cmd": "ping"}), 6).await["type"],
        "ack"
    );

    // Every name once, in order, then values at no more than the rate asked for (timed from before the
    // request: nothing of it can go out earlier).
    let started = Instant::now();
    let ack = command(&mut ws, json!({"cmd": "horde_watch", "hz": 10}), 7).await;
    assert_eq!(ack["type"], "ack", "{ack}");
    assert_eq!(ack["result"]["total"], 132);
    assert_eq!(ack["result"]["count"], 132);
    assert_eq!(ack["result"]["names"], true);
    assert_eq!(ack["result"]["encoding"], "bf16le-base64");
    // At least 3 s of it, and at least 5 values (new values come as fast as the Horde learns).
    let got = gather_until(
        &mut ws,
        &["horde_names", "horde_values"],
        "horde_values at 10 Hz",
        |got| {
            started.elapsed() >= Duration::from_secs(3)
                && got.iter().filter(|m| m["type"] == "horde_values").count() >= 5
        },
    )
    .await;
    let elapsed = started.elapsed().as_secs_f64();
    let mut seen_names = Vec::new();
    let mut values = Vec::new();
    for m in &got {
        if m["type"] == "horde_names" {
            assert!(values.is_empty(), "the names come first");
            assert_eq!(m["from"].as_u64().unwrap() as usize, seen_names.len());
            for n in m["names"].as_array().unwrap() {
                seen_names.push(n.as_str().unwrap().to_string());
            }
        } else {
            values.push(m);
        }
    }
    assert_eq!(seen_names, *names);
    assert!(
        values.len() >= 5,
        "{} horde_values in {elapsed:.1} s",
        values.len()
    );
    // The bound is the correctness property here: at most hz × elapsed, plus the first at once.
    assert!(
        values.len() as f64 <= 10.0 * elapsed + 1.0,
        "{} horde_values in {elapsed:.1} s at 10 Hz",
        values.len()
    );
    let mut last_seq = None;
    for m in &values {
        assert_eq!(
            (m["from"].as_u64(), m["count"].as_u64()),
            (Some(0), Some(132))
        );
        let v = decode(m);
        assert_eq!(v.len(), 132);
        assert!(v.iter().all(|x| x.is_finite()), "{m}");
        let seq = m["seq"].as_u64().unwrap();
        assert!(
            last_seq.is_none_or(|l| seq > l),
            "a stale value was sent again"
        );
        last_seq = Some(seq);
        assert!(m["horde"]["ticks_learned"].as_u64().is_some(), "{m}");
        assert!(m.to_string().len() < 1_000, "{} bytes", m.to_string().len());
    }

    // A window, without the names again.
    let ack = command(
        &mut ws,
        json!({"cmd": "horde_watch", "hz": 2, "from": 10, "count": 5}),
        8,
    )
    .await;
    assert_eq!(ack["result"]["names"], false, "{ack}");
    let got = gather_until(
        &mut ws,
        &["horde_names", "horde_values"],
        "a value of the window",
        |got| got.iter().any(|m| m["from"] == 10),
    )
    .await;
    assert!(got.iter().all(|m| m["type"] == "horde_values"));
    let windowed: Vec<&Value> = got.iter().filter(|m| m["from"] == 10).collect();
    // At most one of the old window was still on its way.
    assert!(got.len() - windowed.len() <= 1, "{got:?}");
    for m in windowed {
        assert_eq!(decode(m).len(), 5);
    }

    // Unwatched: nothing more but what was already on its way.
    let ack = command(&mut ws, json!({"cmd": "horde_unwatch"}), 9).await;
    assert_eq!(ack["result"]["was_watching"], true, "{ack}");
    let (_, got) = gather(&mut ws, Duration::from_secs(2), &["horde_values"]).await;
    assert!(
        got.len() <= 1,
        "{} horde_values after horde_unwatch",
        got.len()
    );
    assert!(lab.dash.stats().horde_values >= 6);
    lab.stop().await;
}

/// A Horde of 880 predictions (every observation dimension at 20 timescales): 2.3 kB `horde_values`.
fn with_a_bigger_horde(cfg: &mut Config) {
    let stall = include_str!("../../../config/stall.toml");
    let taus: Vec<String> = (0..20).map(|i| format!("{}.0", 2 + 3 * i)).collect();
    let horde = HORDE.replace("[2.0, 10.0, 50.0]", &format!("[{}]", taus.join(", ")));
    cfg.horde = Config::from_toml(&format!("{stall}\n{horde}"))
        .unwrap()
        .horde;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watcher_that_stops_reading_holds_no_backlog_of_horde_values() {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message;
    let lab = Lab::start(with_a_bigger_horde).await;
    assert_eq!(lab.server.horde().as_ref().unwrap().names.len(), 880);
    // A client with a 4 kB receive buffer, so that the server's socket fills within a second or two.
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    sock.bind(std::net::SocketAddr::new(loopback(4), 0))
        .unwrap();
    let tcp = sock.connect(lab.addr()).await.unwrap();
    let (mut ws, _) = tokio_tungstenite::client_async(
        format!("ws://{}/ws", lab.addr()),
        tokio_tungstenite::MaybeTlsStream::Plain(tcp),
    )
    .await
    .unwrap();
    let started = Instant::now();
    ws.send(Message::text(
        json!({"cmd": "horde_watch", "hz": 10, "id": 1}).to_string(),
    ))
    .await
    .unwrap();
    // Not reading until the server has had new values it could not hand over (the socket full): it skips
    // them rather than queueing them. (The Horde makes new values only as fast as it gets the CPU.)
    let end = Instant::now() + PATIENCE;
    let stats = loop {
        let stats = lab.dash.stats();
        if stats.horde_values_skipped >= 5 {
            break stats;
        }
        assert!(
            Instant::now() < end,
            "the server kept queueing Horde values for a client that reads nothing: {stats:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    // What went out is at most the rate asked for (the socket's buffers hold a few).
    let elapsed = started.elapsed().as_secs_f64();
    assert!(
        stats.horde_values as f64 <= 10.0 * elapsed + 1.0,
        "{stats:?} in {elapsed:.1} s"
    );
    // Reading again: the connection is still open and fresh values keep coming, newest first, no stale run.
    let got = gather_until(&mut ws, &["horde_values"], "fresh values", |got| {
        got.len() >= 5
    })
    .await;
    let seqs: Vec<u64> = got.iter().map(|m| m["seq"].as_u64().unwrap()).collect();
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "{seqs:?}");
    for m in &got {
        assert_eq!(decode(m).len(), 880);
    }
    lab.stop().await;
}
