//! Checkpoints of a [`PredictionSet`]: weights, traces, runtime parameters and the link to the previous
//! tick, as a plain serialisable struct. Restoring a snapshot into a set built from the same specs
//! continues learning exactly where the snapshot was taken.
//!
//! Take snapshots between ticks (after `learn`): a `predict` whose `learn` has not happened yet is not
//! part of the snapshot, and restoring clears it.

use serde::{Deserialize, Serialize};

use super::LearnError;
use super::set::{Chain, PredictionSet};
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
                .map(|l| PredictionSnapshot {
                    name: l.spec.name.clone(),
                    alpha: l.spec.alpha,
                    lambda: l.spec.lambda,
                    threshold: l.spec.threshold,
                    weights: l.td.weights().to_vec(),
                    traces: l.td.traces().to_vec(),
                    previous: l.chain.has_prev.then(|| PreviousStep {
                        active: l.chain.x_prev.clone(),
                        gamma: l.chain.gamma_prev,
                    }),
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

fn apply(l: &mut super::set::Learner, s: &PredictionSnapshot) -> Result<(), LearnError> {
    let name = &s.name;
    let features = l.td.num_features();
    for v in [&s.weights, &s.traces] {
        if v.len() != features {
            return Err(LearnError::FeatureCountMismatch {
                name: name.clone(),
                expected: features,
                got: v.len(),
            });
        }
    }
    if let Some(prev) = &s.previous {
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
    }
    // The runtime parameters go through the same bounds as `set_params` (α·‖x‖² ≤ 1). Both calls
    // check before they write; `restore` runs this on a copy first, so the set never half-changes.
    l.set_params(Some(s.alpha), Some(s.lambda), Some(s.threshold))?;
    l.td.set_state(&s.weights, &s.traces)
        .map_err(|_| LearnError::NonFiniteSnapshot(name.clone()))?;
    l.diverged = false;
    l.chain = match &s.previous {
        Some(prev) => Chain {
            x_prev: prev.active.clone(),
            gamma_prev: prev.gamma,
            has_prev: true,
        },
        None => Chain {
            x_prev: Vec::with_capacity(l.coder.num_tilings()),
            gamma_prev: 0.0,
            has_prev: false,
        },
    };
    l.clear_pending();
    Ok(())
}
