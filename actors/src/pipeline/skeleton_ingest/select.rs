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
//! joints that precede the elbow in the same bundle are kept. With unbundled messages (KinectV2-OSC sends one
//! datagram per joint, ShoulderLeft before ElbowLeft), the joints a user sends while the selection is vacant
//! are held aside, the newest of each joint for up to [`MAX_CANDIDATES`] users; when the user is selected
//! they go into the cleared pose before the elbow, so the frame being selected keeps its shoulder and the
//! left elbow angle is there from the first frame. Held joints older than `silence_ms` are forgotten.

use pavlov::skeleton::{Joint, JointSample, PoseTracker};

use super::decode::{SkeletonEvent, UserId};

/// How long the selected user may be silent before another user can take over, ms.
pub(crate) const DEFAULT_SILENCE_MS: u64 = 1000;

/// How many not-yet-selected users' joints are held aside (a Kinect v2 tracks up to 6 bodies).
pub(crate) const MAX_CANDIDATES: usize = 6;

/// The newest joints of one user that is not (yet) selected.
#[derive(Debug, Clone, PartialEq)]
struct Candidate {
    user: UserId,
    last_heard_ms: u64,
    joints: Vec<(Joint, JointSample)>,
}

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
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct UserSelector {
    current: Option<UserId>,
    last_heard_ms: u64,
    silence_ms: u64,
    candidates: Vec<Candidate>,
}

impl UserSelector {
    /// No user selected; a selected user may be silent for `silence_ms` before being replaced.
    pub(crate) fn new(silence_ms: u64) -> Self {
        UserSelector {
            current: None,
            last_heard_ms: 0,
            silence_ms,
            candidates: Vec::new(),
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

    /// Selects `user`: clears the pose of the previous person and puts in the joints `user` sent while
    /// waiting (newer than `silence_ms`).
    fn select(&mut self, user: UserId, now_ms: u64, pose: &mut PoseTracker) {
        self.current = Some(user);
        self.last_heard_ms = now_ms;
        pose.clear();
        let held = std::mem::take(&mut self.candidates);
        if let Some(c) = held.into_iter().find(|c| c.user == user) {
            for (joint, sample) in c.joints {
                if now_ms.saturating_sub(sample.at_ms) <= self.silence_ms {
                    pose.update(joint, sample);
                }
            }
        }
    }

    /// Holds a joint of a user that is not selected while the selection is vacant.
    fn hold(&mut self, user: UserId, joint: Joint, sample: JointSample) {
        let now = sample.at_ms;
        let silence = self.silence_ms;
        self.candidates
            .retain(|c| now.saturating_sub(c.last_heard_ms) <= silence);
        let i = match self.candidates.iter().position(|c| c.user == user) {
            Some(i) => i,
            None => {
                if self.candidates.len() >= MAX_CANDIDATES
                    && let Some(oldest) = self
                        .candidates
                        .iter()
                        .enumerate()
                        .min_by_key(|(_, c)| c.last_heard_ms)
                        .map(|(i, _)| i)
                {
                    self.candidates.swap_remove(oldest);
                }
                self.candidates.push(Candidate {
                    user,
                    last_heard_ms: now,
                    joints: Vec::new(),
                });
                self.candidates.len() - 1
            }
        };
        if let Some(c) = self.candidates.get_mut(i) {
            c.last_heard_ms = now;
            match c.joints.iter_mut().find(|(j, _)| *j == joint) {
                Some(slot) => slot.1 = sample,
                None => c.joints.push((joint, sample)),
            }
        }
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
                    if self.vacant(now_ms) {
                        self.hold(user, joint, sample);
                    }
                    Applied::OtherUser
                }
            }
            SkeletonEvent::LostUser(user) if self.current == Some(user) => {
                self.current = None;
                pose.clear();
                Applied::Lost(user)
            }
            SkeletonEvent::LostUser(user) => {
                self.candidates.retain(|c| c.user != user);
                Applied::Nothing
            }
            SkeletonEvent::NewSkeleton(user) if self.current == Some(user) => {
                self.last_heard_ms = now_ms;
                pose.clear();
                Applied::Restarted(user)
            }
            SkeletonEvent::NewSkeleton(_) | SkeletonEvent::NewUser(_) => Applied::Nothing,
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
    fn unbundled_joints_sent_before_the_selecting_elbow_are_kept_for_that_user_only() {
        // KinectV2-OSC: one datagram per joint. User 2's shoulder comes before its elbow; user 9's head
        // and a stale head of user 2 from long ago must not survive.
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        s.apply_all(&[joint(2, Joint::Head, 7.0)], 0, &mut pose);
        s.apply_all(&[joint(9, Joint::Neck, 1.0)], 4990, &mut pose);
        s.apply_all(&[joint(2, Joint::LeftShoulder, 3.0)], 5000, &mut pose);
        assert_eq!(pose.sample(Joint::LeftShoulder), None, "not yet selected");
        let done = s.apply_all(&[joint(2, Joint::LeftElbow, 4.0)], 5001, &mut pose);
        assert_eq!(done, vec![Applied::Selected(2), Applied::JointUsed]);
        let shoulder = pose
            .sample(Joint::LeftShoulder)
            .expect("the frame's shoulder kept");
        assert_eq!((shoulder.pos_mm[0], shoulder.at_ms), (3.0, 5000));
        assert!(pose.sample(Joint::LeftElbow).is_some());
        assert_eq!(pose.sample(Joint::Neck), None, "another user's joint");
        assert_eq!(
            pose.sample(Joint::Head),
            None,
            "older than the silence limit"
        );
        // Once selected, nothing is held any more.
        s.apply_all(&[joint(9, Joint::LeftElbow, 1.0)], 5010, &mut pose);
        assert!(s.candidates.is_empty());
    }

    #[test]
    fn at_most_six_waiting_users_are_held() {
        let mut s = UserSelector::new(1000);
        let mut pose = PoseTracker::new(100);
        for user in 0..20 {
            s.apply_all(&[joint(user, Joint::Head, 1.0)], user, &mut pose);
        }
        assert_eq!(s.candidates.len(), MAX_CANDIDATES);
        assert!(
            s.candidates.iter().all(|c| c.user >= 14),
            "the newest are kept"
        );
        s.apply_all(&[SkeletonEvent::LostUser(19)], 30, &mut pose);
        assert_eq!(s.candidates.len(), MAX_CANDIDATES - 1);
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
