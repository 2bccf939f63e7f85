//! Pure geometry on joint positions: the interior elbow angle, and OSCeleton's normalized-coordinate transform.

/// The paper's command threshold: the left elbow is "bent past 90°" when its interior angle is below this.
pub const COMMAND_THRESHOLD_DEG: f64 = 90.0;

/// Segments shorter than this fraction of the longer segment count as zero-length. Relative, so the test is
/// the same in millimetres and metres.
const DEGENERATE_RATIO: f64 = 1e-9;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// The interior angle at the elbow, in degrees, between the upper arm (elbow→shoulder) and the forearm
/// (elbow→`hand`; pass the wrist when the hand is not available). 180° is a straight arm, 90° a right angle.
///
/// Scale-free: millimetres and metres give the same angle. Returns `None` when any coordinate is not finite
/// or either segment has (relatively) zero length. Uses `atan2(|u×v|, u·v)`, which stays accurate near 0°
/// and 180° where `acos` loses precision.
pub fn elbow_angle_deg(shoulder: [f64; 3], elbow: [f64; 3], hand: [f64; 3]) -> Option<f64> {
    if !shoulder
        .iter()
        .chain(elbow.iter())
        .chain(hand.iter())
        .all(|c| c.is_finite())
    {
        return None;
    }
    let upper = sub(shoulder, elbow);
    let fore = sub(hand, elbow);
    let (lu, lf) = (norm(upper), norm(fore));
    let longer = lu.max(lf);
    if !longer.is_finite() || lu.min(lf) <= longer * DEGENERATE_RATIO {
        return None;
    }
    let angle = norm(cross(upper, fore))
        .atan2(dot(upper, fore))
        .to_degrees();
    angle.is_finite().then_some(angle)
}

/// Undo OSCeleton's default "normalized" output (`x=(1280−X)/2560`, `y=(960−Y)/1920`, `z=Z/1280`), giving back
/// the OpenNI real-world position in millimetres: `X = 1280 − 2560x`, `Y = 960 − 1920y`, `Z = 1280z`.
///
/// Only valid when OSCeleton ran with its default multipliers and offsets (`-mx/-my/-mz 1`, `-o* 0`). The
/// normalized axes are scaled differently, so angles must never be computed before this inverse.
pub fn osceleton_normalized_to_mm(x: f64, y: f64, z: f64) -> [f64; 3] {
    [1280.0 - 2560.0 * x, 960.0 - 1920.0 * y, 1280.0 * z]
}

/// OSCeleton's default normalization of a real-world position in millimetres (the forward transform of
/// [`osceleton_normalized_to_mm`]); used to produce normalized-mode streams from simulated positions.
pub fn mm_to_osceleton_normalized(pos_mm: [f64; 3]) -> [f64; 3] {
    [
        (1280.0 - pos_mm[0]) / 2560.0,
        (960.0 - pos_mm[1]) / 1920.0,
        pos_mm[2] / 1280.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn straight_arm_is_180_and_right_angle_is_90() {
        let s = [0.0, 300.0, 2500.0];
        let e = [0.0, 0.0, 2500.0];
        let straight = elbow_angle_deg(s, e, [0.0, -250.0, 2500.0]).unwrap();
        assert!(close(straight, 180.0, 1e-9), "{straight}");
        let right = elbow_angle_deg(s, e, [0.0, 0.0, 2250.0]).unwrap();
        assert!(close(right, 90.0, 1e-9), "{right}");
        let folded = elbow_angle_deg(s, e, [0.0, 250.0, 2500.0]).unwrap();
        assert!(close(folded, 0.0, 1e-9), "{folded}");
    }

    #[test]
    fn known_oblique_angles() {
        let e = [10.0, 20.0, 30.0];
        for deg in [15.0_f64, 45.0, 60.0, 89.9, 90.1, 120.0, 170.0] {
            let r = deg.to_radians();
            let s = [e[0] + 300.0, e[1], e[2]];
            let h = [e[0] + 260.0 * r.cos(), e[1], e[2] + 260.0 * r.sin()];
            let a = elbow_angle_deg(s, e, h).unwrap();
            assert!(close(a, deg, 1e-9), "{deg} vs {a}");
        }
    }

    #[test]
    fn degenerate_and_non_finite_are_none() {
        let s = [0.0, 300.0, 2500.0];
        let e = [0.0, 0.0, 2500.0];
        assert_eq!(elbow_angle_deg(e, e, [0.0, -250.0, 2500.0]), None);
        assert_eq!(elbow_angle_deg(s, e, e), None);
        assert_eq!(elbow_angle_deg(e, e, e), None);
        assert_eq!(
            elbow_angle_deg([f64::NAN, 0.0, 0.0], e, [1.0, 0.0, 0.0]),
            None
        );
        assert_eq!(elbow_angle_deg(s, e, [0.0, f64::INFINITY, 0.0]), None);
        assert_eq!(elbow_angle_deg(s, [f64::NEG_INFINITY; 3], s), None);
    }

    #[test]
    fn scale_free_between_mm_and_metres() {
        let s = [-211.98, 48.60, 2296.38];
        let e = [-261.81, -187.15, 2237.34];
        let h = [-263.29, -395.54, 2101.31];
        let mm = elbow_angle_deg(s, e, h).unwrap();
        let to_m = |p: [f64; 3]| [p[0] / 1000.0, p[1] / 1000.0, p[2] / 1000.0];
        let m = elbow_angle_deg(to_m(s), to_m(e), to_m(h)).unwrap();
        assert!(close(mm, m, 1e-9), "{mm} vs {m}");
        assert!(mm > 90.0 && mm < 180.0);
    }

    #[test]
    fn real_kinect_v2_frame_in_metres() {
        // First body of the Kinectron recording (ShoulderLeft, ElbowLeft, HandLeft, camera metres); the
        // expected angle was computed independently with acos in Python.
        let s = [-0.2119881957769394, 0.04860438406467438, 2.296380043029785];
        let e = [
            -0.2618103325366974,
            -0.18715129792690277,
            2.2373390197753906,
        ];
        let h = [-0.263294517993927, -0.39554375410079956, 2.101314067840576];
        let a = elbow_angle_deg(s, e, h).unwrap();
        assert!(close(a, 157.9754271490163, 1e-9), "{a}");
    }

    proptest::proptest! {
        #[test]
        fn agrees_with_acos_is_symmetric_and_scale_free(
            s in proptest::array::uniform3(-3000.0..3000.0_f64),
            e in proptest::array::uniform3(-3000.0..3000.0_f64),
            h in proptest::array::uniform3(-3000.0..3000.0_f64),
            k in 1e-4..1e4_f64,
        ) {
            let (u, v) = (sub(s, e), sub(h, e));
            proptest::prop_assume!(norm(u) > 1.0 && norm(v) > 1.0);
            let a = elbow_angle_deg(s, e, h).unwrap();
            let by_acos = (dot(u, v) / (norm(u) * norm(v))).clamp(-1.0, 1.0).acos().to_degrees();
            proptest::prop_assert!((0.0..=180.0).contains(&a));
            proptest::prop_assert!(close(a, by_acos, 1e-5), "{} vs {}", a, by_acos);
            proptest::prop_assert!(close(elbow_angle_deg(h, e, s).unwrap(), a, 1e-9));
            let sc = |p: [f64; 3]| [p[0] * k, p[1] * k, p[2] * k];
            proptest::prop_assert!(close(elbow_angle_deg(sc(s), sc(e), sc(h)).unwrap(), a, 1e-7));
        }
    }

    #[test]
    fn osceleton_normalized_round_trip() {
        for p in [
            [0.0, 0.0, 0.0],
            [-78.588, 838.268, 2602.876],
            [640.0, -480.0, 4000.0],
        ] {
            let n = mm_to_osceleton_normalized(p);
            let back = osceleton_normalized_to_mm(n[0], n[1], n[2]);
            for k in 0..3 {
                assert!(close(back[k], p[k], 1e-9), "{p:?} -> {n:?} -> {back:?}");
            }
        }
        // The centre of OSCeleton's normalized range is the optical axis at Z = 0.
        assert_eq!(osceleton_normalized_to_mm(0.5, 0.5, 0.0), [0.0, 0.0, 0.0]);
        assert_eq!(
            osceleton_normalized_to_mm(0.0, 0.0, 2.0),
            [1280.0, 960.0, 2560.0]
        );
    }

    #[test]
    fn normalized_coordinates_distort_angles() {
        // Why the inverse exists: the same arm gives a different angle before undoing the scaling.
        let s = [0.0, 300.0, 2500.0];
        let e = [0.0, 0.0, 2500.0];
        let h = [0.0, 0.0, 2250.0];
        let true_angle = elbow_angle_deg(s, e, h).unwrap();
        let n = |p| mm_to_osceleton_normalized(p);
        let skewed = elbow_angle_deg(n(s), n(e), n(h)).unwrap();
        assert!(close(true_angle, 90.0, 1e-9));
        assert!(close(skewed, 90.0, 1e-9)); // axis-aligned right angle survives...
        let h2 = [0.0, 200.0, 2300.0];
        let t2 = elbow_angle_deg(s, e, h2).unwrap();
        let k2 = elbow_angle_deg(n(s), n(e), n(h2)).unwrap();
        assert!((t2 - k2).abs() > 5.0, "{t2} vs {k2}"); // ...an oblique one does not
    }
}
