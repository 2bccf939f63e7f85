//! Unit tests of the skeleton decoder: both formats, bundles, swap_lr, and every malformed kind.

use super::*;
use crate::simulated::human::{bundle, message as msg, osceleton_joint as osc_joint};

fn kinect_joint(id: &str, name: &str, p: [f32; 3], state: &str) -> OscPacket {
    msg(
        format!("/bodies/{id}/joints/{name}"),
        vec![
            OscType::Float(p[0]),
            OscType::Float(p[1]),
            OscType::Float(p[2]),
            OscType::String(state.into()),
        ],
    )
}

fn run(d: Decoder, p: &OscPacket) -> (Vec<SkeletonEvent>, DecodeCounts, Vec<Malformed>) {
    let mut events = Vec::new();
    let mut counts = DecodeCounts::default();
    let bad = d.decode(p, &mut events, &mut counts);
    (events, counts, bad)
}

#[test]
fn osceleton_mm_bundle_gives_joints_and_user_events_in_order() {
    let d = Decoder::new(SkeletonFormat::OsceletonMm, false);
    let p = bundle(vec![
        msg("/new_user", vec![OscType::Int(1)]),
        msg("/new_skel", vec![OscType::Int(1)]),
        osc_joint("l_elbow", 1, [-190.5, 300.25, 2500.0]),
        osc_joint("l_collar", 1, [1.0, 2.0, 3.0]),
        msg("/orient", vec![OscType::String("head".into())]),
        msg("/lost_user", vec![OscType::Int(1)]),
    ]);
    let (events, counts, bad) = run(d, &p);
    assert!(bad.is_empty());
    assert_eq!(
        events,
        vec![
            SkeletonEvent::NewUser(1),
            SkeletonEvent::NewSkeleton(1),
            SkeletonEvent::Joint {
                user: 1,
                joint: Joint::LeftElbow,
                pos_mm: [-190.5, 300.25, 2500.0],
                confidence: 1.0
            },
            SkeletonEvent::LostUser(1),
        ]
    );
    assert_eq!(
        (
            counts.messages,
            counts.joints,
            counts.skipped_joints,
            counts.ignored
        ),
        (6, 1, 1, 1)
    );
}

#[test]
fn normalized_coordinates_are_transformed_back_to_mm() {
    let d = Decoder::new(SkeletonFormat::OsceletonNormalized, false);
    let mm = [-190.0, 300.0, 2500.0];
    let n = pavlov::skeleton::mm_to_osceleton_normalized(mm);
    let p = osc_joint("r_hand", 2, n);
    let (events, _, _) = run(d, &p);
    let [SkeletonEvent::Joint { joint, pos_mm, .. }] = events.as_slice() else {
        panic!("{events:?}")
    };
    assert_eq!(*joint, Joint::RightHand);
    for k in 0..3 {
        assert!((pos_mm[k] - mm[k]).abs() < 0.01, "{pos_mm:?}");
    }
}

#[test]
fn kinect_v2_metres_states_and_64_bit_ids() {
    let d = Decoder::new(SkeletonFormat::KinectV2, false);
    let id = "72057594037928243";
    let p = bundle(vec![
        kinect_joint(id, "ElbowLeft", [-0.25, -0.125, 2.5], "Tracked"),
        kinect_joint(id, "WristLeft", [-0.25, 0.0, 2.5], "Inferred"),
        kinect_joint(id, "HandLeft", [0.0, 0.0, 2.5], "NotTracked"),
        kinect_joint(id, "SpineBase", [0.0, 0.0, 2.5], "Tracked"),
        msg(
            format!("/bodies/{id}/hands/Left"),
            vec![OscType::String("Open".into())],
        ),
    ]);
    let (events, counts, bad) = run(d, &p);
    assert!(bad.is_empty());
    assert_eq!(
        events,
        vec![
            SkeletonEvent::Joint {
                user: 72_057_594_037_928_243,
                joint: Joint::LeftElbow,
                pos_mm: [-250.0, -125.0, 2500.0],
                confidence: 1.0
            },
            SkeletonEvent::Joint {
                user: 72_057_594_037_928_243,
                joint: Joint::LeftWrist,
                pos_mm: [-250.0, 0.0, 2500.0],
                confidence: 0.5
            },
        ]
    );
    assert_eq!((counts.skipped_joints, counts.ignored), (2, 1));
}

#[test]
fn swap_lr_mirrors_joints() {
    let d = Decoder::new(SkeletonFormat::OsceletonMm, true);
    let (events, _, _) = run(d, &osc_joint("l_elbow", 1, [1.0, 2.0, 3.0]));
    assert!(matches!(
        events.as_slice(),
        [SkeletonEvent::Joint {
            joint: Joint::RightElbow,
            ..
        }]
    ));
    let (events, _, _) = run(d, &osc_joint("head", 1, [1.0, 2.0, 3.0]));
    assert!(matches!(
        events.as_slice(),
        [SkeletonEvent::Joint {
            joint: Joint::Head,
            ..
        }]
    ));
}

#[test]
fn malformed_messages_are_counted_by_kind_and_good_ones_still_decode() {
    let d = Decoder::new(SkeletonFormat::OsceletonMm, false);
    let p = bundle(vec![
        // Wrong type tags: user id as a float, coordinates as ints, too few arguments.
        msg(
            "/joint",
            vec![
                OscType::String("l_elbow".into()),
                OscType::Float(1.0),
                OscType::Float(1.0),
                OscType::Float(1.0),
                OscType::Float(1.0),
            ],
        ),
        msg(
            "/joint",
            vec![
                OscType::String("l_elbow".into()),
                OscType::Int(1),
                OscType::Int(1),
                OscType::Int(1),
                OscType::Int(1),
            ],
        ),
        msg("/joint", vec![OscType::String("l_elbow".into())]),
        msg("/new_user", vec![OscType::String("x".into())]),
        osc_joint("l_elbow", -3, [1.0, 2.0, 3.0]),
        osc_joint("l_elbow", 1, [f64::NAN, 2.0, 3.0]),
        osc_joint("l_hand", 1, [1.0, f64::INFINITY, 3.0]),
        msg("/something/else", vec![]),
        kinect_joint("5", "ElbowLeft", [0.1, 0.2, 0.3], "Tracked"),
        osc_joint("l_shoulder", 1, [1.0, 2.0, 3.0]),
    ]);
    let (events, counts, bad) = run(d, &p);
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(counts.wrong_types, 5);
    assert_eq!(counts.non_finite, 2);
    assert_eq!(counts.unknown_address, 1);
    assert_eq!(counts.other_format, 1);
    assert_eq!(counts.malformed(), 9);
    assert_eq!(bad.len(), 9);
}

#[test]
fn kinect_format_rejects_bad_addresses_states_and_osceleton_messages() {
    let d = Decoder::new(SkeletonFormat::KinectV2, false);
    let p = bundle(vec![
        kinect_joint("notanumber", "ElbowLeft", [0.1, 0.2, 0.3], "Tracked"),
        kinect_joint("1", "ElbowLeft", [0.1, 0.2, 0.3], "Maybe"),
        msg("/bodies/1/joints", vec![]),
        msg("/bodies/1/faces/Nose", vec![]),
        osc_joint("l_elbow", 1, [1.0, 2.0, 3.0]),
    ]);
    let (events, counts, _) = run(d, &p);
    assert!(events.is_empty());
    assert_eq!(counts.unknown_address, 3);
    assert_eq!(counts.wrong_types, 1);
    assert_eq!(counts.other_format, 1);
}

#[test]
fn nested_bundles_decode_until_the_depth_limit() {
    let d = Decoder::new(SkeletonFormat::OsceletonMm, false);
    let mut p = osc_joint("head", 1, [1.0, 2.0, 3.0]);
    for _ in 0..MAX_BUNDLE_DEPTH {
        p = bundle(vec![p]);
    }
    let (events, counts, _) = run(d, &p);
    assert_eq!((events.len(), counts.too_deep), (1, 0));
    let deeper = bundle(vec![p, osc_joint("neck", 1, [1.0, 2.0, 3.0])]);
    let (events, counts, _) = run(d, &deeper);
    assert_eq!((events.len(), counts.too_deep), (1, 1), "{events:?}");
}

/// `depth` bundles, each holding the next, around one message.
fn nested_bytes(depth: usize) -> Vec<u8> {
    let mut p = osc_joint("head", 1, [1.0, 2.0, 3.0]);
    for _ in 0..depth {
        p = bundle(vec![p]);
    }
    rosc::encoder::encode(&p).unwrap()
}

#[test]
fn nesting_check_agrees_with_the_decoders_depth_limit() {
    assert!(nesting_within(&nested_bytes(0), MAX_BUNDLE_DEPTH));
    assert!(nesting_within(
        &nested_bytes(MAX_BUNDLE_DEPTH),
        MAX_BUNDLE_DEPTH
    ));
    assert!(!nesting_within(
        &nested_bytes(MAX_BUNDLE_DEPTH + 1),
        MAX_BUNDLE_DEPTH
    ));
    // A deep element after a shallow one is found too.
    let two = bundle(vec![
        osc_joint("neck", 1, [1.0, 2.0, 3.0]),
        rosc::decoder::decode_udp(&nested_bytes(MAX_BUNDLE_DEPTH))
            .unwrap()
            .1,
    ]);
    assert!(!nesting_within(
        &rosc::encoder::encode(&two).unwrap(),
        MAX_BUNDLE_DEPTH
    ));
}

#[test]
fn nesting_check_survives_the_datagram_that_overflows_rosc() {
    // 3000 nested bundles in 60 KB: rosc's recursive decoder would overflow the stack on this.
    let mut bytes = b"#bundle\0\0\0\0\0\0\0\0\x01".to_vec();
    for _ in 0..3000 {
        let mut outer = b"#bundle\0\0\0\0\0\0\0\0\x01".to_vec();
        outer.extend_from_slice(&u32::try_from(bytes.len()).unwrap().to_be_bytes());
        outer.extend_from_slice(&bytes);
        bytes = outer;
    }
    assert!(bytes.len() < 65_507);
    assert!(!nesting_within(&bytes, MAX_BUNDLE_DEPTH));
    // Truncated or lying sizes are left to rosc, not rejected here.
    assert!(nesting_within(&bytes[..40], MAX_BUNDLE_DEPTH));
    assert!(nesting_within(
        b"#bundle\0\0\0\0\0\0\0\0\x01\xff\xff\xff\xff",
        MAX_BUNDLE_DEPTH
    ));
    assert!(nesting_within(b"garbage", MAX_BUNDLE_DEPTH));
}
