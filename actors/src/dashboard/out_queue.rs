//! Per-client outgoing queue and tick-rate decimation.
//!
//! Each websocket client has one [`OutQueue`] between the producers (the hub's tick/status stream and the
//! client's own command replies) and the task that writes to the socket. Telemetry is bounded and lossy:
//! when a client falls behind, the oldest telemetry is dropped and counted, so a stalled client costs a
//! fixed amount of memory and never slows anyone else. Replies are never dropped: when the reply capacity
//! is reached, the connection's reader waits for room ([`OutQueue::push_control_waiting`]), which stops it
//! reading the socket and so pushes back on the client; a client that leaves its replies unread for the
//! whole wait is disconnected (see [`QueueFull`]).
//!
//! A third lane, the *slot*, holds at most one bulky opt-in message (the Horde's values and names): it goes
//! out after the replies and before the telemetry, and its producer puts the next one only once the last
//! was taken ([`OutQueue::try_put_slot`], [`OutQueue::put_slot_waiting`]), so a slow client holds one
//! such message, never a queue of them, and the ticks behind it are not pushed out by it.

use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::sync::Notify;

/// Replies (acks, errors, hello, close) queued before the client is considered hopeless.
pub(crate) const CONTROL_CAPACITY: usize = 64;

/// The reply queue is full: the client has not read its replies for a long time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the client's reply queue is full ({CONTROL_CAPACITY} unread replies)")]
pub(crate) struct QueueFull;

struct QueueState<T> {
    control: VecDeque<T>,
    telemetry: VecDeque<T>,
    slot: Option<T>,
    closed: bool,
}

#[derive(Clone, Copy)]
enum Lane {
    Control,
    Slot,
    Telemetry,
}

/// A bounded, drop-oldest queue of outgoing messages for one client, with one consumer.
pub(crate) struct OutQueue<T> {
    state: Mutex<QueueState<T>>,
    ready: Notify,
    room: Notify,
    slot_free: Notify,
    telemetry_capacity: usize,
    dropped: AtomicU64,
}

impl<T> OutQueue<T> {
    /// A queue holding at most `telemetry_capacity` (at least 1) telemetry messages.
    pub(crate) fn new(telemetry_capacity: usize) -> Self {
        OutQueue {
            state: Mutex::new(QueueState {
                control: VecDeque::new(),
                telemetry: VecDeque::new(),
                slot: None,
                closed: false,
            }),
            ready: Notify::new(),
            room: Notify::new(),
            slot_free: Notify::new(),
            telemetry_capacity: telemetry_capacity.max(1),
            dropped: AtomicU64::new(0),
        }
    }

    fn with_state<R>(&self, f: impl FnOnce(&mut QueueState<T>) -> R) -> R {
        // A poisoned lock only means another thread panicked mid-push; the queue itself is still valid.
        let mut guard = match self.state.lock() {
            Ok(g) => g,
            Err(poisoned) => poisoned.into_inner(),
        };
        f(&mut guard)
    }

    /// Queues a tick or status message, dropping the oldest one when full. Returns how many were dropped.
    pub(crate) fn push_telemetry(&self, msg: T) -> u64 {
        let dropped = self.with_state(|s| {
            if s.closed {
                return 0;
            }
            let mut dropped = 0;
            while s.telemetry.len() >= self.telemetry_capacity {
                s.telemetry.pop_front();
                dropped += 1;
            }
            s.telemetry.push_back(msg);
            dropped
        });
        if dropped > 0 {
            self.dropped.fetch_add(dropped, Ordering::Relaxed);
        }
        self.ready.notify_one();
        dropped
    }

    /// Counts telemetry that was lost before it reached this queue (e.g. a lagging broadcast).
    pub(crate) fn count_dropped(&self, n: u64) {
        self.dropped.fetch_add(n, Ordering::Relaxed);
    }

    /// Queues a reply; it goes out before any queued telemetry. Gives the reply back when the queue
    /// already holds [`CONTROL_CAPACITY`] replies.
    fn try_push_control(&self, msg: T) -> Result<(), T> {
        let pushed = self.with_state(|s| {
            if s.control.len() >= CONTROL_CAPACITY {
                return Err(msg);
            }
            if !s.closed {
                s.control.push_back(msg);
            }
            Ok(())
        });
        self.ready.notify_one();
        pushed
    }

    /// Queues a reply; it goes out before any queued telemetry.
    pub(crate) fn push_control(&self, msg: T) -> Result<(), QueueFull> {
        self.try_push_control(msg).map_err(|_| QueueFull)
    }

    /// Queues a reply, waiting up to `patience` for room when [`CONTROL_CAPACITY`] replies are unread.
    pub(crate) async fn push_control_waiting(
        &self,
        msg: T,
        patience: Duration,
    ) -> Result<(), QueueFull> {
        let deadline = tokio::time::Instant::now() + patience;
        let mut msg = msg;
        loop {
            match self.try_push_control(msg) {
                Ok(()) => return Ok(()),
                Err(back) => msg = back,
            }
            // `notify_one` leaves a permit when nobody waits, so a pop between the try and here is not lost.
            if tokio::time::timeout_at(deadline, self.room.notified())
                .await
                .is_err()
            {
                return Err(QueueFull);
            }
        }
    }

    #[cfg(test)]
    fn pop_now(&self) -> Option<T> {
        let (next, lane) = self.with_state(|s| match s.control.pop_front() {
            Some(reply) => (Some(reply), Lane::Control),
            None => match s.slot.take() {
                Some(m) => (Some(m), Lane::Slot),
                None => (s.telemetry.pop_front(), Lane::Telemetry),
            },
        });
        self.taken(lane);
        next
    }

    fn taken(&self, lane: Lane) {
        match lane {
            Lane::Control => self.room.notify_one(),
            Lane::Slot => self.slot_free.notify_one(),
            Lane::Telemetry => {}
        }
    }

    /// Puts `msg` in the slot if it is free (and the queue open); gives it back otherwise.
    pub(crate) fn try_put_slot(&self, msg: T) -> Result<(), T> {
        let put = self.with_state(|s| {
            if s.closed || s.slot.is_some() {
                Err(msg)
            } else {
                s.slot = Some(msg);
                Ok(())
            }
        });
        if put.is_ok() {
            self.ready.notify_one();
        }
        put
    }

    /// Puts `msg` in the slot once it is free; gives up (`false`) when the queue closes.
    pub(crate) async fn put_slot_waiting(&self, msg: T) -> bool {
        let mut msg = msg;
        loop {
            match self.try_put_slot(msg) {
                Ok(()) => return true,
                Err(back) => msg = back,
            }
            if self.is_closed() {
                return false;
            }
            // `notify_one` leaves a permit when nobody waits, so a take between the try and here is not lost.
            self.slot_free.notified().await;
        }
    }

    /// Takes the next message without waiting: replies first, then telemetry, oldest first.
    #[cfg(test)]
    pub(crate) fn try_pop(&self) -> Option<T> {
        self.pop_now()
    }

    /// Takes the next reply, if one is waiting.
    pub(crate) fn try_pop_control(&self) -> Option<T> {
        let reply = self.with_state(|s| s.control.pop_front());
        if reply.is_some() {
            self.room.notify_one();
        }
        reply
    }

    /// Whether [`OutQueue::close`] was called.
    pub(crate) fn is_closed(&self) -> bool {
        self.with_state(|s| s.closed)
    }

    /// Waits for the next message; `None` once the queue is closed and empty of replies.
    pub(crate) async fn pop(&self) -> Option<T> {
        loop {
            let (next, lane, closed) = self.with_state(|s| match s.control.pop_front() {
                Some(reply) => (Some(reply), Lane::Control, s.closed),
                None if s.closed => (None, Lane::Telemetry, true),
                None => match s.slot.take() {
                    Some(m) => (Some(m), Lane::Slot, false),
                    None => (s.telemetry.pop_front(), Lane::Telemetry, false),
                },
            });
            self.taken(lane);
            if next.is_some() {
                return next;
            }
            if closed {
                return None;
            }
            // `notify_one` leaves a permit when nobody waits, so a push between the check and here is not lost.
            self.ready.notified().await;
        }
    }

    /// Stops accepting telemetry; queued replies still drain, then [`OutQueue::pop`] returns `None`.
    pub(crate) fn close(&self) {
        self.with_state(|s| {
            s.closed = true;
            s.telemetry.clear();
            s.slot = None;
        });
        self.ready.notify_one();
        self.slot_free.notify_one();
    }

    /// Telemetry dropped so far.
    /// Whether [`CONTROL_CAPACITY`] replies are waiting: the client is not taking its replies.
    pub(crate) fn replies_full(&self) -> bool {
        self.with_state(|s| s.control.len() >= CONTROL_CAPACITY)
    }

    pub(crate) fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Messages waiting (replies + telemetry).
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.with_state(|s| s.control.len() + s.telemetry.len() + usize::from(s.slot.is_some()))
    }
}

/// Passes every `n`-th tick: a client's requested rate turned into a stride over tick sequence numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Decimator {
    every: u64,
    next_seq: Option<u64>,
}

impl Decimator {
    /// Passes every tick.
    pub(crate) fn all() -> Self {
        Decimator {
            every: 1,
            next_seq: None,
        }
    }

    /// The stride for `hz` when ticks come at `tick_hz`: at least 1, so asking for more than the tick
    /// rate gives every tick.
    pub(crate) fn stride_for(hz: f64, tick_hz: f64) -> u64 {
        if hz.is_nan() || tick_hz.is_nan() || hz <= 0.0 || tick_hz <= 0.0 {
            return 1;
        }
        let stride = (tick_hz / hz).round();
        if stride < 1.0 {
            1
        } else {
            stride.min(u64::MAX as f64) as u64
        }
    }

    /// Changes the stride; the next tick passes.
    pub(crate) fn set_every(&mut self, every: u64) {
        self.every = every.max(1);
        self.next_seq = None;
    }

    /// The current stride.
    pub(crate) fn every(&self) -> u64 {
        self.every
    }

    /// Whether tick `seq` goes to the client. Gaps (skipped or dropped ticks) never cause a burst.
    pub(crate) fn pass(&mut self, seq: u64) -> bool {
        match self.next_seq {
            Some(next) if seq < next => false,
            _ => {
                self.next_seq = Some(seq.saturating_add(self.every));
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn telemetry_drops_the_oldest_when_full_and_counts_it() {
        let q = OutQueue::new(3);
        let dropped: u64 = (0..10).map(|i| q.push_telemetry(i)).sum();
        assert_eq!(dropped, 7);
        assert_eq!(q.dropped(), 7);
        assert_eq!(q.len(), 3);
        assert_eq!(
            [q.try_pop(), q.try_pop(), q.try_pop(), q.try_pop()],
            [Some(7), Some(8), Some(9), None]
        );
    }

    #[test]
    fn replies_jump_the_telemetry_and_are_never_dropped() {
        let q = OutQueue::new(1);
        q.push_telemetry("tick1");
        q.push_telemetry("tick2");
        q.push_control("ack").unwrap();
        q.push_telemetry("tick3");
        assert_eq!(q.try_pop(), Some("ack"));
        assert_eq!(q.try_pop(), Some("tick3"));
        assert_eq!(q.dropped(), 2);
    }

    #[test]
    fn a_client_that_reads_no_replies_overflows_the_reply_queue() {
        let q = OutQueue::new(4);
        for i in 0..CONTROL_CAPACITY {
            q.push_control(i).unwrap();
        }
        assert_eq!(q.push_control(999), Err(QueueFull));
        assert_eq!(q.try_pop(), Some(0));
        assert!(q.push_control(1000).is_ok());
    }

    #[tokio::test(start_paused = true)]
    async fn a_full_reply_queue_makes_the_sender_wait_for_room_then_gives_up() {
        let q = std::sync::Arc::new(OutQueue::new(4));
        for i in 0..CONTROL_CAPACITY {
            q.push_control(i).unwrap();
        }
        let waiting = {
            let q = q.clone();
            tokio::spawn(async move { q.push_control_waiting(999, Duration::from_secs(5)).await })
        };
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert!(!waiting.is_finished());
        assert_eq!(q.try_pop(), Some(0));
        assert_eq!(waiting.await.unwrap(), Ok(()));
        assert_eq!(q.len(), CONTROL_CAPACITY);
        // Nobody reads: the wait ends after the patience.
        let t0 = tokio::time::Instant::now();
        assert_eq!(
            q.push_control_waiting(1000, Duration::from_secs(5)).await,
            Err(QueueFull)
        );
        assert_eq!(t0.elapsed(), Duration::from_secs(5));
    }

    #[test]
    fn lost_upstream_telemetry_is_counted() {
        let q: OutQueue<u8> = OutQueue::new(4);
        q.count_dropped(5);
        assert_eq!(q.dropped(), 5);
    }

    #[tokio::test]
    async fn pop_waits_for_a_push_and_ends_after_close() {
        let q = std::sync::Arc::new(OutQueue::new(8));
        let consumer = {
            let q = q.clone();
            tokio::spawn(async move {
                let mut got = Vec::new();
                while let Some(m) = q.pop().await {
                    got.push(m);
                }
                got
            })
        };
        tokio::task::yield_now().await;
        q.push_telemetry(1);
        q.push_control(2).unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        q.push_control(3).unwrap();
        q.close();
        q.push_telemetry(4); // after close: ignored
        let got = consumer.await.unwrap();
        assert!(
            got.starts_with(&[1, 2]) || got.starts_with(&[2, 1]),
            "{got:?}"
        );
        assert_eq!(got.last(), Some(&3));
        assert!(!got.contains(&4));
    }

    #[test]
    fn replies_can_be_taken_alone_leaving_the_telemetry() {
        let q = OutQueue::new(8);
        q.push_telemetry("tick");
        assert_eq!(q.try_pop_control(), None);
        q.push_control("ack").unwrap();
        assert_eq!(q.try_pop_control(), Some("ack"));
        assert_eq!(q.try_pop(), Some("tick"));
        assert!(!q.is_closed());
        q.close();
        assert!(q.is_closed());
    }

    #[test]
    fn close_discards_telemetry_but_keeps_replies() {
        let q = OutQueue::new(8);
        q.push_telemetry("tick");
        q.push_control("bye").unwrap();
        q.close();
        assert_eq!(q.try_pop(), Some("bye"));
        assert_eq!(q.try_pop(), None);
    }

    #[tokio::test]
    async fn the_slot_holds_one_message_between_the_replies_and_the_telemetry() {
        let q = OutQueue::new(4);
        q.push_telemetry("tick");
        assert!(q.try_put_slot("horde 1").is_ok());
        // Full: the producer gets its message back, and nothing else moves.
        assert_eq!(q.try_put_slot("horde 2"), Err("horde 2"));
        q.push_control("ack").unwrap();
        assert_eq!(q.len(), 3);
        assert_eq!(q.pop().await, Some("ack"));
        assert_eq!(q.pop().await, Some("horde 1"));
        // Taken: a waiting producer gets in.
        assert!(q.put_slot_waiting("horde 2").await);
        assert_eq!(q.pop().await, Some("horde 2"));
        assert_eq!(q.pop().await, Some("tick"));
        // A producer waiting on a full slot gives up when the queue closes.
        assert!(q.try_put_slot("horde 3").is_ok());
        let waiting = q.put_slot_waiting("horde 4");
        tokio::pin!(waiting);
        tokio::select! {
            biased;
            _ = &mut waiting => panic!("the slot is full: the producer must wait"),
            _ = tokio::task::yield_now() => {}
        }
        q.close();
        assert!(!waiting.await);
        assert_eq!(q.pop().await, None);
    }

    #[test]
    fn stride_follows_the_requested_rate() {
        assert_eq!(Decimator::stride_for(50.0, 50.0), 1);
        assert_eq!(Decimator::stride_for(10.0, 50.0), 5);
        assert_eq!(Decimator::stride_for(1.0, 50.0), 50);
        assert_eq!(Decimator::stride_for(500.0, 50.0), 1);
        assert_eq!(Decimator::stride_for(0.0, 50.0), 1);
        assert_eq!(Decimator::stride_for(f64::NAN, 50.0), 1);
        assert_eq!(Decimator::stride_for(1e-300, 50.0), u64::MAX);
    }

    #[test]
    fn decimation_passes_every_nth_tick_and_survives_gaps() {
        let mut d = Decimator::all();
        assert!((0..5).all(|s| d.pass(s)));
        d.set_every(5);
        let passed: Vec<u64> = (5..30).filter(|&s| d.pass(s)).collect();
        assert_eq!(passed, vec![5, 10, 15, 20, 25]);
        // A gap: the next tick after the gap passes, then the stride resumes from it.
        let passed: Vec<u64> = [31, 33, 37, 40, 41, 42]
            .into_iter()
            .filter(|&s| d.pass(s))
            .collect();
        assert_eq!(passed, vec![31, 37, 42]);
        assert_eq!(d.every(), 5);
    }
}
