//! The protobuf encoder's primitives: keys, varints and the scalar field types, appended to a `Vec<u8>`.
//!
//! The recorder encodes every tick (about 50 000 a second in an experiment under virtual time), so these
//! write straight into the buffer: a varint below 128, which most keys, lengths, enums and small sensor
//! values are, is one `push`; a longer one is built on the stack and copied once. Each writes exactly the
//! bytes `prost::encoding` writes for the same value (the tests below compare them over the edge cases):
//! a key is the varint of `number << 3 | wire type`; `uint32`/`uint64`/`bool` are varints; an enum
//! (`int32`) is the varint of the value sign-extended to 64 bits; `sint32` is the varint of its zig-zag
//! form; `double`/`float`/`fixed64` are their little-endian bytes; a string and a packed field are a
//! varint length and then the bytes.

use prost::encoding::WireType;

/// Writes the varint of `v` into `out` and returns how many bytes it took (1 to 10).
#[inline]
pub(super) fn varint_into(mut v: u64, out: &mut [u8; 10]) -> usize {
    let mut n = 0;
    while v >= 0x80 {
        // The low seven bits, with the continuation bit.
        out[n] = (v as u8 & 0x7f) | 0x80;
        v >>= 7;
        n += 1;
    }
    out[n] = v as u8;
    n + 1
}

/// The number of bytes of the varint of `v` (prost's formula: 1 for 0 to 127, 2 up to 16 383, …).
#[inline(always)]
pub fn varint_len(v: u64) -> usize {
    (((v | 1).ilog2() + 1) as usize * 9 + 64) / 64
}

/// Appends the varint of `v`, a byte at a time (most are one byte: keys, enums, small values), inlined
/// where it is called.
#[inline(always)]
pub fn put_varint(buf: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        // The low seven bits, with the continuation bit.
        buf.push((v as u8 & 0x7f) | 0x80);
        v >>= 7;
    }
    buf.push(v as u8);
}

/// Appends the key of field `number` with wire type `wire`.
#[inline(always)]
pub fn put_key(buf: &mut Vec<u8>, number: u32, wire: WireType) {
    put_varint(buf, u64::from(number << 3 | wire as u32));
}

/// The zig-zag form of a `sint32`: 0, −1, 1, −2, … as 0, 1, 2, 3, …
#[inline(always)]
pub fn zigzag(v: i32) -> u64 {
    u64::from(((v << 1) ^ (v >> 31)) as u32)
}

/// Appends a varint field (`uint64`, `uint32`, `bool`, an enum's value as `v`).
#[inline]
pub fn put_varint_field(buf: &mut Vec<u8>, number: u32, v: u64) {
    put_key(buf, number, WireType::Varint);
    put_varint(buf, v);
}

/// Appends a `uint64` field.
#[inline]
pub fn put_uint64(buf: &mut Vec<u8>, number: u32, v: &u64) {
    put_varint_field(buf, number, *v);
}

/// Appends a `uint32` field.
#[inline]
pub fn put_uint32(buf: &mut Vec<u8>, number: u32, v: &u32) {
    put_varint_field(buf, number, u64::from(*v));
}

/// Appends a `sint32` field.
#[inline]
pub fn put_sint32(buf: &mut Vec<u8>, number: u32, v: &i32) {
    put_varint_field(buf, number, zigzag(*v));
}

/// Appends a `bool` field.
#[inline]
pub fn put_bool(buf: &mut Vec<u8>, number: u32, v: &bool) {
    put_varint_field(buf, number, u64::from(*v));
}

/// Appends an enum (`int32`) field: negative values are sign-extended, as protobuf requires.
#[inline]
pub fn put_int32(buf: &mut Vec<u8>, number: u32, v: &i32) {
    put_varint_field(buf, number, i64::from(*v) as u64);
}

/// Appends a length-delimited field holding `bytes`.
#[inline]
pub fn put_bytes(buf: &mut Vec<u8>, number: u32, bytes: &[u8]) {
    put_key(buf, number, WireType::LengthDelimited);
    put_varint(buf, bytes.len() as u64);
    buf.extend_from_slice(bytes);
}

/// Appends a `string` field.
#[inline]
pub fn put_string(buf: &mut Vec<u8>, number: u32, v: &String) {
    put_bytes(buf, number, v.as_bytes());
}

/// Appends a `double` field (its bits as they are: −0.0 and NaN payloads survive).
#[inline]
pub fn put_double(buf: &mut Vec<u8>, number: u32, v: &f64) {
    put_key(buf, number, WireType::SixtyFourBit);
    buf.extend_from_slice(&v.to_le_bytes());
}

/// Appends a `fixed64` field.
#[inline]
pub fn put_fixed64(buf: &mut Vec<u8>, number: u32, v: u64) {
    put_key(buf, number, WireType::SixtyFourBit);
    buf.extend_from_slice(&v.to_le_bytes());
}

/// Appends a packed `repeated float` field (nothing when `values` is empty, as prost).
pub fn put_packed_float(buf: &mut Vec<u8>, number: u32, values: &[f32]) {
    if values.is_empty() {
        return;
    }
    put_key(buf, number, WireType::LengthDelimited);
    put_varint(buf, (values.len() * 4) as u64);
    buf.reserve(values.len() * 4);
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// At most this many values of a packed `sint32` field are encoded on the stack in one pass (a raw
/// sensor snapshot has 59 slots); a longer field is measured first, then written.
const PACKED_ON_STACK: usize = 64;

/// Appends a packed `repeated sint32` field (nothing when `values` is empty, as prost).
pub fn put_packed_sint32(buf: &mut Vec<u8>, number: u32, values: &[i32]) {
    if values.is_empty() {
        return;
    }
    put_key(buf, number, WireType::LengthDelimited);
    if values.len() <= PACKED_ON_STACK {
        // One pass: the values are encoded behind each other on the stack (a `sint32` takes at most 5
        // bytes), then their length and the bytes are appended.
        let mut bytes = [0u8; PACKED_ON_STACK * 5];
        let mut len = 0;
        for &v in values {
            let mut z = zigzag(v);
            while z >= 0x80 {
                bytes[len] = (z as u8 & 0x7f) | 0x80;
                z >>= 7;
                len += 1;
            }
            bytes[len] = z as u8;
            len += 1;
        }
        put_varint(buf, len as u64);
        buf.extend_from_slice(&bytes[..len]);
    } else {
        let len: usize = values.iter().map(|&v| varint_len(zigzag(v))).sum();
        put_varint(buf, len as u64);
        for &v in values {
            put_varint(buf, zigzag(v));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::encoding;

    /// Values at every varint length's edges, both signs, and the extremes.
    fn u64s() -> Vec<u64> {
        let mut v = vec![0, 1, u64::MAX, u64::MAX - 1];
        for bits in 1..64 {
            let edge = 1u64 << bits;
            v.extend([edge - 1, edge, edge + 1]);
        }
        v
    }

    fn i32s() -> Vec<i32> {
        let mut v: Vec<i32> = vec![0, 1, -1, i32::MIN, i32::MAX, i32::MIN + 1, i32::MAX - 1];
        for bits in 1..31 {
            let edge = 1i32 << bits;
            v.extend([edge - 1, edge, edge + 1, -edge, -edge - 1, 1 - edge]);
        }
        v
    }

    fn same(ours: impl Fn(&mut Vec<u8>), prost: impl Fn(&mut Vec<u8>)) {
        // Written after other bytes, as inside a message.
        let (mut a, mut b) = (vec![7u8], vec![7u8]);
        ours(&mut a);
        prost(&mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn varints_and_keys_are_prosts() {
        for v in u64s() {
            same(|b| put_varint(b, v), |b| encoding::encode_varint(v, b));
            assert_eq!(varint_len(v), encoding::encoded_len_varint(v), "{v}");
        }
        for number in [1, 2, 15, 16, 17, 63, 64, 2047, 2048, (1 << 29) - 1] {
            for wire in [
                WireType::Varint,
                WireType::SixtyFourBit,
                WireType::LengthDelimited,
                WireType::ThirtyTwoBit,
            ] {
                same(
                    |b| put_key(b, number, wire),
                    |b| encoding::encode_key(number, wire, b),
                );
            }
        }
    }

    #[test]
    fn scalar_fields_are_prosts() {
        for v in u64s() {
            same(
                |b| put_uint64(b, 9, &v),
                |b| encoding::uint64::encode(9, &v, b),
            );
            same(
                |b| put_fixed64(b, 2, v),
                |b| encoding::fixed64::encode(2, &v, b),
            );
            let w = v as u32;
            same(
                |b| put_uint32(b, 4, &w),
                |b| encoding::uint32::encode(4, &w, b),
            );
            let d = f64::from_bits(v);
            same(
                |b| put_double(b, 17, &d),
                |b| encoding::double::encode(17, &d, b),
            );
        }
        for v in i32s() {
            same(
                |b| put_sint32(b, 5, &v),
                |b| encoding::sint32::encode(5, &v, b),
            );
            same(
                |b| put_int32(b, 12, &v),
                |b| encoding::int32::encode(12, &v, b),
            );
        }
        for v in [false, true] {
            same(|b| put_bool(b, 3, &v), |b| encoding::bool::encode(3, &v, b));
        }
        for s in ["", "p0", "rule 4 ✓", &"x".repeat(200)] {
            let s = s.to_string();
            same(
                |b| put_string(b, 18, &s),
                |b| encoding::string::encode(18, &s, b),
            );
        }
    }

    #[test]
    fn packed_fields_are_prosts() {
        // Up to the stack's 64 values and beyond them, with every varint length.
        let ints: Vec<i32> = i32s().into_iter().cycle().take(300).collect();
        for n in [0, 1, 5, 63, 64, 65, 190, 300] {
            let values = &ints[..n];
            same(
                |b| put_packed_sint32(b, 1, values),
                |b| encoding::sint32::encode_packed(1, values, b),
            );
        }
        let floats: Vec<f32> = [0.0, -0.0, f32::NAN, f32::INFINITY, 1.5e-40, -3.25]
            .into_iter()
            .cycle()
            .take(40)
            .collect();
        for n in [0, 1, 33, 40] {
            let values = &floats[..n];
            same(
                |b| put_packed_float(b, 17, values),
                |b| encoding::float::encode_packed(17, values, b),
            );
        }
    }
}
