//! The ticker: the only clock that drives control.
//!
//! It publishes a [`Tick`] every period (20 ms) on a `watch` channel, so a consumer always sees the newest
//! tick and never a backlog. When it wakes later than a period, the ticks it missed are skipped and
//! counted, never fired in a burst (tokio's `MissedTickBehavior::Skip`; [`schedule`] is that arithmetic).
//! Every tick's lateness is kept in a histogram that the runtime logs once a minute and serves on
//! `/metrics`.
//!
//! Two timers can drive it, chosen by [`spawn`]:
//! - [`thread`]: in real time, by default (`[tick] timer = "thread"`): a dedicated OS thread sleeping to
//!   absolute deadlines (`clock_nanosleep`), tens of µs late instead of tokio's millisecond;
//! - [`interval`]: tokio's interval, under tokio's paused clock always, and in real time with
//!   `[tick] timer = "tokio"` (kept for comparison: `pavlov bench --compare-timers`).
//!
//! **Virtual time keeps tokio's interval.** Tests and experiments run the server under tokio's paused
//! clock, which moves only when the runtime advances it; a thread sleeping in real time would tick
//! outside that clock and make runs nondeterministic. tokio has no public "is paused" query, so
//! [`clock_is_paused`] asks the clock itself: it reads tokio's `Instant::now()`, sleeps the OS thread for
//! a microsecond and reads it again. A running clock has moved by at least that microsecond; a paused one
//! has not moved at all, because it moves only by `advance` or auto-advance, and both happen only while
//! the runtime awaits, never inside a synchronous call (and a paused clock needs the single-threaded
//! runtime, so no other worker runs meanwhile). The choice is made once, when the pipeline starts; a
//! clock paused later is not supported in real time.

pub(crate) mod interval;
pub(crate) mod schedule;
pub(crate) mod thread;

use std::time::Duration;

use pavlov::config::{TickConfig, TickTimer};
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::telemetry::counters::SharedTickStats;

/// One control tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Tick {
    /// Sequence number: `(deadline − start) / period`. Gaps mean skipped ticks.
    pub(crate) seq: u64,
    /// When the tick was due.
    pub(crate) deadline: Instant,
    /// When the ticker actually ran.
    pub(crate) fired: Instant,
}

impl Tick {
    /// How late the tick fired.
    pub(crate) fn lateness(&self) -> Duration {
        self.fired.saturating_duration_since(self.deadline)
    }
}

/// A started ticker.
pub(crate) struct Ticker {
    /// The timer that drives it.
    pub(crate) timer: TickTimer,
    /// Finishes when the ticker has stopped.
    pub(crate) task: JoinHandle<()>,
}

/// Starts the ticker of `config`, its first tick due at `start`; it stops when `cancel` fires. The thread
/// timer is used in real time when configured (and if its thread starts); tokio's interval otherwise.
pub(crate) fn spawn(
    config: &TickConfig,
    start: Instant,
    tx: watch::Sender<Option<Tick>>,
    stats: SharedTickStats,
    cancel: CancellationToken,
) -> Ticker {
    let period = Duration::from_millis(config.period_ms);
    let spin = Duration::from_micros(u64::from(config.spin_us));
    if config.timer == TickTimer::Thread {
        if clock_is_paused() {
            tracing::debug!("virtual time: tokio's interval drives the tick");
        } else {
            let spawned = thread::spawn(
                start,
                period,
                spin,
                tx.clone(),
                stats.clone(),
                cancel.clone(),
            );
            match spawned {
                Ok(task) => {
                    tracing::info!(
                        thread = thread::THREAD_NAME,
                        spin_us = config.spin_us,
                        "the tick runs on its own timer thread"
                    );
                    return Ticker {
                        timer: TickTimer::Thread,
                        task,
                    };
                }
                Err(e) => tracing::warn!(
                    "cannot start the tick thread ({e}): tokio's interval drives the tick"
                ),
            }
        }
    }
    Ticker {
        timer: TickTimer::Tokio,
        task: tokio::spawn(interval::run(start, period, tx, stats, cancel)),
    }
}

/// Whether tokio's clock is paused in the current runtime (see the module doc for why this is sound).
/// Blocks the calling thread for about a microsecond.
pub(crate) fn clock_is_paused() -> bool {
    let before = Instant::now();
    std::thread::sleep(Duration::from_micros(1));
    Instant::now() == before
}

/// Counts `tick` (and the `skipped` ticks before it) and publishes it; false when nobody listens.
fn publish(
    tick: Tick,
    skipped: u64,
    stats: &SharedTickStats,
    tx: &watch::Sender<Option<Tick>>,
) -> bool {
    if let Ok(mut s) = stats.lock() {
        s.fired += 1;
        s.skipped += skipped;
        s.lateness.record(tick.lateness());
    }
    if skipped > 0 {
        tracing::debug!(seq = tick.seq, skipped, "ticker skipped ticks");
    }
    tx.send(Some(tick)).is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Starts a ticker with `config`, checks which timer drives it and that it fires, then stops it.
    async fn fires_on(config: &TickConfig, expected: TickTimer) {
        let (tx, mut rx) = watch::channel(None);
        let cancel = CancellationToken::new();
        let ticker = spawn(
            config,
            Instant::now(),
            tx,
            SharedTickStats::default(),
            cancel.clone(),
        );
        assert_eq!(ticker.timer, expected);
        rx.changed().await.unwrap();
        cancel.cancel();
        ticker.task.await.unwrap();
    }

    #[tokio::test(start_paused = true)]
    async fn a_paused_clock_is_detected_and_keeps_tokios_interval() {
        assert!(clock_is_paused());
        fires_on(&TickConfig::default(), TickTimer::Tokio).await;
    }

    #[tokio::test]
    async fn a_running_clock_is_detected_and_gets_the_thread() {
        assert!(!clock_is_paused());
        fires_on(&TickConfig::default(), TickTimer::Thread).await;
    }

    #[tokio::test]
    async fn timer_tokio_keeps_tokios_interval_in_real_time() {
        let config = TickConfig {
            timer: TickTimer::Tokio,
            ..TickConfig::default()
        };
        fires_on(&config, TickTimer::Tokio).await;
    }
}
