//! Tests of off-policy (GTD(λ)) predictions inside a [`PredictionSet`]: ρ of the previous tick's action
//! gates the update, the set matches the bare learner step for step, and snapshots carry the secondary
//! weights so that a restored set continues bit for bit.

use super::*;
use crate::learn::Sigma;
use crate::learn::gtd::GtdParams;
use crate::learn::spec::{FeatureSpec, TargetPolicy};
use crate::rng::Rng;

fn gtd_spec(name: &str) -> PredictionSpec {
    PredictionSpec {
        name: name.into(),
        tau: 4.0,
        lambda: 0.5,
        alpha: 0.1,
        sigma: Sigma::Identity,
        initial_weight: 0.0,
        threshold: Threshold::Fixed(0.5),
        features: FeatureSpec::OneDim {
            all_obs: false,
            inputs: vec!["u".into()],
            tiles: 4,
            tilings: 1,
        },
        cumulant: Cumulant::Stimulus("e".into()),
        learner: LearnerKind::Gtd,
        target_policy: Some(TargetPolicy::Default),
        beta: Some(0.05),
    }
}

fn set() -> PredictionSet {
    let names = SignalNames {
        obs: vec![],
        extra: vec!["u".into()],
        stimuli: vec!["e".into()],
    };
    PredictionSet::new(vec![gtd_spec("off")], &names).unwrap()
}

/// A random stream: u uniform, E with probability 0.2, ρ ∈ {0, 1} at random.
fn stream(n: usize, seed: u64) -> Vec<(f64, bool, f64)> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let u = rng.next_f64();
            let e = rng.chance(0.2);
            let rho = if rng.chance(0.7) { 1.0 } else { 0.0 };
            (u, e, rho)
        })
        .collect()
}

fn tick(set: &mut PredictionSet, (u, e, rho): (f64, bool, f64)) -> f64 {
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[u],
    });
    set.learn_with_ratio(&[e], rho).unwrap();
    out[0].value
}

#[test]
fn the_set_runs_gtd_with_the_previous_ticks_ratio() {
    let mut s = set();
    let coder = s.coder("off").unwrap().clone();
    let mut bare = Gtd::new(
        4,
        GtdParams {
            alpha: 0.1,
            beta: 0.05,
            lambda: 0.5,
            initial_weight: 0.0,
        },
    )
    .unwrap();
    let spec = gtd_spec("off");
    let mut prev: Option<(Vec<usize>, f64)> = None;
    let mut x = Vec::new();
    for step in stream(500, 3) {
        tick(&mut s, step);
        let (u, e, rho) = step;
        coder.active(&[u], &mut x);
        if let Some((xp, gp)) = &prev {
            bare.try_update(xp, *gp, rho, spec.reward(e), spec.gamma(e), &x)
                .unwrap();
        }
        prev = Some((x.clone(), spec.gamma(e)));
    }
    let learned = s.off_policy_learner("off").unwrap();
    assert_eq!(learned.weights(), bare.weights());
    assert_eq!(learned.secondary(), bare.secondary());
    assert!(learned.secondary().iter().any(|&w| w != 0.0));
    assert!(s.learner("off").is_none(), "not a TD(λ) group");
}

#[test]
fn a_zero_ratio_leaves_the_prediction_alone() {
    let mut s = set();
    tick(&mut s, (0.1, false, 1.0));
    tick(&mut s, (0.9, true, 1.0));
    tick(&mut s, (0.1, false, 1.0));
    let theta = s.off_policy_learner("off").unwrap().weights().to_vec();
    assert_ne!(theta, vec![0.0; 4], "learned from followed transitions");
    // The transition out of the last tick was the response's (ρ = 0): θ does not move and the trace
    // is cut.
    tick(&mut s, (0.9, true, 0.0));
    let after = s.off_policy_learner("off").unwrap();
    assert_eq!(after.weights(), &theta[..]);
    assert_eq!(after.traces(), &[0.0; 4]);
}

#[test]
fn snapshots_carry_the_secondary_weights_and_continue_exactly() {
    let steps = stream(800, 9);
    let mut a = set();
    for &s in &steps[..400] {
        tick(&mut a, s);
    }
    let snap = a.snapshot();
    let p = &snap.predictions[0];
    assert_eq!(p.beta, Some(0.05));
    assert!(p.state.is_none());
    let secondary = p.secondary.clone().unwrap();
    assert_eq!(secondary, a.off_policy_learner("off").unwrap().secondary());
    // Through JSON, as checkpoints and recordings write it.
    let text = serde_json::to_string(&snap).unwrap();
    let back: crate::learn::SetSnapshot = serde_json::from_str(&text).unwrap();
    let mut b = set();
    b.restore(&back).unwrap();
    for &s in &steps[400..] {
        assert_eq!(tick(&mut a, s).to_bits(), tick(&mut b, s).to_bits());
    }
    assert_eq!(a.snapshot(), b.snapshot());

    // Without its secondary weights the snapshot is refused, and nothing changes.
    let before = b.snapshot();
    let mut bad = back.clone();
    bad.predictions[0].secondary = None;
    let e = b.restore(&bad).unwrap_err().to_string();
    assert!(e.contains("secondary"), "{e}");
    let mut bad = back.clone();
    bad.predictions[0].beta = Some(2.0); // above 1/‖x‖² = 1
    let e = b.restore(&bad).unwrap_err().to_string();
    assert!(e.contains("beta"), "{e}");
    assert_eq!(b.snapshot(), before);
}
