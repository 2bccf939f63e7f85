//! Default policies π and fixed responses ϱ, as one configurable [`Policy`] enum, plus
//! [`StallDefaultPolicy`], the stall experiment's deterministic 20 s driving cycle.
//!
//! The paper gives the shape of each behaviour but no speeds; the speeds here are chosen from the
//! geometry and stated, not tuned against results:
//! - Stall cycle (rotate right 3 s, forward 7 s, rotate right 3 s, backward 7 s): **200 mm/s** straight,
//!   so 7 s covers 1.4 m, more than the 1 m legs of the paper's triangular enclosure: the robot meets a
//!   wall and pushes for the rest of the leg, which is what the cycle was "designed to" provoke; 40 % of
//!   the 500 mm/s limit. In-place turns at **±100 mm/s** per wheel: on a Create 1 (258 mm wheel base)
//!   that is 0.78 rad/s, ≈ 133° in 3 s, close to the 135° exterior angle of the enclosure's 45° corners,
//!   so successive legs head back across the enclosure.
//! - Interaction response, spin left in place: **±150 mm/s** per wheel (≈ 67°/s on a Create 1), clearly
//!   visible motion at under a third of the limit, safe next to a person.
//! - Interaction default: stay still.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::action::{Action, MAX_WHEEL_MM_S};

/// Ticks per second at the paper's 20 ms time step.
pub const TICKS_PER_SECOND: u64 = 50;
/// The stall cycle's default straight speed, mm/s.
pub const STALL_DRIVE_MM_S: i16 = 200;
/// The stall cycle's default in-place turn speed per wheel, mm/s.
pub const STALL_TURN_MM_S: i16 = 100;
/// The interaction response's default spin speed per wheel, mm/s.
pub const SPIN_MM_S: i16 = 150;

/// An invalid policy configuration.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ControlError {
    /// A speed outside what the Open Interface's Drive Direct accepts; `field` is the policy's key.
    #[error("{field} = {speed} mm/s is outside the Drive Direct range -500..=500 mm/s")]
    SpeedOutOfRange {
        /// The policy's key, e.g. `drive_mm_s`.
        field: &'static str,
        /// The configured speed.
        speed: i16,
    },
}

/// The stall experiment's default policy: a deterministic 1000-tick (20 s) cycle of
/// rotate right 150 ticks, forward 350, rotate right 150, backward 350.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StallDefaultPolicy {
    drive_mm_s: i16,
    turn_mm_s: i16,
}

impl StallDefaultPolicy {
    /// Ticks spent in each phase: rotate right 3 s, forward 7 s, rotate right 3 s, backward 7 s.
    pub const PHASE_TICKS: [u64; 4] = [150, 350, 150, 350];
    /// The cycle length in ticks (20 s).
    pub const CYCLE_TICKS: u64 = 1000;

    /// The cycle driving straight at `speed_mm_s` and turning with each wheel at half that speed
    /// (200 → 100 mm/s; see the module documentation). Speeds are clamped to the OI's ±500 mm/s, a last
    /// line of defence: a configuration with a speed beyond it is refused ([`Policy::validate`]).
    pub fn new(speed_mm_s: i16) -> Self {
        StallDefaultPolicy {
            drive_mm_s: speed_mm_s.clamp(-MAX_WHEEL_MM_S, MAX_WHEEL_MM_S),
            turn_mm_s: (speed_mm_s / 2).clamp(-MAX_WHEEL_MM_S, MAX_WHEEL_MM_S),
        }
    }

    /// The same cycle with an explicit in-place turn speed per wheel.
    pub fn with_turn_speed(self, turn_mm_s: i16) -> Self {
        StallDefaultPolicy {
            turn_mm_s: turn_mm_s.clamp(-MAX_WHEEL_MM_S, MAX_WHEEL_MM_S),
            ..self
        }
    }

    /// The action on tick `tick` (counted from the start of the run; the cycle repeats).
    pub fn action(&self, tick: u64) -> Action {
        let (drive, turn) = (self.drive_mm_s, self.turn_mm_s);
        let rotate_right = Action::new(turn, turn.saturating_neg());
        match tick % Self::CYCLE_TICKS {
            0..150 => rotate_right,
            150..500 => Action::new(drive, drive),
            500..650 => rotate_right,
            _ => Action::new(drive.saturating_neg(), drive.saturating_neg()),
        }
    }
}

impl Default for StallDefaultPolicy {
    fn default() -> Self {
        StallDefaultPolicy::new(STALL_DRIVE_MM_S)
    }
}

/// A default policy or fixed response, as configured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Policy {
    /// Zero velocity on both wheels (the stall response; the interaction default). A struct variant
    /// (`Stop {}` in Rust, `{ kind = "stop" }` in TOML) so that unknown keys are rejected.
    Stop {},
    /// The stall experiment's 20 s cycle ([`StallDefaultPolicy`]).
    StallCycle {
        #[serde(default = "default_drive")]
        drive_mm_s: i16,
        #[serde(default = "default_turn")]
        turn_mm_s: i16,
    },
    /// Spin left (counter-clockwise) in place: left wheel −speed, right wheel +speed.
    SpinLeft {
        #[serde(default = "default_spin")]
        speed_mm_s: i16,
    },
    /// Spin right (clockwise) in place: left wheel +speed, right wheel −speed.
    SpinRight {
        #[serde(default = "default_spin")]
        speed_mm_s: i16,
    },
    /// Fixed wheel velocities.
    Constant { left_mm_s: i16, right_mm_s: i16 },
}

fn default_drive() -> i16 {
    STALL_DRIVE_MM_S
}
fn default_turn() -> i16 {
    STALL_TURN_MM_S
}
fn default_spin() -> i16 {
    SPIN_MM_S
}

impl Policy {
    /// The action on tick `tick` (counted from the start of the run).
    pub fn action(&self, tick: u64) -> Action {
        match *self {
            Policy::Stop {} => Action::STOP,
            Policy::StallCycle {
                drive_mm_s,
                turn_mm_s,
            } => StallDefaultPolicy::new(drive_mm_s)
                .with_turn_speed(turn_mm_s)
                .action(tick),
            Policy::SpinLeft { speed_mm_s } => Action::new(speed_mm_s.saturating_neg(), speed_mm_s),
            Policy::SpinRight { speed_mm_s } => {
                Action::new(speed_mm_s, speed_mm_s.saturating_neg())
            }
            Policy::Constant {
                left_mm_s,
                right_mm_s,
            } => Action::new(left_mm_s, right_mm_s),
        }
    }

    /// Rejects speeds outside ±500 mm/s, the Drive Direct range: refused, not clamped, so that the robot
    /// never drives at a speed other than the one configured ([`Policy::action`] clamps only as a last
    /// line of defence).
    pub fn validate(&self) -> Result<(), ControlError> {
        let speeds: &[(&'static str, i16)] = match self {
            Policy::Stop {} => &[],
            Policy::StallCycle {
                drive_mm_s,
                turn_mm_s,
            } => &[("drive_mm_s", *drive_mm_s), ("turn_mm_s", *turn_mm_s)],
            Policy::SpinLeft { speed_mm_s } | Policy::SpinRight { speed_mm_s } => {
                &[("speed_mm_s", *speed_mm_s)]
            }
            Policy::Constant {
                left_mm_s,
                right_mm_s,
            } => &[("left_mm_s", *left_mm_s), ("right_mm_s", *right_mm_s)],
        };
        match speeds
            .iter()
            .find(|(_, s)| s.unsigned_abs() > MAX_WHEEL_MM_S.unsigned_abs())
        {
            Some(&(field, speed)) => Err(ControlError::SpeedOutOfRange { field, speed }),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stall_cycle_phase_boundaries() {
        let p = StallDefaultPolicy::new(200);
        let right = Action::new(100, -100);
        let forward = Action::new(200, 200);
        let backward = Action::new(-200, -200);
        let expect = [
            (0, right),
            (149, right),
            (150, forward),
            (499, forward),
            (500, right),
            (649, right),
            (650, backward),
            (999, backward),
            (1000, right),
            (1150, forward),
            (7 * 1000 + 650, backward),
        ];
        for (tick, want) in expect {
            assert_eq!(p.action(tick), want, "tick {tick}");
        }
        assert_eq!(
            StallDefaultPolicy::PHASE_TICKS.iter().sum::<u64>(),
            StallDefaultPolicy::CYCLE_TICKS
        );
        assert_eq!(StallDefaultPolicy::CYCLE_TICKS, 20 * TICKS_PER_SECOND);
    }

    #[test]
    fn stall_cycle_spends_the_documented_time_in_each_phase() {
        let p = StallDefaultPolicy::default();
        let actions: Vec<Action> = (0..1000).map(|t| p.action(t)).collect();
        let count = |a: Action| actions.iter().filter(|&&x| x == a).count();
        assert_eq!(count(Action::new(100, -100)), 300);
        assert_eq!(count(Action::new(200, 200)), 350);
        assert_eq!(count(Action::new(-200, -200)), 350);
        let custom = StallDefaultPolicy::new(300).with_turn_speed(120);
        assert_eq!(custom.action(0), Action::new(120, -120));
        assert_eq!(custom.action(u64::MAX), custom.action(u64::MAX % 1000));
    }

    #[test]
    fn policies_from_config() {
        #[derive(Deserialize)]
        struct W {
            default_policy: Policy,
            response: Policy,
        }
        let w: W = toml::from_str(
            "default_policy = { kind = \"stall_cycle\" }\nresponse = { kind = \"stop\" }",
        )
        .unwrap();
        assert_eq!(
            w.default_policy,
            Policy::StallCycle {
                drive_mm_s: 200,
                turn_mm_s: 100
            }
        );
        assert_eq!(w.default_policy.action(200), Action::new(200, 200));
        assert_eq!(w.response.action(3), Action::STOP);
        let spin: Policy = toml::from_str::<W>(
            "default_policy = { kind = \"stop\" }\nresponse = { kind = \"spin_left\", speed_mm_s = 120 }",
        )
        .unwrap()
        .response;
        assert_eq!(
            spin.action(0),
            Action {
                left_mm_s: -120,
                right_mm_s: 120
            }
        );
        assert!(
            toml::from_str::<W>(
                "default_policy = { kind = \"stop\", speed = 1 }\nresponse = { kind = \"stop\" }"
            )
            .is_err()
        );
    }

    #[test]
    fn spin_directions_and_validation() {
        let left = Policy::SpinLeft {
            speed_mm_s: SPIN_MM_S,
        }
        .action(0);
        assert!(left.left_mm_s < 0 && left.right_mm_s > 0);
        let right = Policy::SpinRight {
            speed_mm_s: SPIN_MM_S,
        }
        .action(0);
        assert!(right.left_mm_s > 0 && right.right_mm_s < 0);
        assert_eq!(Policy::Stop {}.validate(), Ok(()));
        assert_eq!(
            Policy::Constant {
                left_mm_s: 0,
                right_mm_s: -600
            }
            .validate(),
            Err(ControlError::SpeedOutOfRange {
                field: "right_mm_s",
                speed: -600
            })
        );
        let e = Policy::StallCycle {
            drive_mm_s: 2000,
            turn_mm_s: 100,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "drive_mm_s = 2000 mm/s is outside the Drive Direct range -500..=500 mm/s"
        );
        assert!(
            Policy::SpinRight {
                speed_mm_s: i16::MIN
            }
            .validate()
            .is_err()
        );
        for edge in [500, -500] {
            let p = Policy::Constant {
                left_mm_s: edge,
                right_mm_s: edge,
            };
            assert_eq!(p.validate(), Ok(()));
        }
        assert_eq!(
            Policy::SpinLeft {
                speed_mm_s: i16::MIN
            }
            .action(0),
            Action {
                left_mm_s: 500,
                right_mm_s: -500
            }
        );
    }
}
