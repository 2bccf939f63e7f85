//! The raw readings a tick record carries ([`SensorReadings`]), taken from one sensor snapshot.

use crate::oi::SensorValues;
use crate::oi::packets::{bits, id};
use crate::record::SensorReadings;

/// Summarises `values`, with odometry summed over every frame since the previous tick.
pub fn read_sensors(
    values: Option<&SensorValues>,
    distance_mm: i32,
    angle_deg: i32,
) -> SensorReadings {
    let Some(v) = values else {
        return SensorReadings {
            distance_mm,
            angle_deg,
            ..SensorReadings::default()
        };
    };
    let oc = v.get_or_zero(id::OVERCURRENTS);
    let bumps = v.get_or_zero(id::BUMPS_WHEEL_DROPS);
    SensorReadings {
        overcurrent_left: oc & bits::OC_LEFT_WHEEL != 0,
        overcurrent_right: oc & bits::OC_RIGHT_WHEEL != 0,
        bump_left: bumps & bits::BUMP_LEFT != 0,
        bump_right: bumps & bits::BUMP_RIGHT != 0,
        battery_current_ma: v.get(id::CURRENT),
        battery_voltage_mv: v.get(id::VOLTAGE),
        battery_charge_mah: v.get(id::BATTERY_CHARGE),
        distance_mm,
        angle_deg,
        oi_mode: v.get(id::OI_MODE),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_and_values_come_from_the_right_bits() {
        let mut v = SensorValues::new();
        v.set(id::OVERCURRENTS, bits::OC_LEFT_WHEEL);
        v.set(id::BUMPS_WHEEL_DROPS, bits::BUMP_RIGHT);
        v.set(id::CURRENT, -1200);
        let s = read_sensors(Some(&v), 7, -2);
        assert!(s.overcurrent_left && !s.overcurrent_right);
        assert!(s.bump_right && !s.bump_left);
        assert_eq!(s.battery_current_ma, Some(-1200));
        assert_eq!(s.battery_voltage_mv, None);
        assert_eq!((s.distance_mm, s.angle_deg), (7, -2));
        assert_eq!(read_sensors(None, 0, 0), SensorReadings::default());
    }
}
