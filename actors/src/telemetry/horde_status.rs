//! What the Horde thread reports ([`HordeStatus`]): its shape, how it keeps up, and its checkpoints.
//! Defined here, beside the other health figures, so that the [`super::Health`] handle and `/metrics`
//! read it without importing the Horde (the Horde imports this, not the other way round).

use serde::Serialize;

use super::histogram::LatencyQuantiles;

/// The Horde as the dashboard, `/metrics` and the bench see it.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HordeStatus {
    /// Predictions.
    pub predictions: usize,
    /// Trace groups.
    pub groups: usize,
    /// Weights in all.
    pub weights: usize,
    /// `f32` or `f64`.
    pub precision: &'static str,
    /// Ticks learned from.
    pub ticks_learned: u64,
    /// Ticks learning handed over while the Horde was still busy with earlier ones: not learned from.
    pub skipped_busy: u64,
    /// Times the chain of ticks broke (a skipped or stale tick): traces were cleared there.
    pub chain_breaks: u64,
    /// Time of one Horde step (every prediction, then every update).
    pub step: LatencyQuantiles,
    /// The CPU time of one Horde step (the thread's own, without the time it waited for a core); not
    /// on the websocket or in `/metrics`: the bench prints it beside the wall time.
    #[serde(skip)]
    pub step_cpu: LatencyQuantiles,
    /// Predictions that stopped learning because a step was not finite.
    pub stopped: u64,
    /// Rows of a checkpoint still being copied (0 when none is).
    pub snapshot_rows_left: usize,
    /// Checkpoints written, and refused or failed.
    pub checkpoints_written: u64,
    pub checkpoint_errors: u64,
    /// The newest checkpoint written.
    pub last_checkpoint: Option<String>,
}
