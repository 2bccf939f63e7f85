//! The hub: turns each tick record and each event into its JSON message once, keeps the run counters and
//! the [`History`], and fans the messages out to every websocket client over a lossy broadcast.
//!
//! Serialising once per tick (not once per client) keeps the cost of 50 clients near that of one: a client
//! gets a cheap clone of the same bytes. The hub reads the tick feed's broadcast, so it never slows the
//! tick either; if it ever lagged, the records it missed are counted and logged. Per tick it only pushes a
//! compact row into the history; what a new client is sent of it is made by that client's own writer.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use axum::extract::ws::Utf8Bytes;
use pavlov::analysis::interaction::live::LiveInteraction;
use pavlov::analysis::interaction::live_aligned::LiveAligned;
use pavlov::analysis::run_counters::RunCounters;
use pavlov::event::Event;
use pavlov::learn::PredictionSpec;
use pavlov::record::TickRecord;
use tokio::sync::broadcast;
use tokio_util::sync::CancellationToken;

use super::history::{History, Snapshot};
use super::history_messages::event_json;
use super::learning::LearningTracks;
use super::messages::{StatusHealth, StatusMessage, TickMessage};
use super::protocol::STATUS_EVERY_TICKS;
use crate::telemetry::Health;

/// Capacity of the hub's broadcast to the clients' forwarders, in messages (about 4 s of ticks).
pub(crate) const HUB_CAPACITY: usize = 256;

/// `learning` messages kept for a client that joins (300 s at 50 Hz, the default `[dashboard] history_s`,
/// about 0.6 MB): its learning view starts with them, over the same window as the history's charts.
pub(crate) const RECENT_LEARNING: usize = 1500;

/// Statuses carry `interaction.aligned` every this many ticks (a multiple of [`STATUS_EVERY_TICKS`]; once a
/// second at 50 Hz): the curves are about 76 points × 2 series × 2 modes, too many for every status.
pub(crate) const ALIGNED_EVERY_TICKS: u64 = 5 * STATUS_EVERY_TICKS;

/// One message for the clients.
#[derive(Debug, Clone)]
pub(crate) enum Outgoing {
    /// A `tick` message (subject to the client's rate).
    Tick {
        /// The tick's sequence number.
        seq: u64,
        /// The JSON text.
        text: Utf8Bytes,
    },
    /// A `status` message (every client gets every one).
    Status(Utf8Bytes),
    /// A `learning` message (every client gets every one, like a status).
    Learning {
        /// The tick it was made on.
        seq: u64,
        /// The JSON text.
        text: Utf8Bytes,
    },
    /// An `event` message (every client gets every one): as an operator and as a watcher sees it.
    Event {
        /// The event's id.
        id: u64,
        /// The operators' text.
        operator: Utf8Bytes,
        /// The watchers' text (no file paths).
        watcher: Utf8Bytes,
    },
}

/// Counters the hub shares with the endpoint.
#[derive(Debug, Default)]
pub(crate) struct HubCounters {
    /// Websocket clients connected now (kept by [`super::admission::Admission`]).
    pub(crate) clients: Arc<AtomicUsize>,
    /// Tick records the hub itself missed (it lagged behind the feed).
    pub(crate) records_missed: AtomicU64,
}

/// The hub's output side: clients subscribe here.
#[derive(Clone)]
pub(crate) struct HubHandle {
    tx: broadcast::Sender<Outgoing>,
    history: Arc<History>,
    learning: Arc<Mutex<VecDeque<(u64, Utf8Bytes)>>>,
}

impl HubHandle {
    /// A new subscription, starting with the next message.
    #[cfg(test)]
    pub(crate) fn subscribe(&self) -> broadcast::Receiver<Outgoing> {
        self.tx.subscribe()
    }

    /// A new subscription and the history as of now: every tick and event up to the snapshot's
    /// `last_seq` and `last_event_id` is in the snapshot, every later one comes on the subscription (which
    /// may also repeat some of the snapshot's: skip them).
    pub(crate) fn join(&self) -> (broadcast::Receiver<Outgoing>, Snapshot) {
        // Subscribe first: the hub keeps a tick in the history before it sends it, so nothing falls between.
        let rx = self.tx.subscribe();
        (rx, self.history.snapshot())
    }

    /// The recent `learning` messages, oldest first (taken after [`HubHandle::join`], every later one comes
    /// on the subscription, which may repeat some: skip those up to the last one's `seq`).
    pub(crate) fn recent_learning(&self) -> Vec<(u64, Utf8Bytes)> {
        lock(&self.learning).iter().cloned().collect()
    }

    /// The history.
    pub(crate) fn history(&self) -> &History {
        &self.history
    }
}

/// The hub's state: the run counters over every record seen, and the live interaction metrics (with the
/// aligned averages) when the stimulus is the gesture command.
pub(crate) struct Hub {
    recent_learning: Arc<Mutex<VecDeque<(u64, Utf8Bytes)>>>,
    metrics: RunCounters,
    interaction: Option<(LiveInteraction, LiveAligned)>,
    learning: LearningTracks,
    history: Arc<History>,
    period_ms: u64,
    tx: broadcast::Sender<Outgoing>,
}

impl Hub {
    /// A hub for a run ticking every `period_ms` that keeps `history`, and the handle clients subscribe
    /// with. With `track_interaction` (the stimulus is the left-elbow command) the statuses carry
    /// `interaction`.
    pub(crate) fn new(
        period_ms: u64,
        track_interaction: bool,
        history: History,
    ) -> (Hub, HubHandle) {
        let (tx, _) = broadcast::channel(HUB_CAPACITY);
        let history = Arc::new(history);
        let period = period_ms as f64;
        let recent_learning = Arc::new(Mutex::new(VecDeque::with_capacity(RECENT_LEARNING)));
        (
            Hub {
                recent_learning: recent_learning.clone(),
                metrics: RunCounters::new(period),
                interaction: track_interaction.then(|| {
                    (
                        LiveInteraction::with_period(period),
                        LiveAligned::new(period),
                    )
                }),
                learning: LearningTracks::new(&[]),
                history: history.clone(),
                period_ms,
                tx: tx.clone(),
            },
            HubHandle {
                tx,
                history,
                learning: recent_learning,
            },
        )
    }

    /// Tracks the learning of the control predictions `specs` (the `learning` message).
    pub(crate) fn with_learning(mut self, specs: &[PredictionSpec]) -> Self {
        self.learning = LearningTracks::new(specs);
        self
    }

    /// Handles one event: keeps it in the history and broadcasts it.
    pub(crate) fn on_event(&mut self, event: &Arc<Event>) {
        self.history.on_event(event);
        let text = |watcher| Utf8Bytes::from(event_json(event, self.period_ms, watcher));
        // An error only means no client is connected.
        let _ = self.tx.send(Outgoing::Event {
            id: event.id,
            operator: text(false),
            watcher: text(true),
        });
    }

    /// Handles one record: updates the counters and broadcasts its messages.
    pub(crate) fn on_record(
        &mut self,
        record: &TickRecord,
        health: impl FnOnce() -> StatusHealth,
        clients: usize,
    ) {
        self.metrics.observe(record);
        self.learning.observe(record);
        if let Some((live, aligned)) = &mut self.interaction {
            live.observe(record);
            aligned.observe(record);
        }
        let text = Utf8Bytes::from(TickMessage::new(record).to_json());
        // Kept before it is sent: see `HubHandle::join`.
        self.history.push(record);
        // An error only means no client is connected.
        let _ = self.tx.send(Outgoing::Tick {
            seq: record.seq,
            text,
        });
        if record.seq % STATUS_EVERY_TICKS == 0 {
            let health = health();
            let counters = self.metrics.totals();
            let interaction = self.interaction.as_ref().map(|(live, _)| live.figures());
            let aligned = self
                .interaction
                .as_ref()
                .filter(|_| record.seq % ALIGNED_EVERY_TICKS == 0)
                .map(|(_, aligned)| aligned.figures());
            let status = StatusMessage::new(record.seq, &health, &counters, clients)
                .with_interaction(interaction.as_ref())
                .with_aligned(aligned.as_ref())
                .to_json();
            let _ = self.tx.send(Outgoing::Status(Utf8Bytes::from(status)));
            if let Some(learning) = self.learning.take_message(record.seq) {
                let text = Utf8Bytes::from(learning);
                // Kept before it is sent, as the ticks are.
                {
                    let mut recent = lock(&self.recent_learning);
                    if recent.len() >= RECENT_LEARNING {
                        recent.pop_front();
                    }
                    recent.push_back((record.seq, text.clone()));
                }
                let _ = self.tx.send(Outgoing::Learning {
                    seq: record.seq,
                    text,
                });
            }
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A poisoned lock only means another thread panicked while holding it; the data is still valid.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Where the hub reads from: every tick record, the events made before it started, and every later one.
pub(crate) struct HubInputs {
    /// The tick feed.
    pub(crate) feed: broadcast::Receiver<Arc<TickRecord>>,
    /// Events made before the hub started (the event log's recent ones).
    pub(crate) earlier_events: Vec<Arc<Event>>,
    /// Every later event.
    pub(crate) events: broadcast::Receiver<Arc<Event>>,
}

/// Runs the hub until `cancel` fires or the feed closes.
pub(crate) async fn run(
    mut hub: Hub,
    inputs: HubInputs,
    health: Health,
    counters: Arc<HubCounters>,
    cancel: CancellationToken,
) {
    let HubInputs {
        mut feed,
        earlier_events,
        mut events,
    } = inputs;
    for event in &earlier_events {
        hub.on_event(event);
    }
    let mut events_open = true;
    loop {
        let next = tokio::select! {
            _ = cancel.cancelled() => break,
            event = events.recv(), if events_open => {
                match event {
                    Ok(event) => hub.on_event(&event),
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        // Only a hub starved of CPU for 256 events; the log has every one of them.
                        tracing::warn!(missed = n, "the dashboard hub fell behind the event log");
                    }
                    Err(broadcast::error::RecvError::Closed) => events_open = false,
                }
                continue;
            }
            next = feed.recv() => next,
        };
        match next {
            Ok(record) => {
                let clients = counters.clients.load(Ordering::Relaxed);
                hub.on_record(&record, || StatusHealth::from(&health.figures()), clients);
            }
            Err(broadcast::error::RecvError::Lagged(n)) => {
                counters.records_missed.fetch_add(n, Ordering::Relaxed);
                tracing::warn!(missed = n, "the dashboard hub fell behind the tick feed");
            }
            Err(broadcast::error::RecvError::Closed) => break,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::Mode;
    use pavlov::record::SensorReadings;

    fn test_history() -> History {
        History::new(60, 20, Mode::Reactive, Vec::new())
    }

    fn record(seq: u64) -> TickRecord {
        TickRecord {
            sensors: SensorReadings {
                overcurrent_left: seq % 2 == 0,
                ..Default::default()
            },
            obs: vec![0.0; 3],
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Reactive)
        }
    }

    #[test]
    fn every_record_becomes_a_tick_and_every_tenth_a_status_with_counters() {
        let (mut hub, handle) = Hub::new(20, false, test_history());
        let mut rx = handle.subscribe();
        for seq in 0..21 {
            hub.on_record(&record(seq), StatusHealth::default, 3);
        }
        let mut ticks = Vec::new();
        let mut statuses = Vec::new();
        while let Ok(m) = rx.try_recv() {
            match m {
                Outgoing::Tick { seq, text } => {
                    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
                    assert_eq!(v["seq"], seq);
                    ticks.push(seq);
                }
                Outgoing::Status(text) => {
                    statuses.push(serde_json::from_str::<serde_json::Value>(&text).unwrap())
                }
                Outgoing::Event { .. } => panic!("no event was made"),
                Outgoing::Learning { .. } => panic!("no prediction is tracked"),
            }
        }
        assert_eq!(ticks, (0..21).collect::<Vec<_>>());
        assert_eq!(statuses.len(), 3);
        let last = &statuses[2];
        assert_eq!(last["type"], "status");
        assert_eq!(last["seq"], 20);
        assert_eq!(last["clients"], 3);
        assert_eq!(last["counters"]["ticks"], 21);
        assert_eq!(last["counters"]["overcurrent_observations"], 11);
        assert_eq!(hub.metrics.totals().ticks, 21);
        assert!(last.get("interaction").is_none(), "{last}");
    }

    #[test]
    fn an_interaction_hub_reports_commands_and_leads_in_its_statuses() {
        let (mut hub, handle) = Hub::new(20, true, test_history());
        let mut rx = handle.subscribe();
        for seq in 0..121 {
            let mut r = record(seq);
            // The gate engages at tick 65, the stimulus at tick 68: one command answered 60 ms early; the
            // wheels turn and the current rises from 150 to 600 mA at tick 66, 40 ms early.
            r.gate = seq >= 65;
            r.stimulus = seq >= 68;
            r.sensors.angle_deg = i32::from(seq >= 66);
            r.sensors.battery_current_ma = Some(if seq >= 66 { -600 } else { -150 });
            hub.on_record(&r, StatusHealth::default, 1);
        }
        let mut last = None;
        while let Ok(m) = rx.try_recv() {
            if let Outgoing::Status(text) = m {
                last = Some(serde_json::from_str::<serde_json::Value>(&text).unwrap());
            }
        }
        let i = &last.unwrap()["interaction"];
        assert_eq!(i["commands"], 1, "{i}");
        assert_eq!(i["early"], 1, "{i}");
        assert_eq!(i["false_starts"], 0, "{i}");
        assert_eq!(i["mean_lead_ms"], 60.0, "{i}");
        assert_eq!(i["mean_current_lead_ms"], 40.0, "{i}");
        assert_eq!(i["mean_motion_lead_ms"], 40.0, "{i}");
    }

    #[test]
    fn statuses_carry_the_aligned_averages_once_a_second() {
        let (mut hub, handle) = Hub::new(20, true, test_history());
        let mut rx = handle.subscribe();
        for seq in 0..=200 {
            let mut r = record(seq);
            // A Pavlovian command at tick 50; the current steps to −600 mA at tick 45.
            r.mode = Mode::Pavlovian;
            r.stimulus = (50..60).contains(&seq);
            r.sensors.battery_current_ma = Some(if (45..90).contains(&seq) { -600 } else { -150 });
            hub.on_record(&r, StatusHealth::default, 1);
        }
        let mut with_aligned = Vec::new();
        let mut last_aligned = None;
        while let Ok(m) = rx.try_recv() {
            if let Outgoing::Status(text) = m {
                let v: serde_json::Value = serde_json::from_str(&text).unwrap();
                assert!(v["interaction"].is_object(), "{v}");
                if let Some(a) = v["interaction"].get("aligned") {
                    with_aligned.push(v["seq"].as_u64().unwrap());
                    last_aligned = Some(a.clone());
                }
            }
        }
        assert_eq!(with_aligned, vec![0, 50, 100, 150, 200]);
        let a = last_aligned.unwrap();
        assert_eq!(a["offsets_ms"].as_array().unwrap().len(), 76);
        assert_eq!(a["pavlovian"]["commands"], 1, "{a}");
        assert_eq!(a["reactive"]["commands"], 0, "{a}");
        // Offset −100 ms (tick 45): the step; −120 ms (tick 44): the rest current.
        assert_eq!(a["offsets_ms"][20], -100.0);
        assert_eq!(a["pavlovian"]["current_ma"][20], -600.0, "{a}");
        assert_eq!(a["pavlovian"]["current_ma"][19], -150.0, "{a}");
        assert!(a["reactive"]["current_ma"][0].is_null(), "{a}");
    }

    #[test]
    fn a_joining_client_gets_every_tick_and_event_once_in_its_history_or_live() {
        use pavlov::event::EventKind;
        let (mut hub, handle) = Hub::new(20, false, test_history());
        for seq in 0..30 {
            hub.on_record(&record(seq), StatusHealth::default, 1);
        }
        let saved = |id, after| {
            Arc::new(Event {
                id,
                after: Some(after),
                kind: EventKind::WeightsSaved {
                    path: "/lab/saved/w.json".into(),
                },
            })
        };
        hub.on_event(&saved(1, 29));
        let (mut rx, snapshot) = handle.join();
        for seq in 30..40 {
            hub.on_record(&record(seq), StatusHealth::default, 1);
        }
        hub.on_event(&saved(2, 39));
        assert_eq!(snapshot.last_seq, Some(29));
        assert_eq!(snapshot.rows().count(), 30);
        assert_eq!(snapshot.last_event_id, 1);
        let mut live_ticks = Vec::new();
        let mut live_events = Vec::new();
        while let Ok(m) = rx.try_recv() {
            match m {
                Outgoing::Tick { seq, .. } => live_ticks.push(seq),
                Outgoing::Event {
                    id,
                    operator,
                    watcher,
                } => {
                    assert!(
                        operator.as_str().contains("/lab/saved/w.json"),
                        "{operator}"
                    );
                    assert!(!watcher.as_str().contains("/lab"), "{watcher}");
                    assert!(watcher.as_str().contains(r#""t":0.8"#), "{watcher}");
                    live_events.push(id);
                }
                Outgoing::Status(_) | Outgoing::Learning { .. } => {}
            }
        }
        assert_eq!(live_ticks, (30..40).collect::<Vec<_>>());
        assert_eq!(live_events, [2]);
        assert_eq!(handle.history().snapshot().rows().count(), 40);
    }

    #[test]
    fn the_hub_keeps_the_recent_learning_messages_for_a_joining_client_and_no_more() {
        let config =
            pavlov::config::Config::from_toml(include_str!("../../../config/stall.toml")).unwrap();
        let (hub, handle) = Hub::new(20, false, test_history());
        let mut hub = hub.with_learning(&config.predictions);
        let mut rx = handle.subscribe();
        let ticks = (RECENT_LEARNING as u64 + 20) * STATUS_EVERY_TICKS;
        let mut live = Vec::new();
        for seq in 0..ticks {
            hub.on_record(&record(seq), StatusHealth::default, 1);
            while let Ok(m) = rx.try_recv() {
                if let Outgoing::Learning { seq, text } = m {
                    assert!(text.as_str().starts_with(r#"{"type":"learning""#), "{text}");
                    live.push(seq);
                }
            }
        }
        // One per status (every tenth tick); the newest RECENT_LEARNING of them kept.
        assert_eq!(live.len() as u64, ticks / STATUS_EVERY_TICKS);
        let recent: Vec<u64> = handle.recent_learning().iter().map(|(s, _)| *s).collect();
        assert_eq!(recent.len(), RECENT_LEARNING);
        assert_eq!(recent[..], live[live.len() - RECENT_LEARNING..]);
    }
}
