//! The OI's operating modes: the packet-35 codes and the two modes a host drives the robot in.
//!
//! Off (0) listens only for Start; Passive (1) reads sensors and ignores actuators; Safe (2) drives with the
//! firmware's cliff, wheel-drop and charger protection; Full (3) drives without it [C1 p6–7; C2 p7–10].

use serde::{Deserialize, Serialize};

/// The OI modes (packet 35 values) [C1 p6–7; C2 p7–10].
pub mod code {
    /// Off.
    pub const OFF: u8 = 0;
    /// Passive.
    pub const PASSIVE: u8 = 1;
    /// Safe.
    pub const SAFE: u8 = 2;
    /// Full.
    pub const FULL: u8 = 3;
}

/// The OI mode the server drives the robot in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriveMode {
    /// Safe mode: the firmware stops the motors on cliffs, wheel drops and the charger.
    #[default]
    Safe,
    /// Full mode: no firmware safety (needed to drive off the dock).
    Full,
}

impl DriveMode {
    /// The mode's packet-35 code.
    pub fn code(self) -> u8 {
        match self {
            DriveMode::Safe => code::SAFE,
            DriveMode::Full => code::FULL,
        }
    }
}
