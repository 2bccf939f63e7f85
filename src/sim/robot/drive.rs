//! From Drive (137), Drive Direct (145) and Drive PWM (146) arguments to what the wheels are asked to
//! do: the Drive arc geometry, the ±500 mm/s limit and, on the Create 2, the speed controller's dead
//! band and ≈28.5 mm/s steps.

use crate::oi::command::Radius;
use crate::sim::params::SimParams;
use crate::sim::world::DriveTarget;

/// Largest radius Drive accepts, mm [C1 p9; C2 p13]; larger values are limited to it.
const MAX_RADIUS_MM: f64 = 2000.0;

/// Wheel speeds `(left, right)` in mm/s for Drive with `velocity` (mm/s, the average of the wheels) and
/// `radius` [C1 p9; C2 p13]. Positive radii turn left. The specs leave radius 0 undefined; it is
/// taken as straight. An arc that would need a wheel faster than the limit is slowed down as a whole,
/// keeping its radius (the real firmware's saturation is not documented).
pub fn drive_wheel_speeds(velocity: i16, radius: Radius, p: &SimParams) -> (f64, f64) {
    let max = p.max_wheel_speed_mm_s;
    let v = f64::from(velocity).clamp(-max, max);
    let (left, right) = match radius {
        Radius::Straight | Radius::Mm(0) => (v, v),
        Radius::TurnInPlaceClockwise => (v, -v),
        Radius::TurnInPlaceCounterClockwise => (-v, v),
        Radius::Mm(r) => {
            let r = f64::from(r).clamp(-MAX_RADIUS_MM, MAX_RADIUS_MM);
            let half_base = p.wheel_base_m * 1000.0 / 2.0;
            (v * (r - half_base) / r, v * (r + half_base) / r)
        }
    };
    let fastest = left.abs().max(right.abs());
    if fastest > max {
        (left * max / fastest, right * max / fastest)
    } else {
        (left, right)
    }
}

/// The speed the wheel controller actually runs for a requested wheel speed: limited to ±max, zero in
/// the dead band, and rounded up to the controller's next step where it has steps (Create 2 [KT]:
/// anything in `[11, 39.5)` mm/s runs at 39.5).
pub fn controller_speed(requested_mm_s: f64, p: &SimParams) -> f64 {
    let max = p.max_wheel_speed_mm_s;
    let v = requested_mm_s.clamp(-max, max);
    let magnitude = v.abs();
    if magnitude <= p.speed_dead_band_mm_s {
        return 0.0;
    }
    let stepped = match p.speed_quantum_mm_s {
        Some(q) if q > 0.0 => {
            let first = p.speed_dead_band_mm_s + 1.0;
            let k = ((magnitude - first) / q).floor();
            (first + q * (k + 1.0)).min(max)
        }
        _ => magnitude,
    };
    stepped.copysign(v)
}

/// Closed-loop target for wheel speeds `(left, right)` in mm/s.
pub fn speed_target(left: f64, right: f64, p: &SimParams) -> DriveTarget {
    DriveTarget::Speed {
        left_mm_s: controller_speed(left, p),
        right_mm_s: controller_speed(right, p),
    }
}

/// Open-loop target for Drive PWM values (−255..=255 per wheel [C2 p14]).
pub fn pwm_target(left: i16, right: i16) -> DriveTarget {
    let duty = |v: i16| (f64::from(v) / 255.0).clamp(-1.0, 1.0);
    DriveTarget::Duty {
        left: duty(left),
        right: duty(right),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;

    #[test]
    fn drive_geometry() {
        let p = SimParams::for_model(Model::Create1);
        assert_eq!(
            drive_wheel_speeds(200, Radius::Straight, &p),
            (200.0, 200.0)
        );
        assert_eq!(
            drive_wheel_speeds(200, Radius::TurnInPlaceCounterClockwise, &p),
            (-200.0, 200.0)
        );
        assert_eq!(
            drive_wheel_speeds(200, Radius::TurnInPlaceClockwise, &p),
            (200.0, -200.0)
        );
        // r = 500 mm to the left: the right (outer) wheel is faster, the average is v.
        let (l, r) = drive_wheel_speeds(200, Radius::Mm(500), &p);
        assert!(r > l && ((l + r) / 2.0 - 200.0).abs() < 1e-9);
        assert!(((r - l) / 258.0 - 200.0 / 500.0).abs() < 1e-9);
        // A tight fast arc is slowed down keeping its radius.
        let (l, r) = drive_wheel_speeds(500, Radius::Mm(200), &p);
        assert!((r - 500.0).abs() < 1e-9 && l > 0.0 && l < r);
        assert_eq!(
            drive_wheel_speeds(-900, Radius::Straight, &p),
            (-500.0, -500.0)
        );
    }

    #[test]
    fn create2_speeds_are_stepped_with_a_dead_band() {
        let p = SimParams::for_model(Model::Create2);
        assert_eq!(controller_speed(10.0, &p), 0.0);
        assert_eq!(controller_speed(-10.0, &p), 0.0);
        assert_eq!(controller_speed(11.0, &p), 39.5);
        assert_eq!(controller_speed(39.0, &p), 39.5);
        assert_eq!(controller_speed(40.0, &p), 68.0);
        assert_eq!(controller_speed(-100.0, &p), -125.0);
        assert_eq!(controller_speed(499.0, &p), 500.0);
        assert_eq!(controller_speed(700.0, &p), 500.0);
        let c1 = SimParams::for_model(Model::Create1);
        assert_eq!(controller_speed(37.0, &c1), 37.0);
    }

    #[test]
    fn pwm_is_a_duty() {
        assert_eq!(
            pwm_target(255, -128),
            DriveTarget::Duty {
                left: 1.0,
                right: -128.0 / 255.0
            }
        );
    }
}
