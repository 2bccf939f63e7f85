//! [`Sigma`]: the monotonic output function σ of a prediction, `v = σ(wᵀx)`, and its derivative σ′.
//!
//! The stall experiment used the identity; the interaction experiment used the logistic
//! `σ(y) = 1 / (1 + e^(−y))` "to keep the predictions in the range [0, 1]".

use serde::{Deserialize, Serialize};

/// The output nonlinearity of a prediction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sigma {
    /// `σ(y) = y`, `σ′(y) = 1`: linear TD(λ).
    Identity,
    /// `σ(y) = 1 / (1 + e^(−y))`, `σ′(y) = σ(y)(1 − σ(y))`.
    Logistic,
}

impl Sigma {
    /// σ(y).
    #[inline]
    pub fn value(self, y: f64) -> f64 {
        match self {
            Sigma::Identity => y,
            Sigma::Logistic => logistic(y),
        }
    }

    /// σ′(y), the derivative at the pre-activation `y`.
    #[inline]
    pub fn derivative(self, y: f64) -> f64 {
        match self {
            Sigma::Identity => 1.0,
            Sigma::Logistic => {
                let s = logistic(y);
                s * (1.0 - s)
            }
        }
    }
}

/// The logistic function, written so that neither branch overflows (`exp` of a non-positive number).
#[inline]
fn logistic(y: f64) -> f64 {
    if y >= 0.0 {
        1.0 / (1.0 + (-y).exp())
    } else {
        let e = y.exp();
        e / (1.0 + e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logistic_matches_its_definition_and_derivative() {
        for y in [-30.0, -5.0, -1.0, 0.0, 0.3, 2.0, 40.0] {
            let direct = 1.0 / (1.0 + f64::exp(-y));
            assert!((Sigma::Logistic.value(y) - direct).abs() < 1e-15, "{y}");
            let h = 1e-6;
            let numeric = (Sigma::Logistic.value(y + h) - Sigma::Logistic.value(y - h)) / (2.0 * h);
            assert!(
                (Sigma::Logistic.derivative(y) - numeric).abs() < 1e-9,
                "{y}"
            );
        }
        // The paper's initial prediction: five active weights of -1.
        assert!((Sigma::Logistic.value(-5.0) - 0.006_692_850_924_284_856).abs() < 1e-15);
        assert_eq!(Sigma::Logistic.value(-1000.0), 0.0);
        assert_eq!(Sigma::Logistic.value(1000.0), 1.0);
    }

    #[test]
    fn identity_is_linear() {
        assert_eq!(Sigma::Identity.value(-2.5), -2.5);
        assert_eq!(Sigma::Identity.derivative(123.0), 1.0);
    }

    #[test]
    fn names_are_lowercase_in_config() {
        #[derive(Deserialize)]
        struct W {
            s: Sigma,
        }
        let w: W = toml::from_str("s = \"logistic\"").unwrap();
        assert_eq!(w.s, Sigma::Logistic);
        assert!(toml::from_str::<W>("s = \"Logistic\"").is_err());
    }
}
