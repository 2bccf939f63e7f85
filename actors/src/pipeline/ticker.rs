//! The ticker actor: the only clock that drives control.
//!
//! It publishes a [`Tick`] every period (20 ms) on a `watch` channel, so a consumer always sees the newest
//! tick and never a backlog. When the task is woken late by more than a period, the ticks it missed are
//! skipped and counted, never fired in a burst (`MissedTickBehavior::Skip`). Every tick's lateness is kept in
//! a histogram that the runtime logs once a minute and serves on `/metrics`.

use std::time::Duration;

use tokio::sync::watch;
use tokio::time::{Instant, MissedTickBehavior};
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

/// Runs the ticker until `cancel` fires. The first tick is due at `start`.
pub(crate) async fn run(
    start: Instant,
    period: Duration,
    tx: watch::Sender<Option<Tick>>,
    stats: SharedTickStats,
    cancel: CancellationToken,
) {
    let mut interval = tokio::time::interval_at(start, period);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut next_seq = 0u64;
    loop {
        let deadline = tokio::select! {
            _ = cancel.cancelled() => break,
            d = interval.tick() => d,
        };
        let fired = Instant::now();
        let seq = seq_of(start, deadline, period);
        let skipped = seq.saturating_sub(next_seq);
        next_seq = seq + 1;
        let tick = Tick {
            seq,
            deadline,
            fired,
        };
        if let Ok(mut s) = stats.lock() {
            s.fired += 1;
            s.skipped += skipped;
            s.last_fired = Some(fired);
            s.lateness.record(tick.lateness());
        }
        if skipped > 0 {
            tracing::debug!(seq, skipped, "ticker skipped ticks");
        }
        if tx.send(Some(tick)).is_err() {
            break; // nobody listens any more
        }
    }
}

fn seq_of(start: Instant, deadline: Instant, period: Duration) -> u64 {
    let since = deadline.saturating_duration_since(start).as_nanos();
    let p = period.as_nanos().max(1);
    ((since + p / 2) / p) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn ticks_every_period_and_skips_instead_of_bursting() {
        let (tx, mut rx) = watch::channel(None);
        let stats = SharedTickStats::default();
        let cancel = CancellationToken::new();
        let start = Instant::now();
        let period = Duration::from_millis(20);
        let task = tokio::spawn(run(start, period, tx, stats.clone(), cancel.clone()));
        let mut seqs = Vec::new();
        for _ in 0..5 {
            rx.changed().await.unwrap();
            seqs.push(rx.borrow().unwrap().seq);
        }
        assert_eq!(seqs, vec![0, 1, 2, 3, 4]);
        // The process stalls for 75 ms after tick 4 (due at 80 ms): tick 5 fires late, ticks 6 and 7 are
        // skipped, and the schedule resumes on the original phase with tick 8 at 160 ms — no burst.
        tokio::time::advance(Duration::from_millis(75)).await;
        rx.changed().await.unwrap();
        let late = rx.borrow().unwrap();
        assert_eq!(late.seq, 5);
        assert_eq!(late.lateness(), Duration::from_millis(55));
        rx.changed().await.unwrap();
        let resumed = rx.borrow().unwrap();
        assert_eq!(resumed.seq, 8);
        assert_eq!(resumed.deadline - start, Duration::from_millis(160));
        assert_eq!(resumed.lateness(), Duration::ZERO);
        cancel.cancel();
        task.await.unwrap();
        let s = stats.lock().unwrap();
        assert_eq!(s.skipped, 2);
        assert_eq!(s.fired, 7);
    }
}
