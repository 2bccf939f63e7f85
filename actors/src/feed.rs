//! The tick feed: every [`TickRecord`] goes out to the dashboard hub, the recorder and the metrics.
//!
//! Publishing never blocks the tick. Live subscribers (websocket clients, tests) share a `broadcast` channel:
//! a subscriber that falls behind skips the oldest records and is told how many it missed. The recorder gets
//! its own bounded queue; when it is full the record is dropped and counted, so a slow disk is visible rather
//! than silently slowing control.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use pavlov::record::TickRecord;
use tokio::sync::{broadcast, mpsc};

/// Capacity of the live broadcast, in records (20 s at 50 Hz).
pub const LIVE_CAPACITY: usize = 1024;

/// The publishing side of the feed.
#[derive(Clone)]
pub struct TickFeed {
    live: broadcast::Sender<Arc<TickRecord>>,
    recorder: Option<mpsc::Sender<Arc<TickRecord>>>,
    recorder_dropped: Arc<AtomicU64>,
}

impl TickFeed {
    /// A feed with no recorder attached.
    pub fn new() -> Self {
        let (live, _) = broadcast::channel(LIVE_CAPACITY);
        TickFeed {
            live,
            recorder: None,
            recorder_dropped: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Attaches a recorder queue.
    pub fn with_recorder(mut self, tx: mpsc::Sender<Arc<TickRecord>>) -> Self {
        self.recorder = Some(tx);
        self
    }

    /// Sends a record to every consumer without waiting.
    pub fn publish(&self, record: Arc<TickRecord>) {
        if let Some(rec) = &self.recorder
            && rec.try_send(record.clone()).is_err()
        {
            self.recorder_dropped.fetch_add(1, Ordering::Relaxed);
        }
        // An error only means nobody is subscribed right now.
        let _ = self.live.send(record);
    }

    /// A new live subscription, starting with the next record.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<TickRecord>> {
        self.live.subscribe()
    }

    /// Records the recorder could not take.
    pub fn recorder_dropped(&self) -> u64 {
        self.recorder_dropped.load(Ordering::Relaxed)
    }
}

impl Default for TickFeed {
    fn default() -> Self {
        Self::new()
    }
}
