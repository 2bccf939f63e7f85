//! Reads the fields of one MCAP record body: little-endian integers and length-prefixed strings, maps
//! and byte runs, each length checked against the bytes the body still holds before anything is taken.
//!
//! Nothing here allocates from a length the file states: a string is copied only once its bytes are
//! known to be there, so what a record can make us allocate is bounded by the record itself.

use std::collections::BTreeMap;

/// Why a field could not be read: which field, and what was wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum FieldError {
    /// The body ends before the field does.
    #[error("the {field} needs {needed} bytes, but only {left} are left in the record")]
    Short {
        /// The field.
        field: &'static str,
        /// What it claims or needs.
        needed: u64,
        /// What the record still holds.
        left: usize,
    },
    /// A string is not UTF-8.
    #[error("the {0} is not UTF-8")]
    NotUtf8(&'static str),
    /// A map names a key twice.
    #[error("the {field} names the key `{key}` twice")]
    DuplicateKey {
        /// The map.
        field: &'static str,
        /// The key (at most 64 characters of it).
        key: String,
    },
}

/// A cursor over one record's body.
pub(crate) struct Fields<'a> {
    bytes: &'a [u8],
}

impl<'a> Fields<'a> {
    /// A cursor at the start of `body`.
    pub(crate) fn new(body: &'a [u8]) -> Self {
        Fields { bytes: body }
    }

    /// The bytes not read yet.
    pub(crate) fn rest(&self) -> &'a [u8] {
        self.bytes
    }

    /// The next `n` bytes.
    pub(crate) fn take(&mut self, field: &'static str, n: u64) -> Result<&'a [u8], FieldError> {
        let short = FieldError::Short {
            field,
            needed: n,
            left: self.bytes.len(),
        };
        let n = usize::try_from(n).map_err(|_| short.clone())?;
        if n > self.bytes.len() {
            return Err(short);
        }
        let (head, tail) = self.bytes.split_at(n);
        self.bytes = tail;
        Ok(head)
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], FieldError> {
        let bytes = self.take(field, N as u64)?;
        let mut out = [0; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    /// A `u16`.
    pub(crate) fn u16(&mut self, field: &'static str) -> Result<u16, FieldError> {
        self.array(field).map(u16::from_le_bytes)
    }

    /// A `u32`.
    pub(crate) fn u32(&mut self, field: &'static str) -> Result<u32, FieldError> {
        self.array(field).map(u32::from_le_bytes)
    }

    /// A `u64`.
    pub(crate) fn u64(&mut self, field: &'static str) -> Result<u64, FieldError> {
        self.array(field).map(u64::from_le_bytes)
    }

    /// Bytes prefixed by their `u32` length.
    pub(crate) fn bytes_u32(&mut self, field: &'static str) -> Result<&'a [u8], FieldError> {
        let n = self.u32(field)?;
        self.take(field, u64::from(n))
    }

    /// Bytes prefixed by their `u64` length.
    pub(crate) fn bytes_u64(&mut self, field: &'static str) -> Result<&'a [u8], FieldError> {
        let n = self.u64(field)?;
        self.take(field, n)
    }

    /// A UTF-8 string prefixed by its `u32` length, borrowed.
    pub(crate) fn str(&mut self, field: &'static str) -> Result<&'a str, FieldError> {
        std::str::from_utf8(self.bytes_u32(field)?).map_err(|_| FieldError::NotUtf8(field))
    }

    /// A map of strings to strings prefixed by its `u32` length in bytes (MCAP's `Map<string, string>`).
    pub(crate) fn string_map(
        &mut self,
        field: &'static str,
    ) -> Result<BTreeMap<String, String>, FieldError> {
        let mut inner = Fields::new(self.bytes_u32(field)?);
        let mut map = BTreeMap::new();
        while !inner.bytes.is_empty() {
            let key = inner.str(field)?;
            let value = inner.str(field)?;
            if map.insert(key.to_string(), value.to_string()).is_some() {
                return Err(FieldError::DuplicateKey {
                    field,
                    key: key.chars().take(64).collect(),
                });
            }
        }
        Ok(map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_are_checked_against_the_bytes_left_before_anything_is_taken() {
        let mut body = Vec::new();
        body.extend_from_slice(&7u16.to_le_bytes());
        body.extend_from_slice(&u32::MAX.to_le_bytes());
        body.extend_from_slice(b"abc");
        let mut f = Fields::new(&body);
        assert_eq!(f.u16("id"), Ok(7));
        assert_eq!(
            f.str("topic"),
            Err(FieldError::Short {
                field: "topic",
                needed: u64::from(u32::MAX),
                left: 3
            })
        );
        let mut f = Fields::new(&[0xff; 9]);
        assert!(matches!(
            f.bytes_u64("records"),
            Err(FieldError::Short {
                needed: u64::MAX,
                ..
            })
        ));
    }

    #[test]
    fn a_map_is_read_within_its_own_length_and_refuses_a_key_named_twice() {
        let mut body = Vec::new();
        let pair = |out: &mut Vec<u8>, k: &str, v: &str| {
            for s in [k, v] {
                out.extend_from_slice(&(s.len() as u32).to_le_bytes());
                out.extend_from_slice(s.as_bytes());
            }
        };
        let mut map = Vec::new();
        pair(&mut map, "a", "1");
        pair(&mut map, "b", "2");
        body.extend_from_slice(&(map.len() as u32).to_le_bytes());
        body.extend_from_slice(&map);
        body.push(9);
        let mut f = Fields::new(&body);
        let read = f.string_map("metadata").unwrap();
        assert_eq!(read.len(), 2);
        assert_eq!(f.rest(), [9]);
        pair(&mut map, "a", "3");
        let mut twice = (map.len() as u32).to_le_bytes().to_vec();
        twice.extend_from_slice(&map);
        assert!(matches!(
            Fields::new(&twice).string_map("metadata"),
            Err(FieldError::DuplicateKey { .. })
        ));
    }
}
