//! Unit tests of the sensor-packet table: sizes, signedness, groups and per-model availability.
use super::*;
use proptest::prelude::*;

/// Two-byte and signed packets as listed in the OI specifications' packet tables [C1 pp17–21; C2 pp23–32].
const TWO_BYTE: &[u8] = &[
    19, 20, 22, 23, 25, 26, 27, 28, 29, 30, 31, 33, 39, 40, 41, 42, 43, 44, 46, 47, 48, 49, 50, 51,
    54, 55, 56, 57,
];
const SIGNED: &[u8] = &[19, 20, 23, 24, 39, 40, 41, 42, 43, 44, 54, 55, 56, 57];

#[test]
fn every_single_packet_has_an_entry_with_the_spec_size_and_sign() {
    for id in 7..=58u8 {
        let s = spec(id).unwrap();
        assert_eq!(s.id, id);
        assert_eq!(
            s.size,
            if TWO_BYTE.contains(&id) { 2 } else { 1 },
            "size of {id}"
        );
        assert_eq!(s.signed, SIGNED.contains(&id), "signedness of {id}");
        assert!(s.min <= s.max && !s.name.is_empty());
        assert_eq!(s.create1, id <= 42, "Create 1 availability of {id}");
        assert!(s.create2);
    }
    for id in (0..7).chain(59..=255) {
        assert!(spec(id).is_none(), "{id} is not a single packet");
    }
    let names: std::collections::HashSet<_> = PACKETS.iter().map(|s| s.name).collect();
    assert_eq!(names.len(), PACKETS.len(), "names are unique");
}

#[test]
fn group_sizes_and_members_match_the_spec() {
    let sizes = [
        (0, 26, 7, 26),
        (1, 10, 7, 16),
        (2, 6, 17, 20),
        (3, 10, 21, 26),
        (4, 14, 27, 34),
        (5, 12, 35, 42),
        (6, 52, 7, 42),
        (100, 80, 7, 58),
        (101, 28, 43, 58),
        (106, 12, 46, 51),
        (107, 9, 54, 58),
    ];
    for (group, bytes, first, last) in sizes {
        assert_eq!(data_len(group), Some(bytes), "size of group {group}");
        let members: Vec<u8> = (first..=last).collect();
        assert_eq!(
            group_members(group),
            Some(&members[..]),
            "members of {group}"
        );
    }
    for undefined in [7, 59, 99, 102, 103, 104, 105, 108, 255] {
        assert!(
            group_members(undefined).is_none(),
            "{undefined} is no group"
        );
    }
    assert_eq!(data_len(103), None);
    assert_eq!(data_len(19), Some(2));
}

#[test]
fn availability_per_model() {
    for g in 0..=6 {
        assert!(available_on(g, Model::Create1) && available_on(g, Model::Create2));
    }
    for g in [100, 101, 106, 107] {
        assert!(!available_on(g, Model::Create1) && available_on(g, Model::Create2));
    }
    assert!(available_on(42, Model::Create1) && !available_on(43, Model::Create1));
    assert!(!available_on(102, Model::Create2) && !available_on(59, Model::Create2));
    assert_eq!(
        check_available(59, Model::Create2),
        Err(OiError::UnknownPacket(59))
    );
    assert_eq!(
        check_available(100, Model::Create1),
        Err(OiError::NotOnModel {
            id: 100,
            model: Model::Create1
        })
    );
    assert_eq!(Model::Create1.all_sensors_group(), id::GROUP_ALL_CREATE1);
    assert_eq!(Model::Create2.all_sensors_group(), id::GROUP_ALL_CREATE2);
}

#[test]
fn decode_is_big_endian_and_sign_extends() {
    assert_eq!(decode_value(id::DISTANCE, &[255, 253]), Ok(-3));
    assert_eq!(decode_value(id::VOLTAGE, &[0x3E, 0x9C]), Ok(16_028));
    assert_eq!(decode_value(id::VOLTAGE, &[0xFF, 0xFF]), Ok(65_535));
    assert_eq!(decode_value(id::TEMPERATURE, &[0x80]), Ok(-128));
    assert_eq!(decode_value(id::OI_MODE, &[0x80]), Ok(128));
    assert_eq!(
        decode_value(id::CURRENT, &[1]),
        Err(OiError::BadLength {
            id: 23,
            expected: 2,
            got: 1
        })
    );
    assert_eq!(decode_value(3, &[1]), Err(OiError::UnknownPacket(3)));
}

#[test]
fn encode_saturates_like_the_firmware_except_encoders_wrap() {
    let enc = |id, v| {
        let mut out = Vec::new();
        encode_value(id, v, &mut out).unwrap();
        out
    };
    assert_eq!(enc(id::DISTANCE, 40_000), vec![0x7F, 0xFF]);
    assert_eq!(enc(id::ANGLE, -40_000), vec![0x80, 0x00]);
    assert_eq!(enc(id::VOLTAGE, -5), vec![0, 0]);
    assert_eq!(enc(id::TEMPERATURE, 200), vec![127]);
    assert_eq!(enc(id::BUMPS_WHEEL_DROPS, 300), vec![255]);
    assert_eq!(enc(id::LEFT_ENCODER, 32_768), vec![0x80, 0x00]);
    assert_eq!(enc(id::RIGHT_ENCODER, 65_537), vec![0x00, 0x01]);
    let mut out = Vec::new();
    assert_eq!(
        encode_value(59, 0, &mut out),
        Err(OiError::UnknownPacket(59))
    );
}

#[test]
fn group_data_round_trips_and_absent_values_are_zero() {
    let mut v = SensorValues::new();
    v.set(
        id::BUMPS_WHEEL_DROPS,
        bits::BUMP_LEFT | bits::WHEEL_DROP_RIGHT,
    );
    v.set(id::DISTANCE, -1234);
    v.set(id::STASIS, bits::STASIS_TOGGLING);
    let mut bytes = Vec::new();
    encode_data(100, &v, &mut bytes).unwrap();
    assert_eq!(bytes.len(), 80);
    assert_eq!(bytes[0], 6);
    assert_eq!(&bytes[12..14], &(-1234i16).to_be_bytes());
    let mut back = SensorValues::new();
    decode_data(100, &bytes, &mut back).unwrap();
    assert_eq!(back.iter().count(), 52, "every member decoded");
    for id in 7..=58 {
        assert_eq!(back.get(id), Some(v.get_or_zero(id)), "packet {id}");
    }
    assert_eq!(
        decode_data(6, &bytes, &mut back),
        Err(OiError::BadLength {
            id: 6,
            expected: 52,
            got: 80
        })
    );
    assert_eq!(
        decode_data(104, &[], &mut back),
        Err(OiError::UnknownPacket(104))
    );
}

/// A packet id 7–58 and a value in its wire range.
fn packet_and_value() -> impl Strategy<Value = (u8, i32)> {
    (7u8..=58).prop_flat_map(|id| {
        let (lo, hi) = spec(id).map(PacketSpec::wire_range).unwrap_or((0, 0));
        (Just(id), lo..=hi)
    })
}

proptest! {
    #[test]
    fn every_packet_round_trips((id, value) in packet_and_value()) {
        let mut out = Vec::new();
        encode_value(id, value, &mut out).unwrap();
        prop_assert_eq!(out.len(), usize::from(spec(id).unwrap().size));
        prop_assert_eq!(decode_value(id, &out), Ok(value));
    }

    #[test]
    fn every_group_round_trips(group in prop::sample::select(vec![0u8, 1, 2, 3, 4, 5, 6, 100, 101, 106, 107]),
                               raw in prop::collection::vec(any::<u8>(), 80)) {
        // Any data bytes decode, and re-encode to the same bytes.
        let n = data_len(group).unwrap();
        let mut values = SensorValues::new();
        decode_data(group, &raw[..n], &mut values).unwrap();
        let mut again = Vec::new();
        encode_data(group, &values, &mut again).unwrap();
        prop_assert_eq!(&again[..], &raw[..n]);
    }
}

/// The encoding as it was before the tables: each member through `encode_value`, absent as 0.
fn encode_data_by_members(id: u8, values: &SensorValues) -> Vec<u8> {
    let mut out = Vec::new();
    let single = spec(id).map(|s| std::slice::from_ref(&s.id));
    for &m in single.or_else(|| group_members(id)).unwrap() {
        encode_value(m, values.get_or_zero(m), &mut out).unwrap();
    }
    out
}

#[test]
fn the_data_length_table_sums_the_members() {
    for id in 0..=255u8 {
        let by_members = spec(id).map(|s| usize::from(s.size)).or_else(|| {
            group_members(id).map(|m| m.iter().map(|&p| usize::from(spec(p).unwrap().size)).sum())
        });
        assert_eq!(data_len(id), by_members, "id {id}");
    }
}

proptest! {
    /// Any values, present or not, in or far out of their wire range: the table-driven encoding writes the
    /// bytes the member-by-member one does, for every packet and group.
    #[test]
    fn table_encoding_matches_member_encoding(
        raw in prop::collection::vec(any::<i32>(), 52),
        present in any::<u64>(),
        id in prop::sample::select((7u8..=58).chain([0, 1, 2, 3, 4, 5, 6, 100, 101, 106, 107]).collect::<Vec<_>>()),
    ) {
        let mut values = SensorValues::new();
        for (k, &v) in raw.iter().enumerate() {
            if present & (1 << k) != 0 {
                values.set(7 + k as u8, v);
            }
        }
        let mut out = Vec::new();
        encode_data(id, &values, &mut out).unwrap();
        prop_assert_eq!(out, encode_data_by_members(id, &values));
    }
}
