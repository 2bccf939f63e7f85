//! Assembling a [`TickRecord`]: everything that happened on one tick, put together after actuation has
//! chosen the command, so the record states what the robot was actually told to do. The runtime and
//! replay build records the same way.

use crate::control::Action;
use crate::oi::SensorValues;
use crate::record::{LinkStatus, SafetyStop, TickInputs, TickRecord};

use super::gating::GateOutput;
use super::learning::LearnOutput;
use super::readings::read_sensors;

/// What sensor ingest saw on the tick.
#[derive(Debug, Clone)]
pub struct Sensed {
    /// The tick's sequence number.
    pub seq: u64,
    /// The tick's scheduled time since the run started, ms.
    pub t_ms: f64,
    /// How late the tick fired, µs.
    pub lateness_us: u32,
    /// The newest complete frame's values (`None` before the first frame).
    pub values: Option<SensorValues>,
    /// Age of that frame in whole ticks (`None`: no frame yet).
    pub age_ticks: Option<u32>,
    /// Distance (mm) summed over every frame since the previous tick.
    pub distance_mm: i32,
    /// Angle (degrees) summed over every frame since the previous tick.
    pub angle_deg: i32,
    /// The link's state and counters.
    pub link: LinkStatus,
}

/// What actuation decided on the tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Actuated {
    /// The command written to the robot.
    pub command: Action,
    /// Why a stop overrode the gate, if one did.
    pub safety_stop: Option<SafetyStop>,
    /// Whether the e-stop was latched.
    pub estop: bool,
}

/// The tick's record from what each stage produced; `forced_stimulus` is learning's injected request.
pub fn assemble(
    sensed: Sensed,
    learned: LearnOutput,
    forced_stimulus: bool,
    gate: GateOutput,
    actuated: Actuated,
) -> TickRecord {
    TickRecord {
        seq: sensed.seq,
        t_ms: sensed.t_ms,
        mode: gate.mode,
        obs_age_ticks: sensed.age_ticks,
        sensors: read_sensors(sensed.values.as_ref(), sensed.distance_mm, sensed.angle_deg),
        obs: learned.obs_vector,
        elbow: learned.elbow,
        stimulus: learned.stimulus,
        predictions: learned.predictions,
        gate: gate.gate,
        rule: gate.rule.as_deref().map(str::to_owned),
        default_action: gate.default_action,
        command: actuated.command,
        safety_stop: actuated.safety_stop,
        // A safety stop (or the e-stop) overrides the gate with certainty.
        behaviour_prob: if actuated.safety_stop.is_some() {
            1.0
        } else {
            gate.behaviour_prob
        },
        estop: actuated.estop,
        lateness_us: sensed.lateness_us,
        link: sensed.link,
        inputs: Some(TickInputs {
            values: sensed.values,
            forced_stimulus,
            previous_followed_default: learned.previous_followed_default,
            previous_behaviour_prob: learned.previous_behaviour_prob,
        }),
    }
}
