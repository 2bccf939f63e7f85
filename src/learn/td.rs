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

use super::bounds::{check_alpha_positive, check_initial_weight, check_lambda};
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
    /// Checks α (finite, > 0: the learner does not know its feature count, so the bound α·‖x‖² ≤ 1 is
    /// checked where it is known, see [`super::bounds`]), λ and the initial weight; `name` labels the errors.
    pub fn validate(&self, name: &str) -> Result<(), LearnError> {
        check_alpha_positive(name, self.alpha)?;
        check_lambda(name, self.lambda)?;
        check_initial_weight(name, self.initial_weight)
    }
}

/// Why [`TdLambda::try_update`] changed nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UpdateRefused {
    /// δ_t or γ_t is not finite: a prediction that overflowed, or a non-finite cumulant or discount.
    NonFiniteInput {
        /// δ_t as computed.
        delta: f64,
    },
    /// The step would have made a weight or a trace non-finite: the learner is diverging.
    WouldDiverge {
        /// δ_t as computed.
        delta: f64,
    },
}

impl UpdateRefused {
    /// δ_t as computed.
    pub fn delta(self) -> f64 {
        match self {
            UpdateRefused::NonFiniteInput { delta } | UpdateRefused::WouldDiverge { delta } => {
                delta
            }
        }
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
    /// A refused step (see [`TdLambda::try_update`]) changes nothing and returns its δ.
    pub fn update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> f64 {
        self.try_update(x_t, gamma_t, reward_next, gamma_next, x_next)
            .unwrap_or_else(UpdateRefused::delta)
    }

    /// [`TdLambda::update`], or nothing at all when the step cannot be taken safely: when δ_t or γ_t is
    /// not finite (one bad input must not poison every weight), or when the step would make any weight
    /// or trace non-finite (a diverging learner keeps its last finite weights). The second check runs
    /// the step's arithmetic once without writing, in the same order, so it refuses exactly the steps
    /// that would produce a non-finite number; it costs one more read of the weights and traces.
    pub fn try_update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> Result<f64, UpdateRefused> {
        let sigma = self.params.sigma;
        let y_t = self.dot(x_t);
        let delta = reward_next + gamma_next * sigma.value(self.dot(x_next)) - sigma.value(y_t);
        if !delta.is_finite() || !gamma_t.is_finite() {
            return Err(UpdateRefused::NonFiniteInput { delta });
        }
        let decay = gamma_t * self.params.lambda;
        let step = self.params.alpha * delta;
        let grad = sigma.derivative(y_t);
        if !self.step_stays_finite(x_t, decay, step, grad) {
            return Err(UpdateRefused::WouldDiverge { delta });
        }
        // e ← γ_t λ e, then w ← w + αδ·(γ_t λ e) in the same pass ...
        for (w, e) in self.weights.iter_mut().zip(self.traces.iter_mut()) {
            *e *= decay;
            *w += step * *e;
        }
        // ... then the σ′(w_tᵀx_t)·x_t part of e_t, and its share of the weight change.
        for &i in x_t {
            if let (Some(e), Some(w)) = (self.traces.get_mut(i), self.weights.get_mut(i)) {
                *e += grad;
                *w += step * grad;
            }
        }
        Ok(delta)
    }

    /// Whether the step of [`TdLambda::try_update`] leaves every weight and trace finite: the same
    /// operations in the same order, without writing.
    fn step_stays_finite(&self, x_t: &[usize], decay: f64, step: f64, grad: f64) -> bool {
        let decayed = self
            .weights
            .iter()
            .zip(&self.traces)
            .all(|(&w, &e)| (e * decay).is_finite() && (w + step * (e * decay)).is_finite());
        decayed
            && x_t
                .iter()
                .all(|&i| match (self.weights.get(i), self.traces.get(i)) {
                    (Some(&w), Some(&e)) => {
                        let e1 = e * decay;
                        let w1 = w + step * e1;
                        (e1 + grad).is_finite() && (w1 + step * grad).is_finite()
                    }
                    _ => true,
                })
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

    /// Changes α (must be finite and > 0; the bound α·‖x‖² ≤ 1 is the caller's, who knows ‖x‖²); takes
    /// effect on the next update.
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        check_alpha_positive("td", alpha)?;
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
