//! The Horde against the dense reference and against the paper's prediction set.

use super::*;
use crate::learn::{
    Cumulant, PredictionSet, PredictionSpec, Sigma, SignalNames, TdLambda, TdParams, Threshold,
};
use crate::rng::Rng;

pub(super) fn names() -> SignalNames {
    SignalNames {
        obs: (0..6).map(|i| format!("d{i}")).collect(),
        extra: vec!["elbow".into()],
        stimuli: vec!["stall".into()],
    }
}

pub(super) fn family(text: &str) -> FamilySpec {
    toml::from_str(text).unwrap()
}

/// `ticks` ticks of 6 persistent observation dimensions (raw = 100 × scaled), one extra input and a
/// stall stimulus.
pub(super) fn stream(ticks: usize, seed: u64) -> Vec<(Vec<f64>, Vec<f64>, f64, bool)> {
    let mut rng = Rng::new(seed);
    let mut x: Vec<f64> = (0..6).map(|_| rng.next_f64()).collect();
    (0..ticks)
        .map(|_| {
            for v in &mut x {
                if rng.chance(0.1) {
                    *v = rng.next_f64();
                }
            }
            let raw = x.iter().map(|v| v * 100.0).collect();
            (x.clone(), raw, rng.next_f64(), rng.chance(0.03))
        })
        .collect()
}

const NEXTING: &str = r#"
    name = "n"
    cumulants = ["obs/*", "raw/d2", "bias", "features/*"]
    taus = [2.0, 8.0]
    lambda = 0.9
    alpha = 0.008
    terminate_on = "stall"
    features = { kind = "one_dim", all_obs = true, tiles = 4, tilings = 3 }
"#;

#[test]
fn a_family_expands_into_groups_by_timescale() {
    let h: Horde<f32> = Horde::new(vec![family(NEXTING)], &names()).unwrap();
    let shape = h.shape();
    // 6 obs + 1 raw + bias + 72 features = 80 cumulants, at 2 timescales.
    assert_eq!(shape.predictions, 160);
    assert_eq!((shape.groups, shape.feature_sets), (2, 1));
    assert_eq!(shape.active_features, 18);
    assert_eq!(shape.weights, 160 * 72);
    assert_eq!(h.predictions()[0].name, "n/obs/d0@2");
    assert_eq!(h.predictions()[1].name, "n/obs/d0@8");
    assert_eq!(h.index_of("n/feature/71@8"), Some(159));
}

#[test]
fn every_prediction_matches_its_own_dense_learner() {
    let mut h: Horde<f64> = Horde::new(vec![family(NEXTING)], &names()).unwrap();
    let coder = TileCoder::one_dim_offset(6, 4, 3).unwrap();
    let infos = h.predictions().to_vec();
    let mut dense: Vec<TdLambda> = infos
        .iter()
        .map(|_| {
            let p = TdParams {
                alpha: 0.008,
                lambda: 0.9,
                sigma: Sigma::Identity,
                initial_weight: 0.0,
            };
            TdLambda::new(coder.num_features(), p).unwrap()
        })
        .collect();
    let (mut x_prev, mut x_now) = (Vec::new(), Vec::new());
    let mut gammas_prev = vec![0.0; infos.len()];
    let mut worst: f64 = 0.0;
    for (t, (obs, raw, elbow, stall)) in stream(3000, 1).into_iter().enumerate() {
        let stimuli = [stall];
        let signals = TickSignals {
            obs: &obs,
            raw: &raw,
            extra: &[elbow],
            stimuli: &stimuli,
        };
        h.step(&signals);
        coder.active(&obs, &mut x_now);
        for (i, info) in infos.iter().enumerate() {
            let gamma = if stall { 0.0 } else { 1.0 - 1.0 / info.tau };
            let r = signals.value(info.source, |k| x_now.contains(&k));
            let v = dense[i].dot(&x_now);
            worst = worst.max((v - h.value(i).unwrap()).abs());
            if t > 0 {
                dense[i].update(&x_prev, gammas_prev[i], r, gamma, &x_now);
            }
            gammas_prev[i] = gamma;
        }
        std::mem::swap(&mut x_prev, &mut x_now);
    }
    // Values reach 100 (raw/d2 at τ = 8 sums up to ~800): 1e-9 relative.
    assert!(worst < 1e-7, "{worst}");
}

#[test]
fn the_papers_stall_prediction_as_a_family_equals_the_prediction_set_to_rounding() {
    let stall = family(
        r#"
        name = "paper"
        cumulants = ["stimulus/stall"]
        taus = [25.0]
        lambda = 0.5
        alpha = 0.16
        terminate_on = "stall"
        features = { kind = "one_dim", all_obs = true, tiles = 10 }
    "#,
    );
    let mut h: Horde<f64> = Horde::new(vec![stall], &names()).unwrap();
    let spec = PredictionSpec {
        name: "stall".into(),
        tau: 25.0,
        lambda: 0.5,
        alpha: 0.16,
        sigma: Sigma::Identity,
        initial_weight: 0.0,
        threshold: Threshold::Fixed(0.5),
        features: FeatureSpec::OneDim {
            all_obs: true,
            inputs: vec![],
            tiles: 10,
            tilings: 1,
        },
        cumulant: Cumulant::Stimulus("stall".into()),
        learner: Default::default(),
        target_policy: None,
        beta: None,
    };
    let mut set = PredictionSet::new(vec![spec], &names()).unwrap();
    let mut worst: f64 = 0.0;
    for (obs, raw, _, stall) in stream(3000, 2) {
        let out = set.predict(&FeatureInputs {
            obs: &obs,
            extra: &[],
        });
        set.learn(&[stall]).unwrap();
        h.step(&TickSignals {
            obs: &obs,
            raw: &raw,
            extra: &[],
            stimuli: &[stall],
        });
        // The set runs the stall prediction dense, the Horde deferred: the same update, rounded
        // differently.
        let (a, b) = (out[0].value, h.value(0).unwrap());
        worst = worst.max((a - b).abs());
        assert!((a - b).abs() < 1e-9, "{a} against {b}");
    }
    assert!(
        worst > 0.0,
        "the two learners are different code: some rounding shows"
    );
}

#[test]
fn a_bias_prediction_learns_its_timescale() {
    // Σ_k γ^k · 1 = 1 / (1 − γ) = τ: the value a constant cumulant must reach.
    let f = family(
        r#"
        name = "b"
        cumulants = ["bias"]
        taus = [5.0, 20.0]
        lambda = 0.5
        alpha = 0.05
        features = { kind = "one_dim", all_obs = true, tiles = 2 }
    "#,
    );
    let mut h: Horde<f32> = Horde::new(vec![f], &names()).unwrap();
    for (obs, raw, _, _) in stream(20_000, 3) {
        h.step(&TickSignals {
            obs: &obs,
            raw: &raw,
            extra: &[],
            stimuli: &[false],
        });
    }
    let (five, twenty) = (h.value(0).unwrap(), h.value(1).unwrap());
    assert!((five - 5.0).abs() < 0.05, "{five}");
    assert!((twenty - 20.0).abs() < 0.2, "{twenty}");
}

#[test]
fn logistic_predictions_get_a_trace_each_and_families_share_features() {
    let a = family(
        r#"
        name = "a"
        cumulants = ["stimulus/stall", "input/elbow"]
        taus = [10.0]
        lambda = 0.8
        alpha = 0.1
        sigma = "logistic"
        initial_weight = -1.0
        features = { kind = "one_dim", all_obs = true, tiles = 4 }
    "#,
    );
    let mut b = family(NEXTING);
    b.features = a.features.clone();
    b.alpha = 0.1;
    b.cumulants = vec!["obs/d0".into()];
    let h: Horde<f64> = Horde::new(vec![a, b], &names()).unwrap();
    let shape = h.shape();
    assert_eq!(shape.predictions, 4);
    assert_eq!(shape.feature_sets, 1, "one tile coding for both families");
    assert_eq!(shape.groups, 4, "two logistic predictions, two timescales");
}

#[test]
fn sizes_and_names_are_checked_before_anything_is_allocated() {
    let mut huge = family(NEXTING);
    huge.features = FeatureSpec::OneDim {
        all_obs: true,
        inputs: vec![],
        tiles: 1000,
        tilings: 64,
    };
    huge.alpha = 1e-7;
    huge.taus = vec![2.0; 64];
    let e = Horde::<f32>::new(vec![huge], &names()).unwrap_err();
    assert!(
        matches!(
            e,
            LearnError::TooManyPredictions { .. } | LearnError::TooManyFeaturesInAll { .. }
        ),
        "{e}"
    );
    let mut twice = family(NEXTING);
    twice.cumulants = vec!["obs/d0".into()];
    let e = Horde::<f32>::new(vec![twice.clone(), twice], &names()).unwrap_err();
    assert_eq!(e, LearnError::DuplicatePrediction("n".into()));
    let mut stim = family(NEXTING);
    stim.terminate_on = Some("bump".into());
    assert!(matches!(
        Horde::<f32>::new(vec![stim], &names()),
        Err(LearnError::UnknownStimulus { .. })
    ));
}

#[test]
fn a_state_restores_bit_for_bit_and_a_foreign_one_is_refused() {
    let f = family(NEXTING);
    let mut a: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
    let s = stream(2000, 4);
    let step = |h: &mut Horde<f32>, (obs, raw, e, stall): &(Vec<f64>, Vec<f64>, f64, bool)| {
        h.step(&TickSignals {
            obs,
            raw,
            extra: &[*e],
            stimuli: &[*stall],
        });
        let mut v = Vec::new();
        h.values_into(&mut v);
        v
    };
    for t in &s[..1000] {
        step(&mut a, t);
    }
    let mut b: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
    b.restore(&a.state()).unwrap();
    for t in &s[1000..] {
        assert_eq!(step(&mut a, t), step(&mut b, t));
    }
    let mut other = f;
    other.lambda = 0.5;
    let mut c: Horde<f32> = Horde::new(vec![other], &names()).unwrap();
    assert!(c.restore(&a.state()).is_err());
}

#[test]
fn alpha_changes_are_bounded_per_family() {
    let mut h: Horde<f32> = Horde::new(vec![family(NEXTING)], &names()).unwrap();
    h.set_alpha("n/obs/d1@8", 0.05).unwrap();
    let e = h.set_alpha("n/obs/d1@8", 0.1).unwrap_err().to_string();
    assert!(e.contains("exceeds 1/18"), "{e}");
    assert!(h.set_alpha("n/obs/nope@8", 0.01).is_err());
}

#[test]
fn a_snapshot_copied_while_learning_restores_the_state_when_it_began() {
    let f = family(NEXTING);
    let mut a: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
    let s = stream(1500, 5);
    let tick = |h: &mut Horde<f32>, (obs, raw, e, stall): &(Vec<f64>, Vec<f64>, f64, bool)| {
        h.step(&TickSignals {
            obs,
            raw,
            extra: &[*e],
            stimuli: &[*stall],
        });
        let mut v = Vec::new();
        h.values_into(&mut v);
        v
    };
    for t in &s[..500] {
        tick(&mut a, t);
    }
    let at_start = a.state();
    let mut twin: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
    twin.restore(&at_start).unwrap();
    assert!(a.begin_snapshot());
    // 2 groups × 72 rows, 2 rows a tick (and the rows each tick writes).
    let mut t = 500;
    while !a.advance_snapshot(2) {
        tick(&mut a, &s[t]);
        t += 1;
    }
    assert!(t > 505, "{t}");
    let snap = a.take_snapshot().unwrap();
    let mut b: Horde<f32> = Horde::new(vec![f], &names()).unwrap();
    b.restore_snapshot(&snap).unwrap();
    assert_eq!(b.state(), at_start);
    for tick_input in &s[500..] {
        assert_eq!(tick(&mut b, tick_input), tick(&mut twin, tick_input));
    }
}

#[test]
fn snapshots_into_prepared_and_returned_buffers_are_exact_and_reuse_the_memory() {
    let f = family(NEXTING);
    let mut a: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
    a.prepare_snapshot_buffers();
    let s = stream(900, 9);
    let mut at = Vec::new();
    for round in 0..2 {
        for (obs, raw, e, stall) in &s[round * 300..round * 300 + 300] {
            a.step(&TickSignals {
                obs,
                raw,
                extra: &[*e],
                stimuli: &[*stall],
            });
        }
        let expected = a.state();
        assert!(a.begin_snapshot());
        while !a.advance_snapshot(5) {}
        let snap = a.take_snapshot().unwrap();
        let mut b: Horde<f32> = Horde::new(vec![f.clone()], &names()).unwrap();
        b.restore_snapshot(&snap).unwrap();
        assert_eq!(b.state(), expected, "round {round}");
        let ptrs: Vec<*const f32> = snap.groups.iter().map(|(_, w)| w.as_ptr()).collect();
        at.push(ptrs);
        a.keep_snapshot_buffers(snap);
    }
    assert_eq!(
        at[0], at[1],
        "the second snapshot is copied into the first one's memory"
    );
}

#[test]
fn the_one_pass_step_is_bit_for_bit_the_two_pass_step() {
    // Families like config/horde.toml's at a smaller size: every observation, the stimulus and a bias
    // and every feature as cumulants, over one tile coding; a terminating family (γ = 0 on the stall).
    let families = vec![
        family(
            r#"name = "nexting"
            cumulants = ["obs/*", "stimulus/*", "bias"]
            taus = [2.0, 5.0, 25.0]
            lambda = 0.9
            alpha = 0.002
            features = { kind = "one_dim", all_obs = true, tiles = 8, tilings = 4 }"#,
        ),
        family(
            r#"name = "features"
            cumulants = ["features/*"]
            taus = [5.0, 25.0]
            lambda = 0.9
            alpha = 0.002
            features = { kind = "one_dim", all_obs = true, tiles = 8, tilings = 4 }"#,
        ),
        family(
            r#"name = "until_stall"
            cumulants = ["obs/*"]
            taus = [10.0]
            lambda = 0.7
            alpha = 0.01
            terminate_on = "stall"
            features = { kind = "one_dim", all_obs = true, tiles = 8, tilings = 4 }"#,
        ),
    ];
    let mut one: Horde<f32> = Horde::new(families, &names()).unwrap();
    let mut two = one.clone();
    let (mut v1, mut v2) = (Vec::new(), Vec::new());
    for (obs, raw, elbow, stall) in stream(1500, 11) {
        let extra = [elbow];
        let stimuli = [stall];
        let signals = TickSignals {
            obs: &obs,
            raw: &raw,
            extra: &extra,
            stimuli: &stimuli,
        };
        assert_eq!(one.step(&signals), two.step_two_passes(&signals));
        one.values_into(&mut v1);
        two.values_into(&mut v2);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&v1), bits(&v2));
    }
    assert_eq!(one.state(), two.state());
}
