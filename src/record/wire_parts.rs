//! The wire form of the types a tick record borrows from the rest of the core: the enums (mode, safety
//! stop, link state, skeleton status, trip cause), the wheel speeds (`Wheels`) and the raw sensor
//! snapshot (`RawSensors`). Their numbers and names are those every `pavlov-recording/3` file was written
//! with; a number is never changed or reused.

use super::SafetyStop;
use super::wire::{
    self, FieldSpec, FieldType, Message, MessageSpec, Presence, Scalar, Shape, WireError,
    message_fields, wire_enum, wire_message,
};
use crate::control::{Action, Mode};
use crate::oi::SensorValues;
use crate::oi::sensors::PACKET_SLOTS;
use crate::skeleton::SkeletonStatus;
use crate::supervision::{LinkState, TripCause};
use prost::encoding::{self, DecodeContext};

wire_enum! { Mode, "Mode", unspecified "MODE_UNSPECIFIED";
    Mode::Reactive => 1, "MODE_REACTIVE";
    Mode::Pavlovian => 2, "MODE_PAVLOVIAN";
    Mode::Manual => 3, "MODE_MANUAL";
}

// Why actuation overrode the gate's action (`NONE`: it did not).
wire_enum! { Option<SafetyStop>, "SafetyStop";
    None => 0, "SAFETY_STOP_NONE";
    Some(SafetyStop::EStop) => 1, "SAFETY_STOP_E_STOP";
    Some(SafetyStop::StaleObservation) => 2, "SAFETY_STOP_STALE_OBSERVATION";
    Some(SafetyStop::LinkDown) => 3, "SAFETY_STOP_LINK_DOWN";
    Some(SafetyStop::RobotTripped) => 4, "SAFETY_STOP_ROBOT_TRIPPED";
}

wire_enum! { LinkState, "LinkState", unspecified "LINK_STATE_UNSPECIFIED";
    LinkState::Up => 1, "LINK_STATE_UP";
    LinkState::Stale => 2, "LINK_STATE_STALE";
    LinkState::Reconnecting => 3, "LINK_STATE_RECONNECTING";
    LinkState::Tripped => 4, "LINK_STATE_TRIPPED";
    LinkState::Down => 5, "LINK_STATE_DOWN";
}

// Whether a skeleton is coming in (`NONE`: nobody tracked, the default of recordings made before it).
wire_enum! { SkeletonStatus, "SkeletonStatus";
    SkeletonStatus::Absent => 0, "SKELETON_STATUS_NONE";
    SkeletonStatus::Tracked => 1, "SKELETON_STATUS_TRACKED";
    SkeletonStatus::Stale => 2, "SKELETON_STATUS_STALE";
}

// Why the robot tripped to Passive (`NONE`: it is not tripped).
wire_enum! { Option<TripCause>, "TripCause";
    None => 0, "TRIP_CAUSE_NONE";
    Some(TripCause::WheelDrop) => 1, "TRIP_CAUSE_WHEEL_DROP";
    Some(TripCause::Cliff) => 2, "TRIP_CAUSE_CLIFF";
    Some(TripCause::Charger) => 3, "TRIP_CAUSE_CHARGER";
    Some(TripCause::Unknown) => 4, "TRIP_CAUSE_UNKNOWN";
}

// Wheel speeds, mm/s.
wire_message! { Action, "Wheels", blank Action::STOP;
    1 => left_mm_s,
    2 => right_mm_s,
}

/// A raw sensor snapshot, `RawSensors`: `values[id]` is packet `id`'s value when bit `id` of `present` is
/// set (and 0 otherwise); the slots after the last present packet are left out.
impl Message for SensorValues {
    fn spec() -> MessageSpec {
        MessageSpec {
            name: "RawSensors",
            fields: vec![
                FieldSpec {
                    number: 1,
                    name: "values",
                    shape: Shape {
                        ty: FieldType::Scalar(Scalar::Sint32),
                        presence: Presence::Repeated,
                    },
                },
                FieldSpec {
                    number: 2,
                    name: "present",
                    shape: Shape {
                        ty: FieldType::Scalar(Scalar::Fixed64),
                        presence: Presence::Implicit,
                    },
                },
            ],
        }
    }

    fn blank() -> Self {
        SensorValues::new()
    }

    fn encode_fields(&self, buf: &mut Vec<u8>) {
        let (slots, present) = self.slots();
        let used = (64 - present.leading_zeros() as usize).min(slots.len());
        // Nothing when no slot is used.
        super::wire_put::put_packed_sint32(buf, 1, &slots[..used]);
        if present != 0 {
            super::wire_put::put_fixed64(buf, 2, present);
        }
    }

    fn merge_fields(&mut self, mut buf: &[u8]) -> Result<(), WireError> {
        let mut values = Vec::new();
        let mut present = 0u64;
        while !buf.is_empty() {
            let (number, wire_type) = wire::next_key(&mut buf)?;
            let ctx = DecodeContext::default();
            match number {
                1 => encoding::sint32::merge_repeated(wire_type, &mut values, &mut buf, ctx),
                2 => encoding::fixed64::merge(wire_type, &mut present, &mut buf, ctx),
                other => {
                    wire::skip(wire_type, other, &mut buf)?;
                    Ok(())
                }
            }
            .map_err(|e| WireError::Malformed(e.to_string()))?;
        }
        if present >> PACKET_SLOTS != 0 {
            // The bit pattern, as the signed number it reads as.
            return Err(WireError::bad(present as i64).within("present"));
        }
        for id in 0..PACKET_SLOTS {
            if present >> id & 1 == 1 {
                // `id` < 59 fits a u8.
                self.set(id as u8, values.get(id).copied().unwrap_or(0));
            }
        }
        Ok(())
    }
}

message_fields!(SensorValues);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::wire::Field;

    fn round_trip<T: Field + PartialEq + std::fmt::Debug>(v: T, blank: T) {
        let mut buf = Vec::new();
        v.encode_field(1, &mut buf);
        let mut back = blank;
        let mut rest = buf.as_slice();
        if !rest.is_empty() {
            let (n, w) = wire::next_key(&mut rest).unwrap();
            assert_eq!(n, 1);
            back.merge_field(w, &mut rest).unwrap();
        }
        assert!(rest.is_empty());
        assert_eq!(back, v);
    }

    #[test]
    fn every_enum_value_reads_back_and_zero_is_left_out() {
        for m in Mode::ALL {
            round_trip(m, Mode::Manual);
        }
        for s in LinkState::ALL {
            round_trip(s, LinkState::Down);
        }
        round_trip(Some(SafetyStop::RobotTripped), None);
        round_trip(Some(TripCause::Charger), None);
        round_trip(SkeletonStatus::Stale, SkeletonStatus::Absent);
        let mut buf = Vec::new();
        None::<SafetyStop>.encode_field(12, &mut buf);
        SkeletonStatus::Absent.encode_field(5, &mut buf);
        assert!(buf.is_empty(), "a zero enum is left out");
    }

    #[test]
    fn an_unspecified_or_unknown_enum_number_is_refused() {
        assert_eq!(Mode::Reactive.check_absent(), Err(WireError::bad(0)));
        assert_eq!(None::<TripCause>.check_absent(), Ok(()));
        let mut buf = Vec::new();
        encoding::int32::encode(3, &9, &mut buf);
        let mut rest = buf.as_slice();
        let (_, w) = wire::next_key(&mut rest).unwrap();
        let mut m = Mode::Reactive;
        assert_eq!(m.merge_field(w, &mut rest), Err(WireError::bad(9)));
    }

    #[test]
    fn a_snapshot_reads_back_and_a_bit_beyond_the_slots_is_refused() {
        let mut v = SensorValues::new();
        v.set(7, -3);
        v.set(22, 16_000);
        v.set(58, 1);
        let mut buf = Vec::new();
        v.encode_fields(&mut buf);
        assert_eq!(SensorValues::decode(&buf).unwrap(), v);
        let mut bad = Vec::new();
        encoding::fixed64::encode(2, &(1u64 << 60), &mut bad);
        let err = SensorValues::decode(&bad).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "field `present` holds {}, which is not a valid value",
                1i64 << 60
            )
        );
    }

    #[test]
    fn a_speed_beyond_i16_is_refused_naming_the_field() {
        let mut buf = Vec::new();
        encoding::sint32::encode(1, &40_000, &mut buf);
        let err = Action::decode(&buf).unwrap_err();
        assert_eq!(
            err,
            WireError::BadValue {
                field: "left_mm_s".into(),
                value: 40_000
            }
        );
    }
}
