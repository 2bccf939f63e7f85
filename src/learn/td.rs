//! [`TdLambda`]: TD(λ) with accumulating traces and an output nonlinearity σ, exactly as in Modayil &
//! Sutton, over sparse binary features given as lists of active indices.
//!
//! The paper's update, for the transition from time t to t + 1:
//!
//! ```text
//! δ_t     = R_{t+1} + γ_{t+1} σ(w_tᵀ x_{t+1}) − σ(w_tᵀ x_t)
//! e_t     = γ_t λ e_{t−1} + σ′(w_tᵀ x_t) x_t
//! w_{t+1} = w_t + α δ_t e_t
//! ```
//!
//! Note the indices: δ_t uses the cumulant, discount and features of the *next* step (R_{t+1}, γ_{t+1},
//! x_{t+1}), while the trace decays with the discount of the *current* step γ_t. So a step with γ_t = 0
//! (the stimulus was observed at t) both stops bootstrapping from x_t in δ_{t−1} and wipes the trace
//! before x_t is added to it: predictions never look through a stimulus event.
//!
//! [`TdLambda::update`] takes exactly those five quantities. The weights and traces are dense `f64`
//! vectors (the paper's sizes are 440 and 500 features, where a sparse trace would not pay: with
//! λ = 0.5 and 44 active features the trace covers every feature within a few steps).

use super::{LearnError, Sigma};

/// The learning parameters of one TD(λ) learner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TdParams {
    /// Step size α (> 0). The paper used α = 1/44 with 44 active features and α = 0.1/5 with 5.
    pub alpha: f64,
    /// Bootstrapping parameter λ in `[0, 1]`.
    pub lambda: f64,
    /// The output nonlinearity.
    pub sigma: Sigma,
    /// The value every weight starts from (and returns to on [`TdLambda::reset`]).
    pub initial_weight: f64,
}

impl TdParams {
    /// Checks α, λ and the initial weight; `name` labels the errors.
    pub fn validate(&self, name: &str) -> Result<(), LearnError> {
        check_alpha(name, self.alpha)?;
        check_lambda(name, self.lambda)?;
        if !self.initial_weight.is_finite() {
            return Err(LearnError::InvalidInitialWeight {
                name: name.to_string(),
                value: self.initial_weight,
            });
        }
        Ok(())
    }
}

pub(crate) fn check_alpha(name: &str, alpha: f64) -> Result<(), LearnError> {
    if alpha.is_finite() && alpha > 0.0 {
        Ok(())
    } else {
        Err(LearnError::InvalidAlpha {
            name: name.to_string(),
            alpha,
        })
    }
}

pub(crate) fn check_lambda(name: &str, lambda: f64) -> Result<(), LearnError> {
    if (0.0..=1.0).contains(&lambda) {
        Ok(())
    } else {
        Err(LearnError::InvalidLambda {
            name: name.to_string(),
            lambda,
        })
    }
}

/// One TD(λ) learner: a weight vector and an eligibility trace over `num_features` binary features.
///
/// Active-index lists are assumed to hold distinct indices (a tile coder guarantees it); an index
/// beyond `num_features` is ignored rather than trusted.
#[derive(Debug, Clone, PartialEq)]
pub struct TdLambda {
    params: TdParams,
    weights: Vec<f64>,
    traces: Vec<f64>,
}

impl TdLambda {
    /// A learner with every weight at `params.initial_weight` and a zero trace.
    pub fn new(num_features: usize, params: TdParams) -> Result<Self, LearnError> {
        params.validate("td")?;
        Ok(TdLambda {
            params,
            weights: vec![params.initial_weight; num_features],
            traces: vec![0.0; num_features],
        })
    }

    /// `wᵀx` for the binary `x` whose active indices are `active`.
    #[inline]
    pub fn dot(&self, active: &[usize]) -> f64 {
        active.iter().filter_map(|&i| self.weights.get(i)).sum()
    }

    /// The prediction `v = σ(wᵀx)`.
    #[inline]
    pub fn predict(&self, active: &[usize]) -> f64 {
        self.params.sigma.value(self.dot(active))
    }

    /// One TD(λ) step for the transition t → t + 1 (see the module documentation):
    /// `x_t` and `gamma_t` are the features and discount of step t, `reward_next`, `gamma_next` and
    /// `x_next` the cumulant R_{t+1}, discount γ_{t+1} and features x_{t+1}. Returns δ_t.
    ///
    /// If δ_t or γ_t is not finite (a NaN cumulant or discount), nothing changes and the non-finite δ
    /// is returned: one bad input must not poison every weight.
    pub fn update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> f64 {
        let sigma = self.params.sigma;
        let y_t = self.dot(x_t);
        let delta = reward_next + gamma_next * sigma.value(self.dot(x_next)) - sigma.value(y_t);
        if !delta.is_finite() || !gamma_t.is_finite() {
            return delta;
        }
        let decay = gamma_t * self.params.lambda;
        let step = self.params.alpha * delta;
        // e ← γ_t λ e, then w ← w + αδ·(γ_t λ e) in the same pass ...
        for (w, e) in self.weights.iter_mut().zip(self.traces.iter_mut()) {
            *e *= decay;
            *w += step * *e;
        }
        // ... then the σ′(w_tᵀx_t)·x_t part of e_t, and its share of the weight change.
        let grad = sigma.derivative(y_t);
        for &i in x_t {
            if let (Some(e), Some(w)) = (self.traces.get_mut(i), self.weights.get_mut(i)) {
                *e += grad;
                *w += step * grad;
            }
        }
        delta
    }

    /// The learning parameters.
    pub fn params(&self) -> TdParams {
        self.params
    }

    /// The number of features.
    pub fn num_features(&self) -> usize {
        self.weights.len()
    }

    /// The weight vector w.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The eligibility trace e.
    pub fn traces(&self) -> &[f64] {
        &self.traces
    }

    /// Changes α (must be finite and > 0); takes effect on the next update.
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        check_alpha("td", alpha)?;
        self.params.alpha = alpha;
        Ok(())
    }

    /// Changes λ (must be in `[0, 1]`); takes effect on the next update.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        check_lambda("td", lambda)?;
        self.params.lambda = lambda;
        Ok(())
    }

    /// Zeroes the eligibility trace (the next update starts a fresh chain of credit).
    pub fn clear_traces(&mut self) {
        self.traces.fill(0.0);
    }

    /// Back to the initial weights with a zero trace.
    pub fn reset(&mut self) {
        self.weights.fill(self.params.initial_weight);
        self.clear_traces();
    }

    /// Replaces weights and traces (for restoring a checkpoint). Both must have `num_features()`
    /// finite entries; on error nothing changes.
    pub fn set_state(&mut self, weights: &[f64], traces: &[f64]) -> Result<(), LearnError> {
        for v in [weights, traces] {
            if v.len() != self.weights.len() {
                return Err(LearnError::FeatureCountMismatch {
                    name: "td".to_string(),
                    expected: self.weights.len(),
                    got: v.len(),
                });
            }
            if !v.iter().all(|x| x.is_finite()) {
                return Err(LearnError::NonFiniteSnapshot("td".to_string()));
            }
        }
        self.weights.copy_from_slice(weights);
        self.traces.copy_from_slice(traces);
        Ok(())
    }
}

#[cfg(test)]
mod tests;
