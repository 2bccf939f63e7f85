//! Benchmarks of one Horde tick (every prediction, then every update) at nexting scale: 44 Create 1
//! observation dimensions tiled 11 times with 12 tiles (5,808 features, 484 active), every feature as a
//! cumulant at two timescales plus every observation at three (11,748 predictions, 68 M weights), in
//! `f32` and `f64`; and a 1,000-prediction Horde. Inputs: 1024 ticks in which each dimension changes with
//! probability 0.05 a tick (features persist, as a robot's do), drawn beforehand from a seeded generator.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use pavlov::learn::group::Weight;
use pavlov::learn::{FamilySpec, Horde, SignalNames, TickSignals};
use pavlov::obs::ObsLayout;
use pavlov::oi::Model;
use pavlov::rng::Rng;

const TICKS: usize = 1024;

fn families(feature_taus: &str) -> Vec<FamilySpec> {
    let text = format!(
        r#"
        [[f]]
        name = "nexting"
        cumulants = ["obs/*"]
        taus = [2.0, 10.0, 50.0]
        lambda = 0.9
        alpha = 0.0002
        features = {{ kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }}
        [[f]]
        name = "features"
        cumulants = ["features/*"]
        taus = {feature_taus}
        lambda = 0.9
        alpha = 0.0002
        features = {{ kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }}
        "#
    );
    #[derive(serde::Deserialize)]
    struct File {
        f: Vec<FamilySpec>,
    }
    toml::from_str::<File>(&text).expect("valid families").f
}

fn stream(dims: usize) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(7);
    let mut x: Vec<f64> = (0..dims).map(|_| rng.next_f64()).collect();
    (0..TICKS)
        .map(|_| {
            for v in &mut x {
                if rng.chance(0.05) {
                    *v = rng.next_f64();
                }
            }
            x.clone()
        })
        .collect()
}

fn bench_horde<W: Weight>(c: &mut Criterion, label: &str, families: Vec<FamilySpec>) {
    let layout = ObsLayout::for_model(Model::Create1);
    let names = SignalNames::for_layout(&layout, &[], &["stall"]);
    let mut horde: Horde<W> = Horde::new(families, &names).expect("fits");
    let inputs = stream(layout.len());
    let raw = vec![0.0; layout.len()];
    let mut t = 0;
    let shape = horde.shape();
    eprintln!(
        "{label}: {} predictions, {} weights, {} groups",
        shape.predictions, shape.weights, shape.groups
    );
    c.bench_function(label, |b| {
        b.iter(|| {
            let stopped = horde.step(black_box(&TickSignals {
                obs: &inputs[t % TICKS],
                raw: &raw,
                extra: &[],
                stimuli: &[false],
            }));
            t += 1;
            black_box(stopped)
        })
    });
}

fn horde_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("horde");
    group.sample_size(20);
    drop(group);
    bench_horde::<f32>(
        c,
        "horde/1k_f32",
        families("[0.0]").into_iter().take(1).collect(),
    );
    bench_horde::<f32>(c, "horde/11748_f32", families("[10.0, 50.0]"));
    bench_horde::<f64>(c, "horde/11748_f64", families("[10.0, 50.0]"));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = horde_tick
}
criterion_main!(benches);
