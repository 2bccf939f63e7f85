//! [`TdLearner`]: the on-policy TD(λ) learner of one prediction of a [`super::PredictionSet`], dense or
//! deferred, whichever is faster for its shape.
//!
//! A pass over every weight ([`DenseTd`]) costs the features; the deferred group ([`TraceGroup`]) costs
//! the active features, each several times over. Measured with `cargo bench --bench learn` (`dense/`,
//! `group/`, quiet machine with AVX2): at the paper's stall prediction (440 features, 44 active) the dense
//! pass is 2.6× faster (0.26 against 0.68 µs); at its command prediction (500 features, 5 active) the
//! dense pass that skips blocks of zero traces takes 0.148 µs against the group's 0.176. A prediction
//! with at most [`DENSE_PER_ACTIVE`] features per active feature runs dense, up to
//! [`SPARSE_DENSE_PER_ACTIVE`] dense skipping zero blocks, and beyond that (where looking at every block
//! would cost more than the group's work on the active rows) as a group. All of them compute the paper's
//! update and agree with the reference to rounding (1e-9 over 30,000 ticks in the tests).

use super::super::group::{Column, GroupState, TraceGroup};
use super::super::{DenseTd, LearnError, Sigma};

/// The most features per active feature for which the dense learner passes over every weight.
pub const DENSE_PER_ACTIVE: usize = 32;

/// The most features per active feature for which the dense learner runs at all, skipping blocks of
/// zero traces; beyond it, the group.
pub const SPARSE_DENSE_PER_ACTIVE: usize = 256;

/// One on-policy prediction's learner (see the module documentation).
// One per prediction (a handful at most), built once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum TdLearner {
    /// Weights and trace stored densely.
    Dense(DenseTd),
    /// A deferred group of one prediction.
    Group(TraceGroup<f64>),
}

impl TdLearner {
    /// The learner for `features` features of which `active` are active a tick.
    pub fn new(
        features: usize,
        active: usize,
        lambda: f64,
        sigma: Sigma,
        column: Column,
    ) -> Result<Self, LearnError> {
        let per_active = features / active.max(1);
        if per_active <= SPARSE_DENSE_PER_ACTIVE {
            let sparse = per_active > DENSE_PER_ACTIVE;
            Ok(TdLearner::Dense(
                DenseTd::new(features, lambda, sigma, column)?.skipping_zero_blocks(sparse),
            ))
        } else {
            Ok(TdLearner::Group(TraceGroup::new(
                features,
                lambda,
                sigma,
                vec![column],
            )?))
        }
    }

    /// `σ(wᵀx_t)` for this tick's features (step 1 of a tick).
    pub fn predict_value(&mut self, active: &[usize]) -> f64 {
        match self {
            TdLearner::Dense(d) => {
                d.predict(active);
                d.value()
            }
            TdLearner::Group(g) => g.sigma().value(g.predict(active)[0]),
        }
    }

    /// The update into this tick (step 2): δ, or `None` when nothing was learned.
    pub fn learn(&mut self, gamma: f64, reward: f64) -> Option<f64> {
        // `predict` ran (the set checks it) and one cumulant is given: neither can fail.
        let delta = match self {
            TdLearner::Dense(d) => d.learn(gamma, reward).unwrap_or(f64::NAN),
            TdLearner::Group(g) => {
                let mut delta = [f64::NAN];
                match g.learn(gamma, &[reward], &mut delta) {
                    Ok(_) => delta[0],
                    Err(_) => f64::NAN,
                }
            }
        };
        delta.is_finite().then_some(delta)
    }

    /// Whether the prediction stopped learning.
    pub fn diverged(&self) -> bool {
        match self {
            TdLearner::Dense(d) => d.diverged(),
            TdLearner::Group(g) => g.diverged(0),
        }
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        match self {
            TdLearner::Dense(d) => d.clear_pending(),
            TdLearner::Group(g) => g.clear_pending(),
        }
    }

    /// Forgets the previous tick and ends every trace.
    pub fn break_chain(&mut self) {
        match self {
            TdLearner::Dense(d) => d.break_chain(),
            TdLearner::Group(g) => g.break_chain(),
        }
    }

    /// Back to the initial weights.
    pub fn reset(&mut self) {
        match self {
            TdLearner::Dense(d) => d.reset(),
            TdLearner::Group(g) => g.reset(),
        }
    }

    /// Changes α from the next update on.
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        match self {
            TdLearner::Dense(d) => d.set_alpha(alpha),
            TdLearner::Group(g) => g.set_alpha(0, alpha),
        }
    }

    /// Changes λ from the next update on.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        match self {
            TdLearner::Dense(d) => d.set_lambda(lambda),
            TdLearner::Group(g) => g.set_lambda(lambda),
        }
    }

    /// α.
    pub fn alpha(&self) -> f64 {
        match self {
            TdLearner::Dense(d) => d.alpha(),
            TdLearner::Group(g) => g.columns()[0].alpha,
        }
    }

    /// λ.
    pub fn lambda(&self) -> f64 {
        match self {
            TdLearner::Dense(d) => d.lambda(),
            TdLearner::Group(g) => g.lambda(),
        }
    }

    /// The weights, one per feature.
    pub fn weights(&self) -> Vec<f64> {
        match self {
            TdLearner::Dense(d) => d.weights().to_vec(),
            TdLearner::Group(g) => g.weights(0),
        }
    }

    /// The trace, one per feature.
    pub fn traces(&self) -> Vec<f64> {
        match self {
            TdLearner::Dense(d) => d.traces().to_vec(),
            TdLearner::Group(g) => g.traces(),
        }
    }

    /// The previous tick's features and discount.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        match self {
            TdLearner::Dense(d) => d.previous(),
            TdLearner::Group(g) => g.previous(),
        }
    }

    /// The exact state beyond the weights and trace: the group's deferred state; `None` for the dense
    /// learner, whose weights and trace are its exact state.
    pub fn group_state(&self) -> Option<GroupState> {
        match self {
            TdLearner::Dense(_) => None,
            TdLearner::Group(g) => Some(g.state()),
        }
    }

    /// Restores a group's exact state (a dense learner takes the weights, trace and previous tick it
    /// holds: checkpoints of either kind restore into either).
    pub fn restore_group_state(
        &mut self,
        name: &str,
        state: &GroupState,
    ) -> Result<(), LearnError> {
        match self {
            TdLearner::Dense(d) => d.restore_group_state(name, state),
            TdLearner::Group(g) => g.restore_state(name, state),
        }
    }

    /// Restores the weights, trace and previous tick.
    pub fn set_dense(
        &mut self,
        weights: &[f64],
        traces: &[f64],
        previous: Option<(&[usize], f64)>,
    ) -> Result<(), LearnError> {
        match self {
            TdLearner::Dense(d) => d.set_dense(weights, traces, previous),
            TdLearner::Group(g) => g.set_dense(0, weights, traces, previous),
        }
    }
}
