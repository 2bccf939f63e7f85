//! The publisher: reads the tick feed and the event log and puts them on `pavlov/<robot>/tick` and
//! `pavlov/<robot>/event`, and puts the status on `pavlov/<robot>/status` at a fixed period.
//!
//! It holds receivers of the feed's and the event log's lossy broadcasts: bounded rings that drop their
//! oldest entry when the publisher falls behind, so it can never delay the tick; what it loses is counted
//! (`pavlov_zenoh_missed_total`). Puts use Zenoh's default congestion control for data (drop, not block).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use pavlov::event::Event;
use pavlov::record::TickRecord;
use tokio::sync::broadcast::{self, error::RecvError};
use tokio_util::sync::CancellationToken;
use zenoh::Session;
use zenoh::pubsub::Publisher as ZPublisher;

use super::status::StatusSource;
use super::{ZenohError, key};
use crate::telemetry::counters::ZenohCounters;

/// What the publisher reads.
pub(crate) struct Inputs {
    /// The tick feed.
    pub(crate) ticks: broadcast::Receiver<Arc<TickRecord>>,
    /// The event log.
    pub(crate) events: broadcast::Receiver<Arc<Event>>,
}

/// The three publishers and what they read.
pub(crate) struct Publisher {
    tick: ZPublisher<'static>,
    event: ZPublisher<'static>,
    status: ZPublisher<'static>,
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
        let declare = |leaf: &str| {
            let k = key(&robot, leaf);
            let session = session.clone();
            async move {
                session
                    .declare_publisher(k.clone())
                    .await
                    .map_err(|e| ZenohError::Declare {
                        key: k,
                        reason: e.to_string(),
                    })
            }
        };
        Ok(Publisher {
            tick: declare("tick").await?,
            event: declare("event").await?,
            status: declare("status").await?,
            counters,
            inputs,
        })
    }

    async fn put(&self, publisher: &ZPublisher<'static>, bytes: Vec<u8>, sent: &AtomicU64) {
        match publisher.put(bytes).await {
            Ok(()) => {
                sent.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                self.counters.put_errors.fetch_add(1, Ordering::Relaxed);
                tracing::debug!("zenoh: put on {} failed: {e}", publisher.key_expr());
            }
        }
    }

    /// Publishes until `cancel`; the status every `period`, from `status`.
    pub(crate) async fn run(
        mut self,
        mut status: StatusSource,
        period: Duration,
        cancel: CancellationToken,
    ) {
        let mut every = tokio::time::interval(period);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut ticks_open = true;
        let mut events_open = true;
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                r = self.inputs.ticks.recv(), if ticks_open => match r {
                    Ok(record) => {
                        status.saw(&record);
                        if let Ok(bytes) = serde_json::to_vec(&*record) {
                            self.put(&self.tick, bytes, &self.counters.ticks_published).await;
                        }
                    }
                    Err(RecvError::Lagged(n)) => {
                        self.counters.ticks_missed.fetch_add(n, Ordering::Relaxed);
                    }
                    Err(RecvError::Closed) => ticks_open = false,
                },
                r = self.inputs.events.recv(), if events_open => match r {
                    Ok(event) => {
                        if let Ok(bytes) = serde_json::to_vec(&*event) {
                            self.put(&self.event, bytes, &self.counters.events_published).await;
                        }
                    }
                    Err(RecvError::Lagged(n)) => {
                        self.counters.events_missed.fetch_add(n, Ordering::Relaxed);
                    }
                    Err(RecvError::Closed) => events_open = false,
                },
                _ = every.tick() => {
                    let bytes = status.message();
                    self.put(&self.status, bytes, &self.counters.status_published).await;
                }
            }
        }
    }
}
