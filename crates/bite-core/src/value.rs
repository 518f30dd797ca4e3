//! Typed belief values: bool, number, text and 2-D vector.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::sync::Arc;

/// The value of a belief, or of a condition sub-expression.
///
/// In human-readable formats (JSON, YAML) a value is written as itself
/// (`true`, `2.5`, `[1, 2]`, `"red"`). In binary formats (postcard, on the
/// wire between robots) it carries a variant tag — `0` bool, `1` number,
/// `2` vector, `3` text — because a compact format that does not describe
/// itself cannot tell the variants apart (an untagged `Value` written by
/// postcard cannot be read back).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A truth value (`peers_located`).
    Bool(bool),
    /// A number (`distance_walked`), in SI units by convention.
    Num(f64),
    /// A 2-D vector (`box_position`), metres by convention.
    Vec2([f64; 2]),
    /// Text (`colour`).
    Text(Arc<str>),
}

impl Value {
    /// Name of the type, for messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Bool(_) => "bool",
            Value::Num(_) => "number",
            Value::Vec2(_) => "vector",
            Value::Text(_) => "text",
        }
    }
    /// The boolean, if this is one.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }
    /// The number, if this is one.
    pub fn as_num(&self) -> Option<f64> {
        match self {
            Value::Num(n) => Some(*n),
            _ => None,
        }
    }
    /// The vector, if this is one.
    pub fn as_vec2(&self) -> Option<[f64; 2]> {
        match self {
            Value::Vec2(v) => Some(*v),
            _ => None,
        }
    }
    /// The text, if this is text.
    pub fn as_text(&self) -> Option<&str> {
        match self {
            Value::Text(t) => Some(t),
            _ => None,
        }
    }
    /// Equality that treats numbers bit-for-bit, so that "unchanged" is exact
    /// (used to decide whether a percept changed the belief store).
    pub fn same_as(&self, other: &Value) -> bool {
        match (self, other) {
            (Value::Num(a), Value::Num(b)) => a.to_bits() == b.to_bits(),
            (Value::Vec2(a), Value::Vec2(b)) => {
                a[0].to_bits() == b[0].to_bits() && a[1].to_bits() == b[1].to_bits()
            }
            _ => self == other,
        }
    }
}

/// The binary form: a tagged enum whose variant indices are the wire tags.
#[derive(Serialize, Deserialize)]
enum Tagged {
    Bool(bool),
    Num(f64),
    Vec2([f64; 2]),
    Text(Arc<str>),
}

/// The human-readable form: the value as itself.
#[derive(Deserialize)]
#[serde(untagged)]
enum Plain {
    Bool(bool),
    Num(f64),
    Vec2([f64; 2]),
    Text(Arc<str>),
}

impl Serialize for Value {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            match self {
                Value::Bool(b) => s.serialize_bool(*b),
                Value::Num(n) => s.serialize_f64(*n),
                Value::Vec2(v) => v.serialize(s),
                Value::Text(t) => s.serialize_str(t),
            }
        } else {
            // Variant indices 0..3 are the wire tags (docs/zenoh-interface.md).
            match self {
                Value::Bool(b) => s.serialize_newtype_variant("Value", 0, "Bool", b),
                Value::Num(n) => s.serialize_newtype_variant("Value", 1, "Num", n),
                Value::Vec2(v) => s.serialize_newtype_variant("Value", 2, "Vec2", v),
                Value::Text(t) => s.serialize_newtype_variant("Value", 3, "Text", &**t),
            }
        }
    }
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        if d.is_human_readable() {
            Ok(match Plain::deserialize(d)? {
                Plain::Bool(b) => Value::Bool(b),
                Plain::Num(n) => Value::Num(n),
                Plain::Vec2(v) => Value::Vec2(v),
                Plain::Text(t) => Value::Text(t),
            })
        } else {
            Ok(match Tagged::deserialize(d)? {
                Tagged::Bool(b) => Value::Bool(b),
                Tagged::Num(n) => Value::Num(n),
                Tagged::Vec2(v) => Value::Vec2(v),
                Tagged::Text(t) => Value::Text(t),
            })
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Num(n) => write!(f, "{n}"),
            Value::Vec2([x, y]) => write!(f, "[{x}, {y}]"),
            Value::Text(t) => write!(f, "{t:?}"),
        }
    }
}

impl From<bool> for Value {
    fn from(b: bool) -> Self {
        Value::Bool(b)
    }
}
impl From<f64> for Value {
    fn from(n: f64) -> Self {
        Value::Num(n)
    }
}
impl From<[f64; 2]> for Value {
    fn from(v: [f64; 2]) -> Self {
        Value::Vec2(v)
    }
}
impl From<&str> for Value {
    fn from(t: &str) -> Self {
        Value::Text(Arc::from(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all() -> Vec<Value> {
        vec![
            Value::Bool(true),
            Value::Num(-2.5),
            Value::Vec2([1.0, -3.25]),
            Value::Text(Arc::from("yellow")),
        ]
    }

    #[test]
    fn binary_values_round_trip_with_their_tag() {
        for (tag, v) in all().into_iter().enumerate() {
            let bytes = postcard::to_allocvec(&v).expect("encodes");
            assert_eq!(bytes[0] as usize, tag, "{v:?} is tagged {tag}");
            let back: Value = postcard::from_bytes(&bytes).expect("decodes");
            assert!(back.same_as(&v), "{v:?} came back as {back:?}");
        }
    }

    #[test]
    fn human_readable_values_are_written_as_themselves() {
        let json: Vec<String> = all()
            .iter()
            .map(|v| serde_json::to_string(v).expect("json"))
            .collect();
        assert_eq!(json, ["true", "-2.5", "[1.0,-3.25]", "\"yellow\""]);
        for (v, j) in all().iter().zip(&json) {
            let back: Value = serde_json::from_str(j).expect("reads");
            assert!(back.same_as(v));
        }
    }

    #[test]
    fn an_unknown_binary_tag_is_an_error_not_a_panic() {
        assert!(postcard::from_bytes::<Value>(&[7, 0]).is_err());
        assert!(postcard::from_bytes::<Value>(&[]).is_err());
    }
}
