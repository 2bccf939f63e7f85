//! The tick schedule's arithmetic, apart from any clock: which tick is due next, and after a wake-up,
//! which tick fires and how many were skipped.
//!
//! Times are offsets from the first tick's deadline. Tick `n` is due at `n × period`. A wake-up at `now`
//! fires the tick that was due, and the next tick is the first one due strictly after `now`: a wake-up
//! later than a period passes over the ticks it missed (they are skipped and counted when the next tick
//! fires), never fires them in a burst, and keeps the original phase. This is tokio's
//! `MissedTickBehavior::Skip` (whose next deadline is `now + period − (now − due) mod period`), so both
//! timers number and skip ticks alike.

use std::time::Duration;

/// A tick that fires.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Fired {
    /// Its sequence number.
    pub(crate) seq: u64,
    /// When it was due (offset from the first tick's deadline).
    pub(crate) due: Duration,
    /// Ticks passed over since the previous tick fired.
    pub(crate) skipped: u64,
}

/// The schedule of a ticker with a fixed period.
#[derive(Debug, Clone)]
pub(crate) struct Schedule {
    period_ns: u128,
    /// The tick due next.
    next: u64,
    /// The tick after the one fired last (no skip when `next` equals it).
    expected: u64,
}

impl Schedule {
    /// A schedule whose tick 0 is due at offset 0.
    pub(crate) fn new(period: Duration) -> Self {
        Schedule {
            period_ns: period.as_nanos().max(1),
            next: 0,
            expected: 0,
        }
    }

    /// When the next tick is due.
    pub(crate) fn due(&self) -> Duration {
        offset(u128::from(self.next) * self.period_ns)
    }

    /// Fires the tick that is due, on a wake-up at `now` (a wake-up before the deadline counts as on
    /// time), and moves on to the first tick due strictly after `now`.
    pub(crate) fn fire(&mut self, now: Duration) -> Fired {
        let seq = self.next;
        let due_ns = u128::from(seq) * self.period_ns;
        let now_ns = now.as_nanos().max(due_ns);
        let after_now = now_ns / self.period_ns + 1;
        self.next = u64::try_from(after_now).unwrap_or(u64::MAX).max(seq + 1);
        let skipped = seq - self.expected;
        self.expected = seq + 1;
        Fired {
            seq,
            due: offset(due_ns),
            skipped,
        }
    }
}

/// `ns` nanoseconds as a duration (saturating far beyond any run: 2⁶⁴ s).
fn offset(ns: u128) -> Duration {
    const NS_PER_S: u128 = 1_000_000_000;
    let secs = u64::try_from(ns / NS_PER_S).unwrap_or(u64::MAX);
    // The remainder is below 10⁹, so it fits.
    let nanos = (ns % NS_PER_S) as u32;
    Duration::new(secs, nanos)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;
    const US: fn(u64) -> Duration = Duration::from_micros;

    #[test]
    fn on_time_wake_ups_fire_consecutive_ticks_one_period_apart() {
        let mut s = Schedule::new(MS(20));
        let mut fired = Vec::new();
        for _ in 0..5 {
            let due = s.due();
            // Each wake-up is 70 µs late, well within the period.
            fired.push(s.fire(due + US(70)));
        }
        let seqs: Vec<u64> = fired.iter().map(|f| f.seq).collect();
        assert_eq!(seqs, vec![0, 1, 2, 3, 4]);
        let dues: Vec<Duration> = fired.iter().map(|f| f.due).collect();
        assert_eq!(dues, vec![MS(0), MS(20), MS(40), MS(60), MS(80)]);
        assert!(fired.iter().all(|f| f.skipped == 0));
        assert_eq!(s.due(), MS(100));
    }

    #[test]
    fn a_late_wake_up_skips_the_missed_ticks_instead_of_bursting() {
        // The same stall as the tokio ticker's test: tick 5 (due at 100 ms) wakes at 155 ms.
        let mut s = Schedule::new(MS(20));
        for n in 0..5 {
            assert_eq!(s.fire(MS(20 * n)).seq, n);
        }
        let late = s.fire(MS(155));
        assert_eq!((late.seq, late.due, late.skipped), (5, MS(100), 0));
        // Ticks 6 (120 ms) and 7 (140 ms) are passed over: the next is 8, on the original phase.
        assert_eq!(s.due(), MS(160));
        let resumed = s.fire(MS(160));
        assert_eq!((resumed.seq, resumed.skipped), (8, 2));
        assert_eq!(s.fire(MS(180)).skipped, 0);
    }

    #[test]
    fn the_next_tick_is_due_strictly_after_the_wake_up_like_tokios_skip() {
        // tokio's Skip: next = now + period − (now − due) mod period, for a wake-up more than 5 ms late.
        let tokio_skip = |due: u64, now: u64, period: u64| now + period - (now - due) % period;
        for late_ms in [6, 19, 20, 21, 39, 40, 41, 1000] {
            let mut s = Schedule::new(MS(20));
            s.fire(MS(0));
            s.fire(MS(20 + late_ms));
            assert_eq!(
                s.due(),
                MS(tokio_skip(20, 20 + late_ms, 20)),
                "{late_ms} ms late"
            );
        }
        // Less than a period late: simply the next tick (tokio does the same, its threshold aside).
        let mut s = Schedule::new(MS(20));
        s.fire(MS(3));
        assert_eq!(s.due(), MS(20));
    }

    #[test]
    fn an_early_wake_up_counts_as_on_time_and_never_repeats_a_tick() {
        let mut s = Schedule::new(MS(20));
        s.fire(MS(0));
        let early = s.fire(MS(19));
        assert_eq!((early.seq, early.due), (1, MS(20)));
        assert_eq!(s.due(), MS(40));
    }

    #[test]
    fn sub_millisecond_periods_and_far_offsets_keep_exact_deadlines() {
        let mut s = Schedule::new(US(333));
        for _ in 0..3 {
            let due = s.due();
            s.fire(due);
        }
        assert_eq!(s.due(), US(999));
        // A wake-up a day into the run lands on the grid exactly.
        let day = Duration::from_secs(86_400);
        let f = s.fire(day);
        assert_eq!(f.seq, 3);
        let next = s.due();
        assert!(next > day && next - day <= US(333), "{next:?}");
        assert_eq!(next.as_nanos() % 333_000, 0);
    }
}
