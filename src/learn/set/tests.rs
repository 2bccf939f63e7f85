//! Tests of [`PredictionSet`]: the online bookkeeping by hand, convergence to analytically known
//! returns (tabular identity and logistic), chain breaks, runtime changes and snapshots.

use super::*;
use crate::learn::Sigma;
use crate::learn::spec::FeatureSpec;
use crate::rng::Rng;

fn names(extra: &[&str], stimuli: &[&str]) -> SignalNames {
    SignalNames {
        obs: vec![],
        extra: extra.iter().map(|s| s.to_string()).collect(),
        stimuli: stimuli.iter().map(|s| s.to_string()).collect(),
    }
}

/// A prediction of stimulus "e" over the single extra input "u" tiled into `tiles` tiles.
fn spec(tau: f64, lambda: f64, alpha: f64, sigma: Sigma, w0: f64, tiles: usize) -> PredictionSpec {
    PredictionSpec {
        name: "p".into(),
        tau,
        lambda,
        alpha,
        sigma,
        initial_weight: w0,
        threshold: Threshold::Fixed(0.5),
        features: FeatureSpec::OneDim {
            all_obs: false,
            inputs: vec!["u".into()],
            tiles,
            tilings: 1,
        },
        cumulant: Cumulant::Stimulus("e".into()),
        learner: Default::default(),
        target_policy: None,
        beta: None,
    }
}

fn tick(set: &mut PredictionSet, u: f64, e: bool) -> (f64, Option<f64>) {
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[u],
    });
    let delta = set.learn(&[e]).unwrap();
    (out[0].value, delta[0])
}

/// One input u tiled in two (u < 0.5: feature 0, else feature 1); τ = 2 so γ = 0.5 without the
/// stimulus; λ = 1, α = 0.5, identity σ, weights 0.
///
/// tick 1: u = 0.2, x1 = {0}, v = 0. No previous tick: no update. Keep x1, γ1 = 0.5.
/// tick 2: u = 0.8, x2 = {1}, v = 0. E: R2 = 1, γ2 = 0.
///   δ1 = 1 + 0·w1 − w0 = 1; e1 = γ1·λ·0 + x1 = [1, 0]; w = [0.5, 0].
/// tick 3: u = 0.2, x3 = {0}, v = w0 = 0.5 (acted on before learning). No E: R3 = 0, γ3 = 0.5.
///   δ2 = 0 + 0.5·w0 − w1 = 0.25; e2 = γ2·λ·e1 + x2 = [0, 1] (the stimulus cut the trace);
///   w = [0.5, 0.125].
/// tick 4: u = 0.8, x4 = {1}, v = 0.125. No E: γ4 = 0.5.
///   δ3 = 0 + 0.5·w1 − w0 = 0.0625 − 0.5 = −0.4375; e3 = γ3·λ·e2 + x3 = [1, 0.5];
///   w = [0.5 − 0.21875, 0.125 − 0.109375] = [0.28125, 0.015625].
#[test]
fn hand_computed_online_bookkeeping() {
    let mut set = PredictionSet::new(
        vec![spec(2.0, 1.0, 0.5, Sigma::Identity, 0.0, 2)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    assert_eq!(tick(&mut set, 0.2, false), (0.0, None));
    assert_eq!(tick(&mut set, 0.8, true), (0.0, Some(1.0)));
    assert_eq!(set.learner("p").unwrap().weights(), &[0.5, 0.0]);
    assert_eq!(tick(&mut set, 0.2, false), (0.5, Some(0.25)));
    assert_eq!(set.learner("p").unwrap().traces(), &[0.0, 1.0]);
    assert_eq!(set.learner("p").unwrap().weights(), &[0.5, 0.125]);
    assert_eq!(tick(&mut set, 0.8, false), (0.125, Some(-0.4375)));
    assert_eq!(set.learner("p").unwrap().traces(), &[1.0, 0.5]);
    assert_eq!(set.learner("p").unwrap().weights(), &[0.28125, 0.015625]);
}

/// A deterministic cycle of M = 10 ticks with the stimulus at phase 0 and tabular features (tile s
/// for phase s). From phase s the next stimulus is d = (M − s) mod M steps ahead (d = M at the
/// stimulus itself, which terminates everything before it), so with γ = 1 − 1/τ between stimuli the
/// return is exactly `G = γ^(d−1)`: 1 one step before the stimulus, γ^(M−1) at the stimulus.
fn cycle_values(m: usize, gamma: f64) -> Vec<f64> {
    (0..m)
        .map(|s| {
            let d = if s == 0 { m } else { m - s };
            gamma.powi(d as i32 - 1)
        })
        .collect()
}

fn run_cycle(set: &mut PredictionSet, m: usize, cycles: usize) -> Vec<f64> {
    let mut last = vec![f64::NAN; m];
    for _ in 0..cycles {
        for (s, slot) in last.iter_mut().enumerate() {
            let u = (s as f64 + 0.5) / m as f64;
            *slot = tick(set, u, s == 0).0;
        }
    }
    last
}

#[test]
fn converges_to_the_analytic_return_on_a_deterministic_cycle() {
    let m = 10;
    let mut set = PredictionSet::new(
        vec![spec(5.0, 0.5, 0.1, Sigma::Identity, 0.0, m)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    let got = run_cycle(&mut set, m, 2_000);
    let want = cycle_values(m, 0.8);
    for (s, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 1e-6, "phase {s}: learned {g}, true {w}");
    }
}

#[test]
fn logistic_converges_on_the_deterministic_cycle() {
    let m = 10;
    let mut set = PredictionSet::new(
        vec![spec(5.0, 0.8, 0.5, Sigma::Logistic, -1.0, m)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    let got = run_cycle(&mut set, m, 5_000);
    let want = cycle_values(m, 0.8);
    // The target 1.0 one step before the stimulus is reached only as w → ∞, so allow 0.02.
    for (s, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 0.02, "phase {s}: learned {g}, true {w}");
    }
}

/// Stimuli independent with probability p each tick, and a single always-active feature (one tile over
/// a constant input): the future is independent of the present, so the true value is the same at every
/// tick, `E[G] = Σ_k ((1 − p)γ)^k p = p / (1 − (1 − p)γ)`.
fn random_stream(sigma: Sigma, lambda: f64, alpha: f64, w0: f64) -> f64 {
    let (p, tau) = (0.05, 25.0);
    let mut set = PredictionSet::new(
        vec![spec(tau, lambda, alpha, sigma, w0, 1)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    let mut rng = Rng::new(7);
    let (mut sum, mut count) = (0.0, 0);
    for t in 0..400_000 {
        let (v, _) = tick(&mut set, 0.5, rng.chance(p));
        if t >= 200_000 {
            sum += v;
            count += 1;
        }
    }
    let gamma = 1.0 - 1.0 / tau;
    let truth = p / (1.0 - (1.0 - p) * gamma);
    let mean = sum / count as f64;
    assert!(
        (mean - truth).abs() < 0.01,
        "{sigma:?}: mean {mean}, true {truth}"
    );
    mean
}

#[test]
fn converges_in_expectation_on_a_random_stream() {
    random_stream(Sigma::Identity, 0.5, 0.01, 0.0);
    random_stream(Sigma::Logistic, 0.8, 0.05, -1.0);
}

#[test]
fn predictions_learn_side_by_side_independently() {
    let mut fast = spec(2.0, 0.0, 0.2, Sigma::Identity, 0.0, 4);
    fast.name = "fast".into();
    let mut slow = spec(50.0, 0.9, 0.05, Sigma::Logistic, -1.0, 4);
    slow.name = "slow".into();
    slow.cumulant = Cumulant::Stimulus("f".into());
    let n = names(&["u"], &["e", "f"]);
    let mut both = PredictionSet::new(vec![fast.clone(), slow.clone()], &n).unwrap();
    let mut alone = PredictionSet::new(vec![slow], &n).unwrap();
    let mut rng = Rng::new(3);
    for _ in 0..2_000 {
        let u = rng.next_f64();
        let stim = [rng.chance(0.1), rng.chance(0.05)];
        let inputs = FeatureInputs {
            obs: &[],
            extra: &[u],
        };
        let a = both.predict(&inputs);
        let b = alone.predict(&inputs);
        assert_eq!(a[1], b[0]);
        assert_eq!(
            both.learn(&stim).unwrap()[1],
            alone.learn(&stim).unwrap()[0]
        );
    }
    assert_eq!(both.learner("slow"), alone.learner("slow"));
    assert_ne!(both.learner("fast").unwrap().weights(), &[0.0; 4]);
}

#[test]
fn construction_errors_are_precise() {
    let n = names(&["u"], &["e"]);
    let good = spec(25.0, 0.5, 0.1, Sigma::Identity, 0.0, 10);
    let err = PredictionSet::new(vec![good.clone(), good.clone()], &n).unwrap_err();
    assert_eq!(err, LearnError::DuplicatePrediction("p".into()));
    let mut bad = good.clone();
    bad.cumulant = Cumulant::Stimulus("bump".into());
    let err = PredictionSet::new(vec![bad], &n).unwrap_err();
    assert!(err.to_string().contains("unknown stimulus `bump`"), "{err}");
    let mut bad = good.clone();
    bad.tau = 1.0;
    assert!(matches!(
        PredictionSet::new(vec![bad], &n),
        Err(LearnError::OutOfBounds { field, .. }) if field == "tau"
    ));
    // α·‖x‖² ≤ 1: one input, one active feature, so α ≤ 1.
    let mut bad = good.clone();
    bad.alpha = 1.5;
    assert!(matches!(
        PredictionSet::new(vec![bad], &n),
        Err(LearnError::OutOfBounds { field, .. }) if field == "alpha"
    ));
    let mut bad = good;
    bad.features = FeatureSpec::OneDim {
        all_obs: false,
        inputs: vec!["u".into()],
        tiles: 0,
        tilings: 1,
    };
    assert!(matches!(
        PredictionSet::new(vec![bad], &n).unwrap_err(),
        LearnError::OutOfBounds { field, .. } if field == "features.tiles"
    ));
}

#[test]
fn learn_needs_a_predict_and_the_right_stimuli() {
    let mut set = PredictionSet::new(
        vec![spec(25.0, 0.5, 0.1, Sigma::Identity, 0.0, 10)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    assert_eq!(set.learn(&[false]), Err(LearnError::LearnWithoutPredict));
    set.predict(&FeatureInputs {
        obs: &[],
        extra: &[0.1],
    });
    assert_eq!(
        set.learn(&[]),
        Err(LearnError::StimulusCountMismatch {
            expected: 1,
            got: 0
        })
    );
    assert!(set.learn(&[true]).is_ok());
    assert_eq!(set.learn(&[true]), Err(LearnError::LearnWithoutPredict));
}

#[test]
fn a_skipped_learn_breaks_the_chain() {
    let mut set = PredictionSet::new(
        vec![spec(2.0, 1.0, 0.5, Sigma::Identity, 0.0, 2)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    tick(&mut set, 0.2, false);
    tick(&mut set, 0.8, false);
    assert_ne!(set.learner("p").unwrap().traces(), &[0.0, 0.0]);
    let inputs = FeatureInputs {
        obs: &[],
        extra: &[0.2],
    };
    set.predict(&inputs);
    set.predict(&inputs); // the first one was never learned from
    assert_eq!(set.learner("p").unwrap().traces(), &[0.0, 0.0]);
    assert_eq!(set.learn(&[true]).unwrap(), vec![None]);
    assert!(tick(&mut set, 0.8, false).1.is_some());
}

#[test]
fn invalid_inputs_are_reported_and_not_valid_for_the_gate() {
    let mut set = PredictionSet::new(
        vec![spec(25.0, 0.5, 0.1, Sigma::Logistic, 0.0, 10)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[f64::NAN],
    });
    assert_eq!(out[0].active_features, 0);
    assert_eq!(out[0].value, 0.5);
    assert_eq!(out[0].valid_value(), None);
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[],
    });
    assert_eq!(out[0].valid_value(), None);
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[0.3],
    });
    assert_eq!(out[0].valid_value(), Some(0.5));
    assert_eq!((out[0].active_features, out[0].tilings), (1, 1));
}

#[test]
fn runtime_changes_apply_and_are_checked() {
    let mut set = PredictionSet::new(
        vec![spec(25.0, 0.5, 0.1, Sigma::Identity, 0.0, 10)],
        &names(&["u"], &["e"]),
    )
    .unwrap();
    set.set_alpha("p", 0.3).unwrap();
    set.set_lambda("p", 0.9).unwrap();
    set.set_threshold("p", Threshold::Steps(15)).unwrap();
    let learner = set.learner("p").unwrap();
    assert_eq!((learner.alpha(), learner.lambda()), (0.3, 0.9));
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[0.3],
    });
    assert!((out[0].threshold - 0.96f64.powi(15)).abs() < 1e-15);
    assert!(matches!(
        set.set_alpha("p", 0.0),
        Err(LearnError::OutOfBounds { field, .. }) if field == "alpha"
    ));
    assert!(matches!(
        set.set_lambda("p", 1.5),
        Err(LearnError::OutOfBounds { field, .. }) if field == "lambda"
    ));
    // Above α·‖x‖² ≤ 1, and a change that is refused in part changes nothing.
    let e = set.set_alpha("p", 1.01).unwrap_err().to_string();
    assert!(e.contains("exceeds 1/1"), "{e}");
    assert!(set.set_params("p", Some(0.5), Some(2.0), None).is_err());
    assert_eq!(set.learner("p").unwrap().alpha(), 0.3);
    set.set_alpha("p", 1.0).unwrap();
    set.set_alpha("p", 0.3).unwrap();
    assert!(set.set_threshold("p", Threshold::Fixed(f64::NAN)).is_err());
    assert_eq!(
        set.set_alpha("q", 0.1),
        Err(LearnError::UnknownPrediction("q".into()))
    );
    assert_eq!(set.specs().next().unwrap().alpha, 0.3);
}

#[test]
fn snapshot_restore_continues_exactly() {
    let n = names(&["u"], &["e"]);
    let s = spec(10.0, 0.8, 0.1, Sigma::Logistic, -1.0, 10);
    let mut a = PredictionSet::new(vec![s.clone()], &n).unwrap();
    let mut rng = Rng::new(11);
    let stream: Vec<(f64, bool)> = (0..3_000)
        .map(|_| (rng.next_f64(), rng.chance(0.03)))
        .collect();
    for &(u, e) in &stream[..1_000] {
        tick(&mut a, u, e);
    }
    let snap = a.snapshot();
    let text = toml::to_string(&snap).unwrap();
    let parsed: crate::learn::SetSnapshot = toml::from_str(&text).unwrap();
    assert_eq!(parsed, snap);
    let mut b = PredictionSet::new(vec![s], &n).unwrap();
    b.restore(&parsed).unwrap();
    for &(u, e) in &stream[1_000..] {
        assert_eq!(tick(&mut a, u, e), tick(&mut b, u, e));
    }
    assert_eq!(a.snapshot(), b.snapshot());

    // A bad snapshot changes nothing.
    let before = b.snapshot();
    let mut bad = before.clone();
    bad.predictions[0].weights.pop();
    assert!(matches!(
        b.restore(&bad),
        Err(LearnError::FeatureCountMismatch { .. })
    ));
    let mut bad = before.clone();
    bad.predictions[0].previous = Some(crate::learn::PreviousStep {
        active: vec![10],
        gamma: 0.9,
    });
    assert!(matches!(
        b.restore(&bad),
        Err(LearnError::SnapshotIndexOutOfRange { .. })
    ));
    let mut bad = before.clone();
    bad.predictions[0].name = "other".into();
    assert!(b.restore(&bad).is_err());
    assert_eq!(b.snapshot(), before);
}

/// Two features of one input (u < 0.5: feature 0, else 1), α = 1 (the bound for one active feature),
/// λ = 1, τ = 25 (γ = 0.96); the snapshot puts the weights at −0.9e308 and +0.9e308 with a trace of 1 on
/// feature 1 and the previous tick on feature 0. Moving to feature 1 then gives δ = 0.96·0.9e308 + 0.9e308
/// = 1.764e308 (finite), and the decayed trace would add 0.96·δ to w₁ = 0.9e308: beyond f64::MAX.
fn about_to_diverge() -> PredictionSet {
    let n = names(&["u"], &["e"]);
    let mut set =
        PredictionSet::new(vec![spec(25.0, 1.0, 1.0, Sigma::Identity, 0.0, 2)], &n).unwrap();
    let mut snap = set.snapshot();
    snap.predictions[0].weights = vec![-0.9e308, 0.9e308];
    snap.predictions[0].state = None; // edited by hand: restore from the dense form
    snap.predictions[0].traces = vec![0.0, 1.0];
    snap.predictions[0].previous = Some(crate::learn::PreviousStep {
        active: vec![0],
        gamma: 0.96,
    });
    set.restore(&snap).unwrap();
    set
}

#[test]
fn a_diverging_prediction_stops_keeps_its_finite_weights_and_leaves_the_gate() {
    let mut set = about_to_diverge();
    let high = FeatureInputs {
        obs: &[],
        extra: &[0.8],
    };
    let out = set.predict(&high);
    assert_eq!(
        out[0].valid_value(),
        Some(0.9e308),
        "valid before it diverges"
    );
    assert_eq!(set.learn(&[false]).unwrap(), vec![None]);
    assert_eq!(set.divergences(), 1);
    assert_eq!(set.diverged().collect::<Vec<_>>(), vec!["p"]);
    let weights = set.learner("p").unwrap().weights().to_vec();
    assert_eq!(
        weights,
        vec![-0.9e308, 0.9e308],
        "the last finite weights are kept"
    );
    // Its value is finite and far above θ = 0.5, yet it does not drive the gate.
    let out = set.predict(&high);
    assert_eq!(out[0].value, 0.9e308);
    assert!(out[0].diverged);
    assert_eq!(out[0].valid_value(), None);
    use crate::control::{Mode, gate};
    assert!(!gate(
        Mode::Pavlovian,
        false,
        out[0].valid_value(),
        out[0].threshold
    ));
    assert!(gate(
        Mode::Pavlovian,
        true,
        out[0].valid_value(),
        out[0].threshold
    ));
    // Stopped: no further update, no second count, weights unchanged over many ticks.
    for k in 0..100 {
        tick(&mut set, if k % 2 == 0 { 0.2 } else { 0.8 }, k % 7 == 0);
    }
    assert_eq!(set.divergences(), 1);
    assert_eq!(set.learner("p").unwrap().weights(), &weights[..]);
    // Reset: it learns again.
    set.reset();
    assert_eq!(set.diverged().count(), 0);
    tick(&mut set, 0.2, false);
    assert!(tick(&mut set, 0.8, true).1.is_some());
    // δ = R = 1 with γ = 0 on the stimulus, α = 1: feature 0 (u = 0.2) now predicts it exactly.
    assert_eq!(set.learner("p").unwrap().weights(), &[1.0, 0.0]);
}

#[test]
fn at_the_step_size_bound_the_weights_stay_bounded() {
    // 8 inputs tiled in 4: 8 active features, α = 1/8 (the bound); a random stream with stimuli.
    let n = names(&["a", "b", "c", "d", "e", "f", "g", "h"], &["s"]);
    let mut s = spec(25.0, 0.9, 1.0 / 8.0, Sigma::Identity, 0.0, 4);
    s.features = FeatureSpec::OneDim {
        all_obs: false,
        inputs: ["a", "b", "c", "d", "e", "f", "g", "h"]
            .map(String::from)
            .to_vec(),
        tiles: 4,
        tilings: 1,
    };
    s.cumulant = Cumulant::Stimulus("s".into());
    let mut set = PredictionSet::new(vec![s], &n).unwrap();
    let mut rng = Rng::new(5);
    for _ in 0..20_000 {
        let x: Vec<f64> = (0..8).map(|_| rng.next_f64()).collect();
        set.predict(&FeatureInputs {
            obs: &[],
            extra: &x,
        });
        set.learn(&[rng.chance(0.05)]).unwrap();
    }
    assert_eq!(set.divergences(), 0);
    let w = set.learner("p").unwrap().weights();
    // The return is at most 1; the weights of 8 features summing to it stay small.
    assert!(w.iter().all(|v| v.abs() < 2.0), "{w:?}");
}
