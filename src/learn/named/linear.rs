//! `learner = "linear"`: the paper's TD(λ) ([`super::super::td`]) with the identity output, `v = wᵀx`
//! (config/interaction-linear.toml; the paper's stall prediction is one). It runs on the same engine as
//! `learner = "paper"` (the set's dense or deferred [`super::super::set::TdLearner`]); the name only says, and
//! the configuration checks, that σ is the identity:
//!
//! ```text
//! δ_t     = R_{t+1} + γ_{t+1} w_tᵀ x_{t+1} − w_tᵀ x_t
//! e_t     = γ_t λ e_{t−1} + x_t
//! w_{t+1} = w_t + α δ_t e_t
//! ```
//!
//! Reference: Sutton & Barto, *Reinforcement Learning: An Introduction*, 2nd ed., 2018, §12.2 (semi-gradient
//! TD(λ) with accumulating traces). The prediction is not bounded: it can leave `[0, 1]`.

use super::super::{LearnError, Sigma};

/// Refuses a `learner = "linear"` or `"true_online"` prediction whose σ is not the identity.
pub fn check_identity(name: &str, learner: &str, sigma: Sigma) -> Result<(), LearnError> {
    if sigma == Sigma::Identity {
        return Ok(());
    }
    Err(LearnError::OutOfBounds {
        name: name.to_string(),
        field: "sigma".into(),
        value: "\"logistic\"".into(),
        bound: format!(
            "is not supported with learner = \"{learner}\" (a linear learner): use sigma = \"identity\""
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::{TdLambda, TdParams};

    /// Two steps by hand: α = 0.1, λ = 0.5, weights from 0, features {0} then {1}.
    #[test]
    fn two_steps_match_the_hand_computation() {
        let params = TdParams {
            alpha: 0.1,
            lambda: 0.5,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        };
        let mut td = TdLambda::new(2, params).unwrap();
        // 1: δ = 1 + 0.9·0 − 0 = 1, e = (1, 0), w = (0.1, 0).
        assert_eq!(td.update(&[0], 0.9, 1.0, 0.9, &[1]), 1.0);
        assert_eq!(td.weights(), &[0.1, 0.0]);
        // 2: x = {1}, x′ = {0}: δ = 0 + 0.9·0.1 − 0 = 0.09, e = (0.45, 1), w += 0.1·0.09·e.
        let d = td.update(&[1], 0.9, 0.0, 0.9, &[0]);
        assert!((d - 0.09).abs() < 1e-15);
        assert!((td.weights()[0] - (0.1 + 0.009 * 0.45)).abs() < 1e-15);
        assert!((td.weights()[1] - 0.009).abs() < 1e-15);
        assert_eq!(td.traces(), &[0.45, 1.0]);
    }

    #[test]
    fn a_logistic_output_is_refused_by_name() {
        check_identity("p", "linear", Sigma::Identity).unwrap();
        let e = check_identity("p", "true_online", Sigma::Logistic).unwrap_err();
        assert!(e.to_string().contains("true_online"), "{e}");
    }
}
