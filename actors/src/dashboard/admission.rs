//! Who gets a websocket seat, decided at the handshake: operators (clients that may command) and watchers
//! (watch-only clients) are counted apart, so no number of watchers can take an operator's place.
//!
//! - operators: at most `[dashboard] max_operators` at once;
//! - watchers: at most `max_watchers` at once, and `max_watchers_per_address` from one [`Source`]
//!   (loopback included).
//!
//! A [`Seat`] holds the place for the connection's lifetime and frees it when dropped. The total (both
//! kinds) is also kept in the hub's client counter, which the `status` messages and `/metrics` report.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use pavlov::config::DashboardConfig;

use super::auth::Access;
use super::source::Source;

/// Why no seat was given (HTTP 503).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Full {
    /// `max_operators` operators are connected.
    #[error("too many operators connected (the limit is {0}, [dashboard] max_operators)")]
    Operators(usize),
    /// `max_watchers` watchers are connected.
    #[error("too many watchers connected (the limit is {0}, [dashboard] max_watchers)")]
    Watchers(usize),
    /// `max_watchers_per_address` watchers are connected from this address.
    #[error(
        "too many watchers from {address} (the limit is {limit} per address, [dashboard] max_watchers_per_address)"
    )]
    WatchersFromSource {
        /// The address (or IPv6 /64).
        address: Source,
        /// The limit.
        limit: usize,
    },
}

#[derive(Debug, Default)]
struct Counts {
    operators: usize,
    watchers: usize,
    watchers_by_source: HashMap<Source, usize>,
}

/// The seat limits and who holds a seat now.
#[derive(Debug)]
pub(crate) struct Admission {
    max_operators: usize,
    max_watchers: usize,
    max_watchers_per_source: usize,
    counts: Mutex<Counts>,
    /// Seats held now, both kinds (the hub's client counter).
    total: Arc<AtomicUsize>,
}

impl Admission {
    /// The limits of `config`; `total` is kept equal to the seats held.
    pub(crate) fn new(config: &DashboardConfig, total: Arc<AtomicUsize>) -> Self {
        Admission {
            max_operators: config.max_operators,
            max_watchers: config.max_watchers,
            max_watchers_per_source: config.max_watchers_per_address,
            counts: Mutex::new(Counts::default()),
            total,
        }
    }

    fn counts(&self) -> MutexGuard<'_, Counts> {
        self.counts.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Operators and watchers connected now.
    pub(crate) fn held(&self) -> (usize, usize) {
        let c = self.counts();
        (c.operators, c.watchers)
    }

    /// A seat for a connection from `source` with `access`, if there is room.
    pub(crate) fn seat(self: &Arc<Self>, access: Access, source: Source) -> Result<Seat, Full> {
        let mut c = self.counts();
        match access {
            Access::Command => {
                if c.operators >= self.max_operators {
                    return Err(Full::Operators(self.max_operators));
                }
                c.operators += 1;
            }
            Access::Watch => {
                if c.watchers >= self.max_watchers {
                    return Err(Full::Watchers(self.max_watchers));
                }
                let from_source = c.watchers_by_source.entry(source).or_insert(0);
                if *from_source >= self.max_watchers_per_source {
                    return Err(Full::WatchersFromSource {
                        address: source,
                        limit: self.max_watchers_per_source,
                    });
                }
                *from_source += 1;
                c.watchers += 1;
            }
        }
        self.total.fetch_add(1, Ordering::Relaxed);
        Ok(Seat {
            admission: self.clone(),
            access,
            source,
        })
    }

    fn free(&self, access: Access, source: Source) {
        let mut c = self.counts();
        match access {
            Access::Command => c.operators = c.operators.saturating_sub(1),
            Access::Watch => {
                c.watchers = c.watchers.saturating_sub(1);
                if let Some(n) = c.watchers_by_source.get_mut(&source) {
                    *n = n.saturating_sub(1);
                    if *n == 0 {
                        c.watchers_by_source.remove(&source);
                    }
                }
            }
        }
        self.total.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A websocket seat, freed when dropped.
#[derive(Debug)]
pub(crate) struct Seat {
    admission: Arc<Admission>,
    access: Access,
    source: Source,
}

impl Drop for Seat {
    fn drop(&mut self) {
        self.admission.free(self.access, self.source);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn admission(operators: usize, watchers: usize, per_source: usize) -> Arc<Admission> {
        let cfg = DashboardConfig {
            max_operators: operators,
            max_watchers: watchers,
            max_watchers_per_address: per_source,
            ..DashboardConfig::default()
        };
        Arc::new(Admission::new(&cfg, Arc::new(AtomicUsize::new(0))))
    }

    fn src(last: u8) -> Source {
        Source::of(std::net::IpAddr::from([10, 0, 0, last]))
    }

    #[test]
    fn watchers_never_take_an_operators_seat() {
        let a = admission(2, 5, 5);
        let mut seats = Vec::new();
        for i in 0..20 {
            if let Ok(s) = a.seat(Access::Watch, src(i)) {
                seats.push(s);
            }
        }
        assert_eq!(seats.len(), 5);
        assert_eq!(
            a.seat(Access::Watch, src(99)).unwrap_err(),
            Full::Watchers(5)
        );
        let op = a.seat(Access::Command, src(1)).unwrap();
        let _op2 = a.seat(Access::Command, src(1)).unwrap();
        assert_eq!(
            a.seat(Access::Command, src(1)).unwrap_err(),
            Full::Operators(2)
        );
        assert_eq!(a.held(), (2, 5));
        assert_eq!(a.total.load(Ordering::Relaxed), 7);
        drop(op);
        assert!(a.seat(Access::Command, src(1)).is_ok());
    }

    #[test]
    fn one_address_gets_its_share_of_watchers_and_frees_it() {
        let a = admission(1, 10, 2);
        let first = a.seat(Access::Watch, src(1)).unwrap();
        let _second = a.seat(Access::Watch, src(1)).unwrap();
        let e = a.seat(Access::Watch, src(1)).unwrap_err();
        assert_eq!(
            e,
            Full::WatchersFromSource {
                address: src(1),
                limit: 2
            }
        );
        assert!(e.to_string().contains("10.0.0.1"), "{e}");
        assert!(a.seat(Access::Watch, src(2)).is_ok());
        drop(first);
        assert!(a.seat(Access::Watch, src(1)).is_ok());
    }
}
