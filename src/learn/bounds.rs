//! The bounds on everything that configures a prediction, in one place: the configuration check at
//! start-up, the websocket's `set_params`, checkpoint restores and [`super::PredictionSet::new`] all call
//! these functions, so a value refused by one path is refused by every path, with the same message.
//!
//! **Step size.** TD(λ) over binary features changes the prediction on the current features by
//! `α·δ·σ′·‖x‖²`, where `‖x‖²` is the number of active features (one per tiling: 44 in the stall
//! experiment, 5 in the interaction one). With `α·‖x‖² ≤ 1` a step never moves the prediction past its
//! target (it closes at most the whole error δ); above it every step overshoots, and the weights grow
//! without bound (α = 1 with 44 features reached 1.7e241 in 15 s). The paper's α = 1/44 sits exactly on
//! the bound, its 0.1/5 at a tenth of it. With the logistic σ, σ′ ≤ 1/4, so the bound is conservative
//! by a factor of at least four there. The bound counts the features of a fully valid input; an input
//! with missing dimensions activates fewer, which only makes the step smaller.
//!
//! **Other parameters.** α > 0 and finite, λ in `[0, 1]`, τ > 1 and finite, the initial weight and a
//! fixed threshold θ finite.
//!
//! **Sizes**, checked before anything is allocated: at most [`MAX_TILES_PER_DIMENSION`] tiles per input,
//! at most [`MAX_PREDICTIONS`] predictions, and at most [`MAX_FEATURES`] features in all predictions
//! together. The weights and the traces are dense `f64` vectors, and every tick's update walks the whole
//! trace: 10⁶ features are 16 MB and took about 1.2 ms per update on the machine this was written on
//! (including the divergence check), 10⁷ would be 160 MB and took 20 ms, the whole tick. The paper's predictions have 440 and 500.

use serde::Serialize;

use super::LearnError;

/// Most tiles per input dimension (a 2-D pair tiling has this many squared).
pub const MAX_TILES_PER_DIMENSION: usize = 1000;
/// Most offset tilings per input dimension (tiles3 advises about four per input; nexting-style
/// constructions use around ten).
pub const MAX_TILINGS_PER_DIMENSION: usize = 64;
/// Most features of all predictions together (and so of any one): 16 MB of weights and traces.
pub const MAX_FEATURES: usize = 1_000_000;
/// Most predictions learned side by side.
pub const MAX_PREDICTIONS: usize = 32;

/// What bounds a prediction's step size: its feature construction's sizes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ParamBounds {
    /// Active features for a fully valid input (one per tiling): ‖x‖² of the binary features.
    pub active_features: usize,
    /// The length of the weight vector.
    pub features: usize,
    /// The largest step size α allowed: `1 / active_features` (α·‖x‖² ≤ 1).
    pub max_alpha: f64,
}

impl ParamBounds {
    /// The bounds of a feature construction with `active_features` tilings of `features` features in all.
    pub fn new(active_features: usize, features: usize) -> Self {
        ParamBounds {
            active_features,
            features,
            max_alpha: 1.0 / active_features.max(1) as f64,
        }
    }

    /// Checks α of prediction `name`: finite, > 0, and α·‖x‖² ≤ 1.
    pub fn check_alpha(&self, name: &str, alpha: f64) -> Result<(), LearnError> {
        check_alpha_positive(name, alpha)?;
        // The paper's α = 1/44 written in decimal is the bound itself; allow for its last digit.
        if alpha > self.max_alpha * (1.0 + 1e-12) {
            let n = self.active_features;
            return Err(out_of_bounds(
                name,
                "alpha",
                alpha,
                format!(
                    "exceeds 1/{n} = {} (α·‖x‖² ≤ 1 with {n} active features)",
                    short(self.max_alpha)
                ),
            ));
        }
        Ok(())
    }
}

pub(crate) fn out_of_bounds(name: &str, field: &str, value: f64, bound: String) -> LearnError {
    LearnError::OutOfBounds {
        name: name.to_string(),
        field: field.to_string(),
        value: format!("{value:?}"),
        bound,
    }
}

/// `x` with three significant digits (`0.0227`, `0.2`, `0.001`).
fn short(x: f64) -> String {
    let decimals = 2i32
        .saturating_sub(x.abs().log10().floor() as i32)
        .clamp(0, 12) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// α finite and > 0, the part of the step-size bound that needs no feature count.
pub fn check_alpha_positive(name: &str, alpha: f64) -> Result<(), LearnError> {
    if alpha.is_finite() && alpha > 0.0 {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "alpha",
            alpha,
            "is not a finite number > 0".into(),
        ))
    }
}

/// λ in `[0, 1]`.
pub fn check_lambda(name: &str, lambda: f64) -> Result<(), LearnError> {
    if (0.0..=1.0).contains(&lambda) {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "lambda",
            lambda,
            "is outside [0, 1]".into(),
        ))
    }
}

/// τ finite and > 1 (γ = 1 − 1/τ in `(0, 1)`).
/// The longest timescale, ticks: a million (5.6 hours at 50 Hz), far past any horizon a lab run's
/// predictions are scored over. Beyond it a cumulant's return grows to τ times its size and the
/// continuation 1 − 1/τ nears 1 (at τ = 1e16 it rounds to exactly 1, an undiscounted sum that never
/// converges), so `tau = 1e300` is refused rather than learned.
pub const MAX_TAU: f64 = 1e6;

/// The longest name of a prediction, a Horde family or a rule, characters: names travel in every tick's
/// record and every dashboard message, so a long one costs on every tick.
pub const MAX_NAME_CHARS: usize = 64;

/// Checks a name's length against [`MAX_NAME_CHARS`].
pub fn check_name_length(name: &str) -> Result<(), LearnError> {
    let chars = name.chars().count();
    if chars > MAX_NAME_CHARS {
        let shown: String = name.chars().take(16).collect();
        return Err(LearnError::NameTooLong {
            start: shown,
            chars,
            max: MAX_NAME_CHARS,
        });
    }
    Ok(())
}

pub fn check_tau(name: &str, tau: f64) -> Result<(), LearnError> {
    if tau.is_finite() && tau > 1.0 && tau <= MAX_TAU {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "tau",
            tau,
            format!("is not a number of ticks > 1 and at most {MAX_TAU:e}"),
        ))
    }
}

/// Dense weights and traces of a checkpoint: one finite entry per feature of `features`.
pub fn check_dense_state(
    name: &str,
    features: usize,
    weights: &[f64],
    traces: &[f64],
) -> Result<(), LearnError> {
    for v in [weights, traces] {
        if v.len() != features {
            return Err(LearnError::FeatureCountMismatch {
                name: name.into(),
                expected: features,
                got: v.len(),
            });
        }
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LearnError::NonFiniteSnapshot(name.into()));
        }
    }
    Ok(())
}

/// The initial weight finite.
pub fn check_initial_weight(name: &str, value: f64) -> Result<(), LearnError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "initial_weight",
            value,
            "is not finite".into(),
        ))
    }
}

/// The initial prediction before σ, `w₀·‖x‖²` (every active weight at `w₀`), finite: a finite `w₀` such
/// as 1e307 would otherwise overflow the first prediction and stop the learner at once.
pub fn check_initial_value(
    name: &str,
    initial_weight: f64,
    active_features: usize,
) -> Result<(), LearnError> {
    if (initial_weight * active_features as f64).is_finite() {
        Ok(())
    } else {
        Err(out_of_bounds(
            name,
            "initial_weight",
            initial_weight,
            format!("overflows the prediction over {active_features} active features"),
        ))
    }
}

/// The count of predictions and their features together, before any is allocated.
pub fn check_set_size(feature_counts: &[usize]) -> Result<(), LearnError> {
    if feature_counts.len() > MAX_PREDICTIONS {
        return Err(LearnError::TooManyPredictions {
            count: feature_counts.len(),
            max: MAX_PREDICTIONS,
        });
    }
    let total = feature_counts
        .iter()
        .fold(0usize, |a, &n| a.saturating_add(n));
    if total > MAX_FEATURES {
        return Err(LearnError::TooManyFeaturesInAll {
            total,
            max: MAX_FEATURES,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_size_bound_is_one_over_the_active_features() {
        let stall = ParamBounds::new(44, 440);
        assert_eq!(stall.max_alpha, 1.0 / 44.0);
        stall.check_alpha("stall", 0.022727272727272728).unwrap();
        stall.check_alpha("stall", 0.01).unwrap();
        let e = stall.check_alpha("stall", 1.0).unwrap_err().to_string();
        assert_eq!(
            e,
            "prediction `stall`: alpha = 1.0 exceeds 1/44 = 0.0227 (α·‖x‖² ≤ 1 with 44 active features)"
        );
        let e = stall.check_alpha("stall", 1e308).unwrap_err().to_string();
        assert!(e.contains("1e308") && e.contains("1/44"), "{e}");
        for bad in [0.0, -0.1, f64::NAN, f64::INFINITY] {
            let e = stall.check_alpha("stall", bad).unwrap_err();
            assert!(e.to_string().contains("finite number > 0"), "{e}");
        }
        let command = ParamBounds::new(5, 500);
        command.check_alpha("command", 0.2).unwrap();
        assert!(command.check_alpha("command", 0.21).is_err());
    }

    #[test]
    fn scalar_bounds_name_the_field() {
        let field = |r: Result<(), LearnError>| match r {
            Err(LearnError::OutOfBounds { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(field(check_lambda("p", 1.5)), "lambda");
        assert_eq!(field(check_lambda("p", f64::NAN)), "lambda");
        assert_eq!(field(check_tau("p", 1.0)), "tau");
        assert_eq!(field(check_tau("p", f64::INFINITY)), "tau");
        assert_eq!(field(check_initial_weight("p", f64::NAN)), "initial_weight");
        check_lambda("p", 0.0).unwrap();
        check_lambda("p", 1.0).unwrap();
    }

    #[test]
    fn the_set_is_bounded_in_count_and_in_features() {
        check_set_size(&[440, 500]).unwrap();
        assert!(matches!(
            check_set_size(&[1; MAX_PREDICTIONS + 1]),
            Err(LearnError::TooManyPredictions { count: 33, .. })
        ));
        assert!(matches!(
            check_set_size(&[MAX_FEATURES, 1]),
            Err(LearnError::TooManyFeaturesInAll { .. })
        ));
        assert!(check_set_size(&[usize::MAX, usize::MAX]).is_err());
    }

    #[test]
    fn bounds_print_three_significant_digits() {
        assert_eq!(short(1.0 / 44.0), "0.0227");
        assert_eq!(short(0.2), "0.2");
        assert_eq!(short(1e-3), "0.001");
        assert_eq!(short(1.0), "1");
    }
}
