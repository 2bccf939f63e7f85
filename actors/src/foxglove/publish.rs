//! The publisher: reads the tick feed and the event log and logs them on the Foxglove channels.
//!
//! It holds receivers of the feed's and the event log's lossy broadcasts, so it can never delay the
//! tick: when it falls behind it loses the oldest records and counts them
//! (`pavlov_foxglove_missed_total`). A channel is serialised only while some client is subscribed to it.
//! Log times are Unix times on the run's own clock: a tick at its scheduled time (the run's start plus
//! `t_ms`), an event at the time of the first tick it applies to, the configuration at the run's start.
//!
//! A client that subscribes late still gets the configuration and the last [`RECENT_EVENTS`] events:
//! the SDK tells [`SubscribeListener`] about each subscription and the publisher sends those to that
//! client alone.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{SystemTime, UNIX_EPOCH};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{ChannelId, Context, FoxgloveError, PartialMetadata, RawChannel, Schema, SinkId};
use pavlov::event::Event;
use pavlov::record::TickRecord;
use tokio::sync::{broadcast, mpsc};
use tokio_util::sync::CancellationToken;

use super::schema;
use super::signals::Signals;
use crate::telemetry::counters::FoxgloveCounters;

/// The whole tick record.
pub const TOPIC_TICKS: &str = "/pavlov/ticks";
/// The flat, named view of each tick.
pub const TOPIC_SIGNALS: &str = "/pavlov/signals";
/// Every event.
pub const TOPIC_EVENTS: &str = "/pavlov/events";
/// The configuration in force.
pub const TOPIC_CONFIG: &str = "/pavlov/config";

/// Events kept for clients that subscribe later.
pub(crate) const RECENT_EVENTS: usize = 256;
/// Subscriptions waiting to be greeted.
const GREETING_QUEUE: usize = 64;

/// The four channels, on the endpoint's own context.
pub(crate) struct Channels {
    ticks: Arc<RawChannel>,
    signals: Arc<RawChannel>,
    events: Arc<RawChannel>,
    config: Arc<RawChannel>,
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    schema: serde_json::Value,
) -> Result<Arc<RawChannel>, FoxgloveError> {
    let name = schema["title"].as_str().unwrap_or(topic).to_string();
    let data = serde_json::to_vec(&schema).unwrap_or_default();
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", data))
        .build_raw()
}

impl Channels {
    /// Creates the channels; the signals schema names the run's observations and predictions.
    pub(crate) fn new(
        ctx: &Arc<Context>,
        obs_names: &[String],
        predictions: &[String],
    ) -> Result<Self, FoxgloveError> {
        Ok(Channels {
            ticks: json_channel(ctx, TOPIC_TICKS, schema::tick_record())?,
            signals: json_channel(ctx, TOPIC_SIGNALS, schema::signals(obs_names, predictions))?,
            events: json_channel(ctx, TOPIC_EVENTS, schema::event())?,
            config: json_channel(ctx, TOPIC_CONFIG, schema::config())?,
        })
    }
}

/// The run's clock in Unix nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RunClock {
    /// When the first tick was due.
    start_unix_ns: u64,
    /// The tick period.
    period_ns: u64,
}

impl RunClock {
    /// The clock of a run whose first tick was due at `started`.
    pub(crate) fn new(started: tokio::time::Instant, period_ms: u64) -> Self {
        let now = tokio::time::Instant::now();
        let unix_now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .as_nanos() as u64;
        let start_unix_ns = if started <= now {
            unix_now.saturating_sub((now - started).as_nanos() as u64)
        } else {
            unix_now.saturating_add((started - now).as_nanos() as u64)
        };
        RunClock {
            start_unix_ns,
            period_ns: period_ms.saturating_mul(1_000_000),
        }
    }

    /// A tick's scheduled time (`t_ms` after the first tick was due).
    pub(crate) fn tick(&self, t_ms: f64) -> u64 {
        let offset = (t_ms.max(0.0) * 1e6).round() as u64;
        self.start_unix_ns.saturating_add(offset)
    }

    /// The time of the first tick an event applies to (the one after `after`).
    pub(crate) fn event(&self, after: Option<u64>) -> u64 {
        let ticks = after.map_or(0, |a| a.saturating_add(1));
        self.start_unix_ns
            .saturating_add(ticks.saturating_mul(self.period_ns))
    }

    /// When the first tick was due.
    pub(crate) fn start(&self) -> u64 {
        self.start_unix_ns
    }
}

/// A client that has just subscribed to a channel.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Subscribed {
    sink: SinkId,
    channel: ChannelId,
}

/// Tells the publisher about each new subscription (the SDK calls it on the client's task; it only
/// queues).
pub(crate) struct SubscribeListener {
    tx: mpsc::Sender<Subscribed>,
}

impl ServerListener for SubscribeListener {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        if let Some(sink) = client.sink_id() {
            let request = Subscribed {
                sink,
                channel: channel.id(),
            };
            if self.tx.try_send(request).is_err() {
                tracing::debug!(
                    "foxglove: too many subscriptions at once; one client is not greeted"
                );
            }
        }
    }
}

/// The publisher's state.
pub(crate) struct Publisher {
    channels: Channels,
    clock: RunClock,
    obs_names: Vec<String>,
    config_message: Vec<u8>,
    /// Clients without the token may connect: events go out as a watcher may see them.
    watchers: bool,
    recent_events: VecDeque<(Vec<u8>, u64)>,
    counters: Arc<FoxgloveCounters>,
}

/// What the publisher reads.
pub(crate) struct Inputs {
    pub(crate) ticks: broadcast::Receiver<Arc<TickRecord>>,
    pub(crate) events: broadcast::Receiver<Arc<Event>>,
    pub(crate) subscribed: mpsc::Receiver<Subscribed>,
}

/// A listener and the queue it fills.
pub(crate) fn subscribe_listener() -> (Arc<SubscribeListener>, mpsc::Receiver<Subscribed>) {
    let (tx, rx) = mpsc::channel(GREETING_QUEUE);
    (Arc::new(SubscribeListener { tx }), rx)
}

impl Publisher {
    /// A publisher of `channels`; `config_message` is the `/pavlov/config` message; `watchers`: clients
    /// without the token may connect, so events lose their file paths.
    pub(crate) fn new(
        channels: Channels,
        clock: RunClock,
        obs_names: Vec<String>,
        config_message: Vec<u8>,
        watchers: bool,
        counters: Arc<FoxgloveCounters>,
    ) -> Self {
        Publisher {
            channels,
            clock,
            obs_names,
            config_message,
            watchers,
            recent_events: VecDeque::with_capacity(RECENT_EVENTS),
            counters,
        }
    }

    /// Publishes until `cancel` or the end of the feed.
    pub(crate) async fn run(mut self, mut inputs: Inputs, cancel: CancellationToken) {
        let meta = |t| PartialMetadata { log_time: Some(t) };
        self.channels
            .config
            .log_with_meta(&self.config_message, meta(self.clock.start()));
        let mut events_open = true;
        loop {
            tokio::select! {
                () = cancel.cancelled() => return,
                tick = inputs.ticks.recv() => match tick {
                    Ok(record) => self.tick(&record),
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        self.counters.ticks_missed.fetch_add(n, Ordering::Relaxed);
                        tracing::debug!(missed = n, "foxglove: the publisher fell behind the tick feed");
                    }
                    Err(broadcast::error::RecvError::Closed) => return,
                },
                event = inputs.events.recv(), if events_open => match event {
                    Ok(event) => self.event(&event),
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        self.counters.events_missed.fetch_add(n, Ordering::Relaxed);
                    }
                    // The server has gone; the feed ends too.
                    Err(broadcast::error::RecvError::Closed) => events_open = false,
                },
                Some(s) = inputs.subscribed.recv() => self.greet(s),
            }
        }
    }

    fn tick(&self, record: &TickRecord) {
        let meta = PartialMetadata {
            log_time: Some(self.clock.tick(record.t_ms)),
        };
        if self.channels.ticks.has_sinks() {
            match serde_json::to_vec(record) {
                Ok(bytes) => self.channels.ticks.log_with_meta(&bytes, meta),
                Err(e) => tracing::debug!("foxglove: tick {} not serialised: {e}", record.seq),
            }
        }
        if self.channels.signals.has_sinks() {
            match serde_json::to_vec(&Signals::of(record, &self.obs_names)) {
                Ok(bytes) => self.channels.signals.log_with_meta(&bytes, meta),
                Err(e) => tracing::debug!("foxglove: tick {} not serialised: {e}", record.seq),
            }
        }
    }

    fn event(&mut self, event: &Event) {
        let event = if self.watchers {
            crate::dashboard::event_for_watcher(event)
        } else {
            std::borrow::Cow::Borrowed(event)
        };
        let Ok(bytes) = serde_json::to_vec(&*event) else {
            tracing::debug!(id = event.id, "foxglove: event not serialised");
            return;
        };
        let time = self.clock.event(event.after);
        self.channels.events.log_with_meta(
            &bytes,
            PartialMetadata {
                log_time: Some(time),
            },
        );
        if self.recent_events.len() == RECENT_EVENTS {
            self.recent_events.pop_front();
        }
        self.recent_events.push_back((bytes, time));
    }

    /// Sends a new subscriber of the configuration or the events what it missed.
    fn greet(&self, s: Subscribed) {
        let meta = |t| PartialMetadata { log_time: Some(t) };
        if s.channel == self.channels.config.id() {
            self.channels.config.log_with_meta_to_sink(
                &self.config_message,
                meta(self.clock.start()),
                Some(s.sink),
            );
        } else if s.channel == self.channels.events.id() {
            for (bytes, time) in &self.recent_events {
                self.channels
                    .events
                    .log_with_meta_to_sink(bytes, meta(*time), Some(s.sink));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_stamped_at_their_scheduled_time_and_events_at_the_next_tick() {
        let clock = RunClock {
            start_unix_ns: 1_000_000_000,
            period_ns: 20_000_000,
        };
        assert_eq!(clock.tick(0.0), 1_000_000_000);
        assert_eq!(clock.tick(40.0), 1_040_000_000);
        assert_eq!(clock.event(None), 1_000_000_000);
        // An event after tick 1 applies from tick 2.
        assert_eq!(clock.event(Some(1)), 1_040_000_000);
    }

    #[test]
    fn the_run_clock_puts_the_start_in_the_past_by_the_time_since_it() {
        let started = tokio::time::Instant::now() - std::time::Duration::from_secs(5);
        let clock = RunClock::new(started, 20);
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64;
        let ago = now - clock.start();
        assert!((4_900_000_000..6_000_000_000).contains(&ago), "{ago}");
        assert_eq!(clock.period_ns, 20_000_000);
    }
}
