//! The `learning` message: for every control prediction (`[[predictions]]`), its TD error on each tick,
//! its values paired with the returns they predicted once those are known, and its running error.
//!
//! The hub runs it on every tick record it reads from the tick feed, so it costs the tick nothing: the
//! cumulant and discount are the prediction's own ([`PredictionSpec::reward`] and
//! [`PredictionSpec::gamma`] of the tick's stimulus, as learning uses them), the value is the one the tick
//! recorded. The arithmetic is [`pavlov::analysis::realised_return`]; this module batches it into one
//! message every [`STATUS_EVERY_TICKS`] ticks (5 Hz at 50 Hz), so a client gets every tick's figures at
//! full resolution without one more message per tick. Numbers go out as `f32` (7 significant digits).

use pavlov::analysis::realised_return::{DEFAULT_TOLERANCE, ErrorFigures, Realised, ReturnTracker};
use pavlov::learn::PredictionSpec;
use pavlov::record::TickRecord;
use serde::Serialize;

use super::protocol::STATUS_EVERY_TICKS;

/// The most `[seq, value, return, complete]` pairs of one prediction in one message. A stimulus completes
/// every waiting return at once, up to a horizon of them (15,000 at most): past this many, the message
/// carries every `thinned`-th one, evenly spread (the running error still counts them all).
pub(crate) const MAX_PAIRS_PER_MESSAGE: usize = 1024;

/// One prediction's tracker and what it found since the last message.
struct Track {
    spec: PredictionSpec,
    tracker: ReturnTracker,
    td: Vec<(u64, Option<f32>)>,
    realised: Vec<Realised>,
}

/// Every control prediction's learning figures (see the module documentation).
pub(crate) struct LearningTracks {
    tracks: Vec<Track>,
}

#[derive(Serialize)]
struct LearningMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    seq: u64,
    predictions: Vec<PredictionFigures<'a>>,
}

#[derive(Serialize)]
struct PredictionFigures<'a> {
    name: &'a str,
    /// The learner's name (`learner` in `[[predictions]]`).
    learner: &'static str,
    tau: f64,
    horizon: u32,
    tail_bound: f32,
    /// `[seq, δ]` for every tick since the last message (`null`: no δ on that tick).
    td: &'a [(u64, Option<f32>)],
    /// `[seq, value, return, complete]` for every return that became known since the last message.
    realised: Vec<(u64, f32, f32, u8)>,
    /// 1, or k when only every k-th pair is in `realised` (see [`MAX_PAIRS_PER_MESSAGE`]).
    thinned: usize,
    error: ErrorJson,
    /// Values whose returns were lost to a gap in the ticks the hub saw, since the start.
    dropped: u64,
}

#[derive(Serialize)]
struct ErrorJson {
    pairs: u64,
    rmse: Option<f32>,
    mean_abs: Option<f32>,
    bias: Option<f32>,
}

fn finite(x: f64) -> Option<f32> {
    x.is_finite().then_some(x as f32)
}

impl From<ErrorFigures> for ErrorJson {
    fn from(e: ErrorFigures) -> Self {
        ErrorJson {
            pairs: e.pairs,
            rmse: finite(e.rmse),
            mean_abs: finite(e.mean_abs),
            bias: finite(e.bias),
        }
    }
}

impl LearningTracks {
    /// Tracks for the predictions `specs`, in the order ticks carry them. A prediction whose τ gives no
    /// tracker (refused by the configuration already) is left out.
    pub(crate) fn new(specs: &[PredictionSpec]) -> Self {
        let tracks = specs
            .iter()
            .filter_map(|spec| {
                let tracker = ReturnTracker::new(spec.continuation(), DEFAULT_TOLERANCE).ok()?;
                Some(Track {
                    spec: spec.clone(),
                    tracker,
                    td: Vec::with_capacity(STATUS_EVERY_TICKS as usize),
                    realised: Vec::new(),
                })
            })
            .collect();
        LearningTracks { tracks }
    }

    /// One tick record.
    pub(crate) fn observe(&mut self, record: &TickRecord) {
        for track in &mut self.tracks {
            let Some(p) = record
                .predictions
                .iter()
                .find(|p| p.name == track.spec.name)
            else {
                continue;
            };
            let cumulant = track.spec.reward(record.stimulus);
            let gamma = track.spec.gamma(record.stimulus);
            let td =
                track
                    .tracker
                    .observe(record.seq, p.value, cumulant, gamma, &mut track.realised);
            track.td.push((record.seq, td.map(|d| d as f32)));
        }
    }

    /// The `learning` message for everything since the last one (and clears it), or `None` without
    /// control predictions.
    pub(crate) fn take_message(&mut self, seq: u64) -> Option<String> {
        if self.tracks.is_empty() {
            return None;
        }
        let predictions = self
            .tracks
            .iter()
            .map(|t| {
                let thinned = t.realised.len().div_ceil(MAX_PAIRS_PER_MESSAGE).max(1);
                PredictionFigures {
                    name: &t.spec.name,
                    learner: t.spec.learner.name(),
                    tau: t.spec.tau,
                    horizon: t.tracker.horizon(),
                    tail_bound: t.tracker.tail_bound() as f32,
                    td: &t.td,
                    realised: t
                        .realised
                        .iter()
                        .step_by(thinned)
                        .map(|r| (r.seq, r.value as f32, r.ret as f32, u8::from(r.complete)))
                        .collect(),
                    thinned,
                    error: t.tracker.error().into(),
                    dropped: t.tracker.dropped(),
                }
            })
            .collect();
        let text = serde_json::to_string(&LearningMessage {
            kind: "learning",
            seq,
            predictions,
        })
        .unwrap_or_default();
        for t in &mut self.tracks {
            t.td.clear();
            t.realised.clear();
        }
        Some(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::Mode;
    use pavlov::record::PredictionValue;

    const STALL: &str = include_str!("../../../config/stall.toml");

    fn record(seq: u64, value: f64, stimulus: bool) -> TickRecord {
        TickRecord {
            stimulus,
            predictions: vec![PredictionValue {
                name: "stall".into(),
                value,
                threshold: 0.5,
            }],
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        }
    }

    #[test]
    fn the_message_pairs_values_with_the_stimulus_return_and_carries_every_td_error() {
        let config = pavlov::config::Config::from_toml(STALL).unwrap();
        let mut tracks = LearningTracks::new(&config.predictions);
        // τ = 25: γ = 0.96. The stimulus on tick 3: G_0 = 0.96², G_1 = 0.96, G_2 = 1.
        for (seq, stim) in [(0, false), (1, false), (2, false), (3, true)] {
            tracks.observe(&record(seq, 0.5, stim));
        }
        let v: serde_json::Value = serde_json::from_str(&tracks.take_message(3).unwrap()).unwrap();
        assert_eq!(v["type"], "learning");
        let p = &v["predictions"][0];
        assert_eq!(p["name"], "stall");
        assert_eq!(p["horizon"], 113);
        let realised = p["realised"].as_array().unwrap();
        assert_eq!(realised.len(), 3, "{p}");
        let ret = |i: usize| realised[i][2].as_f64().unwrap();
        assert!((ret(0) - 0.9216).abs() < 1e-6, "{p}");
        assert!((ret(1) - 0.96).abs() < 1e-6, "{p}");
        assert_eq!(ret(2), 1.0);
        assert_eq!(realised[0][0], 0);
        assert_eq!(realised[0][3], 1);
        // δ_1 = 0 + 0.96·0.5 − 0.5 = −0.02; δ_3 = 1 + 0 − 0.5 = 0.5.
        let td = p["td"].as_array().unwrap();
        assert_eq!(td.len(), 4);
        assert!(td[0][1].is_null());
        assert!((td[1][1].as_f64().unwrap() + 0.02).abs() < 1e-6, "{p}");
        assert_eq!(td[3][1].as_f64().unwrap(), 0.5);
        assert_eq!(p["error"]["pairs"], 3);
        // The next message starts afresh.
        tracks.observe(&record(4, 0.5, false));
        let v: serde_json::Value = serde_json::from_str(&tracks.take_message(4).unwrap()).unwrap();
        assert_eq!(v["predictions"][0]["td"].as_array().unwrap().len(), 1);
        assert_eq!(v["predictions"][0]["realised"].as_array().unwrap().len(), 0);
        assert_eq!(v["predictions"][0]["error"]["pairs"], 3);
    }

    #[test]
    fn a_stimulus_after_a_long_horizon_sends_a_bounded_number_of_pairs() {
        // τ = 2000: a horizon of 9,209 ticks; a stimulus after 3,000 quiet ticks completes 3,000 returns.
        let mut config = pavlov::config::Config::from_toml(STALL).unwrap();
        config.predictions[0].tau = 2000.0;
        let mut tracks = LearningTracks::new(&config.predictions);
        for seq in 0..3_000 {
            tracks.observe(&record(seq, 0.5, false));
        }
        tracks.take_message(2_999);
        tracks.observe(&record(3_000, 0.5, true));
        let text = tracks.take_message(3_000).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let p = &v["predictions"][0];
        assert_eq!(p["thinned"], 3, "{}", &text[..200]);
        let realised = p["realised"].as_array().unwrap();
        assert_eq!(realised.len(), 1_000);
        assert_eq!(realised[1][0], 3);
        assert_eq!(p["error"]["pairs"], 3_000);
        assert!(text.len() < 64 * 1024, "{} bytes", text.len());
    }

    #[test]
    fn no_control_predictions_no_message() {
        assert!(LearningTracks::new(&[]).take_message(0).is_none());
    }
}
