//! Every learner a Horde family can name through the server (`config/horde-learners.toml`: `paper`,
//! `xent`, `true_online`, `autostep`): the running server's Horde checkpoint holds the true-online groups'
//! V_old and the Autostep group's step sizes, h and v, and `--resume` continues from them.
//!
//! As in [`super::resume`], the Horde runs under `SCHED_IDLE` and may learn little of a run on a busy
//! machine, so the state resumed from is learned by the test itself and written as the newest checkpoint.

use pavlov::config::Config;
use pavlov::learn::{Horde, HordeSnapshot};
use pavlov_actors::storage::horde_file;

use super::resume::{horde_files, learned_snapshot, run, run_with_records};
use crate::storage::fixtures::fresh_dir;

/// Each group's weights (the first block of its values: an Autostep group's step sizes, h and v follow).
fn weights(snapshot: &HordeSnapshot<f32>) -> Vec<Vec<f64>> {
    snapshot
        .groups
        .iter()
        .map(|(state, values)| {
            let n = state.coef.len() * state.a.len();
            values[..n].iter().map(|&w| f64::from(w)).collect()
        })
        .collect()
}

fn distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[tokio::test(start_paused = true)]
async fn every_horde_learner_is_checkpointed_and_resumed() {
    let dir = fresh_dir("horde-learners");
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/horde-learners.toml"
    ))
    .expect("config/horde-learners.toml");
    let mut cfg = Config::from_toml(&text).expect("valid configuration");
    cfg.checkpoint.dir = dir.display().to_string();
    cfg.checkpoint.every_s = 2;
    cfg.checkpoint.keep = 2;
    cfg.checkpoint.autosave = true;
    let (first_run, records) = run_with_records(cfg.clone(), 250).await;
    let newest = horde_files(&first_run)
        .pop()
        .expect("a Horde checkpoint in the run's folder");
    // What the server wrote reads back, with every learner's own state.
    let (tick, written) = horde_file::read::<f32>(&newest).expect("the server's checkpoint reads");
    assert_eq!(written.families, cfg.horde.families);
    assert!(written.groups.iter().any(|(s, _)| s.dutch.is_some()));
    let (autostep, values) = written
        .groups
        .iter()
        .find(|(s, _)| s.autostep)
        .expect("an Autostep group");
    assert_eq!(values.len(), 4 * autostep.coef.len() * autostep.a.len());

    // A Horde that learned every tick of the run, as the newest checkpoint.
    let learned = learned_snapshot(&cfg, &records);
    horde_file::write_atomic(&first_run, tick, &learned).unwrap();
    let mut fresh: Horde<f32> =
        Horde::new(cfg.horde.families.clone(), &cfg.signal_names()).unwrap();
    assert!(fresh.begin_snapshot());
    while !fresh.advance_snapshot(1 << 20) {}
    let initial = weights(&fresh.take_snapshot().unwrap());
    let before = weights(&learned);
    let learned_distance = distance(&before, &initial);
    assert!(
        learned_distance > 1.0,
        "the test's Horde learned: {learned_distance}"
    );

    let mut resumed = cfg.clone();
    resumed.checkpoint.resume = true;
    resumed.checkpoint.every_s = 0;
    let second_run = run(resumed, 3).await;
    let (_, continued) =
        horde_file::read::<f32>(horde_files(&second_run).last().expect("a last checkpoint"))
            .unwrap();
    // Resumed, not reset: only what the second run's few ticks taught on top of what was written. Checked
    // for every group that learned far from its initial weights in the first run (the linear ones: a
    // logistic prediction of a rare stall learns little in 250 ticks), which must include the true-online
    // and the Autostep groups.
    let (mut dutch_checked, mut autostep_checked) = (0, 0);
    for (g, ((state, _), (w_after, (w_before, w_initial)))) in continued
        .groups
        .iter()
        .zip(weights(&continued).iter().zip(before.iter().zip(&initial)))
        .enumerate()
    {
        let learned = distance(
            std::slice::from_ref(w_before),
            std::slice::from_ref(w_initial),
        );
        if learned < 1.0 {
            continue;
        }
        let moved = distance(
            std::slice::from_ref(w_after),
            std::slice::from_ref(w_before),
        );
        assert!(
            moved < 0.5 * learned,
            "group {g} (autostep: {}, true online: {}): moved {moved} from the resumed weights, which \
             are {learned} from the initial ones",
            state.autostep,
            state.dutch.is_some()
        );
        dutch_checked += usize::from(state.dutch.is_some());
        autostep_checked += usize::from(state.autostep);
    }
    assert!(
        dutch_checked > 0 && autostep_checked > 0,
        "{dutch_checked} true-online and {autostep_checked} Autostep groups learned enough to check"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
