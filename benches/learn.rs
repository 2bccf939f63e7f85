//! Benchmarks of one learning step (tile coding + prediction + TD(λ) update) at the paper's two sizes:
//! - stall: 44 observation dimensions × 10 tiles = 440 features, 44 active, identity σ, λ = 0.5;
//! - command: 5 pair tilings × 100 tiles = 500 features, 5 active, logistic σ, λ = 0.8.
//!
//! Each is measured five ways: through [`PredictionSet`] (gather inputs, tile, predict, learn, and the
//! per-tick output vector, i.e. what the learning actor pays per tick); on the bare step that runs
//! (`step/`: [`TileCoder::active`] + the [`TdLearner`] the set picks for the shape, predict and learn, no
//! allocation); on the same step with each learner it picks from (`dense/`: [`DenseTd`]; `group/`:
//! [`TraceGroup`], a group of one, the Horde's deferred learner) and with the dense reference
//! (`reference/`: [`TdLambda`], which also checks every weight for overflow before each step).
//! Inputs cycle through 1024 random ticks drawn beforehand from a seeded generator.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use pavlov::learn::set::TdLearner;
use pavlov::learn::{
    Column, Cumulant, DenseTd, FeatureInputs, FeatureSpec, PairSpec, PredictionSet, PredictionSpec,
    Sigma, SignalNames, TdLambda, TdParams, Threshold, TileCoder, TraceGroup,
};
use pavlov::obs::ObsLayout;
use pavlov::oi::Model;
use pavlov::rng::Rng;

const TICKS: usize = 1024;
const ELBOWS: [&str; 4] = [
    "left_elbow",
    "left_elbow_avg",
    "right_elbow",
    "right_elbow_avg",
];

fn stall_spec() -> PredictionSpec {
    PredictionSpec {
        name: "stall".into(),
        tau: 25.0,
        lambda: 0.5,
        alpha: 1.0 / 44.0,
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
    }
}

fn command_spec() -> PredictionSpec {
    let pair = |x: &str, y: &str, offset| PairSpec {
        x: x.into(),
        y: y.into(),
        offset,
    };
    PredictionSpec {
        name: "command".into(),
        tau: 25.0,
        lambda: 0.8,
        alpha: 0.1 / 5.0,
        sigma: Sigma::Logistic,
        initial_weight: -1.0,
        threshold: Threshold::Steps(15),
        features: FeatureSpec::Pairs {
            pairs: vec![
                pair("left_elbow", "left_elbow_avg", 0.0),
                pair("left_elbow", "left_elbow_avg", 0.5),
                pair("right_elbow", "right_elbow_avg", 0.0),
                pair("right_elbow", "right_elbow_avg", 0.5),
                pair("left_elbow", "right_elbow", 0.0),
            ],
            tiles: 10,
        },
        cumulant: Cumulant::Stimulus("left_elbow_command".into()),
        learner: Default::default(),
        target_policy: None,
        beta: None,
    }
}

/// `TICKS` random input vectors of length `len` and stimuli with probability `p`.
fn stream(len: usize, p: f64, seed: u64) -> (Vec<Vec<f64>>, Vec<bool>) {
    let mut rng = Rng::new(seed);
    let mut x: Vec<f64> = (0..len).map(|_| rng.next_f64()).collect();
    let inputs = (0..TICKS)
        .map(|_| {
            for v in &mut x {
                if rng.chance(0.05) {
                    *v = rng.next_f64();
                }
            }
            x.clone()
        })
        .collect();
    let stimuli = (0..TICKS).map(|_| rng.chance(p)).collect();
    (inputs, stimuli)
}

fn bench_set(c: &mut Criterion, label: &str, spec: PredictionSpec, obs_len: usize, extra: bool) {
    let layout = ObsLayout::for_model(Model::Create1);
    let names = SignalNames::for_layout(&layout, &ELBOWS, &["stall", "left_elbow_command"]);
    let mut set = PredictionSet::new(vec![spec], &names).expect("valid spec");
    let (inputs, stimuli) = stream(if extra { 4 } else { obs_len }, 0.05, 1);
    let obs = vec![0.5; obs_len];
    let mut t = 0;
    c.bench_function(label, |b| {
        b.iter(|| {
            let x = &inputs[t % TICKS];
            let feature_inputs = if extra {
                FeatureInputs {
                    obs: &obs,
                    extra: x,
                }
            } else {
                FeatureInputs { obs: x, extra: &[] }
            };
            let out = set.predict(black_box(&feature_inputs));
            let stim = [stimuli[t % TICKS], stimuli[t % TICKS]];
            let delta = set.learn(&stim).expect("two stimuli");
            t += 1;
            black_box((out, delta))
        })
    });
}

/// Times `step` (given a tick's active features and its stimulus) after the tile coding of each tick.
fn bench_ticks(
    c: &mut Criterion,
    label: &str,
    coder: &TileCoder,
    len: usize,
    mut step: impl FnMut(&[usize], bool) -> (f64, f64),
) {
    let (inputs, stimuli) = stream(len, 0.05, 2);
    let mut x = Vec::with_capacity(coder.num_tilings());
    let mut t = 1;
    c.bench_function(label, |b| {
        b.iter(|| {
            coder.active(black_box(&inputs[t % TICKS]), &mut x);
            let out = step(&x, stimuli[t % TICKS]);
            t += 1;
            black_box(out)
        })
    });
}

fn gamma(stimulus: bool) -> f64 {
    if stimulus { 0.0 } else { 0.96 }
}

fn column(params: &TdParams) -> Column {
    Column {
        alpha: params.alpha,
        initial_weight: params.initial_weight,
    }
}

/// What the set runs for the shape: [`TdLearner`].
fn bench_step(c: &mut Criterion, label: &str, coder: &TileCoder, params: TdParams, len: usize) {
    let (n, tilings) = (coder.num_features(), coder.num_tilings());
    let mut td = TdLearner::new(n, tilings, params.lambda, params.sigma, column(&params))
        .expect("valid params");
    bench_ticks(c, label, coder, len, |x, e| {
        let v = td.predict_value(x);
        let delta = td.learn(gamma(e), f64::from(u8::from(e)));
        (v, delta.unwrap_or(f64::NAN))
    });
}

/// The dense learner alone, whatever the shape.
fn bench_dense(c: &mut Criterion, label: &str, coder: &TileCoder, params: TdParams, len: usize) {
    let n = coder.num_features();
    let mut td =
        DenseTd::new(n, params.lambda, params.sigma, column(&params)).expect("valid params");
    bench_ticks(c, label, coder, len, |x, e| {
        td.predict(x);
        let delta = td.learn(gamma(e), f64::from(u8::from(e)));
        (td.value(), delta.expect("predicted first"))
    });
}

/// The deferred group of one alone, whatever the shape.
fn bench_group(c: &mut Criterion, label: &str, coder: &TileCoder, params: TdParams, len: usize) {
    let n = coder.num_features();
    let mut group: TraceGroup<f64> =
        TraceGroup::new(n, params.lambda, params.sigma, vec![column(&params)])
            .expect("valid params");
    let mut delta = [0.0];
    bench_ticks(c, label, coder, len, |x, e| {
        let v = params.sigma.value(group.predict(x)[0]);
        group
            .learn(gamma(e), &[f64::from(u8::from(e))], &mut delta)
            .expect("one cumulant");
        (v, delta[0])
    });
}

fn bench_reference(
    c: &mut Criterion,
    label: &str,
    coder: &TileCoder,
    params: TdParams,
    len: usize,
) {
    let mut td = TdLambda::new(coder.num_features(), params).expect("valid params");
    let mut x_prev: Vec<usize> = Vec::with_capacity(coder.num_tilings());
    let mut gamma_prev = 0.96;
    bench_ticks(c, label, coder, len, |x, e| {
        let v = td.predict(x);
        let delta = td.update(&x_prev, gamma_prev, f64::from(u8::from(e)), gamma(e), x);
        x_prev.clear();
        x_prev.extend_from_slice(x);
        gamma_prev = gamma(e);
        (v, delta)
    });
}

fn bench_tiles(c: &mut Criterion, label: &str, coder: &TileCoder, len: usize) {
    bench_ticks(c, label, coder, len, |x, _| (x.len() as f64, 0.0));
}

fn learning_step(c: &mut Criterion) {
    bench_set(c, "set/stall_440_44_identity_l0.5", stall_spec(), 44, false);
    bench_set(
        c,
        "set/command_500_5_logistic_l0.8",
        command_spec(),
        44,
        true,
    );
    let stall = stall_spec().td_params();
    let stall_coder = TileCoder::one_dim(44, 10).expect("valid");
    let command = command_spec().td_params();
    let pairs = vec![
        (0, 1, 0.0),
        (0, 1, 0.5),
        (2, 3, 0.0),
        (2, 3, 0.5),
        (0, 2, 0.0),
    ];
    let command_coder = TileCoder::pairs(pairs, 10).expect("valid");
    bench_tiles(c, "tiles/stall_440_44", &stall_coder, 44);
    bench_tiles(c, "tiles/command_500_5", &command_coder, 4);
    bench_step(
        c,
        "step/stall_440_44_identity_l0.5",
        &stall_coder,
        stall,
        44,
    );
    bench_step(
        c,
        "step/command_500_5_logistic_l0.8",
        &command_coder,
        command,
        4,
    );
    bench_dense(
        c,
        "dense/stall_440_44_identity_l0.5",
        &stall_coder,
        stall,
        44,
    );
    bench_dense(
        c,
        "dense/command_500_5_logistic_l0.8",
        &command_coder,
        command,
        4,
    );
    bench_group(
        c,
        "group/stall_440_44_identity_l0.5",
        &stall_coder,
        stall,
        44,
    );
    bench_group(
        c,
        "group/command_500_5_logistic_l0.8",
        &command_coder,
        command,
        4,
    );
    bench_reference(
        c,
        "reference/stall_440_44_identity_l0.5",
        &stall_coder,
        stall,
        44,
    );
    bench_reference(
        c,
        "reference/command_500_5_logistic_l0.8",
        &command_coder,
        command,
        4,
    );
}

criterion_group!(benches, learning_step);
criterion_main!(benches);
