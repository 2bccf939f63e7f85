//! [`LearningStage`]: one tick of perception and prediction learning.
//!
//! Per tick, [`LearningStage::act`] scales the observation, computes the stimulus E (the stall detector on the
//! wheels' over-current flags, or the left-elbow command), and outputs every prediction with the current
//! weights; the caller acts on that at once. [`LearningStage::learn`] then runs the TD(λ) update for the
//! transition into this tick (the paper's "act first, then learn"; see [`crate::learn::set`]).
//!
//! With the left-elbow stimulus, a tick whose elbow angles are missing or stale (either arm: the features
//! tile both) is acted on but not learned from, and the learning chain breaks there, as it does for stale
//! robot data: E is unknown on such a tick, not "no command", and half the tilings are inactive.

use crate::config::{Config, StimulusSpec};
use crate::control::StallDetector;
use crate::learn::{FeatureInputs, LearnError, PredictionSet, SetSnapshot, SignalNames, Threshold};
use crate::obs::ObsLayout;
use crate::oi::SensorValues;
use crate::oi::packets::{bits, id};
use crate::record::{ElbowAngles, PredictionValue};
use crate::skeleton::ElbowFeatures;

/// Names of the extra (non-observation) inputs, scaled to `[0, 1]` as angle / 180°.
pub const ELBOW_INPUTS: [&str; 4] = [
    "left_elbow",
    "left_elbow_avg",
    "right_elbow",
    "right_elbow_avg",
];

/// The stimulus names a configuration can refer to.
pub fn stimulus_name(spec: &StimulusSpec) -> &'static str {
    match spec {
        StimulusSpec::Stall { .. } => "stall",
        StimulusSpec::LeftElbow { .. } => "left_elbow_command",
    }
}

/// One tick's input.
#[derive(Debug, Clone, Copy)]
pub struct LearnInput<'a> {
    /// The newest sensor snapshot, if any frame has arrived.
    pub values: Option<&'a SensorValues>,
    /// Elbow features, when a skeleton stream is configured.
    pub elbow: Option<ElbowFeatures>,
    /// A human command request injected by an operator: E is on regardless of the sensors.
    pub forced_stimulus: bool,
}

/// A prediction's learning parameters in force.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamsInForce {
    /// The prediction's name.
    pub prediction: String,
    /// Step size α.
    pub alpha: f64,
    /// Trace decay λ.
    pub lambda: f64,
    /// Gate threshold θ.
    pub threshold: f64,
}

/// What the stage produced for acting.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnOutput {
    /// The scaled observation vector (NaN where the snapshot lacks a packet).
    pub obs_vector: Vec<f32>,
    /// The stimulus E.
    pub stimulus: bool,
    /// Every prediction with its threshold.
    pub predictions: Vec<PredictionValue>,
    /// The gating prediction's value when it rests on fully valid inputs.
    pub gate_value: Option<f64>,
    /// The gating prediction's threshold θ.
    pub gate_threshold: f64,
    /// Elbow angles, when a skeleton is used.
    pub elbow: Option<ElbowAngles>,
}

/// Perception, prediction and learning for one configuration.
pub struct LearningStage {
    layout: ObsLayout,
    set: PredictionSet,
    stimulus_spec: StimulusSpec,
    stall: StallDetector,
    gate_index: usize,
    obs: Vec<f64>,
    extra: [f64; 4],
    pending_stimulus: Option<bool>,
    /// Whether the pending tick's elbow angles are all there (always true without the elbow stimulus).
    pending_complete: bool,
    /// Ticks not learned from because an elbow angle was missing or stale.
    skipped_missing_elbow: u64,
}

fn scaled_angle(a: Option<f64>) -> f64 {
    a.map_or(f64::NAN, |deg| deg / 180.0)
}

impl LearningStage {
    /// Builds the predictions of `config` over the observation layout of its robot model.
    pub fn new(config: &Config) -> Result<Self, LearnError> {
        let layout = ObsLayout::for_model(config.robot.model);
        let stimulus = stimulus_name(&config.control.stimulus);
        let names = SignalNames::for_layout(&layout, &ELBOW_INPUTS, &[stimulus]);
        let set = PredictionSet::new(config.predictions.clone(), &names)?;
        let gate_index = set
            .specs()
            .position(|s| s.name == config.control.gate_prediction)
            .ok_or_else(|| LearnError::UnknownPrediction(config.control.gate_prediction.clone()))?;
        let stall = match config.control.stimulus {
            StimulusSpec::Stall { above, max } => StallDetector::new(above, max),
            StimulusSpec::LeftElbow { .. } => StallDetector::default(),
        };
        Ok(LearningStage {
            obs: Vec::with_capacity(layout.len()),
            layout,
            set,
            stimulus_spec: config.control.stimulus.clone(),
            stall,
            gate_index,
            extra: [f64::NAN; 4],
            pending_stimulus: None,
            pending_complete: true,
            skipped_missing_elbow: 0,
        })
    }

    /// The observation layout (dimension names for a run's header).
    pub fn layout(&self) -> &ObsLayout {
        &self.layout
    }

    /// The prediction set.
    pub fn predictions(&self) -> &PredictionSet {
        &self.set
    }

    fn stimulus(&mut self, input: &LearnInput) -> bool {
        let sensed = match self.stimulus_spec {
            StimulusSpec::Stall { .. } => match input.values {
                Some(v) => {
                    let oc = v.get_or_zero(id::OVERCURRENTS);
                    self.stall
                        .step(oc & (bits::OC_LEFT_WHEEL | bits::OC_RIGHT_WHEEL) != 0)
                }
                // No reading: the integrator holds; E keeps its last value.
                None => self.stall.is_stalled(),
            },
            StimulusSpec::LeftElbow { below_deg } => input
                .elbow
                .and_then(|e| e.left)
                .is_some_and(|deg| deg < below_deg),
        };
        sensed || input.forced_stimulus
    }

    /// Step 1 of a tick: stimulus and predictions with the current weights.
    pub fn act(&mut self, input: LearnInput) -> LearnOutput {
        self.obs.clear();
        match input.values {
            Some(v) => self.layout.scale(v, &mut self.obs),
            None => self.obs.resize(self.layout.len(), f64::NAN),
        }
        let elbow = input.elbow.map(|e| {
            self.extra = [
                scaled_angle(e.left),
                scaled_angle(e.left_avg),
                scaled_angle(e.right),
                scaled_angle(e.right_avg),
            ];
            ElbowAngles {
                left: e.left,
                left_avg: e.left_avg,
                right: e.right,
                right_avg: e.right_avg,
                skeleton: e.skeleton,
            }
        });
        if input.elbow.is_none() {
            self.extra = [f64::NAN; 4];
        }
        let stimulus = self.stimulus(&input);
        self.pending_stimulus = Some(stimulus);
        self.pending_complete = match self.stimulus_spec {
            StimulusSpec::Stall { .. } => true,
            StimulusSpec::LeftElbow { .. } => input
                .elbow
                .is_some_and(|e| e.left.is_some() && e.right.is_some()),
        };
        let outs = self.set.predict(&FeatureInputs {
            obs: &self.obs,
            extra: &self.extra,
        });
        let (gate_value, gate_threshold) = outs
            .get(self.gate_index)
            .map_or((None, f64::INFINITY), |o| (o.valid_value(), o.threshold));
        LearnOutput {
            obs_vector: self.obs.iter().map(|&x| x as f32).collect(),
            stimulus,
            predictions: outs
                .into_iter()
                .map(|o| PredictionValue {
                    name: o.name,
                    value: o.value,
                    threshold: o.threshold,
                })
                .collect(),
            gate_value,
            gate_threshold,
            elbow,
        }
    }

    /// Step 2 of a tick: the TD(λ) update into this tick. Call once after each [`LearningStage::act`]. A tick
    /// with a missing or stale elbow (elbow stimulus) is not learned from and breaks the chain.
    pub fn learn(&mut self) -> Result<(), LearnError> {
        let Some(stimulus) = self.pending_stimulus.take() else {
            return Err(LearnError::LearnWithoutPredict);
        };
        if !self.pending_complete {
            self.skipped_missing_elbow += 1;
            self.set.break_chain();
            return Ok(());
        }
        self.set.learn(&[stimulus]).map(|_| ())
    }

    /// Ticks not learned from because an elbow angle was missing or stale.
    pub fn skipped_missing_elbow(&self) -> u64 {
        self.skipped_missing_elbow
    }

    /// Forgets the previous tick (after a gap in the sensor stream): credit is not carried across it.
    pub fn break_chain(&mut self) {
        self.set.break_chain();
    }

    /// The parameters in force for prediction `name` (default: the gating prediction).
    pub fn params(&self, name: Option<&str>) -> Option<ParamsInForce> {
        let spec = match name {
            Some(n) => self.set.specs().find(|s| s.name == n),
            None => self.set.specs().nth(self.gate_index),
        }?;
        Some(ParamsInForce {
            prediction: spec.name.clone(),
            alpha: spec.alpha,
            lambda: spec.lambda,
            threshold: spec.threshold_value(),
        })
    }

    /// Changes α, λ or θ of prediction `name` (default: the gating prediction) and returns the
    /// parameters now in force. On error nothing changes.
    pub fn set_params(
        &mut self,
        name: Option<&str>,
        alpha: Option<f64>,
        lambda: Option<f64>,
        threshold: Option<f64>,
    ) -> Result<ParamsInForce, LearnError> {
        let name = match self.params(name) {
            Some(p) => p.prediction,
            None => {
                return Err(LearnError::UnknownPrediction(
                    name.unwrap_or("").to_string(),
                ));
            }
        };
        if let Some(a) = alpha {
            crate::learn::td::check_alpha(&name, a)?;
        }
        if let Some(l) = lambda {
            crate::learn::td::check_lambda(&name, l)?;
        }
        if let Some(t) = threshold {
            crate::learn::spec::check_threshold(&name, Threshold::Fixed(t))?;
        }
        if let Some(a) = alpha {
            self.set.set_alpha(&name, a)?;
        }
        if let Some(l) = lambda {
            self.set.set_lambda(&name, l)?;
        }
        if let Some(t) = threshold {
            self.set.set_threshold(&name, Threshold::Fixed(t))?;
        }
        self.params(Some(&name))
            .ok_or(LearnError::UnknownPrediction(name))
    }

    /// Resets every weight and trace to its initial value.
    pub fn reset(&mut self) {
        self.set.reset();
    }

    /// The learned state of every prediction.
    pub fn snapshot(&self) -> SetSnapshot {
        self.set.snapshot()
    }

    /// Restores a snapshot taken from a stage of the same predictions (on error nothing changes).
    pub fn restore(&mut self, snapshot: &SetSnapshot) -> Result<(), LearnError> {
        self.set.restore(snapshot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stall_stage() -> LearningStage {
        let cfg = Config::from_toml(include_str!("../../config/stall.toml")).unwrap();
        LearningStage::new(&cfg).unwrap()
    }

    fn snapshot(overcurrent: bool) -> SensorValues {
        let mut v = SensorValues::new();
        for (id, _) in (7u8..=42).map(|i| (i, 0)) {
            v.set(id, 0);
        }
        v.set(id::VOLTAGE, 15_000);
        v.set(
            id::OVERCURRENTS,
            if overcurrent { bits::OC_LEFT_WHEEL } else { 0 },
        );
        v
    }

    #[test]
    fn the_stall_stimulus_follows_the_leaky_integrator() {
        let mut s = stall_stage();
        let on = snapshot(true);
        let mut seen = Vec::new();
        for _ in 0..5 {
            let out = s.act(LearnInput {
                values: Some(&on),
                elbow: None,
                forced_stimulus: false,
            });
            s.learn().unwrap();
            seen.push(out.stimulus);
        }
        // +1 per over-current tick: levels 1, 2, 3, 4, 5; E when above 3.
        assert_eq!(seen, vec![false, false, false, true, true]);
        assert_eq!(s.layout().len(), 44);
    }

    #[test]
    fn a_prediction_of_a_recurring_stall_rises_before_it() {
        // Over-current for 10 ticks in every 50, otherwise quiet: the stall prediction must learn to rise in
        // the ticks that lead up to it only if something in the observation announces it; here the battery
        // voltage ramps down before each stall, so it does.
        let mut s = stall_stage();
        let mut before = Vec::new();
        for t in 0..50 * 400 {
            let phase = t % 50;
            let mut v = snapshot(phase >= 40);
            v.set(id::VOLTAGE, 16_000 - 100 * phase);
            let out = s.act(LearnInput {
                values: Some(&v),
                elbow: None,
                forced_stimulus: false,
            });
            s.learn().unwrap();
            if t >= 50 * 390 && phase == 38 {
                before.push(out.predictions[0].value);
            }
        }
        let mean: f64 = before.iter().sum::<f64>() / before.len() as f64;
        assert!(mean > 0.5, "prediction two ticks before the stall: {mean}");
    }

    #[test]
    fn a_missing_elbow_is_not_learned_from_and_breaks_the_chain() {
        let cfg = Config::from_toml(include_str!("../../config/interaction.toml")).unwrap();
        let elbow = |left: Option<f64>| ElbowFeatures {
            left,
            left_avg: Some(120.0),
            right: Some(160.0),
            right_avg: Some(160.0),
            command: false,
            skeleton: crate::skeleton::SkeletonStatus::Tracked,
        };
        let weights = |s: &LearningStage| s.snapshot().predictions[0].weights.clone();
        let tick = |s: &mut LearningStage, left: Option<f64>| {
            s.act(LearnInput {
                values: None,
                elbow: Some(elbow(left)),
                forced_stimulus: false,
            });
            s.learn().unwrap();
        };
        // A bent arm (E on) after a straight one: the update raises the prediction.
        let mut s = LearningStage::new(&cfg).unwrap();
        tick(&mut s, Some(150.0));
        let before = weights(&s);
        tick(&mut s, Some(60.0));
        assert_ne!(weights(&s), before, "a complete transition is learned");
        // The same with a tick whose left elbow is missing in between: neither transition is learned (E is
        // unknown there, not "no command"), and the chain restarts after it.
        let mut s = LearningStage::new(&cfg).unwrap();
        tick(&mut s, Some(150.0));
        let before = weights(&s);
        tick(&mut s, None);
        tick(&mut s, Some(60.0));
        assert_eq!(weights(&s), before, "no update across the missing tick");
        assert_eq!(s.skipped_missing_elbow(), 1);
        tick(&mut s, Some(60.0));
        assert_ne!(weights(&s), before, "learning resumes after it");
    }

    #[test]
    fn forced_stimulus_and_missing_observations_are_explicit() {
        let mut s = stall_stage();
        let out = s.act(LearnInput {
            values: None,
            elbow: None,
            forced_stimulus: true,
        });
        assert!(out.stimulus);
        assert!(out.obs_vector.iter().all(|x| x.is_nan()));
        assert_eq!(out.gate_value, None, "no valid input, no valid prediction");
        s.learn().unwrap();
        assert!(s.learn().is_err(), "learn twice without act");
        let p = s.set_params(None, Some(0.01), None, Some(0.7)).unwrap();
        assert_eq!(
            (p.prediction.as_str(), p.alpha, p.threshold),
            ("stall", 0.01, 0.7)
        );
        assert!(s.set_params(Some("nope"), Some(0.01), None, None).is_err());
    }
}
