//! Pure user selection: which one person's joints reach the pose.
//!
//! The rule:
//! 1. While a user is selected and has been heard from (any joint) within `silence_ms`, only that user's
//!    joints are used; other users' joints are counted and dropped.
//! 2. With no user selected, or once the selected user has been silent for more than `silence_ms`, the first
//!    user that sends an elbow (left or right, after `swap_lr`) becomes the selected user and the pose is
//!    cleared, so no joint of the previous person survives.
//! 3. `/lost_user` of the selected user drops the selection and clears the pose; `/new_skel` of the selected
//!    user clears the pose (a new calibration); `/new_user` changes nothing.
//!
//! Selection looks at a whole datagram first ([`UserSelector::apply_all`]): when a bundle holds an elbow of a
//! user that may be selected, that user is selected before any of the bundle's events is applied, so the
//! joints that precede the elbow in the same bundle are kept. With unbundled messages (KinectV2-OSC), joints
//! that arrive before the first elbow are dropped and used from the next frame on.

use pavlov::skeleton::{Joint, JointSample, PoseTracker};

use super::decode::{SkeletonEvent, UserId};

/// How long the selected user may be silent before another user can take over, ms.
pub(crate) const DEFAULT_SILENCE_MS: u64 = 1000;

/// What applying an event did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Applied {
    /// A joint of the selected user went into the pose.
    JointUsed,
    /// A joint of another (or not yet selected) user was dropped.
    OtherUser,
    /// `user` became the selected user (the pose was cleared and the joint used).
    Selected(UserId),
    /// The selected user was lost (the pose was cleared).
    Lost(UserId),
    /// The selected user's skeleton restarted (the pose was cleared).
    Restarted(UserId),
    /// Nothing changed.
    Nothing,
}

/// The selection state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct UserSelector {
    current: Option<UserId>,
    last_heard_ms: u64,
    silence_ms: u64,
}

impl UserSelector {
    /// No user selected; a selected user may be silent for `silence_ms` before being replaced.
    pub(crate) fn new(silence_ms: u64) -> Self {
        UserSelector {
            current: None,
            last_heard_ms: 0,
            silence_ms,
        }
    }

    /// The selected user.
    pub(crate) fn current(&self) -> Option<UserId> {
        self.current
    }

    fn vacant(&self, now_ms: u64) -> bool {
        self.current.is_none() || now_ms.saturating_sub(self.last_heard_ms) > self.silence_ms
    }

    /// Apply the events of one datagram received at `now_ms`: first select the user of the first elbow among
    /// them when the selection is vacant, then apply each event. Returns what each step did.
    pub(crate) fn apply_all(
        &mut self,
        events: &[SkeletonEvent],
        now_ms: u64,
        pose: &mut PoseTracker,
    ) -> Vec<Applied> {
        let mut done = Vec::with_capacity(events.len() + 1);
        if self.vacant(now_ms) {
            let first_elbow = events.iter().find_map(|e| match *e {
                SkeletonEvent::Joint { user, joint, .. } if is_elbow(joint) => Some(user),
                _ => None,
            });
            if let Some(user) = first_elbow.filter(|&u| self.current != Some(u)) {
                self.select(user, now_ms, pose);
                done.push(Applied::Selected(user));
            }
        }
        done.extend(events.iter().map(|&e| self.apply(e, now_ms, pose)));
        done
    }

    fn select(&mut self, user: UserId, now_ms: u64, pose: &mut PoseTracker) {
        self.current = Some(user);
        self.last_heard_ms = now_ms;
        pose.clear();
    }

    /// Apply one event received at `now_ms`, updating `pose`.
    pub(crate) fn apply(
        &mut self,
        event: SkeletonEvent,
        now_ms: u64,
        pose: &mut PoseTracker,
    ) -> Applied {
        match event {
            SkeletonEvent::Joint {
                user,
                joint,
                pos_mm,
                confidence,
            } => {
                let sample = JointSample {
                    pos_mm,
                    at_ms: now_ms,
                    confidence,
                };
                if self.current == Some(user) {
                    self.last_heard_ms = now_ms;
                    pose.update(joint, sample);
                    return Applied::JointUsed;
                }
                if self.vacant(now_ms) && is_elbow(joint) {
                    self.select(user, now_ms, pose);
                    pose.update(joint, sample);
                    Applied::Selected(user)
                } else {
                    Applied::OtherUser
                }
            }
            SkeletonEvent::LostUser(user) if self.current == Some(user) => {
                self.current = None;
                pose.clear();
                Applied::Lost(user)
            }
            SkeletonEvent::NewSkeleton(user) if self.current == Some(user) => {
                self.last_heard_ms = now_ms;
                pose.clear();
                Applied::Restarted(user)
            }
            SkeletonEvent::LostUser(_)
            | SkeletonEvent::NewSkeleton(_)
            | SkeletonEvent::NewUser(_) => Applied::Nothing,
        }
    }
}

fn is_elbow(joint: Joint) -> bool {
    matches!(joint, Joint::LeftElbow | Joint::RightElbow)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(user: UserId, joint: Joint, x: f64) -> SkeletonEvent {
        SkeletonEvent::Joint {
            user,
            joint,
            pos_mm: [x, 1.0, 2.0],
            confidence: 1.0,
        }
    }

    #[test]
    fn first_user_with_an_elbow_is_selected_and_others_are_dropped() {
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        // A head before any elbow selects no one.
        assert_eq!(
            s.apply(joint(3, Joint::Head, 1.0), 0, &mut pose),
            Applied::OtherUser
        );
        assert_eq!(pose.sample(Joint::Head), None);
        assert_eq!(
            s.apply(joint(3, Joint::LeftElbow, 1.0), 10, &mut pose),
            Applied::Selected(3)
        );
        assert_eq!(
            s.apply(joint(3, Joint::Head, 5.0), 10, &mut pose),
            Applied::JointUsed
        );
        assert_eq!(
            s.apply(joint(4, Joint::LeftElbow, 9.0), 20, &mut pose),
            Applied::OtherUser
        );
        assert_eq!(
            pose.sample(Joint::LeftElbow).map(|j| j.pos_mm[0]),
            Some(1.0)
        );
        assert_eq!(pose.sample(Joint::Head).map(|j| j.at_ms), Some(10));
        assert_eq!(s.current(), Some(3));
    }

    #[test]
    fn a_bundle_with_an_elbow_selects_its_user_before_its_first_joint() {
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        let frame = [
            joint(2, Joint::LeftShoulder, 1.0),
            joint(9, Joint::Head, 1.0),
            joint(2, Joint::LeftElbow, 2.0),
        ];
        let done = s.apply_all(&frame, 0, &mut pose);
        assert_eq!(
            done,
            vec![
                Applied::Selected(2),
                Applied::JointUsed,
                Applied::OtherUser,
                Applied::JointUsed
            ]
        );
        assert!(pose.sample(Joint::LeftShoulder).is_some());
        assert!(pose.sample(Joint::Head).is_none());
        // The same user's next bundle does not select (or clear) again.
        let done = s.apply_all(&frame, 10, &mut pose);
        assert_eq!(done.len(), 3);
        assert_eq!(pose.sample(Joint::LeftShoulder).map(|j| j.at_ms), Some(10));
    }

    #[test]
    fn silence_lets_another_user_take_over_and_clears_the_pose() {
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        s.apply(joint(1, Joint::RightElbow, 1.0), 0, &mut pose);
        s.apply(joint(1, Joint::Head, 1.0), 500, &mut pose);
        // 1000 ms after the last joint: not yet silent long enough.
        assert_eq!(
            s.apply(joint(2, Joint::LeftElbow, 2.0), 1500, &mut pose),
            Applied::OtherUser
        );
        assert_eq!(
            s.apply(joint(2, Joint::LeftElbow, 2.0), 1501, &mut pose),
            Applied::Selected(2)
        );
        assert_eq!(pose.sample(Joint::Head), None);
        assert_eq!(pose.sample(Joint::RightElbow), None);
        assert_eq!(s.current(), Some(2));
    }

    #[test]
    fn lost_user_and_new_skeleton_clear_only_for_the_selected_user() {
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        s.apply(joint(1, Joint::LeftElbow, 1.0), 0, &mut pose);
        assert_eq!(
            s.apply(SkeletonEvent::LostUser(7), 1, &mut pose),
            Applied::Nothing
        );
        assert_eq!(
            s.apply(SkeletonEvent::NewSkeleton(7), 1, &mut pose),
            Applied::Nothing
        );
        assert!(pose.sample(Joint::LeftElbow).is_some());
        assert_eq!(
            s.apply(SkeletonEvent::NewSkeleton(1), 2, &mut pose),
            Applied::Restarted(1)
        );
        assert!(pose.sample(Joint::LeftElbow).is_none());
        assert_eq!(s.current(), Some(1));
        s.apply(joint(1, Joint::LeftElbow, 1.0), 3, &mut pose);
        assert_eq!(
            s.apply(SkeletonEvent::LostUser(1), 4, &mut pose),
            Applied::Lost(1)
        );
        assert_eq!(s.current(), None);
        assert!(pose.sample(Joint::LeftElbow).is_none());
        // Immediately free for the next person's elbow.
        assert_eq!(
            s.apply(joint(5, Joint::LeftElbow, 1.0), 5, &mut pose),
            Applied::Selected(5)
        );
    }
}
