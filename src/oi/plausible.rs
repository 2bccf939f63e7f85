//! Plausibility of a frame's values: can a Create have sent them at all?
//!
//! A stream frame passes the parser's structural checks (header, length, ids, 8-bit checksum) by
//! chance about once in 256 when it is damaged in a way that keeps its length: two bit flips that
//! cancel in the sum, or a frame shifted by a dropped or duplicated byte. Such a frame carries
//! values that are mostly impossible for a real robot: a bit set where the specification says the
//! bit is unused, a boolean of 37, a cliff signal of 40 000. [`implausible`] finds the first value
//! outside what the specifications allow, so the parser can reject the frame instead of committing
//! it (reference §4.3 items 2 and 9: "validate ranges (e.g. 35 ≤ 3, cliff signals ≤ 4095) to detect
//! misalignment").
//!
//! Every bound is documented, and chosen so that **no genuine frame can break it**: where a source
//! is unsure, or the two models' documents disagree, the wider range is used, and a packet without a
//! range is not checked — except two bounds derived from physical limits with a wide margin (22
//! voltage, 54–57 motor currents). Should any bound still be wrong for some robot, the waiver below
//! limits the cost to a few frames. Sources: `../shared/reference/create_oi.md`, its packet table
//! §3.2 (from [C1 pp17–21, 24–25; C2 pp23–32, 37–39]) unless a page is given.
//!
//! | Packet | Create 1 | Create 2 | Source / reasoning |
//! |---|---|---|---|
//! | 7 bumps & wheel drops | 0–31 | 0–15 | C1 bits 0–4 (bit 4 caster drop), C2 bits 0–3, "(0–15)" [C1 p17; C2 p24] |
//! | 8 wall, 9–12 cliffs, 13 virtual wall | 0–1 | 0–1 | booleans, "0–1" |
//! | 14 overcurrents | 0–31 | 0–31 | bits 0–4; C2 says 0–29 but bit 1 is "reserved", so not assumed 0 |
//! | 15 C1 unused / C2 dirt detect | 0 | — | C1 "always 0"; C2 0–255 |
//! | 16 unused | 0 | 0 | "always 0" on both |
//! | 21 charging state | 0–5 | 0–6 | codes 0–5 [C1 p19; C2 p27]; the C2 membership table says 0–6 |
//! | 22 voltage | 0–25 000 mV | 0–25 000 mV | *derived*: battery rail 10–20.5 V incl. charger [BATT, §1.1], + 20 % |
//! | 27 wall signal | 0–4095 | 0–1023 | "0–4095" / "0–1023" |
//! | 28–31 cliff signals | 0–4095 | 0–4095 | "0–4095"; §4.3 item 9 |
//! | 32 cargo-bay digital inputs | 0–31 | — | C1 bits 0–4; the C2 "unused" byte is not said to be 0 |
//! | 33 cargo-bay analog signal | 0–1023 | — | C1 10-bit; C2 unused bytes |
//! | 34 charging sources | 0–3 | 0–3 | bits 0–1, "0–3" |
//! | 35 OI mode | 0–4 | 0–4 | 0–3, plus the mode+1 firmware quirk (create_robot#64, libcreate#67; §5.5) |
//! | 36 song number | 0–15 | 0–15 | C1 0–15; C2 table 0–4 but its text says 0–15 |
//! | 37 song playing | 0–1 | 0–1 | boolean |
//! | 38 stream packet count | 0–43 | 0–108 | C1 0–43 (quick reference 0–42), C2 0–108 |
//! | 39 requested velocity | ±500 | ±500 | "−500..500 mm/s" (see the note on waivers) |
//! | 41, 42 requested right / left velocity | ±500 | ±500 | "−500..500 mm/s" |
//! | 45 light bumper | — | 0–127 | "0–127" [C2 p38] |
//! | 46–51 light-bump signals | — | 0–4095 | "0–4095" |
//! | 54–57 wheel / brush motor currents | — | ±10 000 mA | *derived*: no documented range; brush drivers rated ≤ 1.45 A [BATT, §5.3], wheels limited at 1 A [C1 p10]; 10 A is several times any stall |
//! | 58 stasis | — | 0–3 | bits 0–1 [C2 p32, p38] |
//! | 19 distance (frame after a frame) | ±500 mm | ±500 mm | 15 ms at 500 mm/s is 7.5 mm; see below |
//! | 20 angle (frame after a frame) | ±360° | ±360° | 15 ms at 4.3 rad/s is 3.7° (×3.1 on C2 fw ≤ 3.4.0 [C2 p27]) |
//!
//! Not checked, on purpose: 17/52/53 IR codes, 18 buttons (unused bits not stated to be 0), 23 battery
//! current (charger transients undocumented), 24 temperature, 25/26 battery charge and capacity (no
//! documented limit; charge vs capacity is an estimate the firmware may get wrong), 43/44 encoders
//! (wrap), 40 requested radius (any value is echoed; C2 firmware < 3.3.0 reports it wrong).
//!
//! **Waivers.** A damaged frame is an isolated event: the frames around it are good. A value that
//! breaks its bound in many frames in a row is therefore genuine, whatever the documents say (a
//! firmware that echoes an out-of-range Drive velocity in 39, a pack above 25 V). The parser waives a
//! packet's bound after [`WAIVE_AFTER`] consecutive frames rejected for that packet with no frame
//! accepted between them, so a wrong bound costs a fraction of a second of frames, not the link.
//! (The simulator, for one, echoes a Drive velocity in 39 without clamping it to ±500 mm/s; the host
//! never sends one out of range.)
//!
//! Distance (19) and angle (20) are what accumulated **since the last report** [C1 p18–19; C2 p27]:
//! in a running stream that is 15 ms, but the first frame after a pause, a new stream request or a
//! reconnect may carry any amount (capped at ±32767). They are therefore checked only for a frame
//! that directly follows an accepted frame ([`FrameContext::FollowsFrame`]); the parser decides that
//! (see [`super::parser`]). The ±500 mm and ±360° bounds leave a wide margin (a whole second of full
//! speed) for timing jitter and frames the robot could not send.

use super::packets::id;
use super::{Model, SensorValues};

/// One documented range of one packet's raw value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bound {
    /// Packet id (7–58).
    pub id: u8,
    /// Smallest value a Create can report.
    pub min: i32,
    /// Largest value a Create can report.
    pub max: i32,
}

/// Why a frame's values cannot come from a Create: the first packet found outside its bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error, serde::Serialize)]
#[error("packet {id} = {value} is outside {min}..={max}, impossible for a Create")]
pub struct Implausible {
    /// The packet.
    pub id: u8,
    /// The value the frame carried.
    pub value: i32,
    /// The bound it broke.
    pub min: i32,
    /// The bound it broke.
    pub max: i32,
}

/// Where a frame sits in the stream, which decides whether its odometry is bounded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameContext {
    /// The frame directly follows an accepted frame (one 15 ms stream period after it): distance and
    /// angle hold 15 ms of motion and are bounded.
    FollowsFrame,
    /// The first frame after a start, a reconnect, a pause or skipped bytes: distance and angle may
    /// hold any accumulated motion and are not checked.
    First,
}

const fn b(id: u8, min: i32, max: i32) -> Bound {
    Bound { id, min, max }
}

/// The largest plausible battery voltage, mV (see the module table).
pub const MAX_VOLTAGE_MV: i32 = 25_000;
/// The largest plausible motor current (packets 54–57), mA, either sign.
pub const MAX_MOTOR_CURRENT_MA: i32 = 10_000;
/// Consecutive frames rejected for the same packet, none accepted between, after which the parser
/// takes the value as genuine and stops checking that packet.
pub const WAIVE_AFTER: u32 = 16;
/// The largest plausible distance in a frame that follows a frame, mm.
pub const MAX_FRAME_DISTANCE_MM: i32 = 500;
/// The largest plausible angle in a frame that follows a frame, degrees.
pub const MAX_FRAME_ANGLE_DEG: i32 = 360;

/// The bounds checked in every Create 1 frame (packets 7–42).
static CREATE1: &[Bound] = &[
    b(id::BUMPS_WHEEL_DROPS, 0, 31),
    b(id::WALL, 0, 1),
    b(id::CLIFF_LEFT, 0, 1),
    b(id::CLIFF_FRONT_LEFT, 0, 1),
    b(id::CLIFF_FRONT_RIGHT, 0, 1),
    b(id::CLIFF_RIGHT, 0, 1),
    b(id::VIRTUAL_WALL, 0, 1),
    b(id::OVERCURRENTS, 0, 31),
    b(id::DIRT_DETECT, 0, 0),
    b(id::UNUSED_16, 0, 0),
    b(id::CHARGING_STATE, 0, 5),
    b(id::VOLTAGE, 0, MAX_VOLTAGE_MV),
    b(id::WALL_SIGNAL, 0, 4095),
    b(id::CLIFF_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::CLIFF_RIGHT_SIGNAL, 0, 4095),
    b(id::CARGO_BAY_DIGITAL_INPUTS, 0, 31),
    b(id::CARGO_BAY_ANALOG_SIGNAL, 0, 1023),
    b(id::CHARGING_SOURCES, 0, 3),
    b(id::OI_MODE, 0, 4),
    b(id::SONG_NUMBER, 0, 15),
    b(id::SONG_PLAYING, 0, 1),
    b(id::STREAM_PACKET_COUNT, 0, 43),
    b(id::REQUESTED_VELOCITY, -500, 500),
    b(id::REQUESTED_RIGHT_VELOCITY, -500, 500),
    b(id::REQUESTED_LEFT_VELOCITY, -500, 500),
];

/// The bounds checked in every Create 2 frame (packets 7–58).
static CREATE2: &[Bound] = &[
    b(id::BUMPS_WHEEL_DROPS, 0, 15),
    b(id::WALL, 0, 1),
    b(id::CLIFF_LEFT, 0, 1),
    b(id::CLIFF_FRONT_LEFT, 0, 1),
    b(id::CLIFF_FRONT_RIGHT, 0, 1),
    b(id::CLIFF_RIGHT, 0, 1),
    b(id::VIRTUAL_WALL, 0, 1),
    b(id::OVERCURRENTS, 0, 31),
    b(id::UNUSED_16, 0, 0),
    b(id::CHARGING_STATE, 0, 6),
    b(id::VOLTAGE, 0, MAX_VOLTAGE_MV),
    b(id::WALL_SIGNAL, 0, 1023),
    b(id::CLIFF_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::CLIFF_RIGHT_SIGNAL, 0, 4095),
    b(id::CHARGING_SOURCES, 0, 3),
    b(id::OI_MODE, 0, 4),
    b(id::SONG_NUMBER, 0, 15),
    b(id::SONG_PLAYING, 0, 1),
    b(id::STREAM_PACKET_COUNT, 0, 108),
    b(id::REQUESTED_VELOCITY, -500, 500),
    b(id::REQUESTED_RIGHT_VELOCITY, -500, 500),
    b(id::REQUESTED_LEFT_VELOCITY, -500, 500),
    b(id::LIGHT_BUMPER, 0, 127),
    b(id::LIGHT_BUMP_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_RIGHT_SIGNAL, 0, 4095),
    b(
        id::LEFT_MOTOR_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::RIGHT_MOTOR_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::MAIN_BRUSH_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::SIDE_BRUSH_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(id::STASIS, 0, 3),
];

/// Odometry bounds, checked only in a frame that follows a frame (both models).
static ODOMETRY: &[Bound] = &[
    b(id::DISTANCE, -MAX_FRAME_DISTANCE_MM, MAX_FRAME_DISTANCE_MM),
    b(id::ANGLE, -MAX_FRAME_ANGLE_DEG, MAX_FRAME_ANGLE_DEG),
];

/// The bounds checked in every frame from `model` (odometry excluded: see [`odometry_bounds`]).
pub fn bounds(model: Model) -> &'static [Bound] {
    match model {
        Model::Create1 => CREATE1,
        Model::Create2 => CREATE2,
    }
}

/// The distance and angle bounds of a frame that follows a frame.
pub fn odometry_bounds() -> &'static [Bound] {
    ODOMETRY
}

/// The first value of `values` that no `model` Create can report in a frame in `context`, or `None`
/// when every present value is plausible. Absent packets are not checked.
pub fn implausible(
    values: &SensorValues,
    model: Model,
    context: FrameContext,
) -> Option<Implausible> {
    implausible_except(values, model, context, Waived::NONE)
}

/// A set of packets whose bounds are not checked (ids 0–63).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Waived(u64);

impl Waived {
    /// No packet waived.
    pub const NONE: Waived = Waived(0);

    /// Adds packet `id` (ids above 63 are ignored: there are none).
    pub fn insert(&mut self, id: u8) {
        if id < 64 {
            self.0 |= 1 << id;
        }
    }

    /// Whether packet `id`'s bound is waived.
    pub fn contains(self, id: u8) -> bool {
        id < 64 && self.0 & (1 << id) != 0
    }

    /// The waived packet ids, in increasing order.
    pub fn ids(self) -> impl Iterator<Item = u8> {
        (0..64u8).filter(move |&id| self.contains(id))
    }
}

/// Like [`implausible`], but not checking the packets in `waived`.
pub fn implausible_except(
    values: &SensorValues,
    model: Model,
    context: FrameContext,
    waived: Waived,
) -> Option<Implausible> {
    let odometry = match context {
        FrameContext::FollowsFrame => ODOMETRY,
        FrameContext::First => &[],
    };
    bounds(model).iter().chain(odometry).find_map(|bound| {
        if waived.contains(bound.id) {
            return None;
        }
        let value = values.get(bound.id)?;
        (!(bound.min..=bound.max).contains(&value)).then_some(Implausible {
            id: bound.id,
            value,
            min: bound.min,
            max: bound.max,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::command::{Command, Radius, last_song_number};
    use crate::oi::frame::{STREAM_HEADER, byte_sum, encode_stream_frame};
    use crate::oi::packets::{bits, spec};
    use crate::oi::parser::{ParserStats, StreamParser};
    use crate::rng::Rng;
    use crate::sim::faults::{FaultInjector, FaultSpec};
    use crate::sim::params::SimParams;
    use crate::sim::robot::SimRobot;
    use crate::sim::world::{LEFT, RIGHT};

    const MODELS: [Model; 2] = [Model::Create1, Model::Create2];

    fn robot(model: Model, seed: u64) -> SimRobot {
        SimRobot::new(model, SimParams::for_model(model), seed)
    }

    fn send(robot: &mut SimRobot, command: Command) {
        let bytes = command.encode(robot.model()).unwrap();
        robot.receive(&bytes);
    }

    fn checked(list: &[u8], model: Model) -> StreamParser {
        StreamParser::new(list).unwrap().with_model(model)
    }

    /// Every packet of `model` with an idle simulated robot's values.
    fn idle_values(model: Model) -> SensorValues {
        let mut r = robot(model, 1);
        r.step();
        r.sensors()
    }

    #[test]
    fn every_bound_rejects_a_frame_with_a_valid_checksum_and_accepts_its_limits() {
        for model in MODELS {
            let group = model.all_sensors_group();
            let base = idle_values(model);
            assert_eq!(implausible(&base, model, FrameContext::FollowsFrame), None);
            let first = encode_stream_frame(&[group], &base).unwrap();
            for bound in bounds(model).iter().chain(odometry_bounds()) {
                let (lo, hi) = spec(bound.id).unwrap().wire_range();
                assert!(lo <= bound.min && bound.max <= hi, "{bound:?}");
                let outside = [bound.min - 1, bound.max + 1];
                let wire_outside: Vec<i32> = outside
                    .into_iter()
                    .filter(|v| (lo..=hi).contains(v))
                    .collect();
                assert!(
                    !wire_outside.is_empty(),
                    "{bound:?} rejects nothing the wire can carry"
                );
                for (value, plausible) in [(bound.min, true), (bound.max, true)]
                    .into_iter()
                    .chain(wire_outside.iter().map(|&v| (v, false)))
                {
                    let mut v = base.clone();
                    v.set(bound.id, value);
                    let frame = encode_stream_frame(&[group], &v).unwrap();
                    assert_eq!(byte_sum(&frame), 0);
                    let mut stream = first.clone();
                    stream.extend(&frame);
                    let mut plain = StreamParser::new(&[group]).unwrap();
                    let mut p = checked(&[group], model);
                    let (mut n_plain, mut got) = (0, Vec::new());
                    plain.feed(&stream, |_| n_plain += 1);
                    p.feed(&stream, |f| got.push(f));
                    assert_eq!(n_plain, 2, "the checksum holds");
                    let what = format!("{model} packet {} = {value}", bound.id);
                    if plausible {
                        assert_eq!(got.len(), 2, "{what}");
                        assert_eq!(got[1].get(bound.id), Some(value), "{what}");
                    } else {
                        assert_eq!(got.len(), 1, "{what}");
                        assert_eq!(p.stats().implausible_frames, 1, "{what}");
                        assert_eq!(p.stats().bad_frames, 1, "{what}");
                        let why = p.last_implausible().unwrap();
                        assert_eq!((why.id, why.value), (bound.id, value), "{what}");
                    }
                }
            }
        }
    }

    #[test]
    fn models_differ_where_the_specifications_do() {
        let mut v = SensorValues::new();
        v.set(id::BUMPS_WHEEL_DROPS, bits::WHEEL_DROP_CASTER);
        assert_eq!(implausible(&v, Model::Create1, FrameContext::First), None);
        assert_eq!(
            implausible(&v, Model::Create2, FrameContext::First).map(|w| w.max),
            Some(15)
        );
        let mut v = SensorValues::new();
        v.set(id::WALL_SIGNAL, 2000);
        v.set(id::DIRT_DETECT, 200);
        assert!(implausible(&v, Model::Create1, FrameContext::First).is_some());
        assert_eq!(
            implausible(&v, Model::Create2, FrameContext::First).map(|w| w.id),
            Some(id::WALL_SIGNAL)
        );
        v.set(id::WALL_SIGNAL, 1023);
        assert_eq!(implausible(&v, Model::Create2, FrameContext::First), None);
        assert!(implausible(&v, Model::Create1, FrameContext::First).is_some());
        // Absent packets are not checked; the mode+1 quirk is plausible.
        assert_eq!(
            implausible(
                &SensorValues::new(),
                Model::Create1,
                FrameContext::FollowsFrame
            ),
            None
        );
        let mut v = SensorValues::new();
        v.set(id::OI_MODE, 4);
        assert_eq!(implausible(&v, Model::Create2, FrameContext::First), None);
        v.set(id::OI_MODE, 5);
        let why = implausible(&v, Model::Create2, FrameContext::First).unwrap();
        assert_eq!(
            why.to_string(),
            "packet 35 = 5 is outside 0..=4, impossible for a Create"
        );
    }

    /// What a scenario run went through, so a test can tell it reached the situations it claims.
    #[derive(Debug, Default)]
    struct Seen {
        frames: u64,
        stalled_steps: u64,
        overcurrent_frames: u64,
        bump_frames: u64,
        drop_frames: u64,
        cliff_frames: u64,
        quirk_frames: u64,
        song_frames: u64,
        passive_frames: u64,
        max_abs_distance: i32,
        max_abs_angle: i32,
    }

    impl Seen {
        fn note(&mut self, v: &SensorValues) {
            self.frames += 1;
            let has = |id, mask| v.get(id).is_some_and(|x| x & mask != 0);
            self.overcurrent_frames += u64::from(has(id::OVERCURRENTS, 0x18));
            self.bump_frames += u64::from(has(id::BUMPS_WHEEL_DROPS, 0x03));
            self.drop_frames += u64::from(has(id::BUMPS_WHEEL_DROPS, 0x0C));
            let cliff = [9, 10, 11, 12].iter().any(|&c| v.get(c) == Some(1));
            self.cliff_frames += u64::from(cliff);
            self.quirk_frames += u64::from(v.get(id::OI_MODE) == Some(4));
            self.passive_frames += u64::from(v.get(id::OI_MODE) == Some(1));
            self.song_frames += u64::from(v.get(id::SONG_PLAYING) == Some(1));
            let d = v.get_or_zero(id::DISTANCE).abs();
            let a = v.get_or_zero(id::ANGLE).abs();
            self.max_abs_distance = self.max_abs_distance.max(d);
            self.max_abs_angle = self.max_abs_angle.max(a);
        }
    }

    /// A random valid host command that moves the robot (as the host's encoder allows them).
    fn random_motion(rng: &mut Rng) -> Command {
        let speed = |rng: &mut Rng| rng.uniform(-500.0, 500.0).round() as i16;
        match rng.below(5) {
            0 => Command::DriveDirect {
                right: 500,
                left: 500,
            },
            1 => Command::DriveDirect {
                right: 500,
                left: -500,
            },
            2 => Command::DriveDirect {
                right: speed(rng),
                left: speed(rng),
            },
            _ => {
                let radius = match rng.below(4) {
                    0 => Radius::Straight,
                    1 => Radius::TurnInPlaceClockwise,
                    2 => Radius::TurnInPlaceCounterClockwise,
                    _ => {
                        let r = rng.uniform(2.0, 2000.0).round() as i16;
                        Radius::Mm(if rng.chance(0.5) { r } else { -r })
                    }
                };
                Command::Drive {
                    velocity: speed(rng),
                    radius,
                }
            }
        }
    }

    /// Runs a streaming simulated robot of `model` for `steps` steps through driving, wall stalls, lifts,
    /// cliffs, mode changes and trips, the mode+1 quirk and songs, parsing every frame with plausibility
    /// checks.
    fn scenario(model: Model, list: &[u8], steps: u64, seed: u64) -> (ParserStats, u64, Seen) {
        let mut rng = Rng::new(seed);
        let mut r = robot(model, seed);
        let mut parser = checked(list, model);
        let mut seen = Seen::default();
        send(&mut r, Command::Start);
        send(&mut r, Command::Full);
        let top_song = last_song_number(model);
        send(
            &mut r,
            Command::Song {
                number: top_song,
                notes: vec![(60, 32), (64, 32)],
            },
        );
        send(&mut r, Command::Stream(list.to_vec()));
        for step in 0..steps {
            if step % 60 == 0 {
                send(&mut r, random_motion(&mut rng));
                // Lifts and cliffs last one period.
                r.world_mut().set_lifted(false);
                (0..4).for_each(|i| r.world_mut().set_cliff(i, false));
                match rng.below(12) {
                    0 => send(&mut r, Command::Safe),
                    1 => send(&mut r, Command::Full),
                    2 => send(&mut r, Command::Start),
                    3 => r.world_mut().set_lifted(true),
                    4 => {
                        let i = rng.below(4) as usize;
                        r.world_mut().set_cliff(i, true);
                    }
                    5 => r.set_mode_quirk(!r.mode_quirk()),
                    6 => send(&mut r, Command::Play(top_song)),
                    7 if r.oi_mode().code() == 1 => send(&mut r, Command::Full),
                    _ => {}
                }
                // Keep the robot mostly driving.
                if r.oi_mode().code() <= 1 && rng.chance(0.5) {
                    send(&mut r, Command::Full);
                    send(&mut r, random_motion(&mut rng));
                }
            }
            r.step();
            seen.stalled_steps += u64::from(r.world().stalled(LEFT) || r.world().stalled(RIGHT));
            parser.feed(&r.take_output(), |v| seen.note(&v));
        }
        (parser.stats(), r.counters().frames_sent, seen)
    }

    #[test]
    fn the_simulated_robot_never_sends_an_implausible_frame() {
        for model in MODELS {
            let group = model.all_sensors_group();
            for (list, seed) in [(vec![group], 11), (vec![19, 20, 35, 41, 42], 12)] {
                let (stats, sent, seen) = scenario(model, &list, 8000, seed);
                let what = format!("{model} {list:?}: {stats:?} {seen:?}");
                println!("{what}");
                assert_eq!(stats.implausible_frames, 0, "{what}");
                assert_eq!(stats.bad_frames, 0, "{what}");
                assert_eq!(stats.good_frames, sent, "{what}");
                assert_eq!(seen.frames, 8000, "{what}");
                assert!(seen.max_abs_angle >= 3, "spun at full speed: {what}");
                assert!(seen.quirk_frames > 0 && seen.passive_frames > 0, "{what}");
                if list == [group] {
                    assert!(seen.stalled_steps > 50, "{what}");
                    assert!(seen.overcurrent_frames > 10, "{what}");
                    assert!(seen.bump_frames > 10, "{what}");
                    assert!(seen.drop_frames > 10 && seen.cliff_frames > 10, "{what}");
                    assert!(seen.song_frames > 10, "{what}");
                }
            }
        }
    }

    #[test]
    fn a_paused_stream_resumes_with_a_first_frame_after_a_reset() {
        for model in MODELS {
            let list = [20, 35];
            let mut r = robot(model, 21);
            send(&mut r, Command::Start);
            send(&mut r, Command::Full);
            send(
                &mut r,
                Command::DriveDirect {
                    right: 500,
                    left: -500,
                },
            );
            send(&mut r, Command::Stream(list.to_vec()));
            let mut parser = checked(&list, model);
            for _ in 0..100 {
                r.step();
                parser.feed(&r.take_output(), |_| {});
            }
            // Two seconds spinning at full speed while paused: the first frame holds ~500°.
            send(&mut r, Command::PauseStream);
            (0..135).for_each(|_| r.step());
            send(&mut r, Command::ResumeStream);
            r.step();
            let resumed = r.take_output();
            let mut without_reset = parser.clone();
            assert_eq!(without_reset.feed_newest(&resumed), None, "{model}");
            assert_eq!(
                without_reset.last_implausible().map(|w| w.id),
                Some(id::ANGLE)
            );
            parser.reset();
            let angle = parser.feed_newest(&resumed).and_then(|v| v.get(id::ANGLE));
            assert!(
                angle.is_some_and(|a| a.abs() > MAX_FRAME_ANGLE_DEG),
                "{model}: {angle:?}"
            );
            assert_eq!(parser.stats().implausible_frames, 0);
        }
    }

    /// Committed frames of a faulted stream, judged against what the robot sent: `(genuine, wrong)`.
    /// A committed frame that is nowhere in the sent ones is silently wrong.
    fn judge(sent: &[SensorValues], committed: &[SensorValues]) -> (usize, usize) {
        let mut next = 0;
        let mut wrong = 0;
        for frame in committed {
            match sent
                .get(next..)
                .and_then(|rest| rest.iter().position(|s| s == frame))
            {
                Some(k) => next += k + 1,
                None => wrong += 1,
            }
        }
        (committed.len() - wrong, wrong)
    }

    /// A `model` robot in Full mode streaming its all-sensors group through `faults` for `steps`
    /// steps, parsed with and without plausibility checks: `((genuine, wrong) without, with, stats with)`.
    /// With `wander` false the robot only turns in place at 100 mm/s, exactly as in `sim::faults`' test.
    fn faulted_run(
        model: Model,
        faults: &str,
        steps: usize,
        seed: u64,
        wander: bool,
    ) -> ((usize, usize), (usize, usize), ParserStats) {
        let group = model.all_sensors_group();
        let spec: FaultSpec = faults.parse().unwrap();
        let mut r = robot(model, seed);
        let mut injector = FaultInjector::new(spec, seed);
        injector.configure(&mut r);
        let mut rng = Rng::new(seed);
        send(&mut r, Command::Start);
        send(&mut r, Command::Full);
        let spin = Command::Drive {
            velocity: 100,
            radius: Radius::TurnInPlaceCounterClockwise,
        };
        send(&mut r, spin);
        send(&mut r, Command::Stream(vec![group]));
        let mut reference = StreamParser::new(&[group]).unwrap();
        let mut plain = StreamParser::new(&[group]).unwrap();
        let mut with = checked(&[group], model);
        let (mut sent, mut by_plain, mut by_checked) = (Vec::new(), Vec::new(), Vec::new());
        for step in 0..steps {
            if wander && step % 100 == 0 {
                send(&mut r, random_motion(&mut rng));
            }
            r.step();
            let clean = r.take_output();
            reference.feed(&clean, |v| sent.push(v));
            let outcome = injector.after_step(&mut r, clean);
            plain.feed(&outcome.bytes, |v| by_plain.push(v));
            with.feed(&outcome.bytes, |v| by_checked.push(v));
        }
        assert_eq!(sent.len(), steps);
        (
            judge(&sent, &by_plain),
            judge(&sent, &by_checked),
            with.stats(),
        )
    }

    /// The fault mix of `sim::faults`' silently-wrong-frames test.
    const FAULTS: &str =
        "drop=1e-3,flip=1e-3,dup=1e-3,text=0.02,inside=0.02,burst=0.02,burst_steps=6";

    #[test]
    fn plausibility_checks_cut_the_silently_wrong_frames_of_a_faulted_stream() {
        // The first case is the stream of `sim::faults`' test, byte for byte.
        let cases = [
            (Model::Create2, 3, false),
            (Model::Create2, 4, true),
            (Model::Create1, 3, false),
            (Model::Create1, 4, true),
        ];
        for (model, seed, wander) in cases {
            let steps = 20_000;
            let ((genuine_plain, wrong_plain), (genuine_checked, wrong_checked), stats) =
                faulted_run(model, FAULTS, steps, seed, wander);
            println!(
                "{model} seed {seed} wander {wander}: {steps} frames sent; without checks {genuine_plain} genuine + {wrong_plain} \
                 silently wrong committed; with checks {genuine_checked} genuine + {wrong_checked} \
                 wrong, {} implausible rejected",
                stats.implausible_frames
            );
            assert!(
                wrong_plain > 0,
                "{model}: the 8-bit sum let damaged frames through"
            );
            assert!(wrong_checked < wrong_plain, "{model}");
            assert!(
                wrong_checked * 4 <= wrong_plain,
                "{model}: checks catch most"
            );
            assert!(stats.implausible_frames as usize >= wrong_plain - wrong_checked);
            // No genuine frame was given up for it.
            assert!(genuine_checked >= genuine_plain, "{model}");
        }
    }

    /// Ways of damaging one frame that an 8-bit sum may miss.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Damage {
        /// The same bit flipped up in one data byte and down in another: the sum always holds.
        CompensatingFlips,
        /// One data or checksum byte lost: the frame claims the next frame's header.
        DroppedByte,
        /// One data or checksum byte received twice.
        DuplicatedByte,
    }

    /// `frame` damaged by `damage` at places drawn from `rng` (never header, length or id bytes).
    fn damage(frame: &[u8], damage: Damage, rng: &mut Rng) -> Vec<u8> {
        let data = 3..frame.len();
        let pick = |rng: &mut Rng| data.start + rng.below(data.len() as u64) as usize;
        let mut out = frame.to_vec();
        match damage {
            Damage::DroppedByte => {
                out.remove(pick(rng));
            }
            Damage::DuplicatedByte => {
                let at = pick(rng);
                out.insert(at, frame[at]);
            }
            Damage::CompensatingFlips => loop {
                let (a, b, bit) = (pick(rng), pick(rng), 1u8 << rng.below(8));
                if a != b && frame[a] & bit == 0 && frame[b] & bit != 0 {
                    out[a] |= bit;
                    out[b] &= !bit;
                    break;
                }
            },
        }
        out
    }

    /// Consecutive clean all-sensors frames of a `model` robot driving about, with their values.
    fn clean_frames(model: Model, n: usize, seed: u64) -> Vec<(Vec<u8>, SensorValues)> {
        let group = model.all_sensors_group();
        let mut rng = Rng::new(seed);
        let mut r = robot(model, seed);
        send(&mut r, Command::Start);
        send(&mut r, Command::Full);
        send(&mut r, Command::Stream(vec![group]));
        let mut reference = StreamParser::new(&[group]).unwrap();
        (0..n)
            .map(|step| {
                if step % 50 == 0 {
                    send(&mut r, random_motion(&mut rng));
                }
                r.step();
                let bytes = r.take_output();
                let values = reference.feed_newest(&bytes).unwrap();
                (bytes, values)
            })
            .collect()
    }

    /// `trials` times: a clean frame, a damaged one, a clean one; how many frames that are none of the
    /// three each parser commits: `(without checks, with checks)`.
    fn wrong_frames(model: Model, kind: Damage, trials: usize, seed: u64) -> (usize, usize) {
        let frames = clean_frames(model, 600, seed);
        let group = model.all_sensors_group();
        let mut rng = Rng::new(seed ^ 0x5eed);
        let (mut wrong_plain, mut wrong_checked) = (0, 0);
        for _ in 0..trials {
            let k = 1 + rng.below(frames.len() as u64 - 2) as usize;
            let around = &frames[k - 1..=k + 1];
            let mut stream = around[0].0.clone();
            stream.extend(damage(&around[1].0, kind, &mut rng));
            stream.extend(&around[2].0);
            assert_eq!(stream.first(), Some(&STREAM_HEADER));
            let is_wrong = |v: &SensorValues| around.iter().all(|(_, g)| g != v);
            let mut plain = StreamParser::new(&[group]).unwrap();
            plain.feed(&stream, |v| wrong_plain += usize::from(is_wrong(&v)));
            let mut with = checked(&[group], model);
            with.feed(&stream, |v| wrong_checked += usize::from(is_wrong(&v)));
        }
        (wrong_plain, wrong_checked)
    }

    #[test]
    fn damage_the_checksum_misses_is_mostly_caught_by_the_ranges() {
        for model in MODELS {
            let (flips_plain, flips_checked) =
                wrong_frames(model, Damage::CompensatingFlips, 4000, 31);
            let (drop_plain, drop_checked) = wrong_frames(model, Damage::DroppedByte, 12_000, 32);
            let (dup_plain, dup_checked) = wrong_frames(model, Damage::DuplicatedByte, 12_000, 33);
            println!(
                "{model}: compensating flips {flips_plain} → {flips_checked} of 4000; dropped byte \
                 {drop_plain} → {drop_checked} of 12000; duplicated byte {dup_plain} → {dup_checked} \
                 of 12000 (silently wrong frames without → with checks)"
            );
            // Every compensating pair passes the sum (unless it flipped a pair back to the same
            // values, which cannot happen: the bits differ).
            assert_eq!(flips_plain, 4000, "{model}");
            // A flip pair inside a low byte or an unchecked packet is invisible; the rest is caught.
            assert!(flips_checked * 3 < flips_plain * 2, "{model}");
            // A frame shifted by a lost byte passes the sum when that byte was 19 (the next header
            // takes the checksum's place); by a repeated one, when it equals the checksum. Its shifted
            // values then rarely fit the ranges (a shift within the last, unchecked packets does).
            assert!(drop_plain + dup_plain >= 10, "{model}");
            assert!(
                (drop_checked + dup_checked) * 4 <= drop_plain + dup_plain,
                "{model}"
            );
        }
    }

    #[test]
    fn a_robot_that_persistently_breaks_a_bound_loses_only_a_few_frames() {
        // The simulator echoes an out-of-range Drive velocity (which the host's encoder never sends)
        // in packet 39; a real firmware might too. The run of rejections waives the bound.
        let mut r = robot(Model::Create2, 41);
        send(&mut r, Command::Start);
        send(&mut r, Command::Full);
        r.receive(&[137, 0x03, 0x84, 0x80, 0x00]); // Drive 900 mm/s straight, raw bytes
        send(&mut r, Command::Stream(vec![100]));
        let mut parser = checked(&[100], Model::Create2);
        let mut accepted = Vec::new();
        for _ in 0..200 {
            r.step();
            parser.feed(&r.take_output(), |v| accepted.push(v));
        }
        assert_eq!(parser.stats().implausible_frames, u64::from(WAIVE_AFTER));
        assert_eq!(accepted.len(), 200 - WAIVE_AFTER as usize);
        assert!(
            accepted
                .iter()
                .all(|v| v.get(id::REQUESTED_VELOCITY) == Some(900))
        );
        assert_eq!(
            parser.waived().ids().collect::<Vec<_>>(),
            vec![id::REQUESTED_VELOCITY]
        );
    }
}
