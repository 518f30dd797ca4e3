//! Evaluation of a compiled expression. Allocation-free: intermediate values
//! borrow text from the expression or the environment.

use super::node::{ArithOp, CmpOp, Fn1, Fn2, Node};
use super::{Env, Expr};
use crate::value::Value;
use std::sync::Arc;

/// An intermediate value; `Unknown` is the closed-world "not known".
#[derive(Clone, Copy, Debug)]
pub(super) enum V<'a> {
    Unknown,
    Bool(bool),
    Num(f64),
    Vec2([f64; 2]),
    Text(&'a Arc<str>),
}

impl V<'_> {
    fn from_value(v: Option<&Value>) -> V<'_> {
        match v {
            None => V::Unknown,
            Some(Value::Bool(b)) => V::Bool(*b),
            Some(Value::Num(n)) => V::Num(*n),
            Some(Value::Vec2(v)) => V::Vec2(*v),
            Some(Value::Text(t)) => V::Text(t),
        }
    }

    /// The owned value (cloning text is a reference-count increment).
    pub(super) fn to_value(self) -> Option<Value> {
        match self {
            V::Unknown => None,
            V::Bool(b) => Some(Value::Bool(b)),
            V::Num(n) => Some(Value::Num(n)),
            V::Vec2(v) => Some(Value::Vec2(v)),
            V::Text(t) => Some(Value::Text(Arc::clone(t))),
        }
    }
}

/// A computed number: unknown unless finite.
#[inline]
fn num<'a>(n: f64) -> V<'a> {
    if n.is_finite() { V::Num(n) } else { V::Unknown }
}

/// A computed number, if finite.
#[inline]
fn finite(n: f64) -> Option<f64> {
    n.is_finite().then_some(n)
}

/// A computed vector: unknown unless both components are finite.
#[inline]
fn vec2<'a>(x: f64, y: f64) -> V<'a> {
    if x.is_finite() && y.is_finite() {
        V::Vec2([x, y])
    } else {
        V::Unknown
    }
}

/// `Some(equal)` when both sides are known; values of different types are
/// never equal.
#[inline]
fn equal(a: V<'_>, b: V<'_>) -> Option<bool> {
    Some(match (a, b) {
        (V::Unknown, _) | (_, V::Unknown) => return None,
        (V::Bool(x), V::Bool(y)) => x == y,
        (V::Num(x), V::Num(y)) => x == y,
        (V::Vec2(x), V::Vec2(y)) => x[0] == y[0] && x[1] == y[1],
        (V::Text(x), V::Text(y)) => **x == **y,
        _ => false,
    })
}

#[inline(always)]
fn compare_num(op: CmpOp, x: f64, y: f64) -> bool {
    match op {
        CmpOp::Eq => x == y,
        CmpOp::Ne => x != y,
        CmpOp::Lt => x < y,
        CmpOp::Le => x <= y,
        CmpOp::Gt => x > y,
        CmpOp::Ge => x >= y,
    }
}

#[inline]
fn compare(op: CmpOp, a: V<'_>, b: V<'_>) -> bool {
    if let (V::Num(x), V::Num(y)) = (a, b) {
        return compare_num(op, x, y);
    }
    match op {
        CmpOp::Eq => equal(a, b) == Some(true),
        CmpOp::Ne => equal(a, b) == Some(false),
        _ => {
            let ord = match (a, b) {
                (V::Num(x), V::Num(y)) => x.partial_cmp(&y),
                (V::Text(x), V::Text(y)) => Some((**x).cmp(&**y)),
                _ => None,
            };
            let Some(ord) = ord else { return false };
            match op {
                CmpOp::Lt => ord.is_lt(),
                CmpOp::Le => ord.is_le(),
                CmpOp::Gt => ord.is_gt(),
                _ => ord.is_ge(),
            }
        }
    }
}

#[inline]
fn arith<'a>(op: ArithOp, a: V<'a>, b: V<'a>) -> V<'a> {
    match (op, a, b) {
        (ArithOp::Add, V::Num(x), V::Num(y)) => num(x + y),
        (ArithOp::Sub, V::Num(x), V::Num(y)) => num(x - y),
        (ArithOp::Mul, V::Num(x), V::Num(y)) => num(x * y),
        (ArithOp::Div, V::Num(x), V::Num(y)) if y != 0.0 => num(x / y),
        (ArithOp::Add, V::Vec2(x), V::Vec2(y)) => vec2(x[0] + y[0], x[1] + y[1]),
        (ArithOp::Sub, V::Vec2(x), V::Vec2(y)) => vec2(x[0] - y[0], x[1] - y[1]),
        (ArithOp::Mul, V::Vec2(v), V::Num(k)) | (ArithOp::Mul, V::Num(k), V::Vec2(v)) => {
            vec2(v[0] * k, v[1] * k)
        }
        (ArithOp::Div, V::Vec2(v), V::Num(k)) if k != 0.0 => vec2(v[0] / k, v[1] / k),
        _ => V::Unknown,
    }
}

impl Expr {
    /// The children of an n-ary node.
    #[inline]
    fn list(&self, start: u32, len: u32) -> &[u32] {
        let start = start as usize;
        self.lists.get(start..start + len as usize).unwrap_or(&[])
    }

    /// Node `i` in boolean position: true only for `Bool(true)`.
    pub(super) fn truth<E: Env + ?Sized>(&self, i: u32, env: &E) -> bool {
        match self.nodes.get(i as usize) {
            Some(Node::And(s, n)) => self.list(*s, *n).iter().all(|&c| self.truth(c, env)),
            Some(Node::Or(s, n)) => self.list(*s, *n).iter().any(|&c| self.truth(c, env)),
            Some(Node::Not(c)) => !self.truth(*c, env),
            Some(Node::CmpBelief(op, id, k)) => match env.belief(*id) {
                Some(Value::Num(x)) => compare_num(*op, *x, *k),
                // A known value of another type: never equal, not ordered.
                Some(_) => *op == CmpOp::Ne,
                None => false,
            },
            Some(Node::CmpNum(op, a, k)) => match self.number(*a, env) {
                Some(x) => compare_num(*op, x, *k),
                // Not a number: `!=` holds if the operand is known at all.
                None => *op == CmpOp::Ne && !matches!(self.value(*a, env), V::Unknown),
            },
            Some(Node::CmpNums(op, a, b)) => match (self.number(*a, env), self.number(*b, env)) {
                (Some(x), Some(y)) => compare_num(*op, x, y),
                _ => false,
            },
            Some(Node::Cmp(op, a, b)) => compare(*op, self.value(*a, env), self.value(*b, env)),
            Some(Node::Belief(id)) => matches!(env.belief(*id), Some(Value::Bool(true))),
            Some(Node::Known(id)) => env.belief(*id).is_some(),
            Some(Node::Bool(b)) => *b,
            _ => matches!(self.value(i, env), V::Bool(true)),
        }
    }

    /// Node `i` as a value.
    pub(super) fn value<'a, E: Env + ?Sized>(&'a self, i: u32, env: &'a E) -> V<'a> {
        let Some(node) = self.nodes.get(i as usize) else {
            return V::Unknown;
        };
        match node {
            Node::Num(n) => V::Num(*n),
            Node::Belief(id) => V::from_value(env.belief(*id)),
            Node::Bool(b) => V::Bool(*b),
            Node::Vec2(v) => V::Vec2(*v),
            Node::Text(t) => V::Text(t),
            Node::Known(_)
            | Node::Not(_)
            | Node::And(..)
            | Node::Or(..)
            | Node::Cmp(..)
            | Node::CmpNums(..)
            | Node::CmpBelief(..)
            | Node::CmpNum(..) => V::Bool(self.truth(i, env)),
            Node::Age(_)
            | Node::Elapsed
            | Node::Runs(_)
            | Node::Comp(..)
            | Node::Call1(..)
            | Node::Call2(..) => self.number(i, env).map_or(V::Unknown, V::Num),
            Node::MakeVec(a, b) => match (self.number(*a, env), self.number(*b, env)) {
                (Some(x), Some(y)) => V::Vec2([x, y]),
                _ => V::Unknown,
            },
            Node::Neg(a) => match self.value(*a, env) {
                V::Num(x) => num(-x),
                V::Vec2([x, y]) => vec2(-x, -y),
                _ => V::Unknown,
            },
            Node::Arith(op, a, b) => arith(*op, self.value(*a, env), self.value(*b, env)),
        }
    }

    /// Node `i` if its value is a number, else None: always equal to
    /// `value(i)` restricted to numbers, but returned in registers and
    /// skipping the type dispatch of non-numeric results.
    pub(super) fn number<E: Env + ?Sized>(&self, i: u32, env: &E) -> Option<f64> {
        match self.nodes.get(i as usize)? {
            Node::Num(n) => Some(*n),
            Node::Belief(id) => env.belief(*id)?.as_num(),
            Node::Age(id) => env.belief_age(*id),
            Node::Elapsed => Some(env.elapsed()),
            Node::Runs(b) => Some(f64::from(env.runs(*b))),
            Node::Arith(op, a, b) => {
                // A numeric result needs two numbers (vector results are not
                // numbers).
                let x = self.number(*a, env)?;
                let y = self.number(*b, env)?;
                finite(match op {
                    ArithOp::Add => x + y,
                    ArithOp::Sub => x - y,
                    ArithOp::Mul => x * y,
                    ArithOp::Div if y != 0.0 => x / y,
                    ArithOp::Div => return None,
                })
            }
            Node::Neg(a) => finite(-self.number(*a, env)?),
            Node::Comp(a, c) => match self.value(*a, env) {
                V::Vec2(v) => Some(if *c == 0 { v[0] } else { v[1] }),
                _ => None,
            },
            Node::Call1(Fn1::Abs, a) => finite(self.number(*a, env)?.abs()),
            Node::Call1(Fn1::Norm, a) => match self.value(*a, env) {
                V::Vec2([x, y]) => finite((x * x + y * y).sqrt()),
                _ => None,
            },
            Node::Call2(Fn2::Min, a, b) => finite(self.number(*a, env)?.min(self.number(*b, env)?)),
            Node::Call2(Fn2::Max, a, b) => finite(self.number(*a, env)?.max(self.number(*b, env)?)),
            Node::Call2(Fn2::Dist, a, b) => match (self.value(*a, env), self.value(*b, env)) {
                (V::Vec2(p), V::Vec2(q)) => {
                    let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
                    finite((dx * dx + dy * dy).sqrt())
                }
                _ => None,
            },
            _ => None,
        }
    }
}
