//! Tests of [`FaultInjector`] on a streaming simulated Create 2, read back through the host's
//! [`StreamParser`].

use super::*;
use crate::oi::Model;
use crate::oi::SensorValues;
use crate::oi::packets::{bits, id};
use crate::oi::parser::StreamParser;
use crate::sim::params::SimParams;
use crate::sim::robot::OiMode;

const START: u8 = 128;
const SAFE: u8 = 131;
const FULL: u8 = 132;
const DRIVE: u8 = 137;
const STREAM: u8 = 148;
/// The Create 2's all-sensors group: an 84-byte frame.
const GROUP: u8 = 100;
const FRAME_LEN: usize = 84;

/// Drive at `velocity` mm/s on `radius` mm (1: turn in place counter-clockwise).
fn drive(velocity: i16, radius: i16) -> Vec<u8> {
    let mut v = vec![DRIVE];
    v.extend_from_slice(&velocity.to_be_bytes());
    v.extend_from_slice(&radius.to_be_bytes());
    v
}

/// A Create 2 in `mode` (SAFE or FULL), turning in place (so every frame differs), streaming group
/// 100, with `spec` configured.
fn robot_with(mode: u8, spec: &FaultSpec, seed: u64) -> (SimRobot, FaultInjector) {
    let mut robot = SimRobot::new(Model::Create2, SimParams::for_model(Model::Create2), seed);
    let injector = FaultInjector::new(spec.clone(), seed);
    injector.configure(&mut robot);
    robot.receive(&[START, mode]);
    robot.receive(&drive(100, 1));
    robot.receive(&[STREAM, 1, GROUP]);
    (robot, injector)
}

fn spec(text: &str) -> FaultSpec {
    text.parse().unwrap()
}

/// One step: the robot's own bytes and what the injector made of them.
fn step(robot: &mut SimRobot, injector: &mut FaultInjector) -> (Vec<u8>, StepOutcome) {
    robot.step();
    let out = robot.take_output();
    let outcome = injector.after_step(robot, out.clone());
    (out, outcome)
}

fn run(
    robot: &mut SimRobot,
    injector: &mut FaultInjector,
    steps: usize,
) -> Vec<(Vec<u8>, StepOutcome)> {
    (0..steps).map(|_| step(robot, injector)).collect()
}

fn frames_of(bytes: &[u8]) -> Vec<SensorValues> {
    let mut parser = StreamParser::new(&[GROUP]).unwrap();
    let mut frames = Vec::new();
    parser.feed(bytes, |v| frames.push(v));
    frames
}

#[test]
fn same_seed_same_bytes_and_another_seed_differs() {
    let outcomes = |seed: u64| {
        let (mut r, _) = robot_with(SAFE, &FaultSpec::all(), 5);
        let mut f = FaultInjector::new(FaultSpec::all(), seed);
        f.configure(&mut r);
        let outs: Vec<StepOutcome> = run(&mut r, &mut f, 3000)
            .into_iter()
            .map(|(_, o)| o)
            .collect();
        (outs, f.counters().clone())
    };
    let (a, ca) = outcomes(9);
    let (b, cb) = outcomes(9);
    assert_eq!(a, b);
    assert_eq!(ca, cb);
    assert!(ca.total_events() > 50, "{ca:?}");
    let (c, _) = outcomes(10);
    assert_ne!(a, c);
}

#[test]
fn observed_byte_fault_rates_match_the_spec() {
    let (mut r, mut f) = robot_with(FULL, &spec("drop=2e-3,flip=3e-3,dup=1e-3"), 1);
    let results = run(&mut r, &mut f, 10_000);
    let c = f.counters().clone();
    let robot_bytes: usize = results.iter().map(|(o, _)| o.len()).sum();
    let wire_bytes: usize = results.iter().map(|(_, s)| s.bytes.len()).sum();
    assert_eq!(c.bytes_seen, robot_bytes as u64);
    assert_eq!(
        wire_bytes as u64,
        c.bytes_seen - c.dropped_bytes + c.duplicated_bytes
    );
    let seen = c.bytes_seen as f64;
    let kept = seen - c.dropped_bytes as f64;
    let observed = [
        (c.dropped_bytes as f64 / seen, 2e-3),
        (c.flipped_bytes as f64 / kept, 3e-3),
        (c.duplicated_bytes as f64 / kept, 1e-3),
    ];
    // ≥ 800 expected events each: ±15 % is more than 4 standard deviations.
    for (rate, want) in observed {
        assert!(
            (rate / want - 1.0).abs() < 0.15,
            "observed {rate} for {want}"
        );
    }
    assert_eq!(c.text_lines + c.hangs + c.eofs + c.bursts + c.trips, 0);
}

#[test]
fn observed_step_event_rates_match_the_spec() {
    let (mut r, mut f) = robot_with(FULL, &spec("text=0.02,inside=0.03,burst=0.01,eof=0.01"), 2);
    let results = run(&mut r, &mut f, 20_000);
    let c = f.counters();
    let eof_outcomes = results
        .iter()
        .filter(|(_, s)| s.link == LinkFault::Eof)
        .count();
    assert_eq!(eof_outcomes as u64, c.eofs);
    assert!(
        results
            .iter()
            .filter(|(_, s)| s.link == LinkFault::Eof)
            .all(|(_, s)| s.bytes.is_empty())
    );
    // Events only fire on normal steps (and bursts only when none is running), so allow for that.
    let within = |n: u64, p: f64| (n as f64 / (20_000.0 * p) - 1.0).abs() < 0.3;
    assert!(within(c.eofs, 0.01), "{c:?}");
    assert!(within(c.text_lines, 0.02), "{c:?}");
    assert!(within(c.text_inside, 0.03), "{c:?}");
    assert!(c.bursts > 100 && c.bursts < 260, "{c:?}");
    assert_eq!(c.hangs + c.trips + c.dropped_bytes, 0);
    // The robot kept running through every end of file.
    assert_eq!(r.elapsed_steps(), 20_000);
}

#[test]
fn every_committed_frame_of_a_faulted_stream_is_one_the_robot_sent() {
    let faults =
        spec("drop=1e-3,flip=1e-3,dup=1e-3,text=0.02,inside=0.02,burst=0.02,burst_steps=6");
    let (mut r, mut f) = robot_with(FULL, &faults, 3);
    let steps = 20_000;
    let mut parser = StreamParser::new(&[GROUP]).unwrap();
    let mut sent: Vec<SensorValues> = Vec::new();
    let mut committed: Vec<SensorValues> = Vec::new();
    for _ in 0..steps {
        let (clean, outcome) = step(&mut r, &mut f);
        sent.extend(frames_of(&clean));
        parser.feed(&outcome.bytes, |v| committed.push(v));
    }
    assert_eq!(sent.len(), steps, "the clean stream parses whole");
    // Committed frames must be the sent ones, in order, with gaps; a frame that is not found next is
    // silently wrong.
    let mut next = 0;
    let mut wrong = 0;
    for frame in &committed {
        match sent
            .get(next..)
            .and_then(|rest| rest.iter().position(|s| s == frame))
        {
            Some(k) => next += k + 1,
            None => {
                // Not a frame out of order either: it is nowhere in what the robot sent.
                assert!(!sent.contains(frame), "a real frame committed out of order");
                wrong += 1;
            }
        }
    }
    let lost = steps - (committed.len() - wrong);
    let stats = parser.stats();
    println!(
        "committed {} of {steps}, lost {lost}, silently wrong {wrong} ({:.3} % of committed, {:.2} % of damaged), bad frames {}",
        committed.len(),
        100.0 * wrong as f64 / committed.len() as f64,
        100.0 * wrong as f64 / lost.max(1) as f64,
        stats.bad_frames
    );
    // The parser keeps finding frames: ~84 bytes × 3e-3 + 4 % text ≈ 28 % damaged at most.
    assert!(committed.len() > steps * 6 / 10, "{}", committed.len());
    assert!(lost > steps / 10, "the faults did damage frames ({lost})");
    assert!(stats.bad_frames > 1000);
    // Only checksum collisions get through: well under 2 % of the damaged frames.
    assert!(wrong * 50 < lost, "{wrong} wrong of {lost} damaged");
}

#[test]
fn text_lines_go_between_frames() {
    let (mut r, mut f) = robot_with(FULL, &spec("text=1"), 4);
    for (clean, outcome) in run(&mut r, &mut f, 200) {
        assert_eq!(clean.len(), FRAME_LEN);
        let text_len = outcome.bytes.len() - FRAME_LEN;
        assert!(text_len > 2);
        let (text, frame) = outcome.bytes.split_at(text_len);
        assert_eq!(frame, &clean[..]);
        assert!(text.iter().all(|&b| is_text_byte(b)) && text.ends_with(b"\r\n"));
    }
    assert_eq!(f.counters().text_lines, 200);
}

#[test]
fn text_inside_is_spliced_strictly_inside_the_frame() {
    let (mut r, mut f) = robot_with(FULL, &spec("inside=1"), 5);
    let mut positions = Vec::new();
    let mut collisions = 0;
    for (clean, outcome) in run(&mut r, &mut f, 300) {
        let bytes = &outcome.bytes;
        let text_len = bytes.len() - clean.len();
        // Some split point p: frame[..p] + line + frame[p..], with the line printable and CR LF ended.
        let at = (1..clean.len()).find(|&p| {
            bytes[..p] == clean[..p]
                && bytes[p + text_len..] == clean[p..]
                && bytes[p..p + text_len].iter().all(|&b| is_text_byte(b))
                && bytes[p..p + text_len].ends_with(b"\r\n")
        });
        positions.push(at.expect("a line spliced inside the frame"));
        // A frame with text inside parses only by a checksum collision (about 1 in 256).
        collisions += frames_of(bytes).len();
    }
    println!("text inside: {collisions} of 300 frames still passed the checks");
    assert!(collisions <= 8, "{collisions}");
    assert_eq!(f.counters().text_inside, 300);
    assert!(positions.iter().min() < Some(&10) && positions.iter().max() > Some(&70));
}

#[test]
fn a_burst_holds_output_then_releases_all_of_it_at_once() {
    let (mut r, mut f) = robot_with(FULL, &spec("burst=0.05,burst_steps=5"), 6);
    let results = run(&mut r, &mut f, 4000);
    let clean: Vec<u8> = results.iter().flat_map(|(c, _)| c.clone()).collect();
    let wire: Vec<u8> = results.iter().flat_map(|(_, s)| s.bytes.clone()).collect();
    assert_eq!(
        wire[..],
        clean[..clean.len() - f.held.len()],
        "nothing lost or reordered"
    );
    let empty = results.iter().filter(|(_, s)| s.bytes.is_empty()).count() as u64;
    assert_eq!(empty, f.counters().held_steps);
    let most = results
        .iter()
        .map(|(_, s)| s.bytes.len() / FRAME_LEN)
        .max()
        .unwrap();
    assert_eq!(
        most, 5,
        "the longest burst releases burst_steps frames at once"
    );
    let bursts = f.counters().bursts;
    assert!(bursts > 130 && bursts < 230, "{bursts}");
}

#[test]
fn a_hang_silences_both_ways_for_the_drawn_duration() {
    let (mut r, mut f) = robot_with(SAFE, &spec("hang=0.01,hang_ms=150"), 7);
    let mut run_len = 0;
    let mut runs = Vec::new();
    for _ in 0..6000 {
        let (clean, outcome) = step(&mut r, &mut f);
        assert_eq!(clean.len(), FRAME_LEN, "the robot keeps streaming");
        if outcome.link == LinkFault::Hung {
            assert!(outcome.bytes.is_empty());
            assert!(f.is_hung());
            run_len += 1;
            // A host command sent now is lost: the robot never executes it.
            let commands = r.counters().commands;
            let reaching = f.host_bytes(&drive(-200, 1)).into_owned();
            assert!(reaching.is_empty());
            r.receive(&reaching);
            assert_eq!(r.counters().commands, commands);
        } else {
            assert_eq!(outcome.bytes, clean);
            assert_eq!(f.host_bytes(&[1, 2, 3]).as_ref(), &[1, 2, 3]);
            if run_len > 0 {
                runs.push(run_len);
                run_len = 0;
            }
        }
    }
    let c = f.counters();
    assert!(c.hangs > 30 && c.hangs < 90, "{c:?}");
    assert_eq!(c.hang_steps, c.hangs * 10, "150 ms = 10 steps each");
    // Back-to-back hangs merge into one silent run.
    assert!(runs.iter().all(|&n| n % 10 == 0), "{runs:?}");
    assert_eq!(c.lost_bytes, c.hang_steps * FRAME_LEN as u64);
    assert!(c.host_lost > 0);
}

#[test]
fn hang_durations_stay_within_their_range() {
    let (mut r, mut f) = robot_with(FULL, &spec("hang=0.005,hang_ms=31..300"), 8);
    let mut lengths = Vec::new();
    let mut hangs_before = 0;
    let mut current = 0;
    for _ in 0..20_000 {
        let (_, outcome) = step(&mut r, &mut f);
        let hangs = f.counters().hangs;
        if hangs != hangs_before && current > 0 {
            lengths.push(current);
            current = 0;
        }
        hangs_before = hangs;
        if outcome.link == LinkFault::Hung {
            current += 1;
        } else if current > 0 {
            lengths.push(current);
            current = 0;
        }
    }
    assert!(lengths.len() > 50);
    // 31 ms → 3 steps, 300 ms → 20 steps.
    assert!(
        lengths.iter().all(|&n| (3..=20).contains(&n)),
        "{lengths:?}"
    );
    assert!(lengths.contains(&3) || lengths.contains(&4));
    assert!(lengths.contains(&20) || lengths.contains(&19));
}

#[test]
fn a_wheel_drop_in_safe_mode_trips_to_passive_and_shows_in_the_next_frame() {
    for (mode, expect) in [(SAFE, 1), (FULL, 3)] {
        let (mut r, mut f) = robot_with(mode, &FaultSpec::none(), 9);
        run(&mut r, &mut f, 10);
        f.inject_trip(&mut r, TripKind::WheelDrop, 5);
        let (_, outcome) = step(&mut r, &mut f);
        let frame = frames_of(&outcome.bytes).pop().unwrap();
        let drops = bits::WHEEL_DROP_LEFT | bits::WHEEL_DROP_RIGHT;
        assert_eq!(frame.get(id::BUMPS_WHEEL_DROPS).unwrap() & drops, drops);
        assert_eq!(frame.get(id::OI_MODE), Some(expect), "mode {mode}");
        // The event ends after its 5 steps; Safe stays tripped.
        let results = run(&mut r, &mut f, 5);
        let last = frames_of(&results[4].1.bytes).pop().unwrap();
        assert_eq!(last.get(id::BUMPS_WHEEL_DROPS).unwrap() & drops, 0);
        assert_eq!(last.get(id::OI_MODE), Some(expect));
        assert_eq!(f.active_trip(), None);
    }
}

#[test]
fn a_cliff_while_driving_forward_in_safe_mode_trips_to_passive() {
    for (mode, expect) in [(SAFE, OiMode::Passive), (FULL, OiMode::Full)] {
        let (mut r, mut f) = robot_with(mode, &FaultSpec::none(), 10);
        r.receive(&drive(100, 0x7FFF));
        run(&mut r, &mut f, 10);
        f.inject_trip(&mut r, TripKind::Cliff(1), 3);
        let (_, outcome) = step(&mut r, &mut f);
        let frame = frames_of(&outcome.bytes).pop().unwrap();
        assert_eq!(frame.get(id::CLIFF_FRONT_LEFT), Some(1));
        assert_eq!(frame.get(id::CLIFF_LEFT), Some(0));
        assert_eq!(r.oi_mode(), expect);
    }
}

#[test]
fn random_trips_of_both_kinds_come_and_go() {
    let (mut r, mut f) = robot_with(FULL, &spec("trip=0.01,trip_ms=15..150"), 11);
    let mut tripped_steps = 0;
    for _ in 0..5000 {
        let (_, outcome) = step(&mut r, &mut f);
        let frame = frames_of(&outcome.bytes).pop().unwrap();
        let cliffs: i32 = [
            id::CLIFF_LEFT,
            id::CLIFF_FRONT_LEFT,
            id::CLIFF_FRONT_RIGHT,
            id::CLIFF_RIGHT,
        ]
        .iter()
        .map(|&p| frame.get_or_zero(p))
        .sum();
        let drops = frame.get_or_zero(id::BUMPS_WHEEL_DROPS) & bits::WHEEL_DROP_LEFT;
        if cliffs > 0 || drops > 0 {
            tripped_steps += 1;
        }
        assert!(cliffs <= 1);
    }
    let c = f.counters();
    assert!(c.wheel_drop_trips > 5 && c.cliff_trips > 5, "{c:?}");
    assert_eq!(c.trips, c.wheel_drop_trips + c.cliff_trips);
    // Each lasts 1..=10 steps: between the shortest and longest possible totals.
    assert!(tripped_steps as u64 + 1 >= c.trips && tripped_steps as u64 <= 10 * c.trips);
    assert_eq!(r.oi_mode(), OiMode::Full, "Full ignores trips");
}

#[test]
fn the_quirk_makes_packet_35_read_mode_plus_one() {
    let (mut r, mut f) = robot_with(SAFE, &spec("quirk"), 12);
    assert!(r.mode_quirk());
    let (_, outcome) = step(&mut r, &mut f);
    assert_eq!(frames_of(&outcome.bytes)[0].get(id::OI_MODE), Some(3));
    r.receive(&[FULL]);
    let (_, outcome) = step(&mut r, &mut f);
    assert_eq!(frames_of(&outcome.bytes)[0].get(id::OI_MODE), Some(4));
    r.receive(&[START]);
    let (_, outcome) = step(&mut r, &mut f);
    assert_eq!(frames_of(&outcome.bytes)[0].get(id::OI_MODE), Some(2));
    assert_eq!(r.oi_mode(), OiMode::Passive);
}

#[test]
fn a_line_at_19200_baud_breaks_the_group_100_stream() {
    for (text, broken) in [("baud=19200", true), ("none", false)] {
        let (mut r, mut f) = robot_with(FULL, &spec(text), 13);
        let mut parser = StreamParser::new(&[GROUP]).unwrap();
        for (_, outcome) in run(&mut r, &mut f, 300) {
            parser.feed(&outcome.bytes, |_| {});
        }
        let stats = parser.stats();
        if broken {
            assert_eq!(r.line_rate(), 19_200);
            assert!(stats.good_frames < 10, "{stats:?}");
            assert!(stats.bad_frames > 200, "{stats:?}");
            assert!(r.counters().dropped_tx_bytes > 10_000);
        } else {
            assert_eq!(stats.good_frames, 300);
            assert_eq!(stats.bad_frames, 0);
        }
    }
}

#[test]
fn the_banner_comes_first_and_once() {
    let (mut r, mut f) = robot_with(FULL, &spec("banner"), 14);
    let results = run(&mut r, &mut f, 3);
    let banner = r.boot_banner().into_bytes();
    assert!(results[0].1.bytes.starts_with(&banner));
    assert!(results[0].1.bytes.ends_with(&results[0].0));
    assert_eq!(results[1].1.bytes, results[1].0);
    assert_eq!(f.counters().banners, 1);
    assert!(String::from_utf8_lossy(&banner).contains("Roomba by iRobot!"));
}

#[test]
fn host_byte_faults_apply_only_when_asked() {
    let mut plain = FaultInjector::new(FaultSpec::none(), 1);
    assert!(matches!(
        plain.host_bytes(&[1, 2, 3]),
        Cow::Borrowed(&[1, 2, 3])
    ));
    let mut lossy = FaultInjector::new(spec("host_drop=1"), 1);
    assert!(lossy.host_bytes(&[1, 2, 3]).is_empty());
    let mut noisy = FaultInjector::new(spec("host_flip=1"), 1);
    let flipped = noisy.host_bytes(&[0, 0, 0]).into_owned();
    assert!(flipped.iter().all(|b| b.count_ones() == 1));
    assert_eq!(noisy.counters().host_flipped, 3);
    assert_eq!(noisy.counters().total_events(), 3);
}

#[test]
fn no_faults_pass_the_robot_bytes_through_untouched() {
    let (mut r, mut f) = robot_with(SAFE, &FaultSpec::none(), 15);
    for (clean, outcome) in run(&mut r, &mut f, 500) {
        assert_eq!(
            outcome,
            StepOutcome {
                bytes: clean,
                link: LinkFault::Normal
            }
        );
    }
    assert_eq!(f.counters().total_events(), 0);
}
