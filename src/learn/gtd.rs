//! [`Gtd`]: off-policy prediction learning with GTD(λ), the gradient-TD algorithm with a secondary
//! weight vector, linear in binary features given as lists of active indices.
//!
//! The algorithm is GTD(λ) of Maei's thesis (\[GTD\] in `docs/SOURCES.md`: H. R. Maei, *Gradient
//! Temporal-Difference Learning Algorithms*, PhD thesis, University of Alberta, 2011, ch. 6, "GTD(λ)"),
//! the λ-extension of TDC (Sutton, Maei et al., ICML 2009), in the state-dependent-γ form the Horde
//! architecture ran on a robot (Sutton et al., AAMAS 2011, its equations for GTD(λ)). For the transition
//! from t to t + 1, with the same index convention as [`super::td`] (δ_t reads R_{t+1}, γ_{t+1} and
//! x_{t+1}; the trace decays with γ_t):
//!
//! ```text
//! ρ_t     = π(A_t|S_t) / b(A_t|S_t)                         importance sampling ratio of the action taken
//! δ_t     = R_{t+1} + γ_{t+1} θ_tᵀ x_{t+1} − θ_tᵀ x_t
//! e_t     = ρ_t (γ_t λ e_{t−1} + x_t)
//! θ_{t+1} = θ_t + α (δ_t e_t − γ_{t+1} (1 − λ) (e_tᵀ w_t) x_{t+1})
//! w_{t+1} = w_t + β (δ_t e_t − (w_tᵀ x_t) x_t)
//! ```
//!
//! θ are the primary weights (the prediction is `v = θᵀx`), w the secondary weights (an estimate of the
//! expected TD update's projection, `E[x xᵀ]⁻¹ E[δ e]`), α and β their step sizes. Where ρ_t = 0 (the
//! action taken is one π never takes) the trace is cut to zero and θ does not move; w still decays along
//! x_t. With ρ ≡ 1 and w ≡ 0 the θ update is the paper's linear TD(λ).
//!
//! Only the linear form: the convergent nonlinear GTD (Maei et al., NIPS 2009) needs a Hessian–vector
//! product term for σ(θᵀx), which is not implemented, so a GTD prediction must use σ = identity (the
//! configuration says so, [`super::spec`]). Convergence of GTD(λ) to the λ-projected fixed point under
//! the target policy holds for a stationary behaviour policy with α, β small enough (β of the order of
//! α, or larger, in practice); a Pavlovian behaviour that depends on the learned prediction is not
//! stationary, which the stall study's section of `docs/src/results.md` discusses.
//!
//! The weights, traces and secondary weights are dense `f64` vectors: the paper's sizes (440 features)
//! make a dense step a few microseconds. A step is computed into scratch vectors and committed only if
//! every number stays finite, so a diverging learner keeps its last finite state (as [`super::td`]).

use super::LearnError;
use super::bounds::{check_alpha_positive, check_initial_weight, check_lambda, out_of_bounds};
use super::td::UpdateRefused;

/// The learning parameters of one GTD(λ) learner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GtdParams {
    /// Primary step size α (> 0).
    pub alpha: f64,
    /// Secondary step size β (> 0, and β·‖x‖² ≤ 1 where ‖x‖² is known: [`check_beta`]).
    pub beta: f64,
    /// Bootstrapping parameter λ in `[0, 1]`.
    pub lambda: f64,
    /// The value every primary weight starts from (secondary weights start at 0).
    pub initial_weight: f64,
}

/// β finite and > 0, the part of its bound that needs no feature count.
pub fn check_beta_positive(name: &str, beta: f64) -> Result<(), LearnError> {
    if beta.is_finite() && beta > 0.0 {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "beta",
            beta,
            "is not a finite number > 0".into(),
        ))
    }
}

/// β·‖x‖² ≤ 1 with `active` active binary features: the secondary update `w ← w − β (wᵀx) x` shrinks
/// `wᵀx` by the factor `1 − β‖x‖²`, which overshoots (and then diverges) beyond 2 and oscillates beyond
/// 1; the same bound as α's.
pub fn check_beta(name: &str, beta: f64, active: usize) -> Result<(), LearnError> {
    check_beta_positive(name, beta)?;
    let max = 1.0 / active.max(1) as f64;
    if beta <= max * (1.0 + 1e-12) {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "beta",
            beta,
            format!("exceeds 1/{active} = {max:.4} (β·‖x‖² ≤ 1 with {active} active features)"),
        ))
    }
}

impl GtdParams {
    /// Checks α, β, λ and the initial weight; `name` labels the errors.
    pub fn validate(&self, name: &str) -> Result<(), LearnError> {
        check_alpha_positive(name, self.alpha)?;
        check_beta_positive(name, self.beta)?;
        check_lambda(name, self.lambda)?;
        check_initial_weight(name, self.initial_weight)
    }
}

/// One GTD(λ) learner over `num_features` binary features (see the module documentation).
///
/// Active-index lists are assumed to hold distinct indices; an index beyond `num_features` is ignored.
/// Two learners are equal when their parameters, θ, w and e are (the scratch space is not compared).
#[derive(Debug, Clone)]
pub struct Gtd {
    params: GtdParams,
    theta: Vec<f64>,
    secondary: Vec<f64>,
    traces: Vec<f64>,
    scratch_theta: Vec<f64>,
    scratch_secondary: Vec<f64>,
    scratch_traces: Vec<f64>,
}

impl PartialEq for Gtd {
    fn eq(&self, other: &Self) -> bool {
        self.params == other.params
            && self.theta == other.theta
            && self.secondary == other.secondary
            && self.traces == other.traces
    }
}

fn dot(v: &[f64], active: &[usize]) -> f64 {
    active.iter().filter_map(|&i| v.get(i)).sum()
}

impl Gtd {
    /// A learner with every primary weight at `params.initial_weight`, zero secondary weights and a
    /// zero trace.
    pub fn new(num_features: usize, params: GtdParams) -> Result<Self, LearnError> {
        params.validate("gtd")?;
        Ok(Gtd {
            params,
            theta: vec![params.initial_weight; num_features],
            secondary: vec![0.0; num_features],
            traces: vec![0.0; num_features],
            scratch_theta: vec![0.0; num_features],
            scratch_secondary: vec![0.0; num_features],
            scratch_traces: vec![0.0; num_features],
        })
    }

    /// The prediction `v = θᵀx` for the binary `x` whose active indices are `active`.
    #[inline]
    pub fn predict(&self, active: &[usize]) -> f64 {
        dot(&self.theta, active)
    }

    /// One GTD(λ) step for the transition t → t + 1 (module documentation): `x_t`, `gamma_t` and `rho_t`
    /// are the features, discount and importance sampling ratio of step t, `reward_next`, `gamma_next`
    /// and `x_next` the cumulant R_{t+1}, discount γ_{t+1} and features x_{t+1}. Returns δ_t.
    ///
    /// Changes nothing when δ_t, γ_t or ρ_t is not finite or ρ_t < 0 (`NonFiniteInput`), or when the
    /// step would make any number non-finite (`WouldDiverge`).
    pub fn try_update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        rho_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> Result<f64, UpdateRefused> {
        let GtdParams {
            alpha,
            beta,
            lambda,
            ..
        } = self.params;
        let delta = reward_next + gamma_next * self.predict(x_next) - self.predict(x_t);
        if !delta.is_finite() || !gamma_t.is_finite() || !rho_t.is_finite() || rho_t < 0.0 {
            return Err(UpdateRefused::NonFiniteInput { delta });
        }
        let h_x = dot(&self.secondary, x_t);
        // e_t = ρ_t (γ_t λ e_{t−1} + x_t); e_tᵀw_t.
        let decay = gamma_t * lambda;
        for (new, &old) in self.scratch_traces.iter_mut().zip(&self.traces) {
            *new = rho_t * decay * old;
        }
        for &i in x_t {
            if let Some(e) = self.scratch_traces.get_mut(i) {
                *e += rho_t;
            }
        }
        let e_w: f64 = self
            .scratch_traces
            .iter()
            .zip(&self.secondary)
            .map(|(e, w)| e * w)
            .sum();
        // θ_{t+1} = θ_t + α δ e_t − α γ_{t+1} (1 − λ) (e_tᵀw_t) x_{t+1}.
        let correction = alpha * gamma_next * (1.0 - lambda) * e_w;
        for ((new, &old), &e) in self
            .scratch_theta
            .iter_mut()
            .zip(&self.theta)
            .zip(&self.scratch_traces)
        {
            *new = old + alpha * delta * e;
        }
        for &i in x_next {
            if let Some(t) = self.scratch_theta.get_mut(i) {
                *t -= correction;
            }
        }
        // w_{t+1} = w_t + β δ e_t − β (w_tᵀx_t) x_t.
        for ((new, &old), &e) in self
            .scratch_secondary
            .iter_mut()
            .zip(&self.secondary)
            .zip(&self.scratch_traces)
        {
            *new = old + beta * delta * e;
        }
        for &i in x_t {
            if let Some(w) = self.scratch_secondary.get_mut(i) {
                *w -= beta * h_x;
            }
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(e_w.is_finite()
            && finite(&self.scratch_traces)
            && finite(&self.scratch_theta)
            && finite(&self.scratch_secondary))
        {
            return Err(UpdateRefused::WouldDiverge { delta });
        }
        std::mem::swap(&mut self.theta, &mut self.scratch_theta);
        std::mem::swap(&mut self.secondary, &mut self.scratch_secondary);
        std::mem::swap(&mut self.traces, &mut self.scratch_traces);
        Ok(delta)
    }

    /// The learning parameters.
    pub fn params(&self) -> GtdParams {
        self.params
    }

    /// The number of features.
    pub fn num_features(&self) -> usize {
        self.theta.len()
    }

    /// The primary weights θ.
    pub fn weights(&self) -> &[f64] {
        &self.theta
    }

    /// The secondary weights w.
    pub fn secondary(&self) -> &[f64] {
        &self.secondary
    }

    /// The eligibility trace e.
    pub fn traces(&self) -> &[f64] {
        &self.traces
    }

    /// Changes α (finite, > 0; the bound α·‖x‖² ≤ 1 is the caller's).
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        check_alpha_positive("gtd", alpha)?;
        self.params.alpha = alpha;
        Ok(())
    }

    /// Changes λ (in `[0, 1]`).
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        check_lambda("gtd", lambda)?;
        self.params.lambda = lambda;
        Ok(())
    }

    /// Changes β (finite, > 0; the bound β·‖x‖² ≤ 1 is the caller's).
    pub fn set_beta(&mut self, beta: f64) -> Result<(), LearnError> {
        check_beta_positive("gtd", beta)?;
        self.params.beta = beta;
        Ok(())
    }

    /// Zeroes the eligibility trace.
    pub fn clear_traces(&mut self) {
        self.traces.fill(0.0);
    }

    /// Back to the initial primary weights, zero secondary weights and a zero trace.
    pub fn reset(&mut self) {
        self.theta.fill(self.params.initial_weight);
        self.secondary.fill(0.0);
        self.clear_traces();
    }

    /// Replaces θ, w and e (restoring a checkpoint): each must have `num_features()` finite entries;
    /// on error nothing changes.
    pub fn set_state(
        &mut self,
        name: &str,
        theta: &[f64],
        secondary: &[f64],
        traces: &[f64],
    ) -> Result<(), LearnError> {
        for v in [theta, secondary, traces] {
            if v.len() != self.theta.len() {
                return Err(LearnError::FeatureCountMismatch {
                    name: name.to_string(),
                    expected: self.theta.len(),
                    got: v.len(),
                });
            }
            if !v.iter().all(|x| x.is_finite()) {
                return Err(LearnError::NonFiniteSnapshot(name.to_string()));
            }
        }
        self.theta.copy_from_slice(theta);
        self.secondary.copy_from_slice(secondary);
        self.traces.copy_from_slice(traces);
        Ok(())
    }
}

mod chain;
pub use chain::GtdChain;

#[cfg(test)]
mod tests;
