//! The JSON Schemas of the Foxglove channels, written in the subset the Foxglove app reads.
//!
//! Foxglove turns a channel's JSON Schema into the field list its panels offer (message paths in Plot,
//! Raw Messages, …). It reads one `"type"` string per field (`boolean`, `string`, `number`, `integer`,
//! `object` with `properties`, `array` with typed `items`) and rejects anything else — a `["number",
//! "null"]` union, a missing type, an array of arrays — which would make the whole channel unusable. So a
//! field that may be `null` (a missing sensor packet, no elbow angles yet) is declared with its non-null
//! type, and the tests below check every schema against those rules and every field of real messages
//! against the schema.
//!
//! The schema of `/pavlov/ticks` is not written here: it is derived from the tick's one definition, the
//! record's types and their wire declaration (`pavlov::record`), through the descriptor the recordings
//! carry ([`TICK_DESCRIPTOR_SET`]), so a field added there appears in Foxglove's field lists with no line here
//! (the tests check that a [`TickRecord`](pavlov::record::TickRecord)'s JSON has exactly the descriptor's
//! fields, both ways).

use pavlov::event::EventKind;
use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{FileDescriptorProto, FileDescriptorSet};
use serde_json::{Map, Value, json};

use crate::storage::recording::schema::TICK_DESCRIPTOR_SET;

/// A field of one JSON type.
fn of(ty: &str) -> Value {
    json!({ "type": ty })
}

fn number() -> Value {
    of("number")
}

fn integer() -> Value {
    of("integer")
}

fn boolean() -> Value {
    of("boolean")
}

fn string() -> Value {
    of("string")
}

/// A string that is one of `values`.
fn one_of(values: &[&str]) -> Value {
    json!({ "type": "string", "enum": values })
}

fn array(items: Value) -> Value {
    json!({ "type": "array", "items": items })
}

/// An object with exactly these fields.
fn object<'a>(fields: impl IntoIterator<Item = (&'a str, Value)>) -> Value {
    let properties: Map<String, Value> = fields
        .into_iter()
        .map(|(name, schema)| (name.to_string(), schema))
        .collect();
    json!({ "type": "object", "properties": properties })
}

/// A titled top-level schema.
fn titled(title: &str, description: &str, mut schema: Value) -> Value {
    if let Some(map) = schema.as_object_mut() {
        map.insert("title".into(), title.into());
        map.insert("description".into(), description.into());
    }
    schema
}

fn action() -> Value {
    object([("left_mm_s", integer()), ("right_mm_s", integer())])
}

fn link_state() -> Value {
    one_of(&["up", "stale", "reconnecting", "tripped", "down"])
}

fn trip_cause() -> Value {
    one_of(&["wheel_drop", "cliff", "charger", "unknown"])
}

fn mode() -> Value {
    one_of(&pavlov::control::Mode::ALL.map(pavlov::control::Mode::name))
}

/// `SafetyStop` → `SAFETY_STOP`: the prefix of an enum's value names in the style protobuf asks for.
fn screaming(name: &str) -> String {
    let mut out = String::new();
    for (i, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

/// The JSON Schema of the message named `type_name` (`.pavlov.Tick`) in `file`, as the record it encodes
/// is written in JSON (serde's names): a field of the same name and the JSON type of its protobuf type, a
/// repeated field an array, a message an object, an enum a string among its value names without the
/// enum's prefix in lower case (`SAFETY_STOP_E_STOP` → `e_stop`; `*_UNSPECIFIED` is never written and
/// left out; `*_NONE` is listed as `none`, though a record whose option is `None` writes `null`).
fn from_descriptor(file: &FileDescriptorProto, type_name: &str) -> Value {
    let local = |t: &str| {
        t.strip_prefix('.')
            .and_then(|t| t.strip_prefix(file.package()))
            .and_then(|t| t.strip_prefix('.'))
            .unwrap_or(t)
            .to_string()
    };
    let name = local(type_name);
    let Some(message) = file.message_type.iter().find(|m| m.name() == name) else {
        return object([]);
    };
    let fields: Vec<(String, Value)> = message
        .field
        .iter()
        .map(|f| {
            let one = match f.r#type() {
                Type::Bool => boolean(),
                Type::String | Type::Bytes => string(),
                Type::Double | Type::Float => number(),
                Type::Message | Type::Group => from_descriptor(file, f.type_name()),
                Type::Enum => {
                    let name = local(f.type_name());
                    let prefix = format!("{}_", screaming(&name));
                    let values: Vec<String> = file
                        .enum_type
                        .iter()
                        .filter(|e| e.name() == name)
                        .flat_map(|e| &e.value)
                        .map(|v| v.name().strip_prefix(&prefix).unwrap_or(v.name()))
                        .filter(|v| *v != "UNSPECIFIED")
                        .map(str::to_ascii_lowercase)
                        .collect();
                    json!({ "type": "string", "enum": values })
                }
                _ => integer(),
            };
            let schema = if f.label() == Label::Repeated {
                array(one)
            } else {
                one
            };
            (f.name().to_string(), schema)
        })
        .collect();
    object(fields.iter().map(|(k, v)| (k.as_str(), v.clone())))
}

/// `pavlov.TickRecord`: a [`pavlov::record::TickRecord`] as the recorder writes it, derived from the
/// descriptor of `pavlov.Tick` (see the module doc).
pub(crate) fn tick_record() -> Value {
    let set = FileDescriptorSet::decode(TICK_DESCRIPTOR_SET.as_slice()).unwrap_or_default();
    let fields = set
        .file
        .iter()
        .find(|f| f.message_type.iter().any(|m| m.name() == "Tick"))
        .map_or_else(|| object([]), |file| from_descriptor(file, ".pavlov.Tick"));
    titled(
        "pavlov.TickRecord",
        "Everything that happened on one 20 ms tick (the recorder's record). Fields that can be null: \
         obs entries (a packet the snapshot lacks), obs_age_ticks, elbow, safety_stop, the battery and \
         mode sensors, link.mode, link.trip, inputs. rule (what engaged the gate: a rule's name or \
         `stimulus`) is absent while the gate is off.",
        fields,
    )
}

/// `pavlov.Signals`: the flat message of [`super::signals`], with the run's own observation and
/// prediction names as fields.
pub(crate) fn signals(obs_names: &[String], predictions: &[String]) -> Value {
    let named = |names: &[String]| object(names.iter().map(|n| (n.as_str(), number())));
    titled(
        "pavlov.Signals",
        "One tick as flat numbers: observations and predictions by name, flags as 0/1.",
        object([
            ("seq", integer()),
            ("t_ms", number()),
            ("mode", mode()),
            ("obs", named(obs_names)),
            ("predictions", named(predictions)),
            ("thresholds", named(predictions)),
            ("stimulus", integer()),
            ("gate", integer()),
            ("estop", integer()),
            ("safety_stop", integer()),
            ("command_left_mm_s", integer()),
            ("command_right_mm_s", integer()),
            ("default_left_mm_s", integer()),
            ("default_right_mm_s", integer()),
            ("overcurrent_left", integer()),
            ("overcurrent_right", integer()),
            ("bump_left", integer()),
            ("bump_right", integer()),
            ("battery_current_ma", number()),
            ("battery_voltage_mv", number()),
            ("battery_charge_mah", number()),
            ("distance_mm", integer()),
            ("angle_deg", integer()),
            ("elbow_left", number()),
            ("elbow_right", number()),
            ("obs_age_ticks", number()),
            ("lateness_us", integer()),
            ("link_up", integer()),
        ]),
    )
}

/// The JSON type of a field's value in an example, for a field of an event kind not typed by hand in
/// [`event`].
fn inferred(value: &Value) -> Value {
    match value {
        Value::Bool(_) => boolean(),
        Value::Number(n) if n.is_f64() => number(),
        Value::Number(_) => integer(),
        Value::Object(fields) => object(fields.iter().map(|(k, v)| (k.as_str(), inferred(v)))),
        Value::Array(items) => array(items.first().map_or_else(string, inferred)),
        Value::String(_) | Value::Null => string(),
    }
}

/// `pavlov.Event`: a [`pavlov::event::Event`], flat, with the fields of every kind (each event carries
/// only its own kind's). The kinds are [`EventKind::NAMES`]; the fields typed here are those whose type is
/// richer than their JSON (the enums of states and causes); any other field of a kind's
/// [`EventKind::example`] is declared with the type of its value there, so a new kind needs no line here.
pub(crate) fn event() -> Value {
    let mut schema = titled(
        "pavlov.Event",
        "A change made at run time (mode, e-stop, teleop, request, learning parameters, weights, \
         recording, link), numbered, with the last tick before it took effect.",
        object([
            ("id", integer()),
            ("after", integer()),
            ("kind", one_of(EventKind::NAMES)),
            // mode_set: a control mode; rearm: the OI mode sent (safe, full).
            ("mode", string()),
            ("action", action()),
            ("latched", boolean()),
            ("cause", trip_cause()),
            ("until_tick", integer()),
            ("prediction", string()),
            ("alpha", number()),
            ("lambda", number()),
            ("threshold", number()),
            ("path", string()),
            // recording_stopped (when writing failed) and checkpoint_failed: the error.
            ("reason", string()),
            ("state", link_state()),
            ("trip", trip_cause()),
            ("reconnects", integer()),
            ("ticks", integer()),
        ]),
    );
    if let Some(declared) = schema["properties"].as_object_mut() {
        for example in EventKind::examples() {
            if let Ok(Value::Object(fields)) = serde_json::to_value(&example) {
                for (name, value) in fields {
                    declared.entry(name).or_insert_with(|| inferred(&value));
                }
            }
        }
    }
    schema
}

/// `pavlov.Config`: the configuration in force (its fields vary with the experiment, so they are not
/// listed; the Raw Messages panel shows them all) with the program and the observation names.
pub(crate) fn config() -> Value {
    titled(
        "pavlov.Config",
        "The configuration in force at start-up (token redacted), the program version and the names of \
         the observation vector's dimensions (the order of /pavlov/ticks obs).",
        object([
            ("program", string()),
            ("config", object([])),
            ("obs_names", array(string())),
        ]),
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pavlov::control::{Action, Mode};
    use pavlov::event::{Event, EventKind};
    use pavlov::oi::SensorValues;
    use pavlov::record::{ElbowAngles, PredictionValue, SafetyStop, TickInputs, TickRecord};
    use pavlov::supervision::{LinkState, TripCause};

    /// Checks `schema` against what the Foxglove app's JSON Schema reader accepts; returns the first
    /// problem.
    pub(crate) fn foxglove_can_read(schema: &Value, path: &str) -> Result<(), String> {
        if schema["type"] != "object" {
            return Err(format!(
                "{path}: an object schema needs \"type\": \"object\""
            ));
        }
        let Some(properties) = schema["properties"].as_object() else {
            return Err(format!("{path}: an object schema needs \"properties\""));
        };
        for (name, field) in properties {
            let at = format!("{path}.{name}");
            match field["type"].as_str() {
                Some("boolean" | "string" | "number" | "integer") => {}
                Some("object") => foxglove_can_read(field, &at)?,
                Some("array") => match field["items"]["type"].as_str() {
                    Some("boolean" | "string" | "number" | "integer") => {}
                    Some("object") => foxglove_can_read(&field["items"], &at)?,
                    other => return Err(format!("{at}: unsupported array item type {other:?}")),
                },
                _ => return Err(format!("{at}: unsupported type {}", field["type"])),
            }
        }
        Ok(())
    }

    /// Checks that every field of `value` is declared in `schema` with its JSON type (`null` fits any).
    pub(crate) fn conforms(value: &Value, schema: &Value, path: &str) -> Result<(), String> {
        let ty = schema["type"].as_str().unwrap_or_default();
        match value {
            Value::Null => Ok(()),
            Value::Bool(_) if ty == "boolean" => Ok(()),
            Value::Number(n) if ty == "number" || (ty == "integer" && !n.is_f64()) => Ok(()),
            Value::String(s) => match schema["enum"].as_array() {
                _ if ty != "string" => Err(format!("{path}: a string where {ty} is declared")),
                Some(allowed) if !allowed.iter().any(|a| a == s) => {
                    Err(format!("{path}: `{s}` is not among {allowed:?}"))
                }
                _ => Ok(()),
            },
            Value::Array(items) if ty == "array" => items
                .iter()
                .enumerate()
                .try_for_each(|(i, v)| conforms(v, &schema["items"], &format!("{path}[{i}]"))),
            Value::Object(fields) if ty == "object" => fields.iter().try_for_each(|(k, v)| {
                let declared = &schema["properties"][k];
                if declared.is_null() {
                    Err(format!("{path}.{k} is not declared"))
                } else {
                    conforms(v, declared, &format!("{path}.{k}"))
                }
            }),
            other => Err(format!("{path}: {other} does not fit {schema}")),
        }
    }

    /// A record with every optional part present.
    pub(crate) fn full_record() -> TickRecord {
        let mut values = SensorValues::new();
        values.set(23, -250);
        TickRecord {
            obs_age_ticks: Some(1),
            obs: vec![0.25, f32::NAN, 1.0],
            elbow: Some(ElbowAngles {
                left: Some(91.5),
                left_avg: None,
                right: Some(170.0),
                right_avg: Some(169.0),
                skeleton: pavlov::skeleton::SkeletonStatus::Tracked,
            }),
            stimulus: true,
            predictions: vec![PredictionValue {
                name: "stall".into(),
                value: 0.4,
                threshold: 0.5,
            }],
            gate: true,
            rule: Some("stall".into()),
            default_action: Action {
                left_mm_s: 200,
                right_mm_s: 200,
            },
            safety_stop: Some(SafetyStop::StaleObservation),
            estop: true,
            lateness_us: 1200,
            link: pavlov::record::LinkStatus {
                state: LinkState::Tripped,
                mode: Some(1),
                trip: Some(TripCause::WheelDrop),
                ..Default::default()
            },
            inputs: Some(TickInputs {
                values: Some(values),
                forced_stimulus: true,
                previous_followed_default: true,
                previous_behaviour_prob: 0.5,
            }),
            sensors: pavlov::record::SensorReadings {
                battery_current_ma: Some(-250),
                oi_mode: Some(2),
                ..Default::default()
            },
            ..TickRecord::at_rest(7, 140.0, Mode::Pavlovian)
        }
    }

    /// One event of every kind, every field present (the core's examples: the list is derived from the
    /// enum, so a new kind is checked here without a line here).
    fn all_event_kinds() -> Vec<EventKind> {
        EventKind::examples().collect()
    }

    #[test]
    fn foxglove_can_read_every_schema() {
        let names = vec!["bump".to_string(), "wall".to_string()];
        for schema in [tick_record(), signals(&names, &names), event(), config()] {
            foxglove_can_read(&schema, "$").unwrap_or_else(|e| panic!("{e}\n{schema:#}"));
        }
    }

    #[test]
    fn every_field_of_a_tick_record_is_declared_with_its_type() {
        let schema = tick_record();
        for record in [full_record(), TickRecord::at_rest(0, 0.0, Mode::Reactive)] {
            let value = serde_json::to_value(&record).unwrap();
            conforms(&value, &schema, "$").unwrap();
        }
        // The check can fail: an undeclared field or a wrong type is caught.
        let mut value = serde_json::to_value(full_record()).unwrap();
        value["new_field"] = json!(1);
        assert!(conforms(&value, &schema, "$").is_err());
        let mut value = serde_json::to_value(full_record()).unwrap();
        value["gate"] = json!("yes");
        assert!(conforms(&value, &schema, "$").is_err());
        let mut value = serde_json::to_value(full_record()).unwrap();
        value["rule"] = json!(3);
        assert!(conforms(&value, &schema, "$").is_err());
    }

    /// The declared fields `value` lacks (`schema` an object schema; arrays are checked on their first
    /// item).
    fn undeclared_in(value: &Value, schema: &Value, path: &str, missing: &mut Vec<String>) {
        match (schema["type"].as_str(), value) {
            (Some("object"), Value::Object(fields)) => {
                for (name, declared) in schema["properties"].as_object().into_iter().flatten() {
                    let at = format!("{path}.{name}");
                    match fields.get(name) {
                        None => missing.push(at),
                        Some(v) => undeclared_in(v, declared, &at, missing),
                    }
                }
            }
            (Some("array"), Value::Array(items)) => {
                if let Some(first) = items.first() {
                    undeclared_in(first, &schema["items"], &format!("{path}[0]"), missing);
                }
            }
            _ => {}
        }
    }

    #[test]
    fn the_tick_schema_is_the_descriptors_and_a_record_writes_every_field_of_it() {
        let schema = tick_record();
        let mut missing = Vec::new();
        let value = serde_json::to_value(full_record()).unwrap();
        undeclared_in(&value, &schema, "$", &mut missing);
        assert_eq!(
            missing,
            Vec::<String>::new(),
            "fields of the descriptor a record lacks"
        );
        // As many fields as the descriptor's Tick, and the enums' values in serde's names.
        let set = FileDescriptorSet::decode(TICK_DESCRIPTOR_SET.as_slice()).unwrap();
        let tick = set.file[0]
            .message_type
            .iter()
            .find(|m| m.name() == "Tick")
            .unwrap();
        let declared = schema["properties"].as_object().unwrap();
        assert_eq!(declared.len(), tick.field.len());
        assert_eq!(declared["mode"]["enum"], json!(Mode::ALL.map(Mode::name)));
        assert_eq!(
            declared["safety_stop"]["enum"],
            json!([
                "none",
                "e_stop",
                "stale_observation",
                "link_down",
                "robot_tripped"
            ])
        );
        assert_eq!(
            declared["link"]["properties"]["state"]["enum"],
            json!(["up", "stale", "reconnecting", "tripped", "down"])
        );
        assert_eq!(
            declared["inputs"]["properties"]["values"]["properties"]["values"]["type"],
            "array"
        );
        // A record without a field of the descriptor would be caught.
        let mut value = serde_json::to_value(full_record()).unwrap();
        value["link"].as_object_mut().unwrap().remove("reconnects");
        let mut missing = Vec::new();
        undeclared_in(&value, &schema, "$", &mut missing);
        assert_eq!(missing, ["$.link.reconnects"]);
    }

    #[test]
    fn every_kind_of_event_is_declared_with_its_fields() {
        let schema = event();
        let kinds = all_event_kinds();
        let declared = schema["properties"]["kind"]["enum"]
            .as_array()
            .unwrap()
            .len();
        assert_eq!(declared, kinds.len());
        for (i, kind) in kinds.into_iter().enumerate() {
            let e = Event {
                id: i as u64 + 1,
                after: (i % 2 == 0).then_some(i as u64),
                kind,
            };
            let value = serde_json::to_value(&e).unwrap();
            conforms(&value, &schema, "$").unwrap_or_else(|err| panic!("{err}: {value}"));
        }
    }
}
