//! The pool of pending connections: TCP connections to the dashboard port that are not (yet) websockets
//! (a page or asset request, `/healthz`, `/metrics`, a handshake in progress, an idle keep-alive, or an
//! abuser's silent socket), counted by [`Source`].
//!
//! When the whole pool holds `max_total`, a new connection still gets in: the oldest connection of the
//! source holding the most is evicted. So however many idle sockets an abuser keeps open from however
//! many addresses (and reopens as soon as they are closed), a connection from an address holding fewer
//! always gets in, and stays until it is done or has been pending longer than every other connection of
//! a busier source. When the new connection's own source already holds `max_per_source` (or is the one
//! that would pay), its own oldest is evicted if that one has been pending for [`GRACE`]; otherwise the
//! new connection is refused: a source opening connections faster than it can be served (a storm of
//! handshakes from one address) must not kill its own handshakes in flight, which have not even been
//! read yet. A connection leaves the pool when it becomes a websocket (the operator and watcher limits
//! take over at the handshake), when it closes, or when it is evicted. Pure bookkeeping (time is passed
//! in): the guard acts on it.
//!
//! Whoever pays, its *silent* connections go first, whatever their age: those whose reads have found
//! nothing and that have never sent a byte (an [`Activity`] the guard keeps up to date). A source that
//! holds its share and has no silent connection to give up may still open as many again whose request was
//! already waiting when they were accepted (when the server is behind, as in a flood, a real client's
//! request is there by then; an idle socket's never is); the rule of the grace above applies to them only
//! past twice the share. A connection beyond the share found silent is closed at once (the guard asks
//! [`PendingPool::over_share`]). So a flood of idle sockets from the
//! operator's own address (every local client of a loopback server is 127.0.0.1), however fast it reopens
//! them, only ever displaces itself, and the operator's handshake or a `/healthz` probe from that address,
//! which sends its request at once, gets in and is served.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Duration;

use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::source::Source;

/// How long a connection is safe from being evicted by a newer one from its own source: long enough for
/// a client that sends its request at once to have it served.
pub const GRACE: Duration = Duration::from_secs(1);

/// One pending connection.
#[derive(Debug)]
struct Pending {
    id: u64,
    since: Instant,
    evict: CancellationToken,
    activity: Activity,
}

/// What a pending connection has sent so far, as its reads found it; shared by the pool and the
/// connection's guard, which updates it.
#[derive(Debug, Clone, Default)]
pub(crate) struct Activity(Arc<AtomicU8>);

/// Not read yet.
const FRESH: u8 = 0;
/// A read found nothing, and nothing was ever read.
const SILENT: u8 = 1;
/// Bytes were read.
const TALKING: u8 = 2;

impl Activity {
    /// A read found nothing to read: silent, unless bytes came before. True when it just became silent.
    pub(crate) fn found_nothing(&self) -> bool {
        self.0
            .compare_exchange(FRESH, SILENT, Ordering::Relaxed, Ordering::Relaxed)
            .is_ok()
    }

    /// Bytes were read.
    pub(crate) fn read_bytes(&self) {
        self.0.store(TALKING, Ordering::Relaxed);
    }

    fn silent(&self) -> bool {
        self.0.load(Ordering::Relaxed) == SILENT
    }
}

/// The pending connections, by source, oldest first.
#[derive(Debug)]
pub(crate) struct PendingPool {
    max_total: usize,
    max_per_source: usize,
    by_source: HashMap<Source, VecDeque<Pending>>,
    total: usize,
    next_id: u64,
}

/// What the pool did with a new connection.
#[derive(Debug)]
pub(crate) enum Admission {
    /// It is in the pool.
    Admitted(Admitted),
    /// Its own source holds its share and none of them has been pending for [`GRACE`]: close it.
    Refused,
}

/// A connection admitted to the pool.
#[derive(Debug)]
pub(crate) struct Admitted {
    /// Its id in the pool (to leave it).
    pub(crate) id: u64,
    /// Cancelled when it is evicted.
    pub(crate) evict: CancellationToken,
    /// What it has sent so far, for its guard to keep up to date.
    pub(crate) activity: Activity,
    /// The source of the connection evicted to make room, if one was.
    pub(crate) evicted: Option<Source>,
}

impl PendingPool {
    /// A pool of at most `max_total` connections, `max_per_source` from one source (both at least 1).
    pub(crate) fn new(max_total: usize, max_per_source: usize) -> Self {
        let max_total = max_total.max(1);
        PendingPool {
            max_total,
            max_per_source: max_per_source.clamp(1, max_total),
            by_source: HashMap::new(),
            total: 0,
            next_id: 0,
        }
    }

    /// Pending connections now.
    pub(crate) fn len(&self) -> usize {
        self.total
    }

    /// Pending connections from `source` now.
    #[cfg(test)]
    pub(crate) fn len_of(&self, source: Source) -> usize {
        self.by_source.get(&source).map_or(0, VecDeque::len)
    }

    /// Admits a new connection from `source` at `now` (`speaking`: its first bytes were already waiting
    /// when it was accepted), evicting another one if the pool or the source is full (or refusing it, when
    /// only a connection of its own source younger than [`GRACE`] could pay).
    pub(crate) fn admit(&mut self, source: Source, now: Instant, speaking: bool) -> Admission {
        let own = self.by_source.get(&source).map_or(0, VecDeque::len);
        if own >= self.max_per_source && self.evict_silent(source) {
            return self.push(source, now, Some(source), speaking);
        }
        let limit = if speaking {
            self.max_per_source * 2
        } else {
            self.max_per_source
        };
        let victim_source = if own >= limit {
            Some(source)
        } else if self.total >= self.max_total {
            self.heaviest(source)
        } else {
            None
        };
        let evicted = match victim_source {
            None => None,
            Some(victim) if self.evict_silent(victim) => Some(victim),
            Some(victim) => {
                let oldest = self.by_source.get(&victim).and_then(VecDeque::front);
                if victim == source
                    && oldest.is_some_and(|p| now.saturating_duration_since(p.since) < GRACE)
                {
                    return Admission::Refused;
                }
                self.evict_oldest(victim).then_some(victim)
            }
        };
        self.push(source, now, evicted, speaking)
    }

    /// Adds a connection from `source`; `evicted` is who paid for it.
    fn push(
        &mut self,
        source: Source,
        now: Instant,
        evicted: Option<Source>,
        speaking: bool,
    ) -> Admission {
        let id = self.next_id;
        self.next_id += 1;
        let evict = CancellationToken::new();
        let activity = Activity::default();
        if speaking {
            activity.read_bytes();
        }
        self.by_source
            .entry(source)
            .or_default()
            .push_back(Pending {
                id,
                since: now,
                evict: evict.clone(),
                activity: activity.clone(),
            });
        self.total += 1;
        Admission::Admitted(Admitted {
            id,
            evict,
            activity,
            evicted,
        })
    }

    /// Whether `source` holds more than its share: its connections beyond it are on trial, and one found
    /// silent is closed at once (the guard asks when a connection turns silent).
    pub(crate) fn over_share(&self, source: Source) -> bool {
        self.by_source
            .get(&source)
            .is_some_and(|q| q.len() > self.max_per_source)
    }

    /// Removes connection `id` of `source` (it became a websocket or closed); false if it was not there
    /// (already evicted).
    pub(crate) fn remove(&mut self, source: Source, id: u64) -> bool {
        let Some(queue) = self.by_source.get_mut(&source) else {
            return false;
        };
        let Some(at) = queue.iter().position(|p| p.id == id) else {
            return false;
        };
        queue.remove(at);
        if queue.is_empty() {
            self.by_source.remove(&source);
        }
        self.total -= 1;
        true
    }

    /// The source holding the most pending connections; among equals, `preferred` if it is one of them,
    /// else the one whose oldest connection is the oldest.
    fn heaviest(&self, preferred: Source) -> Option<Source> {
        let most = self.by_source.values().map(VecDeque::len).max()?;
        if self.by_source.get(&preferred).map(VecDeque::len) == Some(most) {
            return Some(preferred);
        }
        self.by_source
            .iter()
            .filter(|(_, q)| q.len() == most)
            .min_by_key(|(_, q)| q.front().map_or(u64::MAX, |p| p.id))
            .map(|(s, _)| *s)
    }

    /// Evicts the oldest silent connection of `source`, if it has one.
    fn evict_silent(&mut self, source: Source) -> bool {
        let at = self
            .by_source
            .get(&source)
            .and_then(|q| q.iter().position(|p| p.activity.silent()));
        at.is_some_and(|at| self.evict_at(source, at))
    }

    fn evict_oldest(&mut self, source: Source) -> bool {
        self.evict_at(source, 0)
    }

    fn evict_at(&mut self, source: Source, at: usize) -> bool {
        let Some(queue) = self.by_source.get_mut(&source) else {
            return false;
        };
        let Some(oldest) = queue.remove(at) else {
            return false;
        };
        if queue.is_empty() {
            self.by_source.remove(&source);
        }
        self.total -= 1;
        oldest.evict.cancel();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn src(last: u8) -> Source {
        Source::of(std::net::IpAddr::from([10, 0, 0, last]))
    }

    fn admitted(a: Admission) -> Admitted {
        match a {
            Admission::Admitted(a) => a,
            Admission::Refused => panic!("refused"),
        }
    }

    /// Admits at `at`, which must succeed.
    fn admit(pool: &mut PendingPool, source: Source, at: Instant) -> Admitted {
        admitted(pool.admit(source, at, false))
    }

    /// Admits at `at` a connection whose request was waiting at once, which must succeed.
    fn admit_speaking(pool: &mut PendingPool, source: Source, at: Instant) -> Admitted {
        admitted(pool.admit(source, at, true))
    }

    #[test]
    fn a_source_over_its_share_loses_its_own_oldest_once_past_the_grace() {
        let t0 = Instant::now();
        let mut pool = PendingPool::new(100, 3);
        let first: Vec<Admitted> = (0..3).map(|_| admit(&mut pool, src(1), t0)).collect();
        assert!(first.iter().all(|a| a.evicted.is_none()));
        // Within the grace, a fourth from the same source is refused: the three may be mid-handshake.
        assert!(matches!(
            pool.admit(src(1), t0 + GRACE / 2, false),
            Admission::Refused
        ));
        // One whose request is already waiting gets in on trial, up to twice the share, nobody paying…
        let trial: Vec<Admitted> = (0..3)
            .map(|_| admit_speaking(&mut pool, src(1), t0 + GRACE / 2))
            .collect();
        assert!(trial.iter().all(|a| a.evicted.is_none()));
        assert!(pool.over_share(src(1)));
        assert!(matches!(
            pool.admit(src(1), t0 + GRACE / 2, true),
            Admission::Refused
        ));
        assert!(first.iter().all(|a| !a.evict.is_cancelled()));
        // …and past the grace, the next gets in and the oldest goes.
        let next = admit(&mut pool, src(1), t0 + GRACE);
        assert_eq!(next.evicted, Some(src(1)));
        assert!(first[0].evict.is_cancelled());
        assert!(!first[1].evict.is_cancelled() && !next.evict.is_cancelled());
        assert_eq!(pool.len_of(src(1)), 6);
        // Another source is untouched by the first one's churn.
        let other = admit(&mut pool, src(2), t0 + GRACE);
        assert!(other.evicted.is_none());
        let later = t0 + GRACE * 10;
        for _ in 0..50 {
            let _ = pool.admit(src(1), later, false);
        }
        assert!(!other.evict.is_cancelled());
        assert_eq!(pool.len(), 7);
    }

    #[test]
    fn a_full_pool_evicts_from_the_source_holding_the_most_whatever_its_age() {
        let t0 = Instant::now();
        let mut pool = PendingPool::new(6, 6);
        let flood: Vec<Admitted> = (0..5).map(|_| admit(&mut pool, src(1), t0)).collect();
        let quiet = admit(&mut pool, src(2), t0);
        assert_eq!(pool.len(), 6);
        // Full: a newcomer from a third source gets in at once, and the flood's oldest goes.
        let newcomer = admit(&mut pool, src(3), t0);
        assert_eq!(newcomer.evicted, Some(src(1)));
        assert!(flood[0].evict.is_cancelled());
        assert!(!quiet.evict.is_cancelled());
        assert_eq!(pool.len(), 6);
        // The flood keeps coming: it only ever displaces itself (or is refused while it is young).
        for i in 0..20 {
            let at = t0 + GRACE * i;
            if let Admission::Admitted(a) = pool.admit(src(1), at, false) {
                assert_eq!(a.evicted, Some(src(1)));
            }
        }
        assert!(!quiet.evict.is_cancelled() && !newcomer.evict.is_cancelled());
    }

    #[test]
    fn among_equals_the_newcomers_own_source_pays_else_the_longest_waiting() {
        let t0 = Instant::now();
        let mut pool = PendingPool::new(4, 4);
        let a = admit(&mut pool, src(1), t0);
        let b = admit(&mut pool, src(2), t0);
        let _a2 = admit(&mut pool, src(1), t0);
        let _b2 = admit(&mut pool, src(2), t0);
        // Two sources with 2 each; a third source's newcomer evicts the oldest of the two: a's.
        assert_eq!(admit(&mut pool, src(3), t0).evicted, Some(src(1)));
        assert!(a.evict.is_cancelled() && !b.evict.is_cancelled());
        // Now src(2) holds the most (2): a newcomer from src(1) evicts src(2)'s oldest.
        assert_eq!(admit(&mut pool, src(1), t0).evicted, Some(src(2)));
        assert!(b.evict.is_cancelled());
        // src(1) now holds the most (2 of 4) and pays for its own newcomer, once past the grace.
        assert!(matches!(pool.admit(src(1), t0, false), Admission::Refused));
        assert_eq!(admit(&mut pool, src(1), t0 + GRACE).evicted, Some(src(1)));
    }

    #[test]
    fn silent_connections_pay_first_so_a_talking_newcomer_from_their_own_source_gets_in() {
        let t0 = Instant::now();
        let mut pool = PendingPool::new(100, 3);
        // An idle flood holds the source's whole share, all of it young.
        let idle: Vec<Admitted> = (0..3).map(|_| admit(&mut pool, src(1), t0)).collect();
        for a in &idle {
            a.activity.found_nothing();
        }
        // A newcomer from the same source (the operator's browser) still gets in, at once, and an idle one goes.
        let operator = admit(&mut pool, src(1), t0);
        assert_eq!(operator.evicted, Some(src(1)));
        assert!(idle[0].evict.is_cancelled());
        operator.activity.read_bytes();
        // The flood keeps reopening: each of its new sockets displaces another silent one, never the talker,
        // whatever its age.
        for i in 0..20 {
            let again = admit(&mut pool, src(1), t0 + GRACE * i);
            again.activity.found_nothing();
            assert!(!operator.evict.is_cancelled(), "round {i}");
        }
        assert_eq!(pool.len_of(src(1)), 3);
        // A connection that sent bytes before a read found nothing stays a talker.
        let slow = Activity::default();
        slow.read_bytes();
        slow.found_nothing();
        assert!(!slow.silent());
    }

    #[test]
    fn leaving_frees_the_place_and_an_evicted_connection_is_gone() {
        let t0 = Instant::now();
        let mut pool = PendingPool::new(2, 2);
        let a = admit(&mut pool, src(1), t0);
        let b = admit(&mut pool, src(1), t0);
        assert!(pool.remove(src(1), b.id));
        assert!(!pool.remove(src(1), b.id));
        assert_eq!(pool.len(), 1);
        assert!(admit(&mut pool, src(1), t0).evicted.is_none());
        assert_eq!(admit(&mut pool, src(1), t0 + GRACE).evicted, Some(src(1)));
        assert!(a.evict.is_cancelled());
        assert!(!pool.remove(src(1), a.id));
        assert_eq!(pool.len(), 2);
    }
}
