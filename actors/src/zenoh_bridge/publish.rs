//! The publisher: reads the tick feed and the event log and puts them on `pavlov/v1/<robot>/tick` and
//! `pavlov/v1/<robot>/event`, and puts the status on `pavlov/v1/<robot>/status` at a fixed period.
//! Every put declares `application/json`, carries the session's HLC timestamp, and has its stream's
//! publication number as attachment ([`super::wire`]).
//!
//! **It works half a period away from the tick.** The publisher does not wait on the broadcasts (a
//! waiting receiver would be woken by actuation's send, on the tick's own path, at the moment the link
//! writer is putting the command on the wire). It wakes on its own clock instead, at the middle of each
//! tick period ([`Phase`]), takes what the broadcasts hold without waiting (`try_recv`), and puts it; so
//! the bridge's thread, Zenoh's transmit thread and any local subscriber run while the tick is idle. A
//! record reaches Zenoh half a period (10 ms) after its tick.
//!
//! It holds receivers of the feed's and the event log's lossy broadcasts: bounded rings that drop their
//! oldest entry when the publisher falls behind, so it can never delay the tick; what it loses is counted
//! (`pavlov_zenoh_missed_total`).
//!
//! **Congestion.** Every put uses congestion control *drop*: a tick is worth nothing late and the next
//! one replaces it, and a *block* put would hold the bridge's one thread, on which the command queryable
//! (an e-stop) is answered too, for as long as a slow subscriber's link stays full. Queries and their
//! replies (commands) use Zenoh's default for requests, *block*. Zenoh gives a publisher no word of a
//! dropped put, so the drops are made visible where they can be seen: at the subscriber, as a gap in the
//! publication numbers (the fleet counts them per robot), and here, as failed puts
//! (`pavlov_zenoh_put_errors_total`).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use pavlov::event::Event;
use pavlov::record::TickRecord;
use tokio::sync::broadcast::{self, error::TryRecvError};
use tokio::time::{Instant, MissedTickBehavior};
use tokio_util::sync::CancellationToken;
use zenoh::Session;
use zenoh::pubsub::Publisher as ZPublisher;
use zenoh::qos::CongestionControl;

use super::status::StatusSource;
use super::wire::{self, SeqCounter};
use super::{ZenohError, key};
use crate::telemetry::counters::ZenohCounters;

/// What the publisher reads.
pub(crate) struct Inputs {
    /// The tick feed.
    pub(crate) ticks: broadcast::Receiver<Arc<TickRecord>>,
    /// The event log.
    pub(crate) events: broadcast::Receiver<Arc<Event>>,
}

/// When the publisher wakes: the tick schedule shifted by half a period.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Phase {
    /// When the first tick was due.
    pub(crate) first_tick: Instant,
    /// The tick period.
    pub(crate) period: Duration,
}

impl Phase {
    /// The first wake-up at or after `now`: half a period after some tick's deadline.
    pub(crate) fn first_wake(&self, now: Instant) -> Instant {
        let half = self.period / 2;
        let first = self.first_tick + half;
        if now <= first || self.period.is_zero() {
            return first;
        }
        let since = now.duration_since(first).as_nanos();
        let period = self.period.as_nanos();
        let periods = since.div_ceil(period);
        let offset = u64::try_from(periods.saturating_mul(period)).unwrap_or(u64::MAX);
        first + Duration::from_nanos(offset)
    }
}

/// One broadcast read without waiting: what it held, what it lost, whether it is still open.
struct Drained<T> {
    items: Vec<T>,
    lost: u64,
    open: bool,
}

fn drain<T: Clone>(rx: &mut broadcast::Receiver<T>) -> Drained<T> {
    let mut out = Drained {
        items: Vec::new(),
        lost: 0,
        open: true,
    };
    loop {
        match rx.try_recv() {
            Ok(item) => out.items.push(item),
            Err(TryRecvError::Lagged(n)) => out.lost += n,
            Err(TryRecvError::Empty) => return out,
            Err(TryRecvError::Closed) => {
                out.open = false;
                return out;
            }
        }
    }
}

/// One stream: its publisher and its publication numbers.
struct Stream {
    publisher: ZPublisher<'static>,
    seq: SeqCounter,
}

/// The three publishers and what they read.
pub(crate) struct Publisher {
    session: Session,
    tick: Stream,
    event: Stream,
    status: Stream,
    counters: Arc<ZenohCounters>,
    inputs: Inputs,
}

impl Publisher {
    /// Declares the three publishers of `robot` on `session`.
    pub(crate) async fn declare(
        session: Session,
        robot: String,
        counters: Arc<ZenohCounters>,
        inputs: Inputs,
    ) -> Result<Publisher, ZenohError> {
        let declare = |leaf: &str, congestion: CongestionControl| {
            let k = key(&robot, leaf);
            let session = session.clone();
            async move {
                session
                    .declare_publisher(k.clone())
                    .encoding(wire::json_encoding())
                    .congestion_control(congestion)
                    .await
                    .map(|publisher| Stream {
                        publisher,
                        seq: SeqCounter::default(),
                    })
                    .map_err(|e| ZenohError::Declare {
                        key: k,
                        reason: e.to_string(),
                    })
            }
        };
        Ok(Publisher {
            tick: declare("tick", CongestionControl::Drop).await?,
            event: declare("event", CongestionControl::Drop).await?,
            status: declare("status", CongestionControl::Drop).await?,
            session,
            counters,
            inputs,
        })
    }

    async fn put(&self, stream: &Stream, bytes: Vec<u8>, sent: &AtomicU64) {
        let publisher = &stream.publisher;
        let put = publisher
            .put(bytes)
            .timestamp(self.session.new_timestamp())
            .attachment(wire::seq_attachment(stream.seq.next()));
        match put.await {
            Ok(()) => {
                sent.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                self.counters.put_errors.fetch_add(1, Ordering::Relaxed);
                tracing::debug!("zenoh: put on {} failed: {e}", publisher.key_expr());
            }
        }
    }

    /// Puts every drained item on `publisher` as JSON and counts what was lost; whether the input is
    /// still open.
    async fn publish<T: serde::Serialize>(
        &self,
        drained: Drained<Arc<T>>,
        publisher: &Stream,
        sent: &AtomicU64,
        missed: &AtomicU64,
    ) -> bool {
        missed.fetch_add(drained.lost, Ordering::Relaxed);
        for item in &drained.items {
            if let Ok(bytes) = serde_json::to_vec(&**item) {
                self.put(publisher, bytes, sent).await;
            }
        }
        drained.open
    }

    /// Publishes until `cancel`, waking at `phase`; the status every `status_every`, from `status`.
    pub(crate) async fn run(
        mut self,
        mut status: StatusSource,
        phase: Phase,
        status_every: Duration,
        cancel: CancellationToken,
    ) {
        let mut wake = tokio::time::interval_at(phase.first_wake(Instant::now()), phase.period);
        wake.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut next_status = Instant::now();
        let (mut ticks_open, mut events_open) = (true, true);
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                _ = wake.tick() => {}
            }
            if ticks_open {
                let d = drain(&mut self.inputs.ticks);
                if let Some(newest) = d.items.last() {
                    status.saw(newest);
                }
                let c = &self.counters;
                ticks_open = self
                    .publish(d, &self.tick, &c.ticks_published, &c.ticks_missed)
                    .await;
            }
            if events_open {
                let d = drain(&mut self.inputs.events);
                let c = &self.counters;
                events_open = self
                    .publish(d, &self.event, &c.events_published, &c.events_missed)
                    .await;
            }
            self.counters.oversized_dropped.store(
                crate::telemetry::zenoh_drops::OVERSIZED_DROPS.load(Ordering::Relaxed),
                Ordering::Relaxed,
            );
            let now = Instant::now();
            if now >= next_status {
                next_status = now + status_every;
                let bytes = status.message();
                self.put(&self.status, bytes, &self.counters.status_published)
                    .await;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn phase(start: Instant) -> Phase {
        Phase {
            first_tick: start,
            period: Duration::from_millis(20),
        }
    }

    #[test]
    fn the_first_wake_is_half_a_period_after_a_tick() {
        let start = Instant::now();
        let p = phase(start);
        let ms = |n| Duration::from_millis(n);
        assert_eq!(p.first_wake(start - ms(5)), start + ms(10));
        assert_eq!(p.first_wake(start), start + ms(10));
        assert_eq!(p.first_wake(start + ms(10)), start + ms(10));
        assert_eq!(p.first_wake(start + ms(11)), start + ms(30));
        assert_eq!(p.first_wake(start + ms(1_000_005)), start + ms(1_000_010));
        assert_eq!(p.first_wake(start + ms(1_000_010)), start + ms(1_000_010));
    }

    #[test]
    fn a_zero_period_wakes_at_the_first_tick() {
        let start = Instant::now();
        let p = Phase {
            first_tick: start,
            period: Duration::ZERO,
        };
        assert_eq!(p.first_wake(start + Duration::from_secs(1)), start);
    }

    #[test]
    fn a_drain_takes_everything_counts_the_lost_and_sees_the_close() {
        let (tx, mut rx) = broadcast::channel(4);
        for i in 0..6 {
            tx.send(i).ok();
        }
        let d = drain(&mut rx);
        assert_eq!(d.items, vec![2, 3, 4, 5]);
        assert_eq!(d.lost, 2);
        assert!(d.open);
        tx.send(6).ok();
        drop(tx);
        let d = drain(&mut rx);
        assert_eq!(d.items, vec![6]);
        assert!(!d.open);
    }
}
