//! Unit tests of the plausibility checks: every bound, the simulated robots that must never trip one,
//! and the faulted streams whose silently wrong frames the checks catch.
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
const FAULTS: &str = "drop=1e-3,flip=1e-3,dup=1e-3,text=0.02,inside=0.02,burst=0.02,burst_steps=6";

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
        let (flips_plain, flips_checked) = wrong_frames(model, Damage::CompensatingFlips, 4000, 31);
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

proptest::proptest! {
    /// The parser's laid-out bounds give the answer of the ordered search, whatever the values (near and
    /// beyond the bounds), the packets present and waived, the model and the context; the cache is kept
    /// across calls, as the parser keeps it.
    #[test]
    fn laid_out_bounds_answer_as_the_search_does(
        frames in proptest::collection::vec(
            (
                proptest::collection::vec(
                    proptest::prop_oneof![4 => 0..2i32, 1 => -2..5_000i32, 1 => proptest::num::i32::ANY],
                    59,
                ),
                proptest::num::u64::ANY,
                proptest::num::u64::ANY,
                proptest::bool::ANY,
                proptest::bool::ANY,
            ),
            1..20,
        ),
    ) {
        let mut cache = None;
        for (raw, present, waived, create2, follows) in frames {
            let model = if create2 { Model::Create2 } else { Model::Create1 };
            let context = if follows { FrameContext::FollowsFrame } else { FrameContext::First };
            let mut values = SensorValues::new();
            for (id, &v) in raw.iter().enumerate() {
                if present & (1 << id) != 0 {
                    values.set(id as u8, v);
                }
            }
            // Mostly nothing waived, as in a running parser.
            let waived = Waived(if waived % 4 == 0 { waived } else { 0 });
            proptest::prop_assert_eq!(
                FrameCheck::implausible(&mut cache, &values, model, context, waived),
                implausible_except(&values, model, context, waived)
            );
        }
    }
}
