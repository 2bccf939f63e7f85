//! Tests of the named learners (`learner = "xent" | "linear" | "true_online" | "autostep"`) inside a
//! [`PredictionSet`]: the keys parse and are checked, the set runs each learner step for step as the bare
//! learner does, and a snapshot carries the learner's own state so that a restored set continues bit for
//! bit.

use super::*;
use crate::learn::Sigma;
use crate::learn::named::XentTd;
use crate::learn::spec::FeatureSpec;
use crate::rng::Rng;

fn spec(learner: LearnerKind, sigma: Sigma) -> PredictionSpec {
    PredictionSpec {
        name: "p".into(),
        tau: 4.0,
        lambda: 0.5,
        alpha: 0.1,
        sigma,
        initial_weight: if sigma == Sigma::Logistic { -1.0 } else { 0.0 },
        threshold: Threshold::Fixed(0.5),
        features: FeatureSpec::OneDim {
            all_obs: false,
            inputs: vec!["u".into()],
            tiles: 4,
            tilings: 1,
        },
        cumulant: Cumulant::Stimulus("e".into()),
        learner,
        target_policy: None,
        beta: None,
    }
}

fn set(learner: LearnerKind, sigma: Sigma) -> PredictionSet {
    let names = SignalNames {
        obs: vec![],
        extra: vec!["u".into()],
        stimuli: vec!["e".into()],
    };
    PredictionSet::new(vec![spec(learner, sigma)], &names).unwrap()
}

fn tick(set: &mut PredictionSet, (u, e): (f64, bool)) -> f64 {
    let out = set.predict(&FeatureInputs {
        obs: &[],
        extra: &[u],
    });
    set.learn(&[e]).unwrap();
    out[0].value
}

fn stream(n: usize, seed: u64) -> Vec<(f64, bool)> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| (rng.next_f64(), rng.chance(0.2))).collect()
}

#[test]
fn the_learner_key_parses_by_name_and_is_checked() {
    for (text, kind) in [
        ("paper", LearnerKind::Td),
        ("td", LearnerKind::Td),
        ("xent", LearnerKind::Xent),
        ("linear", LearnerKind::Linear),
        ("true_online", LearnerKind::TrueOnline),
        ("autostep", LearnerKind::Autostep),
    ] {
        assert_eq!(LearnerKind::from_name(text), Some(kind));
        #[derive(serde::Deserialize)]
        struct W {
            learner: LearnerKind,
        }
        let w: W = toml::from_str(&format!("learner = \"{text}\"")).unwrap();
        assert_eq!(w.learner, kind, "{text}");
    }
    assert_eq!(LearnerKind::Td.name(), "paper");
    assert_eq!(LearnerKind::from_name("sarsa"), None);
    // The linear learners refuse a logistic output, by name.
    for kind in [LearnerKind::Linear, LearnerKind::TrueOnline] {
        match spec(kind, Sigma::Logistic).validate() {
            Err(LearnError::OutOfBounds { field, bound, .. }) => {
                assert_eq!(field, "sigma");
                assert!(bound.contains(kind.name()), "{bound}");
            }
            other => panic!("{other:?}"),
        }
        spec(kind, Sigma::Identity).validate().unwrap();
    }
    spec(LearnerKind::Xent, Sigma::Logistic).validate().unwrap();
    let mut with_beta = spec(LearnerKind::Xent, Sigma::Logistic);
    with_beta.beta = Some(0.01);
    assert!(with_beta.validate().is_err());
}

#[test]
fn the_set_runs_xent_as_the_bare_learner_does() {
    let mut s = set(LearnerKind::Xent, Sigma::Logistic);
    let coder = s.coder("p").unwrap().clone();
    let p = spec(LearnerKind::Xent, Sigma::Logistic);
    let mut bare = XentTd::new(4, p.td_params());
    let mut prev: Option<(Vec<usize>, f64)> = None;
    let mut x = Vec::new();
    for (u, e) in stream(500, 3) {
        coder.active(&[u], &mut x);
        let v = tick(&mut s, (u, e));
        assert_eq!(v, bare.predict(&x));
        if let Some((xp, gp)) = &prev {
            bare.try_update(xp, *gp, p.reward(e), p.gamma(e), &x)
                .unwrap();
        }
        prev = Some((x.clone(), p.gamma(e)));
    }
    assert_eq!(
        s.named_learner("p").unwrap(),
        &crate::learn::Named::Xent(bare)
    );
    assert!(s.learner("p").is_none(), "not the paper's engine");
}

#[test]
fn the_paper_and_linear_learners_run_the_papers_engine() {
    let mut paper = set(LearnerKind::Td, Sigma::Identity);
    let mut linear = set(LearnerKind::Linear, Sigma::Identity);
    for t in stream(300, 5) {
        assert_eq!(tick(&mut paper, t), tick(&mut linear, t));
    }
    assert_eq!(paper.learner("p"), linear.learner("p"));
}

#[test]
fn a_snapshot_restores_each_named_learner_bit_for_bit() {
    for (kind, sigma) in [
        (LearnerKind::Xent, Sigma::Logistic),
        (LearnerKind::TrueOnline, Sigma::Identity),
        (LearnerKind::Autostep, Sigma::Logistic),
    ] {
        let data = stream(600, 9);
        let mut whole = set(kind, sigma);
        let mut first = set(kind, sigma);
        for &t in &data[..300] {
            tick(&mut whole, t);
            tick(&mut first, t);
        }
        let snap = first.snapshot();
        let text = serde_json::to_string(&snap).unwrap();
        let mut resumed = set(kind, sigma);
        resumed
            .restore(&serde_json::from_str(&text).unwrap())
            .unwrap();
        for &t in &data[300..] {
            assert_eq!(
                tick(&mut whole, t),
                tick(&mut resumed, t),
                "{}",
                kind.name()
            );
        }
        assert_eq!(whole.snapshot(), resumed.snapshot(), "{}", kind.name());
        // A snapshot of another learner is refused, and nothing changes.
        let mut other = set(LearnerKind::Td, sigma);
        if kind != LearnerKind::Xent {
            assert!(other.restore(&snap).is_err(), "{}", kind.name());
        }
    }
}
