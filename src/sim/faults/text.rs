//! The ASCII text a Create 2 prints on its transmit line unasked, for injection between and inside
//! stream frames (pycreate2 issue 12, create_robot issue 106): the once-a-second charging line, shaped like
//! `bat:   min 0  sec 10  mV 17061  mA 1016  tenths-deg-C 348  mAH 2696  state 5`
//! (`emard/roomba-wifi`, `AutonomyLab/create_robot#106`), and the lines of the boot banner
//! ([`SimRobot::boot_banner`], pycreate2#12). Every line ends in CR LF and holds only printable ASCII,
//! so it never contains the stream header byte 19.

use crate::oi::packets::id;
use crate::rng::Rng;
use crate::sim::STEP_SECONDS;
use crate::sim::robot::SimRobot;

/// A `bat:` line with the robot's present battery readings; `min`/`sec` count the robot's running
/// time.
pub fn battery_line(robot: &SimRobot) -> String {
    let v = robot.sensors();
    let seconds = (robot.elapsed_steps() as f64 * STEP_SECONDS) as u64;
    format!(
        "bat:   min {}  sec {}  mV {}  mA {}  tenths-deg-C {}  mAH {}  state {}\r\n",
        seconds / 60,
        seconds % 60,
        v.get_or_zero(id::VOLTAGE),
        v.get_or_zero(id::CURRENT),
        v.get_or_zero(id::TEMPERATURE) * 10,
        v.get_or_zero(id::BATTERY_CHARGE),
        v.get_or_zero(id::CHARGING_STATE),
    )
}

/// One line for a text fault: three times in four a `bat:` line, else a random line of the boot
/// banner.
pub fn random_line(robot: &SimRobot, rng: &mut Rng) -> String {
    if rng.below(4) > 0 {
        return battery_line(robot);
    }
    let banner = robot.boot_banner();
    let lines: Vec<&str> = banner.split("\r\n").filter(|l| !l.is_empty()).collect();
    match lines.get(rng.below(lines.len() as u64) as usize) {
        Some(line) => format!("{line}\r\n"),
        None => battery_line(robot),
    }
}

/// True for the bytes injected text may contain: printable ASCII, CR and LF.
pub fn is_text_byte(b: u8) -> bool {
    b == b'\r' || b == b'\n' || (0x20..0x7f).contains(&b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;
    use crate::sim::params::SimParams;

    fn robot() -> SimRobot {
        SimRobot::new(Model::Create2, SimParams::for_model(Model::Create2), 3)
    }

    #[test]
    fn the_battery_line_has_the_create2_shape_and_the_robot_values() {
        let mut r = robot();
        for _ in 0..4100 {
            r.step();
        }
        let line = battery_line(&r);
        let v = r.sensors();
        assert!(line.starts_with("bat:   min 1  sec 1  mV "), "{line}");
        assert!(line.ends_with("\r\n"));
        let words: Vec<&str> = line.split_whitespace().collect();
        let after = |k: &str| words[words.iter().position(|w| *w == k).unwrap() + 1];
        assert_eq!(after("mV"), v.get_or_zero(id::VOLTAGE).to_string());
        assert_eq!(after("mAH"), v.get_or_zero(id::BATTERY_CHARGE).to_string());
        assert!(after("mV").parse::<i32>().unwrap() > 10_000);
    }

    #[test]
    fn random_lines_are_printable_ascii_lines_of_both_kinds() {
        let r = robot();
        let mut rng = Rng::new(1);
        let (mut bat, mut banner) = (0, 0);
        for _ in 0..400 {
            let line = random_line(&r, &mut rng);
            assert!(line.bytes().all(is_text_byte), "{line:?}");
            assert!(line.ends_with("\r\n") && line.len() > 2);
            assert!(!line.contains(char::from(19)));
            if line.starts_with("bat:") {
                bat += 1;
            } else {
                assert!(r.boot_banner().contains(&line), "{line:?}");
                banner += 1;
            }
        }
        assert!(bat > 250 && banner > 60, "{bat} {banner}");
    }
}
