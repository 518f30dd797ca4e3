//! The compiled form of a condition: a flat array of nodes that refer to
//! their children by `u32` index (children always come before parents).

use crate::ids::{BehaviorId, BeliefId};
use std::sync::Arc;

/// Static type of a sub-expression. `Any` is a belief (dynamically typed).
///
/// A known type means "this type, or unknown at run time".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Ty {
    Bool,
    Num,
    Vec,
    Text,
    Any,
}

impl Ty {
    /// The type name used by [`crate::value::Value::type_name`], if known.
    pub(super) fn name(self) -> Option<&'static str> {
        match self {
            Ty::Bool => Some("bool"),
            Ty::Num => Some("number"),
            Ty::Vec => Some("vector"),
            Ty::Text => Some("text"),
            Ty::Any => None,
        }
    }

    /// The type name for messages (`value` when unknown).
    pub(super) fn describe(self) -> &'static str {
        self.name().unwrap_or("value")
    }
}

/// Comparison operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum CmpOp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl CmpOp {
    /// The operator with its operands swapped (`a < b` is `b > a`).
    pub(super) fn flip(self) -> CmpOp {
        match self {
            CmpOp::Lt => CmpOp::Gt,
            CmpOp::Le => CmpOp::Ge,
            CmpOp::Gt => CmpOp::Lt,
            CmpOp::Ge => CmpOp::Le,
            op => op,
        }
    }
}

/// Arithmetic operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ArithOp {
    Add,
    Sub,
    Mul,
    Div,
}

/// One-argument numeric functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Fn1 {
    Abs,
    Norm,
}

/// Two-argument numeric functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Fn2 {
    Min,
    Max,
    Dist,
}

/// One node of a compiled expression.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Node {
    Bool(bool),
    Num(f64),
    Vec2([f64; 2]),
    Text(Arc<str>),
    Belief(BeliefId),
    Known(BeliefId),
    Age(BeliefId),
    Elapsed,
    Runs(Option<BehaviorId>),
    MakeVec(u32, u32),
    /// Component access: `.x` (0) or `.y` (1).
    Comp(u32, u8),
    Neg(u32),
    Not(u32),
    /// `&&` over `lists[start..start + len]`.
    And(u32, u32),
    /// `||` over `lists[start..start + len]`.
    Or(u32, u32),
    Cmp(CmpOp, u32, u32),
    /// A comparison of two statically numeric operands.
    CmpNums(CmpOp, u32, u32),
    /// `belief <op> number` (a fused `Cmp`; the operand nodes stay unused).
    CmpBelief(CmpOp, BeliefId, f64),
    /// `child <op> number` (a fused `Cmp`).
    CmpNum(CmpOp, u32, f64),
    Arith(ArithOp, u32, u32),
    Call1(Fn1, u32),
    Call2(Fn2, u32, u32),
}
