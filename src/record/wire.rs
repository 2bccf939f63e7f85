//! The protobuf wire form of the tick record (`pavlov.Tick`, an MCAP recording's `ticks` channel), derived
//! from the record's own Rust types so that its shape is written once.
//!
//! Each record struct names its fields' protobuf numbers in one `wire_message!` line beside its
//! definition; each Rust type a field may have says how it goes on the wire through [`Field`] (its
//! protobuf type, its presence, how it is written and read). From those the encoder, the decoder and the
//! schema ([`MessageSpec`], from which the shell builds the `FileDescriptorSet` a recording carries and the
//! Foxglove JSON Schema) all follow, so adding a tick field is its line in the struct and its line in
//! the `wire_message!` list, in one file.
//!
//! The rules are proto3's: a plain scalar equal to zero is left out (implicit presence); an `Option`, and
//! every `f64` (so that −0.0, a fresh learner's prediction, comes back as −0.0), has explicit presence
//! (`optional`); enums carry a zero value that is either a meaningful one (`SAFETY_STOP_NONE` is the
//! record's `None`) or `*_UNSPECIFIED`, never written and refused when read; repeated scalars are packed.
//! Fields are written in the order listed, which is number order, so the bytes are those any protobuf
//! library writes for the same message. Unknown fields are skipped when read (forward compatibility).

pub use prost::encoding::WireType;
use prost::encoding::{self, DecodeContext, decode_key, decode_varint, skip_field};

use super::wire_put::{
    put_bool, put_double, put_int32, put_key, put_packed_float, put_sint32, put_string, put_uint32,
    put_uint64,
};

/// Why bytes are not a record this version can read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Not protobuf, or not the expected message.
    #[error("not a pavlov.Tick message: {0}")]
    Malformed(String),
    /// A field holds a value outside its range (an enum number with no meaning, a speed beyond `i16`).
    #[error("field `{field}` holds {value}, which is not a valid value")]
    BadValue {
        /// The field's path from the top message, e.g. `link.state`.
        field: String,
        /// The value.
        value: i64,
    },
}

impl WireError {
    fn malformed(e: prost::DecodeError) -> WireError {
        WireError::Malformed(e.to_string())
    }

    /// A bad value in field `name`, whose path is completed by the messages it is nested in.
    pub fn bad(value: i64) -> WireError {
        WireError::BadValue {
            field: String::new(),
            value,
        }
    }

    /// The error with `outer` put in front of its field path.
    pub fn within(self, outer: &str) -> WireError {
        match self {
            WireError::BadValue { field, value } if field.is_empty() => WireError::BadValue {
                field: outer.to_string(),
                value,
            },
            WireError::BadValue { field, value } => WireError::BadValue {
                field: format!("{outer}.{field}"),
                value,
            },
            other => other,
        }
    }
}

/// A protobuf scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scalar {
    /// `uint64`.
    Uint64,
    /// `uint32`.
    Uint32,
    /// `sint32` (zig-zag).
    Sint32,
    /// `bool`.
    Bool,
    /// `double`.
    Double,
    /// `float`.
    Float,
    /// `string`.
    String,
    /// `fixed64`.
    Fixed64,
}

/// A protobuf enum: its name and its values' names and numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EnumSpec {
    /// The enum's name in the schema.
    pub name: &'static str,
    /// `(name, number)` of every value, the zero one first.
    pub values: &'static [(&'static str, i32)],
}

/// What a field holds on the wire.
#[derive(Debug, Clone, Copy)]
pub enum FieldType {
    /// A scalar.
    Scalar(Scalar),
    /// An enum.
    Enum(EnumSpec),
    /// A nested message.
    Message(fn() -> MessageSpec),
}

/// How a field's presence is told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Presence {
    /// Left out when zero / empty (proto3's default).
    Implicit,
    /// Written whenever it is there (`optional`, or a message).
    Explicit,
    /// `repeated` (scalars packed).
    Repeated,
}

/// A field's type and presence.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// What it holds.
    pub ty: FieldType,
    /// How its presence is told.
    pub presence: Presence,
}

/// One field of a message's schema.
#[derive(Debug, Clone, Copy)]
pub struct FieldSpec {
    /// Its number.
    pub number: u32,
    /// Its name (the Rust field's, which is also its JSON name in the record's serde form).
    pub name: &'static str,
    /// Its type and presence.
    pub shape: Shape,
}

/// A message's schema.
#[derive(Debug, Clone)]
pub struct MessageSpec {
    /// The message's name in the schema.
    pub name: &'static str,
    /// Its fields in number order.
    pub fields: Vec<FieldSpec>,
}

/// A Rust type that can be a field of a wire message.
pub trait Field: Sized {
    /// The field's protobuf type and presence.
    fn shape() -> Shape;
    /// Appends the field (key and value) as number `number`, unless presence rules leave it out.
    fn encode_field(&self, number: u32, buf: &mut Vec<u8>);
    /// Merges one occurrence of the field, whose key said `wire`, from the front of `buf`.
    fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError>;
    /// Whether a message that leaves the field out is valid (an enum without a meaningful zero is not).
    fn check_absent(&self) -> Result<(), WireError> {
        Ok(())
    }
}

/// A record struct that is a wire message (implemented by `wire_message!`).
pub trait Message: Sized {
    /// The schema of the message and, through its fields, of the messages nested in it.
    fn spec() -> MessageSpec;
    /// The value every field takes when absent, which decoding starts from.
    fn blank() -> Self;
    /// Appends every field.
    fn encode_fields(&self, buf: &mut Vec<u8>);
    /// Merges the fields in `buf` (a whole message body) into `self`, then checks the absent ones.
    fn merge_fields(&mut self, buf: &[u8]) -> Result<(), WireError>;

    /// The message's bytes, appended to `buf`.
    fn encode_to(&self, buf: &mut Vec<u8>) {
        self.encode_fields(buf);
    }

    /// The message `bytes` hold.
    fn decode(bytes: &[u8]) -> Result<Self, WireError> {
        let mut out = Self::blank();
        out.merge_fields(bytes)?;
        Ok(out)
    }
}

/// Reads the next key of a message body.
pub fn next_key(buf: &mut &[u8]) -> Result<(u32, WireType), WireError> {
    decode_key(buf).map_err(WireError::malformed)
}

/// Skips a field this version does not know.
pub fn skip(wire: WireType, number: u32, buf: &mut &[u8]) -> Result<(), WireError> {
    skip_field(wire, number, buf, DecodeContext::default()).map_err(WireError::malformed)
}

/// Appends `m` as a length-delimited field: the body is written in place behind a one-byte length that
/// is widened afterwards if the body is 128 bytes or more (no scratch buffer, no length pass: the body is
/// moved up by the extra length bytes, within the buffer's capacity once it is warm).
pub fn encode_nested<M: Message>(m: &M, number: u32, buf: &mut Vec<u8>) {
    put_key(buf, number, WireType::LengthDelimited);
    let at = buf.len();
    buf.push(0);
    m.encode_fields(buf);
    let end = buf.len();
    let len = end - at - 1;
    if len < 0x80 {
        // `len` < 128 fits the one byte.
        buf[at] = len as u8;
    } else {
        // The varint of `len` (at most 10 bytes), as `put_varint` writes it.
        let mut prefix = [0u8; 10];
        let used = super::wire_put::varint_into(len as u64, &mut prefix);
        // Make room for the `used − 1` extra bytes and move the body up behind them.
        buf.resize(end + used - 1, 0);
        buf.copy_within(at + 1..end, at + used);
        buf[at..at + used].copy_from_slice(&prefix[..used]);
    }
}

/// Merges a length-delimited `M` from the front of `buf` into `into`.
pub fn merge_nested<M: Message>(
    into: &mut M,
    wire: WireType,
    buf: &mut &[u8],
) -> Result<(), WireError> {
    if wire != WireType::LengthDelimited {
        return Err(WireError::Malformed(format!(
            "a nested message with wire type {wire:?}"
        )));
    }
    let len = decode_varint(buf).map_err(WireError::malformed)?;
    let len = usize::try_from(len)
        .ok()
        .filter(|&l| l <= buf.len())
        .ok_or_else(|| WireError::Malformed("a nested message longer than its buffer".into()))?;
    let (body, rest) = buf.split_at(len);
    *buf = rest;
    into.merge_fields(body)
}

/// Implements [`Field`] for a scalar type with implicit presence (left out when equal to its zero).
macro_rules! implicit_scalar {
    ($t:ty, $scalar:ident, $codec:ident, $put:ident) => {
        impl Field for $t {
            fn shape() -> Shape {
                Shape {
                    ty: FieldType::Scalar(Scalar::$scalar),
                    presence: Presence::Implicit,
                }
            }
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                if *self != <$t>::default() {
                    $put(buf, number, self);
                }
            }
            fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
                encoding::$codec::merge(wire, self, buf, DecodeContext::default())
                    .map_err(WireError::malformed)
            }
        }
    };
}

/// Implements [`Field`] for `Option` of a scalar type: explicit presence (`optional`).
macro_rules! optional_scalar {
    ($t:ty, $scalar:ident, $codec:ident, $put:ident) => {
        impl Field for Option<$t> {
            fn shape() -> Shape {
                Shape {
                    ty: FieldType::Scalar(Scalar::$scalar),
                    presence: Presence::Explicit,
                }
            }
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                if let Some(v) = self {
                    $put(buf, number, v);
                }
            }
            fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
                let v = self.get_or_insert_with(Default::default);
                encoding::$codec::merge(wire, v, buf, DecodeContext::default())
                    .map_err(WireError::malformed)
            }
        }
    };
}

implicit_scalar!(u64, Uint64, uint64, put_uint64);
implicit_scalar!(u32, Uint32, uint32, put_uint32);
implicit_scalar!(i32, Sint32, sint32, put_sint32);
implicit_scalar!(bool, Bool, bool, put_bool);
implicit_scalar!(String, String, string, put_string);
optional_scalar!(u32, Uint32, uint32, put_uint32);
optional_scalar!(i32, Sint32, sint32, put_sint32);
optional_scalar!(f64, Double, double, put_double);
optional_scalar!(String, String, string, put_string);

/// An `f64` is always written (explicit presence): proto3 would leave out a plain 0.0 and so turn −0.0
/// into +0.0.
impl Field for f64 {
    fn shape() -> Shape {
        Shape {
            ty: FieldType::Scalar(Scalar::Double),
            presence: Presence::Explicit,
        }
    }
    fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
        put_double(buf, number, self);
    }
    fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
        encoding::double::merge(wire, self, buf, DecodeContext::default())
            .map_err(WireError::malformed)
    }
}

/// An `i16` (a wheel speed) is a `sint32` on the wire; a value beyond `i16` is refused when read.
impl Field for i16 {
    fn shape() -> Shape {
        <i32 as Field>::shape()
    }
    fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
        i32::from(*self).encode_field(number, buf);
    }
    fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
        let mut v = 0i32;
        v.merge_field(wire, buf)?;
        *self = i16::try_from(v).map_err(|_| WireError::bad(i64::from(v)))?;
        Ok(())
    }
}

/// An `Option<u8>` (the robot's OI mode) is an optional `uint32`; a value beyond `u8` is refused.
impl Field for Option<u8> {
    fn shape() -> Shape {
        <Option<u32> as Field>::shape()
    }
    fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
        self.map(u32::from).encode_field(number, buf);
    }
    fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
        let mut v = 0u32;
        v.merge_field(wire, buf)?;
        *self = Some(u8::try_from(v).map_err(|_| WireError::bad(i64::from(v)))?);
        Ok(())
    }
}

/// A `Vec<f32>` is a packed `repeated float`.
impl Field for Vec<f32> {
    fn shape() -> Shape {
        Shape {
            ty: FieldType::Scalar(Scalar::Float),
            presence: Presence::Repeated,
        }
    }
    fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
        put_packed_float(buf, number, self);
    }
    fn merge_field(&mut self, wire: WireType, buf: &mut &[u8]) -> Result<(), WireError> {
        encoding::float::merge_repeated(wire, self, buf, DecodeContext::default())
            .map_err(WireError::malformed)
    }
}

/// Declares a Rust type as a protobuf enum: each value (a constant expression of the type) with its
/// number and schema name, the zero one first. With `unspecified NAME`, zero is a schema-only value that
/// is never written and is refused when read (and when the field is absent).
macro_rules! wire_enum {
    ($t:ty, $name:literal, unspecified $zero:literal; $($value:expr => $num:literal, $vname:literal;)+) => {
        $crate::record::wire::wire_enum!(@impl $t, $name, [($zero, 0)], false; $($value => $num, $vname;)+);
    };
    ($t:ty, $name:literal; $($value:expr => $num:literal, $vname:literal;)+) => {
        $crate::record::wire::wire_enum!(@impl $t, $name, [], true; $($value => $num, $vname;)+);
    };
    (@impl $t:ty, $name:literal, [$(($zero:literal, 0))?], $zero_valid:literal;
        $($value:expr => $num:literal, $vname:literal;)+) => {
        impl $crate::record::wire::Field for $t {
            fn shape() -> $crate::record::wire::Shape {
                $crate::record::wire::Shape {
                    ty: $crate::record::wire::FieldType::Enum($crate::record::wire::EnumSpec {
                        name: $name,
                        values: &[$(($zero, 0),)? $(($vname, $num),)+],
                    }),
                    presence: $crate::record::wire::Presence::Implicit,
                }
            }
            #[allow(clippy::partialeq_to_none, reason = "the values are constant expressions")]
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                let n: i32 = $(if *self == $value { $num } else)+ { 0 };
                $crate::record::wire::encode_enum(number, n, buf);
            }
            fn merge_field(
                &mut self,
                wire: $crate::record::wire::WireType,
                buf: &mut &[u8],
            ) -> Result<(), $crate::record::wire::WireError> {
                *self = match $crate::record::wire::merge_enum(wire, buf)? {
                    $($num => $value,)+
                    other => return Err($crate::record::wire::WireError::bad(i64::from(other))),
                };
                Ok(())
            }
            fn check_absent(&self) -> Result<(), $crate::record::wire::WireError> {
                if $zero_valid {
                    Ok(())
                } else {
                    Err($crate::record::wire::WireError::bad(0))
                }
            }
        }
    };
}

/// Declares a struct as a protobuf message: its schema name, the value decoding starts from (every
/// field absent), and `number => field` for each field in number order (numbers below 64; a field with
/// `if (predicate)` is written only when the predicate holds for the struct). Implements [`Message`], and
/// [`Field`] for the struct (a nested message, always written), its `Option` (written when `Some`) and
/// its `Vec` (`repeated`).
macro_rules! wire_message {
    ($t:ty, $name:literal, blank $blank:expr;
        $($num:literal => $field:ident $(if ($cond:expr))?,)+) => {
        impl $crate::record::wire::Message for $t {
            fn spec() -> $crate::record::wire::MessageSpec {
                fn shape_of<T: $crate::record::wire::Field>(
                    _: fn(&$t) -> &T,
                ) -> $crate::record::wire::Shape {
                    T::shape()
                }
                $crate::record::wire::MessageSpec {
                    name: $name,
                    fields: vec![$($crate::record::wire::FieldSpec {
                        number: $num,
                        name: stringify!($field),
                        shape: shape_of(|m: &$t| &m.$field),
                    },)+],
                }
            }
            fn blank() -> Self {
                $blank
            }
            fn encode_fields(&self, buf: &mut Vec<u8>) {
                $(
                    if true $(&& ($cond)(self))? {
                        $crate::record::wire::Field::encode_field(&self.$field, $num, buf);
                    }
                )+
            }
            fn merge_fields(&mut self, mut buf: &[u8]) -> Result<(), $crate::record::wire::WireError> {
                let mut seen = 0u64;
                while !buf.is_empty() {
                    let (number, wire) = $crate::record::wire::next_key(&mut buf)?;
                    match number {
                        $($num => {
                            $crate::record::wire::Field::merge_field(&mut self.$field, wire, &mut buf)
                                .map_err(|e| e.within(stringify!($field)))?;
                            seen |= 1u64 << $num;
                        })+
                        other => $crate::record::wire::skip(wire, other, &mut buf)?,
                    }
                }
                $(
                    if seen & (1u64 << $num) == 0 {
                        $crate::record::wire::Field::check_absent(&self.$field)
                            .map_err(|e| e.within(stringify!($field)))?;
                    }
                )+
                Ok(())
            }
        }

        $crate::record::wire::message_fields!($t);
    };
}

/// Implements [`Field`] for a [`Message`] type (a nested message, always written), its `Option` (written
/// when `Some`) and its `Vec` (`repeated`).
macro_rules! message_fields {
    ($t:ty) => {
        impl $crate::record::wire::Field for $t {
            fn shape() -> $crate::record::wire::Shape {
                $crate::record::wire::Shape {
                    ty: $crate::record::wire::FieldType::Message(
                        <$t as $crate::record::wire::Message>::spec,
                    ),
                    presence: $crate::record::wire::Presence::Explicit,
                }
            }
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                $crate::record::wire::encode_nested(self, number, buf);
            }
            fn merge_field(
                &mut self,
                wire: $crate::record::wire::WireType,
                buf: &mut &[u8],
            ) -> Result<(), $crate::record::wire::WireError> {
                $crate::record::wire::merge_nested(self, wire, buf)
            }
            fn check_absent(&self) -> Result<(), $crate::record::wire::WireError> {
                // An absent message reads as an empty one, which must itself be valid.
                <$t as $crate::record::wire::Message>::decode(&[]).map(|_| ())
            }
        }

        impl $crate::record::wire::Field for Option<$t> {
            fn shape() -> $crate::record::wire::Shape {
                <$t as $crate::record::wire::Field>::shape()
            }
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                if let Some(m) = self {
                    $crate::record::wire::encode_nested(m, number, buf);
                }
            }
            fn merge_field(
                &mut self,
                wire: $crate::record::wire::WireType,
                buf: &mut &[u8],
            ) -> Result<(), $crate::record::wire::WireError> {
                let m = self.get_or_insert_with(<$t as $crate::record::wire::Message>::blank);
                $crate::record::wire::merge_nested(m, wire, buf)
            }
        }

        impl $crate::record::wire::Field for Vec<$t> {
            fn shape() -> $crate::record::wire::Shape {
                $crate::record::wire::Shape {
                    presence: $crate::record::wire::Presence::Repeated,
                    ..<$t as $crate::record::wire::Field>::shape()
                }
            }
            fn encode_field(&self, number: u32, buf: &mut Vec<u8>) {
                for m in self {
                    $crate::record::wire::encode_nested(m, number, buf);
                }
            }
            fn merge_field(
                &mut self,
                wire: $crate::record::wire::WireType,
                buf: &mut &[u8],
            ) -> Result<(), $crate::record::wire::WireError> {
                let mut m = <$t as $crate::record::wire::Message>::blank();
                $crate::record::wire::merge_nested(&mut m, wire, buf)?;
                self.push(m);
                Ok(())
            }
        }
    };
}

pub(crate) use {message_fields, wire_enum, wire_message};

/// Appends an enum field of number `n` unless `n` is zero (implicit presence).
pub fn encode_enum(number: u32, n: i32, buf: &mut Vec<u8>) {
    if n != 0 {
        put_int32(buf, number, &n);
    }
}

/// Reads an enum field's number.
pub fn merge_enum(wire: WireType, buf: &mut &[u8]) -> Result<i32, WireError> {
    let mut n = 0i32;
    encoding::int32::merge(wire, &mut n, buf, DecodeContext::default())
        .map_err(WireError::malformed)?;
    Ok(n)
}
