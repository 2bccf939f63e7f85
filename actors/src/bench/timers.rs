//! `pavlov bench --compare-timers`: tick lateness and tick → command with the timer thread and with
//! tokio's interval, side by side in one invocation.
//!
//! The machine's load changes while a benchmark runs (the project's 2 cores are shared), so the two
//! timers are not measured one after the other but interleaved: thread, tokio, tokio, thread, each a
//! fresh server on the simulated Create for half of the requested time, and each timer's two halves
//! merged into one histogram. The 1-minute load average is read from `/proc/loadavg` before and after.
//! A benchmark, not a test: it prints figures and asserts nothing about them.

use std::fmt;
use std::time::Duration;

use pavlov::config::{Config, TickTimer};

use super::load_average;
use crate::server::{RobotTarget, Server, ServerError};
use crate::telemetry::histogram::{LatencyHistogram, LatencyQuantiles};

/// What one timer measured over its runs.
#[derive(Clone, Default)]
pub struct TimerRun {
    /// Real time run.
    duration: Duration,
    /// Ticks fired.
    ticks: u64,
    /// Ticks skipped.
    skipped: u64,
    /// Lateness of each tick.
    lateness: LatencyHistogram,
    /// Tick deadline → motor command written.
    to_command: LatencyHistogram,
    /// Runs in which the server used another timer than asked (the thread could not start).
    substituted: u32,
}

impl TimerRun {
    fn add(&mut self, other: &TimerRun) {
        self.duration += other.duration;
        self.ticks += other.ticks;
        self.skipped += other.skipped;
        self.lateness.merge(&other.lateness);
        self.to_command.merge(&other.to_command);
        self.substituted += other.substituted;
    }

    /// Tick lateness quantiles.
    pub(crate) fn lateness(&self) -> LatencyQuantiles {
        self.lateness.quantiles()
    }

    /// Tick → command quantiles.
    pub(crate) fn tick_to_command(&self) -> LatencyQuantiles {
        self.to_command.quantiles()
    }
}

/// Both timers, measured interleaved.
pub struct TimerComparison {
    /// The timer thread.
    pub(crate) thread: TimerRun,
    /// tokio's interval.
    pub(crate) tokio: TimerRun,
    /// The thread's spin before each deadline, µs.
    spin_us: u32,
    /// The 1-minute load average before and after (`None` where `/proc/loadavg` is unreadable).
    load: (Option<f64>, Option<f64>),
}

/// Runs the server on the simulated robot with each timer for `duration` in all, interleaved.
pub async fn run_timer_comparison(
    config: Config,
    duration: Duration,
) -> Result<TimerComparison, ServerError> {
    let half = duration / 2;
    let before = load_average();
    let mut thread = TimerRun::default();
    let mut tokio = TimerRun::default();
    for timer in [
        TickTimer::Thread,
        TickTimer::Tokio,
        TickTimer::Tokio,
        TickTimer::Thread,
    ] {
        let run = run_one(&config, timer, half).await?;
        match timer {
            TickTimer::Thread => thread.add(&run),
            TickTimer::Tokio => tokio.add(&run),
        }
    }
    Ok(TimerComparison {
        thread,
        tokio,
        spin_us: config.tick.spin_us,
        load: (before, load_average()),
    })
}

/// One server run with `timer` for `duration` of real time.
async fn run_one(
    config: &Config,
    timer: TickTimer,
    duration: Duration,
) -> Result<TimerRun, ServerError> {
    let mut config = config.clone();
    config.tick.timer = timer;
    let server = Server::builder(config, RobotTarget::Simulated)
        .start()
        .await?;
    let start = std::time::Instant::now();
    tokio::time::sleep(duration).await;
    let health = server.health();
    let figures = health.figures();
    let (lateness, to_command) = health.histograms();
    let run = TimerRun {
        duration: start.elapsed(),
        ticks: figures.ticks_fired,
        skipped: figures.ticks_skipped,
        lateness,
        to_command,
        substituted: u32::from(health.tick_timer() != timer),
    };
    server.shutdown().await;
    Ok(run)
}

/// `a / b` to one decimal; when `b` is 0 (under the histogram's 1 µs resolution), a bound: `> a×`.
fn ratio(a: u64, b: u64) -> String {
    if b == 0 {
        format!("> {a}×")
    } else {
        format!("{:.1}×", a as f64 / b as f64)
    }
}

impl fmt::Display for TimerComparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |l: Option<f64>| l.map_or("?".into(), |v| format!("{v:.2}"));
        writeln!(
            f,
            "tick timers, interleaved (thread, tokio, tokio, thread); spin {} µs; load average (1 min) {} before, {} after",
            self.spin_us,
            show(self.load.0),
            show(self.load.1)
        )?;
        for (name, run) in [("thread", &self.thread), ("tokio", &self.tokio)] {
            writeln!(
                f,
                "{name:>6}: {:.1} s, {} ticks fired, {} skipped{}",
                run.duration.as_secs_f64(),
                run.ticks,
                run.skipped,
                if run.substituted > 0 {
                    format!(" ({} runs fell back to tokio's interval)", run.substituted)
                } else {
                    String::new()
                }
            )?;
        }
        writeln!(
            f,
            "{:<26}{:>10}{:>10}{:>16}",
            "µs", "thread", "tokio", "tokio / thread"
        )?;
        let (tl, kl) = (self.thread.lateness(), self.tokio.lateness());
        let (tc, kc) = (self.thread.tick_to_command(), self.tokio.tick_to_command());
        let rows = [
            ("tick lateness p50", tl.p50_us, kl.p50_us),
            ("tick lateness p99", tl.p99_us, kl.p99_us),
            ("tick lateness max", tl.max_us, kl.max_us),
            ("tick → command p50", tc.p50_us, kc.p50_us),
            ("tick → command p99", tc.p99_us, kc.p99_us),
            ("tick → command max", tc.max_us, kc.max_us),
        ];
        for (name, thread, tokio) in rows {
            writeln!(
                f,
                "{name:<26}{thread:>10}{tokio:>10}{:>16}",
                ratio(tokio, thread)
            )?;
        }
        Ok(())
    }
}
