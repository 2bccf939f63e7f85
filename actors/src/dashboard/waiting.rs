//! The messages of one websocket connection waiting for its worker, in the order the reader read them: a
//! request still to be handled, or a refusal the reader already made (`rate_limited`, `busy`, a binary
//! frame's error), which waits its turn all the same so that every reply leaves in the order of the
//! messages it answers. The reader never waits on the worker: it puts each message in the line at once or
//! learns that there is no room.
//!
//! Two bounds, kept apart: at most [`MAX_REQUESTS`] requests wait (the next is refused `busy`, and that
//! refusal joins the line), and at most [`MAX_REFUSALS`] refusals of at most [`MAX_REFUSAL_BYTES`] together
//! (a refusal costs the worker no work, only the memory of its text). A connection that finds no room for
//! a refusal has sent that many messages it may not send while its own commands are still waiting: the
//! session closes it (1008), or drops it as a client that does not read its replies when those are what
//! holds the worker up.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use tokio::sync::mpsc;

/// Requests of one connection waiting for their turn (behind a command being applied) before the next is
/// answered `busy`; above the rate limit's burst, so a client within its limit never sees it.
pub const MAX_REQUESTS: usize = 64;
/// Refusals of one connection waiting for their turn before the connection is closed.
pub const MAX_REFUSALS: usize = 256;
/// The text of the refusals waiting, bytes, before the connection is closed (an echoed `id` may be long).
pub const MAX_REFUSAL_BYTES: usize = 256 * 1024;

/// One message's place in the line.
pub(crate) enum Turn<R> {
    /// To be handled by the worker.
    Request(R),
    /// Already answered: the reply, sent in its turn.
    Refusal(String),
}

/// Why a message found no place in the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NoRoom {
    /// The line holds as many messages of this kind as it may.
    Full,
    /// The worker is gone.
    Gone,
}

/// What waits now.
#[derive(Debug, Default)]
struct Load {
    requests: usize,
    refusals: usize,
    refusal_bytes: usize,
}

/// The reader's end.
pub(crate) struct LineIn<R> {
    tx: mpsc::UnboundedSender<Box<Turn<R>>>,
    load: Arc<Mutex<Load>>,
}

/// The worker's end.
pub(crate) struct LineOut<R> {
    rx: mpsc::UnboundedReceiver<Box<Turn<R>>>,
    load: Arc<Mutex<Load>>,
}

/// A new, empty line. Its turns wait boxed: the channel's blocks of slots are a pointer each.
pub(crate) fn line<R>() -> (LineIn<R>, LineOut<R>) {
    let (tx, rx) = mpsc::unbounded_channel();
    let load = Arc::new(Mutex::new(Load::default()));
    (
        LineIn {
            tx,
            load: load.clone(),
        },
        LineOut { rx, load },
    )
}

fn lock(load: &Mutex<Load>) -> MutexGuard<'_, Load> {
    load.lock().unwrap_or_else(PoisonError::into_inner)
}

impl<R> LineIn<R> {
    /// Puts a request at the end of the line; gives it back when [`MAX_REQUESTS`] are waiting, or when the
    /// worker is gone.
    pub(crate) fn push_request(&self, request: R) -> Result<(), (R, NoRoom)> {
        let mut load = lock(&self.load);
        if load.requests >= MAX_REQUESTS {
            return Err((request, NoRoom::Full));
        }
        match self.tx.send(Box::new(Turn::Request(request))) {
            Ok(()) => {
                load.requests += 1;
                Ok(())
            }
            Err(mpsc::error::SendError(turn)) => match *turn {
                Turn::Request(r) => Err((r, NoRoom::Gone)),
                Turn::Refusal(_) => unreachable!("a request was sent"),
            },
        }
    }

    /// Puts a refusal at the end of the line, unless [`MAX_REFUSALS`] or [`MAX_REFUSAL_BYTES`] would be
    /// passed.
    pub(crate) fn push_refusal(&self, reply: String) -> Result<(), NoRoom> {
        let mut load = lock(&self.load);
        let bytes = reply.len();
        if load.refusals >= MAX_REFUSALS || load.refusal_bytes + bytes > MAX_REFUSAL_BYTES {
            return Err(NoRoom::Full);
        }
        self.tx
            .send(Box::new(Turn::Refusal(reply)))
            .map_err(|_| NoRoom::Gone)?;
        load.refusals += 1;
        load.refusal_bytes += bytes;
        Ok(())
    }
}

impl<R> LineOut<R> {
    /// The next turn, in the order they were put; `None` once the reader's end is dropped and the line is
    /// empty.
    pub(crate) async fn next(&mut self) -> Option<Turn<R>> {
        let turn = *self.rx.recv().await?;
        let mut load = lock(&self.load);
        match &turn {
            Turn::Request(_) => load.requests -= 1,
            Turn::Refusal(reply) => {
                load.refusals -= 1;
                load.refusal_bytes -= reply.len();
            }
        }
        Some(turn)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn take<R>(out: &mut LineOut<R>) -> Option<Turn<R>> {
        futures_util::FutureExt::now_or_never(out.next()).flatten()
    }

    #[test]
    fn requests_and_refusals_leave_in_the_order_they_were_put() {
        let (tx, mut rx) = line::<u32>();
        tx.push_request(1).unwrap();
        tx.push_refusal("two".into()).unwrap();
        tx.push_request(3).unwrap();
        assert!(matches!(take(&mut rx), Some(Turn::Request(1))));
        assert!(matches!(take(&mut rx), Some(Turn::Refusal(r)) if r == "two"));
        assert!(matches!(take(&mut rx), Some(Turn::Request(3))));
        assert!(take(&mut rx).is_none());
    }

    #[test]
    fn a_full_line_of_requests_still_takes_refusals_and_a_taken_request_makes_room() {
        let (tx, mut rx) = line::<usize>();
        for i in 0..MAX_REQUESTS {
            tx.push_request(i).unwrap();
        }
        assert_eq!(
            tx.push_request(MAX_REQUESTS),
            Err((MAX_REQUESTS, NoRoom::Full))
        );
        tx.push_refusal("busy".into()).unwrap();
        assert!(matches!(take(&mut rx), Some(Turn::Request(0))));
        tx.push_request(MAX_REQUESTS).unwrap();
    }

    #[test]
    fn refusals_are_bounded_by_count_and_by_bytes() {
        let (tx, mut rx) = line::<()>();
        for _ in 0..MAX_REFUSALS {
            tx.push_refusal("no".into()).unwrap();
        }
        assert_eq!(tx.push_refusal("no".into()), Err(NoRoom::Full));
        assert!(matches!(take(&mut rx), Some(Turn::Refusal(_))));
        tx.push_refusal("no".into()).unwrap();

        let (tx, mut rx) = line::<()>();
        let half = "x".repeat(MAX_REFUSAL_BYTES / 2);
        tx.push_refusal(half.clone()).unwrap();
        tx.push_refusal(half.clone()).unwrap();
        assert_eq!(tx.push_refusal("x".into()), Err(NoRoom::Full));
        assert!(matches!(take(&mut rx), Some(Turn::Refusal(_))));
        tx.push_refusal(half).unwrap();
    }

    #[test]
    fn the_line_reports_a_gone_worker_and_ends_once_the_reader_is_gone() {
        let (tx, rx) = line::<u8>();
        drop(rx);
        assert_eq!(tx.push_request(7), Err((7, NoRoom::Gone)));
        assert_eq!(tx.push_refusal("no".into()), Err(NoRoom::Gone));

        let (tx, mut rx) = line::<u8>();
        tx.push_request(1).unwrap();
        drop(tx);
        assert!(matches!(take(&mut rx), Some(Turn::Request(1))));
        assert!(take(&mut rx).is_none());
    }
}
