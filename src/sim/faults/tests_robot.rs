//! Tests of [`FaultInjector`]'s robot-side faults: Safe-mode trips, the mode+1 quirk, a slow line,
//! the boot banner.

use super::tests::*;
use super::*;
use crate::oi::packets::{bits, id};
use crate::oi::parser::StreamParser;
use crate::sim::robot::OiMode;

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
