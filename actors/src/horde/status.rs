//! What the Horde thread reports: its shape, how it keeps up, and its checkpoints.

use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

use crate::telemetry::histogram::LatencyQuantiles;

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

/// Counters written by learning's task and read by the Horde thread.
#[derive(Debug, Default)]
pub(crate) struct OfferCounters {
    /// Ticks learning offered.
    pub(crate) offered: AtomicU64,
    /// Of those, offered while the queue was full.
    pub(crate) skipped_busy: AtomicU64,
}

impl OfferCounters {
    pub(crate) fn skipped(&self) -> u64 {
        self.skipped_busy.load(Ordering::Relaxed)
    }
}
