//! The syntax tree the parser produces: untyped, with the span of every node so the
//! type checker can quote the offending expression.

use super::lexer::Span;

/// The deepest expression the parser accepts. Checking and evaluation recurse over the
/// tree, so its depth is bounded to keep them from overflowing the stack on hostile
/// input; real filters are a few levels deep.
pub(super) const MAX_DEPTH: usize = 100;

/// One expression node.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Expr {
    pub kind: ExprKind,
    /// The source text it was parsed from (parentheses included).
    pub span: Span,
    /// Nodes on the longest path down from here, this one included.
    pub depth: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub(super) enum ExprKind {
    Int(i64),
    Float(f64),
    Bool(bool),
    Str(String),
    /// An attribute reference: `size`, `best.size`, `pose.position.north`.
    Path(Vec<Ident>),
    Call {
        function: Ident,
        args: Vec<Expr>,
    },
    Unary {
        op: UnaryOp,
        operand: Box<Expr>,
    },
    Binary {
        op: BinaryOp,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
}

/// A name in the source: an attribute or a function.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Ident {
    pub name: String,
    pub span: Span,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum UnaryOp {
    /// `!` or `not`.
    Not,
    /// `-`.
    Neg,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum BinaryOp {
    Or,
    And,
    Cmp(Cmp),
    Arith(Arith),
}

/// A comparison operator; also used by the typed tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cmp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl Cmp {
    pub fn symbol(self) -> &'static str {
        match self {
            Cmp::Eq => "==",
            Cmp::Ne => "!=",
            Cmp::Lt => "<",
            Cmp::Le => "<=",
            Cmp::Gt => ">",
            Cmp::Ge => ">=",
        }
    }

    /// `==` and `!=`, the only comparisons bools have.
    pub fn is_equality(self) -> bool {
        matches!(self, Cmp::Eq | Cmp::Ne)
    }
}

/// An arithmetic operator; also used by the typed tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Arith {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
}
