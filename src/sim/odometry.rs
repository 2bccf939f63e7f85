//! The firmware's odometry: the distance (mm) and angle (degrees) accumulated since they were last
//! reported, and the Create 2's wheel encoder counters.
//!
//! - Distance = (left + right) / 2, angle = (right − left) / wheel base, counter-clockwise positive
//!   [C1 p18–19; C2 p27].
//! - Both are reported as whole units, truncated toward zero and capped at the i16 range; a report
//!   (stream frame, Sensors, Query List) subtracts what it reported. With
//!   `keep_odometry_remainder` the fraction left over (and nothing beyond the cap) carries into the next
//!   report; without it every report starts from zero. The firmware's choice is undocumented [C1 pp18–19; C2 p27];
//!   create_robot issue 28 reports slow turns reading 0 on a Create 1.
//! - Encoders [C2 p30–31]: counters of wheel travel in counts of π·72/508.8 mm that wrap at 16 bits;
//!   they are not quadrature, so they count in the *commanded* direction (up when the command is zero).

use super::motor::WheelCommand;
use super::params::SimParams;
use super::world::{LEFT, RIGHT};

/// Accumulators reset on report, plus the wrapping encoder counters.
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    distance_mm: f64,
    angle_deg: f64,
    keep_remainder: bool,
    wheel_base_mm: f64,
    mm_per_count: f64,
    /// Travel not yet counted, in counts (0..1), per wheel.
    count_fraction: [f64; 2],
    counts: [u16; 2],
}

impl Odometry {
    pub fn new(p: &SimParams) -> Self {
        Odometry {
            distance_mm: 0.0,
            angle_deg: 0.0,
            keep_remainder: p.keep_odometry_remainder,
            wheel_base_mm: p.wheel_base_m * 1000.0,
            mm_per_count: p.mm_per_encoder_count(),
            count_fraction: [0.0; 2],
            counts: [0; 2],
        }
    }

    /// Adds one step's signed wheel travel (mm, `[left, right]`) made under `commands`.
    pub fn advance(&mut self, travel_mm: [f64; 2], commands: [WheelCommand; 2]) {
        let [l, r] = travel_mm;
        self.distance_mm += (l + r) / 2.0;
        if self.wheel_base_mm > 0.0 {
            self.angle_deg += ((r - l) / self.wheel_base_mm).to_degrees();
        }
        if self.mm_per_count <= 0.0 {
            return;
        }
        for side in [LEFT, RIGHT] {
            let moved = travel_mm[side].abs() / self.mm_per_count + self.count_fraction[side];
            let whole = moved.floor();
            self.count_fraction[side] = moved - whole;
            let n = (whole as i64 & 0xFFFF) as u16;
            self.counts[side] = if direction(commands[side]) < 0 {
                self.counts[side].wrapping_sub(n)
            } else {
                self.counts[side].wrapping_add(n)
            };
        }
    }

    /// The distance a report would give now, mm.
    pub fn peek_distance_mm(&self) -> i32 {
        whole_capped(self.distance_mm)
    }

    /// The angle a report would give now, degrees.
    pub fn peek_angle_deg(&self) -> i32 {
        whole_capped(self.angle_deg)
    }

    /// Reports the distance and starts accumulating afresh.
    pub fn take_distance_mm(&mut self) -> i32 {
        let v = self.peek_distance_mm();
        self.distance_mm = self.leftover(self.distance_mm);
        v
    }

    /// Reports the angle and starts accumulating afresh.
    pub fn take_angle_deg(&mut self) -> i32 {
        let v = self.peek_angle_deg();
        self.angle_deg = self.leftover(self.angle_deg);
        v
    }

    fn leftover(&self, acc: f64) -> f64 {
        if self.keep_remainder {
            acc.fract()
        } else {
            0.0
        }
    }

    /// Encoder counter of a wheel (`LEFT`/`RIGHT`) as the signed 16-bit value of packets 43/44.
    pub fn encoder(&self, side: usize) -> i32 {
        i32::from(self.counts[side & 1] as i16)
    }
}

/// Direction the firmware counts a wheel's encoder in.
fn direction(cmd: WheelCommand) -> i8 {
    let v = match cmd {
        WheelCommand::Brake => 0.0,
        WheelCommand::Speed(v) | WheelCommand::Duty(v) => v,
    };
    if v < 0.0 { -1 } else { 1 }
}

/// Whole units toward zero, capped to the i16 range [C1 p18–19; C2 p27].
fn whole_capped(v: f64) -> i32 {
    v.trunc().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;

    const FWD: [WheelCommand; 2] = [WheelCommand::Speed(100.0), WheelCommand::Speed(100.0)];

    fn odo(keep: bool) -> Odometry {
        let mut p = SimParams::for_model(Model::Create2);
        p.keep_odometry_remainder = keep;
        Odometry::new(&p)
    }

    #[test]
    fn reports_reset_and_keep_the_fraction() {
        let mut o = odo(true);
        o.advance([1.5, 1.5], FWD);
        assert_eq!(o.peek_distance_mm(), 1);
        assert_eq!(o.take_distance_mm(), 1);
        assert_eq!(o.take_distance_mm(), 0);
        o.advance([0.6, 0.6], FWD);
        // 0.5 left over + 0.6 = 1.1
        assert_eq!(o.take_distance_mm(), 1);
        let mut d = odo(false);
        d.advance([1.5, 1.5], FWD);
        assert_eq!(d.take_distance_mm(), 1);
        d.advance([0.6, 0.6], FWD);
        assert_eq!(d.take_distance_mm(), 0);
    }

    #[test]
    fn negative_values_truncate_toward_zero() {
        let mut o = odo(true);
        o.advance([-2.7, -2.7], FWD);
        assert_eq!(o.take_distance_mm(), -2);
        o.advance([-0.4, -0.4], FWD);
        assert_eq!(o.take_distance_mm(), -1);
    }

    #[test]
    fn angle_is_counter_clockwise_positive_over_the_wheel_base() {
        let mut o = odo(true);
        // Right wheel forward by a quarter of the base circumference-equivalent: 90°.
        let quarter = std::f64::consts::FRAC_PI_2 * 235.0 / 2.0;
        o.advance([-quarter, quarter], FWD);
        assert_eq!(o.peek_distance_mm(), 0);
        assert_eq!(o.take_angle_deg(), 90);
        o.advance([quarter, -quarter], FWD);
        assert_eq!(o.take_angle_deg(), -90);
    }

    #[test]
    fn unpolled_values_cap_at_i16() {
        let mut o = odo(true);
        for _ in 0..100 {
            o.advance([500.0, 500.0], FWD);
        }
        assert_eq!(o.peek_distance_mm(), 32_767);
        assert_eq!(o.take_distance_mm(), 32_767);
        // What lay beyond the cap is gone.
        assert_eq!(o.take_distance_mm(), 0);
        for _ in 0..100 {
            o.advance([-500.0, -500.0], FWD);
        }
        assert_eq!(o.take_distance_mm(), -32_768);
    }

    #[test]
    fn encoders_count_in_the_commanded_direction_and_wrap() {
        let mut o = odo(true);
        let per = SimParams::for_model(Model::Create2).mm_per_encoder_count();
        o.advance([10.0 * per + 0.01, 3.0 * per + 0.01], FWD);
        assert_eq!((o.encoder(LEFT), o.encoder(RIGHT)), (10, 3));
        let back = [WheelCommand::Speed(-100.0), WheelCommand::Brake];
        // Travel forward under a backward command still counts down; zero command counts up.
        o.advance([5.0 * per, -5.0 * per], back);
        assert_eq!((o.encoder(LEFT), o.encoder(RIGHT)), (5, 8));
        for _ in 0..33 {
            o.advance([1000.0 * per, 0.0], FWD);
        }
        // 5 + 33000 counts wraps past 32767.
        assert_eq!(
            o.encoder(LEFT),
            i32::from((5u16.wrapping_add(33_000)) as i16)
        );
        assert!(o.encoder(LEFT) < 0);
    }
}
