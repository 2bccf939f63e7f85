//! [`TickRecord`]: everything that happened on one 20 ms tick, the single source for the dashboard,
//! the recorder, the metrics and replay.
//!
//! The record is plain data (serde), built by the runtime's actuation stage after the motor command has
//! been written, so it states what the robot was actually told to do.
//!
//! Each struct here is also a protobuf message, `pavlov.Tick` and the messages inside it, the encoding
//! of an MCAP recording's `ticks` channel: the `wire_message!` line after each struct gives its fields'
//! numbers, from which the encoder, the decoder and the schema follow ([`wire`]). A new field is added
//! to the struct and to that list, with a number never used before (and a value in
//! [`TickRecord::default`] for tick-level fields), and nowhere else.

pub mod wire;
mod wire_parts;
mod wire_put;
#[cfg(test)]
mod wire_tests;

use serde::{Deserialize, Serialize};

use crate::control::{Action, Mode};
use crate::oi::SensorValues;
use wire::wire_message;

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

wire_message! { SensorReadings, "Sensors", blank SensorReadings::default();
    1 => overcurrent_left,
    2 => overcurrent_right,
    3 => bump_left,
    4 => bump_right,
    5 => battery_current_ma,
    6 => battery_voltage_mv,
    7 => battery_charge_mah,
    8 => distance_mm,
    9 => angle_deg,
    10 => oi_mode,
}

/// One prediction's output on a tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PredictionValue {
    /// The prediction's configured name.
    pub name: String,
    /// σ(wᵀx) on this tick's features, before this tick's learning update.
    pub value: f64,
    /// The gate's threshold θ for this prediction.
    pub threshold: f64,
}

wire_message! { PredictionValue, "Prediction", blank PredictionValue::default();
    1 => name,
    2 => value,
    3 => threshold,
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

wire_message! { ElbowAngles, "Elbow", blank ElbowAngles::default();
    1 => left,
    2 => left_avg,
    3 => right,
    4 => right_avg,
    5 => skeleton,
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

wire_message! { LinkStatus, "Link", blank LinkStatus::default();
    1 => up,
    2 => good_frames,
    3 => bad_frames,
    4 => skipped_bytes,
    5 => state,
    6 => mode,
    7 => trip,
    8 => reconnects,
    9 => stale_events,
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

// `values` is the message `RawSensors` (see `wire_parts`).
wire_message! { TickInputs, "Inputs", blank TickInputs::default();
    1 => values,
    2 => forced_stimulus,
    3 => previous_followed_default,
    // Written only when not 1 (a stochastic gate's draw), so that deterministic runs keep their bytes;
    // absent reads as 1.
    4 => previous_behaviour_prob if (|i: &TickInputs| i.previous_behaviour_prob != certain()),
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

// The scaled observation `obs` (17) is written only for a record without inputs to recompute it from:
// the reader recomputes it from the raw snapshot and the robot model, bit for bit (a recording would be
// half as large again with it).
wire_message! { TickRecord, "Tick", blank TickRecord::default();
    1 => seq,
    2 => t_ms,
    3 => mode,
    4 => obs_age_ticks,
    5 => sensors,
    6 => elbow,
    7 => stimulus,
    8 => predictions,
    9 => gate,
    10 => default_action,
    11 => command,
    12 => safety_stop,
    13 => estop,
    14 => lateness_us,
    15 => link,
    16 => inputs,
    17 => obs if (|r: &TickRecord| r.inputs.is_none()),
    18 => rule,
    // Written only when not 1, like `inputs.previous_behaviour_prob`.
    19 => behaviour_prob if (|r: &TickRecord| r.behaviour_prob != certain()),
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

/// Every field absent: what a `pavlov.Tick` message without fields reads as (its mode is a placeholder:
/// a message without one is refused).
impl Default for TickRecord {
    fn default() -> Self {
        TickRecord {
            seq: 0,
            t_ms: 0.0,
            mode: Mode::Reactive,
            obs_age_ticks: None,
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
            ..TickRecord::default()
        }
    }
}
