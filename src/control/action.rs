//! [`Action`]: what the robot is told to do on one tick, as the two wheel velocities of a Drive Direct
//! command (opcode 145).

use serde::{Deserialize, Serialize};

/// The largest wheel speed the Open Interface accepts, mm/s (both models).
pub const MAX_WHEEL_MM_S: i16 = 500;

/// Wheel velocities in mm/s, positive = forward. In-place rotation: opposite signs (left negative,
/// right positive turns counter-clockwise, i.e. left).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Action {
    pub left_mm_s: i16,
    pub right_mm_s: i16,
}

impl Action {
    /// Both wheels stopped: the zero-velocity command.
    pub const STOP: Action = Action {
        left_mm_s: 0,
        right_mm_s: 0,
    };

    /// An action with both velocities clamped to `±MAX_WHEEL_MM_S`.
    pub fn new(left_mm_s: i16, right_mm_s: i16) -> Self {
        Action {
            left_mm_s: left_mm_s.clamp(-MAX_WHEEL_MM_S, MAX_WHEEL_MM_S),
            right_mm_s: right_mm_s.clamp(-MAX_WHEEL_MM_S, MAX_WHEEL_MM_S),
        }
    }

    /// True when both wheels are commanded to stand still.
    pub fn is_stop(&self) -> bool {
        *self == Action::STOP
    }

    /// True when both velocities are within the OI's ±500 mm/s.
    pub fn is_within_limits(&self) -> bool {
        self.left_mm_s.unsigned_abs() <= MAX_WHEEL_MM_S.unsigned_abs()
            && self.right_mm_s.unsigned_abs() <= MAX_WHEEL_MM_S.unsigned_abs()
    }
}

impl Default for Action {
    fn default() -> Self {
        Action::STOP
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_clamps_to_the_oi_range() {
        assert_eq!(
            Action::new(900, -i16::MAX),
            Action {
                left_mm_s: 500,
                right_mm_s: -500
            }
        );
        assert_eq!(
            Action::new(i16::MIN, 20),
            Action {
                left_mm_s: -500,
                right_mm_s: 20
            }
        );
        assert!(Action::new(i16::MIN, i16::MAX).is_within_limits());
        assert!(
            !Action {
                left_mm_s: 501,
                right_mm_s: 0
            }
            .is_within_limits()
        );
        assert!(Action::default().is_stop());
        assert!(!Action::new(0, 1).is_stop());
    }
}
