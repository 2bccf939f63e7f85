//! The skeleton ingest actor: the newest body pose, for the gesture-command experiment.
//!
//! This first version publishes "no pose" (an empty [`PoseTracker`]): every elbow angle is then invalid,
//! which learning and gating handle explicitly. The OSC/UDP receiver replaces it without changing the
//! interface: a `watch` channel holding the newest pose with each joint's receipt time.

use pavlov::skeleton::PoseTracker;
use tokio::sync::watch;

/// How old a joint may be before it counts as missing, ms (three frames at 30 Hz).
pub const MAX_JOINT_AGE_MS: u64 = 100;

/// A pose channel that never receives a skeleton.
pub fn no_pose() -> (watch::Sender<PoseTracker>, watch::Receiver<PoseTracker>) {
    watch::channel(PoseTracker::new(MAX_JOINT_AGE_MS))
}
