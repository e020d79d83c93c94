//! The type checker: a syntax tree and the trajectory's type to a typed tree.
//!
//! Attribute references are resolved here, once, against the type (and the element
//! types of nested frames), so every question a structure could raise at run time
//! (does `szie` exist? is `name` a number?) is answered when the policy is made.

use super::ast::{BinaryOp, Cmp, Expr, ExprKind, Ident, UnaryOp};
use super::error::FilterError;
use super::lexer::Span;
use super::path::{Field, Path, Step, has_len};
use super::typed::{BoolExpr, FloatExpr, IntExpr, StrExpr, Typed};
use crate::type_check::TypeChecker;
use crate::type_registry::closest_name;
use crate::types::EntityStructureType;
use crate::value::ValueSort;

const FUNCTIONS: [&str; 2] = ["len", "abs"];
const NUMBER: &str = "Int or Float";
const SCALAR: &str = "Int, Float, Bool or Str";
const STRUCTURED: &str =
    "a frame or a structured value (Pos2, Vec, Position, Rotation, PositionAltitude, …)";

/// Checks a whole filter, which must be a truth value.
pub(super) fn check(
    source: &str,
    expr: &Expr,
    types: &TypeChecker,
) -> Result<BoolExpr, FilterError> {
    let checker = Checker { source, types };
    match checker.expr(expr)? {
        Typed::Bool(b) => Ok(b),
        other => Err(FilterError::mismatch(checker.text(expr.span), "Bool", other.ty())),
    }
}

struct Checker<'a> {
    source: &'a str,
    types: &'a TypeChecker,
}

/// Where a path has got to, statically.
#[derive(Clone, Copy)]
enum Shape<'a> {
    Frame { type_name: &'a str, ty: &'a EntityStructureType },
    Sort(ValueSort),
}

fn boxed<T>(t: T) -> Box<T> {
    Box::new(t)
}

/// Segments joined with dots: the path as written.
fn join(segments: &[Ident]) -> String {
    let names: Vec<&str> = segments.iter().map(|s| s.name.as_str()).collect();
    names.join(".")
}

impl<'a> Checker<'a> {
    fn text(&self, span: Span) -> String {
        self.source.get(span.start..span.end).unwrap_or_default().to_owned()
    }

    fn expr(&self, e: &Expr) -> Result<Typed, FilterError> {
        match &e.kind {
            ExprKind::Int(v) => Ok(Typed::Int(IntExpr::Const(*v))),
            ExprKind::Float(v) => Ok(Typed::Float(FloatExpr::Const(*v))),
            ExprKind::Bool(v) => Ok(Typed::Bool(BoolExpr::Const(*v))),
            ExprKind::Str(v) => Ok(Typed::Str(StrExpr::Const(v.as_str().into()))),
            ExprKind::Path(segments) => {
                let (path, sort) = self.path(segments)?;
                scalar(path, sort)
                    .ok_or_else(|| FilterError::mismatch(self.text(e.span), SCALAR, sort))
            }
            ExprKind::Call { function, args } => self.call(function, args),
            ExprKind::Unary { op, operand } => self.unary(*op, operand),
            ExprKind::Binary { op, lhs, rhs } => self.binary(*op, lhs, rhs, e.span),
        }
    }

    fn expect_bool(&self, e: &Expr) -> Result<BoolExpr, FilterError> {
        match self.expr(e)? {
            Typed::Bool(b) => Ok(b),
            other => Err(FilterError::mismatch(self.text(e.span), "Bool", other.ty())),
        }
    }

    fn unary(&self, op: UnaryOp, operand: &Expr) -> Result<Typed, FilterError> {
        match op {
            UnaryOp::Not => Ok(Typed::Bool(BoolExpr::Not(boxed(self.expect_bool(operand)?)))),
            UnaryOp::Neg => match self.expr(operand)? {
                Typed::Int(e) => Ok(Typed::Int(IntExpr::Neg(boxed(e)))),
                Typed::Float(e) => Ok(Typed::Float(FloatExpr::Neg(boxed(e)))),
                other => Err(FilterError::mismatch(self.text(operand.span), NUMBER, other.ty())),
            },
        }
    }

    fn binary(
        &self,
        op: BinaryOp,
        lhs: &Expr,
        rhs: &Expr,
        whole: Span,
    ) -> Result<Typed, FilterError> {
        match op {
            BinaryOp::And | BinaryOp::Or => {
                let (l, r) = (boxed(self.expect_bool(lhs)?), boxed(self.expect_bool(rhs)?));
                Ok(Typed::Bool(if op == BinaryOp::And {
                    BoolExpr::And(l, r)
                } else {
                    BoolExpr::Or(l, r)
                }))
            }
            BinaryOp::Cmp(cmp) => self.compare(cmp, self.expr(lhs)?, self.expr(rhs)?, whole),
            BinaryOp::Arith(arith) => {
                let (l, r) = (self.expr(lhs)?, self.expr(rhs)?);
                let (lt, rt) = (l.ty(), r.ty());
                match (l, r) {
                    (Typed::Int(a), Typed::Int(b)) => {
                        Ok(Typed::Int(IntExpr::Arith(arith, boxed(a), boxed(b))))
                    }
                    (l, r) => match (l.into_float(), r.into_float()) {
                        (Some(a), Some(b)) => {
                            Ok(Typed::Float(FloatExpr::Arith(arith, boxed(a), boxed(b))))
                        }
                        (None, _) => Err(FilterError::mismatch(self.text(lhs.span), NUMBER, lt)),
                        (_, None) => Err(FilterError::mismatch(self.text(rhs.span), NUMBER, rt)),
                    },
                }
            }
        }
    }

    /// Numbers compare with numbers (an integer is promoted if the other side is a
    /// float), strings with strings, bools with bools (equality only).
    fn compare(&self, cmp: Cmp, l: Typed, r: Typed, whole: Span) -> Result<Typed, FilterError> {
        let (lt, rt) = (l.ty(), r.ty());
        let found = format!("{lt} {} {rt}", cmp.symbol());
        let b = match (l, r) {
            (Typed::Int(a), Typed::Int(b)) => BoolExpr::Int(cmp, boxed(a), boxed(b)),
            (Typed::Str(a), Typed::Str(b)) => BoolExpr::Str(cmp, boxed(a), boxed(b)),
            (Typed::Bool(a), Typed::Bool(b)) if cmp.is_equality() => {
                BoolExpr::Bool(cmp, boxed(a), boxed(b))
            }
            (Typed::Bool(_), Typed::Bool(_)) => {
                let expected = "two numbers or two strings (bools have only `==` and `!=`)";
                return Err(FilterError::mismatch(self.text(whole), expected, found));
            }
            (l, r) => match (l.into_float(), r.into_float()) {
                (Some(a), Some(b)) => BoolExpr::Float(cmp, boxed(a), boxed(b)),
                _ => {
                    let expected = "two numbers, two strings or two bools";
                    return Err(FilterError::mismatch(self.text(whole), expected, found));
                }
            },
        };
        Ok(Typed::Bool(b))
    }

    fn call(&self, function: &Ident, args: &[Expr]) -> Result<Typed, FilterError> {
        let name = function.name.as_str();
        if !FUNCTIONS.contains(&name) {
            return Err(FilterError::UnknownFunction {
                function: name.to_owned(),
                suggestion: suggest(name, FUNCTIONS.into_iter()),
            });
        }
        let [arg] = args else {
            return Err(FilterError::WrongArgumentCount {
                function: name.to_owned(),
                expected: 1,
                found: args.len(),
            });
        };
        if name == "len" {
            return self.len(arg);
        }
        match self.expr(arg)? {
            Typed::Int(e) => Ok(Typed::Int(IntExpr::Abs(boxed(e)))),
            Typed::Float(e) => Ok(Typed::Float(FloatExpr::Abs(boxed(e)))),
            other => Err(FilterError::mismatch(self.text(arg.span), NUMBER, other.ty())),
        }
    }

    /// `len` of a sequence or string attribute, or of a string literal.
    fn len(&self, arg: &Expr) -> Result<Typed, FilterError> {
        let expected = "a sequence or a string";
        match &arg.kind {
            ExprKind::Path(segments) => {
                let (path, sort) = self.path(segments)?;
                if !has_len(sort) {
                    return Err(FilterError::mismatch(self.text(arg.span), expected, sort));
                }
                Ok(Typed::Int(IntExpr::Len(path)))
            }
            ExprKind::Str(s) => {
                let n = i64::try_from(s.chars().count()).unwrap_or(i64::MAX);
                Ok(Typed::Int(IntExpr::Const(n)))
            }
            _ => Err(FilterError::mismatch(self.text(arg.span), expected, self.expr(arg)?.ty())),
        }
    }

    /// Resolves a path against the type, returning it and the sort it reaches.
    fn path(&self, segments: &[Ident]) -> Result<(Path, ValueSort), FilterError> {
        let mut steps = Vec::with_capacity(segments.len());
        let mut shape =
            Shape::Frame { type_name: self.types.type_name(), ty: self.types.entity_type() };
        let mut sort = ValueSort::EntityFrame;
        for (i, segment) in segments.iter().enumerate() {
            let written = || join(&segments[..=i]);
            let with_prefix = |s: &str| join(&segments[..i]) + if i > 0 { "." } else { "" } + s;
            let last = i + 1 == segments.len();
            match shape {
                Shape::Frame { type_name, ty } => {
                    let Some((index, attr)) =
                        ty.attributes.iter().enumerate().find(|(_, a)| a.name == segment.name)
                    else {
                        let names = ty.attributes.iter().map(|a| a.name.as_str());
                        return Err(FilterError::UnknownAttribute {
                            attribute: written(),
                            type_name: type_name.to_owned(),
                            suggestion: suggest(&segment.name, names).map(|s| with_prefix(&s)),
                        });
                    };
                    steps.push(Step::Attr { name: attr.name.as_str().into(), index });
                    sort = attr.sort;
                    let untyped = || FilterError::UntypedAttribute {
                        attribute: written(),
                        type_name: type_name.to_owned(),
                        sort: attr.sort,
                    };
                    shape = match (attr.sort, attr.element_type.as_deref()) {
                        (ValueSort::AnyValue, _) => return Err(untyped()),
                        (ValueSort::EntityFrame, Some(element)) => {
                            let ty = self.types.resolve(element).ok_or_else(untyped)?;
                            Shape::Frame { type_name: element, ty }
                        }
                        (ValueSort::EntityFrame, None) if !last => return Err(untyped()),
                        (s, _) => Shape::Sort(s),
                    };
                }
                Shape::Sort(s) => {
                    let fields = Field::of(s);
                    if fields.is_empty() {
                        return Err(FilterError::mismatch(join(&segments[..i]), STRUCTURED, s));
                    }
                    let Some(&(_, field, field_sort)) = fields.iter().find(|f| f.0 == segment.name)
                    else {
                        let names = fields.iter().map(|f| f.0);
                        return Err(FilterError::UnknownAttribute {
                            attribute: written(),
                            type_name: s.to_string(),
                            suggestion: suggest(&segment.name, names).map(|s| with_prefix(&s)),
                        });
                    };
                    steps.push(Step::Field(field));
                    sort = field_sort;
                    shape = Shape::Sort(field_sort);
                }
            }
        }
        Ok((Path::new(steps), sort))
    }
}

/// The candidate closest to `name` (adjacent swaps such as `szie` count as one edit).
fn suggest<'c>(name: &str, candidates: impl Iterator<Item = &'c str>) -> Option<String> {
    closest_name(name, candidates)
}

/// A path of a scalar sort as an expression of its type; `None` for other sorts.
fn scalar(path: Path, sort: ValueSort) -> Option<Typed> {
    Some(match sort {
        ValueSort::Long | ValueSort::Time => Typed::Int(IntExpr::Attr(path)),
        ValueSort::Double | ValueSort::Altitude => Typed::Float(FloatExpr::Attr(path)),
        ValueSort::Bool => Typed::Bool(BoolExpr::Attr(path)),
        ValueSort::String | ValueSort::Symbol => Typed::Str(StrExpr::Attr(path)),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::compile;
    use super::*;
    use crate::filter::ast::Cmp;

    fn err(source: &str) -> FilterError {
        match compile(source) {
            Err(e) => e,
            Ok(f) => panic!("`{source}` compiled to {f:?}"),
        }
    }

    fn mismatch(source: &str) -> (String, String, String) {
        match err(source) {
            FilterError::TypeMismatch { expression, expected, found } => {
                (expression, expected, found)
            }
            e => panic!("`{source}`: expected a type mismatch, got {e:?}"),
        }
    }

    fn unknown(attribute: &str, type_name: &str, suggestion: Option<&str>) -> FilterError {
        FilterError::UnknownAttribute {
            attribute: attribute.into(),
            type_name: type_name.into(),
            suggestion: suggestion.map(Into::into),
        }
    }

    #[test]
    fn unknown_attributes_suggest_the_closest_path() {
        assert_eq!(err("szie > 3"), unknown("szie", "All", Some("size")));
        assert_eq!(err("best.szie > 3"), unknown("best.szie", "Blob", Some("best.size")));
        assert_eq!(
            err("pose.position.nroth > 1"),
            unknown("pose.position.nroth", "Position", Some("pose.position.north"))
        );
        assert_eq!(err("rot.z > 1"), unknown("rot.z", "Rotation", None));
        assert_eq!(err("zzzzzz > 1"), unknown("zzzzzz", "All", None));
        assert_eq!(
            err("best.szie > 3").to_string(),
            "unknown attribute `best.szie` (not declared by `Blob`); did you mean `best.size`?"
        );
    }

    #[test]
    fn the_filter_must_be_a_bool() {
        let m = |e: &str, f: &str| (e.to_owned(), "Bool".to_owned(), f.to_owned());
        assert_eq!(mismatch("x + 1"), m("x + 1", "Int"));
        assert_eq!(mismatch(" speed * 2 "), m("speed * 2", "Float"));
        assert_eq!(mismatch("name"), m("name", "Str"));
        assert_eq!(mismatch("(size)"), m("(size)", "Int"));
        assert_eq!(err("x + 1").to_string(), "`x + 1` has type Int, expected Bool");
    }

    #[test]
    fn operands_of_the_wrong_type() {
        let (expression, _, found) = mismatch("name > 3");
        assert_eq!((expression.as_str(), found.as_str()), ("name > 3", "Str > Int"));
        assert_eq!(mismatch("3.5 == sym").2, "Float == Str");
        assert_eq!(mismatch("flag == 1").2, "Bool == Int");
        let (_, expected, found) = mismatch("flag < true");
        assert!(expected.contains("`==` and `!=`"), "{expected}");
        assert_eq!(found, "Bool < Bool");

        let scalar = |e: &str, f: &str| (e.to_owned(), SCALAR.to_owned(), f.to_owned());
        assert_eq!(mismatch("image_data > 3"), scalar("image_data", "OctetSeq"));
        assert_eq!(mismatch("pos == 3"), scalar("pos", "Pos2"));
        assert_eq!(mismatch("best > 3"), scalar("best", "EntityFrame"));
        assert_eq!(mismatch("raw == 3"), scalar("raw", "EntityFrame"));
        assert_eq!(mismatch("pose.position > 3"), scalar("pose.position", "Position"));

        let number = |e: &str, f: &str| (e.to_owned(), NUMBER.to_owned(), f.to_owned());
        assert_eq!(mismatch("-name < 0"), number("name", "Str"));
        assert_eq!(mismatch(r#""a" + 1 > 0"#), number(r#""a""#, "Str"));
        assert_eq!(mismatch("size + flag > 1"), number("flag", "Bool"));
        assert_eq!(mismatch("abs(name) > 1"), number("name", "Str"));
        assert_eq!(mismatch("flag && size"), ("size".into(), "Bool".into(), "Int".into()));
        assert_eq!(mismatch("!(size)"), ("(size)".into(), "Bool".into(), "Int".into()));
        assert_eq!(mismatch("size || flag"), ("size".into(), "Bool".into(), "Int".into()));

        let seq =
            |e: &str, f: &str| (e.to_owned(), "a sequence or a string".to_owned(), f.to_owned());
        assert_eq!(mismatch("len(size) > 1"), seq("size", "Long"));
        assert_eq!(mismatch("len(best) > 1"), seq("best", "EntityFrame"));
        assert_eq!(mismatch("len(1 + 2) > 1"), seq("1 + 2", "Int"));

        let structured = |e: &str, f: &str| (e.to_owned(), STRUCTURED.to_owned(), f.to_owned());
        assert_eq!(mismatch("size.x > 1"), structured("size", "Long"));
        assert_eq!(mismatch("items.size > 1"), structured("items", "EntityFrameSeq"));
        assert_eq!(mismatch("pose.altitude.x > 1"), structured("pose.altitude", "Altitude"));
    }

    #[test]
    fn untyped_attributes_are_refused() {
        let untyped = |attribute: &str, sort| FilterError::UntypedAttribute {
            attribute: attribute.into(),
            type_name: "All".into(),
            sort,
        };
        assert_eq!(err("any > 1"), untyped("any", ValueSort::AnyValue));
        assert_eq!(err("len(any) > 1"), untyped("any", ValueSort::AnyValue));
        assert_eq!(err("any.x > 1"), untyped("any", ValueSort::AnyValue));
        assert_eq!(err("raw.x > 1"), untyped("raw", ValueSort::EntityFrame));
        assert_eq!(
            err("any > 1").to_string(),
            "attribute `any` of `All` has sort AnyValue with no declared value type, so a \
             filter cannot use it"
        );
    }

    #[test]
    fn unknown_functions_and_arity() {
        assert_eq!(
            err("foo(x) > 1"),
            FilterError::UnknownFunction { function: "foo".into(), suggestion: None }
        );
        assert_eq!(
            err("lne(items) > 1").to_string(),
            "unknown function `lne`; did you mean `len`?"
        );
        assert_eq!(
            err("len(items, x) > 1"),
            FilterError::WrongArgumentCount { function: "len".into(), expected: 1, found: 2 }
        );
        assert_eq!(err("abs() > 1").to_string(), "`abs` takes 1 argument(s), found 0");
    }

    #[test]
    fn types_and_promotions_are_explicit() {
        let f = compile("size < speed").unwrap();
        let size = Path::new(vec![Step::Attr { name: "size".into(), index: 0 }]);
        let speed = Path::new(vec![Step::Attr { name: "speed".into(), index: 3 }]);
        assert_eq!(
            f.expr,
            BoolExpr::Float(
                Cmp::Lt,
                boxed(FloatExpr::FromInt(boxed(IntExpr::Attr(size.clone())))),
                boxed(FloatExpr::Attr(speed)),
            )
        );
        let f = compile("size % 2 == 0").unwrap();
        assert!(matches!(f.expr, BoolExpr::Int(Cmp::Eq, ..)));
        let f = compile(r#"sym >= "a""#).unwrap();
        assert!(matches!(f.expr, BoolExpr::Str(Cmp::Ge, ..)));
        let f = compile("flag != (size > 1)").unwrap();
        assert!(matches!(f.expr, BoolExpr::Bool(Cmp::Ne, ..)));
        let f = compile("len(name) > abs(-2.5)").unwrap();
        assert!(matches!(f.expr, BoolExpr::Float(Cmp::Gt, ..)));
        let f = compile(r#"len("héllo") == 5"#).unwrap();
        assert_eq!(
            f.expr,
            BoolExpr::Int(Cmp::Eq, boxed(IntExpr::Const(5)), boxed(IntExpr::Const(5)))
        );
    }

    #[test]
    fn paths_resolve_to_declared_positions_and_fields() {
        let f = compile("pose.position.north > best.size").unwrap();
        let north = Path::new(vec![
            Step::Attr { name: "pose".into(), index: 20 },
            Step::Field(Field::Position),
            Step::Field(Field::North),
        ]);
        let best_size = Path::new(vec![
            Step::Attr { name: "best".into(), index: 23 },
            Step::Attr { name: "size".into(), index: 2 },
        ]);
        assert_eq!(
            f.expr,
            BoolExpr::Float(
                Cmp::Gt,
                boxed(FloatExpr::Attr(north)),
                boxed(FloatExpr::FromInt(boxed(IntExpr::Attr(best_size)))),
            )
        );
        let f = compile("t > 0 && pa.altitude > 0").unwrap();
        assert!(matches!(
            f.expr,
            BoolExpr::And(ref a, ref b)
                if matches!(**a, BoolExpr::Int(..)) && matches!(**b, BoolExpr::Float(..))
        ));
    }
}
