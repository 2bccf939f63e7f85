//! The per-connection message rate limit: a token bucket that every client message (text or binary)
//! draws one token from.
//!
//! A connection may send [`RateLimit::burst`] messages at once and [`RateLimit::per_second`] on average.
//! A message over the limit is not processed at all: it gets an error reply with code `rate_limited` and
//! the connection stays open. This bounds what one connection can make the server do (parse, forward
//! commands to the control actors, answer) no matter how fast it sends; the connection limit bounds the
//! number of connections. The bucket is pure (time is passed in), so it is tested without sleeping.

use std::time::Instant;

/// A message rate limit.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RateLimit {
    /// Messages a connection may send back to back.
    pub burst: u32,
    /// Messages per second a connection may send on average.
    pub per_second: f64,
}

/// The limit of every dashboard connection: the page sends teleop every 200 ms while driving and a few
/// clicks besides, far below it.
pub const DEFAULT_RATE_LIMIT: RateLimit = RateLimit {
    burst: 40,
    per_second: 20.0,
};

/// A token bucket for one connection.
#[derive(Debug, Clone)]
pub(crate) struct TokenBucket {
    limit: RateLimit,
    tokens: f64,
    last: Instant,
}

impl TokenBucket {
    /// A full bucket at `now`.
    pub(crate) fn new(limit: RateLimit, now: Instant) -> Self {
        TokenBucket {
            limit,
            tokens: f64::from(limit.burst),
            last: now,
        }
    }

    /// Takes one token if there is one at `now`; false means the message is over the limit.
    pub(crate) fn try_take(&mut self, now: Instant) -> bool {
        let elapsed = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = self.last.max(now);
        let rate = if self.limit.per_second.is_finite() {
            self.limit.per_second.max(0.0)
        } else {
            0.0
        };
        self.tokens = (self.tokens + elapsed * rate).min(f64::from(self.limit.burst));
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    const LIMIT: RateLimit = RateLimit {
        burst: 5,
        per_second: 10.0,
    };

    #[test]
    fn a_burst_passes_then_the_excess_is_refused() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(LIMIT, t0);
        let passed = (0..20).filter(|_| b.try_take(t0)).count();
        assert_eq!(passed, 5);
    }

    #[test]
    fn tokens_come_back_at_the_rate_and_never_beyond_the_burst() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(LIMIT, t0);
        while b.try_take(t0) {}
        // 10 per second: 0.25 s gives 2 tokens (2.5, rounded down by the whole-token rule).
        let t1 = t0 + Duration::from_millis(250);
        assert_eq!((0..10).filter(|_| b.try_take(t1)).count(), 2);
        // An hour of silence refills to the burst, no further.
        let t2 = t1 + Duration::from_secs(3600);
        assert_eq!((0..100).filter(|_| b.try_take(t2)).count(), 5);
    }

    #[test]
    fn a_steady_sender_gets_the_average_rate() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(LIMIT, t0);
        // 1000 messages/s for 10 s: the burst plus 10/s.
        let passed = (0..10_000)
            .filter(|i| b.try_take(t0 + Duration::from_millis(*i)))
            .count();
        assert!((104..=106).contains(&passed), "{passed}");
    }

    #[test]
    fn time_going_backwards_gives_no_tokens() {
        let t0 = Instant::now() + Duration::from_secs(10);
        let mut b = TokenBucket::new(LIMIT, t0);
        while b.try_take(t0) {}
        assert!(!b.try_take(t0 - Duration::from_secs(5)));
        assert!(!b.try_take(t0));
        assert!(b.try_take(t0 + Duration::from_millis(100)));
    }
}
