//! `pavlov bench --horde`: the server with a Horde against the same server without one, in real time.
//!
//! The question is whether many predictions learned beside control cost control anything. The same
//! configuration runs with its `[horde]` and with `[horde]` removed, interleaved (Horde, plain, plain,
//! Horde, each a fresh server on the simulated Create for half of the requested time) because the
//! project's 2 cores are shared and the load drifts; each side's two halves are merged. Both sides write
//! checkpoints into a temporary folder every third of a half, so each Horde run copies and writes at
//! least one Horde checkpoint while it learns; the skipped ticks are counted inside and outside those
//! checkpoints. A benchmark, not a test: it prints what it measured and says which goal was missed.

use std::fmt;
use std::path::Path;
use std::time::{Duration, Instant};

use pavlov::config::{Config, HordeConfig};

use super::load_average;
use crate::horde::status::HordeStatus;
use crate::server::{RobotTarget, Server, ServerError};
use crate::storage::horde_file;
use crate::telemetry::histogram::{LatencyHistogram, LatencyQuantiles};

/// How often the run is sampled while it runs.
const SAMPLE: Duration = Duration::from_millis(100);
/// The goal on tick → command p99, Horde over plain.
const P99_GOAL: f64 = 1.2;

/// One side (with or without the Horde), its runs merged.
#[derive(Clone, Default)]
pub struct Side {
    duration: Duration,
    /// The process's CPU time (user + system, every thread) over the runs.
    cpu: Duration,
    ticks: u64,
    skipped: u64,
    lateness: LatencyHistogram,
    to_command: LatencyHistogram,
    /// The Horde's figures at the end of each run (empty without a Horde).
    hordes: Vec<HordeStatus>,
    /// The checkpoints each run copied and wrote, with the Horde's skipped ticks around them.
    checkpoints: Vec<CheckpointWindow>,
    /// Skipped ticks and seconds outside checkpoints.
    skipped_outside: u64,
    outside: Duration,
    /// Checkpoints asked for too near a run's end to be written, not counted.
    too_late: usize,
}

/// One Horde checkpoint as seen from outside: from the tick learning asked for it until its file was
/// there (plus one status period, since the Horde publishes its figures every half second).
#[derive(Clone, Debug)]
struct CheckpointWindow {
    /// Seconds into the run it was asked for.
    at: f64,
    /// Seconds until its file was there (`None`: it was not written before the run ended).
    took: Option<f64>,
    /// The Horde's skipped ticks in the window.
    skipped: u64,
}

/// The Horde's run beside the plain run.
pub struct HordeComparison {
    horde: Side,
    plain: Side,
    load: (Option<f64>, Option<f64>),
    predictions: usize,
}

/// Runs `config` with and without its `[horde]` for `duration` each, interleaved.
pub async fn run_horde_comparison(
    config: Config,
    duration: Duration,
) -> Result<HordeComparison, ServerError> {
    let half = duration / 2;
    let before = load_average();
    let dir = std::env::temp_dir().join(format!("pavlov-bench-horde-{}", std::process::id()));
    let mut horde = Side::default();
    let mut plain = Side::default();
    let mut plain_config = config.clone();
    plain_config.horde = HordeConfig::default();
    for (i, with_horde) in [true, false, false, true].into_iter().enumerate() {
        let base = if with_horde { &config } else { &plain_config };
        let cpu_before = process_cpu_time();
        let run = run_one(base, &dir.join(format!("run{i}")), half).await;
        let cpu = process_cpu_time().saturating_sub(cpu_before);
        let _ = std::fs::remove_dir_all(&dir);
        let mut run = run?;
        run.cpu = cpu;
        let side = if with_horde { &mut horde } else { &mut plain };
        side.add(run);
    }
    let predictions = horde.hordes.first().map_or(0, |h| h.predictions);
    Ok(HordeComparison {
        horde,
        plain,
        load: (before, load_average()),
        predictions,
    })
}

/// The CPU time (user + system) of every thread of this process so far.
fn process_cpu_time() -> Duration {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: `getrusage` writes one `rusage` into the zeroed buffer, which outlives the call.
    let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) };
    if rc != 0 {
        return Duration::ZERO;
    }
    // SAFETY: zeroed is a valid `rusage` (plain integers), and the call succeeded.
    let usage = unsafe { usage.assume_init() };
    let tv = |t: libc::timeval| {
        Duration::from_secs(u64::try_from(t.tv_sec).unwrap_or(0))
            + Duration::from_micros(u64::try_from(t.tv_usec).unwrap_or(0))
    };
    tv(usage.ru_utime) + tv(usage.ru_stime)
}

impl Side {
    fn add(&mut self, run: Side) {
        self.duration += run.duration;
        self.cpu += run.cpu;
        self.ticks += run.ticks;
        self.skipped += run.skipped;
        self.lateness.merge(&run.lateness);
        self.to_command.merge(&run.to_command);
        self.hordes.extend(run.hordes);
        self.checkpoints.extend(run.checkpoints);
        self.skipped_outside += run.skipped_outside;
        self.outside += run.outside;
        self.too_late += run.too_late;
    }
}

/// What the sampler saw at one instant.
struct Sample {
    at: Instant,
    ticks: u64,
    horde_skipped: u64,
    horde_files: usize,
}

/// One fresh server on `config` (checkpointing into `dir`) for `duration`.
async fn run_one(config: &Config, dir: &Path, duration: Duration) -> Result<Side, ServerError> {
    let mut config = config.clone();
    let every_s = (duration.as_secs() / 3).max(1);
    config.checkpoint.dir = dir.display().to_string();
    config.checkpoint.autosave = true;
    config.checkpoint.every_s = every_s;
    config.checkpoint.keep = 1000;
    let server = Server::builder(config.clone(), RobotTarget::Simulated)
        .start()
        .await?;
    let run_dir = server.checkpoints().run_dir.clone();
    let status = server.horde().as_ref().map(|h| h.status.clone());
    let health = server.health();
    let start = Instant::now();
    let mut samples = Vec::new();
    let mut sample_tick = tokio::time::interval(SAMPLE);
    while start.elapsed() < duration {
        sample_tick.tick().await;
        samples.push(Sample {
            at: Instant::now(),
            ticks: health.figures().ticks_fired,
            horde_skipped: status.as_ref().map_or(0, |s| s.borrow().skipped_busy),
            horde_files: run_dir.as_deref().map_or(0, count_horde_files),
        });
    }
    let figures = health.figures();
    let (lateness, to_command) = health.histograms();
    let hordes: Vec<HordeStatus> = status.iter().map(|s| s.borrow().clone()).collect();
    let (mut checkpoints, skipped_outside, outside) = if status.is_some() {
        let period_ms = config.tick.period_ms.max(1);
        windows(&samples, start, every_s * 1000 / period_ms)
    } else {
        (Vec::new(), 0, Duration::ZERO)
    };
    // One asked for in the run's last half period has no time to be written: not counted.
    let before = checkpoints.len();
    checkpoints.retain(|c| c.at + every_s as f64 / 2.0 < duration.as_secs_f64());
    let too_late = before - checkpoints.len();
    let run = Side {
        duration: start.elapsed(),
        cpu: Duration::ZERO,
        ticks: figures.ticks_fired,
        skipped: figures.ticks_skipped,
        lateness,
        to_command,
        hordes,
        checkpoints,
        skipped_outside,
        outside,
        too_late,
    };
    server.shutdown().await;
    Ok(run)
}

fn count_horde_files(dir: &Path) -> usize {
    horde_file::list(dir).map_or(0, |files| files.len())
}

/// The checkpoint windows in `samples` (the k-th asked for at tick `k · every_ticks`, done when the k-th
/// file is there), and the skipped ticks and time outside them.
fn windows(
    samples: &[Sample],
    start: Instant,
    every_ticks: u64,
) -> (Vec<CheckpointWindow>, u64, Duration) {
    let mut out = Vec::new();
    let mut inside = vec![false; samples.len()];
    let status_period = (Duration::from_millis(500).as_millis() / SAMPLE.as_millis()) as usize;
    let every_ticks = every_ticks.max(1);
    for k in 1.. {
        let asked_tick = k as u64 * every_ticks;
        // The last sample before the tick that asked for it.
        let Some(first) = samples.iter().rposition(|s| s.ticks < asked_tick) else {
            break;
        };
        if first + 1 >= samples.len() {
            break;
        }
        let done = samples[first..].iter().position(|s| s.horde_files >= k);
        let last = done.map_or(samples.len() - 1, |d| {
            (first + d + status_period).min(samples.len() - 1)
        });
        for flag in &mut inside[first..=last] {
            *flag = true;
        }
        out.push(CheckpointWindow {
            at: (samples[first].at - start).as_secs_f64(),
            took: done.map(|d| (samples[first + d].at - samples[first].at).as_secs_f64()),
            skipped: samples[last].horde_skipped - samples[first].horde_skipped,
        });
    }
    let mut skipped_outside = 0;
    let mut outside = Duration::ZERO;
    for (i, pair) in samples.windows(2).enumerate() {
        if !inside[i] || !inside[i + 1] {
            skipped_outside += pair[1].horde_skipped - pair[0].horde_skipped;
            outside += pair[1].at - pair[0].at;
        }
    }
    (out, skipped_outside, outside)
}

impl fmt::Display for HordeComparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |l: Option<f64>| l.map_or("?".into(), |v| format!("{v:.2}"));
        writeln!(
            f,
            "Horde ({} predictions) against the same server without [horde], interleaved (Horde, plain, plain, Horde); load average (1 min) {} before, {} after",
            self.predictions,
            show(self.load.0),
            show(self.load.1)
        )?;
        for (name, side) in [("Horde", &self.horde), ("plain", &self.plain)] {
            writeln!(
                f,
                "{name:>6}: {:.1} s wall, {:.1} s CPU (user + system, all threads), {} ticks fired, {} skipped by the ticker",
                side.duration.as_secs_f64(),
                side.cpu.as_secs_f64(),
                side.ticks,
                side.skipped
            )?;
        }
        writeln!(f, "the Horde's learner, each Horde run:")?;
        writeln!(
            f,
            "{:>6}{:>18}{:>10}{:>10}{:>18}{:>10}{:>10}{:>16}{:>14}{:>10}",
            "run",
            "step CPU µs p50",
            "p99",
            "max",
            "step wall µs p50",
            "p99",
            "learned",
            "skipped",
            "chain breaks",
            "stopped"
        )?;
        for (i, h) in self.horde.hordes.iter().enumerate() {
            writeln!(
                f,
                "{:>6}{:>18}{:>10}{:>10}{:>18}{:>10}{:>10}{:>16}{:>14}{:>10}",
                i + 1,
                h.step_cpu.p50_us,
                h.step_cpu.p99_us,
                h.step_cpu.max_us,
                h.step.p50_us,
                h.step.p99_us,
                h.ticks_learned,
                format!(
                    "{} ({:.1} %)",
                    h.skipped_busy,
                    percent(h.skipped_busy, h.ticks_learned + h.skipped_busy)
                ),
                h.chain_breaks,
                h.stopped
            )?;
        }
        writeln!(
            f,
            "{:<24}{:>10}{:>10}{:>14}",
            "µs", "Horde", "plain", "Horde / plain"
        )?;
        let (hl, pl) = (
            self.horde.lateness.quantiles(),
            self.plain.lateness.quantiles(),
        );
        let (hc, pc) = (
            self.horde.to_command.quantiles(),
            self.plain.to_command.quantiles(),
        );
        let rows: [Row; 6] = [
            ("tick lateness p50", &hl, &pl, |q| q.p50_us),
            ("tick lateness p99", &hl, &pl, |q| q.p99_us),
            ("tick lateness max", &hl, &pl, |q| q.max_us),
            ("tick → command p50", &hc, &pc, |q| q.p50_us),
            ("tick → command p99", &hc, &pc, |q| q.p99_us),
            ("tick → command max", &hc, &pc, |q| q.max_us),
        ];
        for (name, h, p, get) in rows {
            writeln!(
                f,
                "{name:<24}{:>10}{:>10}{:>14}",
                get(h),
                get(p),
                ratio(get(h), get(p))
            )?;
        }
        let p99 = hc.p99_us as f64 / pc.p99_us.max(1) as f64;
        writeln!(
            f,
            "goal tick → command p99 Horde / plain ≤ {P99_GOAL}: {:.2}, {}",
            p99,
            if p99 <= P99_GOAL { "met" } else { "MISSED" }
        )?;
        let learned: u64 = self.horde.hordes.iter().map(|h| h.ticks_learned).sum();
        let skipped: u64 = self.horde.hordes.iter().map(|h| h.skipped_busy).sum();
        writeln!(
            f,
            "goal every tick learned by the Horde: {}",
            if skipped == 0 && learned > 0 {
                "met".to_string()
            } else {
                format!("MISSED ({skipped} of {} ticks skipped)", learned + skipped)
            }
        )?;
        self.fmt_checkpoints(f)
    }
}

impl HordeComparison {
    fn fmt_checkpoints(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let side = &self.horde;
        let outside_s = side.outside.as_secs_f64();
        let rate = if outside_s > 0.0 {
            side.skipped_outside as f64 / outside_s
        } else {
            0.0
        };
        writeln!(
            f,
            "Horde checkpoints (asked for every third of a run; window: asked → file written, + 0.5 s):"
        )?;
        let mut worst = Verdict::Met;
        for c in &side.checkpoints {
            let (took, width) = match c.took {
                Some(t) => (format!("written {t:.1} s later"), t + 0.5),
                None => ("NOT written before the run ended".into(), 0.0),
            };
            let expected = rate * width;
            writeln!(
                f,
                "  at {:>5.1} s: {took}; the Horde skipped {} ticks in the window ({expected:.1} expected at its rate outside checkpoints)",
                c.at, c.skipped
            )?;
            let verdict = match (c.took, c.skipped) {
                (None, _) => Verdict::Missed,
                (Some(_), 0) => Verdict::Met,
                (Some(_), n) if (n as f64) <= expected + 2.0 * expected.sqrt() => Verdict::NotShown,
                _ => Verdict::Missed,
            };
            worst = worst.max(verdict);
        }
        writeln!(
            f,
            "  outside checkpoints: {} skipped in {outside_s:.1} s ({rate:.2} a second); {} asked for in a run's last half period not counted",
            side.skipped_outside, side.too_late
        )?;
        let says = if side.checkpoints.is_empty() {
            "NOT SHOWN (no checkpoint was asked for: run longer)"
        } else {
            match worst {
                Verdict::Met => "met",
                Verdict::NotShown => {
                    "NOT SHOWN (the Horde skips ticks outside checkpoints too; within the window no more than that rate explains)"
                }
                Verdict::Missed => "MISSED",
            }
        };
        writeln!(f, "goal a checkpoint adds no skipped tick: {says}")
    }
}

/// A row of the comparison: its name, both sides' quantiles, and which quantile.
type Row<'a> = (
    &'a str,
    &'a LatencyQuantiles,
    &'a LatencyQuantiles,
    fn(&LatencyQuantiles) -> u64,
);

#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Verdict {
    Met,
    NotShown,
    Missed,
}

fn percent(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

/// `a / b` to two decimals; when `b` is 0 (under the histogram's 1 µs resolution), a bound.
fn ratio(a: u64, b: u64) -> String {
    if b == 0 {
        format!("> {a}×")
    } else {
        format!("{:.2}×", a as f64 / b as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(start: Instant, rows: &[(u64, u64, usize)]) -> Vec<Sample> {
        rows.iter()
            .enumerate()
            .map(|(i, &(ticks, horde_skipped, horde_files))| Sample {
                at: start + SAMPLE * i as u32,
                ticks,
                horde_skipped,
                horde_files,
            })
            .collect()
    }

    #[test]
    fn skipped_ticks_are_split_into_checkpoint_windows_and_the_rest() {
        let start = Instant::now();
        // A checkpoint asked for at tick 20, its file there two samples later; one skip before it,
        // two inside its window (which runs five samples past the file), one long after.
        let mut rows = vec![(0, 0, 0), (5, 1, 0), (10, 1, 0), (15, 1, 0), (20, 2, 0)];
        rows.extend([(22, 3, 0), (24, 3, 1)]);
        rows.extend((0..5).map(|i| (26 + 2 * i, 3, 1)));
        rows.extend([(36, 3, 1), (38, 4, 1)]);
        let s = samples(start, &rows);
        let (w, outside_skipped, outside) = windows(&s, start, 20);
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].skipped, 2);
        assert!((w[0].at - 0.3).abs() < 1e-9, "{w:?}");
        assert!((w[0].took.unwrap() - 0.3).abs() < 1e-9, "{w:?}");
        assert_eq!(outside_skipped, 2);
        // Pairs outside: 0-1, 1-2, 2-3 before the window (it starts at sample 3), 11-12, 12-13 after.
        assert_eq!(outside, SAMPLE * 5);
    }

    #[test]
    fn a_checkpoint_never_written_is_a_window_to_the_end() {
        let start = Instant::now();
        let s = samples(start, &[(0, 0, 0), (10, 0, 0), (20, 1, 0), (24, 2, 0)]);
        let (w, _, _) = windows(&s, start, 15);
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].took, None);
        assert_eq!(w[0].skipped, 2);
    }
}
