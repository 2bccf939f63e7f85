//! [`LearningStage`]: one tick of perception and prediction learning.
//!
//! Per tick, [`LearningStage::act`] scales the observation, computes the stimulus E (the stall detector on the
//! wheels' over-current flags, or the left-elbow command), and outputs every prediction with the current
//! weights; the caller acts on that at once. [`LearningStage::learn`] then runs the TD(λ) update for the
//! transition into this tick (the paper's "act first, then learn"; see [`crate::learn::set`]).
//!
//! Runtime changes are bounded like the configuration: [`LearningStage::set_params`] goes through
//! [`crate::learn::bounds`] (α·‖x‖² ≤ 1 and the rest), and an injected human request lasts at most
//! [`MAX_REQUEST_MS`]. A prediction whose weights were about to become non-finite stops learning, is
//! reported by [`LearningStage::learn`], and no longer drives the gate (see [`crate::learn::set`]).
//!
//! Off-policy predictions (`learner = "gtd"`, `target_policy = "default"`) learn about the default
//! policy π from the behaviour actually run: the inputs [`LearnInput::previous_followed_default`] and
//! [`LearnInput::previous_behaviour_prob`] give the ratio ρ of the transition into the tick
//! ([`importance_ratio`]: 0 or 1 with the paper's deterministic gate, [`followed_default`] says why;
//! 1/ε on π's action drawn by a stochastic gate). On-policy predictions ignore it.
//!
//! With the left-elbow stimulus, a tick whose elbow angles are missing or stale (either arm: the features
//! tile both) is acted on but not learned from, and the learning chain breaks there, as it does for stale
//! robot data: E is unknown on such a tick, not "no command", and half the tilings are inactive. This is a
//! design choice, not the paper's (the paper is silent on missing elbows); its measured effect is in the
//! interaction study's footnote (`actors/src/experiment/design_notes.rs`).

use crate::config::{Config, StimulusSpec};
use crate::control::StallDetector;
use crate::learn::{
    FeatureInputs, LearnError, ParamBounds, PredictionSet, SetSnapshot, Threshold, TickSignals,
};
use crate::obs::ObsLayout;
use crate::oi::SensorValues;
use crate::oi::packets::{bits, id};
use crate::record::{ElbowAngles, PredictionValue};
use crate::skeleton::ElbowFeatures;

/// One tick's input.
#[derive(Debug, Clone, Copy)]
pub struct LearnInput<'a> {
    /// The newest sensor snapshot, if any frame has arrived.
    pub values: Option<&'a SensorValues>,
    /// Elbow features, when a skeleton stream is configured.
    pub elbow: Option<ElbowFeatures>,
    /// A human command request injected by an operator: E is on regardless of the sensors.
    pub forced_stimulus: bool,
    /// Whether the command sent on the previous tick was the default policy π's
    /// ([`followed_default`]): the importance sampling ratio of the transition into this tick for an
    /// off-policy prediction about π (see the module documentation).
    pub previous_followed_default: bool,
    /// The behaviour probability b(A|S) of the command sent on the previous tick (its record's
    /// `behaviour_prob`): 1 unless a stochastic gate drew it ([`importance_ratio`]).
    pub previous_behaviour_prob: f64,
}

/// The importance sampling ratio ρ = π(A|S)/b(A|S) of a tick's command for a prediction whose target
/// policy is π: 1/b when the command was π's (π is deterministic, so π(A|S) = 1), else 0 (π never takes
/// it). With the paper's gate b = 1 and ρ ∈ {0, 1}; with a stochastic gate b = ε on π's action in the gate
/// region, so ρ = 1/ε there. A b that is not a probability above 0 gives 0 (it cannot be the
/// probability of an action taken).
pub fn importance_ratio(followed_default: bool, behaviour_prob: f64) -> f64 {
    if followed_default && behaviour_prob > 0.0 && behaviour_prob <= 1.0 {
        1.0 / behaviour_prob
    } else {
        0.0
    }
}

/// Whether a tick's command was the default policy π's: the importance sampling ratio
/// `ρ = π(A|S) / b(A|S)` of that tick's action for a prediction whose target policy is π.
///
/// Both policies are deterministic given the agent's state on the tick: π is a fixed function of the
/// tick (the stall cycle) and the behaviour b is the gate's choice between π and the response ϱ (and a
/// safety stop or teleop over it), made from the stimulus, the prediction and the mode, all of which are
/// part of that state. So b gives the action taken probability 1 (b(A|S) = 1) and π gives it 1 when it
/// is π's action and 0 otherwise: ρ = 1/b = 1 when the command equals π's, else 0. (With the stochastic
/// gate b is a genuinely random mixture of π and ϱ, with probability ε of π in the gate region, and
/// ρ = 1/ε on π's action there: [`importance_ratio`].) The comparison is on the command actually written, so a safety stop or an
/// e-stop counts as leaving π.
pub fn followed_default(command: crate::control::Action, default: crate::control::Action) -> bool {
    command == default
}

/// The longest injected human request, ms (10 s). A request forces the stimulus E on for its whole
/// length: the gate engages the response (the interaction experiment spins the robot in place) and the
/// learner is told the stimulus is there. The page's Request button asks for 500 ms and a real gesture
/// command lasts about a second; 10 s leaves room for slow demonstrations, while 10⁹ ms would leave the
/// robot spinning, and the predictions learning a fake stimulus, for eleven days.
pub const MAX_REQUEST_MS: u64 = 10_000;

/// A human request longer than [`MAX_REQUEST_MS`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("human_request.duration_ms = {duration_ms} exceeds {max} ms (10 s)", max = MAX_REQUEST_MS)]
pub struct RequestTooLong {
    /// The duration asked for, ms.
    pub duration_ms: u64,
}

/// The first tick after a human request of `duration_ms` made on tick `seq`, with ticks of `period_ms`.
pub fn request_end(seq: u64, duration_ms: u64, period_ms: u64) -> Result<u64, RequestTooLong> {
    if duration_ms > MAX_REQUEST_MS {
        return Err(RequestTooLong { duration_ms });
    }
    Ok(seq.saturating_add(duration_ms.div_ceil(period_ms.max(1))))
}

/// What one learning step reports.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LearnReport {
    /// Predictions that stopped learning on this step because their weights were about to become
    /// non-finite (they keep their last finite weights and no longer drive the gate).
    pub newly_diverged: Vec<String>,
    /// How many times a prediction has stopped so, since the stage was built.
    pub divergences: u64,
}

/// The whole state of a [`LearningStage`] between two ticks.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageSnapshot {
    /// Weights, traces, parameters in force and the previous step of every prediction.
    pub predictions: SetSnapshot,
    /// The stall detector's level.
    pub stall_level: u8,
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
    /// The bounds of changes to α (α·‖x‖² ≤ 1).
    pub bounds: ParamBounds,
    /// The prediction stopped learning because its weights were about to become non-finite.
    pub diverged: bool,
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
    /// Every prediction's input to the rule table (valid value and threshold), in the set's order.
    pub gate_inputs: Vec<crate::control::GateInput>,
    /// Elbow angles, when a skeleton is used.
    pub elbow: Option<ElbowAngles>,
    /// The input of the same name, carried into the tick's record for replay.
    pub previous_followed_default: bool,
    /// The input of the same name, carried into the tick's record for replay.
    pub previous_behaviour_prob: f64,
}

/// Perception, prediction and learning for one configuration.
pub struct LearningStage {
    layout: ObsLayout,
    set: PredictionSet,
    stimulus_spec: StimulusSpec,
    stall: StallDetector,
    gate_index: usize,
    obs: Vec<f64>,
    /// The unscaled observation of the last `act`, filled from `values` only when
    /// [`LearningStage::signals`] asks for it (a Horde reads it; the predictions never do).
    raw: Vec<f64>,
    /// The snapshot the last `act` saw, kept for `raw`; `obs` is its scaled form when it is `Some`.
    values: Option<SensorValues>,
    extra: [f64; 4],
    stimuli: [bool; 1],
    pending_stimulus: Option<bool>,
    /// ρ of the transition into the pending tick (1: the previous tick followed π).
    pending_rho: f64,
    /// Diverged predictions already reported by `learn`.
    reported: Vec<String>,
    /// Whether the pending tick's elbow angles are all there (always true without the elbow stimulus).
    pending_complete: bool,
    /// Ticks not learned from because an elbow angle was missing or stale.
    skipped_missing_elbow: u64,
    /// The largest ratio the behaviour produces (1/ε with a stochastic gate, else 1), and the
    /// predictions whose α it bounds (off-policy about π): α·ρ_max·‖x‖² ≤ 1 for runtime changes too.
    rho_max: f64,
    about_default: Vec<String>,
}

fn scaled_angle(a: Option<f64>) -> f64 {
    a.map_or(f64::NAN, |deg| deg / 180.0)
}

impl LearningStage {
    /// Builds the predictions of `config` over the observation layout of its robot model.
    pub fn new(config: &Config) -> Result<Self, LearnError> {
        let layout = ObsLayout::for_model(config.robot.model);
        let names = config.signal_names();
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
            raw: Vec::with_capacity(layout.len()),
            values: None,
            stimuli: [false],
            layout,
            set,
            stimulus_spec: config.control.stimulus.clone(),
            stall,
            gate_index,
            extra: [f64::NAN; 4],
            pending_stimulus: None,
            pending_rho: 0.0,
            reported: Vec::new(),
            pending_complete: true,
            skipped_missing_elbow: 0,
            rho_max: config.rho_max(),
            about_default: config
                .predictions
                .iter()
                .filter(|p| crate::config::gate::learns_about_default(p))
                .map(|p| p.name.clone())
                .collect(),
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
        // `obs` holds the scaled `values` of the previous tick (when it had a snapshot): only what
        // changed since is scaled again.
        match (input.values, &self.values) {
            (Some(v), Some(previous)) => self.layout.rescale(v, previous, &mut self.obs),
            (Some(v), None) => self.layout.scale(v, &mut self.obs),
            (None, _) => {
                self.obs.clear();
                self.obs.resize(self.layout.len(), f64::NAN);
            }
        }
        self.values = input.values.cloned();
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
        self.pending_rho = importance_ratio(
            input.previous_followed_default,
            input.previous_behaviour_prob,
        );
        self.stimuli = [stimulus];
        self.pending_complete = match self.stimulus_spec {
            StimulusSpec::Stall { .. } => true,
            StimulusSpec::LeftElbow { .. } => input
                .elbow
                .is_some_and(|e| e.left.is_some() && e.right.is_some()),
        };
        // The predictions straight into the output's vectors (no vector of outputs between, each name
        // copied once, into the record).
        let n = self.set.len();
        let mut predictions = Vec::with_capacity(n);
        let mut gate_inputs = Vec::with_capacity(n);
        let (mut gate_value, mut gate_threshold) = (None, f64::INFINITY);
        let gate_index = self.gate_index;
        self.set.predict_each(
            &FeatureInputs {
                obs: &self.obs,
                extra: &self.extra,
            },
            |name, o| {
                if predictions.len() == gate_index {
                    (gate_value, gate_threshold) = (o.valid_value(), o.threshold);
                }
                gate_inputs.push(crate::control::GateInput {
                    value: o.valid_value(),
                    threshold: o.threshold,
                });
                predictions.push(PredictionValue {
                    name: name.to_string(),
                    value: o.value,
                    threshold: o.threshold,
                });
            },
        );
        LearnOutput {
            obs_vector: self.obs.iter().map(|&x| x as f32).collect(),
            stimulus,
            predictions,
            gate_value,
            gate_threshold,
            gate_inputs,
            elbow,
            previous_followed_default: input.previous_followed_default,
            previous_behaviour_prob: input.previous_behaviour_prob,
        }
    }

    /// Step 2 of a tick: the TD(λ) update into this tick. Call once after each [`LearningStage::act`].
    /// Reports any prediction that stopped learning on this step (the caller logs it). A tick with a
    /// missing or stale elbow (elbow stimulus) is not learned from and breaks the chain.
    pub fn learn(&mut self) -> Result<LearnReport, LearnError> {
        let Some(stimulus) = self.pending_stimulus.take() else {
            return Err(LearnError::LearnWithoutPredict);
        };
        if !self.pending_complete {
            self.skipped_missing_elbow += 1;
            self.set.break_chain();
            return Ok(LearnReport {
                newly_diverged: Vec::new(),
                divergences: self.set.divergences(),
            });
        }
        let before = self.set.divergences();
        self.set
            .learn_each(&[stimulus], self.pending_rho, |_delta| {})?;
        let divergences = self.set.divergences();
        let newly_diverged = if divergences > before {
            // Rare (never with the bounds in force); the names are only gathered then.
            let mut names: Vec<String> = self.set.diverged().map(str::to_string).collect();
            names.retain(|n| !self.reported.contains(n));
            self.reported.extend(names.iter().cloned());
            names
        } else {
            Vec::new()
        };
        Ok(LearnReport {
            newly_diverged,
            divergences,
        })
    }

    /// The signals of the last [`LearningStage::act`], as a Horde reads them: the observation scaled and
    /// unscaled, the extra inputs and the stimulus. The unscaled observation is filled here, from the
    /// snapshot `act` kept (a tick without a Horde never needs it).
    pub fn signals(&mut self) -> TickSignals<'_> {
        match &self.values {
            Some(v) => self.layout.raw(v, &mut self.raw),
            None => {
                self.raw.clear();
                self.raw.resize(self.layout.len(), f64::NAN);
            }
        }
        TickSignals {
            obs: &self.obs,
            raw: &self.raw,
            extra: &self.extra,
            stimuli: &self.stimuli,
        }
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
        let mut bounds = self.set.bounds(&spec.name)?;
        if self.about_default.contains(&spec.name) {
            // α·ρ_max·‖x‖² ≤ 1 under a stochastic gate (`crate::config::gate`).
            bounds.max_alpha /= self.rho_max;
        }
        Some(ParamsInForce {
            prediction: spec.name.clone(),
            alpha: spec.alpha,
            lambda: spec.lambda,
            threshold: spec.threshold_value(),
            bounds,
            diverged: self.set.diverged().any(|n| n == spec.name),
        })
    }

    /// Changes α, λ or θ of prediction `name` (default: the gating prediction) and returns the
    /// parameters now in force. Every value is checked against its bound first (α finite, > 0 and
    /// α·‖x‖² ≤ 1 — α·ρ_max·‖x‖² ≤ 1 for an off-policy prediction about π under a stochastic gate,
    /// [`crate::config::gate`] —, λ in `[0, 1]`, θ finite; [`crate::learn::bounds`]); on error nothing
    /// changes.
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
        if let (Some(a), Some(b)) = (alpha, self.set.bounds(&name))
            && self.about_default.contains(&name)
            && a > b.max_alpha / self.rho_max * (1.0 + 1e-12)
        {
            return Err(crate::learn::bounds::out_of_bounds(
                &name,
                "alpha",
                a,
                format!(
                    "exceeds ε/{n} = {max:.6} (α·ρ_max·‖x‖² ≤ 1 with ρ_max = {rho} under the stochastic gate)",
                    n = b.active_features,
                    max = b.max_alpha / self.rho_max,
                    rho = self.rho_max
                ),
            ));
        }
        self.set
            .set_params(&name, alpha, lambda, threshold.map(Threshold::Fixed))?;
        self.params(Some(&name))
            .ok_or(LearnError::UnknownPrediction(name))
    }

    /// How many times a prediction stopped learning because it diverged, since the stage was built.
    pub fn divergences(&self) -> u64 {
        self.set.divergences()
    }

    /// Resets every weight and trace to its initial value; a diverged prediction learns again.
    pub fn reset(&mut self) {
        self.set.reset();
        self.reported.clear();
    }

    /// The learned state of every prediction.
    pub fn snapshot(&self) -> SetSnapshot {
        self.set.snapshot()
    }

    /// Restores a snapshot taken from a stage of the same predictions (on error nothing changes); its
    /// α, λ and θ must be within their bounds, and a diverged prediction learns again.
    pub fn restore(&mut self, snapshot: &SetSnapshot) -> Result<(), LearnError> {
        self.set.restore(snapshot)?;
        self.reported.clear();
        Ok(())
    }

    /// Everything the stage carries from one tick to the next: the predictions' learned state and the
    /// stall detector's level. A stage restored from it (between ticks) continues exactly.
    pub fn stage_snapshot(&self) -> StageSnapshot {
        StageSnapshot {
            predictions: self.set.snapshot(),
            stall_level: self.stall.level(),
        }
    }

    /// Restores a [`LearningStage::stage_snapshot`] of a stage of the same configuration.
    pub fn restore_stage(&mut self, snapshot: &StageSnapshot) -> Result<(), LearnError> {
        self.set.restore(&snapshot.predictions)?;
        self.stall.set_level(snapshot.stall_level);
        self.pending_stimulus = None;
        Ok(())
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
                previous_followed_default: true,
                previous_behaviour_prob: 1.0,
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
                previous_followed_default: true,
                previous_behaviour_prob: 1.0,
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
                previous_followed_default: true,
                previous_behaviour_prob: 1.0,
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
            previous_followed_default: true,
            previous_behaviour_prob: 1.0,
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

    #[test]
    fn set_params_is_bounded_like_the_configuration() {
        let mut s = stall_stage();
        let before = s.params(None).unwrap();
        assert_eq!(before.bounds.active_features, 44);
        for alpha in [1.0, 1e308, 0.0228, -1.0, f64::NAN] {
            let e = s.set_params(None, Some(alpha), None, None).unwrap_err();
            assert!(e.to_string().contains("alpha"), "{e}");
        }
        let e = s.set_params(None, Some(1.0), None, None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "prediction `stall`: alpha = 1.0 exceeds 1/44 = 0.0227 (α·‖x‖² ≤ 1 with 44 active features)"
        );
        // Refused as a whole: a good λ next to a bad α changes nothing.
        assert!(
            s.set_params(None, Some(1e308), Some(0.9), Some(0.3))
                .is_err()
        );
        assert!(s.set_params(None, None, Some(-0.1), None).is_err());
        assert!(s.set_params(None, None, None, Some(f64::INFINITY)).is_err());
        assert_eq!(s.params(None).unwrap(), before);
        // At the bound: accepted.
        let p = s
            .set_params(None, Some(1.0 / 44.0), Some(1.0), None)
            .unwrap();
        assert_eq!((p.alpha, p.lambda), (1.0 / 44.0, 1.0));
    }

    #[test]
    fn human_requests_are_bounded() {
        assert_eq!(request_end(100, 500, 20), Ok(125));
        assert_eq!(request_end(100, MAX_REQUEST_MS, 20), Ok(600));
        assert_eq!(request_end(u64::MAX, 500, 20), Ok(u64::MAX));
        let e = request_end(100, 1_000_000_000, 20).unwrap_err();
        assert_eq!(
            e.to_string(),
            "human_request.duration_ms = 1000000000 exceeds 10000 ms (10 s)"
        );
    }

    /// One input, `bump_right` (0 or 1), in two tiles: α = 1 is the bound. The restored weights are
    /// −0.9e308 on "no bump" and +0.9e308 on "bump", with a trace of 1 on "bump" and the previous tick on
    /// "no bump": moving to "bump" gives a finite δ ≈ 1.76e308 whose step would overflow w.
    fn diverging_stage() -> LearningStage {
        let text = include_str!("../../config/stall.toml")
            .replace(
                "features = { kind = \"one_dim\", all_obs = true, tiles = 10 }",
                "features = { kind = \"one_dim\", inputs = [\"bump_right\"], tiles = 2 }",
            )
            .replace("alpha = 0.022727272727272728", "alpha = 1.0")
            .replace("lambda = 0.5", "lambda = 1.0");
        let mut s = LearningStage::new(&Config::from_toml(&text).unwrap()).unwrap();
        let mut snap = s.snapshot();
        let p = &mut snap.predictions[0];
        p.weights = vec![-0.9e308, 0.9e308];
        p.state = None; // edited by hand: restore from the dense form
        p.traces = vec![0.0, 1.0];
        p.previous = Some(crate::learn::PreviousStep {
            active: vec![0],
            gamma: 0.96,
        });
        s.restore(&snap).unwrap();
        s
    }

    #[test]
    fn a_diverged_prediction_does_not_drive_the_gate() {
        use crate::agent::gating::GatingStage;
        use crate::control::{Action, Mode, Policy};
        let mut s = diverging_stage();
        let response = Policy::Stop {};
        let default = Policy::Constant {
            left_mm_s: 100,
            right_mm_s: 100,
        };
        let rules = Config::from_toml(include_str!("../../config/stall.toml"))
            .unwrap()
            .rule_table();
        let mut gate = GatingStage::new(Mode::Pavlovian, default, response, rules);
        let mut bumped = snapshot(false);
        bumped.set(id::BUMPS_WHEEL_DROPS, 1);
        let input = |v| LearnInput {
            values: Some(v),
            elbow: None,
            forced_stimulus: false,
            previous_followed_default: true,
            previous_behaviour_prob: 1.0,
        };
        let out = s.act(input(&bumped));
        assert_eq!(out.gate_value, Some(0.9e308), "valid until it diverges");
        let report = s.learn().unwrap();
        assert_eq!(report.newly_diverged, vec!["stall".to_string()]);
        assert_eq!(report.divergences, 1);
        assert!(s.params(None).unwrap().diverged);
        for seq in 0..50 {
            let out = s.act(input(&bumped));
            assert!(out.predictions[0].value.is_finite());
            assert!(out.predictions[0].value > out.gate_threshold);
            assert_eq!(out.gate_value, None);
            assert_eq!(out.gate_inputs[0].value, None);
            let d = gate.decide(seq, out.stimulus, &out.gate_inputs);
            assert!(!d.gate, "a diverged prediction engaged the response");
            assert_eq!(d.action, Action::new(100, 100));
            // The stimulus still engages it: the gate is the reactive rule.
            let d = gate.decide(seq, true, &out.gate_inputs);
            assert_eq!((d.gate, d.rule.as_deref()), (true, Some("stimulus")));
            let report = s.learn().unwrap();
            assert!(report.newly_diverged.is_empty(), "reported once");
            assert_eq!(report.divergences, 1);
        }
        let w = s.snapshot().predictions[0].weights.clone();
        assert_eq!(w, vec![-0.9e308, 0.9e308]);
        s.reset();
        assert!(!s.params(None).unwrap().diverged);
        assert_eq!(s.act(input(&bumped)).gate_value, Some(0.0));
    }
}
