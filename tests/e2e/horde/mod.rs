//! The Horde (`[horde]`) through the whole server: it learns and `/metrics` shows it
//! ([`learning`]); its checkpoints are written with the run's and resumed, and a mismatching or
//! corrupted one starts it afresh while the server runs on ([`resume`]); and control is exactly the
//! same with a Horde, even one so large that it skips ticks ([`control`]); every learner a family can
//! name is checkpointed and resumed ([`learners`]).

mod control;
mod learners;
mod learning;
mod resume;

use std::time::{Duration, Instant};

use pavlov::config::Config;
use pavlov::learn::group::Weight;
use pavlov::learn::{Horde, HordeSnapshot, TickSignals};
use pavlov_actors::horde::status::HordeStatus;
use tokio::sync::watch;

/// How long a test waits, in wall-clock time, for the Horde to learn what it needs.
pub const LEARNING_PATIENCE: Duration = Duration::from_secs(180);

/// Waits until `status` says the Horde has learned at least `ticks` ticks (it says so every 25), and
/// returns its status then.
///
/// The Horde runs under `SCHED_IDLE` (the default, which the tests keep): it gets the CPU only when no
/// normal thread wants it, so on a busy machine it learns slowly and skips the ticks it is too busy for
/// (counted), while control is untouched. What is guaranteed is that it learns, not how many of the ticks
/// fired it learns: a test waits for the ticks it needs learned, under a generous wall-clock bound
/// ([`LEARNING_PATIENCE`]), rather than expecting a share of wall time. Under the paused clock the server
/// goes on ticking while this waits.
pub async fn learned(status: &mut watch::Receiver<HordeStatus>, ticks: u64) -> HordeStatus {
    let deadline = Instant::now() + LEARNING_PATIENCE;
    loop {
        let now = status.borrow_and_update().clone();
        if now.ticks_learned >= ticks {
            return now;
        }
        assert!(
            Instant::now() < deadline,
            "the Horde learned {} ticks ({} skipped) in {LEARNING_PATIENCE:?}; {ticks} wanted",
            now.ticks_learned,
            now.skipped_busy
        );
        // Wakes at least every 100 ms (virtual under the paused clock) to look at the wall clock.
        let _ = tokio::time::timeout(Duration::from_millis(100), status.changed()).await;
    }
}

/// A small Horde over a coarse tiling (176 features, 44 active, so a large α fits): every observation,
/// the stall stimulus and a bias at two timescales.
pub fn small_horde(taus: &str) -> String {
    format!(
        r#"
[horde]
precision = "f32"
[[horde.families]]
name = "probe"
cumulants = ["obs/*", "stimulus/*", "bias"]
taus = {taus}
lambda = 0.0
alpha = 0.01
features = {{ kind = "one_dim", all_obs = true, tiles = 4 }}
"#
    )
}

/// The shipped stall configuration's text.
pub fn stall_text() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
        .expect("config/stall.toml")
}

/// The stall configuration with `horde` appended (TOML).
pub fn stall_with(horde: &str) -> Config {
    Config::from_toml(&format!("{}\n{horde}", stall_text())).expect("valid configuration")
}

/// The value of prediction `name` of a Horde of `cfg`'s families restored from `snapshot` (or fresh),
/// after one step on a fixed mid-range input.
pub fn probe_value<W: Weight>(
    cfg: &Config,
    snapshot: Option<&HordeSnapshot<W>>,
    name: &str,
) -> f32 {
    let mut horde: Horde<W> = Horde::new(cfg.horde.families.clone(), &cfg.signal_names()).unwrap();
    if let Some(s) = snapshot {
        horde.restore_snapshot(s).unwrap();
    }
    let dims = cfg.signal_names().obs.len();
    let obs = vec![0.5; dims];
    horde.step(&TickSignals {
        obs: &obs,
        raw: &obs,
        extra: &[],
        stimuli: &[false],
    });
    let mut values = Vec::new();
    horde.values_into(&mut values);
    let i = horde
        .predictions()
        .iter()
        .position(|p| p.name == name)
        .unwrap_or_else(|| panic!("no prediction {name}"));
    values[i]
}
