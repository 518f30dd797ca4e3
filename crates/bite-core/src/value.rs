//! Typed belief values: bool, number, text and 2-D vector.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::sync::Arc;

/// The value of a belief, or of a condition sub-expression.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
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
