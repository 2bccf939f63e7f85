//! Tests of [`FaultInjector`]'s link faults on a streaming simulated Create 2, read back through the
//! host's [`StreamParser`]; the helpers here serve `tests_robot` too.

use super::*;
use crate::oi::Model;
use crate::oi::SensorValues;
use crate::oi::parser::StreamParser;
use crate::sim::params::SimParams;

pub(super) const START: u8 = 128;
pub(super) const SAFE: u8 = 131;
pub(super) const FULL: u8 = 132;
pub(super) const DRIVE: u8 = 137;
pub(super) const STREAM: u8 = 148;
/// The Create 2's all-sensors group: an 84-byte frame.
pub(super) const GROUP: u8 = 100;
pub(super) const FRAME_LEN: usize = 84;

/// Drive at `velocity` mm/s on `radius` mm (1: turn in place counter-clockwise).
pub(super) fn drive(velocity: i16, radius: i16) -> Vec<u8> {
    let mut v = vec![DRIVE];
    v.extend_from_slice(&velocity.to_be_bytes());
    v.extend_from_slice(&radius.to_be_bytes());
    v
}

/// A Create 2 in `mode` (SAFE or FULL), turning in place (so every frame differs), streaming group
/// 100, with `spec` configured.
pub(super) fn robot_with(mode: u8, spec: &FaultSpec, seed: u64) -> (SimRobot, FaultInjector) {
    let mut robot = SimRobot::new(Model::Create2, SimParams::for_model(Model::Create2), seed);
    let injector = FaultInjector::new(spec.clone(), seed);
    injector.configure(&mut robot);
    robot.receive(&[START, mode]);
    robot.receive(&drive(100, 1));
    robot.receive(&[STREAM, 1, GROUP]);
    (robot, injector)
}

pub(super) fn spec(text: &str) -> FaultSpec {
    text.parse().unwrap()
}

/// One step: the robot's own bytes and what the injector made of them.
pub(super) fn step(robot: &mut SimRobot, injector: &mut FaultInjector) -> (Vec<u8>, StepOutcome) {
    robot.step();
    let out = robot.take_output();
    let outcome = injector.after_step(robot, out.clone());
    (out, outcome)
}

pub(super) fn run(
    robot: &mut SimRobot,
    injector: &mut FaultInjector,
    steps: usize,
) -> Vec<(Vec<u8>, StepOutcome)> {
    (0..steps).map(|_| step(robot, injector)).collect()
}

pub(super) fn frames_of(bytes: &[u8]) -> Vec<SensorValues> {
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

#[test]
fn a_steady_delay_shifts_every_step_by_whole_steps() {
    let (mut r, mut f) = robot_with(FULL, &spec("delay_ms=40"), 16);
    let results = run(&mut r, &mut f, 50);
    for (i, (_, outcome)) in results.iter().enumerate() {
        match i.checked_sub(3) {
            None => assert!(outcome.bytes.is_empty(), "step {i}"),
            Some(j) => assert_eq!(outcome.bytes, results[j].0, "step {i}"),
        }
    }
}

#[test]
fn an_end_of_file_loses_what_was_in_flight_or_held() {
    let (mut r, mut f) = robot_with(FULL, &spec("delay_ms=30,burst=1,burst_steps=4"), 17);
    run(&mut r, &mut f, 7);
    let lost_before = f.counters().lost_bytes;
    let in_flight = f.in_flight.iter().map(Vec::len).sum::<usize>() + f.held.len();
    assert!(in_flight >= 2 * FRAME_LEN);
    f.spec.eof = 1.0;
    let (_, outcome) = step(&mut r, &mut f);
    assert_eq!(outcome.link, LinkFault::Eof);
    assert!(outcome.bytes.is_empty());
    assert_eq!(
        f.counters().lost_bytes - lost_before,
        (in_flight + FRAME_LEN) as u64
    );
    assert!(f.in_flight.is_empty() && f.held.is_empty());
}
