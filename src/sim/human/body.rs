//! Forward kinematics of the simulated operator: from the body's sway and each arm's elbow angle to 3-D joint
//! positions in the sensor's frame (x to the sensor's right, y up, z away from the sensor, mm — OSCeleton's raw
//! `-xr` frame).
//!
//! The person faces the sensor, so "forward" for the person is −z. Their left arm is drawn at −x, the way a
//! mirrored (NiTE default) image shows it; the effective handedness of real streamers depends on their mirror
//! settings (see the skeleton reference), which only swaps labels and never changes an angle.

use crate::rng::Rng;
use crate::skeleton::{Joint, Side};

use super::params::HumanParams;

type V3 = [f64; 3];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: V3) -> Option<V3> {
    let n = dot(a, a).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// Head above the neck joint, mm.
const HEAD_ABOVE_NECK_MM: f64 = 230.0;
/// Torso joint (mid-chest) below the neck, mm.
const TORSO_BELOW_NECK_MM: f64 = 260.0;
/// Hip joints below the neck and out from the midline, mm.
const HIP_BELOW_NECK_MM: f64 = 520.0;
const HIP_HALF_WIDTH_MM: f64 = 100.0;
/// Thigh and shank lengths, mm.
const THIGH_MM: f64 = 440.0;
const SHANK_MM: f64 = 420.0;

/// Slow postural sway of the whole body (an Ornstein–Uhlenbeck process per axis; vertical sway is a third of
/// the horizontal).
#[derive(Debug, Clone)]
pub struct Sway {
    rng: Rng,
    offset: V3,
}

impl Sway {
    pub fn new(rng: Rng) -> Self {
        Sway {
            rng,
            offset: [0.0; 3],
        }
    }

    /// Advance by `dt_ms` and return the current offset, mm.
    pub fn step(&mut self, dt_ms: f64, p: &HumanParams) -> V3 {
        let tau_ms = 1000.0 * p.sway_tau_s;
        if tau_ms > 0.0 && dt_ms > 0.0 {
            let a = (-dt_ms / tau_ms).exp();
            let k = (1.0 - a * a).sqrt();
            for (axis, sd) in [
                (0, p.sway_sd_mm),
                (1, p.sway_sd_mm / 3.0),
                (2, p.sway_sd_mm),
            ] {
                let prev = self.offset[axis];
                self.offset[axis] = a * prev + self.rng.normal(0.0, sd * k);
            }
        }
        self.offset
    }
}

/// How one arm is posed at an instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmPose {
    /// True interior elbow angle, degrees.
    pub elbow_deg: f64,
    /// Sideways lift of the upper arm from the body, degrees.
    pub abduction_deg: f64,
    /// Forward lift of the upper arm, degrees.
    pub flexion_deg: f64,
    /// Inward yaw of the forearm's swing plane, degrees.
    pub forearm_yaw_deg: f64,
}

/// Shoulder, elbow, wrist and hand of one arm.
fn arm_joints(side: Side, shoulder: V3, arm: ArmPose, p: &HumanParams) -> [(Joint, V3); 4] {
    let out = match side {
        Side::Left => -1.0,
        Side::Right => 1.0,
    };
    let (ab, fl, yaw, th) = (
        arm.abduction_deg.to_radians(),
        arm.flexion_deg.to_radians(),
        arm.forearm_yaw_deg.to_radians(),
        arm.elbow_deg.to_radians(),
    );
    let forward = [0.0, 0.0, -1.0];
    let hanging = [out * ab.sin(), -ab.cos(), 0.0];
    // Upper-arm direction, shoulder → elbow (unit: `hanging` ⟂ `forward`).
    let upper = add(scale(hanging, fl.cos()), scale(forward, fl.sin()));
    // Direction the forearm swings towards as the elbow bends, made perpendicular to the upper arm.
    let swing = [-out * yaw.sin(), 0.0, -yaw.cos()];
    let perp = normalize(add(swing, scale(upper, -dot(swing, upper)))).unwrap_or(forward);
    // Interior angle θ between (−upper) and the forearm: θ = 180° continues the upper arm, 90° is `perp`.
    let fore = add(scale(upper, -th.cos()), scale(perp, th.sin()));
    let elbow = add(shoulder, scale(upper, p.upper_arm_mm));
    let wrist = add(elbow, scale(fore, p.forearm_mm));
    let hand = add(elbow, scale(fore, p.forearm_mm + p.hand_offset_mm));
    [
        (Joint::shoulder(side), shoulder),
        (Joint::elbow(side), elbow),
        (Joint::wrist(side), wrist),
        (Joint::hand(side), hand),
    ]
}

/// True positions of every joint, in [`Joint::ALL`] order (wrists only when `include_wrists`).
pub fn joint_positions(
    sway: V3,
    left: ArmPose,
    right: ArmPose,
    p: &HumanParams,
) -> Vec<(Joint, V3)> {
    let neck = add([0.0, p.neck_height_mm, p.distance_mm], sway);
    let below = |v: V3, dx: f64, dy: f64, dz: f64| add(v, [dx, -dy, dz]);
    let l_hip = below(neck, -HIP_HALF_WIDTH_MM, HIP_BELOW_NECK_MM, 0.0);
    let r_hip = below(neck, HIP_HALF_WIDTH_MM, HIP_BELOW_NECK_MM, 0.0);
    let l_knee = below(l_hip, 0.0, THIGH_MM, 0.0);
    let r_knee = below(r_hip, 0.0, THIGH_MM, 0.0);
    let mut all = vec![
        (Joint::Head, below(neck, 0.0, -HEAD_ABOVE_NECK_MM, 0.0)),
        (Joint::Neck, neck),
        (Joint::Torso, below(neck, 0.0, TORSO_BELOW_NECK_MM, 0.0)),
    ];
    let l_shoulder = below(neck, -p.shoulder_half_width_mm, 0.0, 0.0);
    let r_shoulder = below(neck, p.shoulder_half_width_mm, 0.0, 0.0);
    all.extend(arm_joints(Side::Left, l_shoulder, left, p));
    all.extend(arm_joints(Side::Right, r_shoulder, right, p));
    all.extend([
        (Joint::LeftHip, l_hip),
        (Joint::LeftKnee, l_knee),
        (Joint::LeftFoot, below(l_knee, 0.0, SHANK_MM, -40.0)),
        (Joint::RightHip, r_hip),
        (Joint::RightKnee, r_knee),
        (Joint::RightFoot, below(r_knee, 0.0, SHANK_MM, -40.0)),
    ]);
    if !p.include_wrists {
        all.retain(|(j, _)| !matches!(j, Joint::LeftWrist | Joint::RightWrist));
    }
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::elbow_angle_deg;

    fn find(js: &[(Joint, V3)], j: Joint) -> V3 {
        js.iter().find(|(k, _)| *k == j).map(|(_, v)| *v).unwrap()
    }

    #[test]
    fn measured_angle_equals_the_posed_angle_whatever_the_arm_orientation() {
        let p = HumanParams::default();
        for (deg, ab, fl, yaw) in [
            (160.0, 10.0, 0.0, 0.0),
            (89.0, 5.0, 20.0, -20.0),
            (55.0, 15.0, 12.0, 20.0),
        ] {
            let arm = ArmPose {
                elbow_deg: deg,
                abduction_deg: ab,
                flexion_deg: fl,
                forearm_yaw_deg: yaw,
            };
            let js = joint_positions([3.0, -2.0, 7.0], arm, arm, &p);
            assert_eq!(js.len(), Joint::COUNT);
            for side in [Side::Left, Side::Right] {
                let s = find(&js, Joint::shoulder(side));
                let e = find(&js, Joint::elbow(side));
                let via_hand = elbow_angle_deg(s, e, find(&js, Joint::hand(side))).unwrap();
                let via_wrist = elbow_angle_deg(s, e, find(&js, Joint::wrist(side))).unwrap();
                assert!((via_hand - deg).abs() < 1e-9 && (via_wrist - deg).abs() < 1e-9);
                assert!(
                    ((0..3).map(|k| (s[k] - e[k]).powi(2)).sum::<f64>().sqrt() - p.upper_arm_mm)
                        .abs()
                        < 1e-9
                );
            }
        }
    }

    #[test]
    fn body_layout_is_a_standing_person_facing_the_sensor() {
        let p = HumanParams {
            include_wrists: false,
            ..HumanParams::default()
        };
        let rest = ArmPose {
            elbow_deg: 160.0,
            abduction_deg: 10.0,
            flexion_deg: 0.0,
            forearm_yaw_deg: 0.0,
        };
        let bent = ArmPose {
            elbow_deg: 60.0,
            ..rest
        };
        let js = joint_positions([0.0; 3], bent, rest, &p);
        assert_eq!(js.len(), 15, "the NiTE 15");
        assert!(find(&js, Joint::Head)[1] > find(&js, Joint::Neck)[1]);
        assert!(find(&js, Joint::LeftFoot)[1] < find(&js, Joint::LeftKnee)[1]);
        assert!(
            find(&js, Joint::LeftShoulder)[0] < 0.0 && find(&js, Joint::RightShoulder)[0] > 0.0
        );
        // The bent left hand is raised and in front of (closer to the sensor than) the elbow.
        let (le, lh) = (find(&js, Joint::LeftElbow), find(&js, Joint::LeftHand));
        assert!(lh[1] > le[1] && lh[2] < le[2]);
        // The resting right hand hangs below its elbow.
        assert!(find(&js, Joint::RightHand)[1] < find(&js, Joint::RightElbow)[1]);
        for (_, v) in &js {
            assert!(v[2] > 2000.0 && v[2] < 3000.0);
        }
    }

    #[test]
    fn sway_stays_small_and_moves() {
        let p = HumanParams::default();
        let mut s = Sway::new(Rng::new(9));
        let mut max: f64 = 0.0;
        let mut first = None;
        let mut moved = false;
        for _ in 0..9000 {
            let o = s.step(1000.0 / 30.0, &p);
            max = max.max(o[0].abs()).max(o[2].abs());
            moved |= first.is_some_and(|f: V3| (f[0] - o[0]).abs() > 1.0);
            first.get_or_insert(o);
        }
        assert!(moved && max < 6.0 * p.sway_sd_mm, "max {max}");
    }
}
