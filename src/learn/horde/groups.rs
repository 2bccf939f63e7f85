//! [`SlotGroup`]: the kinds of group a Horde's predictions learn in, and the one interface the Horde
//! calls them by.
//!
//! | kind | learners | sharing |
//! |---|---|---|
//! | [`TraceGroup`] (deferred rows) | `paper`, `xent`, `linear`; `true_online` with a shared dutch trace | one trace per group; a tick costs the active rows |
//! | [`AutostepGroup`] | `autostep` | one trace per group; step size, h and v per weight; a tick costs the rows of non-zero trace |

use super::super::LearnError;
use super::super::Sigma;
use super::super::group::{AutostepGroup, GroupState, TraceGroup, Weight};

/// A Horde's group of predictions (see the module documentation). A Horde holds a few dozen, one per
/// slot: their size is nothing beside their weights, and neither kind is boxed (no indirection on the
/// paper's hot path).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub(super) enum SlotGroup<W> {
    /// The deferred trace group (paper, xent, linear, true online).
    Trace(TraceGroup<W>),
    /// Autostep.
    Autostep(AutostepGroup<W>),
}

/// Calls `$call` on whichever group `$self` holds.
macro_rules! each {
    ($self:expr, $g:ident => $call:expr) => {
        match $self {
            SlotGroup::Trace($g) => $call,
            SlotGroup::Autostep($g) => $call,
        }
    };
}

impl<W: Weight> SlotGroup<W> {
    /// A tick: the prediction for `active`, then the update into it; in one pass over each active
    /// weight row where the group has one (the paper's), else `predict` then `learn`.
    pub fn step(
        &mut self,
        active: &[usize],
        gamma: f64,
        cumulants: &[f64],
        deltas: &mut [f64],
        fused: bool,
    ) -> Result<usize, LearnError> {
        match self {
            SlotGroup::Trace(g) if fused => g.predict_and_learn(active, gamma, cumulants, deltas),
            SlotGroup::Trace(g) => {
                g.predict(active);
                g.learn(gamma, cumulants, deltas)
            }
            SlotGroup::Autostep(g) => {
                g.predict(active);
                g.learn(gamma, cumulants, deltas)
            }
        }
    }

    /// σ.
    pub fn sigma(&self) -> Sigma {
        each!(self, g => g.sigma())
    }

    /// `wᵀx` of the last prediction, one per column.
    pub fn values(&self) -> &[f64] {
        each!(self, g => g.values())
    }

    /// Predictions.
    pub fn len(&self) -> usize {
        each!(self, g => g.len())
    }

    /// Features.
    pub fn features(&self) -> usize {
        each!(self, g => g.features())
    }

    /// The values a snapshot's weights hold: the weights, and for Autostep its step sizes, h and v.
    pub fn value_count(&self) -> usize {
        match self {
            SlotGroup::Trace(g) => g.weight_count(),
            SlotGroup::Autostep(g) => g.value_count(),
        }
    }

    /// Forgets the previous tick and ends the trace.
    pub fn break_chain(&mut self) {
        each!(self, g => g.break_chain())
    }

    /// Back to the initial state.
    pub fn reset(&mut self) {
        each!(self, g => g.reset())
    }

    /// Changes α of column `col`.
    pub fn set_alpha(&mut self, col: usize, alpha: f64) -> Result<(), LearnError> {
        each!(self, g => g.set_alpha(col, alpha))
    }

    /// The exact state.
    pub fn state(&self) -> GroupState {
        each!(self, g => g.state())
    }

    /// Starts a snapshot into `buffer` (the paper's group copies it a few rows a tick, Autostep's at
    /// once); false when one is in progress.
    pub fn begin_snapshot_into(&mut self, buffer: Option<Vec<W>>) -> bool {
        each!(self, g => g.begin_snapshot_into(buffer))
    }

    /// Copies up to `rows` more rows of the snapshot; whether it is complete.
    pub fn advance_snapshot(&mut self, rows: usize) -> bool {
        match self {
            SlotGroup::Trace(g) => g.advance_snapshot(rows),
            SlotGroup::Autostep(_) => true,
        }
    }

    /// Rows the snapshot has still to copy.
    pub fn snapshot_rows_left(&self) -> usize {
        match self {
            SlotGroup::Trace(g) => g.snapshot_rows_left(),
            SlotGroup::Autostep(_) => 0,
        }
    }

    /// The completed snapshot.
    pub fn take_snapshot(&mut self) -> Option<(GroupState, Vec<W>)> {
        each!(self, g => g.take_snapshot())
    }

    /// Restores a snapshot.
    pub fn restore_snapshot(
        &mut self,
        name: &str,
        state: &GroupState,
        values: &[W],
    ) -> Result<(), LearnError> {
        each!(self, g => g.restore_snapshot(name, state, values))
    }

    /// Restores a state.
    pub fn restore_state(&mut self, name: &str, state: &GroupState) -> Result<(), LearnError> {
        each!(self, g => g.restore_state(name, state))
    }
}
