//! What the simulated robot reports after every step ([`SimStatus`]): defined here, beside the other
//! health figures, so that the [`super::Health`] handle reads it without importing the simulator (the
//! simulator imports this, not the other way round).

use pavlov::sim::faults::FaultCounters;

/// What the simulator task publishes after every step, for tests, soak runs and `pavlov sim`'s report.
#[derive(Debug, Clone, Default)]
pub struct SimStatus {
    /// The OI mode (packet 35 value, without any quirk).
    pub oi_mode: i32,
    /// Actual wheel speeds `[left, right]`, mm/s.
    pub wheel_speed_mm_s: [f64; 2],
    /// A host connection is plugged in.
    pub connected: bool,
    /// Bytes flow on the line this step (not hung, not unplugged, host and robot at the same rate).
    pub flowing: bool,
    /// What the fault injector has done so far.
    pub faults: FaultCounters,
}
