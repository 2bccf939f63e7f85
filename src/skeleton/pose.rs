//! The newest position of every joint with its receipt time, and the elbow angle computed from it.
//!
//! Skeleton streamers run at about 30 fps, drop joints whose confidence is low, and sometimes stop sending
//! altogether, while control runs at 50 Hz. The tracker therefore holds each joint's newest sample and reports a
//! joint as unusable once it is older than `max_age_ms`; an angle built from an unusable joint is
//! [`ElbowAngle::Invalid`] with the reason, never 0.

use serde::{Deserialize, Serialize};

use super::geometry::elbow_angle_deg;
use super::joint::{Joint, Side};

/// One received joint position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct JointSample {
    /// Position in the sensor's Cartesian frame (mm for OSCeleton raw mode; any unit works for angles).
    pub pos_mm: [f64; 3],
    /// Host time at which the sample was received, in milliseconds.
    pub at_ms: u64,
    /// Tracker confidence in `[0, 1]` (OSCeleton sends only joints ≥ 0.5; Kinect v2 Tracked = 1, Inferred = 0.5).
    pub confidence: f32,
}

/// Why a joint or an angle could not be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, thiserror::Error)]
pub enum InvalidReason {
    /// No sample of this joint since the tracker was created or cleared.
    #[error("joint {0:?} has never been received")]
    MissingJoint(Joint),
    /// The newest sample is older than the tracker's age limit.
    #[error("joint {0:?} is stale")]
    Stale(Joint),
    /// The newest sample has a NaN or infinite coordinate.
    #[error("joint {0:?} has a non-finite coordinate")]
    NotFinite(Joint),
    /// The newest sample is exactly (0, 0, 0), the placeholder some trackers emit instead of a position.
    #[error("joint {0:?} is at the exact origin (tracker placeholder)")]
    AtOrigin(Joint),
    /// The newest sample's confidence is below the tracker's minimum (or is NaN).
    #[error("joint {0:?} has low confidence")]
    LowConfidence(Joint),
    /// Upper arm or forearm has zero length, so the angle is undefined.
    #[error("zero-length arm segment")]
    Degenerate,
}

/// An elbow angle, or why there is none.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum ElbowAngle {
    /// Interior angle in degrees: 180 = straight arm, below 90 = bent past a right angle.
    Valid(f64),
    /// The angle could not be computed.
    Invalid(InvalidReason),
}

impl ElbowAngle {
    /// The angle in degrees when valid.
    pub fn value(self) -> Option<f64> {
        match self {
            ElbowAngle::Valid(deg) => Some(deg),
            ElbowAngle::Invalid(_) => None,
        }
    }

    /// Whether the angle is valid.
    pub fn is_valid(self) -> bool {
        matches!(self, ElbowAngle::Valid(_))
    }
}

/// Whether a skeleton is coming in, for the dashboard's warning.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkeletonStatus {
    /// A joint of the selected person arrived within the age limit.
    Tracked,
    /// Joints are held, but the newest is older than the age limit (the stream stopped, or the person
    /// stands still out of view).
    Stale,
    /// No joint at all: nobody selected yet, or the person was lost.
    #[default]
    #[serde(rename = "none")]
    Absent,
}

/// Holds the newest sample of each joint and judges whether it is still usable.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseTracker {
    samples: [Option<JointSample>; Joint::COUNT],
    max_age_ms: u64,
    min_confidence: f32,
}

impl PoseTracker {
    /// A tracker that treats a joint as stale once its newest sample is more than `max_age_ms` old.
    /// The default minimum confidence is 0: every received sample counts (the streamers already drop
    /// low-confidence joints); raise it with [`PoseTracker::with_min_confidence`].
    pub fn new(max_age_ms: u64) -> Self {
        PoseTracker {
            samples: [None; Joint::COUNT],
            max_age_ms,
            min_confidence: 0.0,
        }
    }

    /// The same tracker, rejecting samples whose confidence is below `min_confidence` (NaN is always rejected).
    pub fn with_min_confidence(mut self, min_confidence: f32) -> Self {
        self.min_confidence = min_confidence;
        self
    }

    /// The age limit in milliseconds.
    pub fn max_age_ms(&self) -> u64 {
        self.max_age_ms
    }

    /// Record a sample. A sample older than the one already held for this joint (earlier `at_ms`) is ignored,
    /// so the tracker always keeps the newest; equal times replace.
    pub fn update(&mut self, joint: Joint, sample: JointSample) {
        let slot = &mut self.samples[joint.index()];
        if slot.is_none_or(|held| held.at_ms <= sample.at_ms) {
            *slot = Some(sample);
        }
    }

    /// Forget every joint (call on user lost / new skeleton / user switch).
    pub fn clear(&mut self) {
        self.samples = [None; Joint::COUNT];
    }

    /// The newest raw sample of `joint`, whatever its age or quality.
    pub fn sample(&self, joint: Joint) -> Option<&JointSample> {
        self.samples[joint.index()].as_ref()
    }

    /// Whether a skeleton is coming in at `now_ms`: tracked when the newest joint is within the age limit,
    /// stale when joints are held but all older, none without any joint.
    pub fn status(&self, now_ms: u64) -> SkeletonStatus {
        match self.samples.iter().flatten().map(|s| s.at_ms).max() {
            None => SkeletonStatus::Absent,
            Some(at) if now_ms.saturating_sub(at) <= self.max_age_ms => SkeletonStatus::Tracked,
            Some(_) => SkeletonStatus::Stale,
        }
    }

    /// Milliseconds since the newest sample of `joint` was received (0 if it is stamped after `now_ms`).
    pub fn age_ms(&self, joint: Joint, now_ms: u64) -> Option<u64> {
        self.sample(joint).map(|s| now_ms.saturating_sub(s.at_ms))
    }

    /// The usable position of `joint` at `now_ms`, or why it is unusable.
    pub fn joint_checked(&self, joint: Joint, now_ms: u64) -> Result<[f64; 3], InvalidReason> {
        let s = self
            .sample(joint)
            .ok_or(InvalidReason::MissingJoint(joint))?;
        if now_ms.saturating_sub(s.at_ms) > self.max_age_ms {
            return Err(InvalidReason::Stale(joint));
        }
        if !s.pos_mm.iter().all(|c| c.is_finite()) {
            return Err(InvalidReason::NotFinite(joint));
        }
        if s.pos_mm == [0.0; 3] {
            return Err(InvalidReason::AtOrigin(joint));
        }
        if s.confidence.is_nan() || s.confidence < self.min_confidence {
            return Err(InvalidReason::LowConfidence(joint));
        }
        Ok(s.pos_mm)
    }

    /// The usable position of `joint` at `now_ms`: `None` when missing, stale, not finite, at the origin or
    /// below the minimum confidence.
    pub fn joint(&self, j: Joint, now_ms: u64) -> Option<[f64; 3]> {
        self.joint_checked(j, now_ms).ok()
    }

    /// The interior elbow angle on `side` at `now_ms`. Uses shoulder, elbow and hand; when the hand is
    /// unusable the wrist stands in for it, and when both are unusable the hand's reason is reported.
    pub fn elbow_angle(&self, side: Side, now_ms: u64) -> ElbowAngle {
        match self.elbow_angle_checked(side, now_ms) {
            Ok(deg) => ElbowAngle::Valid(deg),
            Err(reason) => ElbowAngle::Invalid(reason),
        }
    }

    fn elbow_angle_checked(&self, side: Side, now_ms: u64) -> Result<f64, InvalidReason> {
        let shoulder = self.joint_checked(Joint::shoulder(side), now_ms)?;
        let elbow = self.joint_checked(Joint::elbow(side), now_ms)?;
        let hand = self
            .joint_checked(Joint::hand(side), now_ms)
            .or_else(|hand_reason| {
                self.joint_checked(Joint::wrist(side), now_ms)
                    .map_err(|_| hand_reason)
            })?;
        elbow_angle_deg(shoulder, elbow, hand).ok_or(InvalidReason::Degenerate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(pos: [f64; 3], at_ms: u64) -> JointSample {
        JointSample {
            pos_mm: pos,
            at_ms,
            confidence: 1.0,
        }
    }

    /// A left arm bent to exactly 90°, all samples received at `t`.
    fn right_angle_left_arm(p: &mut PoseTracker, t: u64) {
        p.update(Joint::LeftShoulder, at([-190.0, 600.0, 2500.0], t));
        p.update(Joint::LeftElbow, at([-190.0, 300.0, 2500.0], t));
        p.update(Joint::LeftHand, at([-190.0, 300.0, 2200.0], t));
    }

    #[test]
    fn fresh_joints_give_a_valid_angle() {
        let mut p = PoseTracker::new(100);
        right_angle_left_arm(&mut p, 1000);
        let a = p.elbow_angle(Side::Left, 1050).value().unwrap();
        assert!((a - 90.0).abs() < 1e-9);
        assert_eq!(p.age_ms(Joint::LeftElbow, 1050), Some(50));
    }

    #[test]
    fn missing_joint_is_invalid_not_zero() {
        let mut p = PoseTracker::new(100);
        p.update(Joint::LeftShoulder, at([-190.0, 600.0, 2500.0], 0));
        p.update(Joint::LeftHand, at([-190.0, 300.0, 2200.0], 0));
        assert_eq!(
            p.elbow_angle(Side::Left, 10),
            ElbowAngle::Invalid(InvalidReason::MissingJoint(Joint::LeftElbow))
        );
        assert_eq!(p.elbow_angle(Side::Left, 10).value(), None);
        assert_eq!(p.joint(Joint::LeftElbow, 10), None);
        // The other arm was never seen at all.
        assert_eq!(
            p.elbow_angle(Side::Right, 10),
            ElbowAngle::Invalid(InvalidReason::MissingJoint(Joint::RightShoulder))
        );
    }

    #[test]
    fn stale_joint_is_invalid_exactly_after_the_age_limit() {
        let mut p = PoseTracker::new(100);
        right_angle_left_arm(&mut p, 1000);
        assert!(p.elbow_angle(Side::Left, 1100).is_valid());
        p.update(Joint::LeftShoulder, at([-190.0, 600.0, 2500.0], 1050));
        p.update(Joint::LeftHand, at([-190.0, 300.0, 2200.0], 1050));
        assert_eq!(
            p.elbow_angle(Side::Left, 1101),
            ElbowAngle::Invalid(InvalidReason::Stale(Joint::LeftElbow))
        );
        assert_eq!(
            p.joint(Joint::LeftShoulder, 1101),
            Some([-190.0, 600.0, 2500.0])
        );
    }

    #[test]
    fn non_finite_origin_and_low_confidence_are_invalid() {
        let mut p = PoseTracker::new(100).with_min_confidence(0.5);
        right_angle_left_arm(&mut p, 0);
        p.update(Joint::LeftElbow, at([f64::NAN, 300.0, 2500.0], 1));
        assert_eq!(
            p.elbow_angle(Side::Left, 2),
            ElbowAngle::Invalid(InvalidReason::NotFinite(Joint::LeftElbow))
        );
        p.update(Joint::LeftElbow, at([0.0; 3], 2));
        assert_eq!(
            p.elbow_angle(Side::Left, 2),
            ElbowAngle::Invalid(InvalidReason::AtOrigin(Joint::LeftElbow))
        );
        let mut weak = at([-190.0, 300.0, 2500.0], 3);
        weak.confidence = 0.3;
        p.update(Joint::LeftElbow, weak);
        assert_eq!(
            p.elbow_angle(Side::Left, 3),
            ElbowAngle::Invalid(InvalidReason::LowConfidence(Joint::LeftElbow))
        );
        weak.confidence = f32::NAN;
        p.update(Joint::LeftElbow, weak);
        assert_eq!(p.joint(Joint::LeftElbow, 3), None);
    }

    #[test]
    fn wrist_stands_in_for_a_missing_hand() {
        let mut p = PoseTracker::new(100);
        p.update(Joint::RightShoulder, at([190.0, 600.0, 2500.0], 0));
        p.update(Joint::RightElbow, at([190.0, 300.0, 2500.0], 0));
        p.update(Joint::RightWrist, at([190.0, 50.0, 2500.0], 0));
        let a = p.elbow_angle(Side::Right, 0).value().unwrap();
        assert!((a - 180.0).abs() < 1e-9);
        // A fresh hand takes precedence over the wrist.
        p.update(Joint::RightHand, at([190.0, 300.0, 2200.0], 0));
        let a = p.elbow_angle(Side::Right, 0).value().unwrap();
        assert!((a - 90.0).abs() < 1e-9);
        // When both are gone the hand's reason is reported.
        let mut q = PoseTracker::new(100);
        q.update(Joint::RightShoulder, at([190.0, 600.0, 2500.0], 0));
        q.update(Joint::RightElbow, at([190.0, 300.0, 2500.0], 0));
        assert_eq!(
            q.elbow_angle(Side::Right, 0),
            ElbowAngle::Invalid(InvalidReason::MissingJoint(Joint::RightHand))
        );
    }

    #[test]
    fn zero_length_segment_is_degenerate() {
        let mut p = PoseTracker::new(100);
        p.update(Joint::LeftShoulder, at([-190.0, 300.0, 2500.0], 0));
        p.update(Joint::LeftElbow, at([-190.0, 300.0, 2500.0], 0));
        p.update(Joint::LeftHand, at([-190.0, 0.0, 2500.0], 0));
        assert_eq!(
            p.elbow_angle(Side::Left, 0),
            ElbowAngle::Invalid(InvalidReason::Degenerate)
        );
    }

    #[test]
    fn older_samples_do_not_replace_newer_and_clear_forgets() {
        let mut p = PoseTracker::new(100);
        p.update(Joint::Head, at([1.0, 2.0, 3.0], 500));
        p.update(Joint::Head, at([9.0, 9.0, 9.0], 400));
        assert_eq!(p.joint(Joint::Head, 500), Some([1.0, 2.0, 3.0]));
        p.update(Joint::Head, at([4.0, 5.0, 6.0], 500));
        assert_eq!(p.joint(Joint::Head, 500), Some([4.0, 5.0, 6.0]));
        p.clear();
        assert_eq!(p.sample(Joint::Head), None);
        assert_eq!(p.age_ms(Joint::Head, 500), None);
    }

    #[test]
    fn status_is_none_then_tracked_then_stale_and_none_again_when_cleared() {
        let mut p = PoseTracker::new(100);
        assert_eq!(p.status(0), SkeletonStatus::Absent);
        p.update(
            Joint::Head,
            JointSample {
                pos_mm: [1.0, 2.0, 3.0],
                at_ms: 50,
                confidence: 1.0,
            },
        );
        assert_eq!(p.status(150), SkeletonStatus::Tracked);
        assert_eq!(p.status(151), SkeletonStatus::Stale);
        p.clear();
        assert_eq!(p.status(151), SkeletonStatus::Absent);
    }
}
