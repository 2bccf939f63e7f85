//! [`DenseTd`] against the dense reference [`TdLambda`] and the deferred [`TraceGroup`], over long runs
//! of the paper's two predictions; its checkpoints, its stop on divergence, and its trace floor.

use super::*;
use crate::learn::{TdLambda, TdParams, TileCoder};

use crate::learn::test_stream::held_stream as stream;

struct Paper {
    coder: TileCoder,
    dims: usize,
    lambda: f64,
    sigma: Sigma,
    column: Column,
}

/// The stall prediction: 44 dimensions × 10 tiles, identity, λ = 0.5, α = 1/44.
fn stall() -> Paper {
    Paper {
        coder: TileCoder::one_dim(44, 10).unwrap(),
        dims: 44,
        lambda: 0.5,
        sigma: Sigma::Identity,
        column: Column {
            alpha: 1.0 / 44.0,
            initial_weight: 0.0,
        },
    }
}

/// The command prediction: 5 pair tilings of 10 × 10, logistic, λ = 0.8, α = 0.1/5, weights −1.
fn command() -> Paper {
    let pairs = vec![
        (0, 1, 0.0),
        (0, 1, 0.5),
        (2, 3, 0.0),
        (2, 3, 0.5),
        (0, 2, 0.0),
    ];
    Paper {
        coder: TileCoder::pairs(pairs, 10).unwrap(),
        dims: 4,
        lambda: 0.8,
        sigma: Sigma::Logistic,
        column: Column {
            alpha: 0.1 / 5.0,
            initial_weight: -1.0,
        },
    }
}

/// γ: 1 − 1/25, ending (0) on the stimulus, as the paper's predictions do.
fn gamma(stimulus: bool) -> f64 {
    if stimulus { 0.0 } else { 0.96 }
}

/// The largest difference of the three learners' predictions over `ticks` ticks, and of their weights
/// at the end.
fn compare(p: &Paper, ticks: usize, seed: u64) -> (f64, f64) {
    let n = p.coder.num_features();
    let mut dense = DenseTd::new(n, p.lambda, p.sigma, p.column).unwrap();
    let mut group: TraceGroup<f64> = TraceGroup::new(n, p.lambda, p.sigma, vec![p.column]).unwrap();
    let mut reference = TdLambda::new(
        n,
        TdParams {
            alpha: p.column.alpha,
            lambda: p.lambda,
            sigma: p.sigma,
            initial_weight: p.column.initial_weight,
        },
    )
    .unwrap();
    let (mut x, mut x_prev) = (Vec::new(), Vec::new());
    let mut gamma_prev = 0.0;
    let mut worst: f64 = 0.0;
    for (t, (input, stim)) in stream(ticks, p.dims, 0.02, seed).iter().enumerate() {
        p.coder.active(input, &mut x);
        let v_dense = p.sigma.value(dense.predict(&x));
        let v_group = p.sigma.value(group.predict(&x)[0]);
        let v_ref = reference.predict(&x);
        worst = worst
            .max((v_dense - v_ref).abs())
            .max((v_dense - v_group).abs());
        let r = f64::from(u8::from(*stim));
        dense.learn(gamma(*stim), r).unwrap();
        group.learn(gamma(*stim), &[r], &mut [0.0]).unwrap();
        if t > 0 {
            reference.update(&x_prev, gamma_prev, r, gamma(*stim), &x);
        }
        std::mem::swap(&mut x, &mut x_prev);
        gamma_prev = gamma(*stim);
    }
    let weights = dense
        .weights()
        .iter()
        .zip(reference.weights())
        .zip(group.weights(0))
        .fold(0.0f64, |m, ((d, r), g)| {
            m.max((d - r).abs()).max((d - g).abs())
        });
    (worst, weights)
}

#[test]
fn the_paper_predictions_match_the_reference_and_the_group_over_long_runs() {
    for (name, paper) in [("stall", stall()), ("command", command())] {
        let (values, weights) = compare(&paper, 30_000, 7);
        assert!(values < 1e-9, "{name}: predictions differ by {values:e}");
        assert!(weights < 1e-9, "{name}: weights differ by {weights:e}");
    }
}

#[test]
fn a_snapshot_of_weights_traces_and_previous_tick_continues_bit_for_bit() {
    let p = command();
    let s = stream(3000, p.dims, 0.05, 3);
    let mut a = DenseTd::new(p.coder.num_features(), p.lambda, p.sigma, p.column).unwrap();
    let mut x = Vec::new();
    let mut run = |td: &mut DenseTd, (input, stim): &(Vec<f64>, bool)| {
        p.coder.active(input, &mut x);
        let y = td.predict(&x);
        let delta = td.learn(gamma(*stim), f64::from(u8::from(*stim))).unwrap();
        (y.to_bits(), delta.to_bits())
    };
    for tick in &s[..1500] {
        run(&mut a, tick);
    }
    let mut b = DenseTd::new(p.coder.num_features(), p.lambda, p.sigma, p.column).unwrap();
    b.set_dense(a.weights(), a.traces(), a.previous()).unwrap();
    for tick in &s[1500..] {
        assert_eq!(run(&mut a, tick), run(&mut b, tick));
    }
}

#[test]
fn a_group_state_of_an_earlier_checkpoint_is_restored() {
    let p = stall();
    let n = p.coder.num_features();
    let mut group: TraceGroup<f64> = TraceGroup::new(n, p.lambda, p.sigma, vec![p.column]).unwrap();
    let mut x = Vec::new();
    for (input, stim) in &stream(800, p.dims, 0.02, 5) {
        p.coder.active(input, &mut x);
        group.predict(&x);
        group
            .learn(gamma(*stim), &[f64::from(u8::from(*stim))], &mut [0.0])
            .unwrap();
    }
    let mut dense = DenseTd::new(n, p.lambda, p.sigma, p.column).unwrap();
    dense.restore_group_state("stall", &group.state()).unwrap();
    assert_eq!(dense.weights(), &group.weights(0)[..]);
    assert_eq!(dense.traces(), &group.traces()[..]);
    assert_eq!(dense.previous(), group.previous());
    // A state of another size is refused.
    let mut small = DenseTd::new(10, p.lambda, p.sigma, p.column).unwrap();
    assert!(small.restore_group_state("stall", &group.state()).is_err());
}

#[test]
fn a_step_that_would_overflow_stops_the_prediction_and_keeps_its_weights() {
    let mut td = DenseTd::new(
        4,
        0.9,
        Sigma::Identity,
        Column {
            alpha: 0.5,
            initial_weight: 0.0,
        },
    )
    .unwrap();
    td.set_dense(&[1e299, 0.0, 0.0, 0.0], &[0.0; 4], None)
        .unwrap();
    td.predict(&[0]);
    assert!(
        td.learn(0.9, 0.0).unwrap().is_nan(),
        "the first tick learns nothing"
    );
    // δ ≈ 1e308: the step would carry weight 0 (1e299) past the bound of 1e300.
    td.predict(&[1]);
    let delta = td.learn(0.9, 1e308).unwrap();
    assert!(delta.is_nan(), "{delta}");
    assert!(td.diverged());
    assert_eq!(td.weights(), &[1e299, 0.0, 0.0, 0.0]);
    // Its trace still moved, and it learns nothing more until a reset.
    assert_eq!(td.traces()[0], 1.0);
    td.predict(&[2]);
    assert!(td.learn(0.9, 1.0).unwrap().is_nan());
    assert_eq!(td.weights(), &[1e299, 0.0, 0.0, 0.0]);
    td.reset();
    assert!(!td.diverged());
    assert_eq!(td.weights(), &[0.0; 4]);
}

#[test]
fn a_long_unvisited_trace_ends_at_zero_not_in_subnormal_numbers() {
    let mut td = DenseTd::new(
        3,
        0.5,
        Sigma::Identity,
        Column {
            alpha: 0.1,
            initial_weight: 0.0,
        },
    )
    .unwrap();
    td.predict(&[0]);
    td.learn(0.96, 0.0).unwrap();
    for _ in 0..2000 {
        td.predict(&[1]);
        td.learn(0.96, 1.0).unwrap();
    }
    let e = td.traces()[0];
    assert_eq!(
        e, 0.0,
        "feature 0's trace decayed by 0.48 a tick for 2000 ticks"
    );
    assert!(td.traces().iter().all(|e| *e == 0.0 || e.is_normal()));
}

#[test]
fn skipping_zero_blocks_changes_no_result() {
    for paper in [stall(), command()] {
        let n = paper.coder.num_features();
        let mut plain = DenseTd::new(n, paper.lambda, paper.sigma, paper.column).unwrap();
        let mut skipping = plain.clone().skipping_zero_blocks(true);
        let mut x = Vec::new();
        for (input, stim) in &stream(5000, paper.dims, 0.05, 11) {
            paper.coder.active(input, &mut x);
            assert_eq!(plain.predict(&x), skipping.predict(&x));
            let r = f64::from(u8::from(*stim));
            let (a, b) = (
                plain.learn(gamma(*stim), r).unwrap(),
                skipping.learn(gamma(*stim), r).unwrap(),
            );
            assert!(a == b || (a.is_nan() && b.is_nan()), "{a} against {b}");
        }
        // Equal as numbers (a skipped block may keep a weight's −0 where the full pass makes it +0).
        let equal = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x == y);
        assert!(equal(plain.weights(), skipping.weights()));
        assert!(equal(plain.traces(), skipping.traces()));
    }
}
