//! [`TickRecord`]: everything that happened on one 20 ms tick, the single source for the dashboard,
//! the recorder, the metrics and replay.
//!
//! The record is plain data (serde), built by the runtime's actuation stage after the motor command has
//! been written, so it states what the robot was actually told to do.

use serde::{Deserialize, Serialize};

use crate::control::{Action, Mode};
use crate::oi::SensorValues;

/// The robot-side readings the dashboard, the metrics and the experiments need on every tick, in the
/// OI's own units. `None` where the snapshot did not carry the packet.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorReadings {
    /// Packet 14 bit 4: the left wheel's over-current flag.
    pub overcurrent_left: bool,
    /// Packet 14 bit 3: the right wheel's over-current flag.
    pub overcurrent_right: bool,
    /// Packet 7 bit 1 / bit 0: bumpers.
    pub bump_left: bool,
    /// Packet 7 bit 0.
    pub bump_right: bool,
    /// Packet 23, mA (negative = discharging).
    pub battery_current_ma: Option<i32>,
    /// Packet 22, mV.
    pub battery_voltage_mv: Option<i32>,
    /// Packet 25, mAh.
    pub battery_charge_mah: Option<i32>,
    /// Packet 19 summed over the frames since the previous tick, mm.
    pub distance_mm: i32,
    /// Packet 20 summed over the frames since the previous tick, degrees.
    pub angle_deg: i32,
    /// Packet 35 as reported (0 Off, 1 Passive, 2 Safe, 3 Full).
    pub oi_mode: Option<i32>,
}

/// One prediction's output on a tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredictionValue {
    /// The prediction's configured name.
    pub name: String,
    /// σ(wᵀx) on this tick's features, before this tick's learning update.
    pub value: f64,
    /// The gate's threshold θ for this prediction.
    pub threshold: f64,
}

/// Elbow angles seen on the tick (interaction experiment), degrees; `None` = invalid.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ElbowAngles {
    /// Left elbow interior angle.
    pub left: Option<f64>,
    /// Exponentially weighted average of the left angle.
    pub left_avg: Option<f64>,
    /// Right elbow interior angle.
    pub right: Option<f64>,
    /// Exponentially weighted average of the right angle.
    pub right_avg: Option<f64>,
    /// Whether a skeleton is coming in: `tracked`, `stale` or `none` (recordings without it read `none`).
    #[serde(default)]
    pub skeleton: crate::skeleton::SkeletonStatus,
}

/// Why actuation overrode the gate's action with a stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SafetyStop {
    /// The e-stop is latched.
    EStop,
    /// The newest observation is too old (sensor stream stale).
    StaleObservation,
    /// The robot link is not up (stream stale, reconnecting, or closed).
    LinkDown,
    /// The robot tripped from Safe to Passive by itself; control resumes after the operator's `rearm`.
    RobotTripped,
}

/// The robot link's state on a tick.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkStatus {
    /// False once the link has failed or closed.
    pub up: bool,
    /// Stream frames that passed every check, so far.
    pub good_frames: u64,
    /// Candidate frames rejected (wrong length, ids or checksum), so far.
    pub bad_frames: u64,
    /// Bytes skipped while searching for a frame, so far.
    pub skipped_bytes: u64,
    /// The supervisor's view of the link (recordings older than link supervision read as `up`).
    #[serde(default)]
    pub state: crate::supervision::LinkState,
    /// The robot's OI mode from packet 35, corrected for the mode-plus-one quirk (0 Off … 3 Full).
    #[serde(default)]
    pub mode: Option<u8>,
    /// Why the robot last tripped to Passive, while it stays tripped.
    #[serde(default)]
    pub trip: Option<crate::supervision::TripCause>,
    /// Times the port was reopened, so far.
    #[serde(default)]
    pub reconnects: u64,
    /// Times the stream went stale, so far.
    #[serde(default)]
    pub stale_events: u64,
}

/// The probability 1 of an action a deterministic behaviour takes: what a record made before the
/// stochastic gate (or by any deterministic gate) reads as its `behaviour_prob`.
pub fn certain() -> f64 {
    1.0
}

/// The learning stage's exact inputs on a tick, so that a recording can be replayed bit for bit (the
/// scaled `obs` vector is `f32` and would not reproduce the tile boundaries exactly).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TickInputs {
    /// The raw sensor snapshot learning saw (`None` before the first frame).
    pub values: Option<SensorValues>,
    /// Whether an operator's injected request forced the stimulus on.
    pub forced_stimulus: bool,
    /// Whether the previous tick's command was the default policy's (its importance sampling ratio
    /// ρ = 1 for an off-policy prediction about π; else 0): see `crate::agent::learning`.
    #[serde(default)]
    pub previous_followed_default: bool,
    /// The behaviour probability b(A|S) of the previous tick's command (its record's `behaviour_prob`):
    /// with `previous_followed_default`, the ratio is ρ = 1/b (1 unless a stochastic gate drew π's
    /// action); 1 in recordings made before the stochastic gate.
    #[serde(default = "certain")]
    pub previous_behaviour_prob: f64,
}

impl Default for TickInputs {
    fn default() -> Self {
        TickInputs {
            values: None,
            forced_stimulus: false,
            previous_followed_default: false,
            previous_behaviour_prob: certain(),
        }
    }
}

/// Everything that happened on one tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TickRecord {
    /// Tick sequence number (0 = first tick of the run).
    pub seq: u64,
    /// The tick's scheduled time since the run started, ms.
    pub t_ms: f64,
    /// Control mode in force.
    pub mode: Mode,
    /// Age of the observation used, in ticks (`None` = none received yet).
    pub obs_age_ticks: Option<u32>,
    /// Raw readings of interest.
    pub sensors: SensorReadings,
    /// The scaled observation vector (names are announced once, in the run's header). NaN (a packet the
    /// snapshot lacks) is written as JSON `null` and read back as NaN.
    #[serde(with = "nan_as_null")]
    pub obs: Vec<f32>,
    /// Elbow angles (interaction experiment only).
    pub elbow: Option<ElbowAngles>,
    /// The stimulus E on this tick.
    pub stimulus: bool,
    /// Every prediction with its threshold.
    pub predictions: Vec<PredictionValue>,
    /// Whether the fixed response ϱ was selected (f(v) = 1).
    pub gate: bool,
    /// What engaged the gate: the name of the `[[rules]]` rule that fired (by default the gate
    /// prediction's name), or `stimulus` for the stimulus alone; absent when the gate did not engage
    /// (and in recordings made before the rule table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rule: Option<String>,
    /// The default policy's action π on this tick.
    pub default_action: Action,
    /// The command written to the robot.
    pub command: Action,
    /// Set when actuation overrode the gate's action.
    pub safety_stop: Option<SafetyStop>,
    /// The behaviour probability b(A|S) of the command written: 1 for a deterministic choice (the
    /// paper's gate, the stimulus, teleop, a safety stop), ε or 1 − ε where a stochastic gate drew π's
    /// action or the response (`[control] gate = "stochastic"`); 1 in older recordings.
    #[serde(default = "certain")]
    pub behaviour_prob: f64,
    /// Whether the e-stop is latched.
    pub estop: bool,
    /// How late the tick fired, µs.
    pub lateness_us: u32,
    /// The robot link.
    pub link: LinkStatus,
    /// The learning stage's exact inputs, for replay (absent in older recordings).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<TickInputs>,
}

/// Serde for `Vec<f32>` with NaN as `null` both ways (JSON has no NaN; serde_json writes it as `null` but
/// cannot read that back into a float).
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
        let opts: Vec<Option<f32>> = v.iter().map(|x| (!x.is_nan()).then_some(*x)).collect();
        opts.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
        let opts = Vec::<Option<f32>>::deserialize(d)?;
        Ok(opts.into_iter().map(|x| x.unwrap_or(f32::NAN)).collect())
    }
}

impl TickRecord {
    /// A record of a tick on which nothing happened: the robot at rest, no observation values, no
    /// predictions, no stimulus. Tests and tools build the records they need from it with struct update
    /// syntax (`TickRecord { stimulus: true, ..TickRecord::at_rest(7, 140.0, mode) }`).
    pub fn at_rest(seq: u64, t_ms: f64, mode: Mode) -> TickRecord {
        TickRecord {
            seq,
            t_ms,
            mode,
            obs_age_ticks: Some(0),
            sensors: SensorReadings::default(),
            obs: Vec::new(),
            elbow: None,
            stimulus: false,
            predictions: Vec::new(),
            gate: false,
            rule: None,
            default_action: Action::STOP,
            command: Action::STOP,
            safety_stop: None,
            behaviour_prob: 1.0,
            estop: false,
            lateness_us: 0,
            link: LinkStatus::default(),
            inputs: None,
        }
    }
}
