//! The deferred group against the dense reference [`TdLambda`], step by step.

use super::*;
use crate::learn::{TdLambda, TdParams, TileCoder};

use crate::learn::test_stream::held_stream as stream;

struct Case {
    lambda: f64,
    tau: f64,
    sigma: Sigma,
    alphas: Vec<f64>,
    initial: f64,
    /// Whether the stimulus terminates (γ = 0 on it).
    terminating: bool,
}

/// Runs the group and one dense learner per prediction side by side over `s`; returns the largest
/// difference of the predictions (every tick) and of the weights and traces (at the end).
fn compare<W: Weight>(case: &Case, coder: &TileCoder, s: &[(Vec<f64>, bool)]) -> (f64, f64) {
    let cols = case.alphas.len();
    let columns = case
        .alphas
        .iter()
        .map(|&alpha| Column {
            alpha,
            initial_weight: case.initial,
        })
        .collect();
    let n = coder.num_features();
    let mut group: TraceGroup<W> = TraceGroup::new(n, case.lambda, case.sigma, columns).unwrap();
    let mut dense: Vec<TdLambda> = case
        .alphas
        .iter()
        .map(|&alpha| {
            TdLambda::new(
                n,
                TdParams {
                    alpha,
                    lambda: case.lambda,
                    sigma: case.sigma,
                    initial_weight: case.initial,
                },
            )
            .unwrap()
        })
        .collect();
    let gamma = |e: bool| {
        if e && case.terminating {
            0.0
        } else {
            1.0 - 1.0 / case.tau
        }
    };
    // Column i's cumulant: the stimulus for column 0, a scaled input for the others.
    let cumulant = |i: usize, x: &[f64], e: bool| {
        if i == 0 {
            f64::from(u8::from(e))
        } else {
            x[i % x.len()] * i as f64
        }
    };
    let mut x_prev: Vec<usize> = Vec::new();
    let mut x_now = Vec::new();
    let mut gamma_prev = 0.0;
    let mut max_value: f64 = 0.0;
    let mut deltas = vec![0.0; cols];
    for (t, (input, e)) in s.iter().enumerate() {
        coder.active(input, &mut x_now);
        let y = group.predict(&x_now).to_vec();
        for (i, d) in dense.iter().enumerate() {
            max_value = max_value.max((d.dot(&x_now) - y[i]).abs());
        }
        let rewards: Vec<f64> = (0..cols).map(|i| cumulant(i, input, *e)).collect();
        group.learn(gamma(*e), &rewards, &mut deltas).unwrap();
        if t > 0 {
            for (i, d) in dense.iter_mut().enumerate() {
                d.update(&x_prev, gamma_prev, rewards[i], gamma(*e), &x_now);
            }
        }
        std::mem::swap(&mut x_prev, &mut x_now);
        gamma_prev = gamma(*e);
    }
    let mut max_state: f64 = 0.0;
    for (i, d) in dense.iter().enumerate() {
        for (a, b) in group.weights(i).iter().zip(d.weights()) {
            max_state = max_state.max((a - b).abs());
        }
        if case.sigma == Sigma::Identity {
            for (a, b) in group.traces().iter().zip(d.traces()) {
                max_state = max_state.max((a - b).abs());
            }
        }
    }
    (max_value, max_state)
}

fn stall_like() -> Case {
    Case {
        lambda: 0.5,
        tau: 25.0,
        sigma: Sigma::Identity,
        alphas: vec![1.0 / 44.0],
        initial: 0.0,
        terminating: true,
    }
}

#[test]
fn the_papers_stall_prediction_matches_the_dense_learner() {
    let coder = TileCoder::one_dim(44, 10).unwrap();
    let s = stream(5000, 44, 0.03, 1);
    let (value, state) = compare::<f64>(&stall_like(), &coder, &s);
    // Measured: 3.5e-12 and 7e-14 (rounding in a different order); the goal is 1e-6.
    assert!(value < 1e-10 && state < 1e-10, "{value} {state}");
}

#[test]
fn the_papers_command_prediction_matches_the_dense_learner() {
    let coder = TileCoder::pairs(
        vec![
            (0, 1, 0.0),
            (0, 1, 0.5),
            (2, 3, 0.0),
            (2, 3, 0.5),
            (0, 2, 0.0),
        ],
        10,
    )
    .unwrap();
    let case = Case {
        lambda: 0.8,
        tau: 25.0,
        sigma: Sigma::Logistic,
        alphas: vec![0.1 / 5.0],
        initial: -1.0,
        terminating: true,
    };
    let s = stream(5000, 4, 0.05, 2);
    let (value, state) = compare::<f64>(&case, &coder, &s);
    assert!(value < 1e-12 && state < 1e-12, "{value} {state}");
}

#[test]
fn many_predictions_share_one_trace_exactly() {
    // Long traces (λ = 0.95, τ = 100: the epoch lasts ~90 ticks) and rows that go quiet for long
    // stretches, so rows leave the ring of epochs with their trace dropped.
    let coder = TileCoder::one_dim(8, 16).unwrap();
    let case = Case {
        lambda: 0.95,
        tau: 100.0,
        sigma: Sigma::Identity,
        alphas: vec![0.1 / 8.0, 0.05 / 8.0, 0.01 / 8.0, 0.12 / 8.0, 0.02 / 8.0],
        initial: 0.25,
        terminating: false,
    };
    let s = stream(20_000, 8, 0.05, 3);
    let (value, state) = compare::<f64>(&case, &coder, &s);
    assert!(value < 1e-9 && state < 1e-9, "{value} {state}");
}

#[test]
fn no_bootstrapping_and_no_trace_still_match() {
    let coder = TileCoder::one_dim(6, 5).unwrap();
    let s = stream(3000, 6, 0.1, 4);
    for (lambda, tau) in [(0.0, 10.0), (1.0, 4.0), (0.9, 1.25)] {
        let case = Case {
            lambda,
            tau,
            sigma: Sigma::Identity,
            alphas: vec![0.1 / 6.0, 0.15 / 6.0],
            initial: 0.0,
            terminating: true,
        };
        let (value, state) = compare::<f64>(&case, &coder, &s);
        assert!(
            value < 1e-10 && state < 1e-10,
            "λ {lambda} τ {tau}: {value} {state}"
        );
    }
}

#[test]
fn f32_weights_stay_close_to_the_f64_reference() {
    let coder = TileCoder::one_dim(44, 10).unwrap();
    let s = stream(5000, 44, 0.03, 5);
    let (value, state) = compare::<f32>(&stall_like(), &coder, &s);
    // Measured: 1.7e-5 on the prediction and 4e-7 on a weight after 5000 ticks: f32 rounds each of the
    // 44 weights of a prediction to ~6e-8 of its size, and the deferred base `w − c·A` to ~6e-8 of
    // up to 1/EPOCH_FLOOR = 100 times that.
    assert!(value < 1e-4 && state < 1e-5, "{value} {state}");
}

#[test]
fn an_exact_state_continues_bit_for_bit() {
    let coder = TileCoder::one_dim(8, 16).unwrap();
    let s = stream(4000, 8, 0.05, 6);
    let columns = vec![
        Column {
            alpha: 0.1 / 8.0,
            initial_weight: 0.0,
        };
        3
    ];
    let mut a: TraceGroup<f32> =
        TraceGroup::new(coder.num_features(), 0.9, Sigma::Identity, columns).unwrap();
    let mut x = Vec::new();
    let mut deltas = [0.0; 3];
    let mut step = |g: &mut TraceGroup<f32>, x: &mut Vec<usize>, (input, e): &(Vec<f64>, bool)| {
        coder.active(input, x);
        let y = g.predict(x).to_vec();
        let r = [f64::from(u8::from(*e)), input[0], input[1]];
        g.learn(if *e { 0.0 } else { 0.98 }, &r, &mut deltas)
            .unwrap();
        y
    };
    for tick in &s[..2000] {
        step(&mut a, &mut x, tick);
    }
    let json = serde_json::to_string(&a.state()).unwrap();
    let state: GroupState = serde_json::from_str(&json).unwrap();
    let mut b = TraceGroup::new(
        coder.num_features(),
        0.5,
        Sigma::Identity,
        vec![
            Column {
                alpha: 1.0,
                initial_weight: 0.0,
            };
            3
        ],
    )
    .unwrap();
    b.restore_state("p", &state).unwrap();
    assert_eq!(a.state(), b.state());
    for tick in &s[2000..] {
        assert_eq!(step(&mut a, &mut x, tick), step(&mut b, &mut x, tick));
    }
    assert_eq!(a.weights(2), b.weights(2));
}

#[test]
fn a_bad_state_is_refused_and_changes_nothing() {
    let mut g: TraceGroup<f64> = TraceGroup::new(
        10,
        0.5,
        Sigma::Identity,
        vec![
            Column {
                alpha: 0.1,
                initial_weight: 0.0,
            };
            2
        ],
    )
    .unwrap();
    let good = g.state();
    let before = g.clone();
    let mut wrong = good.clone();
    wrong.w0.pop();
    assert!(matches!(
        g.restore_state("p", &wrong),
        Err(LearnError::BadGroupState { .. })
    ));
    let mut nan = good.clone();
    nan.a[1] = f64::NAN;
    assert!(matches!(
        g.restore_state("p", &nan),
        Err(LearnError::NonFiniteSnapshot(_))
    ));
    let mut index = good.clone();
    index.members.push(10);
    assert!(g.restore_state("p", &index).is_err());
    let mut precision = good;
    precision.precision = "f32".into();
    assert!(g.restore_state("p", &precision).is_err());
    assert_eq!(g, before);
}

#[test]
fn a_logistic_group_has_one_prediction() {
    let two = vec![
        Column {
            alpha: 0.1,
            initial_weight: 0.0,
        };
        2
    ];
    assert_eq!(
        TraceGroup::<f64>::new(10, 0.5, Sigma::Logistic, two).unwrap_err(),
        LearnError::SharedLogisticTrace(2)
    );
}

#[test]
fn a_non_finite_cumulant_skips_the_update_without_stopping() {
    let mut g: TraceGroup<f64> = TraceGroup::new(
        4,
        0.5,
        Sigma::Identity,
        vec![Column {
            alpha: 0.5,
            initial_weight: 0.0,
        }],
    )
    .unwrap();
    let mut d = [0.0];
    g.predict(&[0]);
    g.learn(0.9, &[1.0], &mut d).unwrap();
    g.predict(&[1]);
    assert_eq!(g.learn(0.9, &[f64::NAN], &mut d).unwrap(), 0);
    assert!(d[0].is_nan() && !g.diverged(0));
    assert_eq!(g.weights(0), vec![0.0; 4]);
    g.predict(&[2]);
    g.learn(0.9, &[1.0], &mut d).unwrap();
    assert_eq!(d[0], 1.0);
    assert!(g.weights(0)[1] > 0.0);
}

#[test]
fn a_snapshot_copied_while_learning_is_the_state_when_it_began() {
    let coder = TileCoder::one_dim(8, 16).unwrap();
    let s = stream(3000, 8, 0.05, 7);
    let columns = vec![
        Column {
            alpha: 0.1 / 8.0,
            initial_weight: 0.5,
        };
        4
    ];
    let mut g: TraceGroup<f32> =
        TraceGroup::new(coder.num_features(), 0.9, Sigma::Identity, columns).unwrap();
    let mut x = Vec::new();
    let mut d = [0.0; 4];
    let mut tick = |g: &mut TraceGroup<f32>, (input, e): &(Vec<f64>, bool)| {
        coder.active(input, &mut x);
        g.predict(&x);
        let r = [f64::from(u8::from(*e)), input[0], input[1], 1.0];
        g.learn(if *e { 0.0 } else { 0.98 }, &r, &mut d).unwrap();
    };
    for t in &s[..1500] {
        tick(&mut g, t);
    }
    let expected = g.state();
    assert!(g.begin_snapshot());
    assert!(!g.begin_snapshot(), "one at a time");
    // 128 rows, 5 a tick: the copy takes 26 ticks of learning, which writes many rows meanwhile.
    let mut ticks = 0;
    while !g.advance_snapshot(5) {
        tick(&mut g, &s[1500 + ticks]);
        ticks += 1;
    }
    assert!(ticks > 20);
    assert_ne!(g.state(), expected, "it kept learning");
    let (mut state, weights) = g.take_snapshot().unwrap();
    state.w0 = weights.iter().map(|&w| f64::from(w)).collect();
    assert_eq!(state, expected);
    assert!(g.take_snapshot().is_none());
    // A reset during a copy completes the copy first: the snapshot is still of the old weights.
    assert!(g.begin_snapshot());
    let before = g.state();
    g.reset();
    let (mut state, weights) = g.take_snapshot().unwrap();
    state.w0 = weights.iter().map(|&w| f64::from(w)).collect();
    assert_eq!(state, before);
}

/// A logistic group with the log-loss trace (`learner = "xent"` in the Horde) against the dense
/// [`crate::learn::named::XentTd`], step by step.
#[test]
fn a_unit_gradient_group_matches_the_cross_entropy_learner() {
    use crate::learn::named::XentTd;
    let params = TdParams {
        alpha: 0.1,
        lambda: 0.8,
        sigma: Sigma::Logistic,
        initial_weight: -1.0,
    };
    let mut group: TraceGroup<f64> = TraceGroup::new(
        8,
        0.8,
        Sigma::Logistic,
        vec![Column {
            alpha: 0.1,
            initial_weight: -1.0,
        }],
    )
    .unwrap()
    .with_unit_gradient(true);
    let mut dense = XentTd::new(8, params);
    let mut rng = crate::rng::Rng::new(4);
    let mut prev: Option<(Vec<usize>, f64)> = None;
    let mut delta = [f64::NAN];
    for _ in 0..400 {
        let x = vec![rng.below(4) as usize, 4 + rng.below(4) as usize];
        let e = rng.chance(0.2);
        let (r, g) = (f64::from(u8::from(e)), if e { 0.0 } else { 0.96 });
        let y = group.predict(&x)[0];
        assert!((Sigma::Logistic.value(y) - dense.predict(&x)).abs() < 1e-12);
        group.learn(g, &[r], &mut delta).unwrap();
        if let Some((xp, gp)) = &prev {
            let d = dense.try_update(xp, *gp, r, g, &x).unwrap();
            assert!((d - delta[0]).abs() < 1e-12);
        }
        prev = Some((x, g));
    }
}
