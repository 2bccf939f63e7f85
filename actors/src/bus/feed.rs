//! The tick feed: every [`TickRecord`] goes out to the dashboard hub, the recorder and the metrics.
//!
//! Publishing never blocks the tick. Live subscribers (websocket clients, tests) share a `broadcast` channel:
//! a subscriber that falls behind skips the oldest records and is told how many it missed. The recorder gets
//! its own bounded queue; when it is full the record is dropped and counted, so a slow disk is visible rather
//! than silently slowing control.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use pavlov::record::{LinkStatus, TickRecord};

use super::recorder_queue::{RecorderGauge, RecorderInput};
use tokio::sync::{broadcast, mpsc, watch};

/// Capacity of the live broadcast, in records (20 s at 50 Hz).
pub(crate) const LIVE_CAPACITY: usize = 1024;

/// The publishing side of the feed.
#[derive(Clone)]
pub struct TickFeed {
    live: broadcast::Sender<Arc<TickRecord>>,
    latest_link: Arc<watch::Sender<Option<LinkStatus>>>,
    /// The newest record's tick + 1 (0: none yet).
    next_seq: Arc<AtomicU64>,
    recorder: Option<mpsc::Sender<RecorderInput>>,
    recorder_dropped: Arc<AtomicU64>,
}

impl TickFeed {
    /// A feed with no recorder attached.
    pub(crate) fn new() -> Self {
        let (live, _) = broadcast::channel(LIVE_CAPACITY);
        TickFeed {
            live,
            latest_link: Arc::new(watch::Sender::new(None)),
            next_seq: Arc::new(AtomicU64::new(0)),
            recorder: None,
            recorder_dropped: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Attaches a recorder queue.
    pub(crate) fn with_recorder(mut self, tx: mpsc::Sender<RecorderInput>) -> Self {
        self.recorder = Some(tx);
        self
    }

    /// Sends a record to every consumer without waiting.
    pub(crate) fn publish(&self, record: Arc<TickRecord>) {
        if let Some(rec) = &self.recorder
            && rec.try_send(RecorderInput::Tick(record.clone())).is_err()
        {
            self.recorder_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.latest_link.send_replace(Some(record.link));
        self.next_seq.store(record.seq + 1, Ordering::Relaxed);
        // An error only means nobody is subscribed right now.
        let _ = self.live.send(record);
    }

    /// A new live subscription, starting with the next record.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<TickRecord>> {
        self.live.subscribe()
    }

    /// The newest record's tick (`None` before the first).
    pub fn last_seq(&self) -> Option<u64> {
        self.next_seq.load(Ordering::Relaxed).checked_sub(1)
    }

    /// The link summary of the newest record (`None` before the first).
    pub(crate) fn latest_link(&self) -> watch::Receiver<Option<LinkStatus>> {
        self.latest_link.subscribe()
    }

    /// The counter of what the recorder's queue could not take (shared with the event log).
    pub(crate) fn recorder_dropped_counter(&self) -> Arc<AtomicU64> {
        self.recorder_dropped.clone()
    }

    /// Records the recorder could not take.
    pub(crate) fn recorder_dropped(&self) -> u64 {
        self.recorder_dropped.load(Ordering::Relaxed)
    }

    /// A read-only view of the recorder's queue for metrics. It holds no sender, so it does not keep the
    /// recorder running after the server has gone.
    pub(crate) fn recorder_gauge(&self) -> RecorderGauge {
        RecorderGauge::new(
            self.recorder.as_ref().map(|tx| tx.downgrade()),
            self.recorder_dropped.clone(),
        )
    }
}

impl Default for TickFeed {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::Mode;

    fn record(seq: u64) -> Arc<TickRecord> {
        Arc::new(TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Reactive))
    }

    #[test]
    fn the_backlog_counts_records_queued_and_not_yet_taken() {
        let (tx, mut rx) = mpsc::channel(4);
        let feed = TickFeed::new().with_recorder(tx);
        let gauge = feed.recorder_gauge();
        assert!(gauge.attached());
        for seq in 0..6 {
            feed.publish(record(seq));
        }
        assert_eq!(gauge.backlog(), 4);
        assert_eq!(gauge.dropped(), 2);
        assert!(rx.try_recv().is_ok());
        assert_eq!(gauge.backlog(), 3);
        // The gauge keeps no sender: the recorder sees the end of the feed.
        drop(feed);
        while rx.try_recv().is_ok() {}
        assert!(rx.is_closed());
        assert_eq!(gauge.backlog(), 0);
    }

    #[test]
    fn without_a_recorder_there_is_no_backlog() {
        let feed = TickFeed::new();
        assert!(!feed.recorder_gauge().attached());
        assert_eq!(feed.recorder_gauge().backlog(), 0);
    }
}
