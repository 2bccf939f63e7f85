//! Tests of [`TdLambda`]: a hand-computed two-step update, and the update rules' structure.

use super::*;

fn td(n: usize, alpha: f64, lambda: f64, sigma: Sigma, w0: f64) -> TdLambda {
    TdLambda::new(
        n,
        TdParams {
            alpha,
            lambda,
            sigma,
            initial_weight: w0,
        },
    )
    .unwrap()
}

fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
}

/// Four features, identity σ, α = 0.5, λ = 0.5, every weight starting at 0.1.
///
/// Step 1: x_t = {0, 1}, γ_t = 0.9, R_{t+1} = 1, γ_{t+1} = 0.9, x_{t+1} = {1, 2}.
///   wᵀx_t = 0.2, wᵀx_{t+1} = 0.2, δ = 1 + 0.9·0.2 − 0.2 = 0.98.
///   e = 0.9·0.5·0 + 1·x_t = [1, 1, 0, 0].
///   w = 0.1 + 0.5·0.98·e = [0.59, 0.59, 0.1, 0.1].
/// Step 2: x_t = {1, 2}, γ_t = 0.9, R_{t+1} = 0, γ_{t+1} = 0.9, x_{t+1} = {3}.
///   wᵀx_t = 0.59 + 0.1 = 0.69, wᵀx_{t+1} = 0.1, δ = 0 + 0.9·0.1 − 0.69 = −0.6.
///   e = 0.9·0.5·[1, 1, 0, 0] + [0, 1, 1, 0] = [0.45, 1.45, 1, 0].
///   w = w + 0.5·(−0.6)·e = [0.59 − 0.135, 0.59 − 0.435, 0.1 − 0.3, 0.1] = [0.455, 0.155, −0.2, 0.1].
#[test]
fn hand_computed_two_steps_identity() {
    let mut l = td(4, 0.5, 0.5, Sigma::Identity, 0.1);
    let d1 = l.update(&[0, 1], 0.9, 1.0, 0.9, &[1, 2]);
    assert!((d1 - 0.98).abs() < 1e-12, "{d1}");
    assert!(close(l.traces(), &[1.0, 1.0, 0.0, 0.0]), "{:?}", l.traces());
    assert!(
        close(l.weights(), &[0.59, 0.59, 0.1, 0.1]),
        "{:?}",
        l.weights()
    );
    let d2 = l.update(&[1, 2], 0.9, 0.0, 0.9, &[3]);
    assert!((d2 + 0.6).abs() < 1e-12, "{d2}");
    assert!(
        close(l.traces(), &[0.45, 1.45, 1.0, 0.0]),
        "{:?}",
        l.traces()
    );
    assert!(
        close(l.weights(), &[0.455, 0.155, -0.2, 0.1]),
        "{:?}",
        l.weights()
    );
    assert!((l.predict(&[0, 2]) - 0.255).abs() < 1e-12);
}

/// Two features, logistic σ, α = 0.1, λ = 0.8, weights −1 (the paper's initialisation).
///
/// Step: x_t = {0}, γ_t = 0.96, R_{t+1} = 1, γ_{t+1} = 0, x_{t+1} = {1}.
///   y = −1, s = σ(−1) = 1/(1 + e) ≈ 0.268941, σ′ = s(1 − s) ≈ 0.196612.
///   δ = 1 + 0 − s ≈ 0.731059; e = [σ′, 0]; w_0 = −1 + 0.1·δ·σ′ ≈ −0.985627.
#[test]
fn hand_computed_logistic_step() {
    let mut l = td(2, 0.1, 0.8, Sigma::Logistic, -1.0);
    let s = 1.0 / (1.0 + std::f64::consts::E);
    let d = l.update(&[0], 0.96, 1.0, 0.0, &[1]);
    assert!((d - (1.0 - s)).abs() < 1e-12);
    assert!((l.traces()[0] - s * (1.0 - s)).abs() < 1e-12);
    assert!((l.weights()[0] - (-1.0 + 0.1 * (1.0 - s) * s * (1.0 - s))).abs() < 1e-12);
    assert_eq!(l.weights()[1], -1.0);
    assert!((l.weights()[0] + 0.985_627).abs() < 1e-6);
}

#[test]
fn gamma_t_zero_wipes_the_trace_before_adding_x_t() {
    let mut l = td(3, 0.1, 1.0, Sigma::Identity, 0.0);
    l.update(&[0], 1.0, 0.0, 1.0, &[1]);
    l.update(&[1], 1.0, 0.0, 0.0, &[2]);
    assert!(close(l.traces(), &[1.0, 1.0, 0.0]));
    // γ_t = 0 at the step whose features are {2}: the old trace is gone.
    l.update(&[2], 0.0, 1.0, 0.9, &[0]);
    assert!(close(l.traces(), &[0.0, 0.0, 1.0]), "{:?}", l.traces());
}

#[test]
fn non_finite_inputs_change_nothing() {
    let mut l = td(3, 0.1, 0.9, Sigma::Identity, 0.2);
    l.update(&[0, 1], 0.9, 1.0, 0.9, &[2]);
    let before = l.clone();
    assert!(l.update(&[0], 0.9, f64::NAN, 0.9, &[1]).is_nan());
    assert!(l.update(&[0], f64::NAN, 0.0, 0.9, &[1]).is_finite());
    assert_eq!(l, before);
}

#[test]
fn a_step_that_would_overflow_is_refused_and_changes_nothing() {
    // An extreme cumulant: δ = 1e308 + 0 − 0 is finite, but α·δ on a trace of 1 plus the new
    // σ′·x_t would take weight 0 from 1e308 to 2e308 = ∞.
    let mut l = td(2, 1.0, 1.0, Sigma::Identity, 0.0);
    l.set_state(&[1e308, 0.0], &[1.0, 0.0]).unwrap();
    let before = l.clone();
    assert_eq!(
        l.try_update(&[1], 1.0, 1e308, 0.0, &[1]),
        Err(UpdateRefused::WouldDiverge { delta: 1e308 })
    );
    assert_eq!(l, before);
    // The same through `update`: δ comes back, nothing changes.
    assert_eq!(l.update(&[1], 1.0, 1e308, 0.0, &[1]), 1e308);
    assert_eq!(l, before);
    // Overflowing through the σ′·x_t part alone (no trace yet) is refused too; this needs α above the
    // bound α·‖x‖² ≤ 1, which the learner itself does not know (its set checks it).
    let mut fresh = td(1, 4.0, 0.0, Sigma::Identity, 1e308);
    let untouched = fresh.clone();
    assert!(matches!(
        fresh.try_update(&[0], 0.5, 1.5e308, 1.0, &[]),
        Err(UpdateRefused::WouldDiverge { .. })
    ));
    assert_eq!(fresh, untouched);
    // A non-finite δ is refused as such.
    assert!(matches!(
        l.try_update(&[0], 1.0, f64::INFINITY, 0.0, &[1]),
        Err(UpdateRefused::NonFiniteInput { .. })
    ));
    // A large but safe step is taken.
    assert_eq!(l.try_update(&[1], 1.0, 1.0, 0.0, &[1]), Ok(1.0));
    assert!(l.weights().iter().all(|w| w.is_finite()));
}

#[test]
fn out_of_range_indices_are_ignored() {
    let mut l = td(2, 0.5, 0.0, Sigma::Identity, 1.0);
    assert_eq!(l.dot(&[0, 7]), 1.0);
    l.update(&[0, 9], 0.5, 0.0, 0.5, &[1, 99]);
    assert_eq!(l.traces(), &[1.0, 0.0]);
}

#[test]
fn parameters_are_checked_and_state_round_trips() {
    let p = |alpha, lambda| TdParams {
        alpha,
        lambda,
        sigma: Sigma::Identity,
        initial_weight: 0.0,
    };
    assert!(TdLambda::new(3, p(0.0, 0.5)).is_err());
    assert!(TdLambda::new(3, p(0.1, 2.0)).is_err());
    let mut l = TdLambda::new(3, p(0.1, 0.5)).unwrap();
    assert!(l.set_alpha(-1.0).is_err());
    assert!(l.set_lambda(f64::NAN).is_err());
    l.set_lambda(1.0).unwrap();
    assert_eq!(l.params().lambda, 1.0);
    assert!(l.set_state(&[1.0, 2.0], &[0.0; 3]).is_err());
    assert!(l.set_state(&[1.0, f64::INFINITY, 0.0], &[0.0; 3]).is_err());
    l.set_state(&[1.0, 2.0, 3.0], &[0.5, 0.0, 0.0]).unwrap();
    assert_eq!(l.weights(), &[1.0, 2.0, 3.0]);
    l.reset();
    assert_eq!(l.weights(), &[0.0; 3]);
    assert_eq!(l.traces(), &[0.0; 3]);
}
