//! [`XentTd`] (`learner = "xent"`): TD(λ) with the cross-entropy (log-loss) gradient of a logistic output —
//! the paper's update without σ′ in the trace, keeping σ, the initial weight, α and the features.
//!
//! For a logistic output `v = σ(wᵀx)` and a target `z` in `[0, 1]`, the log loss
//! `L = −z log v − (1 − z) log(1 − v)` has the gradient `∂L/∂w = −(z − v) x`: the σ′ of the squared error's
//! gradient `−(z − v) σ′(wᵀx) x` cancels against the derivative of the logarithm (the gradient of logistic
//! regression). With the TD target `z = R_{t+1} + γ_{t+1} σ(w_tᵀx_{t+1})` and an eligibility trace, for the
//! transition from t to t + 1:
//!
//! ```text
//! δ_t     = R_{t+1} + γ_{t+1} σ(w_tᵀ x_{t+1}) − σ(w_tᵀ x_t)      (as in the paper)
//! e_t     = γ_t λ e_{t−1} + x_t                                  (the paper: + σ′(w_tᵀ x_t) x_t)
//! w_{t+1} = w_t + α δ_t e_t
//! ```
//!
//! Why it matters here: with every weight at −1 over 5 active features, σ′(−5) ≈ 0.0066, so the paper's
//! trace moves the prediction about 150 times less per command than this one does; away from the
//! saturated ends the two differ by the factor σ′ ≤ 1/4 only. The prediction stays in `(0, 1)` (σ is kept).
//! With σ = identity the update is exactly the paper's linear TD(λ).
//!
//! Reference: the gradient of the logistic log loss (e.g. Bishop, *Pattern Recognition and Machine
//! Learning*, 2006, §4.3.2, eq. 4.91), used as the TD(λ) semi-gradient; the rest is the paper's update.

use super::super::{Sigma, TdParams, UpdateRefused};
use super::dot;

/// The cross-entropy TD(λ) learner (see the module documentation), dense over its features.
#[derive(Debug, Clone, PartialEq)]
pub struct XentTd {
    pub(super) params: TdParams,
    pub(super) weights: Vec<f64>,
    pub(super) traces: Vec<f64>,
}

impl XentTd {
    /// Every weight at the initial weight, a zero trace (the caller validated `params`).
    pub fn new(num_features: usize, params: TdParams) -> Self {
        XentTd {
            params,
            weights: vec![params.initial_weight; num_features],
            traces: vec![0.0; num_features],
        }
    }

    /// σ(wᵀx).
    pub fn predict(&self, active: &[usize]) -> f64 {
        self.params.sigma.value(dot(&self.weights, active))
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
        let sigma: Sigma = self.params.sigma;
        let delta = reward_next + gamma_next * sigma.value(dot(&self.weights, x_next))
            - sigma.value(dot(&self.weights, x_t));
        if !delta.is_finite() || !gamma_t.is_finite() {
            return Err(UpdateRefused::NonFiniteInput { delta });
        }
        let decay = gamma_t * self.params.lambda;
        let step = self.params.alpha * delta;
        let finite = self
            .weights
            .iter()
            .zip(&self.traces)
            .enumerate()
            .all(|(i, (&w, &e))| {
                let e1 = e * decay + if x_t.contains(&i) { 1.0 } else { 0.0 };
                e1.is_finite() && (w + step * e1).is_finite()
            });
        if !finite {
            return Err(UpdateRefused::WouldDiverge { delta });
        }
        for e in &mut self.traces {
            *e *= decay;
        }
        for &i in x_t {
            if let Some(e) = self.traces.get_mut(i) {
                *e += 1.0;
            }
        }
        for (w, e) in self.weights.iter_mut().zip(&self.traces) {
            *w += step * e;
        }
        Ok(delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One transition: x_t, γ_t, R_{t+1}, γ_{t+1}, x_{t+1}.
    type Step<'a> = (&'a [usize], f64, f64, f64, &'a [usize]);
    use crate::learn::TdLambda;

    fn logistic(y: f64) -> f64 {
        1.0 / (1.0 + (-y).exp())
    }

    fn params(sigma: Sigma, initial_weight: f64) -> TdParams {
        TdParams {
            alpha: 0.1,
            lambda: 0.5,
            sigma,
            initial_weight,
        }
    }

    /// Two steps by hand: features {0} then {1}, weights from −1, α = 0.1, λ = 0.5, logistic.
    #[test]
    fn two_steps_match_the_hand_computation_and_drop_only_sigma_prime() {
        let mut x = XentTd::new(2, params(Sigma::Logistic, -1.0));
        // Step 1: x_t = {0}, γ_t = 0.96, R = 1, γ_{t+1} = 0 (the command came): δ = 1 − σ(−1),
        // e = (1, 0), w = (−1 + 0.1 δ, −1).
        let d1 = x.try_update(&[0], 0.96, 1.0, 0.0, &[1]).unwrap();
        let want_d1 = 1.0 - logistic(-1.0);
        assert!((d1 - want_d1).abs() < 1e-15);
        let w0 = -1.0 + 0.1 * want_d1;
        assert!((x.weights[0] - w0).abs() < 1e-15 && x.weights[1] == -1.0);
        assert_eq!(x.traces, vec![1.0, 0.0]);
        // Step 2: x_t = {1}, γ_t = 0 (wipes the trace), R = 0, γ_{t+1} = 0.96, x_{t+1} = {0}:
        // δ = 0.96 σ(w0) − σ(−1), e = (0, 1), w1 = −1 + 0.1 δ.
        let d2 = x.try_update(&[1], 0.0, 0.0, 0.96, &[0]).unwrap();
        let want_d2 = 0.96 * logistic(w0) - logistic(-1.0);
        assert!((d2 - want_d2).abs() < 1e-15);
        assert_eq!(x.traces, vec![0.0, 1.0]);
        assert!((x.weights[1] - (-1.0 + 0.1 * want_d2)).abs() < 1e-15);
        assert!((x.weights[0] - w0).abs() < 1e-15);

        // The paper's first step moves w0 by σ′(−1) times as much: the only difference.
        let mut paper = TdLambda::new(2, params(Sigma::Logistic, -1.0)).unwrap();
        paper.update(&[0], 0.96, 1.0, 0.0, &[1]);
        let sigma_prime = logistic(-1.0) * (1.0 - logistic(-1.0));
        let ratio = (paper.weights()[0] + 1.0) / (0.1 * want_d1);
        assert!((ratio - sigma_prime).abs() < 1e-12, "{ratio}");
    }

    #[test]
    fn with_an_identity_output_it_is_the_papers_linear_td() {
        let mut x = XentTd::new(3, params(Sigma::Identity, 0.0));
        let mut td = TdLambda::new(3, params(Sigma::Identity, 0.0)).unwrap();
        let steps: [Step; 3] = [
            (&[0, 1], 0.9, 0.0, 0.9, &[1, 2]),
            (&[1, 2], 0.9, 1.0, 0.0, &[0]),
            (&[0], 0.0, 0.0, 0.9, &[2]),
        ];
        for (a, g, r, g1, b) in steps {
            let (dx, dt) = (
                x.try_update(a, g, r, g1, b).unwrap(),
                td.update(a, g, r, g1, b),
            );
            assert!((dx - dt).abs() < 1e-15, "{dx} {dt}");
        }
        for (a, b) in x
            .weights
            .iter()
            .zip(td.weights())
            .chain(x.traces.iter().zip(td.traces()))
        {
            assert!((a - b).abs() < 1e-15, "{a} {b}");
        }
    }

    #[test]
    fn a_non_finite_cumulant_changes_nothing() {
        let mut x = XentTd::new(2, params(Sigma::Logistic, -1.0));
        let before = x.clone();
        assert!(x.try_update(&[0], 0.9, f64::NAN, 0.9, &[1]).is_err());
        assert_eq!(x, before);
    }
}
