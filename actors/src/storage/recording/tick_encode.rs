//! Encodes a [`TickRecord`] as a `pavlov.Tick` protobuf message straight from the record, on the
//! recorder's thread for every tick.
//!
//! Why not `prost`'s derived encoder on the [`super::tick_pb::Tick`] struct: filling that struct copies
//! the record, and the derived code computes the length of every nested message once per level above it
//! (the raw sensor snapshot four times); this writes each nested message once into a scratch buffer and
//! copies it behind its length. It uses `prost`'s wire-format functions, writes the fields in the same
//! order with the same presence rules, and a test checks it produces exactly the derived encoder's bytes
//! for records that use every field, so the two (and the schema both follow) cannot drift apart.

use pavlov::record::TickRecord;
use prost::encoding::{self, WireType, encode_key, encode_varint};

use super::tick_pb::{
    PbMode, PbSafetyStop, mode_to_pb, skeleton_to_pb, state_to_pb, stop_to_pb, trip_to_pb,
    uncertain,
};

/// Reusable buffers, so that encoding allocates nothing once warm.
#[derive(Debug, Default)]
pub struct TickEncoder {
    outer: Vec<u8>,
    inner: Vec<u8>,
    raw: Vec<u8>,
}

/// Writes `body` (already encoded into `scratch`) as field `tag` of `buf`.
fn nested(buf: &mut Vec<u8>, tag: u32, scratch: &[u8]) {
    encode_key(tag, WireType::LengthDelimited, buf);
    encode_varint(scratch.len() as u64, buf);
    buf.extend_from_slice(scratch);
}

fn varint_field(buf: &mut Vec<u8>, tag: u32, v: u64) {
    if v != 0 {
        encoding::uint64::encode(tag, &v, buf);
    }
}

fn bool_field(buf: &mut Vec<u8>, tag: u32, v: bool) {
    if v {
        encoding::bool::encode(tag, &v, buf);
    }
}

fn sint32_field(buf: &mut Vec<u8>, tag: u32, v: i32) {
    if v != 0 {
        encoding::sint32::encode(tag, &v, buf);
    }
}

fn enum_field(buf: &mut Vec<u8>, tag: u32, v: i32) {
    if v != 0 {
        encoding::int32::encode(tag, &v, buf);
    }
}

fn opt_sint32(buf: &mut Vec<u8>, tag: u32, v: Option<i32>) {
    if let Some(v) = v {
        encoding::sint32::encode(tag, &v, buf);
    }
}

fn opt_double(buf: &mut Vec<u8>, tag: u32, v: Option<f64>) {
    if let Some(v) = v {
        encoding::double::encode(tag, &v, buf);
    }
}

fn wheels(buf: &mut Vec<u8>, tag: u32, a: pavlov::control::Action, scratch: &mut Vec<u8>) {
    scratch.clear();
    sint32_field(scratch, 1, i32::from(a.left_mm_s));
    sint32_field(scratch, 2, i32::from(a.right_mm_s));
    nested(buf, tag, scratch);
}

impl TickEncoder {
    /// The message for `r` (see [`super::tick_pb`] for what it holds), valid until the next call.
    pub fn encode(&mut self, r: &TickRecord) -> &[u8] {
        let TickEncoder {
            outer: buf,
            inner: scratch,
            raw,
        } = self;
        buf.clear();
        varint_field(buf, 1, r.seq);
        opt_double(buf, 2, Some(r.t_ms));
        enum_field(buf, 3, mode_to_pb(r.mode) as i32);
        if let Some(age) = r.obs_age_ticks {
            encoding::uint32::encode(4, &age, buf);
        }
        // 5: sensors.
        let s = &r.sensors;
        scratch.clear();
        bool_field(scratch, 1, s.overcurrent_left);
        bool_field(scratch, 2, s.overcurrent_right);
        bool_field(scratch, 3, s.bump_left);
        bool_field(scratch, 4, s.bump_right);
        opt_sint32(scratch, 5, s.battery_current_ma);
        opt_sint32(scratch, 6, s.battery_voltage_mv);
        opt_sint32(scratch, 7, s.battery_charge_mah);
        sint32_field(scratch, 8, s.distance_mm);
        sint32_field(scratch, 9, s.angle_deg);
        opt_sint32(scratch, 10, s.oi_mode);
        nested(buf, 5, scratch);
        // 6: elbow.
        if let Some(e) = &r.elbow {
            scratch.clear();
            opt_double(scratch, 1, e.left);
            opt_double(scratch, 2, e.left_avg);
            opt_double(scratch, 3, e.right);
            opt_double(scratch, 4, e.right_avg);
            enum_field(scratch, 5, skeleton_to_pb(e.skeleton) as i32);
            nested(buf, 6, scratch);
        }
        bool_field(buf, 7, r.stimulus);
        // 8: predictions.
        for p in &r.predictions {
            scratch.clear();
            if !p.name.is_empty() {
                encoding::string::encode(1, &p.name, scratch);
            }
            opt_double(scratch, 2, Some(p.value));
            opt_double(scratch, 3, Some(p.threshold));
            nested(buf, 8, scratch);
        }
        bool_field(buf, 9, r.gate);
        wheels(buf, 10, r.default_action, scratch);
        wheels(buf, 11, r.command, scratch);
        enum_field(buf, 12, stop_to_pb(r.safety_stop) as i32);
        bool_field(buf, 13, r.estop);
        varint_field(buf, 14, u64::from(r.lateness_us));
        // 15: link.
        let l = &r.link;
        scratch.clear();
        bool_field(scratch, 1, l.up);
        varint_field(scratch, 2, l.good_frames);
        varint_field(scratch, 3, l.bad_frames);
        varint_field(scratch, 4, l.skipped_bytes);
        enum_field(scratch, 5, state_to_pb(l.state) as i32);
        if let Some(m) = l.mode {
            encoding::uint32::encode(6, &u32::from(m), scratch);
        }
        enum_field(scratch, 7, trip_to_pb(l.trip) as i32);
        varint_field(scratch, 8, l.reconnects);
        varint_field(scratch, 9, l.stale_events);
        nested(buf, 15, scratch);
        match &r.inputs {
            // 16: inputs, with 1: the raw snapshot inside.
            Some(inputs) => {
                scratch.clear();
                if let Some(v) = &inputs.values {
                    // Absent slots are 0; the ones after the last present packet are left out.
                    let (slots, present) = v.slots();
                    let used = (64 - present.leading_zeros() as usize).min(slots.len());
                    raw.clear();
                    if used > 0 {
                        encoding::sint32::encode_packed(1, &slots[..used], raw);
                    }
                    if present != 0 {
                        encoding::fixed64::encode(2, &present, raw);
                    }
                    nested(scratch, 1, raw);
                }
                bool_field(scratch, 2, inputs.forced_stimulus);
                bool_field(scratch, 3, inputs.previous_followed_default);
                opt_double(scratch, 4, uncertain(inputs.previous_behaviour_prob));
                nested(buf, 16, scratch);
            }
            // 17: the observation, when there are no inputs to recompute it from.
            None => {
                if !r.obs.is_empty() {
                    encoding::float::encode_packed(17, &r.obs, buf);
                }
            }
        }
        // 18: what engaged the gate, when something did.
        if let Some(rule) = &r.rule {
            encoding::string::encode(18, rule, buf);
        }
        // 19: the behaviour probability, when it is not 1.
        opt_double(buf, 19, uncertain(r.behaviour_prob));
        buf
    }
}

// The enum values the encoder writes are the schema's.
const _: () = assert!(PbMode::Unspecified as i32 == 0 && PbSafetyStop::None as i32 == 0);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::storage::recording::schema::TICK_DESCRIPTOR_SET;
    use crate::storage::recording::tick_pb;
    use prost::Message as _;
    use prost::encoding::{DecodeContext, decode_key, decode_varint, skip_field};
    use prost_types::field_descriptor_proto::Type;
    use prost_types::{FileDescriptorProto, FileDescriptorSet};
    use std::collections::BTreeSet;

    /// Adds to `seen` the (message, field number) of every field in `bytes`, a `message` of `file`,
    /// and of the messages nested in it.
    fn fields_in(
        file: &FileDescriptorProto,
        message: &str,
        mut bytes: &[u8],
        seen: &mut BTreeSet<(String, i32)>,
    ) {
        let m = file
            .message_type
            .iter()
            .find(|m| m.name() == message)
            .unwrap();
        while !bytes.is_empty() {
            let (tag, wire) = decode_key(&mut bytes).unwrap();
            seen.insert((message.to_string(), tag as i32));
            let field = m.field.iter().find(|f| f.number() == tag as i32);
            match field {
                Some(f) if f.r#type() == Type::Message => {
                    let len = decode_varint(&mut bytes).unwrap() as usize;
                    let (inner, rest) = bytes.split_at(len);
                    let nested = f.type_name().rsplit('.').next().unwrap();
                    fields_in(file, nested, inner, seen);
                    bytes = rest;
                }
                _ => skip_field(wire, tag, &mut bytes, DecodeContext::default()).unwrap(),
            }
        }
    }

    #[test]
    fn every_field_of_tick_proto_is_written_for_some_record() {
        // A field added to tick.proto that the encoder never writes fails here (the test records use
        // every field of the record).
        let set = FileDescriptorSet::decode(TICK_DESCRIPTOR_SET).unwrap();
        let file = &set.file[0];
        let mut enc = TickEncoder::default();
        let mut seen = BTreeSet::new();
        for r in &tick_pb::tests::records() {
            fields_in(file, "Tick", enc.encode(r), &mut seen);
        }
        let declared: BTreeSet<(String, i32)> = file
            .message_type
            .iter()
            .flat_map(|m| m.field.iter().map(|f| (m.name().to_string(), f.number())))
            .collect();
        let never: Vec<_> = declared.difference(&seen).collect();
        assert!(never.is_empty(), "fields never written: {never:?}");
        assert_eq!(seen, declared);
    }

    #[test]
    fn it_writes_exactly_the_derived_encoders_bytes_for_every_record() {
        let mut enc = TickEncoder::default();
        let records = tick_pb::tests::records();
        assert!(records.len() >= 10);
        for r in &records {
            let derived = tick_pb::from_record(r).encode_to_vec();
            assert_eq!(enc.encode(r), derived.as_slice(), "tick {}", r.seq);
        }
    }
}
