//! [`HordeState`]: the exact state of a [`Horde`], one [`GroupState`] per trace group, in the Horde's
//! group order; restoring it into a Horde built from the same families continues bit for bit.

use serde::{Deserialize, Serialize};

use super::super::group::{GroupState, Weight};
use super::super::{FamilySpec, LearnError};
use super::Horde;

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
        Ok(())
    }
}
