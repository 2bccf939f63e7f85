//! Safe-mode trip events: the robot lifted (both wheel drops) or a cliff under one cliff sensor, for a
//! number of 15 ms steps. In Safe mode the firmware then stops and drops to Passive [C1 p6; C2 p7];
//! Full ignores them. The event is undone when it ends; only what the event itself set is undone.

use crate::sim::robot::SimRobot;

/// What the robot runs into.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum TripKind {
    /// Lifted off the floor: both wheel drops (and the Create 1 caster drop) are set.
    WheelDrop,
    /// A drop-off under cliff sensor 0 (left), 1 (front left), 2 (front right) or 3 (right).
    Cliff(usize),
}

/// A trip event in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct ActiveTrip {
    pub kind: TripKind,
    /// Steps still to be seen by the robot's sensors.
    pub steps_left: u32,
}

impl TripKind {
    /// Sets (`true`) or clears the physical condition in the robot's world.
    pub(super) fn apply(self, robot: &mut SimRobot, on: bool) {
        match self {
            TripKind::WheelDrop => robot.world_mut().set_lifted(on),
            TripKind::Cliff(index) => robot.world_mut().set_cliff(index, on),
        }
    }
}

impl ActiveTrip {
    /// Counts one step seen; ends the event (and undoes it) after its last step. Returns `None` once
    /// over.
    pub(super) fn tick(mut self, robot: &mut SimRobot) -> Option<ActiveTrip> {
        self.steps_left = self.steps_left.saturating_sub(1);
        if self.steps_left == 0 {
            self.kind.apply(robot, false);
            None
        } else {
            Some(self)
        }
    }
}
