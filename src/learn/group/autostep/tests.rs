//! The Autostep group against the single-prediction learner, and its state restored.

use super::*;
use crate::learn::named::AutostepTd;
use crate::learn::test_stream::held_stream;
use crate::learn::{TdParams, TileCoder};

fn group<W: Weight>(cols: usize, lambda: f64, sigma: Sigma, n: usize) -> AutostepGroup<W> {
    let columns = (0..cols)
        .map(|i| Column {
            alpha: 0.02 + 0.01 * (i % 3) as f64,
            initial_weight: if sigma == Sigma::Logistic { -1.0 } else { 0.0 },
        })
        .collect();
    AutostepGroup::new(n, lambda, sigma, columns).unwrap()
}

/// The cumulant of column `i`: the stimulus for column 0, a scaled input for the others.
fn cumulants(cols: usize, x: &[f64], stim: bool) -> Vec<f64> {
    (0..cols)
        .map(|i| {
            if i == 0 {
                f64::from(u8::from(stim))
            } else {
                x[i % x.len()]
            }
        })
        .collect()
}

/// A group of `cols` Autostep predictions against as many single learners over the same stream
/// (the stimulus terminates: γ = 0 there): every value and δ, and at the end every weight, step
/// size and trace, bit for bit.
/// Returns on how many steps a learner's step was normalised (M > 1).
fn same_as_single(cols: usize, lambda: f64, sigma: Sigma, seed: u64) -> usize {
    let coder = TileCoder::one_dim(12, 8).unwrap();
    let n = coder.num_features();
    let mut g: AutostepGroup<f64> = group(cols, lambda, sigma, n);
    let mut single: Vec<AutostepTd> = g
        .columns()
        .iter()
        .map(|c| {
            AutostepTd::new(
                n,
                TdParams {
                    alpha: c.alpha,
                    lambda,
                    sigma,
                    initial_weight: c.initial_weight,
                },
            )
        })
        .collect();
    let (mut x_prev, mut x_now, mut gamma_prev) = (Vec::new(), Vec::new(), 0.0);
    let mut deltas = vec![0.0; cols];
    let mut normalised = 0;
    for (t, (x, stim)) in held_stream(1200, 12, 0.05, seed).into_iter().enumerate() {
        coder.active(&x, &mut x_now);
        let gamma = if stim { 0.0 } else { 0.95 };
        let r = cumulants(cols, &x, stim);
        let values = g.predict(&x_now).to_vec();
        for (i, s) in single.iter().enumerate() {
            assert_eq!(
                s.predict(&x_now),
                sigma.value(values[i]),
                "value {i} at {t}"
            );
        }
        g.learn(gamma, &r, &mut deltas).unwrap();
        if t > 0 {
            for (i, s) in single.iter_mut().enumerate() {
                let d = s
                    .try_update(&x_prev, gamma_prev, r[i], gamma, &x_now)
                    .unwrap();
                assert_eq!(d.to_bits(), deltas[i].to_bits(), "δ {i} at {t}");
                // After a normalised step Σ α_i e_i x_i is 1; below 1 otherwise.
                let m: f64 = x_prev.iter().map(|&f| s.alphas()[f] * s.traces()[f]).sum();
                normalised += usize::from((m - 1.0).abs() < 1e-9);
            }
        }
        std::mem::swap(&mut x_prev, &mut x_now);
        gamma_prev = gamma;
    }
    for (i, s) in single.iter().enumerate() {
        assert_eq!(g.alphas(i), s.alphas(), "step sizes of {i}");
        assert_eq!(g.weights(i), s.weights(), "weights of {i}");
        assert_eq!(g.traces(), s.traces(), "trace of {i}");
    }
    normalised
}

#[test]
fn a_group_is_its_single_learners_bit_for_bit() {
    // With λ = 0.9 the trace reaches ~7: Σ α_i e_i x_i > 1 and the normaliser M acts, on every step
    // of the prediction, the rows of zero trace too.
    assert!(same_as_single(1, 0.9, Sigma::Identity, 1) > 0);
    assert!(same_as_single(4, 0.9, Sigma::Identity, 2) > 0);
    same_as_single(3, 0.0, Sigma::Identity, 3);
    // The trace holds no σ′: logistic predictions share it too.
    same_as_single(3, 0.7, Sigma::Logistic, 4);
}

#[test]
fn a_state_restores_exactly_and_a_foreign_one_is_refused() {
    let coder = TileCoder::one_dim(12, 4).unwrap();
    let n = coder.num_features();
    let mut a: AutostepGroup<f32> = group(3, 0.9, Sigma::Identity, n);
    let s = held_stream(600, 12, 0.05, 7);
    let mut active = Vec::new();
    let mut deltas = vec![0.0; 3];
    let mut tick = |g: &mut AutostepGroup<f32>, (x, stim): &(Vec<f64>, bool)| {
        coder.active(x, &mut active);
        g.predict(&active);
        g.learn(0.9, &cumulants(3, x, *stim), &mut deltas).unwrap();
        g.values().to_vec()
    };
    for t in &s[..300] {
        tick(&mut a, t);
    }
    assert!(a.begin_snapshot_into(None));
    let (state, values) = a.take_snapshot().unwrap();
    assert_eq!(values.len(), a.value_count());
    assert_eq!(state.value_count(), a.value_count());
    let mut b: AutostepGroup<f32> = group(3, 0.9, Sigma::Identity, n);
    b.restore_snapshot("b", &state, &values).unwrap();
    assert_eq!(b.state(), a.state());
    for t in &s[300..] {
        assert_eq!(tick(&mut a, t), tick(&mut b, t));
    }
    let mut other: AutostepGroup<f32> = group(2, 0.9, Sigma::Identity, n);
    assert!(other.restore_state("o", &a.state()).is_err());
    let mut not_autostep = a.state();
    not_autostep.autostep = false;
    let e = b.restore_state("b", &not_autostep).unwrap_err().to_string();
    assert!(e.contains("Autostep"), "{e}");
}
