//! A count of the messages Zenoh's transport drops for being larger than
//! `transport.link.rx.max_message_size` (the bridge and the fleet set it: `zenoh_bridge::wire::harden`).
//!
//! Zenoh drops such a message while reassembling its fragments, before anything of it is delivered, and
//! says so only in a trace-level log line ("Defragmentation buffer full") of its receive path; it has no
//! counter or callback. [`layer`] is a tracing layer that sees only that module's trace events (its own
//! filter: the rest of the program's logging keeps `RUST_LOG`) and counts the lines that report such a
//! drop in [`OVERSIZED_DROPS`]; the bridge publishes the count as
//! `pavlov_zenoh_oversized_dropped_total`. Reading a line costs at most its first few dozen characters.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};

use tracing::field::{Field, Visit};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::layer::Context;

/// Messages Zenoh dropped for their size since the process started.
pub static OVERSIZED_DROPS: AtomicU64 = AtomicU64::new(0);

/// Zenoh's receive path, where the drop is logged.
const TARGET: &str = "zenoh_transport::unicast::universal::rx";

/// The start of the line that reports the drop.
const MARK: &str = "Defragmentation buffer full";

/// A writer that keeps the first `MARK.len()` bytes and then refuses, which stops the formatting.
#[derive(Default)]
struct Head(String);

impl std::fmt::Write for Head {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let room = MARK.len().saturating_sub(self.0.len());
        let take = s.char_indices().nth(room).map_or(s.len(), |(i, _)| i);
        self.0.push_str(&s[..take]);
        if self.0.len() >= MARK.len() {
            Err(std::fmt::Error)
        } else {
            Ok(())
        }
    }
}

/// Whether an event's message starts with the mark.
#[derive(Default)]
struct Finder(bool);

impl Visit for Finder {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let mut head = Head::default();
            let _ = write!(head, "{value:?}");
            self.0 = head.0.starts_with(MARK);
        }
    }
}

/// The counting layer.
struct Counter;

impl<S: tracing::Subscriber> Layer<S> for Counter {
    fn on_event(&self, event: &tracing::Event<'_>, _: Context<'_, S>) {
        let mut finder = Finder::default();
        event.record(&mut finder);
        if finder.0 {
            OVERSIZED_DROPS.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The layer, filtered to Zenoh's receive path at trace level.
pub fn layer<S>() -> impl Layer<S>
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    Counter.with_filter(Targets::new().with_target(TARGET, tracing::Level::TRACE))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::layer::SubscriberExt;

    #[test]
    fn the_drop_line_is_counted_and_nothing_else() {
        let subscriber = tracing_subscriber::registry().with(layer());
        let before = OVERSIZED_DROPS.load(Ordering::Relaxed);
        tracing::subscriber::with_default(subscriber, || {
            let e = "Defragmentation buffer full: 70000 bytes. Capacity: 65536.";
            tracing::trace!(target: "zenoh_transport::unicast::universal::rx", "{}", e);
            tracing::trace!(target: "zenoh_transport::unicast::universal::rx", "Received: frame");
            tracing::trace!(target: "elsewhere", "{}", e);
        });
        assert_eq!(OVERSIZED_DROPS.load(Ordering::Relaxed) - before, 1);
    }

    #[test]
    fn the_head_stops_after_the_mark() {
        let mut head = Head::default();
        let long = "x".repeat(10_000);
        assert!(write!(head, "{long}").is_err());
        assert_eq!(head.0.len(), MARK.len());
    }
}
