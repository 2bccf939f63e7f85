//! The tick feed: every [`TickRecord`] goes out to the dashboard hub, the recorder and the metrics.
//!
//! Publishing never blocks the tick. Live subscribers (websocket clients, tests) share a `broadcast` channel:
//! a subscriber that falls behind skips the oldest records and is told how many it missed. The recorder gets
//! its own bounded queue; when it is full the record is dropped and counted, so a slow disk is visible rather
//! than silently slowing control.
//!
//! The newest link summary is replaced on every record, but its watchers are woken only when the link's
//! state changes: its counters move on every tick, and waking (eight `Notify`s in tokio's `watch`) on
//! every tick cost the tick's thread more than the rest of publishing. Readers `borrow` the newest.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use pavlov::record::{LinkStatus, TickRecord};

use super::recorder_queue::{RecorderGauge, RecorderInput};
use tokio::sync::{broadcast, mpsc, watch};

/// Capacity of the live broadcast, in records (20 s at 50 Hz).
pub(crate) const LIVE_CAPACITY: usize = 1024;

/// Whether watchers of the link summary should wake for `new`: on the first record and whenever the
/// link's state, up flag, OI mode or trip cause differ from `old` (not for its counters alone).
fn link_changed(old: Option<&LinkStatus>, new: &LinkStatus) -> bool {
    old.is_none_or(|o| (o.up, o.state, o.mode, o.trip) != (new.up, new.state, new.mode, new.trip))
}

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
        // The value is always replaced (readers `borrow` the newest); watchers wake on a change of state.
        let link = record.link;
        self.latest_link.send_if_modified(|latest| {
            let changed = link_changed(latest.as_ref(), &link);
            *latest = Some(link);
            changed
        });
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

    /// The link summary of the newest record (`None` before the first). `changed` wakes when the
    /// link's state, up flag, OI mode or trip cause change; `borrow` always gives the newest record's.
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
    fn the_link_summary_is_always_the_newest_and_wakes_watchers_on_a_change_of_state() {
        use pavlov::supervision::LinkState;
        let feed = TickFeed::new();
        let mut link = feed.latest_link();
        assert_eq!(*link.borrow(), None);
        let with = |seq: u64, good: u64, state: LinkState| {
            let mut r = TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Reactive);
            r.link.good_frames = good;
            r.link.state = state;
            Arc::new(r)
        };
        feed.publish(with(0, 1, LinkState::Up));
        assert!(link.has_changed().unwrap(), "the first record is a change");
        assert_eq!(link.borrow_and_update().unwrap().good_frames, 1);
        feed.publish(with(1, 2, LinkState::Up));
        assert!(!link.has_changed().unwrap(), "counters alone wake nobody");
        assert_eq!(link.borrow().unwrap().good_frames, 2, "but are the newest");
        feed.publish(with(2, 3, LinkState::Stale));
        assert!(link.has_changed().unwrap());
        let now = link.borrow_and_update().unwrap();
        assert_eq!((now.good_frames, now.state), (3, LinkState::Stale));
    }

    #[test]
    fn without_a_recorder_there_is_no_backlog() {
        let feed = TickFeed::new();
        assert!(!feed.recorder_gauge().attached());
        assert_eq!(feed.recorder_gauge().backlog(), 0);
    }
}
