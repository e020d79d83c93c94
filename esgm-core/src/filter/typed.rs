//! The typed expression tree: what a filter compiles to.
//!
//! There is one tree per static type, and every int-to-float promotion is an explicit
//! [`FloatExpr::FromInt`] node, so evaluation never inspects a type tag and never
//! builds an intermediate value: each node yields a plain `i64`, `f64`, `bool` or
//! borrowed `&str`.

use std::fmt;

use super::ast::{Arith, Cmp};
use super::path::Path;

/// The static types of the language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Ty {
    /// `Long` and `Time` attributes, integer literals, `len(..)`.
    Int,
    /// `Double` and `Altitude` attributes and fields, float literals.
    Float,
    Bool,
    /// `String` and `Symbol` attributes, string literals.
    Str,
}

impl fmt::Display for Ty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Ty::Int => "Int",
            Ty::Float => "Float",
            Ty::Bool => "Bool",
            Ty::Str => "Str",
        })
    }
}

/// A checked expression of any type, as the checker builds it bottom-up.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Typed {
    Int(IntExpr),
    Float(FloatExpr),
    Bool(BoolExpr),
    Str(StrExpr),
}

impl Typed {
    pub fn ty(&self) -> Ty {
        match self {
            Typed::Int(_) => Ty::Int,
            Typed::Float(_) => Ty::Float,
            Typed::Bool(_) => Ty::Bool,
            Typed::Str(_) => Ty::Str,
        }
    }

    /// The expression as a float, promoting an integer; `None` if it is no number.
    pub fn into_float(self) -> Option<FloatExpr> {
        match self {
            Typed::Int(e) => Some(FloatExpr::FromInt(Box::new(e))),
            Typed::Float(e) => Some(e),
            Typed::Bool(_) | Typed::Str(_) => None,
        }
    }
}

/// A truth-valued expression; a whole filter is one.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum BoolExpr {
    Const(bool),
    Attr(Path),
    Not(Box<BoolExpr>),
    And(Box<BoolExpr>, Box<BoolExpr>),
    Or(Box<BoolExpr>, Box<BoolExpr>),
    Int(Cmp, Box<IntExpr>, Box<IntExpr>),
    Float(Cmp, Box<FloatExpr>, Box<FloatExpr>),
    Str(Cmp, Box<StrExpr>, Box<StrExpr>),
    /// Only `==` and `!=`.
    Bool(Cmp, Box<BoolExpr>, Box<BoolExpr>),
}

/// An integer expression.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum IntExpr {
    Const(i64),
    Attr(Path),
    /// `len(path)` of a sequence or string attribute.
    Len(Path),
    Neg(Box<IntExpr>),
    Abs(Box<IntExpr>),
    Arith(Arith, Box<IntExpr>, Box<IntExpr>),
}

/// A float expression.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum FloatExpr {
    Const(f64),
    Attr(Path),
    FromInt(Box<IntExpr>),
    Neg(Box<FloatExpr>),
    Abs(Box<FloatExpr>),
    Arith(Arith, Box<FloatExpr>, Box<FloatExpr>),
}

/// A string expression: strings are only compared, so there are no string operators
/// (and nothing that would allocate during evaluation).
#[derive(Debug, Clone, PartialEq)]
pub(super) enum StrExpr {
    Const(Box<str>),
    Attr(Path),
}
