//! The tokio ticker: `tokio::time::interval` with `MissedTickBehavior::Skip`. It drives the tick under
//! tokio's paused clock (tests and experiments, in virtual time) and, with `[tick] timer = "tokio"`, in
//! real time too. Its timer wheel has millisecond granularity, so in real time a tick fires about 1 ms
//! after its deadline.

use std::time::Duration;

use tokio::sync::watch;
use tokio::time::{Instant, MissedTickBehavior};
use tokio_util::sync::CancellationToken;

use super::{Tick, publish};
use crate::telemetry::counters::SharedTickStats;

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
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        let deadline = tokio::select! {
            _ = &mut cancelled => break,
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
        if !publish(tick, skipped, &stats, &tx) {
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
