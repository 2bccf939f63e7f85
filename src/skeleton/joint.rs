//! Joint and body-side names, and how the skeleton streamers spell them.
//!
//! The set is the NiTE 15 that OSCeleton sends (head, neck, torso, shoulders, elbows, hands, hips, knees,
//! feet) plus the two wrists, which Kinect v2 (and OpenNI's enum, though NiTE never fills it) provides. Names
//! a streamer sends that have no counterpart here (Kinect v2 `SpineBase`, `HandTipLeft`, OpenNI `l_collar`,
//! ...) map to `None` and are ignored.

use serde::{Deserialize, Serialize};

/// A side of the body, in the person's own (anatomical) sense.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// The person's left.
    Left,
    /// The person's right.
    Right,
}

impl Side {
    /// The other side.
    pub fn opposite(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// A tracked body joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Joint {
    Head,
    Neck,
    Torso,
    LeftShoulder,
    LeftElbow,
    LeftWrist,
    LeftHand,
    RightShoulder,
    RightElbow,
    RightWrist,
    RightHand,
    LeftHip,
    LeftKnee,
    LeftFoot,
    RightHip,
    RightKnee,
    RightFoot,
}

impl Joint {
    /// Every joint, in declaration order (`Joint::ALL[j.index()] == j`).
    pub const ALL: [Joint; 17] = [
        Joint::Head,
        Joint::Neck,
        Joint::Torso,
        Joint::LeftShoulder,
        Joint::LeftElbow,
        Joint::LeftWrist,
        Joint::LeftHand,
        Joint::RightShoulder,
        Joint::RightElbow,
        Joint::RightWrist,
        Joint::RightHand,
        Joint::LeftHip,
        Joint::LeftKnee,
        Joint::LeftFoot,
        Joint::RightHip,
        Joint::RightKnee,
        Joint::RightFoot,
    ];

    /// Number of joints.
    pub const COUNT: usize = Joint::ALL.len();

    /// Position of this joint in [`Joint::ALL`]; always `< Joint::COUNT`.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The joint named by OSCeleton / OpenNI (`"l_elbow"`, `"head"`, ...). Case-sensitive, as sent on the wire.
    pub fn from_osceleton(name: &str) -> Option<Joint> {
        Joint::ALL.into_iter().find(|j| j.osceleton_name() == name)
    }

    /// The joint named by the Kinect v2 SDK `JointType` (`"ElbowLeft"`, `"SpineMid"`, ...).
    /// `SpineMid` is taken as the torso; `SpineBase`, `SpineShoulder`, ankles, hand tips and thumbs are `None`.
    pub fn from_kinect_v2(name: &str) -> Option<Joint> {
        Joint::ALL.into_iter().find(|j| j.kinect_v2_name() == name)
    }

    /// The name OSCeleton sends for this joint.
    pub fn osceleton_name(self) -> &'static str {
        match self {
            Joint::Head => "head",
            Joint::Neck => "neck",
            Joint::Torso => "torso",
            Joint::LeftShoulder => "l_shoulder",
            Joint::LeftElbow => "l_elbow",
            Joint::LeftWrist => "l_wrist",
            Joint::LeftHand => "l_hand",
            Joint::RightShoulder => "r_shoulder",
            Joint::RightElbow => "r_elbow",
            Joint::RightWrist => "r_wrist",
            Joint::RightHand => "r_hand",
            Joint::LeftHip => "l_hip",
            Joint::LeftKnee => "l_knee",
            Joint::LeftFoot => "l_foot",
            Joint::RightHip => "r_hip",
            Joint::RightKnee => "r_knee",
            Joint::RightFoot => "r_foot",
        }
    }

    /// The Kinect v2 `JointType` name for this joint.
    pub fn kinect_v2_name(self) -> &'static str {
        match self {
            Joint::Head => "Head",
            Joint::Neck => "Neck",
            Joint::Torso => "SpineMid",
            Joint::LeftShoulder => "ShoulderLeft",
            Joint::LeftElbow => "ElbowLeft",
            Joint::LeftWrist => "WristLeft",
            Joint::LeftHand => "HandLeft",
            Joint::RightShoulder => "ShoulderRight",
            Joint::RightElbow => "ElbowRight",
            Joint::RightWrist => "WristRight",
            Joint::RightHand => "HandRight",
            Joint::LeftHip => "HipLeft",
            Joint::LeftKnee => "KneeLeft",
            Joint::LeftFoot => "FootLeft",
            Joint::RightHip => "HipRight",
            Joint::RightKnee => "KneeRight",
            Joint::RightFoot => "FootRight",
        }
    }

    /// The side this joint belongs to, or `None` for the midline joints (head, neck, torso).
    pub fn side(self) -> Option<Side> {
        match self {
            Joint::Head | Joint::Neck | Joint::Torso => None,
            Joint::LeftShoulder
            | Joint::LeftElbow
            | Joint::LeftWrist
            | Joint::LeftHand
            | Joint::LeftHip
            | Joint::LeftKnee
            | Joint::LeftFoot => Some(Side::Left),
            _ => Some(Side::Right),
        }
    }

    /// The same joint on the other side of the body (midline joints map to themselves). Used for the
    /// `swap_lr` setting, because mirror settings in the streamers swap the left/right labels.
    pub fn mirrored(self) -> Joint {
        match self {
            Joint::Head => Joint::Head,
            Joint::Neck => Joint::Neck,
            Joint::Torso => Joint::Torso,
            Joint::LeftShoulder => Joint::RightShoulder,
            Joint::LeftElbow => Joint::RightElbow,
            Joint::LeftWrist => Joint::RightWrist,
            Joint::LeftHand => Joint::RightHand,
            Joint::RightShoulder => Joint::LeftShoulder,
            Joint::RightElbow => Joint::LeftElbow,
            Joint::RightWrist => Joint::LeftWrist,
            Joint::RightHand => Joint::LeftHand,
            Joint::LeftHip => Joint::RightHip,
            Joint::LeftKnee => Joint::RightKnee,
            Joint::LeftFoot => Joint::RightFoot,
            Joint::RightHip => Joint::LeftHip,
            Joint::RightKnee => Joint::LeftKnee,
            Joint::RightFoot => Joint::LeftFoot,
        }
    }

    /// The shoulder on `side`.
    pub fn shoulder(side: Side) -> Joint {
        match side {
            Side::Left => Joint::LeftShoulder,
            Side::Right => Joint::RightShoulder,
        }
    }

    /// The elbow on `side`.
    pub fn elbow(side: Side) -> Joint {
        match side {
            Side::Left => Joint::LeftElbow,
            Side::Right => Joint::RightElbow,
        }
    }

    /// The wrist on `side`.
    pub fn wrist(side: Side) -> Joint {
        match side {
            Side::Left => Joint::LeftWrist,
            Side::Right => Joint::RightWrist,
        }
    }

    /// The hand on `side`.
    pub fn hand(side: Side) -> Joint {
        match side {
            Side::Left => Joint::LeftHand,
            Side::Right => Joint::RightHand,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_matches_position_in_all() {
        for (i, j) in Joint::ALL.into_iter().enumerate() {
            assert_eq!(j.index(), i);
        }
    }

    #[test]
    fn osceleton_and_kinect_names_round_trip_and_are_distinct() {
        for j in Joint::ALL {
            assert_eq!(Joint::from_osceleton(j.osceleton_name()), Some(j));
            assert_eq!(Joint::from_kinect_v2(j.kinect_v2_name()), Some(j));
        }
        assert_eq!(Joint::from_osceleton("l_elbow"), Some(Joint::LeftElbow));
        assert_eq!(Joint::from_osceleton("r_hand"), Some(Joint::RightHand));
        assert_eq!(Joint::from_kinect_v2("ElbowLeft"), Some(Joint::LeftElbow));
        assert_eq!(Joint::from_kinect_v2("WristRight"), Some(Joint::RightWrist));
    }

    #[test]
    fn unknown_and_wrongly_cased_names_are_none() {
        for name in ["", "L_ELBOW", "l_collar", "waist", "Left_Elbow", "elbow"] {
            assert_eq!(Joint::from_osceleton(name), None, "{name}");
        }
        for name in [
            "SpineBase",
            "SpineShoulder",
            "HandTipLeft",
            "ThumbRight",
            "AnkleLeft",
            "l_elbow",
        ] {
            assert_eq!(Joint::from_kinect_v2(name), None, "{name}");
        }
    }

    #[test]
    fn mirrored_swaps_sides_and_is_an_involution() {
        for j in Joint::ALL {
            let m = j.mirrored();
            assert_eq!(m.mirrored(), j);
            assert_eq!(m.side(), j.side().map(Side::opposite));
            if j.side().is_none() {
                assert_eq!(m, j);
            }
        }
        assert_eq!(Joint::LeftElbow.mirrored(), Joint::RightElbow);
        assert_eq!(Joint::RightHand.mirrored(), Joint::LeftHand);
    }

    #[test]
    fn side_constructors_agree_with_side() {
        for side in [Side::Left, Side::Right] {
            for j in [
                Joint::shoulder(side),
                Joint::elbow(side),
                Joint::wrist(side),
                Joint::hand(side),
            ] {
                assert_eq!(j.side(), Some(side));
            }
        }
    }
}
