//! [`PredictionSet`]: many predictions learned side by side, each with its own cumulant, τ, λ, α, σ
//! and features, so that adding a prediction is configuration, not code.
//!
//! # The online bookkeeping ("act first, then learn")
//!
//! At each tick t the caller does, in this order:
//! 1. [`PredictionSet::predict`] with the tick's inputs: for every prediction, compute x_t and output
//!    `v_t = σ(wᵀx_t)` with the current weights, to be used for acting right away.
//! 2. [`PredictionSet::learn`] with the tick's stimuli E_t: R_t = I{E_t}, γ_t = γ(E_t), and the TD(λ)
//!    update of the transition from the previous tick,
//!    `δ_{t−1} = R_t + γ_t σ(wᵀx_t) − σ(wᵀx_{t−1})`, `e_{t−1} = γ_{t−1} λ e_{t−2} + σ′(wᵀx_{t−1}) x_{t−1}`,
//!    `w ← w + α δ_{t−1} e_{t−1}` (the paper's equations with t − 1 in place of t). Then x_t and γ_t
//!    are kept as "previous" for the next tick.
//!
//! The weights used in step 1 at tick t are those from after the update at tick t − 1, so the value
//! acted on, `σ(wᵀx_t)`, is exactly the bootstrap term of the δ computed in step 2 of the same tick:
//! acting never waits for learning, and nothing is computed with stale features.
//!
//! Each on-policy prediction is a [`TdLearner`] in `f64`: dense ([`super::DenseTd`]) or a deferred
//! group of one ([`super::TraceGroup`]), whichever its shape makes faster; both match the dense
//! reference [`super::TdLambda`] to rounding (about 1e-12 over a stall run). That is `learner = "paper"`
//! (the default) and `"linear"`; `"xent"`, `"true_online"` and `"autostep"` run their own dense learners
//! ([`super::named`]), `"gtd"` GTD(λ).
//!
//! # Divergence
//!
//! The bounds of [`super::bounds`] keep a prediction's step size where TD(λ) does not diverge. Should a
//! prediction's weights still be about to become non-finite (an extreme weight restored from a
//! checkpoint, an overflowing sum), its learner refuses a step whose δ or deferred sum is not finite,
//! the prediction **stops learning and keeps its last finite weights**, and it is counted ([`PredictionSet::divergences`]) and
//! named ([`PredictionSet::diverged`]) so that the caller reports it. A stopped prediction is not valid
//! for the gate ([`PredictionOut::valid_value`] is `None`), so the gate falls back to the stimulus alone,
//! exactly as for an invalid input: its value neither engages nor holds off the response. It learns
//! again after [`PredictionSet::reset`] or [`PredictionSet::restore`].
//!
//! The first tick (or the first after a break) only records x_t and γ_t. The chain breaks, and the
//! traces are cleared, when a tick is predicted without being learned (two `predict` calls in a row:
//! the skipped transition cannot be learned from) or on [`PredictionSet::break_chain`].

use super::LearnError;
use super::bounds::{ParamBounds, check_lambda, check_set_size};
use super::group::Column;
use super::gtd::{Gtd, GtdChain};
use super::inputs::{FeatureInputs, SignalNames, resolve};
use super::named::{AutostepTd, Named, NamedChain, TrueOnlineTd, XentTd};
use super::spec::check_threshold;
use super::spec::{Cumulant, LearnerKind, PredictionSpec, Threshold};
use super::tiles::TileCoder;

/// One prediction's output on one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct PredictionOut {
    /// The prediction's name.
    pub name: String,
    /// v_t = σ(wᵀx_t).
    pub value: f64,
    /// The mixing-function threshold θ.
    pub threshold: f64,
    /// How many features were active (fewer than `tilings` when some inputs were missing or invalid).
    pub active_features: usize,
    /// How many tilings the coder has: the active count for a fully valid input.
    pub tilings: usize,
    /// The prediction stopped learning because its weights were about to become non-finite.
    pub diverged: bool,
}

/// One prediction's output on one tick without its name (which is its spec's, [`PredictionSet::specs`]):
/// what [`PredictionSet::predict_each`] hands over, so that a tick need not copy every name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Predicted {
    /// v_t = σ(wᵀx_t).
    pub value: f64,
    /// The mixing-function threshold θ.
    pub threshold: f64,
    /// How many features were active (fewer than `tilings` when some inputs were missing or invalid).
    pub active_features: usize,
    /// How many tilings the coder has: the active count for a fully valid input.
    pub tilings: usize,
    /// The prediction stopped learning because its weights were about to become non-finite.
    pub diverged: bool,
}

impl Predicted {
    /// As [`PredictionOut::valid_value`].
    pub fn valid_value(&self) -> Option<f64> {
        (self.active_features == self.tilings && self.value.is_finite() && !self.diverged)
            .then_some(self.value)
    }

    /// With the prediction's `name`.
    pub fn named(self, name: &str) -> PredictionOut {
        PredictionOut {
            name: name.to_string(),
            value: self.value,
            threshold: self.threshold,
            active_features: self.active_features,
            tilings: self.tilings,
            diverged: self.diverged,
        }
    }
}

impl PredictionOut {
    /// The value when it rests on a fully valid input (every tiling active), is finite and comes from a
    /// prediction that has not diverged, else `None`: the gate then falls back to the stimulus alone.
    pub fn valid_value(&self) -> Option<f64> {
        (self.active_features == self.tilings && self.value.is_finite() && !self.diverged)
            .then_some(self.value)
    }
}

/// The algorithm behind one prediction.
// One per prediction (a handful at most), built once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub(crate) enum Engine {
    /// On-policy TD(λ), dense or deferred ([`TdLearner`]), in f64.
    Td(TdLearner),
    /// Off-policy GTD(λ) ([`super::gtd`]).
    Gtd(Box<GtdChain>),
    /// A named learner with its own state: `xent`, `true_online`, `autostep` ([`super::named`]).
    Named(Box<NamedChain>),
}

/// One prediction and its learner.
#[derive(Debug, Clone)]
pub(crate) struct Learner {
    pub spec: PredictionSpec,
    pub gather: Vec<usize>,
    pub coder: TileCoder,
    /// The learner.
    pub engine: Engine,
    pub stimulus: usize,
    pub threshold: f64,
    /// The limits of runtime changes (α·‖x‖² ≤ 1).
    pub bounds: ParamBounds,
    scratch: Vec<f64>,
    /// `gather` is `0, 1, …, n − 1`: the coder reads the first n observation dimensions as they are
    /// (when the observation has n of them), with no copy into `scratch`.
    gather_is_prefix: bool,
    /// The coder's input of the last `predict`: `x_now` holds its active features.
    coded: Vec<f64>,
    x_now: Vec<usize>,
    fresh: bool,
}

impl Learner {
    /// `bounds` are those of `spec` ([`PredictionSpec::bounds`]), checked before anything is allocated.
    fn new(
        spec: PredictionSpec,
        bounds: ParamBounds,
        names: &SignalNames,
    ) -> Result<Self, LearnError> {
        let resolved = resolve(&spec.name, &spec.features, names)?;
        let stimulus = match &spec.cumulant {
            Cumulant::Stimulus(s) => names.resolve_stimulus(&spec.name, s)?,
        };
        let features = resolved.coder.num_features();
        let named = |n: Named| Engine::Named(Box::new(NamedChain::new(n)));
        let engine = match spec.gtd_params() {
            Some(params) if spec.learner == LearnerKind::Gtd => {
                Engine::Gtd(Box::new(GtdChain::new(Gtd::new(features, params)?)))
            }
            _ if spec.learner == LearnerKind::Xent => {
                named(Named::Xent(XentTd::new(features, spec.td_params())))
            }
            _ if spec.learner == LearnerKind::TrueOnline => named(Named::TrueOnline(
                TrueOnlineTd::new(features, spec.td_params()),
            )),
            _ if spec.learner == LearnerKind::Autostep => {
                named(Named::Autostep(AutostepTd::new(features, spec.td_params())))
            }
            // "paper" and "linear" (σ = identity, checked by the spec): the paper's engine.
            _ => Engine::Td(TdLearner::new(
                resolved.coder.num_features(),
                resolved.coder.num_tilings(),
                spec.lambda,
                spec.sigma,
                Column {
                    alpha: spec.alpha,
                    initial_weight: spec.initial_weight,
                },
            )?),
        };
        let tilings = resolved.coder.num_tilings();
        Ok(Learner {
            threshold: spec.threshold_value(),
            scratch: Vec::with_capacity(resolved.gather.len()),
            gather_is_prefix: resolved.gather.iter().enumerate().all(|(k, &i)| k == i),
            coded: Vec::with_capacity(resolved.gather.len()),
            x_now: Vec::with_capacity(tilings),
            fresh: false,
            bounds,
            gather: resolved.gather,
            coder: resolved.coder,
            engine,
            stimulus,
            spec,
        })
    }

    /// Whether the prediction stopped learning (see the module documentation).
    pub fn diverged(&self) -> bool {
        match &self.engine {
            Engine::Td(g) => g.diverged(),
            Engine::Gtd(c) => c.diverged(),
            Engine::Named(c) => c.diverged(),
        }
    }

    fn predict(&mut self, inputs: &FeatureInputs) -> Predicted {
        if self.fresh {
            self.break_chain();
        }
        // With a prefix gather the coder's input is the observation's first `gather.len()` values,
        // exactly what the copy below would hold (`FeatureInputs::get` of an index inside `obs`).
        let input = match inputs.obs.get(..self.gather.len()) {
            Some(prefix) if self.gather_is_prefix => prefix,
            _ => {
                self.scratch.clear();
                self.scratch
                    .extend(self.gather.iter().map(|&i| inputs.get(i)));
                &self.scratch[..]
            }
        };
        // `x_now` still holds the features of `coded`, the last tick's input: only what changed is
        // coded again.
        self.coder.active_since(input, &self.coded, &mut self.x_now);
        self.coded.clear();
        self.coded.extend_from_slice(input);
        let value = match &mut self.engine {
            Engine::Td(g) => g.predict_value(&self.x_now),
            Engine::Gtd(c) => self.spec.sigma.value(c.predict(&self.x_now)),
            Engine::Named(c) => c.predict(&self.x_now),
        };
        self.fresh = true;
        Predicted {
            value,
            threshold: self.threshold,
            active_features: self.x_now.len(),
            tilings: self.coder.num_tilings(),
            diverged: self.diverged(),
        }
    }

    /// The update into this tick; `None` when there was nothing to learn from, or when the prediction
    /// has diverged (now or before). `rho_prev` is the importance sampling ratio of the previous tick's
    /// action; an on-policy prediction ignores it.
    fn learn(&mut self, stimulus: bool, rho_prev: f64) -> Option<f64> {
        let reward = self.spec.reward(stimulus);
        let gamma = self.spec.gamma(stimulus);
        self.fresh = false;
        match &mut self.engine {
            Engine::Td(g) => g.learn(gamma, reward),
            Engine::Gtd(c) => c.learn(gamma, reward, rho_prev),
            Engine::Named(c) => c.learn(gamma, reward),
        }
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.fresh = false;
        match &mut self.engine {
            Engine::Td(g) => g.clear_pending(),
            Engine::Gtd(c) => c.clear_pending(),
            Engine::Named(c) => c.clear_pending(),
        }
    }

    pub fn break_chain(&mut self) {
        self.fresh = false;
        match &mut self.engine {
            Engine::Td(g) => g.break_chain(),
            Engine::Gtd(c) => c.break_chain(),
            Engine::Named(c) => c.break_chain(),
        }
    }

    /// Back to the initial weights, no previous tick.
    fn reset(&mut self) {
        self.fresh = false;
        match &mut self.engine {
            Engine::Td(g) => g.reset(),
            Engine::Gtd(c) => c.reset(),
            Engine::Named(c) => c.reset(),
        }
    }

    /// Checks α, λ and θ against their bounds, then applies them all (or nothing).
    pub(crate) fn set_params(
        &mut self,
        alpha: Option<f64>,
        lambda: Option<f64>,
        threshold: Option<Threshold>,
    ) -> Result<(), LearnError> {
        let name = self.spec.name.as_str();
        if let Some(a) = alpha {
            self.bounds.check_alpha(name, a)?;
        }
        if let Some(l) = lambda {
            check_lambda(name, l)?;
        }
        if let Some(t) = threshold {
            check_threshold(name, t)?;
        }
        if let Some(a) = alpha {
            match &mut self.engine {
                Engine::Td(g) => g.set_alpha(a)?,
                Engine::Gtd(c) => c.gtd_mut().set_alpha(a)?,
                Engine::Named(c) => c.set_alpha(a)?,
            }
            self.spec.alpha = a;
        }
        if let Some(l) = lambda {
            match &mut self.engine {
                Engine::Td(g) => g.set_lambda(l)?,
                Engine::Gtd(c) => c.gtd_mut().set_lambda(l)?,
                Engine::Named(c) => c.set_lambda(l)?,
            }
            self.spec.lambda = l;
        }
        if let Some(t) = threshold {
            self.spec.threshold = t;
            self.threshold = self.spec.threshold_value();
        }
        Ok(())
    }
}

/// A set of predictions learned together from the same inputs.
#[derive(Debug, Clone)]
pub struct PredictionSet {
    pub(crate) learners: Vec<Learner>,
    names: SignalNames,
    divergences: u64,
}

impl PredictionSet {
    /// Validates every spec against its bounds (`super::bounds`: parameters, sizes, and the count and
    /// features of the whole set, all before any weight is allocated) and resolves its features and
    /// cumulant against `names`.
    pub fn new(specs: Vec<PredictionSpec>, names: &SignalNames) -> Result<Self, LearnError> {
        names.check_unique()?;
        let mut bounds = Vec::with_capacity(specs.len().min(super::bounds::MAX_PREDICTIONS + 1));
        for (i, spec) in specs.iter().enumerate() {
            if specs[..i].iter().any(|s| s.name == spec.name) {
                return Err(LearnError::DuplicatePrediction(spec.name.clone()));
            }
            bounds.push(spec.bounds(names.obs.len())?);
        }
        check_set_size(&bounds.iter().map(|b| b.features).collect::<Vec<_>>())?;
        let mut learners: Vec<Learner> = Vec::with_capacity(specs.len());
        for (spec, bounds) in specs.into_iter().zip(bounds) {
            learners.push(Learner::new(spec, bounds, names)?);
        }
        Ok(PredictionSet {
            learners,
            names: names.clone(),
            divergences: 0,
        })
    }

    /// Step 1 of a tick: features and predictions for this tick's inputs, in spec order.
    pub fn predict(&mut self, inputs: &FeatureInputs) -> Vec<PredictionOut> {
        let mut outs = Vec::with_capacity(self.learners.len());
        self.predict_each(inputs, |name, p| outs.push(p.named(name)));
        outs
    }

    /// [`PredictionSet::predict`] without collecting: hands each prediction's name and output to
    /// `each`, in spec order (a tick's caller builds what it needs from them without a vector between).
    pub fn predict_each(&mut self, inputs: &FeatureInputs, mut each: impl FnMut(&str, Predicted)) {
        for l in &mut self.learners {
            let p = l.predict(inputs);
            each(&l.spec.name, p);
        }
    }

    /// Step 2 of a tick for on-policy data: [`PredictionSet::learn_with_ratio`] with ρ = 1 (the previous
    /// tick's action was the target policy's; on-policy predictions ignore ρ anyway).
    pub fn learn(&mut self, stimuli: &[bool]) -> Result<Vec<Option<f64>>, LearnError> {
        self.learn_with_ratio(stimuli, 1.0)
    }

    /// Step 2 of a tick: the TD(λ) or GTD(λ) update for the transition from the previous tick to this
    /// one, given this tick's stimuli (in [`SignalNames::stimuli`] order) and the importance sampling
    /// ratio `rho_prev` of the previous tick's action (used by off-policy predictions only). Returns each
    /// prediction's δ, or `None` where there was no previous tick to learn from or the prediction has
    /// diverged (see the module documentation; [`PredictionSet::divergences`] counts the predictions
    /// that stopped).
    pub fn learn_with_ratio(
        &mut self,
        stimuli: &[bool],
        rho_prev: f64,
    ) -> Result<Vec<Option<f64>>, LearnError> {
        let mut deltas = Vec::with_capacity(self.learners.len());
        self.learn_each(stimuli, rho_prev, |delta| deltas.push(delta))?;
        Ok(deltas)
    }

    /// [`PredictionSet::learn_with_ratio`] without collecting: hands each prediction's δ to `each`, in
    /// spec order (nothing, on an error, which is found before any prediction learns).
    pub fn learn_each(
        &mut self,
        stimuli: &[bool],
        rho_prev: f64,
        mut each: impl FnMut(Option<f64>),
    ) -> Result<(), LearnError> {
        if stimuli.len() != self.names.stimuli.len() {
            return Err(LearnError::StimulusCountMismatch {
                expected: self.names.stimuli.len(),
                got: stimuli.len(),
            });
        }
        if self.learners.iter().any(|l| !l.fresh) {
            return Err(LearnError::LearnWithoutPredict);
        }
        let mut stopped = 0;
        for l in &mut self.learners {
            let was = l.diverged();
            let delta = l.learn(stimuli.get(l.stimulus).copied().unwrap_or(false), rho_prev);
            stopped += u64::from(l.diverged() && !was);
            each(delta);
        }
        self.divergences += stopped;
        Ok(())
    }

    /// How many times a prediction stopped learning because its weights were about to become
    /// non-finite, since the set was built.
    pub fn divergences(&self) -> u64 {
        self.divergences
    }

    /// The predictions that have stopped learning (diverged), by name.
    pub fn diverged(&self) -> impl Iterator<Item = &str> + '_ {
        self.learners
            .iter()
            .filter(|l| l.diverged())
            .map(|l| l.spec.name.as_str())
    }

    /// The bounds of prediction `name`'s runtime changes (α·‖x‖² ≤ 1).
    pub fn bounds(&self, name: &str) -> Option<ParamBounds> {
        self.learners
            .iter()
            .find(|l| l.spec.name == name)
            .map(|l| l.bounds)
    }

    /// Forgets the previous tick and clears every trace (e.g. after a sensor gap): the next tick
    /// starts a new chain of credit. Weights are kept.
    pub fn break_chain(&mut self) {
        self.learners.iter_mut().for_each(Learner::break_chain);
    }

    /// Back to the initial weights, zero traces and no previous tick; a diverged prediction learns again.
    pub fn reset(&mut self) {
        self.learners.iter_mut().for_each(Learner::reset);
    }

    /// The number of predictions.
    pub fn len(&self) -> usize {
        self.learners.len()
    }

    /// True for a set without predictions.
    pub fn is_empty(&self) -> bool {
        self.learners.is_empty()
    }

    /// The signal names the set was built against.
    pub fn signal_names(&self) -> &SignalNames {
        &self.names
    }

    /// The specs, in order, with any runtime changes to α, λ and the threshold applied.
    pub fn specs(&self) -> impl Iterator<Item = &PredictionSpec> + '_ {
        self.learners.iter().map(|l| &l.spec)
    }

    /// The learner of on-policy prediction `name`; `None` for an off-policy one
    /// ([`PredictionSet::off_policy_learner`]).
    pub fn learner(&self, name: &str) -> Option<&TdLearner> {
        self.learners
            .iter()
            .find(|l| l.spec.name == name)
            .and_then(|l| match &l.engine {
                Engine::Td(g) => Some(g),
                Engine::Gtd(_) | Engine::Named(_) => None,
            })
    }

    /// The named learner (`xent`, `true_online`, `autostep`) of prediction `name`.
    pub fn named_learner(&self, name: &str) -> Option<&Named> {
        self.learners
            .iter()
            .find(|l| l.spec.name == name)
            .and_then(|l| match &l.engine {
                Engine::Named(c) => Some(c.learner()),
                _ => None,
            })
    }

    /// The GTD(λ) learner of off-policy prediction `name`.
    pub fn off_policy_learner(&self, name: &str) -> Option<&Gtd> {
        self.learners
            .iter()
            .find(|l| l.spec.name == name)
            .and_then(|l| match &l.engine {
                Engine::Gtd(c) => Some(c.gtd()),
                Engine::Td(_) | Engine::Named(_) => None,
            })
    }

    /// The tile coder of prediction `name`.
    pub fn coder(&self, name: &str) -> Option<&TileCoder> {
        self.learners
            .iter()
            .find(|l| l.spec.name == name)
            .map(|l| &l.coder)
    }

    /// Changes α of prediction `name` from the next update on (within α·‖x‖² ≤ 1).
    pub fn set_alpha(&mut self, name: &str, alpha: f64) -> Result<(), LearnError> {
        self.set_params(name, Some(alpha), None, None)
    }

    /// Changes λ of prediction `name` from the next update on.
    pub fn set_lambda(&mut self, name: &str, lambda: f64) -> Result<(), LearnError> {
        self.set_params(name, None, Some(lambda), None)
    }

    /// Changes the threshold of prediction `name` from the next prediction on.
    pub fn set_threshold(&mut self, name: &str, threshold: Threshold) -> Result<(), LearnError> {
        self.set_params(name, None, None, Some(threshold))
    }

    /// Changes any of α, λ and θ of prediction `name`: every value is checked against its bound
    /// (`super::bounds`) first, and on error nothing changes.
    pub fn set_params(
        &mut self,
        name: &str,
        alpha: Option<f64>,
        lambda: Option<f64>,
        threshold: Option<Threshold>,
    ) -> Result<(), LearnError> {
        self.find_mut(name)?.set_params(alpha, lambda, threshold)
    }

    fn find_mut(&mut self, name: &str) -> Result<&mut Learner, LearnError> {
        self.learners
            .iter_mut()
            .find(|l| l.spec.name == name)
            .ok_or_else(|| LearnError::UnknownPrediction(name.to_string()))
    }
}

mod td_learner;
pub use td_learner::{DENSE_PER_ACTIVE, SPARSE_DENSE_PER_ACTIVE, TdLearner};

#[cfg(test)]
mod tests;

#[cfg(test)]
mod gtd_tests;

#[cfg(test)]
mod named_tests;
