//! Reading the OI mode from packet 35, with the firmware's mode-plus-one quirk.
//!
//! Some Create 2 firmware reports every mode one too high (Safe as 3, Full as 4: `AutonomyLab/create_robot#64`,
//! `AutonomyLab/libcreate#67`). Uncorrected, a trip to Passive would read as 2, i.e. Safe, and go unnoticed.
//! [`ModeReader`] corrects it: set on or off in the configuration, or detected (`auto`) from a value the
//! robot cannot report honestly — 4 — or from Full (3) right after the host asked for Safe, which the robot
//! never enters by itself.

use serde::{Deserialize, Serialize};

/// Whether the robot's firmware reports mode + 1.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModeQuirk {
    /// Detect it from the values seen (the default).
    #[default]
    Auto,
    /// The firmware reports mode + 1.
    On,
    /// The firmware reports the mode as specified.
    Off,
}

pub use crate::oi::mode::code;

/// Turns raw packet-35 values into modes.
#[derive(Debug, Clone)]
pub struct ModeReader {
    setting: ModeQuirk,
    detected: bool,
}

impl ModeReader {
    /// A reader with the configured quirk setting.
    pub fn new(setting: ModeQuirk) -> Self {
        ModeReader {
            setting,
            detected: false,
        }
    }

    /// True when values are being corrected by one.
    pub fn quirk_active(&self) -> bool {
        match self.setting {
            ModeQuirk::On => true,
            ModeQuirk::Off => false,
            ModeQuirk::Auto => self.detected,
        }
    }

    /// The mode for a raw value, given the mode the host last commanded (Safe or Full), or `None` when the
    /// value cannot be a mode at all.
    pub fn read(&mut self, raw: i32, commanded: u8) -> Option<u8> {
        if self.setting == ModeQuirk::Auto && !self.detected {
            let impossible = raw == 4;
            let full_while_safe = commanded == code::SAFE && raw == i32::from(code::FULL);
            if impossible || full_while_safe {
                self.detected = true;
            }
        }
        let corrected = if self.quirk_active() { raw - 1 } else { raw };
        u8::try_from(corrected).ok().filter(|m| *m <= code::FULL)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn honest_firmware_reads_as_is() {
        let mut r = ModeReader::new(ModeQuirk::Auto);
        assert_eq!(r.read(2, code::SAFE), Some(code::SAFE));
        assert_eq!(r.read(1, code::SAFE), Some(code::PASSIVE));
        assert!(!r.quirk_active());
        assert_eq!(r.read(9, code::SAFE), None);
        assert_eq!(r.read(-1, code::SAFE), None);
    }

    #[test]
    fn auto_detects_full_reported_while_safe_and_then_sees_the_trip() {
        let mut r = ModeReader::new(ModeQuirk::Auto);
        assert_eq!(r.read(3, code::SAFE), Some(code::SAFE));
        assert!(r.quirk_active());
        // Passive under the quirk reads 2: without the correction this trip would look like Safe.
        assert_eq!(r.read(2, code::SAFE), Some(code::PASSIVE));
    }

    #[test]
    fn auto_detects_four() {
        let mut r = ModeReader::new(ModeQuirk::Auto);
        assert_eq!(r.read(4, code::FULL), Some(code::FULL));
        assert_eq!(r.read(2, code::FULL), Some(code::PASSIVE));
    }

    #[test]
    fn fixed_settings_do_not_learn() {
        let mut off = ModeReader::new(ModeQuirk::Off);
        assert_eq!(off.read(3, code::SAFE), Some(code::FULL));
        assert_eq!(off.read(4, code::SAFE), None);
        let mut on = ModeReader::new(ModeQuirk::On);
        assert_eq!(on.read(2, code::SAFE), Some(code::PASSIVE));
        assert_eq!(on.read(0, code::SAFE), None);
    }
}
