//! Body skeletons for the gesture-command experiment (Modayil & Sutton, "Reducing Lag By Predicting the Next
//! Command"): joint names as the skeleton streamers spell them, the newest position of each joint with its age,
//! the interior elbow angle, its exponentially weighted moving average, and the per-tick elbow features with the
//! stimulus `E = 𝕀{LeftElbow < 90°}`.
//!
//! Conventions used throughout:
//! - The elbow angle is the *interior* angle at the elbow between the upper arm (elbow→shoulder) and the forearm
//!   (elbow→hand): 180° is a straight arm, 90° a right angle, small angles a tightly bent arm. "Bent past 90°"
//!   means this angle is below 90°.
//! - An angle that cannot be computed (missing, stale, low-confidence or non-finite joint, zero-length segment)
//!   is *invalid*, never 0.
//! - Positions are Cartesian in any unit (mm from OSCeleton raw mode, metres from Kinect v2); angles are
//!   scale-free. Do not compute angles from OSCeleton's default normalized coordinates; undo them first with
//!   [`osceleton_normalized_to_mm`].

mod ewma;
mod features;
mod geometry;
mod joint;
mod pose;

pub use ewma::Ewma;
pub use features::{ElbowFeatureTracker, ElbowFeatures};
pub use geometry::{
    COMMAND_THRESHOLD_DEG, elbow_angle_deg, mm_to_osceleton_normalized, osceleton_normalized_to_mm,
};
pub use joint::{Joint, Side};
pub use pose::{ElbowAngle, InvalidReason, JointSample, PoseTracker, SkeletonStatus};
