//! The throttle on wrong tokens: each `Source` may present a wrong token [`FAILURE_BURST`] times in a
//! row, then about once every [`FAILURE_REFILL`] (a token bucket that only failures draw from); its wrong
//! tokens beyond that are answered 429 (with `Retry-After`) instead of 401, and are neither logged nor
//! counted as failures one by one. It throttles failures only: every token is compared (in constant time)
//! first, and the right one is admitted even from an address being throttled, so a guesser cannot lock out
//! an operator who shares its address (every local client of a loopback server is 127.0.0.1). What makes
//! guessing hopeless is the token's strength (at least 60 bits on a public bind, `pavlov::config`), not this
//! throttle. Other sources are not affected.
//!
//! The table is bounded: past `MAX_SOURCES` entries, the sources whose buckets have refilled are
//! forgotten (they are indistinguishable from new ones), and if that frees nothing the table starts
//! over (an attack from that many addresses at once is counted, not remembered).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use super::source::Source;

/// Wrong tokens a source may present back to back.
pub const FAILURE_BURST: u32 = 5;
/// One more wrong token is allowed every this long.
pub const FAILURE_REFILL: Duration = Duration::from_secs(1);
/// Sources remembered at most.
const MAX_SOURCES: usize = 4096;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    allowance: f64,
    last: Instant,
}

impl Bucket {
    fn refill(&mut self, now: Instant) {
        let elapsed = now.saturating_duration_since(self.last);
        self.last = self.last.max(now);
        self.allowance = (self.allowance + elapsed.as_secs_f64() / FAILURE_REFILL.as_secs_f64())
            .min(f64::from(FAILURE_BURST));
    }
}

/// Each source's remaining wrong-token allowance.
#[derive(Debug, Default)]
pub(crate) struct TokenThrottle {
    buckets: HashMap<Source, Bucket>,
}

impl TokenThrottle {
    /// Whether `source` may have its token checked at `now` (false: answer 429 without checking).
    pub(crate) fn allows(&mut self, source: Source, now: Instant) -> bool {
        match self.buckets.get_mut(&source) {
            None => true,
            Some(b) => {
                b.refill(now);
                b.allowance >= 1.0
            }
        }
    }

    /// Records a wrong token from `source` at `now`.
    pub(crate) fn failed(&mut self, source: Source, now: Instant) {
        if !self.buckets.contains_key(&source) && self.buckets.len() >= MAX_SOURCES {
            self.forget_refilled(now);
        }
        let b = self.buckets.entry(source).or_insert(Bucket {
            allowance: f64::from(FAILURE_BURST),
            last: now,
        });
        b.refill(now);
        b.allowance = (b.allowance - 1.0).max(0.0);
    }

    fn forget_refilled(&mut self, now: Instant) {
        self.buckets.retain(|_, b| {
            b.refill(now);
            b.allowance < f64::from(FAILURE_BURST)
        });
        if self.buckets.len() >= MAX_SOURCES {
            tracing::warn!(
                sources = self.buckets.len(),
                "wrong tokens from too many addresses to remember; starting the table over"
            );
            self.buckets.clear();
        }
    }

    /// Sources remembered now.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.buckets.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn src(n: u32) -> Source {
        Source::of(std::net::IpAddr::from(std::net::Ipv4Addr::from(
            0x0a00_0000 + n,
        )))
    }

    #[test]
    fn a_burst_of_failures_then_one_per_refill() {
        let mut t = TokenThrottle::default();
        let t0 = Instant::now();
        let mut checked = 0;
        for _ in 0..100 {
            if t.allows(src(1), t0) {
                checked += 1;
                t.failed(src(1), t0);
            }
        }
        assert_eq!(checked, FAILURE_BURST);
        // Another source is not affected.
        assert!(t.allows(src(2), t0));
        // One more guess per refill period.
        let t1 = t0 + FAILURE_REFILL;
        assert!(t.allows(src(1), t1));
        t.failed(src(1), t1);
        assert!(!t.allows(src(1), t1 + FAILURE_REFILL / 2));
        // Left alone, the allowance comes back to the burst, no further.
        let t2 = t1 + FAILURE_REFILL * 100;
        let again = (0..100)
            .filter(|_| {
                let ok = t.allows(src(1), t2);
                if ok {
                    t.failed(src(1), t2);
                }
                ok
            })
            .count();
        assert_eq!(again, FAILURE_BURST as usize);
    }

    #[test]
    fn the_table_stays_bounded() {
        let mut t = TokenThrottle::default();
        let t0 = Instant::now();
        for n in 0..(MAX_SOURCES as u32 * 3) {
            t.failed(src(n), t0);
        }
        assert!(t.len() <= MAX_SOURCES, "{}", t.len());
        // Refilled sources are forgotten first.
        let later = t0 + FAILURE_REFILL * 10;
        let mut t = TokenThrottle::default();
        for n in 0..MAX_SOURCES as u32 {
            t.failed(src(n), t0);
        }
        for _ in 0..FAILURE_BURST {
            t.failed(src(1_000_000), later);
        }
        assert_eq!(t.len(), 1);
        assert!(!t.allows(src(1_000_000), later));
    }
}
