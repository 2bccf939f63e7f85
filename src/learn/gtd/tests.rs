//! Tests of [`Gtd`]: hand-computed steps, traces cut where ρ = 0, and the must-show of issue 14: on a
//! random walk whose target-policy values are known in closed form, GTD(λ) learning from behaviour data
//! converges to them where on-policy TD(λ) on the same data does not.

use super::*;
use crate::learn::{Sigma, TdLambda, TdParams};
use crate::rng::Rng;

fn gtd(n: usize, alpha: f64, beta: f64, lambda: f64, w0: f64) -> Gtd {
    Gtd::new(
        n,
        GtdParams {
            alpha,
            beta,
            lambda,
            initial_weight: w0,
        },
    )
    .unwrap()
}

fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
}

/// Four features, α = 0.5, β = 0.25, λ = 0.5, θ₀ = 0.1, w₀ = 0.
///
/// Step 1: x_t = {0, 1}, γ_t = 0.9, ρ_t = 2, R = 1, γ' = 0.9, x' = {1, 2}.
///   θᵀx_t = 0.2, θᵀx' = 0.2, δ = 1 + 0.18 − 0.2 = 0.98; e = 2·x_t = [2, 2, 0, 0]; eᵀw = 0, wᵀx_t = 0.
///   θ = 0.1 + 0.5·0.98·e = [1.08, 1.08, 0.1, 0.1]; w = 0.25·0.98·e = [0.49, 0.49, 0, 0].
/// Step 2: x_t = {1, 2}, γ_t = 0.9, ρ_t = 0.5, R = 0, γ' = 0.9, x' = {3}.
///   θᵀx_t = 1.18, θᵀx' = 0.1, δ = 0.09 − 1.18 = −1.09; wᵀx_t = 0.49.
///   e = 0.5·(0.45·[2, 2, 0, 0] + [0, 1, 1, 0]) = [0.45, 0.95, 0.5, 0]; eᵀw = 1.4·0.49 = 0.686.
///   θ = θ − 0.545·e − [0, 0, 0, 0.5·0.9·0.5·0.686] = [0.83475, 0.56225, −0.1725, −0.05435].
///   w = w − 0.2725·e − 0.25·0.49·x_t = [0.367375, 0.108625, −0.25875, 0].
/// Step 3: ρ_t = 0 on x_t = {3}: the trace is cut to zero, θ does not move, w moves by −β(wᵀx_t)x_t = 0.
#[test]
fn hand_computed_steps() {
    let mut l = gtd(4, 0.5, 0.25, 0.5, 0.1);
    let d1 = l.try_update(&[0, 1], 0.9, 2.0, 1.0, 0.9, &[1, 2]).unwrap();
    assert!((d1 - 0.98).abs() < 1e-12, "{d1}");
    assert!(close(l.traces(), &[2.0, 2.0, 0.0, 0.0]), "{:?}", l.traces());
    assert!(
        close(l.weights(), &[1.08, 1.08, 0.1, 0.1]),
        "{:?}",
        l.weights()
    );
    assert!(
        close(l.secondary(), &[0.49, 0.49, 0.0, 0.0]),
        "{:?}",
        l.secondary()
    );

    let d2 = l.try_update(&[1, 2], 0.9, 0.5, 0.0, 0.9, &[3]).unwrap();
    assert!((d2 + 1.09).abs() < 1e-12, "{d2}");
    assert!(
        close(l.traces(), &[0.45, 0.95, 0.5, 0.0]),
        "{:?}",
        l.traces()
    );
    assert!(
        close(l.weights(), &[0.83475, 0.56225, -0.1725, -0.05435]),
        "{:?}",
        l.weights()
    );
    assert!(
        close(l.secondary(), &[0.367375, 0.108625, -0.25875, 0.0]),
        "{:?}",
        l.secondary()
    );

    let theta = l.weights().to_vec();
    let w = l.secondary().to_vec();
    l.try_update(&[3], 0.9, 0.0, 1.0, 0.0, &[]).unwrap();
    assert_eq!(l.traces(), &[0.0; 4], "ρ = 0 cuts the trace");
    assert_eq!(l.weights(), &theta[..], "ρ = 0: θ does not move");
    assert_eq!(l.secondary(), &w[..]);
}

#[test]
fn with_rho_one_and_no_correction_it_is_linear_td() {
    // λ = 1 removes the correction term (1 − λ = 0); θ then follows TD(λ) exactly whatever w does.
    let mut g = gtd(5, 0.1, 0.05, 1.0, 0.0);
    let mut t = TdLambda::new(
        5,
        TdParams {
            alpha: 0.1,
            lambda: 1.0,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        },
    )
    .unwrap();
    let steps: [(&[usize], f64, f64, &[usize]); 4] = [
        (&[0, 1], 0.9, 0.0, &[2]),
        (&[2], 0.9, 1.0, &[3, 4]),
        (&[3, 4], 0.9, 0.0, &[0]),
        (&[0], 0.9, 0.5, &[1]),
    ];
    for (x, gamma, r, next) in steps {
        let a = g.try_update(x, gamma, 1.0, r, 0.9, next).unwrap();
        let b = t.update(x, gamma, r, 0.9, next);
        assert!((a - b).abs() < 1e-12);
    }
    assert!(close(g.weights(), t.weights()));
}

#[test]
fn bad_inputs_and_divergence_change_nothing() {
    let mut l = gtd(2, 0.5, 0.5, 0.5, 0.0);
    l.try_update(&[0], 0.9, 1.0, 1.0, 0.9, &[1]).unwrap();
    let before = l.clone();
    for rho in [f64::NAN, -1.0, f64::INFINITY] {
        assert!(matches!(
            l.try_update(&[0], 0.9, rho, 1.0, 0.9, &[1]),
            Err(UpdateRefused::NonFiniteInput { .. })
        ));
    }
    assert!(l.try_update(&[0], f64::NAN, 1.0, 1.0, 0.9, &[1]).is_err());
    assert!(matches!(
        l.try_update(&[0], 0.9, 1e308, 1e308, 0.9, &[1]),
        Err(UpdateRefused::WouldDiverge { .. })
    ));
    assert_eq!(l, before);
}

#[test]
fn parameters_are_checked_with_their_names() {
    let bad = |p: GtdParams| Gtd::new(2, p).unwrap_err().to_string();
    let ok = GtdParams {
        alpha: 0.1,
        beta: 0.01,
        lambda: 0.5,
        initial_weight: 0.0,
    };
    assert!(bad(GtdParams { beta: 0.0, ..ok }).contains("beta"));
    assert!(
        bad(GtdParams {
            beta: f64::NAN,
            ..ok
        })
        .contains("beta")
    );
    assert!(bad(GtdParams { alpha: -1.0, ..ok }).contains("alpha"));
    assert!(bad(GtdParams { lambda: 2.0, ..ok }).contains("lambda"));
    let e = check_beta("stall_pi", 0.1, 44).unwrap_err().to_string();
    assert_eq!(
        e,
        "prediction `stall_pi`: beta = 0.1 exceeds 1/44 = 0.0227 (β·‖x‖² ≤ 1 with 44 active features)"
    );
    check_beta("stall_pi", 1.0 / 44.0, 44).unwrap();
}

/// The five-state random walk (Sutton & Barto's, with actions): states 1..=5, start in 3; `right`
/// moves up, `left` down; leaving on the right gives R = 1 and ends the episode, on the left R = 0.
/// The behaviour b goes right with probability 1/2, the target π with probability p = 0.8. Under a
/// policy that goes right with probability p, the value of state i (gambler's ruin, r = (1 − p)/p) is
/// `v(i) = (1 − rⁱ) / (1 − r⁶)`: under π [0.750, 0.938, 0.984, 0.996, 0.999], under b i/6
/// [0.167, 0.333, 0.5, 0.667, 0.833]. Features are one-hot (tabular), so the fixed point of each
/// learner is the true value of the policy it evaluates.
///
/// Tolerance: after 20 000 episodes with α = β = 0.005, GTD(λ)'s largest error against v_π is below
/// 0.05 (about a tenth of the smallest gap, 0.58 in state 1, between the two policies' values), while
/// on-policy TD(λ) with the same α and λ on the same transitions stays more than 0.2 away from v_π in
/// some state (it converges to v_b instead).
#[test]
fn off_policy_random_walk_converges_to_the_target_values_where_td_does_not() {
    const P_TARGET: f64 = 0.8;
    const P_BEHAVIOUR: f64 = 0.5;
    let r: f64 = (1.0 - P_TARGET) / P_TARGET;
    let v_pi: Vec<f64> = (1..=5)
        .map(|i| (1.0 - r.powi(i)) / (1.0 - r.powi(6)))
        .collect();
    let v_b: Vec<f64> = (1..=5).map(|i| f64::from(i) / 6.0).collect();

    let (alpha, lambda) = (0.005, 0.5);
    let mut g = gtd(5, alpha, 0.005, lambda, 0.0);
    let mut td = TdLambda::new(
        5,
        TdParams {
            alpha,
            lambda,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        },
    )
    .unwrap();
    let mut rng = Rng::new(14);
    for _ in 0..20_000 {
        let mut s: i32 = 3;
        // γ_t of an episode's first state is 0: nothing is carried over from the last episode.
        let mut gamma_t = 0.0;
        loop {
            let right = rng.chance(P_BEHAVIOUR);
            let rho = if right {
                P_TARGET / P_BEHAVIOUR
            } else {
                (1.0 - P_TARGET) / P_BEHAVIOUR
            };
            let next = if right { s + 1 } else { s - 1 };
            let x = [(s - 1) as usize];
            let (reward, gamma_next, x_next): (f64, f64, Vec<usize>) = match next {
                0 => (0.0, 0.0, vec![]),
                6 => (1.0, 0.0, vec![]),
                n => (0.0, 1.0, vec![(n - 1) as usize]),
            };
            g.try_update(&x, gamma_t, rho, reward, gamma_next, &x_next)
                .unwrap();
            td.update(&x, gamma_t, reward, gamma_next, &x_next);
            if x_next.is_empty() {
                break;
            }
            s = next;
            gamma_t = 1.0;
        }
    }
    let max_err = |w: &[f64], v: &[f64]| {
        w.iter()
            .zip(v)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    };
    let gtd_err = max_err(g.weights(), &v_pi);
    let td_err = max_err(td.weights(), &v_pi);
    eprintln!("max error against v_π: GTD(λ) {gtd_err:.4}, on-policy TD(λ) {td_err:.4}");
    assert!(
        gtd_err < 0.05,
        "GTD(λ) {:?} vs v_π {v_pi:?}: max error {gtd_err}",
        g.weights()
    );
    assert!(
        td_err > 0.2,
        "on-policy TD(λ) {:?} came within {td_err} of v_π",
        td.weights()
    );
    // And TD(λ) did learn: it is close to the behaviour policy's values.
    assert!(max_err(td.weights(), &v_b) < 0.05, "{:?}", td.weights());
}
