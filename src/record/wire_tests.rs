//! Tests of the tick record's wire form as a whole: every struct field is on the wire, every record reads
//! back exactly, and invalid messages are refused naming the field.

use super::wire::{FieldType, Message, MessageSpec, WireError};
use super::*;
use crate::rng::Rng;
use crate::skeleton::SkeletonStatus;
use crate::supervision::{LinkState, TripCause};
use std::collections::BTreeSet;

/// A record whose every field, and every field of every nested struct, is drawn from `rng` (options
/// are `Some` or `None`, floats include −0.0, infinities and NaN in `obs`). A field added later takes its
/// default here until it is drawn too; the wire form of its type is tested on its own.
#[allow(
    clippy::needless_update,
    reason = "a field added later takes its default until it is drawn here"
)]
fn random_record(rng: &mut Rng) -> TickRecord {
    let f = |rng: &mut Rng| match rng.below(6) {
        0 => -0.0,
        1 => f64::INFINITY,
        2 => 0.0,
        _ => rng.normal(0.0, 1e3),
    };
    let opt_f = |rng: &mut Rng| rng.chance(0.7).then(|| f(rng));
    let i = |rng: &mut Rng| rng.next_u64() as i32;
    let opt_i = |rng: &mut Rng| rng.chance(0.7).then(|| rng.next_u64() as i32);
    let b = |rng: &mut Rng| rng.chance(0.5);
    let values = rng.chance(0.8).then(|| {
        let mut v = SensorValues::new();
        for _ in 0..rng.below(40) {
            v.set(rng.below(59) as u8, i(rng));
        }
        v
    });
    let probability = |rng: &mut Rng| [1.0, 0.5, 0.35, 0.65][rng.below(4) as usize];
    let inputs = rng.chance(0.8).then(|| TickInputs {
        values,
        forced_stimulus: b(rng),
        previous_followed_default: b(rng),
        previous_behaviour_prob: probability(rng),
    });
    let obs: Vec<f32> = (0..rng.below(50))
        .map(|_| match rng.below(5) {
            0 => f32::NAN,
            _ => rng.next_f64() as f32,
        })
        .collect();
    let action = |rng: &mut Rng| Action::new(rng.next_u64() as i16, rng.next_u64() as i16);
    TickRecord {
        seq: rng.next_u64() >> rng.below(64),
        t_ms: f(rng),
        mode: Mode::ALL[rng.below(3) as usize],
        obs_age_ticks: rng.chance(0.7).then(|| rng.next_u64() as u32),
        sensors: SensorReadings {
            overcurrent_left: b(rng),
            overcurrent_right: b(rng),
            bump_left: b(rng),
            bump_right: b(rng),
            battery_current_ma: opt_i(rng),
            battery_voltage_mv: opt_i(rng),
            battery_charge_mah: opt_i(rng),
            distance_mm: i(rng),
            angle_deg: i(rng),
            oi_mode: opt_i(rng),
        },
        obs: if inputs.is_none() { obs } else { Vec::new() },
        elbow: rng.chance(0.5).then(|| ElbowAngles {
            left: opt_f(rng),
            left_avg: opt_f(rng),
            right: opt_f(rng),
            right_avg: opt_f(rng),
            skeleton: [
                SkeletonStatus::Absent,
                SkeletonStatus::Tracked,
                SkeletonStatus::Stale,
            ][rng.below(3) as usize],
        }),
        stimulus: b(rng),
        predictions: (0..rng.below(4))
            .map(|k| PredictionValue {
                name: if k == 0 {
                    String::new()
                } else {
                    format!("p{k} ✓")
                },
                value: f(rng),
                threshold: f(rng),
            })
            .collect(),
        gate: b(rng),
        rule: rng
            .chance(0.5)
            .then(|| ["", "stall", "stimulus"][rng.below(3) as usize].to_string()),
        default_action: action(rng),
        command: action(rng),
        safety_stop: [
            None,
            Some(SafetyStop::EStop),
            Some(SafetyStop::StaleObservation),
            Some(SafetyStop::LinkDown),
            Some(SafetyStop::RobotTripped),
        ][rng.below(5) as usize],
        behaviour_prob: probability(rng),
        estop: b(rng),
        lateness_us: rng.next_u64() as u32 >> rng.below(32),
        link: LinkStatus {
            up: b(rng),
            good_frames: rng.next_u64(),
            bad_frames: rng.below(1000),
            skipped_bytes: rng.below(3),
            state: LinkState::ALL[rng.below(5) as usize],
            mode: rng.chance(0.5).then(|| rng.below(256) as u8),
            trip: [
                None,
                Some(TripCause::WheelDrop),
                Some(TripCause::Cliff),
                Some(TripCause::Charger),
                Some(TripCause::Unknown),
            ][rng.below(5) as usize],
            reconnects: rng.below(10),
            stale_events: rng.below(10),
        },
        inputs,
        ..TickRecord::default()
    }
}

/// Equality bit for bit: as JSON text, where NaN is `null` on both sides and −0.0 differs from 0.0.
fn same(a: &TickRecord, b: &TickRecord) -> bool {
    serde_json::to_string(a).unwrap() == serde_json::to_string(b).unwrap()
}

#[test]
fn every_record_reads_back_exactly() {
    let mut rng = Rng::new(23);
    let mut buf = Vec::new();
    for n in 0..2_000 {
        let r = random_record(&mut rng);
        buf.clear();
        r.encode_to(&mut buf);
        let back = TickRecord::decode(&buf).unwrap();
        assert!(same(&r, &back), "record {n}:\n{r:?}\n{back:?}");
        let mut again = Vec::new();
        back.encode_to(&mut again);
        assert_eq!(again, buf, "record {n} re-encodes to the same bytes");
    }
}

#[test]
fn the_observation_is_written_only_without_inputs() {
    let mut r = TickRecord::at_rest(1, 20.0, Mode::Pavlovian);
    r.obs = vec![0.5, f32::NAN];
    r.inputs = Some(TickInputs::default());
    let mut with_inputs = Vec::new();
    r.encode_to(&mut with_inputs);
    assert!(TickRecord::decode(&with_inputs).unwrap().obs.is_empty());
    r.inputs = None;
    let mut without = Vec::new();
    r.encode_to(&mut without);
    assert!(same(&TickRecord::decode(&without).unwrap(), &r));
}

/// The JSON keys of `value`, an object.
fn keys(value: &serde_json::Value) -> BTreeSet<String> {
    value.as_object().unwrap().keys().cloned().collect()
}

fn spec_names(spec: &MessageSpec) -> BTreeSet<String> {
    spec.fields.iter().map(|f| f.name.to_string()).collect()
}

#[test]
fn every_field_of_every_record_struct_is_on_the_wire() {
    // A field added to a struct but not to its `wire_message!` list fails here.
    let mut rng = Rng::new(5);
    let r = loop {
        let r = random_record(&mut rng);
        if r.rule.is_some() && r.elbow.is_some() && !r.predictions.is_empty() {
            if let Some(i) = &r.inputs {
                if i.values.is_some() {
                    break r;
                }
            }
        }
    };
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(keys(&json), spec_names(&TickRecord::spec()));
    for (key, spec) in [
        ("sensors", SensorReadings::spec()),
        ("elbow", ElbowAngles::spec()),
        ("link", LinkStatus::spec()),
        ("inputs", TickInputs::spec()),
    ] {
        assert_eq!(keys(&json[key]), spec_names(&spec), "{key}");
    }
    assert_eq!(
        keys(&json["predictions"][0]),
        spec_names(&PredictionValue::spec())
    );
    assert_eq!(keys(&json["default_action"]), spec_names(&Action::spec()));
}

#[test]
fn field_numbers_are_unique_and_below_64_in_every_message() {
    fn check(spec: &MessageSpec, seen: &mut BTreeSet<&'static str>) {
        let numbers: BTreeSet<u32> = spec.fields.iter().map(|f| f.number).collect();
        assert_eq!(numbers.len(), spec.fields.len(), "{}", spec.name);
        assert!(
            numbers.iter().all(|&n| (1..64).contains(&n)),
            "{}",
            spec.name
        );
        let mut sorted: Vec<u32> = spec.fields.iter().map(|f| f.number).collect();
        sorted.sort_unstable();
        let listed: Vec<u32> = spec.fields.iter().map(|f| f.number).collect();
        assert_eq!(sorted, listed, "{}: listed in number order", spec.name);
        seen.insert(spec.name);
        for f in &spec.fields {
            if let FieldType::Message(nested) = f.shape.ty {
                check(&nested(), seen);
            }
        }
    }
    let mut seen = BTreeSet::new();
    check(&TickRecord::spec(), &mut seen);
    assert_eq!(seen.len(), 8, "{seen:?}");
}

#[test]
fn a_message_without_a_mode_or_a_link_state_is_refused_naming_the_field() {
    let bad = |field: &str, value: i64| WireError::BadValue {
        field: field.into(),
        value,
    };
    assert_eq!(TickRecord::decode(&[]).unwrap_err(), bad("mode", 0));
    let mut buf = Vec::new();
    TickRecord::at_rest(0, 0.0, Mode::Manual).encode_to(&mut buf);
    assert!(TickRecord::decode(&buf).is_ok());
    // Field 15 (link) holding field 5 (state) = 9.
    buf.extend_from_slice(&[0x7a, 0x02, 0x28, 0x09]);
    assert_eq!(TickRecord::decode(&buf).unwrap_err(), bad("link.state", 9));
    assert!(matches!(
        TickRecord::decode(&[0xff, 0xff, 0xff]),
        Err(WireError::Malformed(_))
    ));
    // A nested length beyond the buffer.
    assert!(matches!(
        TickRecord::decode(&[0x2a, 0x40, 0x08]),
        Err(WireError::Malformed(_))
    ));
}

#[test]
fn unknown_fields_are_skipped() {
    let r = TickRecord::at_rest(3, 60.0, Mode::Reactive);
    let mut buf = Vec::new();
    r.encode_to(&mut buf);
    // Field 40, a string "x", from a newer writer.
    buf.extend_from_slice(&[0xc2, 0x02, 0x01, b'x']);
    assert!(same(&TickRecord::decode(&buf).unwrap(), &r));
}
