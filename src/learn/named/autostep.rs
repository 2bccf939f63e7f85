//! [`AutostepTd`] (`learner = "autostep"`): a step size per weight, adapted online by Autostep (Mahmood,
//! Sutton, Degris & Pilarski, "Tuning-free step-size adaptation", ICASSP 2012, Algorithm "Autostep"), on the
//! cross-entropy TD(λ) update of [`super::xent`] (with σ = identity: the paper's linear TD(λ)).
//!
//! Autostep was stated for supervised linear learning with the gradient x; here the eligibility trace e
//! takes x's place where the update uses it (as TIDBD does for IDBD, Kearney et al. 2018), and `e_i x_i`
//! takes `x_i²`'s (the change of this tick's prediction per unit step). For the transition t → t + 1, with
//! `α_i` starting at the configured α, `h_i` and `v_i` at 0, meta step size μ and timescale τ_v:
//!
//! ```text
//! δ_t  = R_{t+1} + γ_{t+1} σ(w_tᵀ x_{t+1}) − σ(w_tᵀ x_t)
//! e_t  = γ_t λ e_{t−1} + x_t
//! for every i:      g_i = δ_t e_i h_i
//!                   v_i ← max(|g_i|, v_i + (1/τ_v) α_i e_i x_i (|g_i| − v_i))
//! where e_i ≠ 0 and v_i > 0:  α_i ← α_i exp(μ g_i / v_i)
//! M    = max(Σ_i α_i e_i x_i, 1);   α_i ← α_i / M   (for every i: the step never overshoots this tick's target)
//! w_i  ← w_i + α_i δ_t e_i
//! h_i  ← h_i (1 − α_i e_i x_i) + α_i δ_t e_i
//! ```
//!
//! μ = [`META_STEP`] and τ_v = [`TAU_V`] are the values Mahmood et al. recommend (10⁻² and 10⁴).

use super::super::{TdParams, UpdateRefused};
use super::dot;

/// The meta step size μ (Mahmood et al. 2012: 10⁻²).
pub const META_STEP: f64 = 0.01;
/// The timescale τ_v of the normaliser v (Mahmood et al. 2012: 10⁴).
pub const TAU_V: f64 = 10_000.0;

/// The Autostep TD(λ) learner (see the module documentation), dense over its features.
#[derive(Debug, Clone, PartialEq)]
pub struct AutostepTd {
    pub(super) params: TdParams,
    pub(super) weights: Vec<f64>,
    pub(super) traces: Vec<f64>,
    /// The step size of each weight.
    pub(super) alphas: Vec<f64>,
    /// The trace of recent weight changes h.
    pub(super) h: Vec<f64>,
    /// The normaliser v.
    pub(super) v: Vec<f64>,
    meta_step: f64,
    tau_v: f64,
}

impl AutostepTd {
    /// Every weight at the initial weight, every step size at α, zero traces (the caller validated
    /// `params`), with μ = [`META_STEP`] and τ_v = [`TAU_V`].
    pub fn new(num_features: usize, params: TdParams) -> Self {
        Self::with_meta(num_features, params, META_STEP, TAU_V)
    }

    /// The same with the meta step size μ and the timescale τ_v given.
    pub fn with_meta(num_features: usize, params: TdParams, meta_step: f64, tau_v: f64) -> Self {
        AutostepTd {
            params,
            weights: vec![params.initial_weight; num_features],
            traces: vec![0.0; num_features],
            alphas: vec![params.alpha; num_features],
            h: vec![0.0; num_features],
            v: vec![0.0; num_features],
            meta_step,
            tau_v,
        }
    }

    /// σ(wᵀx).
    pub fn predict(&self, active: &[usize]) -> f64 {
        self.params.sigma.value(dot(&self.weights, active))
    }

    /// The weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The eligibility trace.
    pub fn traces(&self) -> &[f64] {
        &self.traces
    }

    /// The step sizes α_i.
    pub fn alphas(&self) -> &[f64] {
        &self.alphas
    }

    /// One step for the transition t → t + 1 (the arguments as for [`super::super::TdLambda::update`]);
    /// a step whose δ is not finite, or that would make a number non-finite, changes nothing.
    pub fn try_update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> Result<f64, UpdateRefused> {
        let sigma = self.params.sigma;
        let delta = reward_next + gamma_next * sigma.value(dot(&self.weights, x_next))
            - sigma.value(dot(&self.weights, x_t));
        if !delta.is_finite() || !gamma_t.is_finite() {
            return Err(UpdateRefused::NonFiniteInput { delta });
        }
        let before = self.clone();
        let decay = gamma_t * self.params.lambda;
        let x = |i: usize| if x_t.contains(&i) { 1.0 } else { 0.0 };
        for e in &mut self.traces {
            *e *= decay;
        }
        for &i in x_t {
            if let Some(e) = self.traces.get_mut(i) {
                *e += 1.0;
            }
        }
        for i in 0..self.weights.len() {
            let e = self.traces[i];
            let g = delta * e * self.h[i];
            let v = &mut self.v[i];
            *v = g
                .abs()
                .max(*v + self.alphas[i] * e * x(i) * (g.abs() - *v) / self.tau_v);
            if e != 0.0 && *v > 0.0 {
                self.alphas[i] *= (self.meta_step * g / *v).exp();
            }
        }
        let m = x_t
            .iter()
            .filter_map(|&i| Some(self.alphas.get(i)? * self.traces.get(i)?))
            .sum::<f64>()
            .max(1.0);
        for i in 0..self.weights.len() {
            let a = self.alphas[i] / m;
            self.alphas[i] = a;
            let e = self.traces[i];
            self.weights[i] += a * delta * e;
            self.h[i] = self.h[i] * (1.0 - a * e * x(i)) + a * delta * e;
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if ![&self.weights, &self.traces, &self.alphas, &self.h, &self.v]
            .iter()
            .all(|v| finite(v))
        {
            *self = before;
            return Err(UpdateRefused::WouldDiverge { delta });
        }
        Ok(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::Sigma;

    fn params(alpha: f64) -> TdParams {
        TdParams {
            alpha,
            lambda: 0.0,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        }
    }

    /// Two steps by hand: feature {0} twice with R = 1 and γ_{t+1} = 0, α = 0.1, λ = 0, τ_v = 2.
    #[test]
    fn two_steps_match_the_hand_computation() {
        let mut a = AutostepTd::with_meta(2, params(0.1), 0.01, 2.0);
        // 1: δ = 1, e = (1, 0), h = 0 so g = 0 and v stays 0: α unchanged; M = max(0.1, 1) = 1;
        // w₀ = 0.1, h₀ = 0.1.
        assert_eq!(a.try_update(&[0], 0.9, 1.0, 0.0, &[1]).unwrap(), 1.0);
        assert_eq!(
            (a.weights[0], a.h[0], a.alphas[0], a.v[0]),
            (0.1, 0.1, 0.1, 0.0)
        );
        // 2: δ = 1 − 0.1 = 0.9, g = 0.9·1·0.1 = 0.09, v₀ = max(0.09, 0 + 0.1·(0.09 − 0)/2) = 0.09,
        // α₀ = 0.1·e^{0.01·0.09/0.09} = 0.1·e^{0.01}; M = 1; w₀ = 0.1 + α₀·0.9;
        // h₀ = 0.1·(1 − α₀) + α₀·0.9.
        let d = a.try_update(&[0], 0.9, 1.0, 0.0, &[1]).unwrap();
        assert!((d - 0.9).abs() < 1e-15);
        let alpha = 0.1 * 0.01_f64.exp();
        assert!((a.v[0] - 0.09).abs() < 1e-15);
        assert!((a.alphas[0] - alpha).abs() < 1e-15);
        assert!((a.weights[0] - (0.1 + alpha * 0.9)).abs() < 1e-15);
        assert!((a.h[0] - (0.1 * (1.0 - alpha) + alpha * 0.9)).abs() < 1e-15);
        // The inactive weight never moved.
        assert_eq!((a.weights[1], a.alphas[1], a.h[1]), (0.0, 0.1, 0.0));
    }

    #[test]
    fn the_normaliser_keeps_the_effective_step_at_most_one() {
        // Two active features with α = 0.6 each: Σ α_i e_i x_i = 1.2, so both become 0.5 and the
        // prediction moves exactly to its target.
        let mut a = AutostepTd::new(2, params(0.6));
        let d = a.try_update(&[0, 1], 0.9, 1.0, 0.0, &[]).unwrap();
        assert_eq!(d, 1.0);
        assert_eq!(a.alphas(), &[0.5, 0.5]);
        assert_eq!(a.weights, vec![0.5, 0.5]);
        assert_eq!(a.predict(&[0, 1]), 1.0);
    }

    #[test]
    fn a_non_finite_cumulant_changes_nothing() {
        let mut a = AutostepTd::new(2, params(0.1));
        let before = a.clone();
        assert!(a.try_update(&[0], 0.9, f64::NAN, 0.0, &[1]).is_err());
        assert_eq!(a, before);
    }
}
