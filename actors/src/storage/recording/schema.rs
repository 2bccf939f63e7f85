//! What an MCAP recording declares: its channels (topics), the schema of each, and the provenance
//! metadata record. The writer (`super::mcap_write`) and the reader (`super::mcap_read`) both take
//! their names from here, and so does the channel table in `docs/src/recordings.md`.
//!
//! - `ticks`: one `pavlov.Tick` per tick, protobuf; the schema is the `FileDescriptorSet` derived from
//!   the tick record's wire declaration (`TICK_DESCRIPTOR_SET`, built in `super::tick_descriptor`).
//! - `events`, `config`, `learner`: JSON with a JSON Schema.
//! - Metadata `pavlov.recording`: format, program, label, UTC start, seed, where the run stood.

use std::sync::LazyLock;

use pavlov::event::EventKind;
/// Topic of the tick records.
pub const TICKS: &str = "ticks";
/// Topic of the events.
pub const EVENTS: &str = "events";
/// Topic of the configuration in force (one message, at the start).
pub const CONFIG: &str = "config";
/// Topic of the learner's state (one message, at the start: where the recording begins).
pub const LEARNER: &str = "learner";

/// The protobuf type of a tick message.
pub(crate) const TICK_SCHEMA_NAME: &str = "pavlov.Tick";
/// The name of the metadata record with the provenance.
pub const METADATA_NAME: &str = "pavlov.recording";
/// The format written into the metadata (`format` key): the one format version of both encodings.
pub(crate) const MCAP_FORMAT: &str = super::FORMAT;

/// The JSON Schema of an `events` message; its list of kinds is [`EventKind::NAMES`], derived from the
/// enum (the text around it is as it always was, byte for byte).
pub(crate) static EVENT_SCHEMA: LazyLock<String> = LazyLock::new(|| {
    let kinds: Vec<String> = EventKind::NAMES
        .iter()
        .map(|k| format!("\"{k}\""))
        .collect();
    format!(
        r#"{{"title":"pavlov.Event","description":"A change made at run time (pavlov::event::Event): it applies from the tick after `after`; the other fields depend on `kind`.","type":"object","properties":{{"id":{{"type":"integer","description":"Position in the order events were made"}},"after":{{"type":["integer","null"],"description":"The last tick its owner had handled when it took effect (null: before the first)"}},"kind":{{"type":"string","enum":[{}]}}}},"required":["id","after","kind"]}}"#,
        kinds.join(",")
    )
});

/// The JSON Schema of the `config` message.
pub(crate) const CONFIG_SCHEMA: &str = r#"{"title":"pavlov.Config","description":"The configuration in force, every key as in config/README.md; [sim] seed is the run's seed.","type":"object","properties":{"robot":{"type":"object"},"tick":{"type":"object"},"safety":{"type":"object"},"link":{"type":"object"},"control":{"type":"object"},"predictions":{"type":"array","items":{"type":"object"}},"sim":{"type":"object"},"dashboard":{"type":"object"},"checkpoint":{"type":"object"},"skeleton":{"type":"object"}},"required":["robot","tick","control","predictions","sim"]}"#;

/// The JSON Schema of a `learner` message.
pub(crate) const LEARNER_SCHEMA: &str = r#"{"title":"pavlov.StartState","description":"Where the run stood when the recording began: the ticks recorded are those after `after`, the events those with id >= `events_before`; `learner` is the learner's complete state then (weights, traces, parameters in force, previous step, stall level).","type":"object","properties":{"after":{"type":["integer","null"]},"events_before":{"type":"integer"},"learner":{"type":"object","properties":{"predictions":{"type":"object","properties":{"predictions":{"type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"alpha":{"type":"number"},"lambda":{"type":"number"},"threshold":{},"weights":{"type":"array","items":{"type":"number"}},"traces":{"type":"array","items":{"type":"number"}},"previous":{}}}}}},"stall_level":{"type":"integer"}}}},"required":["after","events_before","learner"]}"#;

/// The `ticks` channel's schema: the serialised `FileDescriptorSet` of `pavlov/tick.proto`.
pub(crate) use super::tick_descriptor::TICK_DESCRIPTOR_SET;

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::event::Event;
    use prost::Message as _;
    use prost_types::field_descriptor_proto::Type;
    use prost_types::{DescriptorProto, FileDescriptorSet};

    #[test]
    fn the_json_schemas_are_json_objects() {
        for s in [&EVENT_SCHEMA, CONFIG_SCHEMA, LEARNER_SCHEMA] {
            let v: serde_json::Value = serde_json::from_str(s).unwrap();
            assert_eq!(v["type"], "object");
        }
    }

    #[test]
    fn the_event_schema_names_every_kind() {
        let v: serde_json::Value = serde_json::from_str(&EVENT_SCHEMA).unwrap();
        let listed: Vec<&str> = v["properties"]["kind"]["enum"]
            .as_array()
            .unwrap()
            .iter()
            .map(|k| k.as_str().unwrap())
            .collect();
        assert_eq!(listed, EventKind::NAMES);
        for k in EventKind::examples() {
            let json = serde_json::to_value(Event {
                id: 1,
                after: None,
                kind: k,
            })
            .unwrap();
            assert!(listed.contains(&json["kind"].as_str().unwrap()));
        }
    }

    #[test]
    fn the_tick_descriptor_reads_back_with_optional_fields_in_synthetic_oneofs() {
        let set = FileDescriptorSet::decode(TICK_DESCRIPTOR_SET.as_slice()).unwrap();
        let file = &set.file[0];
        assert_eq!(file.package(), "pavlov");
        let tick = &file.message_type[0];
        assert_eq!(tick.name(), "Tick");
        let age = tick
            .field
            .iter()
            .find(|f| f.name() == "obs_age_ticks")
            .unwrap();
        assert_eq!(age.proto3_optional, Some(true));
        let oneof = &tick.oneof_decl[age.oneof_index.unwrap() as usize];
        assert_eq!(oneof.name(), "_obs_age_ticks");
        let rule = tick.field.iter().find(|f| f.name() == "rule").unwrap();
        assert_eq!((rule.number(), rule.proto3_optional), (18, Some(true)));
        assert_eq!(rule.r#type(), Type::String);
        // Every message or enum a field names is declared.
        let declared: Vec<String> = file
            .message_type
            .iter()
            .map(|m| format!(".pavlov.{}", m.name()))
            .chain(
                file.enum_type
                    .iter()
                    .map(|e| format!(".pavlov.{}", e.name())),
            )
            .collect();
        for m in &file.message_type {
            for field in &m.field {
                if let Some(t) = &field.type_name {
                    assert!(declared.contains(t), "{}.{}: {t}", m.name(), field.name());
                }
            }
        }
    }

    /// A message's fields as (name, number, label, type, type name, explicit presence), sorted by number.
    fn fields(m: &DescriptorProto) -> Vec<(String, i32, i32, i32, String, bool)> {
        let mut out: Vec<_> = m
            .field
            .iter()
            .map(|f| {
                (
                    f.name().to_string(),
                    f.number(),
                    f.label() as i32,
                    f.r#type() as i32,
                    f.type_name().to_string(),
                    f.proto3_optional(),
                )
            })
            .collect();
        out.sort_by_key(|f| f.1);
        out
    }

    #[test]
    fn the_compiled_schema_declares_every_field_of_the_one_recordings_were_written_with() {
        // The hand-built descriptor every `pavlov-recording/3` file carried before the derived one (see
        // tests/data/README.md): each of its messages, fields and enum values is in the compiled one with
        // the same number, label, type, type name and presence, so those recordings read as they did.
        let old = include_bytes!("../../../../tests/data/tick_descriptor_recording3.bin");
        let old = FileDescriptorSet::decode(old.as_slice()).unwrap();
        let new = FileDescriptorSet::decode(TICK_DESCRIPTOR_SET.as_slice()).unwrap();
        let (old, new) = (&old.file[0], &new.file[0]);
        assert_eq!(
            (old.name(), old.package(), old.syntax()),
            (new.name(), new.package(), new.syntax())
        );
        assert_eq!(old.message_type.len(), 8);
        for m in &old.message_type {
            let compiled = new
                .message_type
                .iter()
                .find(|n| n.name() == m.name())
                .unwrap_or_else(|| panic!("message {} is gone", m.name()));
            let now = fields(compiled);
            for f in fields(m) {
                assert!(now.contains(&f), "{}: {f:?} changed or is gone", m.name());
            }
        }
        for e in &old.enum_type {
            let compiled = new
                .enum_type
                .iter()
                .find(|n| n.name() == e.name())
                .unwrap_or_else(|| panic!("enum {} is gone", e.name()));
            let values = |e: &prost_types::EnumDescriptorProto| {
                e.value
                    .iter()
                    .map(|v| (v.name().to_string(), v.number()))
                    .collect::<Vec<_>>()
            };
            for v in values(e) {
                assert!(values(compiled).contains(&v), "{}: {v:?}", e.name());
            }
        }
        // The comparison can fail: a field with another number is caught.
        let mut moved = old.message_type[0].clone();
        moved.field[0].number = Some(99);
        assert!(!fields(&new.message_type[0]).contains(&fields(&moved)[17]));
    }
}
