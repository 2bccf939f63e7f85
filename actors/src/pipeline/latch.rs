//! The e-stop latch: the `watch` that actuation (the only writer of motion commands) and gating read on
//! every tick, and the one way to set it — logged, announced as an event, answered with its outcome.
//!
//! The router sets it for any client of the command inbox; an operator's websocket connection holds a
//! clone and sets it the moment it reads an `estop`, ahead of the commands that connection sent before
//! (`crate::dashboard::session`), so an e-stop is in force from the next tick however many slow commands
//! (a run of `save_weights`) its own connection has queued.

use std::sync::Arc;

use pavlov::event::EventKind;
use tokio::sync::watch;

use crate::bus::{EventLog, TickFeed};
use crate::command::Applied;

/// A handle on the e-stop latch; clones set the same latch.
#[derive(Clone)]
pub struct EstopLatch {
    latch: Arc<watch::Sender<bool>>,
    /// Where changes are announced, and the feed that tells the newest tick.
    events: Option<(EventLog, TickFeed)>,
}

impl EstopLatch {
    /// The latch behind `latch`, announcing its changes on `events`.
    pub(crate) fn new(latch: watch::Sender<bool>, events: Option<(EventLog, TickFeed)>) -> Self {
        EstopLatch {
            latch: Arc::new(latch),
            events,
        }
    }

    /// Latches (`true`) or releases (`false`) the e-stop; in force from the next tick on.
    pub fn set(&self, on: bool) -> Applied {
        self.latch.send_replace(on);
        if on {
            tracing::warn!("e-stop latched");
        }
        if let Some((events, feed)) = &self.events {
            events.emit(feed.last_seq(), EventKind::EStop { latched: on });
        }
        Applied::Estop { estop: on }
    }

    /// Whether the e-stop is latched now.
    pub fn latched(&self) -> bool {
        *self.latch.borrow()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_clone_sets_the_one_latch_the_actors_read() {
        let (tx, rx) = watch::channel(false);
        let latch = EstopLatch::new(tx, None);
        let other = latch.clone();
        assert_eq!(other.set(true), Applied::Estop { estop: true });
        assert!(*rx.borrow() && latch.latched());
        assert_eq!(latch.set(false), Applied::Estop { estop: false });
        assert!(!*rx.borrow() && !other.latched());
    }
}
