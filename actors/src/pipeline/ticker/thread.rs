//! The thread ticker: a dedicated OS thread, `pavlov-tick`, that sleeps to each tick's absolute deadline
//! with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)` and publishes the tick on the `watch` channel.
//!
//! tokio's timer wheel rounds to milliseconds, so its interval fires about 1 ms late; a thread sleeping to
//! an absolute deadline wakes within tens of µs of it (the kernel's high-resolution timers), and an
//! absolute deadline never drifts, however late a wake-up was. The thread also sets its timer slack to
//! 1 ns (`PR_SET_TIMERSLACK`; a normal thread's default lets the kernel defer its wake-ups by 50 µs), and
//! can wake `[tick] spin_us` early and spin to the deadline.
//!
//! It never waits on the async world: `watch::Sender::send` is synchronous and only wakes the receivers.
//! It numbers and skips ticks by the same [`Schedule`] arithmetic as tokio's `MissedTickBehavior::Skip`.
//! It checks the cancellation token before and after each sleep, so it stops at most one period (plus
//! the spin) after the server is cancelled, and also when nobody listens to its ticks any more; the task
//! [`spawn`] returns finishes when the thread has left its loop and dropped its sender.
//!
//! **Time frames.** Ticks carry tokio `Instant`s like everything else in the pipeline. When tokio's clock
//! is not paused its `Instant::now()` is std's `Instant::now()` (tokio reads `base + unfrozen.elapsed()`,
//! both taken at the same moment when the runtime starts; only a clock once paused and resumed is shifted
//! by the paused span), and std's `Instant` is `CLOCK_MONOTONIC` on Linux. [`Monotonic::anchored`]
//! samples the three clocks back to back once, so the thread maps the first deadline onto std's clock and
//! onto `CLOCK_MONOTONIC` exactly (up to the tens of ns between the reads) even in the shifted case. The
//! thread is never used under a paused clock (see the module [`super`]).

use std::time::Duration;

use nix::errno::Errno;
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::schedule::Schedule;
use super::{Tick, publish};
use crate::telemetry::counters::SharedTickStats;

/// The timer thread's name (as `top -H` and `/proc/<pid>/task/*/comm` show it).
pub(crate) const THREAD_NAME: &str = "pavlov-tick";

/// The tick loop's clock: offsets from the first tick's deadline. The real one is [`Monotonic`]; tests
/// inject their own to drive the loop through late wake-ups without timing anything.
pub(crate) trait TickClock {
    /// Time since the first tick's deadline (zero before it).
    fn now(&mut self) -> Duration;
    /// Returns at or after `due` (an offset from the first tick's deadline).
    fn sleep_until(&mut self, due: Duration);
}

/// `CLOCK_MONOTONIC`, anchored at the first tick's deadline.
pub(crate) struct Monotonic {
    /// The first deadline on std's clock.
    start_std: std::time::Instant,
    /// The first deadline on `CLOCK_MONOTONIC`, as time since that clock's origin.
    start_mono: Duration,
    /// How long before each deadline to stop sleeping and spin.
    spin: Duration,
    /// Whether `clock_nanosleep` has failed (other than by a signal) and the thread sleeps relatively.
    fell_back: bool,
}

impl Monotonic {
    /// Anchors `start`, a deadline on tokio's clock, to std's clock and `CLOCK_MONOTONIC`.
    pub(crate) fn anchored(start: Instant, spin: Duration) -> nix::Result<Self> {
        let tokio_now = Instant::now();
        let std_now = std::time::Instant::now();
        let mono_now = Duration::from(clock_gettime(ClockId::CLOCK_MONOTONIC)?);
        let (start_std, start_mono) = if start >= tokio_now {
            let ahead = start - tokio_now;
            (std_now + ahead, mono_now + ahead)
        } else {
            // The pipeline may start after the first deadline (a slow link open): it lies in the past.
            let behind = tokio_now - start;
            let start_std = std_now.checked_sub(behind).unwrap_or(std_now);
            (start_std, mono_now.saturating_sub(behind))
        };
        Ok(Monotonic {
            start_std,
            start_mono,
            spin,
            fell_back: false,
        })
    }

    /// Sleeps until `CLOCK_MONOTONIC` reaches `until_mono` (std's `until_std`), through signals.
    fn sleep_absolute(&mut self, until_mono: Duration, until_std: std::time::Instant) {
        if !self.fell_back {
            let request = TimeSpec::from_duration(until_mono);
            loop {
                match clock_nanosleep(
                    ClockId::CLOCK_MONOTONIC,
                    ClockNanosleepFlags::TIMER_ABSTIME,
                    &request,
                ) {
                    Ok(_) => return,
                    Err(Errno::EINTR) => continue,
                    Err(e) => {
                        tracing::warn!(
                            "clock_nanosleep failed ({e}): the tick thread sleeps relatively from now on"
                        );
                        self.fell_back = true;
                        break;
                    }
                }
            }
        }
        std::thread::sleep(until_std.saturating_duration_since(std::time::Instant::now()));
    }
}

impl TickClock for Monotonic {
    fn now(&mut self) -> Duration {
        self.start_std.elapsed()
    }

    fn sleep_until(&mut self, due: Duration) {
        let until_std = self.start_std + due;
        let wake = due.saturating_sub(self.spin);
        self.sleep_absolute(self.start_mono + wake, self.start_std + wake);
        while std::time::Instant::now() < until_std {
            std::hint::spin_loop();
        }
    }
}

/// Runs the tick loop on `clock` until `cancel` fires or nobody listens; the first tick is due at
/// `start` (tokio's clock), which is offset zero on `clock`.
pub(crate) fn tick_loop(
    clock: &mut impl TickClock,
    start: Instant,
    period: Duration,
    tx: watch::Sender<Option<Tick>>,
    stats: SharedTickStats,
    cancel: CancellationToken,
) {
    let mut schedule = Schedule::new(period);
    while !cancel.is_cancelled() {
        clock.sleep_until(schedule.due());
        if cancel.is_cancelled() {
            break;
        }
        let now = clock.now();
        let fired = schedule.fire(now);
        let tick = Tick {
            seq: fired.seq,
            deadline: start + fired.due,
            fired: start + now,
        };
        if !publish(tick, fired.skipped, &stats, &tx) {
            break; // nobody listens any more
        }
    }
}

/// Lets the kernel wake this thread at its deadline rather than up to 50 µs later.
fn precise_wake_ups() {
    if let Err(e) = nix::sys::prctl::set_timerslack(1) {
        tracing::warn!(
            "cannot set the tick thread's timer slack ({e}): wake-ups may be 50 µs later"
        );
    }
}

/// Starts the timer thread; the returned task finishes once the thread has stopped ticking. Fails when
/// the clock cannot be read or the thread cannot be started (the caller then uses tokio's interval).
pub(crate) fn spawn(
    start: Instant,
    period: Duration,
    spin: Duration,
    tx: watch::Sender<Option<Tick>>,
    stats: SharedTickStats,
    cancel: CancellationToken,
) -> std::io::Result<JoinHandle<()>> {
    let mut clock = Monotonic::anchored(start, spin).map_err(std::io::Error::from)?;
    let (done_tx, done_rx) = oneshot::channel::<()>();
    std::thread::Builder::new()
        .name(THREAD_NAME.into())
        .spawn(move || {
            precise_wake_ups();
            tick_loop(&mut clock, start, period, tx, stats, cancel);
            // The loop has dropped its sender; a panic drops `done_tx` unsent instead.
            let _ = done_tx.send(());
        })?;
    Ok(tokio::spawn(async move {
        if done_rx.await.is_err() {
            tracing::error!("the tick thread panicked");
        }
    }))
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    /// A clock that wakes each sleep at its deadline plus a scripted delay, notes the tick published
    /// before each sleep, and cancels the loop after its script.
    struct ScriptedClock {
        now: Duration,
        delays: VecDeque<Duration>,
        published: watch::Receiver<Option<Tick>>,
        seen: Vec<Tick>,
        cancel: CancellationToken,
    }

    impl TickClock for ScriptedClock {
        fn now(&mut self) -> Duration {
            self.now
        }

        fn sleep_until(&mut self, due: Duration) {
            if let Some(t) = *self.published.borrow_and_update() {
                self.seen.push(t);
            }
            match self.delays.pop_front() {
                Some(delay) => self.now = self.now.max(due) + delay,
                None => self.cancel.cancel(),
            }
        }
    }

    #[test]
    fn the_loop_publishes_consecutive_ticks_and_skips_after_a_late_wake_up() {
        let (tx, rx) = watch::channel(None);
        let stats = SharedTickStats::default();
        let cancel = CancellationToken::new();
        // Ticks 0–4 wake 70 µs late; tick 5 (due at 100 ms) wakes at 155 ms; then on time again.
        let mut delays: VecDeque<Duration> = vec![Duration::from_micros(70); 5].into();
        delays.extend([MS(55), MS(0), MS(0)]);
        let mut clock = ScriptedClock {
            now: Duration::ZERO,
            delays,
            published: rx,
            seen: Vec::new(),
            cancel: cancel.clone(),
        };
        let start = Instant::now();
        tick_loop(&mut clock, start, MS(20), tx, stats.clone(), cancel);
        let seqs: Vec<u64> = clock.seen.iter().map(|t| t.seq).collect();
        assert_eq!(seqs, vec![0, 1, 2, 3, 4, 5, 8, 9]);
        for t in &clock.seen {
            assert_eq!(t.deadline - start, MS(20) * t.seq as u32);
        }
        assert_eq!(clock.seen[0].lateness(), Duration::from_micros(70));
        assert_eq!(clock.seen[5].lateness(), MS(55));
        assert_eq!(clock.seen[6].lateness(), Duration::ZERO);
        let s = stats.lock().unwrap();
        assert_eq!((s.fired, s.skipped), (8, 2));
        assert_eq!(s.lateness.quantiles().count, 8);
    }

    #[test]
    fn the_loop_stops_when_nobody_listens() {
        let (tx, rx) = watch::channel(None);
        drop(rx);
        let cancel = CancellationToken::new();
        let mut clock = ScriptedClock {
            now: Duration::ZERO,
            delays: vec![Duration::ZERO; 100].into(),
            // A receiver of another channel: the loop's own has none left.
            published: watch::channel(None).1,
            seen: Vec::new(),
            cancel: cancel.clone(),
        };
        let stats = SharedTickStats::default();
        tick_loop(
            &mut clock,
            Instant::now(),
            MS(20),
            tx,
            stats.clone(),
            cancel,
        );
        assert_eq!(stats.lock().unwrap().fired, 1);
        assert_eq!(clock.delays.len(), 99, "it stopped after the first tick");
    }

    #[tokio::test]
    async fn the_thread_ticks_on_the_schedule_and_stops_on_cancel() {
        let (tx, mut rx) = watch::channel(None);
        let stats = SharedTickStats::default();
        let cancel = CancellationToken::new();
        let period = MS(5);
        let start = Instant::now() + period;
        let task = spawn(
            start,
            period,
            Duration::ZERO,
            tx,
            stats.clone(),
            cancel.clone(),
        )
        .unwrap();
        let mut last = None;
        for _ in 0..4 {
            rx.changed().await.unwrap();
            let t = rx.borrow_and_update().unwrap();
            // Exact deadlines on the schedule's grid, fired no earlier, numbered upwards.
            assert_eq!(t.deadline - start, period * t.seq as u32);
            assert!(t.fired >= t.deadline, "{t:?}");
            if let Some(prev) = last {
                assert!(t.seq > prev, "{t:?} after seq {prev}");
            }
            last = Some(t.seq);
        }
        cancel.cancel();
        task.await.unwrap();
        // The thread has left its loop and dropped its sender.
        assert!(rx.changed().await.is_err());
        let s = stats.lock().unwrap();
        let newest = rx.borrow().unwrap().seq;
        assert_eq!(s.fired + s.skipped, newest + 1);
    }
}
