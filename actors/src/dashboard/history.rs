//! The dashboard's memory of the recent past: a ring of the last `[dashboard] history_s` seconds of ticks,
//! the events among them and the state in force (mode, learning parameters, the recording being written),
//! so that a page opened mid-run starts with what came before rather than an empty chart.
//!
//! The hub pushes one compact [`TickRow`] per tick (about 56 bytes, plus 16 per prediction: a tenth of the
//! tick's JSON); rows fill chunks of [`CHUNK_TICKS`] that are sealed behind an `Arc`, so a new client's
//! snapshot ([`History::snapshot`]) copies at most one open chunk under the lock and shares the rest. The
//! client's own writer then turns the snapshot into `history` messages ([`super::history_messages`]), at
//! its own pace and never larger than its byte limit: the hub only ever pushes.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};

use pavlov::agent::learning::ParamsInForce;
use pavlov::control::Mode;
use pavlov::event::{Event, GatingChange, LearningChange, RecordingChange};
use pavlov::record::{SafetyStop, TickRecord};
use pavlov::supervision::LinkState;
use serde::Serialize;

/// Rows per sealed chunk (5 s at 50 Hz).
pub(crate) const CHUNK_TICKS: usize = 250;
/// Most events the history keeps (the newest; teleop is never kept).
pub(crate) const MAX_EVENTS: usize = 512;

/// One tick as the charts need it: what the page plots and exports, in a fixed-size row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TickRow {
    pub(crate) seq: u64,
    pub(crate) t_ms: f64,
    pub(crate) battery_current_ma: Option<i32>,
    pub(crate) command: [i16; 2],
    pub(crate) default: [i16; 2],
    pub(crate) mode: Mode,
    pub(crate) link: LinkState,
    pub(crate) safety_stop: Option<SafetyStop>,
    /// [`FLAG_STIMULUS`] | [`FLAG_GATE`] | [`FLAG_ESTOP`] | [`FLAG_OC_LEFT`] | [`FLAG_OC_RIGHT`] |
    /// [`FLAG_ELBOW`].
    pub(crate) flags: u8,
    /// The elbow angles of the interaction experiment, degrees: left, left average, right, right average
    /// (NaN: invalid); meaningful only with [`FLAG_ELBOW`].
    pub(crate) elbow: [f32; 4],
}

pub(crate) const FLAG_STIMULUS: u8 = 1;
pub(crate) const FLAG_GATE: u8 = 2;
pub(crate) const FLAG_ESTOP: u8 = 4;
pub(crate) const FLAG_OC_LEFT: u8 = 8;
pub(crate) const FLAG_OC_RIGHT: u8 = 16;
/// The tick carried elbow angles ([`TickRow::elbow`]).
pub(crate) const FLAG_ELBOW: u8 = 32;

impl TickRow {
    fn of(r: &TickRecord) -> Self {
        let flag = |on: bool, bit: u8| if on { bit } else { 0 };
        TickRow {
            seq: r.seq,
            t_ms: r.t_ms,
            battery_current_ma: r.sensors.battery_current_ma,
            command: [r.command.left_mm_s, r.command.right_mm_s],
            default: [r.default_action.left_mm_s, r.default_action.right_mm_s],
            mode: r.mode,
            link: r.link.state,
            safety_stop: r.safety_stop,
            flags: flag(r.stimulus, FLAG_STIMULUS)
                | flag(r.gate, FLAG_GATE)
                | flag(r.estop, FLAG_ESTOP)
                | flag(r.sensors.overcurrent_left, FLAG_OC_LEFT)
                | flag(r.sensors.overcurrent_right, FLAG_OC_RIGHT)
                | flag(r.elbow.is_some(), FLAG_ELBOW),
            elbow: r.elbow.as_ref().map_or([f32::NAN; 4], |e| {
                [e.left, e.left_avg, e.right, e.right_avg].map(|v| v.map_or(f32::NAN, |v| v as f32))
            }),
        }
    }

    /// Whether `flag` is set.
    pub(crate) fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }
}

/// Rows and their predictions: `predictions` holds, per row, each prediction's value then threshold.
#[derive(Debug, Clone, Default)]
pub(crate) struct Chunk {
    pub(crate) rows: Vec<TickRow>,
    pub(crate) predictions: Vec<f64>,
}

impl Chunk {
    fn with_capacity(n_predictions: usize) -> Self {
        Chunk {
            rows: Vec::with_capacity(CHUNK_TICKS),
            predictions: Vec::with_capacity(CHUNK_TICKS * 2 * n_predictions),
        }
    }

    /// Bytes this chunk holds (its allocations).
    fn bytes(&self) -> usize {
        self.rows.capacity() * std::mem::size_of::<TickRow>()
            + self.predictions.capacity() * std::mem::size_of::<f64>()
    }
}

/// One prediction's parameters in force.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Params {
    pub(crate) prediction: String,
    pub(crate) alpha: f64,
    pub(crate) lambda: f64,
    pub(crate) threshold: f64,
}

impl From<&ParamsInForce> for Params {
    fn from(p: &ParamsInForce) -> Self {
        Params {
            prediction: p.prediction.clone(),
            alpha: p.alpha,
            lambda: p.lambda,
            threshold: p.threshold,
        }
    }
}

/// What is in force now: `hello.in_force`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct InForce {
    /// The mode of the newest tick (the configured one before the first).
    pub(crate) mode: Mode,
    /// Every prediction's α, λ, θ, in `signals.predictions` order.
    pub(crate) params: Vec<Params>,
    /// The recording being written, if any (its path; [`super::REDACTED`] for a watcher).
    pub(crate) recording: Option<String>,
}

struct Ring {
    /// Ticks kept: `history_s` in ticks (0 keeps none).
    capacity_ticks: u64,
    n_predictions: usize,
    sealed: VecDeque<Arc<Chunk>>,
    open: Chunk,
    newest_seq: Option<u64>,
    events: VecDeque<Arc<Event>>,
    in_force: InForce,
}

/// The history, shared by the hub (which pushes) and the sessions (which take snapshots).
pub(crate) struct History {
    ring: Mutex<Ring>,
}

/// What a new client is sent: the rows and events of the history window and the state in force, as of
/// one instant.
#[derive(Debug, Clone)]
pub(crate) struct Snapshot {
    /// Chunks, oldest first (the open one copied).
    pub(crate) chunks: Vec<Arc<Chunk>>,
    /// Rows with `seq` below this are outside the window.
    pub(crate) first_seq: u64,
    /// The newest row's `seq` (`None`: no tick yet); live ticks up to it are already in the history.
    pub(crate) last_seq: Option<u64>,
    /// Predictions per row.
    pub(crate) n_predictions: usize,
    /// Events of the window, in the order they were made.
    pub(crate) events: Vec<Arc<Event>>,
    /// The newest event id the snapshot has seen (0: none); live events up to it are already in it.
    pub(crate) last_event_id: u64,
    /// The state in force.
    pub(crate) in_force: InForce,
}

impl History {
    /// A history of `history_s` seconds of ticks every `period_ms`, starting in `mode` with `params`.
    pub(crate) fn new(history_s: u64, period_ms: u64, mode: Mode, params: Vec<Params>) -> Self {
        let n_predictions = params.len();
        History {
            ring: Mutex::new(Ring {
                capacity_ticks: (history_s * 1000).div_ceil(period_ms.max(1)),
                n_predictions,
                sealed: VecDeque::new(),
                open: Chunk::with_capacity(n_predictions),
                newest_seq: None,
                events: VecDeque::new(),
                in_force: InForce {
                    mode,
                    params,
                    recording: None,
                },
            }),
        }
    }

    fn ring(&self) -> std::sync::MutexGuard<'_, Ring> {
        self.ring.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Keeps `record` (and its mode as the one in force); lets go of what fell out of the window.
    pub(crate) fn push(&self, record: &TickRecord) {
        let mut ring = self.ring();
        ring.in_force.mode = record.mode;
        ring.newest_seq = Some(record.seq);
        if ring.capacity_ticks == 0 {
            return;
        }
        let n = ring.n_predictions;
        ring.open.rows.push(TickRow::of(record));
        for k in 0..n {
            let p = record.predictions.get(k);
            ring.open.predictions.push(p.map_or(f64::NAN, |p| p.value));
            ring.open
                .predictions
                .push(p.map_or(f64::NAN, |p| p.threshold));
        }
        if ring.open.rows.len() >= CHUNK_TICKS {
            let full = std::mem::replace(&mut ring.open, Chunk::with_capacity(n));
            ring.sealed.push_back(Arc::new(full));
        }
        let first = ring.first_seq();
        while ring
            .sealed
            .front()
            .and_then(|c| c.rows.last())
            .is_some_and(|r| r.seq < first)
        {
            ring.sealed.pop_front();
        }
        ring.forget_old_events();
    }

    /// Keeps `event` (unless it is frequent) and updates what is in force.
    pub(crate) fn on_event(&self, event: &Arc<Event>) {
        let mut ring = self.ring();
        // What is in force follows the event's effects (see `EventKind::effects`), never its kind.
        let effects = event.kind.effects();
        match effects.learning {
            Some(LearningChange::Params {
                prediction,
                alpha,
                lambda,
                threshold,
            }) => {
                if let Some(p) = ring
                    .in_force
                    .params
                    .iter_mut()
                    .find(|p| p.prediction == prediction)
                {
                    (p.alpha, p.lambda, p.threshold) = (alpha, lambda, threshold);
                }
            }
            Some(LearningChange::Reset) | None => {}
        }
        match effects.gating {
            Some(GatingChange::Mode(mode)) => ring.in_force.mode = mode,
            Some(GatingChange::Teleop(_)) | None => {}
        }
        match effects.recording {
            Some(RecordingChange::Started(path)) => {
                ring.in_force.recording = Some(path.to_string())
            }
            // Stopped as asked, or by a failure to write it: either way it is no longer being written.
            Some(RecordingChange::Stopped(path))
                if ring.in_force.recording.as_deref() == Some(path) =>
            {
                ring.in_force.recording = None;
            }
            Some(RecordingChange::Stopped(_)) | None => {}
        }
        if event.kind.is_frequent() || ring.capacity_ticks == 0 {
            return;
        }
        if ring.events.len() == MAX_EVENTS {
            ring.events.pop_front();
        }
        ring.events.push_back(event.clone());
        ring.forget_old_events();
    }

    /// The recording being written now, if any.
    pub(crate) fn recording(&self) -> Option<String> {
        self.ring().in_force.recording.clone()
    }

    /// Everything a new client is sent, as of now.
    pub(crate) fn snapshot(&self) -> Snapshot {
        let ring = self.ring();
        let mut chunks: Vec<Arc<Chunk>> = ring.sealed.iter().cloned().collect();
        if !ring.open.rows.is_empty() {
            chunks.push(Arc::new(ring.open.clone()));
        }
        Snapshot {
            chunks,
            first_seq: ring.first_seq(),
            last_seq: ring.newest_seq,
            n_predictions: ring.n_predictions,
            events: ring.events.iter().cloned().collect(),
            last_event_id: ring.events.back().map_or(0, |e| e.id),
            in_force: ring.in_force.clone(),
        }
    }

    /// Ticks and bytes the ring holds now (rows and predictions; for measurements and `/metrics`).
    pub(crate) fn footprint(&self) -> (usize, usize) {
        let ring = self.ring();
        let chunks = ring.sealed.iter().map(|c| c.as_ref()).chain([&ring.open]);
        chunks.fold((0, 0), |(rows, bytes), c| {
            (rows + c.rows.len(), bytes + c.bytes())
        })
    }
}

impl Ring {
    /// The oldest `seq` inside the window.
    fn first_seq(&self) -> u64 {
        match self.newest_seq {
            Some(newest) => (newest + 1).saturating_sub(self.capacity_ticks),
            None => 0,
        }
    }

    /// Drops events that took effect before the window (an event with no tick before it stays only while
    /// the window still begins at the first tick).
    fn forget_old_events(&mut self) {
        let first = self.first_seq();
        while self
            .events
            .front()
            .is_some_and(|e| e.after.map_or(first > 0, |a| a + 1 < first))
        {
            self.events.pop_front();
        }
        if self.capacity_ticks == 0 {
            self.events.clear();
        }
    }
}

#[cfg(test)]
impl Snapshot {
    /// The rows inside the window with their predictions (value, threshold per prediction), oldest first.
    pub(crate) fn rows(&self) -> impl Iterator<Item = (&TickRow, &[f64])> + '_ {
        let width = 2 * self.n_predictions;
        self.chunks.iter().flat_map(move |c| {
            c.rows.iter().enumerate().filter_map(move |(i, row)| {
                let preds = c.predictions.get(i * width..(i + 1) * width).unwrap_or(&[]);
                (row.seq >= self.first_seq).then_some((row, preds))
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::event::EventKind;
    use pavlov::record::PredictionValue;

    pub(crate) fn record(seq: u64) -> TickRecord {
        TickRecord {
            predictions: vec![PredictionValue {
                name: "stall".into(),
                value: seq as f64 / 1000.0,
                threshold: 0.5,
            }],
            gate: seq % 2 == 0,
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        }
    }

    fn params() -> Vec<Params> {
        vec![Params {
            prediction: "stall".into(),
            alpha: 0.01,
            lambda: 0.9,
            threshold: 0.5,
        }]
    }

    fn event(id: u64, after: Option<u64>, kind: EventKind) -> Arc<Event> {
        Arc::new(Event { id, after, kind })
    }

    #[test]
    fn the_ring_keeps_exactly_the_window_and_lets_old_chunks_go() {
        // 10 s of 20 ms ticks: 500 rows.
        let h = History::new(10, 20, Mode::Pavlovian, params());
        for seq in 0..2000 {
            h.push(&record(seq));
        }
        let s = h.snapshot();
        let seqs: Vec<u64> = s.rows().map(|(r, _)| r.seq).collect();
        assert_eq!(seqs, (1500..2000).collect::<Vec<_>>());
        assert_eq!(s.last_seq, Some(1999));
        let (_, preds) = s.rows().last().unwrap();
        assert_eq!(preds, [1.999, 0.5]);
        let (rows, bytes) = h.footprint();
        assert!((500..=500 + 2 * CHUNK_TICKS).contains(&rows), "{rows}");
        assert!(bytes < 1000 * 64, "{bytes} bytes for {rows} rows");
        let (first, _) = s.rows().next().unwrap();
        assert!(first.has(FLAG_GATE));
        assert_eq!(first.link, LinkState::Up);
    }

    #[test]
    fn events_update_what_is_in_force_and_stay_while_inside_the_window() {
        let h = History::new(2, 20, Mode::Pavlovian, params());
        h.push(&record(0));
        h.on_event(&event(
            1,
            Some(0),
            EventKind::ParamsSet {
                prediction: "stall".into(),
                alpha: 0.02,
                lambda: 0.5,
                threshold: 0.4,
            },
        ));
        h.on_event(&event(
            2,
            Some(0),
            EventKind::RecordingStarted {
                path: "recordings/a/ticks.jsonl".into(),
            },
        ));
        h.on_event(&event(
            3,
            Some(0),
            EventKind::Teleop {
                action: pavlov::control::Action::STOP,
            },
        ));
        h.on_event(&event(
            4,
            Some(0),
            EventKind::ModeSet { mode: Mode::Manual },
        ));
        let s = h.snapshot();
        assert_eq!(s.in_force.params[0].alpha, 0.02);
        assert_eq!(s.in_force.params[0].threshold, 0.4);
        assert_eq!(s.in_force.mode, Mode::Manual);
        assert_eq!(
            s.in_force.recording.as_deref(),
            Some("recordings/a/ticks.jsonl")
        );
        let ids: Vec<u64> = s.events.iter().map(|e| e.id).collect();
        assert_eq!(ids, [1, 2, 4], "teleop is not kept");
        assert_eq!(s.last_event_id, 4);
        h.on_event(&event(
            5,
            Some(1),
            EventKind::RecordingStopped {
                path: "recordings/a/ticks.jsonl".into(),
                reason: None,
            },
        ));
        assert_eq!(h.recording(), None);
        // The window is 100 ticks: events after tick 0 (in force from tick 1) stay while tick 1 is in it.
        let ids = |h: &History| h.snapshot().events.iter().map(|e| e.id).collect::<Vec<_>>();
        for seq in 1..=100 {
            h.push(&record(seq));
        }
        assert_eq!(ids(&h), [1, 2, 4, 5]);
        h.push(&record(101));
        assert_eq!(ids(&h), [5]);
        h.push(&record(102));
        assert!(ids(&h).is_empty());
        assert_eq!(h.snapshot().in_force.mode, Mode::Pavlovian, "ticks say");
    }

    #[test]
    fn a_recording_stopped_by_a_write_error_is_no_longer_in_force() {
        let h = History::new(2, 20, Mode::Pavlovian, params());
        let path = "recordings/a/recording.mcap".to_string();
        h.on_event(&event(
            1,
            Some(0),
            EventKind::RecordingStarted { path: path.clone() },
        ));
        assert_eq!(h.recording().as_deref(), Some(path.as_str()));
        // A failure of another recording's write leaves this one in force.
        h.on_event(&event(
            2,
            Some(3),
            EventKind::RecordingStopped {
                path: "recordings/b/recording.mcap".into(),
                reason: Some("No space left on device (os error 28)".into()),
            },
        ));
        assert_eq!(h.recording().as_deref(), Some(path.as_str()));
        h.on_event(&event(
            3,
            Some(4),
            EventKind::RecordingStopped {
                path,
                reason: Some("No space left on device (os error 28)".into()),
            },
        ));
        assert_eq!(h.recording(), None);
        assert_eq!(h.snapshot().in_force.recording, None);
    }

    #[test]
    fn no_history_keeps_no_rows_and_no_events_but_still_the_state_in_force() {
        let h = History::new(0, 20, Mode::Reactive, params());
        for seq in 0..10 {
            h.push(&record(seq));
        }
        h.on_event(&event(1, Some(3), EventKind::WeightsReset));
        let s = h.snapshot();
        assert_eq!(s.rows().count(), 0);
        assert!(s.events.is_empty());
        assert_eq!(s.last_seq, Some(9));
        assert_eq!(s.in_force.mode, Mode::Pavlovian);
        assert_eq!(h.footprint().0, 0);
    }
}
