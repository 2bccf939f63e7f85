//! Logging that can never affect control.
//!
//! The formatting layer of `tracing-subscriber` writes each event into a [`LogSink`], which only hands the
//! formatted line to a bounded queue (`try_send`: a full queue drops the line and counts it) and always
//! reports success. A dedicated thread takes lines off the queue and writes them to stderr; a failed write
//! (stderr closed, `tee` gone, a full pipe's EPIPE) is counted and ignored, and after the first failure the
//! thread stops trying and only drains. So no actor ever waits on a log write, and no log write can panic:
//! `tracing-subscriber`'s own complaint about a failing writer goes through `eprintln!`, which panics on a
//! closed stderr, so it is turned off ([`init`]).
//!
//! Colour codes are used only when stderr is a terminal, so a log file holds plain text.

use std::io::{IsTerminal, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::Duration;

use tracing_subscriber::EnvFilter;
use tracing_subscriber::Layer as _;
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;

/// Lines the queue holds before new ones are dropped (about a minute of a busy INFO log).
pub const QUEUE_LINES: usize = 4096;

/// What the logging thread has seen, shared with whoever wants to report it.
#[derive(Debug, Default)]
pub struct LogCounters {
    /// Lines dropped because the queue was full.
    pub dropped: AtomicU64,
    /// Lines the thread could not write (and dropped).
    pub failed: AtomicU64,
    /// Set after the first failed write: stderr is gone.
    pub broken: AtomicBool,
    /// Lines queued and not yet written.
    pub pending: AtomicU64,
}

/// The writer the formatting layer writes each event into.
#[derive(Clone)]
pub struct LogSink {
    queue: SyncSender<Vec<u8>>,
    counters: Arc<LogCounters>,
}

impl LogSink {
    /// A sink and the receiving end the writing thread drains.
    fn new(capacity: usize) -> (Self, Receiver<Vec<u8>>) {
        let (queue, lines) = sync_channel(capacity.max(1));
        let sink = LogSink {
            queue,
            counters: Arc::new(LogCounters::default()),
        };
        (sink, lines)
    }

    /// The sink's counters.
    pub fn counters(&self) -> Arc<LogCounters> {
        self.counters.clone()
    }
}

impl Write for LogSink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.queue.try_send(buf.to_vec()) {
            Ok(()) => {
                self.counters.pending.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
        // Always "written": a log line that cannot go out is counted, never an error for the caller.
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> MakeWriter<'a> for LogSink {
    type Writer = LogSink;

    fn make_writer(&'a self) -> Self::Writer {
        self.clone()
    }
}

/// Writes `lines` to `out` until every sender is gone; failures are counted, never raised.
fn drain(lines: Receiver<Vec<u8>>, mut out: impl Write, counters: &LogCounters) {
    while let Ok(line) = lines.recv() {
        counters.pending.fetch_sub(1, Ordering::Relaxed);
        if counters.broken.load(Ordering::Relaxed) {
            counters.failed.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        if out.write_all(&line).and_then(|()| out.flush()).is_err() {
            counters.failed.fetch_add(1, Ordering::Relaxed);
            counters.broken.store(true, Ordering::Relaxed);
        }
    }
}

/// Keeps the logging thread; dropping it waits briefly for queued lines to go out.
pub struct LogGuard {
    thread: Option<std::thread::JoinHandle<()>>,
    counters: Arc<LogCounters>,
}

impl LogGuard {
    /// The logging counters.
    pub fn counters(&self) -> Arc<LogCounters> {
        self.counters.clone()
    }
}

impl Drop for LogGuard {
    fn drop(&mut self) {
        // The global subscriber keeps its sink, so the thread never sees the end of the queue: give it a
        // moment to write what is queued, without ever hanging the exit.
        let deadline = std::time::Instant::now() + Duration::from_millis(200);
        while self.thread.as_ref().is_some_and(|t| !t.is_finished())
            && self.counters.pending.load(Ordering::Relaxed) > 0
            && !self.counters.broken.load(Ordering::Relaxed)
            && std::time::Instant::now() < deadline
        {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// Installs the global subscriber: `filter` (from `RUST_LOG`, default `info`), plain text unless stderr is a
/// terminal, written through a [`LogSink`] by a thread of its own; beside it, with a filter of its own,
/// the count of Zenoh's oversized-message drops ([`super::zenoh_drops`]).
pub fn init(filter: EnvFilter) -> LogGuard {
    let (sink, lines) = LogSink::new(QUEUE_LINES);
    let counters = sink.counters();
    let thread_counters = counters.clone();
    let thread = std::thread::Builder::new()
        .name("log-writer".into())
        .spawn(move || drain(lines, std::io::stderr(), &thread_counters))
        .ok();
    let fmt = tracing_subscriber::fmt::layer()
        .with_ansi(std::io::stderr().is_terminal())
        .log_internal_errors(false)
        .with_writer(sink)
        .with_filter(filter);
    let _ = tracing_subscriber::registry()
        .with(fmt)
        .with(super::zenoh_drops::layer())
        .try_init();
    LogGuard { thread, counters }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer that fails every write, like a closed pipe.
    struct Closed;

    impl Write for Closed {
        fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
            Err(std::io::Error::from(std::io::ErrorKind::BrokenPipe))
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_full_queue_drops_lines_without_blocking_or_failing() {
        let (mut sink, lines) = LogSink::new(2);
        for _ in 0..5 {
            assert_eq!(sink.write(b"line\n").unwrap(), 5);
        }
        assert_eq!(sink.counters().dropped.load(Ordering::Relaxed), 3);
        drop(lines);
        // With the writing side gone, writes still succeed and are counted.
        assert!(sink.write(b"more\n").is_ok());
        assert_eq!(sink.counters().dropped.load(Ordering::Relaxed), 4);
    }

    #[test]
    fn a_closed_output_is_counted_once_broken_and_drained() {
        let (mut sink, lines) = LogSink::new(16);
        let counters = sink.counters();
        for _ in 0..3 {
            sink.write_all(b"x\n").unwrap();
        }
        drop(sink);
        drain(lines, Closed, &counters);
        assert!(counters.broken.load(Ordering::Relaxed));
        assert_eq!(counters.failed.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn lines_reach_a_working_output_in_order() {
        let (mut sink, lines) = LogSink::new(16);
        let counters = sink.counters();
        sink.write_all(b"a\n").unwrap();
        sink.write_all(b"b\n").unwrap();
        drop(sink);
        let mut out = Vec::new();
        drain(lines, &mut out, &counters);
        assert_eq!(out, b"a\nb\n");
    }
}
