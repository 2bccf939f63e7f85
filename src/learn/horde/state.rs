//! [`HordeState`]: the exact state of a [`Horde`], one [`GroupState`] per trace group, in the Horde's
//! group order; restoring it into a Horde built from the same families continues bit for bit.

use serde::{Deserialize, Serialize};

use super::super::group::{GroupState, Weight};
use super::super::{FamilySpec, LearnError};
use super::Horde;

/// A Horde's state taken a few rows at a time while it learns ([`Horde::begin_snapshot`]): each
/// group's state without its weights, and the weights in the group's own type (hundreds of megabytes
/// at nexting scale, written as they are rather than as JSON numbers).
#[derive(Debug, Clone, PartialEq)]
pub struct HordeSnapshot<W> {
    /// The families the state was learned with.
    pub families: Vec<FamilySpec>,
    /// One per trace group: the state with an empty `w0`, and the weights, feature-major.
    pub groups: Vec<(GroupState, Vec<W>)>,
    /// Predictions stopped since the Horde was built.
    pub stopped: u64,
}

/// See the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HordeState {
    /// The families the state was learned with (restoring into other families is refused).
    pub families: Vec<FamilySpec>,
    /// One per trace group.
    pub groups: Vec<GroupState>,
    /// Predictions stopped since the Horde was built.
    pub stopped: u64,
}

impl<W: Weight> Horde<W> {
    /// The exact state, between two ticks.
    pub fn state(&self) -> HordeState {
        HordeState {
            families: self.families.clone(),
            groups: self.slots.iter().map(|s| s.group.state()).collect(),
            stopped: self.stopped,
        }
    }

    /// The exact state of trace group `g` alone (for a copy made a group at a time).
    pub fn group_state(&self, g: usize) -> Option<GroupState> {
        self.slots.get(g).map(|s| s.group.state())
    }

    /// The number of trace groups.
    pub fn groups(&self) -> usize {
        self.slots.len()
    }

    /// Starts a snapshot of every group as it is now; its weights are copied by
    /// [`Horde::advance_snapshot`] between ticks, while the Horde keeps learning (a row about to be
    /// written is copied first). False when one is in progress.
    pub fn begin_snapshot(&mut self) -> bool {
        if self.snapshot_stopped.is_some() {
            return false;
        }
        for slot in &mut self.slots {
            slot.group.begin_snapshot_into(slot.spare.take());
        }
        self.snapshot_stopped = Some(self.stopped);
        true
    }

    /// Copies up to `rows` more rows (of all groups together); returns whether the snapshot is
    /// complete (false without one).
    pub fn advance_snapshot(&mut self, rows: usize) -> bool {
        if self.snapshot_stopped.is_none() {
            return false;
        }
        let mut budget = rows;
        let mut complete = true;
        for slot in &mut self.slots {
            let left = slot.group.snapshot_rows_left();
            let take = left.min(budget);
            budget -= take;
            complete &= slot.group.advance_snapshot(take) || left == 0;
        }
        complete
    }

    /// Rows the snapshot in progress has still to copy, all groups together.
    pub fn snapshot_rows_left(&self) -> usize {
        self.slots
            .iter()
            .map(|s| s.group.snapshot_rows_left())
            .sum()
    }

    /// Whether a snapshot is being copied.
    pub fn snapshot_in_progress(&self) -> bool {
        self.snapshot_stopped.is_some()
    }

    /// The completed snapshot; `None` while it is being copied (or without one).
    pub fn take_snapshot(&mut self) -> Option<HordeSnapshot<W>> {
        if self.snapshot_rows_left() > 0 {
            return None;
        }
        let stopped = self.snapshot_stopped.take()?;
        let mut groups = Vec::with_capacity(self.slots.len());
        for slot in &mut self.slots {
            groups.push(slot.group.take_snapshot()?);
        }
        Some(HordeSnapshot {
            families: self.families.clone(),
            groups,
            stopped,
        })
    }

    /// Maps the memory of the next snapshot's weights now (writing every page of it), so copying a
    /// snapshot later allocates nothing: the Horde then holds its weights twice.
    pub fn prepare_snapshot_buffers(&mut self) {
        for slot in &mut self.slots {
            let len = slot.group.value_count();
            if slot.spare.as_ref().is_none_or(|s| s.len() != len) {
                slot.spare = Some(crate::learn::group::snapshot_buffer(len));
            }
        }
    }

    /// Takes back a written snapshot's weights as the memory of the next one (those of another shape
    /// are dropped).
    pub fn keep_snapshot_buffers(&mut self, snapshot: HordeSnapshot<W>) {
        for (slot, (_, weights)) in self.slots.iter_mut().zip(snapshot.groups) {
            if weights.len() == slot.group.value_count() {
                slot.spare = Some(weights);
            }
        }
    }

    /// Restores a snapshot; everything is checked before anything changes.
    pub fn restore_snapshot(&mut self, snapshot: &HordeSnapshot<W>) -> Result<(), LearnError> {
        if snapshot.families != self.families {
            return Err(LearnError::BadGroupState {
                name: "horde".into(),
                what: "was learned with other families".into(),
            });
        }
        if snapshot.groups.len() != self.slots.len() {
            return Err(LearnError::SnapshotCountMismatch {
                expected: self.slots.len(),
                got: snapshot.groups.len(),
            });
        }
        let mut restored = Vec::with_capacity(self.slots.len());
        for (slot, (state, weights)) in self.slots.iter().zip(&snapshot.groups) {
            let mut group = slot.group.clone();
            let name = &self.predictions[slot.predictions[0]].name;
            group.restore_snapshot(name, state, weights)?;
            restored.push(group);
        }
        for (slot, group) in self.slots.iter_mut().zip(restored) {
            slot.group = group;
        }
        self.stopped = snapshot.stopped;
        self.snapshot_stopped = None;
        Ok(())
    }

    /// Restores `state`; everything is checked before anything changes.
    pub fn restore(&mut self, state: &HordeState) -> Result<(), LearnError> {
        if state.families != self.families {
            return Err(LearnError::BadGroupState {
                name: "horde".into(),
                what: "was learned with other families".into(),
            });
        }
        if state.groups.len() != self.slots.len() {
            return Err(LearnError::SnapshotCountMismatch {
                expected: self.slots.len(),
                got: state.groups.len(),
            });
        }
        let mut restored = Vec::with_capacity(self.slots.len());
        for (slot, g) in self.slots.iter().zip(&state.groups) {
            let mut group = slot.group.clone();
            let name = &self.predictions[slot.predictions[0]].name;
            group.restore_state(name, g)?;
            restored.push(group);
        }
        for (slot, group) in self.slots.iter_mut().zip(restored) {
            slot.group = group;
        }
        self.stopped = state.stopped;
        self.snapshot_stopped = None;
        Ok(())
    }
}
