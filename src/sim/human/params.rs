//! Parameters of the simulated human operator, each with the reasoning behind its default.
//!
//! Ranges are `[lo, hi]` and drawn uniformly per gesture. Nothing here was tuned against a learning result;
//! the values come from body dimensions, motor-control findings on voluntary arm movements, and what the
//! real OSCeleton and Kinect v2 recordings show (30 frames a second, frame gaps, dropped joints;
//! [OSCeleton], [Kinectron] in `docs/SOURCES.md`).

use serde::{Deserialize, Serialize};

/// Everything that shapes the simulated operator's body, gestures and sensor artefacts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct HumanParams {
    /// Sensor frame rate. OpenNI/NiTE (which the paper's Xtion Pro used through OSCeleton) runs at 30 fps;
    /// real OSCeleton recordings average a 33.1 ms frame interval.
    pub frame_rate_hz: f64,
    /// The user id OSCeleton would report (small integers, reused).
    pub user_id: i32,

    /// Distance from the sensor to the person's neck along the optical axis (z), mm. The paper's operator stood
    /// in front of a stationary sensor; 2–3 m is where NiTE tracks a whole standing body reliably.
    pub distance_mm: f64,
    /// Height of the neck joint above the sensor's optical axis (y), mm: a ~1.45 m neck with the sensor on a
    /// ~0.85 m table.
    pub neck_height_mm: f64,
    /// Half the distance between the shoulder joints, mm (adult biacromial breadth ≈ 360–410 mm).
    pub shoulder_half_width_mm: f64,
    /// Shoulder-to-elbow length, mm. NiTE's upper arm measured 199–425 mm (mean 299) in a real recording.
    pub upper_arm_mm: f64,
    /// Elbow-to-wrist length, mm (adult forearm ≈ 240–280 mm).
    pub forearm_mm: f64,
    /// Wrist-to-hand-joint length, mm: NiTE's "hand" is the palm centre, about 80 mm beyond the wrist.
    pub hand_offset_mm: f64,
    /// Emit wrist joints. NiTE (OSCeleton) never sends wrists, Kinect v2 does; on by default so the
    /// hand→wrist fallback is exercised. Turn off for an exact NiTE-15 joint set.
    pub include_wrists: bool,
    /// Abduction of each upper arm away from the body at rest, degrees (relaxed arms hang slightly out).
    pub upper_arm_abduction_deg: [f64; 2],

    /// Mean interior elbow angle of a relaxed hanging arm, degrees. A relaxed arm is not fully straight:
    /// resting elbow flexion is roughly 10–25°, i.e. an interior angle of about 155–170°.
    pub rest_elbow_deg: f64,
    /// Standard deviation of the slow drift of the resting angle, degrees.
    pub rest_elbow_sd_deg: f64,
    /// Time constant of that drift (an Ornstein–Uhlenbeck process), seconds.
    pub rest_drift_tau_s: f64,
    /// The resting angle is kept within this band, degrees (always well above 90°).
    pub rest_elbow_limits_deg: [f64; 2],

    /// Delay before the first left-arm gesture, seconds.
    pub first_gesture_after_s: [f64; 2],
    /// Minimum pause between the end of one left-arm gesture and the start of the next, seconds: the operator
    /// watches the robot spin before commanding again.
    pub gap_min_s: f64,
    /// Mean of the exponentially distributed extra pause on top of `gap_min_s`, seconds. With the defaults a
    /// gesture starts every ~8.6 s (≈ 7 a minute, ≈ 5.6 of them commands), comparable to the paper's "last 40
    /// commands" of a run under 10 minutes.
    pub gap_extra_mean_s: f64,
    /// Upper bound on one pause, seconds.
    pub gap_max_s: f64,
    /// Fraction of left-arm gestures that are partial bends stopping short of 90° (not commands).
    pub partial_fraction: f64,
    /// Smallest interior angle reached by a command gesture, degrees (well past 90° so the command is clear).
    pub command_min_deg: [f64; 2],
    /// Smallest interior angle reached by a partial bend, degrees. Kept ≥ 105° so that sensor noise (a few
    /// degrees of angle) rarely makes a partial bend look like a command.
    pub partial_min_deg: [f64; 2],
    /// Duration of the bend from rest to the smallest angle, seconds. Self-paced single-joint elbow flexions
    /// of 90–110° take roughly 0.5–1 s at comfortable speed (point-to-point movements follow a smooth,
    /// bell-shaped velocity profile, Flash & Hogan 1985); a deliberate signalling gesture is at the slower end.
    /// With a minimum-jerk profile the 90° crossing falls 55–65% of the way through the bend, i.e. the arm has
    /// been visibly bending for 0.33–0.8 s before the command registers: the lead the prediction can exploit.
    pub bend_s: [f64; 2],
    /// How long the bent pose is held, seconds: the command is "spin while my arm is bent".
    pub hold_s: [f64; 2],
    /// Duration of the return to rest, seconds (releasing the arm is a little quicker than raising it).
    pub return_s: [f64; 2],
    /// Forward flexion of the upper arm at the bent pose, degrees: people lift the elbow a little while bending.
    pub shoulder_flex_deg: [f64; 2],
    /// Sideways yaw of the forearm's swing plane at the bent pose, degrees (the hand drifts in or out).
    pub forearm_yaw_deg: [f64; 2],

    /// Right arm: minimum pause between movements, seconds.
    pub right_gap_min_s: f64,
    /// Right arm: mean extra pause (exponential), seconds. The right arm moves now and then (scratching,
    /// gesturing) and is never a command in the left-spin experiment.
    pub right_gap_extra_mean_s: f64,
    /// Right arm: smallest angle of a movement, degrees. Spans both sides of 90° on purpose: a right bend past
    /// 90° must not be mistaken for the left command.
    pub right_min_deg: [f64; 2],

    /// Standard deviation of the whole body's postural sway, mm (standing sway is about 1–2 cm).
    pub sway_sd_mm: f64,
    /// Time constant of the sway, seconds.
    pub sway_tau_s: f64,

    /// Per-axis Gaussian noise on every reported joint (x, y, z), mm. Depth noise at 2.5 m is larger than
    /// lateral noise; skeleton jitter of a few mm to a couple of cm is typical of NiTE / Kinect trackers.
    pub noise_sd_mm: [f64; 3],
    /// Long-run fraction of frames in which each arm joint (elbow, wrist, hand) is missing. OSCeleton leaves
    /// out joints with confidence < 0.5; in a real recording l_elbow and l_hand were each missing in ~15% of
    /// frames, part of which was calibration. 5% per joint gives ≈ 10% of frames missing the left elbow or hand.
    pub arm_drop_rate: f64,
    /// Long-run fraction of frames in which each other joint (head, torso, shoulders, legs) is missing.
    pub body_drop_rate: f64,
    /// Mean length of a dropout burst, frames: tracking loss lasts a few frames rather than single frames.
    pub drop_burst_frames: f64,
}

impl Default for HumanParams {
    fn default() -> Self {
        HumanParams {
            frame_rate_hz: 30.0,
            user_id: 1,
            distance_mm: 2500.0,
            neck_height_mm: 600.0,
            shoulder_half_width_mm: 190.0,
            upper_arm_mm: 300.0,
            forearm_mm: 255.0,
            hand_offset_mm: 80.0,
            include_wrists: true,
            upper_arm_abduction_deg: [5.0, 15.0],
            rest_elbow_deg: 160.0,
            rest_elbow_sd_deg: 4.0,
            rest_drift_tau_s: 3.0,
            rest_elbow_limits_deg: [145.0, 175.0],
            first_gesture_after_s: [1.0, 4.0],
            gap_min_s: 2.5,
            gap_extra_mean_s: 3.5,
            gap_max_s: 20.0,
            partial_fraction: 0.2,
            command_min_deg: [50.0, 70.0],
            partial_min_deg: [105.0, 140.0],
            bend_s: [0.6, 1.2],
            hold_s: [0.4, 1.5],
            return_s: [0.5, 1.0],
            shoulder_flex_deg: [0.0, 20.0],
            forearm_yaw_deg: [-20.0, 20.0],
            right_gap_min_s: 3.0,
            right_gap_extra_mean_s: 9.0,
            right_min_deg: [40.0, 150.0],
            sway_sd_mm: 12.0,
            sway_tau_s: 2.0,
            noise_sd_mm: [6.0, 6.0, 12.0],
            arm_drop_rate: 0.05,
            body_drop_rate: 0.01,
            drop_burst_frames: 3.0,
        }
    }
}

/// A parameter set that cannot describe a sensible operator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HumanParamsError {
    /// A value is NaN or infinite, or negative where it must not be.
    #[error("parameter `{0}` must be finite and non-negative")]
    NotFiniteOrNegative(&'static str),
    /// A `[lo, hi]` range has `lo > hi`.
    #[error("range `{0}` has lo > hi")]
    ReversedRange(&'static str),
    /// A fraction or rate is outside `[0, 1)`.
    #[error("rate `{0}` must be in [0, 1)")]
    RateOutOfRange(&'static str),
    /// Gesture angles are on the wrong side of 90° (commands must end below it, partial bends and rest above it).
    #[error("angle parameter `{0}` is on the wrong side of 90 degrees")]
    WrongSideOfThreshold(&'static str),
    /// A rate, length or duration that must be positive is zero.
    #[error("parameter `{0}` must be positive")]
    NotPositive(&'static str),
}

impl HumanParams {
    /// Check the set. [`super::SimHuman::new`] never panics on a bad set, but its ground truth is only
    /// meaningful for a set that passes this check.
    pub fn validate(&self) -> Result<(), HumanParamsError> {
        use HumanParamsError as E;
        let scalars = [
            ("frame_rate_hz", self.frame_rate_hz),
            ("distance_mm", self.distance_mm),
            ("shoulder_half_width_mm", self.shoulder_half_width_mm),
            ("upper_arm_mm", self.upper_arm_mm),
            ("forearm_mm", self.forearm_mm),
            ("hand_offset_mm", self.hand_offset_mm),
            ("rest_elbow_sd_deg", self.rest_elbow_sd_deg),
            ("rest_drift_tau_s", self.rest_drift_tau_s),
            ("gap_min_s", self.gap_min_s),
            ("gap_extra_mean_s", self.gap_extra_mean_s),
            ("gap_max_s", self.gap_max_s),
            ("right_gap_min_s", self.right_gap_min_s),
            ("right_gap_extra_mean_s", self.right_gap_extra_mean_s),
            ("sway_sd_mm", self.sway_sd_mm),
            ("sway_tau_s", self.sway_tau_s),
            ("drop_burst_frames", self.drop_burst_frames),
            ("noise_sd_x", self.noise_sd_mm[0]),
            ("noise_sd_y", self.noise_sd_mm[1]),
            ("noise_sd_z", self.noise_sd_mm[2]),
        ];
        for (name, v) in scalars {
            if !v.is_finite() || v < 0.0 {
                return Err(E::NotFiniteOrNegative(name));
            }
        }
        if !self.neck_height_mm.is_finite() || !self.rest_elbow_deg.is_finite() {
            return Err(E::NotFiniteOrNegative("neck_height_mm/rest_elbow_deg"));
        }
        for (name, v) in [
            ("frame_rate_hz", self.frame_rate_hz),
            ("upper_arm_mm", self.upper_arm_mm),
            ("forearm_mm", self.forearm_mm),
            ("rest_drift_tau_s", self.rest_drift_tau_s),
            ("sway_tau_s", self.sway_tau_s),
        ] {
            if v == 0.0 {
                return Err(E::NotPositive(name));
            }
        }
        if self.drop_burst_frames < 1.0 {
            return Err(E::NotPositive("drop_burst_frames (>= 1)"));
        }
        let ranges = [
            ("upper_arm_abduction_deg", self.upper_arm_abduction_deg),
            ("rest_elbow_limits_deg", self.rest_elbow_limits_deg),
            ("first_gesture_after_s", self.first_gesture_after_s),
            ("command_min_deg", self.command_min_deg),
            ("partial_min_deg", self.partial_min_deg),
            ("bend_s", self.bend_s),
            ("hold_s", self.hold_s),
            ("return_s", self.return_s),
            ("shoulder_flex_deg", self.shoulder_flex_deg),
            ("forearm_yaw_deg", self.forearm_yaw_deg),
            ("right_min_deg", self.right_min_deg),
        ];
        for (name, [lo, hi]) in ranges {
            if !lo.is_finite() || !hi.is_finite() {
                return Err(E::NotFiniteOrNegative(name));
            }
            if lo > hi {
                return Err(E::ReversedRange(name));
            }
        }
        for (name, [lo, _]) in [
            ("bend_s", self.bend_s),
            ("return_s", self.return_s),
            ("hold_s", self.hold_s),
        ] {
            if lo <= 0.0 {
                return Err(E::NotPositive(name));
            }
        }
        for (name, r) in [
            ("partial_fraction", self.partial_fraction),
            ("arm_drop_rate", self.arm_drop_rate),
            ("body_drop_rate", self.body_drop_rate),
        ] {
            if !(0.0..1.0).contains(&r) {
                return Err(E::RateOutOfRange(name));
            }
        }
        if self.command_min_deg[1] >= 90.0 {
            return Err(E::WrongSideOfThreshold("command_min_deg"));
        }
        if self.partial_min_deg[0] <= 90.0 {
            return Err(E::WrongSideOfThreshold("partial_min_deg"));
        }
        if self.rest_elbow_limits_deg[0] <= self.partial_min_deg[1]
            || self.rest_elbow_limits_deg[1] > 180.0
        {
            return Err(E::WrongSideOfThreshold("rest_elbow_limits_deg"));
        }
        Ok(())
    }

    /// Duration of one sensor frame, ms.
    pub fn frame_period_ms(&self) -> f64 {
        1000.0 / self.frame_rate_hz
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        assert_eq!(HumanParams::default().validate(), Ok(()));
        assert!((HumanParams::default().frame_period_ms() - 1000.0 / 30.0).abs() < 1e-12);
    }

    #[test]
    fn bad_sets_are_rejected() {
        let bad = |f: fn(&mut HumanParams)| {
            let mut p = HumanParams::default();
            f(&mut p);
            p.validate()
        };
        assert!(matches!(
            bad(|p| p.frame_rate_hz = 0.0),
            Err(HumanParamsError::NotPositive(_))
        ));
        assert!(matches!(
            bad(|p| p.distance_mm = f64::NAN),
            Err(HumanParamsError::NotFiniteOrNegative(_))
        ));
        assert!(matches!(
            bad(|p| p.bend_s = [1.2, 0.6]),
            Err(HumanParamsError::ReversedRange(_))
        ));
        assert!(matches!(
            bad(|p| p.arm_drop_rate = 1.0),
            Err(HumanParamsError::RateOutOfRange(_))
        ));
        assert!(matches!(
            bad(|p| p.command_min_deg = [60.0, 95.0]),
            Err(HumanParamsError::WrongSideOfThreshold(_))
        ));
        assert!(matches!(
            bad(|p| p.partial_min_deg = [85.0, 120.0]),
            Err(HumanParamsError::WrongSideOfThreshold(_))
        ));
    }

    #[test]
    fn partial_toml_fills_in_defaults() {
        let p: HumanParams =
            toml::from_str("partial_fraction = 0.25\nbend_s = [0.7, 1.0]").unwrap();
        assert_eq!(p.partial_fraction, 0.25);
        assert_eq!(p.bend_s, [0.7, 1.0]);
        assert_eq!(p.distance_mm, HumanParams::default().distance_mm);
    }
}
