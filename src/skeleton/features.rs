//! The per-tick elbow features of the command experiment: both elbow angles, their moving averages, and the
//! stimulus `E = 𝕀{LeftElbow < 90°}`, computed once per 20 ms control tick from the [`PoseTracker`].

use serde::Serialize;

use super::ewma::Ewma;
use super::geometry::COMMAND_THRESHOLD_DEG;
use super::joint::Side;
use super::pose::{PoseTracker, SkeletonStatus};

/// The paper's averaging weight: `μ_{t+1} = 0.8 μ_t + 0.2 LeftElbow_t`.
///
/// As the paper writes it, the average a tick uses, μ_t, holds the angles of the ticks *before* it; this
/// tick's angle enters μ_{t+1}. So the tile coder sees the angle now and its average up to the previous tick
/// (a tracker whose first valid angle is x starts from μ = x).
pub const ELBOW_EWMA_KEEP: f64 = 0.8;

/// Consecutive invalid ticks after which an elbow's average is forgotten (50 ticks = 1 s at 20 ms). Shorter
/// gaps, such as the 100–200 ms joint dropouts of a depth tracker, hold the average; after a longer gap (the
/// person stepped out, or tracking was lost) the old average says nothing about the new pose, so the next
/// valid angle re-initialises it.
pub const DEFAULT_MAX_HOLD_TICKS: u32 = 50;

/// Elbow features for one tick. Invalid angles are `None`, never 0.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ElbowFeatures {
    /// Left elbow interior angle in degrees, when valid this tick.
    pub left: Option<f64>,
    /// Moving average of the left angle (held through short gaps).
    pub left_avg: Option<f64>,
    /// Right elbow interior angle in degrees, when valid this tick.
    pub right: Option<f64>,
    /// Moving average of the right angle (held through short gaps).
    pub right_avg: Option<f64>,
    /// Stimulus `E`: the left angle is valid and below 90°.
    pub command: bool,
    /// Whether a skeleton is coming in.
    pub skeleton: SkeletonStatus,
}

/// One elbow's smoothing state.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SmoothedElbow {
    avg: Ewma,
    invalid_run: u32,
}

impl SmoothedElbow {
    fn new() -> Self {
        SmoothedElbow {
            avg: Ewma::new(ELBOW_EWMA_KEEP),
            invalid_run: 0,
        }
    }

    /// μ_t for this tick (the average of the earlier angles; the first valid angle when there are none),
    /// then folds this tick's angle in for μ_{t+1}.
    fn step(&mut self, angle: Option<f64>, max_hold_ticks: u32) -> Option<f64> {
        if angle.is_some() {
            self.invalid_run = 0;
        } else {
            self.invalid_run = self.invalid_run.saturating_add(1);
            if self.invalid_run > max_hold_ticks {
                self.avg.reset();
            }
        }
        let mu_t = self.avg.value().or(angle.filter(|deg| deg.is_finite()));
        self.avg.update(angle);
        mu_t
    }
}

/// Turns the pose into [`ElbowFeatures`] once per tick, keeping the moving averages between ticks.
#[derive(Debug, Clone, PartialEq)]
pub struct ElbowFeatureTracker {
    left: SmoothedElbow,
    right: SmoothedElbow,
    max_hold_ticks: u32,
}

impl Default for ElbowFeatureTracker {
    fn default() -> Self {
        Self::new()
    }
}

impl ElbowFeatureTracker {
    /// A tracker with the paper's 0.8 averaging and `DEFAULT_MAX_HOLD_TICKS`.
    pub fn new() -> Self {
        ElbowFeatureTracker {
            left: SmoothedElbow::new(),
            right: SmoothedElbow::new(),
            max_hold_ticks: DEFAULT_MAX_HOLD_TICKS,
        }
    }

    /// The same tracker, forgetting an average after more than `ticks` consecutive invalid ticks.
    pub fn with_max_hold_ticks(mut self, ticks: u32) -> Self {
        self.max_hold_ticks = ticks;
        self
    }

    /// Forget both averages (call when the tracked user changes).
    pub fn reset(&mut self) {
        self.left = SmoothedElbow::new();
        self.right = SmoothedElbow::new();
    }

    /// Compute this tick's features from the pose as seen at `now_ms`. Call exactly once per tick: the
    /// averages advance on every call.
    pub fn step(&mut self, pose: &PoseTracker, now_ms: u64) -> ElbowFeatures {
        let left = pose.elbow_angle(Side::Left, now_ms).value();
        let right = pose.elbow_angle(Side::Right, now_ms).value();
        ElbowFeatures {
            left,
            left_avg: self.left.step(left, self.max_hold_ticks),
            right,
            right_avg: self.right.step(right, self.max_hold_ticks),
            command: left.is_some_and(|deg| deg < COMMAND_THRESHOLD_DEG),
            skeleton: pose.status(now_ms),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::{Joint, JointSample};

    fn sample(pos: [f64; 3], at_ms: u64) -> JointSample {
        JointSample {
            pos_mm: pos,
            at_ms,
            confidence: 1.0,
        }
    }

    /// Put a left arm with interior angle `deg` into the pose at time `t` (upper arm straight down, forearm
    /// swinging forward towards the sensor).
    fn set_left(p: &mut PoseTracker, deg: f64, t: u64) {
        let e = [-190.0, 300.0, 2500.0];
        let r = deg.to_radians();
        p.update(Joint::LeftShoulder, sample([-190.0, 600.0, 2500.0], t));
        p.update(Joint::LeftElbow, sample(e, t));
        p.update(
            Joint::LeftHand,
            sample([e[0], e[1] + 260.0 * r.cos(), e[2] - 260.0 * r.sin()], t),
        );
    }

    #[test]
    fn command_is_left_angle_below_ninety() {
        let mut pose = PoseTracker::new(100);
        let mut f = ElbowFeatureTracker::new();
        for (deg, expect) in [
            (160.0, false),
            (90.5, false),
            (89.5, true),
            (45.0, true),
            (135.0, false),
        ] {
            set_left(&mut pose, deg, 0);
            let out = f.step(&pose, 0);
            assert_eq!(out.command, expect, "{deg}");
            assert!((out.left.unwrap() - deg).abs() < 1e-9);
            assert_eq!(out.right, None);
            assert_eq!(out.right_avg, None);
        }
    }

    #[test]
    fn invalid_left_never_commands_and_average_is_held() {
        let mut pose = PoseTracker::new(100);
        let mut f = ElbowFeatureTracker::new();
        set_left(&mut pose, 45.0, 0);
        let bent = f.step(&pose, 0);
        assert!(bent.command);
        // The same bent arm, now stale: no angle, no command, average held.
        let later = f.step(&pose, 500);
        assert_eq!(later.left, None);
        assert!(!later.command);
        assert_eq!(later.left_avg, bent.left_avg);
    }

    #[test]
    fn average_follows_the_paper_recurrence_one_tick_behind_the_angle() {
        // μ_{t+1} = 0.8 μ_t + 0.2 LeftElbow_t: a tick's average does not contain its own angle.
        let mut pose = PoseTracker::new(100);
        let mut f = ElbowFeatureTracker::new();
        set_left(&mut pose, 160.0, 0);
        assert!((f.step(&pose, 0).left_avg.unwrap() - 160.0).abs() < 1e-9);
        set_left(&mut pose, 60.0, 20);
        let second = f.step(&pose, 20);
        assert!((second.left.unwrap() - 60.0).abs() < 1e-9);
        assert!(
            (second.left_avg.unwrap() - 160.0).abs() < 1e-9,
            "{second:?}"
        );
        set_left(&mut pose, 60.0, 40);
        let avg = f.step(&pose, 40).left_avg.unwrap();
        assert!((avg - (0.8 * 160.0 + 0.2 * 60.0)).abs() < 1e-9, "{avg}");
    }

    #[test]
    fn long_gaps_forget_the_average() {
        let mut pose = PoseTracker::new(100);
        let mut f = ElbowFeatureTracker::new().with_max_hold_ticks(3);
        set_left(&mut pose, 60.0, 0);
        f.step(&pose, 0);
        let mut now = 1000;
        for _ in 0..3 {
            assert!(f.step(&pose, now).left_avg.is_some());
            now += 20;
        }
        assert_eq!(f.step(&pose, now).left_avg, None);
        set_left(&mut pose, 150.0, now);
        // Re-initialised from the new sample, not blended with the old 60°.
        let avg = f.step(&pose, now).left_avg.unwrap();
        assert!((avg - 150.0).abs() < 1e-9, "{avg}");
        let avg = f.step(&pose, now + 20).left_avg.unwrap();
        assert!((avg - 150.0).abs() < 1e-9, "{avg}");
    }
}
