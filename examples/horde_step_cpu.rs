//! The CPU time of one Horde step for `config/horde.toml`'s families (11,892 predictions, 69 M `f32`
//! weights), the one-pass step ([`Horde::step`]) against the two-pass step it replaced
//! ([`Horde::step_two_passes`]), interleaved tick by tick on two Hordes fed the same seeded stream so that
//! the machine's load falls on both alike; checks that they predict the same values, bit for bit.
//!
//! `cargo run --release -p pavlov --example horde_step_cpu [-- TICKS]` (default 400 ticks each).
//! Prints p50 / p99 / max of the thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`) and of the wall time per
//! step, and the load average before and after.

use std::time::{Duration, Instant};

use pavlov::config::Config;
use pavlov::learn::{Horde, TickSignals};
use pavlov::rng::Rng;

fn thread_cpu() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `clock_gettime` writes one `timespec` into `ts`, which outlives the call.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "CLOCK_THREAD_CPUTIME_ID");
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

fn quantiles(mut v: Vec<Duration>) -> String {
    v.sort();
    let at = |q: f64| v[((v.len() as f64 - 1.0) * q).round() as usize].as_micros();
    format!("{:>6} / {:>6} / {:>6}", at(0.5), at(0.99), at(1.0))
}

fn main() {
    let ticks: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(400);
    let config = Config::from_toml(include_str!("../config/horde.toml"))
        .expect("config/horde.toml is valid");
    let names = config.signal_names();
    let mut one: Horde<f32> =
        Horde::new(config.horde.families.clone(), &names).expect("the Horde fits");
    let mut two = one.clone();
    let shape = one.shape();
    println!(
        "{} predictions, {} weights, {} groups; {} ticks each, interleaved; load average {} before",
        shape.predictions,
        shape.weights,
        shape.groups,
        ticks,
        load()
    );
    let dims = names.obs.len();
    let mut rng = Rng::new(7);
    let mut obs: Vec<f64> = (0..dims).map(|_| rng.next_f64()).collect();
    let raw = vec![0.0; dims];
    let extra = vec![0.0; names.extra.len()];
    let mut stimuli = vec![false; names.stimuli.len()];
    let (mut cpu1, mut cpu2, mut wall1, mut wall2) = (vec![], vec![], vec![], vec![]);
    let (mut v1, mut v2) = (Vec::new(), Vec::new());
    let mut differ = 0usize;
    for t in 0..ticks {
        for v in &mut obs {
            if rng.chance(0.05) {
                *v = rng.next_f64();
            }
        }
        stimuli.iter_mut().for_each(|s| *s = rng.chance(0.02));
        let signals = TickSignals {
            obs: &obs,
            raw: &raw,
            extra: &extra,
            stimuli: &stimuli,
        };
        // Alternate which goes first, so neither always finds the other's rows in the cache.
        let order: [bool; 2] = if t % 2 == 0 {
            [true, false]
        } else {
            [false, true]
        };
        for fused in order {
            let (c0, w0) = (thread_cpu(), Instant::now());
            if fused {
                one.step(&signals);
                cpu1.push(thread_cpu() - c0);
                wall1.push(w0.elapsed());
            } else {
                two.step_two_passes(&signals);
                cpu2.push(thread_cpu() - c0);
                wall2.push(w0.elapsed());
            }
        }
        one.values_into(&mut v1);
        two.values_into(&mut v2);
        differ += v1
            .iter()
            .zip(&v2)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
    }
    // The first ticks fault the pages in and warm the caches: left out.
    let skip = (ticks / 10).min(50);
    let tail = |v: Vec<Duration>| v.into_iter().skip(skip).collect::<Vec<_>>();
    println!("µs per step, p50 / p99 / max (first {skip} ticks left out):");
    println!(
        "  one pass:  CPU {}   wall {}",
        quantiles(tail(cpu1)),
        quantiles(tail(wall1))
    );
    println!(
        "  two passes: CPU {}   wall {}",
        quantiles(tail(cpu2)),
        quantiles(tail(wall2))
    );
    println!("values that differ between the two (bit for bit): {differ}");
    let huge = std::fs::read_to_string("/proc/self/smaps_rollup")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("AnonHugePages"))
                .map(str::to_string)
        })
        .unwrap_or_else(|| "AnonHugePages: ?".into());
    println!("{huge} (both Hordes); load average {} after", load());
}
