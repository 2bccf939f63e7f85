//! Physics tests of [`World`]: driving, turning, walls, stalls, bumpers, battery.

use super::*;
use crate::oi::Model;

fn world(model: Model) -> World {
    World::new(SimParams::for_model(model), Rng::new(1))
}

fn run(w: &mut World, seconds: f64) {
    let n = (seconds / STEP_SECONDS).round() as usize;
    for _ in 0..n {
        w.step();
    }
}

fn forward(v: f64) -> DriveTarget {
    DriveTarget::Speed {
        left_mm_s: v,
        right_mm_s: v,
    }
}

/// Distance from the body's edge to the nearest wall, m (negative: overlapping).
fn clearance(w: &World) -> f64 {
    let p = w.pose();
    let c = Vec2::new(p.x_m, p.y_m);
    w.enclosure()
        .walls()
        .iter()
        .map(|s| (c - s.closest_point(c)).length())
        .fold(f64::INFINITY, f64::min)
        - w.params().body_radius_m
}

#[test]
fn nothing_moves_before_the_command_latency() {
    let mut w = world(Model::Create1);
    w.command(forward(300.0));
    // The 60 ms latency ends in the fourth step.
    run(&mut w, 0.045);
    assert_eq!(w.wheel_duty(LEFT), 0.0);
    assert_eq!(w.battery().current_a(), w.params().idle_current_a);
    w.step();
    assert!(w.wheel_duty(LEFT) > 0.0);
}

#[test]
fn forward_into_the_wall_from_the_start_stalls_both_wheels_and_backing_off_frees_them() {
    let mut w = world(Model::Create1);
    assert_eq!(w.bumps(), [false, false]);
    w.command(forward(200.0));
    run(&mut w, 3.0);
    assert_eq!(
        w.bumps(),
        [true, true],
        "head-on contact presses both halves"
    );
    assert!(w.blocked());
    assert!(w.stalled(LEFT) && w.stalled(RIGHT));
    assert_eq!(w.wheel_speed_mm_s(LEFT), 0.0);
    for side in [LEFT, RIGHT] {
        let demand = w.wheel_current_demand_a(side);
        assert!(demand > 1.0 && demand < 2.0, "stall demand {demand}");
        let i = w.wheel_current_a(side);
        assert!((i - 1.0).abs() < 1e-6, "held at the 1.0 A limit: {i}");
    }
    let battery = w.battery().current_a();
    assert!(battery > 1.2 && battery < 1.8, "battery {battery}");
    assert!(clearance(&w).abs() < 0.002, "clearance {}", clearance(&w));
    // Free path to the hypotenuse was 23.6 − 16.5 = 7.1 cm.
    assert!((w.odometer_m() - 0.071).abs() < 0.003, "{}", w.odometer_m());

    w.command(forward(-200.0));
    run(&mut w, 0.6);
    assert_eq!(w.bumps(), [false, false]);
    assert!(!w.stalled(LEFT) && !w.stalled(RIGHT));
    assert!(w.wheel_speed_mm_s(LEFT) < -50.0);
    assert!(w.wheel_current_a(LEFT).abs() < 0.6);
}

#[test]
fn turning_in_place_at_a_wall_stays_free() {
    let mut w = world(Model::Create2);
    w.command(forward(150.0));
    run(&mut w, 2.0);
    assert!(w.stalled(LEFT));
    let before = w.pose();
    w.command(DriveTarget::Speed {
        left_mm_s: 150.0,
        right_mm_s: -150.0,
    });
    run(&mut w, 1.0);
    let after = w.pose();
    assert!(!w.stalled(LEFT) && !w.stalled(RIGHT));
    assert!(
        after.heading_rad < before.heading_rad - 0.5,
        "turned clockwise"
    );
    let moved = ((after.x_m - before.x_m).powi(2) + (after.y_m - before.y_m).powi(2)).sqrt();
    assert!(moved < 0.002, "moved {moved}");
}

#[test]
fn spin_in_place_turns_by_the_wheel_travel_over_the_base() {
    let mut w = world(Model::Create1);
    let start = w.pose();
    w.command(DriveTarget::Speed {
        left_mm_s: -100.0,
        right_mm_s: 100.0,
    });
    run(&mut w, 1.5);
    let [l, r] = w.total_travel_mm();
    let expected = (r - l) / 258.0;
    let turned = wrap_angle(w.pose().heading_rad - start.heading_rad);
    assert!(turned > 0.5, "counter-clockwise: {turned}");
    assert!((turned - expected).abs() < 1e-6);
    // The wheels differ a little (floor irregularities), so the centre drifts a few millimetres.
    assert!((w.pose().x_m - start.x_m).abs() < 0.005);
}

#[test]
fn backing_into_a_wall_stalls_without_a_bump() {
    let mut w = world(Model::Create1);
    w.command(forward(-200.0));
    run(&mut w, 4.0);
    assert!(w.stalled(LEFT) && w.stalled(RIGHT));
    assert_eq!(w.bumps(), [false, false], "the Create has no rear bumper");
    assert!(clearance(&w).abs() < 0.002);
}

#[test]
fn the_contact_bearing_picks_the_bumper_half() {
    let mut w = world(Model::Create1);
    let r = w.params().body_radius_m;
    // Against the x-axis wall (below the robot); the wall's bearing is −π/2 − heading.
    let at = |heading: f64| Pose {
        x_m: 0.5,
        y_m: r,
        heading_rad: heading,
    };
    let cases = [
        (-std::f64::consts::FRAC_PI_4, [false, true]),
        (-3.0 * std::f64::consts::FRAC_PI_4, [true, false]),
        (-std::f64::consts::FRAC_PI_2, [true, true]),
        (std::f64::consts::FRAC_PI_2, [false, false]),
    ];
    for (heading, bumps) in cases {
        w.set_pose(at(heading));
        assert_eq!(w.bumps(), bumps, "heading {heading}");
    }
}

#[test]
fn lifted_robot_spins_its_wheels_but_does_not_move() {
    let mut w = world(Model::Create1);
    w.set_lifted(true);
    w.command(forward(300.0));
    run(&mut w, 1.0);
    assert!(w.wheel_speed_mm_s(LEFT) > 200.0);
    assert_eq!(w.odometer_m(), 0.0);
    assert_eq!(w.wheel_drops(), [true, true]);
    assert!(!w.touching_wall());
}

#[test]
fn battery_drains_faster_when_stalled_than_idle() {
    let mut idle = world(Model::Create2);
    let mut stalled = world(Model::Create2);
    stalled.command(forward(300.0));
    run(&mut idle, 10.0);
    run(&mut stalled, 10.0);
    let used = |w: &World| {
        w.params().capacity_mah * w.params().initial_charge_fraction - w.battery().charge_mah()
    };
    assert!(used(&idle) > 0.0);
    assert!(used(&stalled) > 10.0 * used(&idle));
    assert!(stalled.battery().energy_j() > 10.0 * idle.battery().energy_j());
}

#[test]
fn pwm_drives_open_loop() {
    let mut w = world(Model::Create2);
    w.command(DriveTarget::Duty {
        left: -0.5,
        right: 0.5,
    });
    run(&mut w, 1.0);
    assert!((w.wheel_duty(RIGHT) - 0.5).abs() < 1e-12);
    assert!(w.wheel_speed_mm_s(RIGHT) > 100.0 && w.wheel_speed_mm_s(LEFT) < -100.0);
}

#[test]
fn angles_wrap_into_one_turn() {
    assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
    assert!((wrap_angle(7.0) - (7.0 - std::f64::consts::TAU)).abs() < 1e-12);
}

/// `wrap_angle` skips `fmod` for angles within a turn: its results are those of `rem_euclid`, bit for bit.
#[test]
fn angle_wrapping_matches_rem_euclid_bit_for_bit() {
    fn by_rem_euclid(a: f64) -> f64 {
        let tau = std::f64::consts::TAU;
        let w = a.rem_euclid(tau);
        if w > std::f64::consts::PI { w - tau } else { w }
    }
    let tau = std::f64::consts::TAU;
    let pi = std::f64::consts::PI;
    let mut rng = crate::rng::Rng::new(5);
    let mut angles: Vec<f64> = (0..100_000).map(|_| rng.uniform(-20.0, 20.0)).collect();
    for edge in [0.0, pi, tau, 2.0 * tau, 1e-300] {
        angles.extend(crate::sim::test_floats::around(edge));
    }
    angles.extend([
        -0.0,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e300,
    ]);
    for a in angles {
        assert_eq!(wrap_angle(a).to_bits(), by_rem_euclid(a).to_bits(), "{a:e}");
    }
}

/// When `moves_below_resolution` says so, moving the centre leaves it bit for bit where it was, and it
/// does say so for the tiny advances of turning on the spot at a wall.
#[test]
fn a_move_below_resolution_changes_no_bit() {
    let mut rng = Rng::new(3);
    let mut below = 0;
    for i in 0..200_000 {
        let centre = Vec2::new(rng.uniform(0.1, 1.0), rng.uniform(0.1, 1.0));
        let angle = rng.uniform(-4.0, 4.0);
        // Around the threshold, half a gap of the smaller coordinate, and far below it.
        let gap = centre.x.abs().min(centre.y.abs()) / (1u64 << 54) as f64;
        let advance = match i % 3 {
            0 => gap * rng.uniform(0.0, 2.0),
            1 => gap * rng.uniform(0.0, 1e-3),
            _ => 0.0,
        } * if rng.chance(0.5) { 1.0 } else { -1.0 };
        if moves_below_resolution(centre, angle, advance) {
            below += 1;
            let moved = centre + Vec2::from_angle(angle) * advance;
            assert_eq!(
                (moved.x.to_bits(), moved.y.to_bits()),
                (centre.x.to_bits(), centre.y.to_bits()),
                "{centre:?} {angle} {advance:e}"
            );
        }
    }
    assert!(below > 100_000, "{below}");
    let at = Vec2::new(0.5, 0.5);
    assert!(!moves_below_resolution(at, f64::NAN, 0.0));
    assert!(!moves_below_resolution(at, 0.3, f64::NAN));
    assert!(!moves_below_resolution(Vec2::new(0.0, 0.5), 0.3, 0.0));
    assert!(!moves_below_resolution(at, 0.3, 1e-9));
}
