//! The soak: 24 simulated hours of the whole server (every actor, the simulated Create behind the same
//! byte link a serial port would be) under virtual time, with faults injected throughout — byte damage
//! both ways, ASCII text between and inside frames, bursts, a steady delay, silent hangs, end-of-file,
//! trips to Passive with the mode-plus-one quirk. A simulated operator re-arms two seconds after each trip.
//!
//! It checks, on every one of the 4.3 million ticks: the server never commands motion while the link is
//! not up or the observation is stale, and the robot is never left moving for long while the host has no
//! stream and could reach it. At the end: no panic, memory and task counts flat between hour 1 and hour 24,
//! every injected outage recovered, and the stall prediction still tracking its return (its error in the
//! last hour no worse than in the first).
//!
//! Built with `test = false` (see actors/Cargo.toml): `cargo test --workspace --all-targets` does not run it;
//! `tests/run.sh` runs it in release code (`cargo test --profile soak -p pavlov-actors --test soak`: the
//! release profile without LTO, Cargo.toml). Set `PAVLOV_SOAK_HOURS` to run a shorter soak by hand.

use pavlov::config::Config;
use pavlov::control::{Action, Mode};
use pavlov::record::TickRecord;
use pavlov::supervision::LinkState;
use pavlov_actors::command::{ControlRequest, LinkCommand};
use pavlov_actors::server::{RobotTarget, Server};

/// The soak preset (byte faults, text, bursts, delay, quirk, banner) with the link events made ~5× denser
/// (about 5 hangs, 5 end-of-file events and 2–3 trips an hour), and damage on the way to the robot too
/// (about 9 flipped and 9 dropped host bytes an hour; a flip can move the robot to another baud rate).
const FAULTS: &str = "soak,hang=2e-5,eof=2e-5,trip=1e-5,host_flip=1e-5,host_drop=1e-5";
const TICKS_PER_HOUR: usize = 3600 * 50;

fn rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// Root-mean-square error of the prediction against its discounted return over one hour of ticks
/// `(stimulus, prediction)`, and that of the best constant prediction (the returns' standard deviation),
/// skipping the last 500 ticks whose returns are truncated.
fn prediction_rmse(hour: &[(bool, f64)], gamma: f64) -> (f64, f64) {
    let mut ret = 0.0;
    let mut returns = vec![0.0; hour.len()];
    for t in (0..hour.len().saturating_sub(1)).rev() {
        let next_stimulus = hour[t + 1].0;
        let r = if next_stimulus { 1.0 } else { 0.0 };
        let g = if next_stimulus { 0.0 } else { gamma };
        ret = r + g * ret;
        returns[t] = ret;
    }
    let n = hour.len().saturating_sub(500).max(1);
    let sq: f64 = (0..n).map(|t| (hour[t].1 - returns[t]).powi(2)).sum();
    let mean = returns[..n].iter().sum::<f64>() / n as f64;
    let var: f64 = returns[..n].iter().map(|g| (g - mean).powi(2)).sum::<f64>() / n as f64;
    ((sq / n as f64).sqrt(), var.sqrt())
}

/// Counts and lengths of the periods the link was not up.
#[derive(Default)]
struct Outages {
    current: usize,
    lengths_ticks: Vec<usize>,
}

impl Outages {
    fn observe(&mut self, up: bool) {
        if up {
            if self.current > 0 {
                self.lengths_ticks.push(self.current);
            }
            self.current = 0;
        } else {
            self.current += 1;
        }
    }
}

#[tokio::test(start_paused = true)]
async fn twenty_four_simulated_hours_with_faults() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let hours: usize = std::env::var("PAVLOV_SOAK_HOURS")
        .ok()
        .and_then(|h| h.parse().ok())
        .unwrap_or(24);
    assert!(hours >= 2, "the soak compares hour 1 with the last hour");
    let mut cfg =
        Config::from_toml(include_str!("../config/stall.toml")).expect("valid stall config");
    cfg.sim.faults = FAULTS.into();
    cfg.sim.seed = 24;
    // A fixed policy keeps the prediction's question stationary, so convergence can be judged.
    cfg.control.mode = Mode::Reactive;
    cfg.checkpoint.autosave = false;
    cfg.validate().expect("valid configuration");
    let gamma = cfg.predictions[0].continuation();
    let max_obs_age = cfg.safety.max_obs_age_ticks;

    let server = Server::builder(cfg, RobotTarget::Simulated)
        .start()
        .await
        .expect("server starts");
    let sim = server.health().sim_status().expect("simulated robot");
    let metrics = tokio::runtime::Handle::current().metrics();
    let mut rx = server.feed().subscribe();

    let mut first_hour: Vec<(bool, f64)> = Vec::with_capacity(TICKS_PER_HOUR);
    let mut last_hour: Vec<(bool, f64)> = Vec::with_capacity(TICKS_PER_HOUR);
    // Touch the last hour's buffer now, so that filling it is not counted as growth.
    last_hour.resize(TICKS_PER_HOUR, (false, 0.0));
    last_hour.clear();
    let mut outages = Outages::default();
    let (mut tripped_for, mut rearms) = (0usize, 0u64);
    let mut unattended_run = 0usize;
    let mut longest_unattended = 0usize;
    let mut baseline = None;
    let mut last: Option<TickRecord> = None;
    let total = hours * TICKS_PER_HOUR;
    let started = std::time::Instant::now();

    for i in 0..total {
        let r = match rx.recv().await {
            Ok(r) => r,
            Err(e) => panic!("tick feed at tick {i}: {e}"),
        };
        // The host never commands motion without an up link and a fresh observation.
        let stale = r.obs_age_ticks.is_none_or(|a| a > max_obs_age);
        if r.link.state != LinkState::Up || stale {
            assert_eq!(
                r.command,
                Action::STOP,
                "tick {}: motion commanded with link {:?}, observation age {:?}",
                r.seq,
                r.link.state,
                r.obs_age_ticks
            );
        }
        outages.observe(r.link.state == LinkState::Up);
        // The robot side: while bytes can reach it and the host has no stream, it must come to rest.
        let s = sim.borrow().clone();
        let moving = s.wheel_speed_mm_s.iter().any(|w| w.abs() > 5.0);
        let reachable = s.connected && s.flowing;
        unattended_run = if moving && reachable && r.link.state != LinkState::Up {
            unattended_run + 1
        } else {
            0
        };
        longest_unattended = longest_unattended.max(unattended_run);
        // The operator re-arms two seconds after a trip.
        tripped_for = if r.link.state == LinkState::Tripped {
            tripped_for + 1
        } else {
            0
        };
        if tripped_for == 100 {
            let (req, _reply) = ControlRequest::new(LinkCommand::Rearm {});
            if server.commands().try_send(req).is_ok() {
                rearms += 1;
            }
        }
        let prediction = r.predictions.first().map_or(f64::NAN, |p| p.value);
        assert!(
            prediction.is_finite(),
            "tick {}: prediction {prediction}",
            r.seq
        );
        if i < TICKS_PER_HOUR {
            first_hour.push((r.stimulus, prediction));
        } else if i >= total - TICKS_PER_HOUR {
            last_hour.push((r.stimulus, prediction));
        }
        if i == TICKS_PER_HOUR {
            baseline = Some((rss_kib(), metrics.num_alive_tasks()));
        }
        if i % TICKS_PER_HOUR == 0 && i > 0 {
            eprintln!(
                "soak: hour {:>2} done ({:.0} s wall), rss {} KiB, tasks {}, link {:?}, reconnects {}",
                i / TICKS_PER_HOUR,
                started.elapsed().as_secs_f64(),
                rss_kib(),
                metrics.num_alive_tasks(),
                r.link.state,
                r.link.reconnects
            );
        }
        last = Some((*r).clone());
    }
    let end = (rss_kib(), metrics.num_alive_tasks());
    let faults = sim.borrow().faults.clone();
    let report = server.shutdown().await;
    let robot = report.sim_robot.expect("the simulated robot comes back");

    let last = last.expect("records");
    let (base_rss, base_tasks) = baseline.expect("baseline taken after hour 1");
    let (first_rmse, _) = prediction_rmse(&first_hour, gamma);
    let (last_rmse, last_constant) = prediction_rmse(&last_hour, gamma);
    let mut lengths = outages.lengths_ticks.clone();
    lengths.sort_unstable();
    let pct = |q: f64| {
        lengths
            .get(((lengths.len() as f64 - 1.0) * q).round() as usize)
            .map_or(0, |t| t * 20)
    };
    eprintln!(
        "soak report: {hours} h in {:.0} s wall\n\
         faults injected: {}\n\
         link: {} good / {} bad frames, {} stale events, {} reconnects, trips re-armed {rearms}\n\
         outages: {} (p50 {} ms, p90 {} ms, max {} ms); longest unattended motion {} ticks\n\
         memory: rss {base_rss} KiB after hour 1 → {} KiB at the end; tasks {base_tasks} → {}\n\
         prediction rmse vs return: first hour {first_rmse:.4}, last hour {last_rmse:.4} \
         (best constant prediction: {last_constant:.4})",
        started.elapsed().as_secs_f64(),
        serde_json::to_string(&faults).unwrap_or_default(),
        last.link.good_frames,
        last.link.bad_frames,
        last.link.stale_events,
        last.link.reconnects,
        lengths.len(),
        pct(0.5),
        pct(0.9),
        pct(1.0),
        longest_unattended,
        end.0,
        end.1,
    );

    // Faults really happened, and each kind was survived.
    assert!(faults.hangs >= hours as u64, "hangs: {}", faults.hangs);
    assert!(
        faults.eofs >= hours as u64,
        "end-of-file events: {}",
        faults.eofs
    );
    assert!(faults.dropped_bytes + faults.flipped_bytes + faults.duplicated_bytes > 0);
    assert!(faults.text_lines > 0 && faults.bursts > 0);
    assert!(faults.host_flipped > 0 && faults.host_dropped > 0);
    assert!(
        last.link.reconnects >= faults.eofs / 2,
        "reconnects {}",
        last.link.reconnects
    );
    assert!(last.link.bad_frames > 0);
    // Up at the end, and every outage ended (none still running).
    assert_eq!(last.link.state, LinkState::Up, "link at the end");
    assert_eq!(outages.current, 0);
    assert!(pct(1.0) <= 10_000, "an outage lasted {} ms", pct(1.0));
    // The robot was never left moving for long while the host had no stream and could reach it: the stops
    // the host writes every tick land within a few ticks (motor spin-down included).
    assert!(
        longest_unattended <= 25,
        "the robot moved for {longest_unattended} ticks while the host had no stream"
    );
    // Bounded: memory and tasks flat between hour 1 and the end.
    assert!(
        end.0 <= base_rss + 16 * 1024,
        "memory grew from {base_rss} KiB to {} KiB",
        end.0
    );
    assert!(
        end.1 <= base_tasks + 2,
        "tasks grew from {base_tasks} to {}",
        end.1
    );
    // Learning still converging: no worse at the end than after the first hour.
    assert!(last_rmse.is_finite() && first_rmse.is_finite());
    assert!(
        last_rmse <= first_rmse * 1.05,
        "prediction error grew: {first_rmse:.4} → {last_rmse:.4}"
    );
    assert!(
        last_rmse < 0.8 * last_constant,
        "the prediction ({last_rmse:.4}) is barely better than a constant ({last_constant:.4})"
    );
    // And the robot was left stopped.
    let w = robot.world();
    assert_eq!((w.wheel_speed_mm_s(0), w.wheel_speed_mm_s(1)), (0.0, 0.0));
}
