//! The Horde's `true_online` and `autostep` families against their single-prediction learners, their
//! grouping, their state through a snapshot, and the memory bound.

use super::tests::{family, names, stream};
use super::*;
use crate::learn::named::{AutostepTd, TrueOnlineTd};
use crate::learn::{Sigma, TdParams};

/// One tick of the test stream as the Horde's signals.
fn step<W: Weight>(h: &mut Horde<W>, (obs, raw, elbow, stall): &(Vec<f64>, Vec<f64>, f64, bool)) {
    h.step(&TickSignals {
        obs,
        raw,
        extra: &[*elbow],
        stimuli: &[*stall],
    });
}

const TRUE_ONLINE: &str = r#"
    name = "dutch"
    cumulants = ["obs/*", "bias", "stimulus/stall"]
    taus = [2.0, 8.0]
    lambda = 0.9
    alpha = 0.05
    terminate_on = "stall"
    learner = "true_online"
    features = { kind = "one_dim", all_obs = true, tiles = 4, tilings = 3 }
"#;

const AUTOSTEP: &str = r#"
    name = "auto"
    cumulants = ["obs/*", "bias", "input/elbow"]
    taus = [2.0, 8.0]
    lambda = 0.9
    alpha = 0.03
    learner = "autostep"
    features = { kind = "one_dim", all_obs = true, tiles = 4, tilings = 3 }
"#;

/// Every prediction of the Horde against one single learner each, fed the same transitions; returns
/// the largest difference of the values.
fn against_single<L>(
    h: &mut Horde<f64>,
    ticks: usize,
    seed: u64,
    mut single: Vec<L>,
    predict: impl Fn(&L, &[usize]) -> f64,
    update: impl Fn(&mut L, &[usize], f64, f64, f64, &[usize]),
) -> f64 {
    let coder = TileCoder::one_dim_offset(6, 4, 3).unwrap();
    let infos = h.predictions().to_vec();
    let (mut x_prev, mut x_now) = (Vec::new(), Vec::new());
    let mut gammas_prev = vec![0.0; infos.len()];
    let mut worst: f64 = 0.0;
    for (t, tick) in stream(ticks, seed).into_iter().enumerate() {
        step(h, &tick);
        let (obs, raw, elbow, stall) = &tick;
        let stimuli = [*stall];
        let signals = TickSignals {
            obs,
            raw,
            extra: &[*elbow],
            stimuli: &stimuli,
        };
        coder.active(obs, &mut x_now);
        let terminates = h.families()[0].terminate_on.is_some();
        for (i, info) in infos.iter().enumerate() {
            let gamma = if *stall && terminates {
                0.0
            } else {
                1.0 - 1.0 / info.tau
            };
            let r = signals.value(info.source, |k| x_now.contains(&k));
            let d = (predict(&single[i], &x_now) - h.value(i).unwrap()).abs();
            worst = worst.max(d);
            if t > 0 {
                update(&mut single[i], &x_prev, gammas_prev[i], r, gamma, &x_now);
            }
            gammas_prev[i] = gamma;
        }
        std::mem::swap(&mut x_prev, &mut x_now);
    }
    worst
}

fn params(alpha: f64, sigma: Sigma, initial_weight: f64) -> TdParams {
    TdParams {
        alpha,
        lambda: 0.9,
        sigma,
        initial_weight,
    }
}

#[test]
fn a_true_online_family_learns_what_its_single_learners_learn() {
    let mut h: Horde<f64> = Horde::new(vec![family(TRUE_ONLINE)], &names()).unwrap();
    // 6 obs + bias + stimulus at 2 timescales: one dutch group per τ.
    assert_eq!((h.shape().predictions, h.shape().groups), (16, 2));
    let n = TileCoder::one_dim_offset(6, 4, 3).unwrap().num_features();
    let single = (0..16)
        .map(|_| TrueOnlineTd::new(n, params(0.05, Sigma::Identity, 0.0)))
        .collect();
    let worst = against_single(
        &mut h,
        3000,
        21,
        single,
        |l, x| l.predict(x),
        |l, a, g, r, g1, b| {
            l.try_update(a, g, r, g1, b).unwrap();
        },
    );
    // The bias prediction at τ = 8 reaches 8: the group rounds differently (see `group::dutch`).
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn an_autostep_family_is_its_single_learners_bit_for_bit() {
    let mut logistic = family(AUTOSTEP);
    logistic.name = "auto_logistic".into();
    logistic.sigma = Sigma::Logistic;
    logistic.initial_weight = -1.0;
    logistic.cumulants = vec!["stimulus/stall".into(), "input/elbow".into()];
    let mut h: Horde<f64> = Horde::new(vec![family(AUTOSTEP), logistic], &names()).unwrap();
    // 8 + 2 cumulants at 2 timescales; Autostep's trace holds no σ′, so the logistic predictions of a
    // timescale share one group (a group has one σ): 4 groups.
    assert_eq!((h.shape().predictions, h.shape().groups), (20, 4));
    let n = TileCoder::one_dim_offset(6, 4, 3).unwrap().num_features();
    let single = h
        .predictions()
        .iter()
        .map(|p| {
            let f = &h.families()[p.family];
            AutostepTd::new(n, params(f.alpha, f.sigma, f.initial_weight))
        })
        .collect();
    let worst = against_single(
        &mut h,
        2000,
        22,
        single,
        |l, x| l.predict(x),
        |l, a, g, r, g1, b| {
            l.try_update(a, g, r, g1, b).unwrap();
        },
    );
    assert_eq!(worst, 0.0);
}

#[test]
fn true_online_groups_are_keyed_by_alpha_and_refuse_one_alpha_changed_alone() {
    let mut other = family(TRUE_ONLINE);
    other.name = "dutch_slow".into();
    other.alpha = 0.01;
    other.terminate_on = None;
    let mut same_alpha = other.clone();
    same_alpha.name = "dutch_slow_too".into();
    same_alpha.cumulants = vec!["input/elbow".into()];
    let mut h: Horde<f32> =
        Horde::new(vec![family(TRUE_ONLINE), other, same_alpha], &names()).unwrap();
    // τ 2 and 8 for the terminating family; τ 2 and 8 for the two others, which share α.
    assert_eq!(h.shape().groups, 4);
    let e = h.set_alpha("dutch/obs/d0@2", 0.01).unwrap_err().to_string();
    assert!(e.contains("dutch trace"), "{e}");
    // An Autostep prediction's step sizes restart from a new α.
    let mut a: Horde<f32> = Horde::new(vec![family(AUTOSTEP)], &names()).unwrap();
    a.set_alpha("auto/bias@2", 0.01).unwrap();
}

#[test]
fn new_learners_state_restores_through_a_snapshot_and_continues_exactly() {
    let mut paper = family(TRUE_ONLINE);
    paper.name = "paper".into();
    paper.learner = Default::default();
    let families = vec![paper, family(TRUE_ONLINE), family(AUTOSTEP)];
    let mut a: Horde<f32> = Horde::new(families.clone(), &names()).unwrap();
    let s = stream(1200, 23);
    let tick = |h: &mut Horde<f32>, t: &(Vec<f64>, Vec<f64>, f64, bool)| {
        step(h, t);
        let mut v = Vec::new();
        h.values_into(&mut v);
        v
    };
    for t in &s[..400] {
        tick(&mut a, t);
    }
    let at_start = a.state();
    assert!(at_start.groups.iter().any(|g| g.dutch.is_some()));
    assert!(at_start.groups.iter().any(|g| g.autostep));
    // Through JSON, as `HordeState` is written.
    let text = serde_json::to_string(&at_start).unwrap();
    let mut twin: Horde<f32> = Horde::new(families.clone(), &names()).unwrap();
    twin.restore(&serde_json::from_str(&text).unwrap()).unwrap();
    assert!(a.begin_snapshot());
    let mut t = 400;
    while !a.advance_snapshot(2) {
        tick(&mut a, &s[t]);
        t += 1;
    }
    let snap = a.take_snapshot().unwrap();
    for (state, values) in &snap.groups {
        assert_eq!(values.len(), state.value_count());
    }
    let mut b: Horde<f32> = Horde::new(families, &names()).unwrap();
    b.restore_snapshot(&snap).unwrap();
    assert_eq!(b.state(), at_start);
    for input in &s[400..] {
        let expected = tick(&mut twin, input);
        assert_eq!(tick(&mut b, input), expected);
    }
    // A state of one learner is refused by a group of another.
    let mut swapped = at_start.clone();
    swapped.groups.swap(0, 2);
    let mut c: Horde<f32> = Horde::new(a.families().to_vec(), &names()).unwrap();
    assert!(c.restore(&swapped).is_err());
}

#[test]
fn autostep_state_counts_against_the_hordes_memory_bound() {
    // 192,000 features × 8 cumulants × 64 timescales ≈ 9.8·10⁷ weights: within the bound of 2²⁸ as the
    // paper's learner; four times that, with Autostep's step sizes, h and v, is beyond it.
    let mut big = family(AUTOSTEP);
    big.learner = Default::default();
    big.features = FeatureSpec::OneDim {
        all_obs: true,
        inputs: vec![],
        tiles: 1000,
        tilings: 32,
    };
    big.alpha = 1e-3;
    big.taus = (2..66).map(f64::from).collect();
    let shape = check(&[big.clone()], &names()).unwrap();
    assert!(shape.weights <= MAX_HORDE_WEIGHTS && 4 * shape.weights > MAX_HORDE_WEIGHTS);
    big.learner = crate::learn::LearnerKind::Autostep;
    let e = check(&[big], &names()).unwrap_err();
    assert!(matches!(e, LearnError::AutostepStateTooLarge { .. }), "{e}");
    assert!(e.to_string().contains("autostep"), "{e}");
}
