//! Behavioural tests of the simulated operator over whole simulated sessions.

use super::*;
use crate::skeleton::elbow_angle_deg;

const FIVE_MINUTES_MS: f64 = 5.0 * 60.0 * 1000.0;

/// One recorded session: every frame and the true left/right angles at each.
struct Session {
    sim: SimHuman,
    frames: Vec<HumanFrame>,
    true_left: Vec<f64>,
    true_right: Vec<f64>,
}

fn run(params: HumanParams, seed: u64, duration_ms: f64) -> Session {
    let mut sim = SimHuman::new(params, seed);
    let (mut frames, mut true_left, mut true_right) = (Vec::new(), Vec::new(), Vec::new());
    loop {
        let f = sim.step();
        if f.t_ms > duration_ms {
            break;
        }
        true_left.push(sim.true_elbow_deg(Side::Left));
        true_right.push(sim.true_elbow_deg(Side::Right));
        frames.push(f);
    }
    Session {
        sim,
        frames,
        true_left,
        true_right,
    }
}

fn position(frame: &HumanFrame, j: Joint) -> Option<[f64; 3]> {
    frame.joints.iter().find(|(k, _)| *k == j).map(|(_, p)| *p)
}

/// The left angle a receiver would compute from a frame (hand, falling back to wrist), if it can.
fn measured_left(frame: &HumanFrame) -> Option<f64> {
    let s = position(frame, Joint::LeftShoulder)?;
    let e = position(frame, Joint::LeftElbow)?;
    let h = position(frame, Joint::LeftHand).or_else(|| position(frame, Joint::LeftWrist))?;
    elbow_angle_deg(s, e, h)
}

#[test]
fn same_seed_same_frames_different_seed_different_frames() {
    let a = run(HumanParams::default(), 42, 60_000.0);
    let b = run(HumanParams::default(), 42, 60_000.0);
    let c = run(HumanParams::default(), 43, 60_000.0);
    assert_eq!(a.frames, b.frames);
    assert_eq!(a.sim.commands(), b.sim.commands());
    assert_ne!(a.frames, c.frames);
}

#[test]
fn frames_are_thirty_per_second_from_time_zero() {
    let mut sim = SimHuman::new(HumanParams::default(), 1);
    assert!((sim.frame_period_ms() - 1000.0 / 30.0).abs() < 1e-9);
    let first = sim.step();
    assert_eq!(first.t_ms, 0.0);
    assert_eq!(first.user_id, 1);
    let second = sim.step();
    assert!((second.t_ms - sim.frame_period_ms()).abs() < 1e-9);
}

#[test]
fn command_count_over_five_minutes_is_in_the_expected_band() {
    let p = HumanParams::default();
    // Expected gestures: one per (mean pause + mean gesture length); a fraction are partial bends.
    let mean = |r: [f64; 2]| 0.5 * (r[0] + r[1]);
    let cycle_s =
        p.gap_min_s + p.gap_extra_mean_s + mean(p.bend_s) + mean(p.hold_s) + mean(p.return_s);
    let expected = (FIVE_MINUTES_MS / 1000.0 - mean(p.first_gesture_after_s)) / cycle_s
        * (1.0 - p.partial_fraction);
    for seed in [1, 2, 3, 4] {
        let s = run(p.clone(), seed, FIVE_MINUTES_MS);
        let n = s.sim.commands().len() as f64;
        assert!(
            n > 0.6 * expected && n < 1.4 * expected,
            "seed {seed}: {n} commands, expected ~{expected:.1}"
        );
        let left: Vec<_> = s
            .sim
            .gestures()
            .iter()
            .filter(|g| g.side == Side::Left)
            .collect();
        let partial = left.iter().filter(|g| !g.is_command).count() as f64 / left.len() as f64;
        assert!(
            partial > 0.03 && partial < 0.45,
            "seed {seed}: partial fraction {partial}"
        );
    }
}

#[test]
fn every_command_crosses_ninety_and_partial_bends_do_not() {
    let s = run(HumanParams::default(), 7, FIVE_MINUTES_MS);
    let times: Vec<f64> = s.frames.iter().map(|f| f.t_ms).collect();
    let commands = s.sim.commands();
    assert!(!commands.is_empty());
    for c in commands {
        let inside: Vec<f64> = times
            .iter()
            .zip(&s.true_left)
            .filter(|(t, _)| **t > c.onset_ms && **t < c.end_ms)
            .map(|(_, a)| *a)
            .collect();
        if c.end_ms < *times.last().unwrap() {
            assert!(
                inside.len() >= 3,
                "command at {} spans {} frames",
                c.onset_ms,
                inside.len()
            );
        }
        assert!(
            inside.iter().all(|a| *a < 90.0),
            "command at {}",
            c.onset_ms
        );
    }
    // Outside every command window the true left angle is at or above 90°.
    for (t, a) in times.iter().zip(&s.true_left) {
        if *a < 90.0 {
            assert!(
                commands.iter().any(|c| *t >= c.onset_ms && *t <= c.end_ms),
                "stray bend at {t}"
            );
        }
    }
    let partials: Vec<_> = s
        .sim
        .gestures()
        .iter()
        .filter(|g| g.side == Side::Left && !g.is_command)
        .collect();
    assert!(!partials.is_empty());
    for g in partials {
        assert!(g.min_deg > 90.0);
        let lowest = times
            .iter()
            .zip(&s.true_left)
            .filter(|(t, _)| **t >= g.start_ms && **t <= g.end_ms)
            .map(|(_, a)| *a)
            .fold(f64::INFINITY, f64::min);
        assert!(
            lowest > 90.0 && lowest < g.from_deg - 10.0,
            "partial bend reached {lowest}"
        );
    }
}

#[test]
fn the_angle_falls_steadily_in_the_300_ms_before_each_onset() {
    let s = run(HumanParams::default(), 11, FIVE_MINUTES_MS);
    let (mut down_pairs, mut pairs) = (0usize, 0usize);
    for c in s.sim.commands() {
        let window: Vec<usize> = (0..s.frames.len())
            .filter(|&k| s.frames[k].t_ms >= c.onset_ms - 300.0 && s.frames[k].t_ms < c.onset_ms)
            .collect();
        assert!(window.len() >= 8, "{} frames", window.len());
        let truth: Vec<f64> = window.iter().map(|&k| s.true_left[k]).collect();
        assert!(
            truth.windows(2).all(|w| w[1] < w[0]),
            "true angle not falling: {truth:?}"
        );
        assert!(
            truth[0] > 100.0,
            "already near 90° 300 ms early: {}",
            truth[0]
        );
        // What a receiver sees: noisy, sometimes missing, but still mostly falling.
        let seen: Vec<f64> = window
            .iter()
            .filter_map(|&k| measured_left(&s.frames[k]))
            .collect();
        for w in seen.windows(2) {
            pairs += 1;
            down_pairs += usize::from(w[1] < w[0]);
        }
    }
    let share = down_pairs as f64 / pairs as f64;
    assert!(
        share > 0.75,
        "only {share:.2} of measured steps fall before onsets"
    );
}

#[test]
fn measured_angle_tracks_the_true_angle_within_sensor_noise() {
    let s = run(HumanParams::default(), 5, 120_000.0);
    let errors: Vec<f64> = s
        .frames
        .iter()
        .zip(&s.true_left)
        .filter_map(|(f, t)| measured_left(f).map(|m| m - t))
        .collect();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    assert!(rms > 0.5 && rms < 8.0, "rms angle error {rms}");
}

#[test]
fn dropped_joint_rates_are_in_the_configured_band() {
    let p = HumanParams::default();
    let s = run(p.clone(), 3, FIVE_MINUTES_MS);
    let n = s.frames.len() as f64;
    let missing =
        |j: Joint| s.frames.iter().filter(|f| position(f, j).is_none()).count() as f64 / n;
    for j in [
        Joint::LeftElbow,
        Joint::LeftHand,
        Joint::RightElbow,
        Joint::RightHand,
    ] {
        let r = missing(j);
        assert!(
            r > 0.5 * p.arm_drop_rate && r < 1.5 * p.arm_drop_rate,
            "{j:?} missing {r}"
        );
    }
    assert!(missing(Joint::Head) < 3.0 * p.body_drop_rate);
    let either = s
        .frames
        .iter()
        .filter(|f| {
            position(f, Joint::LeftElbow).is_none() || position(f, Joint::LeftHand).is_none()
        })
        .count() as f64
        / n;
    assert!(
        (0.05..=0.15).contains(&either),
        "left elbow or hand missing in {either}"
    );
    // Dropouts come in bursts: runs average more than one frame.
    let flags: Vec<bool> = s
        .frames
        .iter()
        .map(|f| position(f, Joint::LeftElbow).is_none())
        .collect();
    let runs = flags.windows(2).filter(|w| w[1] && !w[0]).count() as f64;
    let mean_run = flags.iter().filter(|d| **d).count() as f64 / runs;
    assert!(mean_run > 1.8, "mean dropout run {mean_run}");
}

#[test]
fn right_arm_moves_without_making_commands() {
    let s = run(HumanParams::default(), 9, FIVE_MINUTES_MS);
    let right = s
        .sim
        .gestures()
        .iter()
        .filter(|g| g.side == Side::Right)
        .count();
    assert!(right >= 5, "{right} right-arm movements");
    assert!(
        s.sim
            .gestures()
            .iter()
            .filter(|g| g.side == Side::Right)
            .all(|g| !g.is_command)
    );
    let right_alone = s
        .true_right
        .iter()
        .zip(&s.true_left)
        .filter(|(r, l)| **r < 90.0 && **l >= 90.0)
        .count();
    assert!(right_alone > 0, "no right bend past 90° on its own");
}

#[test]
fn all_reported_positions_are_a_person_about_two_and_a_half_metres_away() {
    let s = run(HumanParams::default(), 2, 30_000.0);
    for f in &s.frames {
        for (j, p) in &f.joints {
            assert!(p.iter().all(|c| c.is_finite()), "{j:?}");
            assert!(p[2] > 2000.0 && p[2] < 3000.0, "{j:?} at z {}", p[2]);
            assert!(
                p[0].abs() < 900.0 && p[1] > -1200.0 && p[1] < 1100.0,
                "{j:?} at {p:?}"
            );
        }
    }
}

#[test]
fn nite_fifteen_when_wrists_are_off() {
    let p = HumanParams {
        include_wrists: false,
        arm_drop_rate: 0.0,
        body_drop_rate: 0.0,
        ..HumanParams::default()
    };
    let mut sim = SimHuman::new(p, 1);
    let f = sim.step();
    assert_eq!(f.joints.len(), 15);
    assert!(position(&f, Joint::LeftWrist).is_none());
}
