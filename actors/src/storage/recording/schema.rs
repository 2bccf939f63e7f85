//! What an MCAP recording declares: its channels (topics), the schema of each, and the provenance
//! metadata record. The writer (`super::mcap_write`) and the reader (`super::mcap_read`) both take
//! their names from here, and so does the channel table in `docs/src/recordings.md`.
//!
//! - `ticks`: one `pavlov.Tick` per tick, protobuf; the schema is a `FileDescriptorSet` built here by hand
//!   to match `super::tick_pb` field for field (the independent-reader test decodes every message with
//!   it, so a mismatch fails there).
//! - `events`, `config`, `learner`: JSON with a JSON Schema.
//! - Metadata `pavlov.recording`: format, program, label, UTC start, seed, where the run stood.

use std::sync::LazyLock;

use pavlov::event::EventKind;
use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{
    DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
    FileDescriptorProto, FileDescriptorSet, OneofDescriptorProto,
};

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

/// One field of a message descriptor.
struct F {
    name: &'static str,
    number: i32,
    ty: Type,
    /// `.pavlov.X` for messages and enums.
    type_name: Option<&'static str>,
    repeated: bool,
    /// A proto3 `optional` scalar (explicit presence).
    optional: bool,
}

const fn f(name: &'static str, number: i32, ty: Type) -> F {
    F {
        name,
        number,
        ty,
        type_name: None,
        repeated: false,
        optional: false,
    }
}

const fn opt(name: &'static str, number: i32, ty: Type) -> F {
    F {
        optional: true,
        ..f(name, number, ty)
    }
}

const fn typed(name: &'static str, number: i32, ty: Type, type_name: &'static str) -> F {
    F {
        type_name: Some(type_name),
        ..f(name, number, ty)
    }
}

const fn list(name: &'static str, number: i32, ty: Type, type_name: Option<&'static str>) -> F {
    F {
        type_name,
        repeated: true,
        ..f(name, number, ty)
    }
}

fn message(name: &str, fields: &[F]) -> DescriptorProto {
    let mut oneofs = Vec::new();
    let field = fields
        .iter()
        .map(|x| {
            // A proto3 optional field is the only member of a synthetic oneof `_name`.
            let oneof_index = x.optional.then(|| {
                oneofs.push(OneofDescriptorProto {
                    name: Some(format!("_{}", x.name)),
                    options: None,
                });
                oneofs.len() as i32 - 1
            });
            FieldDescriptorProto {
                name: Some(x.name.to_string()),
                number: Some(x.number),
                label: Some(if x.repeated {
                    Label::Repeated
                } else {
                    Label::Optional
                } as i32),
                r#type: Some(x.ty as i32),
                type_name: x.type_name.map(str::to_string),
                json_name: None,
                oneof_index,
                proto3_optional: x.optional.then_some(true),
                ..FieldDescriptorProto::default()
            }
        })
        .collect();
    DescriptorProto {
        name: Some(name.to_string()),
        field,
        oneof_decl: oneofs,
        ..DescriptorProto::default()
    }
}

fn enumeration(name: &str, values: &[&str]) -> EnumDescriptorProto {
    EnumDescriptorProto {
        name: Some(name.to_string()),
        value: values
            .iter()
            .enumerate()
            .map(|(i, v)| EnumValueDescriptorProto {
                name: Some((*v).to_string()),
                number: Some(i as i32),
                options: None,
            })
            .collect(),
        ..EnumDescriptorProto::default()
    }
}

/// The `pavlov/tick.proto` file: `pavlov.Tick` and the messages and enums it uses.
fn tick_file() -> FileDescriptorProto {
    use Type::*;
    let tick = message(
        "Tick",
        &[
            f("seq", 1, Uint64),
            opt("t_ms", 2, Double),
            typed("mode", 3, Enum, ".pavlov.Mode"),
            opt("obs_age_ticks", 4, Uint32),
            typed("sensors", 5, Message, ".pavlov.Sensors"),
            typed("elbow", 6, Message, ".pavlov.Elbow"),
            f("stimulus", 7, Bool),
            list("predictions", 8, Message, Some(".pavlov.Prediction")),
            f("gate", 9, Bool),
            typed("default_action", 10, Message, ".pavlov.Wheels"),
            typed("command", 11, Message, ".pavlov.Wheels"),
            typed("safety_stop", 12, Enum, ".pavlov.SafetyStop"),
            f("estop", 13, Bool),
            f("lateness_us", 14, Uint32),
            typed("link", 15, Message, ".pavlov.Link"),
            typed("inputs", 16, Message, ".pavlov.Inputs"),
            list("obs", 17, Float, None),
            opt("rule", 18, String),
        ],
    );
    let sensors = message(
        "Sensors",
        &[
            f("overcurrent_left", 1, Bool),
            f("overcurrent_right", 2, Bool),
            f("bump_left", 3, Bool),
            f("bump_right", 4, Bool),
            opt("battery_current_ma", 5, Sint32),
            opt("battery_voltage_mv", 6, Sint32),
            opt("battery_charge_mah", 7, Sint32),
            f("distance_mm", 8, Sint32),
            f("angle_deg", 9, Sint32),
            opt("oi_mode", 10, Sint32),
        ],
    );
    let elbow = message(
        "Elbow",
        &[
            opt("left", 1, Double),
            opt("left_avg", 2, Double),
            opt("right", 3, Double),
            opt("right_avg", 4, Double),
            typed("skeleton", 5, Enum, ".pavlov.SkeletonStatus"),
        ],
    );
    let prediction = message(
        "Prediction",
        &[
            f("name", 1, String),
            opt("value", 2, Double),
            opt("threshold", 3, Double),
        ],
    );
    let wheels = message(
        "Wheels",
        &[f("left_mm_s", 1, Sint32), f("right_mm_s", 2, Sint32)],
    );
    let link = message(
        "Link",
        &[
            f("up", 1, Bool),
            f("good_frames", 2, Uint64),
            f("bad_frames", 3, Uint64),
            f("skipped_bytes", 4, Uint64),
            typed("state", 5, Enum, ".pavlov.LinkState"),
            opt("mode", 6, Uint32),
            typed("trip", 7, Enum, ".pavlov.TripCause"),
            f("reconnects", 8, Uint64),
            f("stale_events", 9, Uint64),
        ],
    );
    let inputs = message(
        "Inputs",
        &[
            typed("values", 1, Message, ".pavlov.RawSensors"),
            f("forced_stimulus", 2, Bool),
            f("previous_followed_default", 3, Bool),
        ],
    );
    let raw = message(
        "RawSensors",
        &[list("values", 1, Sint32, None), f("present", 2, Fixed64)],
    );
    FileDescriptorProto {
        name: Some("pavlov/tick.proto".into()),
        package: Some("pavlov".into()),
        message_type: vec![tick, sensors, elbow, prediction, wheels, link, inputs, raw],
        enum_type: vec![
            enumeration(
                "Mode",
                &[
                    "MODE_UNSPECIFIED",
                    "MODE_REACTIVE",
                    "MODE_PAVLOVIAN",
                    "MODE_MANUAL",
                ],
            ),
            enumeration(
                "SafetyStop",
                &[
                    "SAFETY_STOP_NONE",
                    "SAFETY_STOP_E_STOP",
                    "SAFETY_STOP_STALE_OBSERVATION",
                    "SAFETY_STOP_LINK_DOWN",
                    "SAFETY_STOP_ROBOT_TRIPPED",
                ],
            ),
            enumeration(
                "LinkState",
                &[
                    "LINK_STATE_UNSPECIFIED",
                    "LINK_STATE_UP",
                    "LINK_STATE_STALE",
                    "LINK_STATE_RECONNECTING",
                    "LINK_STATE_TRIPPED",
                    "LINK_STATE_DOWN",
                ],
            ),
            enumeration(
                "SkeletonStatus",
                &[
                    "SKELETON_STATUS_NONE",
                    "SKELETON_STATUS_TRACKED",
                    "SKELETON_STATUS_STALE",
                ],
            ),
            enumeration(
                "TripCause",
                &[
                    "TRIP_CAUSE_NONE",
                    "TRIP_CAUSE_WHEEL_DROP",
                    "TRIP_CAUSE_CLIFF",
                    "TRIP_CAUSE_CHARGER",
                    "TRIP_CAUSE_UNKNOWN",
                ],
            ),
        ],
        syntax: Some("proto3".into()),
        ..FileDescriptorProto::default()
    }
}

/// The `ticks` channel's schema: a serialised `FileDescriptorSet` holding `pavlov/tick.proto`.
pub(crate) fn tick_descriptor_set() -> Vec<u8> {
    FileDescriptorSet {
        file: vec![tick_file()],
    }
    .encode_to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::event::Event;

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
        let set = FileDescriptorSet::decode(tick_descriptor_set().as_slice()).unwrap();
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
}
