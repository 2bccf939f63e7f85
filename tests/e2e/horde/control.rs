//! Control is untouched by a Horde: under the paused clock the same run with and without `[horde]`
//! gives exactly the same control tick records (observations, stimulus, every prediction of
//! `[[predictions]]`, the gate, the default action and the command), also with a Horde so large that
//! it cannot keep up and skips ticks (it must have skipped some, or the test shows nothing).

use pavlov::record::TickRecord;

use super::{learned, small_horde, stall_with};
use crate::common::run_sim;

/// What control decided on a tick.
#[derive(Debug, PartialEq)]
struct Control {
    seq: u64,
    obs: Vec<u32>,
    stimulus: bool,
    predictions: Vec<(String, u64, u64)>,
    gate: bool,
    default_action: String,
    command: String,
    safety_stop: String,
}

fn control(r: &TickRecord) -> Control {
    Control {
        seq: r.seq,
        obs: r.obs.iter().map(|v| v.to_bits()).collect(),
        stimulus: r.stimulus,
        predictions: r
            .predictions
            .iter()
            .map(|p| (p.name.clone(), p.value.to_bits(), p.threshold.to_bits()))
            .collect(),
        gate: r.gate,
        default_action: format!("{:?}", r.default_action),
        command: format!("{:?}", r.command),
        safety_stop: format!("{:?}", r.safety_stop),
    }
}

/// The control of `ticks` ticks of the stall configuration (seed 5) with `horde` appended, and the
/// Horde's final figures (ticks learned, skipped) if it has one. The server runs on (its records no
/// longer collected) until the Horde has learned `learn` ticks: under `SCHED_IDLE` on a busy machine it
/// may have learned none of the first `ticks` (see [`learned`]).
async fn run(horde: &str, ticks: usize, learn: u64) -> (Vec<Control>, Option<(u64, u64)>) {
    let mut cfg = stall_with(horde);
    cfg.sim.seed = 5;
    let (records, server) = run_sim(cfg, ticks).await;
    let mut status = server.horde().as_ref().map(|h| h.status.clone());
    if let Some(status) = &mut status {
        learned(status, learn).await;
    }
    server.shutdown().await;
    // The Horde publishes its final figures when it stops.
    let figures = status.map(|s| {
        let s = s.borrow();
        (s.ticks_learned, s.skipped_busy)
    });
    (records.iter().map(control).collect(), figures)
}

/// 5,808 features (484 active) and every one of them predicted at two timescales: 67 M weights,
/// far more than a debug build learns in the time the paused clock takes to run a tick.
const LARGE: &str = r#"
[horde]
precision = "f32"
[[horde.families]]
name = "features"
cumulants = ["features/*"]
taus = [5.0, 25.0]
lambda = 0.9
alpha = 0.0002
features = { kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }
"#;

#[tokio::test(start_paused = true)]
async fn control_is_the_same_with_a_horde_that_keeps_up_or_skips() {
    const TICKS: usize = 1500;
    let (plain, none) = run("", TICKS, 0).await;
    assert!(none.is_none());
    assert!(
        plain.iter().any(|c| c.gate),
        "the run must gate at least once"
    );
    assert!(plain.iter().any(|c| c.stimulus), "and stall at least once");

    let (small, figures) = run(&small_horde("[2.0, 10.0, 50.0]"), TICKS, 25).await;
    let (learned, _) = figures.expect("a Horde");
    assert!(learned > 0, "the small Horde learned");
    assert_eq!(small, plain, "control with a small Horde");

    // (The large Horde is not waited for: it skips ticks however fast the machine.)
    let (large, figures) = run(LARGE, TICKS, 0).await;
    let (learned, skipped) = figures.expect("a Horde");
    assert!(
        skipped > 0,
        "the large Horde must skip ticks for this test to show anything ({learned} learned)"
    );
    assert_eq!(
        large, plain,
        "control with a Horde that skipped {skipped} ticks"
    );
}
