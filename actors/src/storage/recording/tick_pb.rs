//! A tick record as a Protocol Buffers message (`pavlov.Tick`), the encoding of an MCAP recording's
//! `ticks` channel, and its exact conversion to and from [`TickRecord`].
//!
//! Why protobuf and not JSON for ticks: a tick is written 50 times a second in real time and ~50 000 times
//! a second in an experiment under virtual time, on the same two cores that compute the runs; encoding a
//! tick as protobuf takes a fraction of the time JSON needs (floats are copied, not printed) and gives a
//! third of the bytes to compress (the book's "Recording format", `docs/src/recordings.md`, has the measurements). Foxglove, the `mcap`
//! CLI and `mcap-protobuf-support` decode it with the schema the file carries ([`super::schema`]).
//!
//! What is not in the message: the scaled observation vector `obs`. It is a pure function of the raw
//! sensor snapshot the message does carry (`inputs.values`) and the robot model in the recording's
//! configuration, so the reader recomputes it bit for bit ([`to_record`]); storing it would add half the
//! bytes again. (Only a record without inputs, from a JSON Lines recording older than replay, carries
//! its `obs` in field 17.)
//!
//! Every field maps one to one; absent options are protobuf field presence (`optional`, or an unset
//! message), enums carry a zero `UNSPECIFIED`/`NONE` value as proto3 requires, and floats are copied
//! bit for bit — every `double` has explicit presence, because proto3 leaves out a plain field equal to
//! zero, and −0.0 (a prediction of a fresh learner) would come back as +0.0 — so a record read back
//! equals the one written.

use pavlov::control::{Action, Mode};
use pavlov::oi::SensorValues;
use pavlov::record::{
    ElbowAngles, LinkStatus, PredictionValue, SafetyStop, SensorReadings, TickInputs, TickRecord,
};
use pavlov::skeleton::SkeletonStatus;
use pavlov::supervision::{LinkState, TripCause};

/// `pavlov.Tick`: everything that happened on one tick (field numbers are the schema's).
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Tick {
    #[prost(uint64, tag = "1")]
    pub(crate) seq: u64,
    /// Optional (explicit presence) so that −0.0 is written, not left out as a default.
    #[prost(double, optional, tag = "2")]
    pub(crate) t_ms: Option<f64>,
    #[prost(enumeration = "PbMode", tag = "3")]
    pub(crate) mode: i32,
    #[prost(uint32, optional, tag = "4")]
    pub(crate) obs_age_ticks: Option<u32>,
    #[prost(message, optional, tag = "5")]
    pub(crate) sensors: Option<Sensors>,
    #[prost(message, optional, tag = "6")]
    pub(crate) elbow: Option<Elbow>,
    #[prost(bool, tag = "7")]
    pub(crate) stimulus: bool,
    #[prost(message, repeated, tag = "8")]
    pub(crate) predictions: Vec<Prediction>,
    #[prost(bool, tag = "9")]
    pub(crate) gate: bool,
    #[prost(message, optional, tag = "10")]
    pub(crate) default_action: Option<Wheels>,
    #[prost(message, optional, tag = "11")]
    pub(crate) command: Option<Wheels>,
    #[prost(enumeration = "PbSafetyStop", tag = "12")]
    pub(crate) safety_stop: i32,
    #[prost(bool, tag = "13")]
    pub(crate) estop: bool,
    #[prost(uint32, tag = "14")]
    pub(crate) lateness_us: u32,
    #[prost(message, optional, tag = "15")]
    pub(crate) link: Option<Link>,
    #[prost(message, optional, tag = "16")]
    pub(crate) inputs: Option<Inputs>,
    /// The scaled observation, only for a record without inputs to recompute it from.
    #[prost(float, repeated, tag = "17")]
    pub(crate) obs: Vec<f32>,
    /// What engaged the gate (a rule's name or `stimulus`); absent when it did not, and in recordings
    /// made before the rule table.
    #[prost(string, optional, tag = "18")]
    pub(crate) rule: Option<String>,
}

/// `pavlov.Sensors`: the readings of interest, in the OI's units.
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Sensors {
    #[prost(bool, tag = "1")]
    pub(crate) overcurrent_left: bool,
    #[prost(bool, tag = "2")]
    pub(crate) overcurrent_right: bool,
    #[prost(bool, tag = "3")]
    pub(crate) bump_left: bool,
    #[prost(bool, tag = "4")]
    pub(crate) bump_right: bool,
    #[prost(sint32, optional, tag = "5")]
    pub(crate) battery_current_ma: Option<i32>,
    #[prost(sint32, optional, tag = "6")]
    pub(crate) battery_voltage_mv: Option<i32>,
    #[prost(sint32, optional, tag = "7")]
    pub(crate) battery_charge_mah: Option<i32>,
    #[prost(sint32, tag = "8")]
    pub(crate) distance_mm: i32,
    #[prost(sint32, tag = "9")]
    pub(crate) angle_deg: i32,
    #[prost(sint32, optional, tag = "10")]
    pub(crate) oi_mode: Option<i32>,
}

/// `pavlov.Elbow`: elbow angles, degrees.
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Elbow {
    #[prost(double, optional, tag = "1")]
    pub(crate) left: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub(crate) left_avg: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub(crate) right: Option<f64>,
    #[prost(double, optional, tag = "4")]
    pub(crate) right_avg: Option<f64>,
    #[prost(enumeration = "PbSkeletonStatus", tag = "5")]
    pub(crate) skeleton: i32,
}

/// `pavlov.Prediction`: one prediction's value and threshold.
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Prediction {
    #[prost(string, tag = "1")]
    pub(crate) name: String,
    /// Optional (explicit presence) so that −0.0 is written, not left out as a default.
    #[prost(double, optional, tag = "2")]
    pub(crate) value: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub(crate) threshold: Option<f64>,
}

/// `pavlov.Wheels`: wheel speeds, mm/s.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub(crate) struct Wheels {
    #[prost(sint32, tag = "1")]
    pub(crate) left_mm_s: i32,
    #[prost(sint32, tag = "2")]
    pub(crate) right_mm_s: i32,
}

/// `pavlov.Link`: the robot link's state.
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Link {
    #[prost(bool, tag = "1")]
    pub(crate) up: bool,
    #[prost(uint64, tag = "2")]
    pub(crate) good_frames: u64,
    #[prost(uint64, tag = "3")]
    pub(crate) bad_frames: u64,
    #[prost(uint64, tag = "4")]
    pub(crate) skipped_bytes: u64,
    #[prost(enumeration = "PbLinkState", tag = "5")]
    pub(crate) state: i32,
    #[prost(uint32, optional, tag = "6")]
    pub(crate) mode: Option<u32>,
    #[prost(enumeration = "PbTripCause", tag = "7")]
    pub(crate) trip: i32,
    #[prost(uint64, tag = "8")]
    pub(crate) reconnects: u64,
    #[prost(uint64, tag = "9")]
    pub(crate) stale_events: u64,
}

/// `pavlov.Inputs`: the learning stage's exact inputs.
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct Inputs {
    #[prost(message, optional, tag = "1")]
    pub(crate) values: Option<RawSensors>,
    #[prost(bool, tag = "2")]
    pub(crate) forced_stimulus: bool,
    #[prost(bool, tag = "3")]
    pub(crate) previous_followed_default: bool,
}

/// `pavlov.RawSensors`: a raw sensor snapshot: `values[id]` is packet `id`'s value when bit `id` of
/// `present` is set (and 0 otherwise).
#[derive(Clone, PartialEq, prost::Message)]
pub(crate) struct RawSensors {
    #[prost(sint32, repeated, tag = "1")]
    pub(crate) values: Vec<i32>,
    #[prost(fixed64, tag = "2")]
    pub(crate) present: u64,
}

/// `pavlov.Mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub(crate) enum PbMode {
    Unspecified = 0,
    Reactive = 1,
    Pavlovian = 2,
    Manual = 3,
}

/// `pavlov.SafetyStop` (`NONE`: no stop).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub(crate) enum PbSafetyStop {
    None = 0,
    EStop = 1,
    StaleObservation = 2,
    LinkDown = 3,
    RobotTripped = 4,
}

/// `pavlov.LinkState`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub(crate) enum PbLinkState {
    Unspecified = 0,
    Up = 1,
    Stale = 2,
    Reconnecting = 3,
    Tripped = 4,
    Down = 5,
}

/// `pavlov.SkeletonStatus` (`NONE`: nobody tracked, the default of recordings made before it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub(crate) enum PbSkeletonStatus {
    None = 0,
    Tracked = 1,
    Stale = 2,
}

pub(super) fn skeleton_to_pb(s: SkeletonStatus) -> PbSkeletonStatus {
    match s {
        SkeletonStatus::Absent => PbSkeletonStatus::None,
        SkeletonStatus::Tracked => PbSkeletonStatus::Tracked,
        SkeletonStatus::Stale => PbSkeletonStatus::Stale,
    }
}

/// `pavlov.TripCause` (`NONE`: not tripped).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, prost::Enumeration)]
#[repr(i32)]
pub(crate) enum PbTripCause {
    None = 0,
    WheelDrop = 1,
    Cliff = 2,
    Charger = 3,
    Unknown = 4,
}

/// Why a message is not a tick this version can read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TickDecodeError {
    /// Not protobuf, or not a `pavlov.Tick`.
    #[error("not a pavlov.Tick message: {0}")]
    Malformed(String),
    /// A field holds a value outside its range.
    #[error("field `{field}` holds {value}, which is not a valid value")]
    BadValue {
        /// The field.
        field: &'static str,
        /// The value.
        value: i64,
    },
}

pub(super) fn mode_to_pb(m: Mode) -> PbMode {
    match m {
        Mode::Reactive => PbMode::Reactive,
        Mode::Pavlovian => PbMode::Pavlovian,
        Mode::Manual => PbMode::Manual,
    }
}

pub(super) fn stop_to_pb(s: Option<SafetyStop>) -> PbSafetyStop {
    match s {
        None => PbSafetyStop::None,
        Some(SafetyStop::EStop) => PbSafetyStop::EStop,
        Some(SafetyStop::StaleObservation) => PbSafetyStop::StaleObservation,
        Some(SafetyStop::LinkDown) => PbSafetyStop::LinkDown,
        Some(SafetyStop::RobotTripped) => PbSafetyStop::RobotTripped,
    }
}

pub(super) fn state_to_pb(s: LinkState) -> PbLinkState {
    match s {
        LinkState::Up => PbLinkState::Up,
        LinkState::Stale => PbLinkState::Stale,
        LinkState::Reconnecting => PbLinkState::Reconnecting,
        LinkState::Tripped => PbLinkState::Tripped,
        LinkState::Down => PbLinkState::Down,
    }
}

pub(super) fn trip_to_pb(t: Option<TripCause>) -> PbTripCause {
    match t {
        None => PbTripCause::None,
        Some(TripCause::WheelDrop) => PbTripCause::WheelDrop,
        Some(TripCause::Cliff) => PbTripCause::Cliff,
        Some(TripCause::Charger) => PbTripCause::Charger,
        Some(TripCause::Unknown) => PbTripCause::Unknown,
    }
}

#[cfg(test)]
fn wheels(a: Action) -> Wheels {
    Wheels {
        left_mm_s: i32::from(a.left_mm_s),
        right_mm_s: i32::from(a.right_mm_s),
    }
}

#[cfg(test)]
fn fill_raw(out: &mut RawSensors, v: &SensorValues) {
    out.values.clear();
    out.present = 0;
    for (id, value) in v.iter() {
        let i = usize::from(id);
        if out.values.len() <= i {
            out.values.resize(i + 1, 0);
        }
        out.values[i] = value;
        out.present |= 1 << id;
    }
}

/// The message for `r` (its `obs` is left out: see the module doc).
#[cfg(test)]
pub(crate) fn from_record(r: &TickRecord) -> Tick {
    let mut msg = Tick::default();
    fill(&mut msg, r);
    msg
}

/// Makes `msg` the message for `r`, reusing its allocations (the recorder encodes with
/// [`super::tick_encode`], which must write the same bytes as this struct's derived encoder).
#[cfg(test)]
pub(crate) fn fill(msg: &mut Tick, r: &TickRecord) {
    let s = &r.sensors;
    msg.seq = r.seq;
    msg.t_ms = Some(r.t_ms);
    msg.mode = mode_to_pb(r.mode) as i32;
    msg.obs_age_ticks = r.obs_age_ticks;
    msg.sensors = Some(Sensors {
        overcurrent_left: s.overcurrent_left,
        overcurrent_right: s.overcurrent_right,
        bump_left: s.bump_left,
        bump_right: s.bump_right,
        battery_current_ma: s.battery_current_ma,
        battery_voltage_mv: s.battery_voltage_mv,
        battery_charge_mah: s.battery_charge_mah,
        distance_mm: s.distance_mm,
        angle_deg: s.angle_deg,
        oi_mode: s.oi_mode,
    });
    msg.elbow = r.elbow.as_ref().map(|e| Elbow {
        left: e.left,
        left_avg: e.left_avg,
        right: e.right,
        right_avg: e.right_avg,
        skeleton: skeleton_to_pb(e.skeleton) as i32,
    });
    msg.stimulus = r.stimulus;
    msg.predictions.truncate(r.predictions.len());
    for (i, p) in r.predictions.iter().enumerate() {
        if msg.predictions.len() <= i {
            msg.predictions.push(Prediction::default());
        }
        let out = &mut msg.predictions[i];
        if out.name != p.name {
            out.name.clear();
            out.name.push_str(&p.name);
        }
        out.value = Some(p.value);
        out.threshold = Some(p.threshold);
    }
    msg.gate = r.gate;
    msg.rule.clone_from(&r.rule);
    msg.default_action = Some(wheels(r.default_action));
    msg.command = Some(wheels(r.command));
    msg.safety_stop = stop_to_pb(r.safety_stop) as i32;
    msg.estop = r.estop;
    msg.lateness_us = r.lateness_us;
    msg.link = Some(Link {
        up: r.link.up,
        good_frames: r.link.good_frames,
        bad_frames: r.link.bad_frames,
        skipped_bytes: r.link.skipped_bytes,
        state: state_to_pb(r.link.state) as i32,
        mode: r.link.mode.map(u32::from),
        trip: trip_to_pb(r.link.trip) as i32,
        reconnects: r.link.reconnects,
        stale_events: r.link.stale_events,
    });
    msg.obs.clear();
    match &r.inputs {
        None => {
            msg.inputs = None;
            msg.obs.extend_from_slice(&r.obs);
        }
        Some(i) => {
            let out = msg.inputs.get_or_insert_with(Inputs::default);
            out.forced_stimulus = i.forced_stimulus;
            out.previous_followed_default = i.previous_followed_default;
            match &i.values {
                None => out.values = None,
                Some(v) => fill_raw(out.values.get_or_insert_with(RawSensors::default), v),
            }
        }
    }
}

fn bad(field: &'static str, value: impl Into<i64>) -> TickDecodeError {
    TickDecodeError::BadValue {
        field,
        value: value.into(),
    }
}

fn action(w: Option<Wheels>, field: &'static str) -> Result<Action, TickDecodeError> {
    let w = w.unwrap_or_default();
    let left = i16::try_from(w.left_mm_s).map_err(|_| bad(field, w.left_mm_s))?;
    let right = i16::try_from(w.right_mm_s).map_err(|_| bad(field, w.right_mm_s))?;
    Ok(Action::new(left, right))
}

fn values_from(raw: &RawSensors) -> Result<SensorValues, TickDecodeError> {
    let mut v = SensorValues::new();
    for id in 0..pavlov::oi::sensors::PACKET_SLOTS {
        if raw.present >> id & 1 == 1 {
            let value = raw.values.get(id).copied().unwrap_or(0);
            // `id` < 59 fits a u8.
            v.set(id as u8, value);
        }
    }
    if raw.present >> pavlov::oi::sensors::PACKET_SLOTS != 0 {
        return Err(bad("inputs.values.present", raw.present as i64));
    }
    Ok(v)
}

/// The record `msg` encodes, with `obs` recomputed from its raw snapshot by `layout`.
pub(crate) fn to_record(
    msg: Tick,
    layout: &pavlov::obs::ObsLayout,
) -> Result<TickRecord, TickDecodeError> {
    let mode = match PbMode::try_from(msg.mode) {
        Ok(PbMode::Reactive) => Mode::Reactive,
        Ok(PbMode::Pavlovian) => Mode::Pavlovian,
        Ok(PbMode::Manual) => Mode::Manual,
        _ => return Err(bad("mode", msg.mode)),
    };
    let safety_stop = match PbSafetyStop::try_from(msg.safety_stop) {
        Ok(PbSafetyStop::None) => None,
        Ok(PbSafetyStop::EStop) => Some(SafetyStop::EStop),
        Ok(PbSafetyStop::StaleObservation) => Some(SafetyStop::StaleObservation),
        Ok(PbSafetyStop::LinkDown) => Some(SafetyStop::LinkDown),
        Ok(PbSafetyStop::RobotTripped) => Some(SafetyStop::RobotTripped),
        Err(_) => return Err(bad("safety_stop", msg.safety_stop)),
    };
    let l = msg.link.unwrap_or_default();
    let state = match PbLinkState::try_from(l.state) {
        Ok(PbLinkState::Up) => LinkState::Up,
        Ok(PbLinkState::Stale) => LinkState::Stale,
        Ok(PbLinkState::Reconnecting) => LinkState::Reconnecting,
        Ok(PbLinkState::Tripped) => LinkState::Tripped,
        Ok(PbLinkState::Down) => LinkState::Down,
        _ => return Err(bad("link.state", l.state)),
    };
    let trip = match PbTripCause::try_from(l.trip) {
        Ok(PbTripCause::None) => None,
        Ok(PbTripCause::WheelDrop) => Some(TripCause::WheelDrop),
        Ok(PbTripCause::Cliff) => Some(TripCause::Cliff),
        Ok(PbTripCause::Charger) => Some(TripCause::Charger),
        Ok(PbTripCause::Unknown) => Some(TripCause::Unknown),
        Err(_) => return Err(bad("link.trip", l.trip)),
    };
    let link_mode = match l.mode {
        None => None,
        Some(m) => Some(u8::try_from(m).map_err(|_| bad("link.mode", m))?),
    };
    let inputs = match msg.inputs {
        None => None,
        Some(i) => Some(TickInputs {
            values: i.values.as_ref().map(values_from).transpose()?,
            forced_stimulus: i.forced_stimulus,
            previous_followed_default: i.previous_followed_default,
        }),
    };
    let obs = match inputs.as_ref().and_then(|i| i.values.as_ref()) {
        None if inputs.is_none() => msg.obs,
        Some(values) => {
            let mut scaled = Vec::with_capacity(layout.len());
            layout.scale(values, &mut scaled);
            scaled.into_iter().map(|x| x as f32).collect()
        }
        None => vec![f32::NAN; layout.len()],
    };
    let s = msg.sensors.unwrap_or_default();
    Ok(TickRecord {
        seq: msg.seq,
        t_ms: msg.t_ms.unwrap_or_default(),
        mode,
        obs_age_ticks: msg.obs_age_ticks,
        sensors: SensorReadings {
            overcurrent_left: s.overcurrent_left,
            overcurrent_right: s.overcurrent_right,
            bump_left: s.bump_left,
            bump_right: s.bump_right,
            battery_current_ma: s.battery_current_ma,
            battery_voltage_mv: s.battery_voltage_mv,
            battery_charge_mah: s.battery_charge_mah,
            distance_mm: s.distance_mm,
            angle_deg: s.angle_deg,
            oi_mode: s.oi_mode,
        },
        obs,
        elbow: match msg.elbow {
            None => None,
            Some(e) => Some(ElbowAngles {
                left: e.left,
                left_avg: e.left_avg,
                right: e.right,
                right_avg: e.right_avg,
                skeleton: match PbSkeletonStatus::try_from(e.skeleton) {
                    Ok(PbSkeletonStatus::None) => SkeletonStatus::Absent,
                    Ok(PbSkeletonStatus::Tracked) => SkeletonStatus::Tracked,
                    Ok(PbSkeletonStatus::Stale) => SkeletonStatus::Stale,
                    Err(_) => return Err(bad("elbow.skeleton", e.skeleton)),
                },
            }),
        },
        stimulus: msg.stimulus,
        predictions: msg
            .predictions
            .into_iter()
            .map(|p| PredictionValue {
                name: p.name,
                value: p.value.unwrap_or_default(),
                threshold: p.threshold.unwrap_or_default(),
            })
            .collect(),
        gate: msg.gate,
        rule: msg.rule,
        default_action: action(msg.default_action, "default_action")?,
        command: action(msg.command, "command")?,
        safety_stop,
        estop: msg.estop,
        lateness_us: msg.lateness_us,
        link: LinkStatus {
            up: l.up,
            good_frames: l.good_frames,
            bad_frames: l.bad_frames,
            skipped_bytes: l.skipped_bytes,
            state,
            mode: link_mode,
            trip,
            reconnects: l.reconnects,
            stale_events: l.stale_events,
        },
        inputs,
    })
}

/// Decodes a `ticks` message.
pub(crate) fn decode(
    bytes: &[u8],
    layout: &pavlov::obs::ObsLayout,
) -> Result<TickRecord, TickDecodeError> {
    let msg = <Tick as prost::Message>::decode(bytes)
        .map_err(|e| TickDecodeError::Malformed(e.to_string()))?;
    to_record(msg, layout)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pavlov::obs::ObsLayout;
    use pavlov::oi::Model;
    use prost::Message as _;

    fn layout() -> ObsLayout {
        ObsLayout::for_model(Model::Create1)
    }

    fn values(k: i32) -> SensorValues {
        let mut v = SensorValues::new();
        for id in 7..=42u8 {
            v.set(id, (i32::from(id) * 37 + k) % 300 - 150);
        }
        v.set(22, 15_000 + k);
        v.set(23, -1_200 - k);
        v
    }

    fn obs_of(v: Option<&SensorValues>) -> Vec<f32> {
        let l = layout();
        match v {
            Some(v) => {
                let mut out = Vec::new();
                l.scale(v, &mut out);
                out.into_iter().map(|x| x as f32).collect()
            }
            None => vec![f32::NAN; l.len()],
        }
    }

    /// Records that between them use every variant and every option both ways.
    pub(crate) fn records() -> Vec<TickRecord> {
        let stops = [
            None,
            Some(SafetyStop::EStop),
            Some(SafetyStop::StaleObservation),
            Some(SafetyStop::LinkDown),
            Some(SafetyStop::RobotTripped),
        ];
        let states = [
            LinkState::Up,
            LinkState::Stale,
            LinkState::Reconnecting,
            LinkState::Tripped,
            LinkState::Down,
        ];
        let trips = [
            None,
            Some(TripCause::WheelDrop),
            Some(TripCause::Cliff),
            Some(TripCause::Charger),
            Some(TripCause::Unknown),
        ];
        (0..15u64)
            .map(|i| {
                let k = i as usize;
                let vals = (i % 4 != 3).then(|| values(i as i32));
                TickRecord {
                    seq: i * 1_000_003,
                    t_ms: if i == 2 {
                        -0.0
                    } else {
                        i as f64 * 20.000000000000004
                    },
                    mode: [Mode::Reactive, Mode::Pavlovian, Mode::Manual][k % 3],
                    obs_age_ticks: (i % 2 == 0).then_some(i as u32 * 7),
                    sensors: SensorReadings {
                        overcurrent_left: i % 2 == 0,
                        overcurrent_right: i % 3 == 0,
                        bump_left: i % 5 == 0,
                        bump_right: i % 7 == 0,
                        battery_current_ma: (i % 3 != 1).then_some(-1_500 + i as i32),
                        battery_voltage_mv: (i % 3 != 2).then_some(16_000),
                        battery_charge_mah: (i % 4 != 0).then_some(2_500),
                        distance_mm: 3 - i as i32,
                        angle_deg: -(i as i32),
                        oi_mode: (i % 2 == 1).then_some(2),
                    },
                    obs: obs_of(vals.as_ref()),
                    elbow: (i % 3 == 0).then(|| ElbowAngles {
                        left: Some(91.25 + i as f64),
                        left_avg: (i % 2 == 0).then_some(0.1 + 0.2),
                        right: None,
                        right_avg: Some(-0.0),
                        skeleton: [
                            SkeletonStatus::Tracked,
                            SkeletonStatus::Stale,
                            SkeletonStatus::Absent,
                        ][(i % 3) as usize],
                    }),
                    stimulus: i % 2 == 1,
                    predictions: (0..k % 3)
                        .map(|p| PredictionValue {
                            name: format!("p{p}"),
                            value: if i == 1 { -0.0 } else { 1.0 / (i as f64 + 3.0) },
                            threshold: if p == 1 { f64::INFINITY } else { 0.5 },
                        })
                        .collect(),
                    gate: i % 4 == 0,
                    rule: match i % 4 {
                        0 => Some(format!("rule {i} ✓")),
                        1 => Some("stimulus".into()),
                        2 => Some(String::new()),
                        _ => None,
                    },
                    default_action: Action::new(-500 + i as i16, 500),
                    command: Action::new(i16::MIN, i16::MAX),
                    safety_stop: stops[k % 5],
                    estop: i % 6 == 0,
                    lateness_us: i as u32 * 1_000,
                    link: LinkStatus {
                        up: i % 2 == 0,
                        good_frames: u64::MAX - i,
                        bad_frames: i,
                        skipped_bytes: 3 * i,
                        state: states[k % 5],
                        mode: (i % 3 != 0).then_some(3),
                        trip: trips[(k + 2) % 5],
                        reconnects: i / 2,
                        stale_events: i / 3,
                    },
                    inputs: (i % 5 != 4).then(|| TickInputs {
                        values: vals.clone(),
                        forced_stimulus: i % 2 == 0,
                        previous_followed_default: i % 3 == 0,
                    }),
                }
            })
            .collect()
    }

    /// Equality bit for bit: as JSON text, where NaN (an observation without a reading) is `null` on
    /// both sides and −0.0 differs from 0.0.
    fn same(a: &TickRecord, b: &TickRecord) -> bool {
        serde_json::to_string(a).unwrap() == serde_json::to_string(b).unwrap()
    }

    #[test]
    fn every_record_reads_back_exactly_with_its_observation_recomputed() {
        let layout = layout();
        let mut reused = Tick::default();
        for r in records() {
            let bytes = from_record(&r).encode_to_vec();
            let back = decode(&bytes, &layout).unwrap();
            assert!(same(&r, &back), "{r:?}\n{back:?}");
            // A message reused from a different record encodes the same bytes as a fresh one.
            fill(&mut reused, &r);
            assert_eq!(reused.encode_to_vec(), bytes, "tick {}", r.seq);
        }
    }

    #[test]
    fn only_a_record_without_inputs_carries_its_observation() {
        for r in records() {
            let msg = from_record(&r);
            if r.inputs.is_some() {
                assert!(msg.obs.is_empty(), "tick {}: recomputed, not stored", r.seq);
            } else {
                assert_eq!(
                    msg.obs.len(),
                    44,
                    "tick {}: nothing to recompute it from",
                    r.seq
                );
                let back = decode(&msg.encode_to_vec(), &layout()).unwrap();
                assert_eq!(back.inputs, None);
                assert!(same(&r, &back));
            }
        }
    }

    #[test]
    fn bad_bytes_and_bad_values_are_errors_naming_them() {
        let layout = layout();
        assert!(matches!(
            decode(&[0xff, 0xff, 0xff], &layout),
            Err(TickDecodeError::Malformed(_))
        ));
        let mut msg = from_record(&records()[0]);
        msg.mode = 9;
        let err = decode(&msg.encode_to_vec(), &layout).unwrap_err();
        assert_eq!(
            err,
            TickDecodeError::BadValue {
                field: "mode",
                value: 9
            }
        );
        let mut msg = from_record(&records()[0]);
        msg.command = Some(Wheels {
            left_mm_s: 40_000,
            right_mm_s: 0,
        });
        let err = decode(&msg.encode_to_vec(), &layout).unwrap_err();
        assert!(err.to_string().contains("`command`"), "{err}");
        let mut msg = from_record(&records()[0]);
        msg.mode = 0;
        assert!(
            decode(&msg.encode_to_vec(), &layout).is_err(),
            "an unspecified mode"
        );
    }
}
