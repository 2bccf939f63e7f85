//! The `ticks` channel's schema: the protobuf `FileDescriptorSet` of `pavlov/tick.proto`, built from the
//! tick record's wire declaration ([`pavlov::record::wire`]) rather than from a `.proto` file, so the
//! record's types are the one definition of the message.
//!
//! The set is the one a protobuf compiler gives for the equivalent `.proto` (file `pavlov/tick.proto`,
//! package `pavlov`, proto3; a field with explicit presence is `proto3_optional` in its synthetic oneof
//! `_<name>`; `json_name` in lowerCamelCase), byte for byte what format-3 recordings carried since the
//! schema was compiled: messages in the order they are first reached from `Tick`, enums in that file's
//! order (any new one after them).

use std::sync::LazyLock;

use pavlov::record::TickRecord;
use pavlov::record::wire::{EnumSpec, FieldType, Message as _, MessageSpec, Presence, Scalar};
use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{
    DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
    FileDescriptorProto, FileDescriptorSet, OneofDescriptorProto,
};

/// The serialised set, built once.
pub(crate) static TICK_DESCRIPTOR_SET: LazyLock<Vec<u8>> =
    LazyLock::new(|| descriptor_set().encode_to_vec());

/// The order of the enums in the file recordings of format 3 carry.
const ENUM_ORDER: [&str; 5] = [
    "Mode",
    "SafetyStop",
    "LinkState",
    "SkeletonStatus",
    "TripCause",
];

/// The descriptor set of `pavlov.Tick` and everything it uses.
pub(crate) fn descriptor_set() -> FileDescriptorSet {
    let mut messages = Vec::new();
    let mut enums: Vec<EnumSpec> = Vec::new();
    collect(TickRecord::spec(), &mut messages, &mut enums);
    enums.sort_by_key(|e| {
        ENUM_ORDER
            .iter()
            .position(|n| *n == e.name)
            .unwrap_or(ENUM_ORDER.len())
    });
    FileDescriptorSet {
        file: vec![FileDescriptorProto {
            name: Some("pavlov/tick.proto".into()),
            package: Some("pavlov".into()),
            message_type: messages.iter().map(message).collect(),
            enum_type: enums.iter().map(enumeration).collect(),
            syntax: Some("proto3".into()),
            ..FileDescriptorProto::default()
        }],
    }
}

/// Adds `spec` and the messages and enums it reaches (depth first, each once) to the lists.
fn collect(spec: MessageSpec, messages: &mut Vec<MessageSpec>, enums: &mut Vec<EnumSpec>) {
    if messages.iter().any(|m| m.name == spec.name) {
        return;
    }
    let fields = spec.fields.clone();
    messages.push(spec);
    for f in fields {
        match f.shape.ty {
            FieldType::Message(nested) => collect(nested(), messages, enums),
            FieldType::Enum(e) if !enums.iter().any(|known| known.name == e.name) => enums.push(e),
            _ => {}
        }
    }
}

fn message(spec: &MessageSpec) -> DescriptorProto {
    let mut oneofs = Vec::new();
    let field = spec
        .fields
        .iter()
        .map(|f| {
            let (r#type, type_name) = match f.shape.ty {
                FieldType::Scalar(s) => (scalar(s), None),
                FieldType::Enum(e) => (Type::Enum, Some(format!(".pavlov.{}", e.name))),
                FieldType::Message(m) => (Type::Message, Some(format!(".pavlov.{}", m().name))),
            };
            // proto3 `optional`: a scalar with explicit presence (a message has it anyway).
            let optional = f.shape.presence == Presence::Explicit && r#type != Type::Message;
            let oneof_index = optional.then(|| {
                oneofs.push(OneofDescriptorProto {
                    name: Some(format!("_{}", f.name)),
                    options: None,
                });
                // At most 63 fields, so the index fits.
                (oneofs.len() - 1) as i32
            });
            let label = if f.shape.presence == Presence::Repeated {
                Label::Repeated
            } else {
                Label::Optional
            };
            FieldDescriptorProto {
                name: Some(f.name.into()),
                // Field numbers are below 64 (`pavlov::record::wire`).
                number: Some(f.number as i32),
                label: Some(label as i32),
                r#type: Some(r#type as i32),
                type_name,
                oneof_index,
                json_name: Some(lower_camel(f.name)),
                proto3_optional: optional.then_some(true),
                ..FieldDescriptorProto::default()
            }
        })
        .collect();
    DescriptorProto {
        name: Some(spec.name.into()),
        field,
        oneof_decl: oneofs,
        ..DescriptorProto::default()
    }
}

fn enumeration(spec: &EnumSpec) -> EnumDescriptorProto {
    EnumDescriptorProto {
        name: Some(spec.name.into()),
        value: spec
            .values
            .iter()
            .map(|(name, number)| EnumValueDescriptorProto {
                name: Some((*name).into()),
                number: Some(*number),
                options: None,
            })
            .collect(),
        ..EnumDescriptorProto::default()
    }
}

fn scalar(s: Scalar) -> Type {
    match s {
        Scalar::Uint64 => Type::Uint64,
        Scalar::Uint32 => Type::Uint32,
        Scalar::Sint32 => Type::Sint32,
        Scalar::Bool => Type::Bool,
        Scalar::Double => Type::Double,
        Scalar::Float => Type::Float,
        Scalar::String => Type::String,
        Scalar::Fixed64 => Type::Fixed64,
    }
}

/// protoc's JSON name: `snake_case` → `snakeCase`.
fn lower_camel(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut upper = false;
    for c in name.chars() {
        if c == '_' {
            upper = true;
        } else if upper {
            out.extend(c.to_uppercase());
            upper = false;
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_names_are_lower_camel_case() {
        assert_eq!(lower_camel("battery_current_ma"), "batteryCurrentMa");
        assert_eq!(lower_camel("seq"), "seq");
        assert_eq!(lower_camel("t_ms"), "tMs");
    }

    #[test]
    fn the_set_names_every_message_and_enum_once() {
        let set = descriptor_set();
        let file = &set.file[0];
        let names: Vec<&str> = file.message_type.iter().map(|m| m.name()).collect();
        assert_eq!(
            names,
            [
                "Tick",
                "Sensors",
                "Elbow",
                "Prediction",
                "Wheels",
                "Link",
                "Inputs",
                "RawSensors"
            ]
        );
        let enums: Vec<&str> = file.enum_type.iter().map(|e| e.name()).collect();
        assert_eq!(enums, ENUM_ORDER);
    }
}
