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
//! Every bound is chosen so that **no genuine frame can break it**: where a source is unsure, or
//! the two models' documents disagree, the wider range is used, and a packet without a documented
//! range is not checked. Sources are tags of `../shared/reference/create_oi.md` (§3.2 is its packet
//! table).
//!
//! | Packet | Create 1 | Create 2 | Source / reasoning |
//! |---|---|---|---|
//! | 7 bumps & wheel drops | 0–31 | 0–15 | bits 0–4 (C1 caster bit 4), C2 bits 0–3 "(0–15)" [C1 p17; C2 p24] |
//! | 8 wall, 9–12 cliffs, 13 virtual wall | 0–1 | 0–1 | booleans [C1 p17; C2 p24–25] |
//! | 14 overcurrents | 0–31 | 0–31 | bits 0–4; C2 documents 0–29, but its bit 1 is "reserved", so not assumed 0 |
//! | 15 C1 unused / C2 dirt detect | 0 | — | C1 "always 0" |
//! | 16 unused | 0 | 0 | "always 0" on both |
//! | 21 charging state | 0–5 | 0–6 | codes 0–5; the C2 membership table says 0–6 |
//! | 22 voltage | 0–25 000 mV | 0–25 000 mV | battery rail at most 20.5 V incl. charger [BATT], + 20 % margin |
//! | 27 wall signal | 0–4095 | 0–1023 | [C1 p20; C2 p29] |
//! | 28–31 cliff signals | 0–4095 | 0–4095 | [C1 p20; C2 p29] |
//! | 32 cargo-bay digital inputs | 0–31 | — | C1 bits 0–4; C2 "unused" byte not said to be 0 |
//! | 33 cargo-bay analog signal | 0–1023 | — | C1 10-bit ADC; C2 unused bytes |
//! | 34 charging sources | 0–3 | 0–3 | bits 0–1 |
//! | 35 OI mode | 0–4 | 0–4 | 0–3, plus the mode+1 firmware quirk (create_robot#64, libcreate#67) |
//! | 36 song number | 0–15 | 0–15 | C1 0–15; C2 table 0–4 but its text says 0–15 |
//! | 37 song playing | 0–1 | 0–1 | boolean |
//! | 38 stream packet count | 0–43 | 0–108 | [C1 p21; C2 p29] |
//! | 41, 42 requested right / left velocity | ±500 | ±500 | mm/s [C1 p21; C2 p30] |
//! | 45 light bumper | — | 0–127 | [C2 p38] |
//! | 46–51 light-bump signals | — | 0–4095 | [C2 p38] |
//! | 58 stasis | — | 0–3 | bits 0–1 [C2 p32, p38] |
//! | 19 distance (frame after a frame) | ±500 mm | ±500 mm | 15 ms at 500 mm/s is 7.5 mm; see below |
//! | 20 angle (frame after a frame) | ±360° | ±360° | 15 ms at 4.3 rad/s is 3.7° (×3.1 on C2 fw ≤ 3.4.0) |
//!
//! Not checked, on purpose: 17/52/53 IR codes, 18 buttons (unused bits not stated to be 0), 23 current,
//! 24 temperature, 25/26 battery charge and capacity (no documented limit; charge vs capacity is an
//! estimate the firmware may get wrong), 43/44 encoders (wrap), 54–57 motor currents, 40 requested
//! radius (any value is echoed; C2 firmware < 3.3.0 reports it wrong), and 39 requested velocity:
//! documented as ±500 mm/s, but the simulator echoes a Drive velocity unclamped and the firmware's
//! behaviour for an out-of-range Drive is undocumented.
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
    b(id::REQUESTED_RIGHT_VELOCITY, -500, 500),
    b(id::REQUESTED_LEFT_VELOCITY, -500, 500),
    b(id::LIGHT_BUMPER, 0, 127),
    b(id::LIGHT_BUMP_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_RIGHT_SIGNAL, 0, 4095),
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
    let odometry = match context {
        FrameContext::FollowsFrame => ODOMETRY,
        FrameContext::First => &[],
    };
    bounds(model).iter().chain(odometry).find_map(|bound| {
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
}
