//! [`Horde`]: thousands of general predictions (GVFs) learned side by side every tick, after Sutton
//! et al.'s Horde and Modayil, White & Sutton's nexting [Horde] \[nexting\].
//!
//! Predictions come in families ([`family`]): every cumulant ([`signals`]) at every timescale over one
//! feature construction. The Horde builds each distinct feature construction once per tick, however
//! many predictions read it, and puts predictions that share features, λ, the discount (τ and its
//! terminating stimulus) and a linear output into one [`TraceGroup`](super::group::TraceGroup): one
//! trace, one row of weights per feature, and a tick whose cost is the active features times the
//! predictions, never all features. A family's `learner` picks the group's kind (`groups.rs`):
//! `paper`, `xent` and `linear` in the paper's group; `true_online` in the same deferred group with a
//! shared dutch trace (its group also keyed by α, which is in that trace); `autostep` in an
//! [`super::group::AutostepGroup`] (a step size, h and v per weight: four numbers per weight, and its
//! logistic predictions share a trace too). Off-policy `gtd` is not run in a Horde.
//!
//! A tick is [`Horde::step`]: every prediction for this tick's features with the current weights, then
//! the TD(λ) update of the transition into this tick, as in [`crate::learn::set`]; both in one pass over
//! each active weight row (`TraceGroup::predict_and_learn`).

mod build;
pub mod family;
mod groups;
pub mod signals;
mod state;

pub use build::check;
pub use family::FamilySpec;
pub use signals::{Source, TickSignals};
pub use state::{HordeSnapshot, HordeState};

use super::group::Weight;
use super::inputs::FeatureInputs;
use super::tiles::TileCoder;
use super::{FeatureSpec, LearnError};

/// Most predictions in a Horde.
pub const MAX_HORDE_PREDICTIONS: usize = 100_000;
/// Most weights in a Horde (2²⁸: 1 GiB of `f32`).
pub const MAX_HORDE_WEIGHTS: usize = 1 << 28;

/// One feature construction, built once per tick.
#[derive(Debug, Clone)]
struct Bank {
    spec: FeatureSpec,
    gather: Vec<usize>,
    coder: TileCoder,
    scratch: Vec<f64>,
    active: Vec<usize>,
    /// Which features are active, kept only when a cumulant reads a feature.
    on: Option<Vec<bool>>,
}

/// Predictions sharing a trace, and where their cumulants come from.
#[derive(Debug, Clone)]
struct Slot<W> {
    bank: usize,
    /// `1 − 1/τ`.
    continuation: f64,
    /// The stimulus that ends the predictions (γ = 0 while it is on).
    terminate: Option<usize>,
    group: groups::SlotGroup<W>,
    sources: Vec<Source>,
    /// The index of each column's prediction.
    predictions: Vec<usize>,
    cumulants: Vec<f64>,
    deltas: Vec<f64>,
    /// The memory the next snapshot's weights are copied into ([`Horde::keep_snapshot_buffers`]).
    spare: Option<Vec<W>>,
}

/// What identifies a prediction in the Horde.
#[derive(Debug, Clone, PartialEq)]
pub struct PredictionInfo {
    /// `<family>/<cumulant>@<τ>`.
    pub name: String,
    /// The family's index.
    pub family: usize,
    /// The cumulant.
    pub source: Source,
    /// The timescale in ticks.
    pub tau: f64,
}

/// Many predictions learned together (see the module documentation).
#[derive(Debug, Clone)]
pub struct Horde<W> {
    families: Vec<FamilySpec>,
    /// The bounds of each family's features (α·‖x‖² ≤ 1).
    family_bounds: Vec<super::ParamBounds>,
    banks: Vec<Bank>,
    slots: Vec<Slot<W>>,
    predictions: Vec<PredictionInfo>,
    /// Prediction `i` is column `.1` of slot `.0`.
    place: Vec<(usize, usize)>,
    /// Predictions that stopped learning because a step was not finite, since the Horde was built.
    stopped: u64,
    /// While a snapshot is being copied: `stopped` when it began.
    snapshot_stopped: Option<u64>,
}

/// How a Horde is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HordeShape {
    /// Predictions.
    pub predictions: usize,
    /// Feature constructions (tile codings per tick).
    pub feature_sets: usize,
    /// Trace groups.
    pub groups: usize,
    /// Weights in all.
    pub weights: usize,
    /// Active features of all feature constructions together, for a fully valid input.
    pub active_features: usize,
}

impl<W: Weight> Horde<W> {
    /// One tick: every prediction for this tick's features, then the update into this tick. Returns
    /// how many predictions stopped learning on this tick (a step that was not finite).
    pub fn step(&mut self, signals: &TickSignals) -> usize {
        self.step_with(signals, true)
    }

    /// [`Horde::step`] as it was before its passes were fused: each group's `predict`, then its
    /// `learn`, two passes over the active weight rows. The same result bit for bit (the reference the
    /// tests and `examples/horde_step_cpu.rs` compare the step with); slower at Horde scale.
    #[doc(hidden)]
    pub fn step_two_passes(&mut self, signals: &TickSignals) -> usize {
        self.step_with(signals, false)
    }

    fn step_with(&mut self, signals: &TickSignals, fused: bool) -> usize {
        let inputs = FeatureInputs {
            obs: signals.obs,
            extra: signals.extra,
        };
        for bank in &mut self.banks {
            bank.scratch.clear();
            bank.scratch
                .extend(bank.gather.iter().map(|&i| inputs.get(i)));
            if let Some(on) = &mut bank.on {
                for &f in &bank.active {
                    on[f] = false;
                }
            }
            bank.coder.active(&bank.scratch, &mut bank.active);
            if let Some(on) = &mut bank.on {
                for &f in &bank.active {
                    on[f] = true;
                }
            }
        }
        let mut stopped = 0;
        for slot in &mut self.slots {
            let bank = &self.banks[slot.bank];
            let ends = slot
                .terminate
                .is_some_and(|i| signals.stimuli.get(i).copied().unwrap_or(false));
            let gamma = if ends { 0.0 } else { slot.continuation };
            let on = bank.on.as_deref();
            for (r, &source) in slot.cumulants.iter_mut().zip(&slot.sources) {
                *r = signals.value(source, |k| on.is_some_and(|o| o.get(k) == Some(&true)));
            }
            // The slices are the group's size: this cannot fail. The paper's group makes one pass
            // over each active weight row (`learn::group`'s `fused`), the same result as `predict`
            // then `learn`; the true-online and Autostep groups predict, then learn.
            stopped += slot
                .group
                .step(
                    &bank.active,
                    gamma,
                    &slot.cumulants,
                    &mut slot.deltas,
                    fused,
                )
                .unwrap_or(0);
        }
        self.stopped += stopped as u64;
        stopped
    }

    /// Forgets the previous tick and ends every trace (after a tick that was not learned from).
    pub fn break_chain(&mut self) {
        self.slots.iter_mut().for_each(|s| s.group.break_chain());
    }

    /// Every weight back to its initial value, every trace to zero.
    pub fn reset(&mut self) {
        self.slots.iter_mut().for_each(|s| s.group.reset());
    }

    /// The predictions, in order.
    pub fn predictions(&self) -> &[PredictionInfo] {
        &self.predictions
    }

    /// The families it was built from.
    pub fn families(&self) -> &[FamilySpec] {
        &self.families
    }

    /// The index of prediction `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.predictions.iter().position(|p| p.name == name)
    }

    /// Prediction `i`'s value on the last step, `σ(wᵀx_t)`.
    pub fn value(&self, i: usize) -> Option<f64> {
        let &(s, c) = self.place.get(i)?;
        let slot = &self.slots[s];
        Some(slot.group.sigma().value(slot.group.values()[c]))
    }

    /// Prediction `i`'s δ on the last step (NaN when nothing was learned), its cumulant and discount.
    pub fn learning(&self, i: usize) -> Option<(f64, f64, f64)> {
        let &(s, c) = self.place.get(i)?;
        let slot = &self.slots[s];
        Some((slot.deltas[c], slot.cumulants[c], slot.continuation))
    }

    /// Every prediction's value, in order, into `out`.
    pub fn values_into(&self, out: &mut Vec<f32>) {
        out.clear();
        out.resize(self.predictions.len(), 0.0);
        for slot in &self.slots {
            let sigma = slot.group.sigma();
            for (c, &i) in slot.predictions.iter().enumerate() {
                out[i] = sigma.value(slot.group.values()[c]) as f32;
            }
        }
    }

    /// Predictions that stopped learning since the Horde was built.
    pub fn stopped(&self) -> u64 {
        self.stopped
    }

    /// Its layout.
    pub fn shape(&self) -> HordeShape {
        HordeShape {
            predictions: self.predictions.len(),
            feature_sets: self.banks.len(),
            groups: self.slots.len(),
            weights: self
                .slots
                .iter()
                .map(|s| s.group.features() * s.group.len())
                .sum(),
            active_features: self.banks.iter().map(|b| b.coder.num_tilings()).sum(),
        }
    }

    /// Changes α of prediction `name` from the next update on, within its family's bound.
    pub fn set_alpha(&mut self, name: &str, alpha: f64) -> Result<(), LearnError> {
        let i = self
            .index_of(name)
            .ok_or_else(|| LearnError::UnknownPrediction(name.to_string()))?;
        self.family_bounds[self.predictions[i].family].check_alpha(name, alpha)?;
        let (s, c) = self.place[i];
        self.slots[s].group.set_alpha(c, alpha)
    }
}

#[cfg(test)]
mod learner_tests;
#[cfg(test)]
mod tests;
