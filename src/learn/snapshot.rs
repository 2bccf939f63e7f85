//! Checkpoints of a [`PredictionSet`]: weights, traces, runtime parameters and the link to the previous
//! tick, as a plain serialisable struct. Restoring a snapshot into a set built from the same specs
//! continues learning exactly where the snapshot was taken.
//!
//! Each prediction is written twice: densely (`weights`, `traces`, `previous`: what a reader of the file
//! wants, and all that earlier versions wrote) and as its learner's exact state (`state`, a
//! [`GroupState`]). Restoring uses `state` when it is there, so a resumed run or a replay continues bit
//! for bit; it first checks that `state` and the dense form agree, so a file edited by hand in one place
//! is refused rather than half-believed. A snapshot without `state` (an earlier version's) restores from
//! the dense form, which continues the run to rounding.
//!
//! An off-policy (GTD(λ)) prediction has no deferred state: its dense `weights` (θ), `traces` and
//! `previous` are exact, and its secondary weights w and step size β are written beside them
//! (`secondary`, `beta`), so it too continues bit for bit.
//!
//! Take snapshots between ticks (after `learn`): a `predict` whose `learn` has not happened yet is not
//! part of the snapshot, and restoring clears it.

use serde::{Deserialize, Serialize};

use super::LearnError;
use super::group::GroupState;
use super::set::{Engine, PredictionSet};
use super::spec::Threshold;

/// The learned state of one prediction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictionSnapshot {
    pub name: String,
    pub alpha: f64,
    pub lambda: f64,
    pub threshold: Threshold,
    pub weights: Vec<f64>,
    pub traces: Vec<f64>,
    /// The previous tick's active features and discount, if there was one.
    pub previous: Option<PreviousStep>,
    /// The learner's exact state (see the module documentation); absent in earlier versions' files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<GroupState>,
    /// An off-policy prediction's secondary weights w (GTD(λ)); absent for on-policy ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub secondary: Option<Vec<f64>>,
    /// An off-policy prediction's secondary step size β; absent for on-policy ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beta: Option<f64>,
    /// A named learner's state beyond weights and trace (`learner = "true_online"`: `[V_old]`;
    /// `"autostep"`: the step sizes, h and v; [`super::named::Named::aux`]); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aux: Option<Vec<f64>>,
}

/// The previous tick, which the next `learn` learns from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreviousStep {
    pub active: Vec<usize>,
    pub gamma: f64,
}

/// The learned state of a whole set, in set order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetSnapshot {
    pub predictions: Vec<PredictionSnapshot>,
}

impl PredictionSet {
    /// The current learned state.
    pub fn snapshot(&self) -> SetSnapshot {
        SetSnapshot {
            predictions: self
                .learners
                .iter()
                .map(|l| match &l.engine {
                    Engine::Td(group) => PredictionSnapshot {
                        name: l.spec.name.clone(),
                        alpha: l.spec.alpha,
                        lambda: l.spec.lambda,
                        threshold: l.spec.threshold,
                        weights: group.weights(),
                        traces: group.traces(),
                        previous: group.previous().map(|(active, gamma)| PreviousStep {
                            active: active.to_vec(),
                            gamma,
                        }),
                        state: group.group_state(),
                        secondary: None,
                        beta: None,
                        aux: None,
                    },
                    Engine::Gtd(chain) => PredictionSnapshot {
                        name: l.spec.name.clone(),
                        alpha: l.spec.alpha,
                        lambda: l.spec.lambda,
                        threshold: l.spec.threshold,
                        weights: chain.gtd().weights().to_vec(),
                        traces: chain.gtd().traces().to_vec(),
                        previous: chain.previous().map(|(active, gamma)| PreviousStep {
                            active: active.to_vec(),
                            gamma,
                        }),
                        state: None,
                        secondary: Some(chain.gtd().secondary().to_vec()),
                        beta: Some(chain.gtd().params().beta),
                        aux: None,
                    },
                    Engine::Named(chain) => PredictionSnapshot {
                        name: l.spec.name.clone(),
                        alpha: l.spec.alpha,
                        lambda: l.spec.lambda,
                        threshold: l.spec.threshold,
                        weights: chain.learner().weights().to_vec(),
                        traces: chain.learner().traces().to_vec(),
                        previous: chain.previous().map(|(active, gamma)| PreviousStep {
                            active: active.to_vec(),
                            gamma,
                        }),
                        state: None,
                        secondary: None,
                        beta: None,
                        aux: chain.learner().aux(),
                    },
                })
                .collect(),
        }
    }

    /// Restores `snapshot`, which must hold the same predictions in the same order with the same
    /// feature counts. Everything is checked before anything changes: on error the set is untouched.
    pub fn restore(&mut self, snapshot: &SetSnapshot) -> Result<(), LearnError> {
        if snapshot.predictions.len() != self.learners.len() {
            return Err(LearnError::SnapshotCountMismatch {
                expected: self.learners.len(),
                got: snapshot.predictions.len(),
            });
        }
        for (l, s) in self.learners.iter().zip(&snapshot.predictions) {
            if l.spec.name != s.name {
                return Err(LearnError::UnknownPrediction(s.name.clone()));
            }
            let mut probe = l.clone();
            apply(&mut probe, s)?;
        }
        for (l, s) in self.learners.iter_mut().zip(&snapshot.predictions) {
            apply(l, s)?;
        }
        Ok(())
    }
}

/// How far the exact state's weights and traces may be from the dense ones written beside it: they are
/// the same numbers, the dense ones computed from the state (a relative 1e-9 leaves room for the sum
/// of the deferred parts, never for an edit).
const AGREEMENT: f64 = 1e-9;

fn agrees(dense: &[f64], exact: &[f64]) -> bool {
    dense.len() == exact.len()
        && dense
            .iter()
            .zip(exact)
            .all(|(a, b)| (a - b).abs() <= AGREEMENT * a.abs().max(b.abs()).max(1.0))
}

fn apply(l: &mut super::set::Learner, s: &PredictionSnapshot) -> Result<(), LearnError> {
    let name = &s.name;
    let features = l.coder.num_features();
    for v in [&s.weights, &s.traces] {
        if v.len() != features {
            return Err(LearnError::FeatureCountMismatch {
                name: name.clone(),
                expected: features,
                got: v.len(),
            });
        }
    }
    let previous = match &s.previous {
        Some(prev) => {
            if let Some(&index) = prev.active.iter().find(|&&i| i >= features) {
                return Err(LearnError::SnapshotIndexOutOfRange {
                    name: name.clone(),
                    index,
                    features,
                });
            }
            if !prev.gamma.is_finite() {
                return Err(LearnError::NonFiniteSnapshot(name.clone()));
            }
            Some((&prev.active[..], prev.gamma))
        }
        None => None,
    };
    // The runtime parameters go through the same bounds as `set_params` (α·‖x‖² ≤ 1). Both calls
    // check before they write; `restore` runs this on a copy first, so the set never half-changes.
    l.set_params(Some(s.alpha), Some(s.lambda), Some(s.threshold))?;
    if s.aux.is_some() && !matches!(l.engine, Engine::Named(_)) {
        return Err(LearnError::BadGroupState {
            name: name.clone(),
            what: "has a named learner's state (`aux`), but the prediction's learner keeps none"
                .into(),
        });
    }
    let group = match &mut l.engine {
        Engine::Td(group) => {
            if s.secondary.is_some() || s.beta.is_some() {
                return Err(LearnError::BadGroupState {
                    name: name.clone(),
                    what: "has secondary weights (GTD(λ)), but the prediction is on-policy TD(λ)"
                        .into(),
                });
            }
            group
        }
        Engine::Gtd(chain) => {
            let (Some(secondary), Some(beta)) = (&s.secondary, s.beta) else {
                return Err(LearnError::BadGroupState {
                    name: name.clone(),
                    what: "has no secondary weights or beta, but the prediction is off-policy \
                           (learner = \"gtd\")"
                        .into(),
                });
            };
            if s.state.is_some() {
                return Err(LearnError::BadGroupState {
                    name: name.clone(),
                    what: "has a TD(λ) group state, but the prediction is off-policy (learner = \"gtd\")"
                        .into(),
                });
            }
            super::gtd::check_beta(name, beta, l.bounds.active_features)?;
            chain.gtd_mut().set_beta(beta)?;
            chain.restore(name, &s.weights, secondary, &s.traces, previous)?;
            l.spec.beta = Some(beta);
            l.clear_pending();
            return Ok(());
        }
        Engine::Named(chain) => {
            if s.state.is_some() || s.secondary.is_some() || s.beta.is_some() {
                return Err(LearnError::BadGroupState {
                    name: name.clone(),
                    what: format!(
                        "has a TD(λ) group state or secondary weights, but the prediction's learner is \"{}\"",
                        l.spec.learner.name()
                    ),
                });
            }
            chain.restore(name, &s.weights, &s.traces, s.aux.as_deref(), previous)?;
            l.clear_pending();
            return Ok(());
        }
    };
    match &s.state {
        Some(state) => {
            let same_params = state.alphas == [s.alpha] && state.lambda == s.lambda;
            let same_previous = state.x_prev.as_deref()
                == s.previous.as_ref().map(|p| &p.active[..])
                && s.previous
                    .as_ref()
                    .is_none_or(|p| p.gamma == state.gamma_prev);
            group.restore_group_state(name, state)?;
            let consistent = same_params
                && same_previous
                && agrees(&s.weights, &group.weights())
                && agrees(&s.traces, &group.traces());
            if !consistent {
                return Err(LearnError::BadGroupState {
                    name: name.clone(),
                    what: "disagrees with the weights, traces, parameters or previous step written \
                           beside it (after editing those by hand, remove `state` to restore from them)"
                        .into(),
                });
            }
        }
        None => group
            .set_dense(&s.weights, &s.traces, previous)
            .map_err(|_| LearnError::NonFiniteSnapshot(name.clone()))?,
    }
    l.clear_pending();
    Ok(())
}
