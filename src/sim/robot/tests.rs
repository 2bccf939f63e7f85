//! Byte-level tests of [`SimRobot`]: the mode machine, replies, stream frames, odometry, and the
//! physical behaviour seen through the bytes (latencies, stalls, over-current flags).

use super::*;
use crate::oi::frame::checksum_ok;
use crate::oi::packets::{bits, data_len, decode_data, id};

const START: u8 = 128;
const SAFE: u8 = 131;
const FULL: u8 = 132;
const SENSORS: u8 = 142;
const QUERY: u8 = 149;
const STREAM: u8 = 148;
const STOP: u8 = 173;

fn robot(model: Model) -> SimRobot {
    SimRobot::new(model, SimParams::for_model(model), 7)
}

fn drive_direct(right: i16, left: i16) -> Vec<u8> {
    let mut v = vec![145];
    v.extend_from_slice(&right.to_be_bytes());
    v.extend_from_slice(&left.to_be_bytes());
    v
}

fn stream(ids: &[u8]) -> Vec<u8> {
    let mut v = vec![STREAM, ids.len() as u8];
    v.extend_from_slice(ids);
    v
}

fn steps(r: &mut SimRobot, n: usize) {
    for _ in 0..n {
        r.step();
    }
}

/// Splits `bytes` into stream frames of `ids`, checking each checksum, and decodes them.
fn frames(bytes: &[u8], ids: &[u8]) -> Vec<SensorValues> {
    let n: usize = ids.iter().map(|&i| 1 + data_len(i).unwrap()).sum();
    assert_eq!(bytes.len() % (n + 3), 0, "output is not whole frames");
    bytes
        .chunks(n + 3)
        .map(|f| {
            assert_eq!(f[0], 19);
            assert_eq!(usize::from(f[1]), n);
            assert!(checksum_ok(f), "bad checksum in {f:?}");
            let mut v = SensorValues::new();
            let mut at = 2;
            for &i in ids {
                assert_eq!(f[at], i);
                let len = data_len(i).unwrap();
                decode_data(i, &f[at + 1..at + 1 + len], &mut v).unwrap();
                at += 1 + len;
            }
            v
        })
        .collect()
}

/// Runs `n` steps and returns the frames streamed meanwhile.
fn run_frames(r: &mut SimRobot, n: usize, ids: &[u8]) -> Vec<SensorValues> {
    steps(r, n);
    frames(&r.take_output(), ids)
}

#[test]
fn start_safe_drive_stream_gives_checksummed_frames_of_a_moving_robot() {
    for model in [Model::Create1, Model::Create2] {
        let mut r = robot(model);
        let group = model.all_sensors_group();
        r.receive(&[START, SAFE]);
        r.receive(&drive_direct(150, 150));
        r.receive(&stream(&[group]));
        assert_eq!(r.oi_mode(), OiMode::Safe);
        let fs = run_frames(&mut r, 40, &[group]);
        assert_eq!(fs.len(), 40);
        let last = fs.last().unwrap();
        assert_eq!(last.get(id::OI_MODE), Some(2));
        assert_eq!(last.get(id::REQUESTED_RIGHT_VELOCITY), Some(150));
        assert_eq!(last.get(id::REQUESTED_LEFT_VELOCITY), Some(150));
        assert_eq!(last.get(id::STREAM_PACKET_COUNT), Some(1));
        let travelled: i32 = fs.iter().map(|v| v.get_or_zero(id::DISTANCE)).sum();
        assert!(travelled > 20, "{model}: distance {travelled}");
        assert!(last.get_or_zero(id::CURRENT) < -200, "{model}: current");
        if model == Model::Create2 {
            assert!(last.get_or_zero(id::LEFT_ENCODER) > 40);
            assert!(last.get_or_zero(id::LEFT_MOTOR_CURRENT) > 50);
        }
    }
}

#[test]
fn passive_consumes_and_ignores_drive() {
    let mut r = robot(Model::Create1);
    r.receive(&[START]);
    r.receive(&drive_direct(300, 300));
    steps(&mut r, 70);
    assert_eq!(r.oi_mode(), OiMode::Passive);
    assert_eq!(r.world().odometer_m(), 0.0);
    assert_eq!(r.counters().ignored_in_passive, 1);
    // The data bytes were consumed, not read as opcodes.
    assert_eq!(r.counters().unknown_opcode_bytes, 0);
    r.receive(&[SENSORS, id::OI_MODE]);
    assert_eq!(r.take_output(), vec![1]);
}

#[test]
fn off_listens_only_for_start() {
    let mut r = robot(Model::Create1);
    assert_eq!(r.oi_mode(), OiMode::Off);
    let mut junk = vec![SAFE, SENSORS, 7, 7];
    junk.extend(drive_direct(200, 200));
    junk.extend(stream(&[6]));
    r.receive(&junk);
    steps(&mut r, 10);
    assert!(r.take_output().is_empty());
    assert_eq!(r.oi_mode(), OiMode::Off);
    assert_eq!(r.counters().ignored_in_off, junk.len() as u64);
    r.receive(&[START, SENSORS, id::OI_MODE]);
    assert_eq!(r.oi_mode(), OiMode::Passive);
    assert_eq!(r.take_output(), vec![1]);
}

#[test]
fn create2_reset_and_stop_return_to_off() {
    let mut r = robot(Model::Create2);
    r.receive(&[START, FULL]);
    r.receive(&drive_direct(200, 200));
    r.receive(&stream(&[id::OI_MODE]));
    let fs = run_frames(&mut r, 30, &[id::OI_MODE]);
    assert!(fs.iter().all(|v| v.get(id::OI_MODE) == Some(3)));
    r.receive(&[STOP]);
    assert_eq!(r.oi_mode(), OiMode::Off);
    steps(&mut r, 30);
    assert!(r.take_output().is_empty(), "stream must stop");
    assert!(r.world().wheel_speed_mm_s(LEFT).abs() < 1.0);
    assert!(r.stream_ids().is_empty());
    // Reset works even in Off, prints a banner and stays Off.
    r.receive(&[7]);
    let banner = String::from_utf8(r.take_output()).unwrap();
    assert!(banner.contains("2068 mAH"), "{banner}");
    assert_eq!(r.oi_mode(), OiMode::Off);
    // On the Create 1, 173 is not an opcode: one byte dropped and counted.
    let mut c1 = robot(Model::Create1);
    c1.receive(&[START, STOP]);
    assert_eq!(c1.oi_mode(), OiMode::Passive);
    assert_eq!(c1.counters().unknown_opcode_bytes, 1);
}

#[test]
fn query_list_replies_concatenated_data() {
    let mut r = robot(Model::Create1);
    r.receive(&[START]);
    r.step();
    r.take_output();
    r.receive(&[QUERY, 3, id::BUMPS_WHEEL_DROPS, id::DISTANCE, 6]);
    assert_eq!(r.take_output().len(), 1 + 2 + 52);
    // A packet the Create 1 lacks is skipped and counted.
    r.receive(&[QUERY, 2, id::VOLTAGE, id::LEFT_ENCODER]);
    let reply = r.take_output();
    assert_eq!(reply.len(), 2);
    let mv = u16::from_be_bytes([reply[0], reply[1]]);
    assert!((14_000..17_500).contains(&mv), "{mv}");
    assert_eq!(r.counters().rejected_requests, 1);
    let mut c2 = robot(Model::Create2);
    c2.receive(&[START, QUERY, 2, 100, id::LEFT_ENCODER]);
    assert_eq!(c2.take_output().len(), 80 + 2);
}

#[test]
fn odometry_resets_when_reported() {
    let mut r = robot(Model::Create1);
    r.receive(&[START, SAFE]);
    r.receive(&drive_direct(200, 200));
    steps(&mut r, 40);
    r.receive(&[SENSORS, id::DISTANCE]);
    let first = i16::from_be_bytes(r.take_output().try_into().unwrap());
    assert!(first > 20, "{first}");
    // Reading the group that contains it also takes it; with no step in between it is 0.
    r.receive(&[SENSORS, 2]);
    let group2 = r.take_output();
    assert_eq!(&group2[2..4], &[0, 0]);
    // sensors() peeks without resetting.
    steps(&mut r, 5);
    let peek = r.sensors().get_or_zero(id::DISTANCE);
    assert!(peek > 0);
    assert_eq!(r.sensors().get_or_zero(id::DISTANCE), peek);
    r.receive(&[SENSORS, id::DISTANCE]);
    assert_eq!(
        i16::from_be_bytes(r.take_output().try_into().unwrap()),
        peek as i16
    );
}

#[test]
fn unread_distance_caps_at_i16() {
    let mut r = robot(Model::Create1);
    r.receive(&[START, FULL]);
    r.world_mut().set_lifted(true);
    r.receive(&drive_direct(500, 500));
    // 32.8 m at 0.5 m/s is ≈66 s; run 70 s.
    steps(&mut r, 4700);
    assert_eq!(r.oi_mode(), OiMode::Full, "Full ignores wheel drops");
    assert_eq!(r.sensors().get(id::DISTANCE), Some(i32::from(i16::MAX)));
    r.receive(&[SENSORS, id::DISTANCE]);
    assert_eq!(r.take_output(), vec![0x7F, 0xFF]);
}

#[test]
fn same_seed_same_bytes() {
    let script = |r: &mut SimRobot| {
        let mut out = Vec::new();
        r.receive(&[START, SAFE]);
        r.receive(&stream(&[6]));
        for k in 0..1000 {
            match k {
                10 => r.receive(&drive_direct(200, 200)),
                300 => r.receive(&drive_direct(-150, 150)),
                600 => r.receive(&drive_direct(-200, -200)),
                _ => {}
            }
            r.step();
            out.extend(r.take_output());
        }
        out
    };
    let mut a = SimRobot::new(Model::Create1, SimParams::default(), 42);
    let mut b = SimRobot::new(Model::Create1, SimParams::default(), 42);
    let mut c = SimRobot::new(Model::Create1, SimParams::default(), 43);
    let (oa, ob, oc) = (script(&mut a), script(&mut b), script(&mut c));
    assert_eq!(oa.len(), 1000 * 56);
    assert_eq!(oa, ob);
    assert_ne!(oa, oc);
}

#[test]
fn chunking_does_not_matter() {
    let mut bytes = vec![START, SAFE];
    bytes.extend(drive_direct(-100, 250));
    bytes.extend(stream(&[id::DISTANCE, id::ANGLE]));
    bytes.extend([QUERY, 2, id::VOLTAGE, id::OI_MODE]);
    let mut whole = robot(Model::Create2);
    let mut single = robot(Model::Create2);
    whole.receive(&bytes);
    for b in &bytes {
        single.receive(std::slice::from_ref(b));
    }
    steps(&mut whole, 50);
    steps(&mut single, 50);
    assert_eq!(whole.take_output(), single.take_output());
}

#[test]
fn drive_sets_requested_velocity_and_radius() {
    let mut r = robot(Model::Create2);
    // v = −200, r = 500: the spec's example bytes [C1 p9; C2 p13].
    r.receive(&[START, SAFE, 137, 255, 56, 1, 244]);
    steps(&mut r, 2);
    let v = r.sensors();
    assert_eq!(v.get(id::REQUESTED_VELOCITY), Some(-200));
    assert_eq!(v.get(id::REQUESTED_RADIUS), Some(500));
    steps(&mut r, 60);
    // Backing on a left arc turns clockwise.
    assert!(r.world().pose().heading_rad < std::f64::consts::FRAC_PI_4);
}

#[test]
fn safe_mode_trips_on_wheel_drop_and_forward_cliff_but_full_does_not() {
    let mut r = robot(Model::Create1);
    r.receive(&[START, SAFE]);
    r.receive(&drive_direct(100, 100));
    steps(&mut r, 5);
    r.world_mut().set_lifted(true);
    r.step();
    assert_eq!(r.oi_mode(), OiMode::Passive);
    assert_eq!(r.counters().safety_trips, 1);
    steps(&mut r, 20);
    assert!(r.world().wheel_speed_mm_s(LEFT).abs() < 1.0);

    let mut c = robot(Model::Create1);
    c.receive(&[START, SAFE]);
    c.world_mut().set_cliff(1, true);
    steps(&mut c, 3);
    assert_eq!(
        c.oi_mode(),
        OiMode::Safe,
        "a cliff while standing still is fine"
    );
    c.receive(&drive_direct(100, 100));
    c.step();
    assert_eq!(c.oi_mode(), OiMode::Passive);

    let mut f = robot(Model::Create1);
    f.receive(&[START, FULL]);
    f.receive(&drive_direct(100, 100));
    f.world_mut().set_cliff(0, true);
    f.world_mut().set_lifted(true);
    steps(&mut f, 5);
    assert_eq!(f.oi_mode(), OiMode::Full);
}

#[test]
fn over_budget_stream_loses_bytes() {
    let mut r = robot(Model::Create1);
    r.receive(&[START]);
    // Two copies of group 6: 3 + 2·53 = 109 bytes per 15 ms, over the 86 of 57600 baud.
    r.receive(&stream(&[6, 6]));
    steps(&mut r, 50);
    assert!(r.counters().dropped_tx_bytes > 0);
    let out = r.take_output();
    assert!(out.len() < 50 * 109);
    // A stream within budget loses nothing.
    let mut ok = robot(Model::Create1);
    ok.receive(&[START]);
    ok.receive(&stream(&[6]));
    steps(&mut ok, 50);
    assert_eq!(ok.counters().dropped_tx_bytes, 0);
}

#[test]
fn invalid_stream_requests_are_rejected_and_pause_resume_works() {
    let mut r = robot(Model::Create1);
    r.receive(&[START]);
    r.receive(&stream(&[id::OI_MODE]));
    r.receive(&stream(&[id::LEFT_ENCODER]));
    assert_eq!(r.counters().rejected_requests, 1);
    assert_eq!(r.stream_ids(), &[id::OI_MODE]);
    r.receive(&[150, 0]);
    steps(&mut r, 5);
    assert!(r.take_output().is_empty());
    r.receive(&[150, 1]);
    steps(&mut r, 5);
    assert_eq!(r.take_output().len(), 5 * 5);
    r.receive(&[STREAM, 0]);
    steps(&mut r, 5);
    assert!(r.take_output().is_empty());
}

/// Steps from a spin-left command (Drive Direct right +v, left −v, sent at rest) to the first stream
/// frame whose battery current differs from the idle level by more than 30 mA, and to the first frame
/// with a non-zero angle or distance.
fn spin_latencies(model: Model, seed: u64, speed: i16) -> (f64, f64) {
    spin_latencies_with(model, SimParams::for_model(model), seed, speed)
}

fn spin_latencies_with(model: Model, params: SimParams, seed: u64, speed: i16) -> (f64, f64) {
    let ids = [id::DISTANCE, id::ANGLE, id::CURRENT];
    let mut r = SimRobot::new(model, params, seed);
    r.receive(&[START, SAFE]);
    r.receive(&stream(&ids));
    let idle = run_frames(&mut r, 40, &ids);
    let baseline = idle.iter().map(|v| v.get_or_zero(id::CURRENT)).sum::<i32>() / 40;
    r.receive(&drive_direct(speed, -speed));
    let fs = run_frames(&mut r, 60, &ids);
    let when = |pred: &dyn Fn(&SensorValues) -> bool| {
        fs.iter()
            .position(pred)
            .map_or(f64::INFINITY, |k| (k + 1) as f64 * 0.015)
    };
    let current = when(&|v| (v.get_or_zero(id::CURRENT) - baseline).abs() > 30);
    let odometry = when(&|v| v.get_or_zero(id::ANGLE) != 0 || v.get_or_zero(id::DISTANCE) != 0);
    (current, odometry)
}

#[test]
fn spin_command_latencies_match_the_paper() {
    // Paper: ≈0.1 s until the battery current changes, ≈0.3 s until odometry reports motion.
    for model in [Model::Create1, Model::Create2] {
        let mut sums = (0.0, 0.0);
        for seed in 0..8 {
            let (current, odometry) = spin_latencies(model, seed, 200);
            assert!(
                (0.04..=0.2).contains(&current),
                "{model} seed {seed}: current {current}"
            );
            assert!(
                (0.2..=0.45).contains(&odometry),
                "{model} seed {seed}: odometry {odometry}"
            );
            sums.0 += current / 8.0;
            sums.1 += odometry / 8.0;
        }
        assert!(
            sums.1 - sums.0 > 0.1,
            "{model}: current must lead motion, {sums:?}"
        );
    }
}

#[test]
fn driving_into_the_wall_stalls_with_persistent_overcurrents_and_backing_off_clears_them() {
    let ids = [id::BUMPS_WHEEL_DROPS, id::OVERCURRENTS, id::CURRENT];
    let wheels = bits::OC_LEFT_WHEEL | bits::OC_RIGHT_WHEEL;
    let mut r = robot(Model::Create1);
    r.receive(&[START, SAFE]);
    r.receive(&stream(&ids));
    r.receive(&drive_direct(200, 200));
    let fs = run_frames(&mut r, 200, &ids);
    let last_second = &fs[fs.len() - 67..];
    let bumped = bits::BUMP_LEFT | bits::BUMP_RIGHT;
    assert!(
        last_second
            .iter()
            .all(|v| v.get_or_zero(id::BUMPS_WHEEL_DROPS) == bumped)
    );
    let both = last_second
        .iter()
        .filter(|v| v.get_or_zero(id::OVERCURRENTS) & wheels == wheels)
        .count();
    assert!(both >= 60, "persistent over-current: {both}/67");
    assert!(r.world().stalled(LEFT) && r.world().stalled(RIGHT));
    // The wheels demand more than the 1.0 A limit; the driver holds them at it [C1 p10, p17].
    for side in [LEFT, RIGHT] {
        assert!(r.world().wheel_current_demand_a(side) > 1.4);
        assert!((r.world().wheel_current_a(side) - 1.0).abs() < 0.01);
    }
    // So the battery supplies two limited wheels plus the electronics: about 1.5 A, not 3.5 A.
    let battery: Vec<i32> = last_second
        .iter()
        .map(|v| v.get_or_zero(id::CURRENT))
        .collect();
    assert!(
        battery.iter().all(|&ma| (-1700..-1300).contains(&ma)),
        "{battery:?}"
    );
    assert_eq!(r.oi_mode(), OiMode::Safe, "a bump is no safety trip");

    r.receive(&drive_direct(-200, -200));
    let fs = run_frames(&mut r, 100, &ids);
    let settled = &fs[40..];
    assert!(
        settled
            .iter()
            .all(|v| v.get_or_zero(id::BUMPS_WHEEL_DROPS) == 0)
    );
    let flagged = settled
        .iter()
        .filter(|v| v.get_or_zero(id::OVERCURRENTS) != 0)
        .count();
    assert!(
        flagged <= 1,
        "{flagged} over-current frames after backing off"
    );
    assert!(!r.world().stalled(LEFT) && !r.world().stalled(RIGHT));
}

#[test]
fn isolated_overcurrents_are_rare_in_free_driving() {
    // Spin left and right from rest, over and over, in the open middle of the enclosure: every start
    // overcomes static friction. 5 simulated minutes.
    let ids = [id::OVERCURRENTS];
    let mut r = robot(Model::Create1);
    r.receive(&[START, SAFE]);
    r.receive(&stream(&ids));
    let mut flags = Vec::new();
    for cycle in 0..100 {
        let speed = if cycle % 2 == 0 { 250 } else { -250 };
        r.receive(&drive_direct(speed, -speed));
        flags.extend(run_frames(&mut r, 133, &ids));
        r.receive(&drive_direct(0, 0));
        flags.extend(run_frames(&mut r, 67, &ids));
    }
    assert!(!r.world().touching_wall());
    let set: Vec<bool> = flags
        .iter()
        .map(|v| v.get_or_zero(id::OVERCURRENTS) != 0)
        .collect();
    let count = set.iter().filter(|&&s| s).count();
    let rate = count as f64 / set.len() as f64;
    // "Isolated observations … occurred regularly in normal operation" (paper): between about one per
    // half minute and one per second and a half of driving (the defaults give ≈7 a minute).
    assert!(
        (5e-4..=1e-2).contains(&rate),
        "rate {rate} ({count} of {})",
        set.len()
    );
    let longest = set.split(|&s| !s).map(<[bool]>::len).max().unwrap_or(0);
    assert!(
        longest <= 3,
        "a run of {longest} over-current frames is not isolated"
    );
}

#[test]
fn battery_charge_and_energy_fall_while_driving() {
    let mut r = robot(Model::Create2);
    r.receive(&[START, SAFE]);
    let before = r.sensors();
    r.receive(&drive_direct(200, 200));
    steps(&mut r, 2000);
    let after = r.sensors();
    assert!(after.get_or_zero(id::BATTERY_CHARGE) < before.get_or_zero(id::BATTERY_CHARGE));
    // 30 s, most of it pushing the wall with both wheels held at their 1.0 A limit.
    assert!(r.world().battery().energy_j() > 30.0 * 1.2 * 14.0);
    assert!(after.get_or_zero(id::VOLTAGE) < before.get_or_zero(id::VOLTAGE));
}

#[test]
fn songs_play_for_their_length_in_safe_mode_only() {
    let mut r = robot(Model::Create1);
    // Song 3: two notes of 32/64 s = 1 s in all.
    r.receive(&[START, 140, 3, 2, 60, 32, 64, 32]);
    r.receive(&[141, 3]);
    assert_eq!(r.counters().ignored_in_passive, 1);
    assert_eq!(r.sensors().get(id::SONG_PLAYING), Some(0));
    r.receive(&[SAFE, 141, 3]);
    steps(&mut r, 60);
    assert_eq!(r.sensors().get(id::SONG_PLAYING), Some(1));
    assert_eq!(r.sensors().get(id::SONG_NUMBER), Some(3));
    steps(&mut r, 10);
    assert_eq!(r.sensors().get(id::SONG_PLAYING), Some(0));
    // An undefined song is refused.
    r.receive(&[141, 9]);
    assert_eq!(r.counters().rejected_requests, 1);
}

#[test]
fn a_slower_baud_shrinks_the_stream_budget() {
    let mut r = robot(Model::Create1);
    r.receive(&[START, 129, 7]); // 19200 baud: 28 bytes per 15 ms
    r.receive(&stream(&[6]));
    steps(&mut r, 20);
    assert!(r.counters().dropped_tx_bytes > 0);
    r.receive(&[129, 12]);
    assert_eq!(
        r.counters().rejected_requests,
        1,
        "baud code 12 does not exist"
    );
}
