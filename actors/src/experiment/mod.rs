//! The paper's experiments, reproduced on the simulated Create through the real actor runtime.
//!
//! Every experiment is a folder that plans interleaved runs (run 0 reactive, run 1 Pavlovian, …), hands
//! each to the one `runner` (the server's stages under a paused clock — on the actors, or stepped in order
//! by `stepped` — on a pool of OS threads), and
//! analyses, tabulates and plots what comes back:
//!
//! - [`stall`]: "Reducing Motor Stalls" (over-current observations and efficiency, Figures 1 and 2);
//! - [`interaction`]: "Reducing Lag By Predicting the Next Command" (Figures 3 and 4);
//! - [`results`]: where a study writes, never over earlier results; [`shard`]: a study in slices.

pub(crate) mod design_notes;
#[cfg(test)]
mod drivers_agree;
pub mod interaction;
pub(crate) mod plot_style;
pub mod results;
pub(crate) mod runner;
pub mod shard;
pub mod stall;
pub(crate) mod stepped;
pub(crate) mod tables;

use pavlov::control::Mode;
use pavlov::rng::Rng;

pub(crate) use runner::run_all;

/// The policy of run `index` in an interleaved study: even runs reactive, odd runs Pavlovian.
pub(crate) fn interleaved_mode(index: usize) -> Mode {
    if index % 2 == 0 {
        Mode::Reactive
    } else {
        Mode::Pavlovian
    }
}

/// The random stream of run `index` of a study with seed `seed`; every seed a run uses is drawn from it.
pub(crate) fn run_rng(seed: u64, index: usize) -> Rng {
    Rng::new(seed).fork(index as u64)
}

/// The progress bar both studies show on stderr (hidden when `visible` is false).
pub(crate) fn progress_bar(runs: usize, visible: bool) -> indicatif::ProgressBar {
    let bar = if visible {
        indicatif::ProgressBar::new(runs as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// What the allocation test (`tests/alloc_per_tick.rs`) drives: a stepped run, tick by tick.
#[doc(hidden)]
pub mod stepped_bench_support {
    pub use super::stepped::SteppedError;
    pub use super::stepped::bench_support::SteppedRun;
}
