//! JSON that means one thing: client messages are parsed into a [`Value`] that refuses a key given twice
//! in one object, at any depth.
//!
//! RFC 8259 only says names "SHOULD be unique", and parsers differ on duplicates: serde_json keeps the last
//! one, others the first. So `{"cmd":"ping","cmd":"estop"}` could be a ping to a proxy or a log reader and
//! an e-stop to the server. Refusing duplicates removes the ambiguity; the error names the key and where
//! it is (`duplicate key "cmd" in the message`, `duplicate key "x" in params[0]`).

use std::cell::RefCell;
use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Number, Value};

/// Why a text is not a strict JSON value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum StrictJsonError {
    /// Not JSON at all (serde_json's message, with line and column).
    #[error("{0}")]
    Syntax(String),
    /// An object has the same key twice.
    #[error("duplicate key \"{key}\" in {at}")]
    DuplicateKey {
        /// The key.
        key: String,
        /// Where the object is: `the message`, or a path like `params[0]`.
        at: String,
    },
}

/// Parses `text`, refusing duplicate keys.
pub(crate) fn parse(text: &str) -> Result<Value, StrictJsonError> {
    let duplicate = RefCell::new(None);
    let mut de = serde_json::Deserializer::from_str(text);
    let parsed = Seed {
        path: &Path::Root,
        duplicate: &duplicate,
    }
    .deserialize(&mut de)
    .and_then(|v| de.end().map(|()| v));
    match parsed {
        Ok(v) => Ok(v),
        Err(e) => Err(duplicate
            .into_inner()
            .unwrap_or_else(|| StrictJsonError::Syntax(e.to_string()))),
    }
}

/// Where a value sits in the message.
enum Path<'a> {
    Root,
    Key(&'a Path<'a>, &'a str),
    Index(&'a Path<'a>, usize),
}

impl fmt::Display for Path<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Path::Root => Ok(()),
            Path::Key(Path::Root, key) => write!(f, "{key}"),
            Path::Key(parent, key) => write!(f, "{parent}.{key}"),
            Path::Index(parent, i) => write!(f, "{parent}[{i}]"),
        }
    }
}

impl Path<'_> {
    fn describe(&self) -> String {
        match self {
            Path::Root => "the message".into(),
            other => other.to_string(),
        }
    }
}

/// Builds one value at `path`, recording the first duplicate key it meets.
struct Seed<'a> {
    path: &'a Path<'a>,
    duplicate: &'a RefCell<Option<StrictJsonError>>,
}

impl<'de> DeserializeSeed<'de> for Seed<'_> {
    type Value = Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Value, D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Seed<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::Number(v.into()))
    }

    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::Number(v.into()))
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Number::from_f64(v).map_or(Value::Null, Value::Number))
    }

    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_string()))
    }

    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<Value, D::Error> {
        deserializer.deserialize_any(self)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::new();
        while let Some(item) = seq.next_element_seed(Seed {
            path: &Path::Index(self.path, items.len()),
            duplicate: self.duplicate,
        })? {
            items.push(item);
        }
        Ok(Value::Array(items))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut fields = Map::new();
        while let Some(key) = map.next_key::<String>()? {
            if fields.contains_key(&key) {
                let error = StrictJsonError::DuplicateKey {
                    at: self.path.describe(),
                    key,
                };
                let message = error.to_string();
                *self.duplicate.borrow_mut() = Some(error);
                return Err(de::Error::custom(message));
            }
            let value = map.next_value_seed(Seed {
                path: &Path::Key(self.path, &key),
                duplicate: self.duplicate,
            })?;
            fields.insert(key, value);
        }
        Ok(Value::Object(fields))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn values_parse_as_serde_json_parses_them() {
        for text in [
            r#"{"cmd":"set_params","alpha":0.25,"n":-3,"big":18446744073709551615,"ok":true,"x":null}"#,
            r#"[1, 2.5, "a", [], {}, {"a":{"b":[{"c":1}]}}]"#,
            r#""just a string""#,
            "  42 ",
            r#"{"a":"\u00e9\n"}"#,
        ] {
            let ours = parse(text).unwrap();
            let theirs: Value = serde_json::from_str(text).unwrap();
            assert_eq!(ours, theirs, "{text}");
        }
    }

    #[test]
    fn a_duplicate_key_is_refused_at_any_depth_and_named() {
        let cases = [
            (
                r#"{"cmd":"ping","cmd":"estop"}"#,
                r#"duplicate key "cmd" in the message"#,
            ),
            (
                r#"{"cmd":"set_params","p":{"alpha":1,"alpha":2}}"#,
                r#"duplicate key "alpha" in p"#,
            ),
            (
                r#"{"a":[{"x":1},{"y":{"z":1,"z":2}}]}"#,
                r#"duplicate key "z" in a[1].y"#,
            ),
            (r#"[{"k":1,"k":1}]"#, r#"duplicate key "k" in [0]"#),
        ];
        for (text, message) in cases {
            let e = parse(text).unwrap_err();
            assert!(matches!(e, StrictJsonError::DuplicateKey { .. }), "{text}");
            assert_eq!(e.to_string(), message, "{text}");
        }
        // The same key in sibling objects is fine.
        assert_eq!(
            parse(r#"[{"k":1},{"k":2}]"#).unwrap(),
            json!([{"k":1},{"k":2}])
        );
    }

    #[test]
    fn syntax_errors_keep_serde_jsons_detail() {
        let e = parse(r#"{"cmd":"estop""#).unwrap_err();
        assert!(
            matches!(e, StrictJsonError::Syntax(ref m) if m.contains("EOF")),
            "{e}"
        );
        let e = parse(r#"{"a":1} trailing"#).unwrap_err();
        assert!(
            matches!(e, StrictJsonError::Syntax(ref m) if m.contains("trailing")),
            "{e}"
        );
    }
}
