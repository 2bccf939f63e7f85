//! [`TrueOnlineTd`] (`learner = "true_online"`): true online TD(λ) with dutch traces (van Seijen & Sutton,
//! "True Online TD(λ)", ICML 2014; the form with time-varying γ from van Seijen et al., "True Online
//! Temporal-Difference Learning", JMLR 2016, Algorithm 1). Linear output only (`sigma = "identity"`).
//!
//! For the transition from t to t + 1, with `V_old` the previous step's `w_{t−1}ᵀx_t` (0 after a break):
//!
//! ```text
//! V       = w_tᵀ x_t,   V′ = w_tᵀ x_{t+1}
//! δ_t     = R_{t+1} + γ_{t+1} V′ − V
//! e_t     = γ_t λ e_{t−1} + x_t − α γ_t λ (e_{t−1}ᵀ x_t) x_t             (the dutch trace)
//! w_{t+1} = w_t + α (δ_t + V − V_old) e_t − α (V − V_old) x_t
//! V_old   ← V′
//! ```
//!
//! With λ = 0 it is TD(0); it matches the offline λ-return algorithm exactly at every step, where the
//! accumulating trace of the paper only approximates it.

use super::super::{TdParams, UpdateRefused};
use super::dot;

/// The true online TD(λ) learner (see the module documentation), dense over its features.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueOnlineTd {
    pub(super) params: TdParams,
    pub(super) weights: Vec<f64>,
    pub(super) traces: Vec<f64>,
    /// `w_{t−1}ᵀ x_t`: the previous step's V′.
    pub(super) v_old: f64,
    next_w: Vec<f64>,
    next_e: Vec<f64>,
}

impl TrueOnlineTd {
    /// Every weight at the initial weight, a zero trace, `V_old` = 0 (the caller validated `params`).
    pub fn new(num_features: usize, params: TdParams) -> Self {
        TrueOnlineTd {
            params,
            weights: vec![params.initial_weight; num_features],
            traces: vec![0.0; num_features],
            v_old: 0.0,
            next_w: vec![0.0; num_features],
            next_e: vec![0.0; num_features],
        }
    }

    /// The weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The dutch trace.
    pub fn traces(&self) -> &[f64] {
        &self.traces
    }

    /// `V_old`: the previous step's `V′` (0 at the start).
    pub fn v_old(&self) -> f64 {
        self.v_old
    }

    /// wᵀx (linear output).
    pub fn predict(&self, active: &[usize]) -> f64 {
        dot(&self.weights, active)
    }

    /// One step for the transition t → t + 1 (the arguments as for [`super::super::TdLambda::update`]);
    /// a step whose δ is not finite, or that would make a weight or trace non-finite, changes nothing.
    pub fn try_update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> Result<f64, UpdateRefused> {
        let alpha = self.params.alpha;
        let v = dot(&self.weights, x_t);
        let v_next = dot(&self.weights, x_next);
        let delta = reward_next + gamma_next * v_next - v;
        if !delta.is_finite() || !gamma_t.is_finite() {
            return Err(UpdateRefused::NonFiniteInput { delta });
        }
        let decay = gamma_t * self.params.lambda;
        let e_dot_x = dot(&self.traces, x_t);
        let correction = alpha * decay * e_dot_x;
        let step = alpha * (delta + v - self.v_old);
        let back = alpha * (v - self.v_old);
        self.next_e.clear();
        self.next_e.extend(self.traces.iter().map(|e| e * decay));
        for &i in x_t {
            if let Some(e) = self.next_e.get_mut(i) {
                *e += 1.0 - correction;
            }
        }
        self.next_w.clear();
        self.next_w.extend(
            self.weights
                .iter()
                .zip(&self.next_e)
                .map(|(w, e)| w + step * e),
        );
        for &i in x_t {
            if let Some(w) = self.next_w.get_mut(i) {
                *w -= back;
            }
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&self.next_w) || !finite(&self.next_e) {
            return Err(UpdateRefused::WouldDiverge { delta });
        }
        std::mem::swap(&mut self.weights, &mut self.next_w);
        std::mem::swap(&mut self.traces, &mut self.next_e);
        self.v_old = v_next;
        Ok(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One transition: x_t, γ_t, R_{t+1}, γ_{t+1}, x_{t+1}.
    type Step<'a> = (&'a [usize], f64, f64, f64, &'a [usize]);
    use crate::learn::{Sigma, TdLambda};

    fn params(lambda: f64) -> TdParams {
        TdParams {
            alpha: 0.1,
            lambda,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        }
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    /// Three steps by hand, α = 0.1, λ = 0.5, γ = 0.9, weights from 0, features {0}, {1}, {0}.
    #[test]
    fn three_steps_match_the_hand_computation() {
        let mut t = TrueOnlineTd::new(2, params(0.5));
        // 1: V = 0, V′ = 0, δ = 1; e = (1, 0); w = 0.1·1·e = (0.1, 0); V_old = 0.
        assert_eq!(t.try_update(&[0], 0.9, 1.0, 0.9, &[1]).unwrap(), 1.0);
        assert!(close(&t.weights, &[0.1, 0.0]) && close(&t.traces, &[1.0, 0.0]));
        // 2: x = {1}: V = 0, V′ = w₀ = 0.1, δ = 0.9·0.1 = 0.09; eᵀx = 0, e = 0.45·(1, 0) + (0, 1) =
        // (0.45, 1); w += 0.1·(0.09 + 0 − 0)·e = (0.00405, 0.009); V_old = 0.1.
        assert!((t.try_update(&[1], 0.9, 0.0, 0.9, &[0]).unwrap() - 0.09).abs() < 1e-15);
        assert!(close(&t.traces, &[0.45, 1.0]));
        assert!(close(&t.weights, &[0.10405, 0.009]));
        assert_eq!(t.v_old, 0.1);
        // 3: x = {0}, R = 1, γ′ = 0: V = 0.10405, δ = 1 − 0.10405 = 0.89595; eᵀx = 0.45, the dutch
        // correction α·γλ·eᵀx = 0.1·0.45·0.45 = 0.02025, e = (0.45·0.45 + 1 − 0.02025, 0.45) =
        // (1.18225, 0.45); w += 0.1·(0.89595 + 0.10405 − 0.1)·e − 0.1·(0.10405 − 0.1)·(1, 0).
        assert!((t.try_update(&[0], 0.9, 1.0, 0.0, &[1]).unwrap() - 0.89595).abs() < 1e-12);
        assert!(close(&t.traces, &[1.18225, 0.45]));
        let w0 = 0.10405 + 0.09 * 1.18225 - 0.1 * 0.00405;
        let w1 = 0.009 + 0.09 * 0.45;
        assert!(close(&t.weights, &[w0, w1]), "{:?}", t.weights);
        assert!((t.v_old - 0.009).abs() < 1e-15);
    }

    #[test]
    fn with_lambda_zero_it_is_td_zero() {
        let mut t = TrueOnlineTd::new(3, params(0.0));
        let mut td = TdLambda::new(3, params(0.0)).unwrap();
        let steps: [Step; 4] = [
            (&[0, 1], 0.9, 0.0, 0.9, &[1, 2]),
            (&[1, 2], 0.9, 1.0, 0.0, &[0]),
            (&[0], 0.0, 0.0, 0.9, &[2]),
            (&[2], 0.9, 0.5, 0.9, &[0, 2]),
        ];
        for (a, g, r, g1, b) in steps {
            let (dt, dr) = (
                t.try_update(a, g, r, g1, b).unwrap(),
                td.update(a, g, r, g1, b),
            );
            assert!((dt - dr).abs() < 1e-12);
        }
        assert!(close(&t.weights, td.weights()));
    }

    #[test]
    fn a_non_finite_cumulant_changes_nothing() {
        let mut t = TrueOnlineTd::new(2, params(0.5));
        t.try_update(&[0], 0.9, 1.0, 0.9, &[1]).unwrap();
        let before = t.clone();
        assert!(t.try_update(&[0], 0.9, f64::INFINITY, 0.9, &[1]).is_err());
        assert_eq!(t, before);
    }
}
