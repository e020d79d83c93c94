//! The parser: tokens to a syntax tree, by precedence climbing (Pratt).
//!
//! Precedence, loosest first: `||`, `&&`, prefix `!`, comparisons, `+ -`, `* / %`,
//! prefix `-`. Prefix `!` binds looser than comparisons (as Python's `not`), so
//! `!size > 3` means `!(size > 3)`; since `!` only applies to bools, this never changes
//! the meaning of an expression that would type-check with C's precedence. Comparisons
//! do not chain: `a < b < c` is a syntax error rather than a silent `(a < b) < c`.

use super::ast::{Arith, BinaryOp, Cmp, Expr, ExprKind, Ident, MAX_DEPTH, UnaryOp};
use super::error::FilterError;
use super::lexer::{Span, Token, TokenKind, tokenize};

/// The left and right binding power of each infix operator level: an operator is
/// taken while its left power is at least the caller's minimum, and its right operand
/// is parsed with the right power (one more, so levels associate to the left).
fn infix(kind: &TokenKind) -> Option<(BinaryOp, u8, u8)> {
    let (op, level) = match kind {
        TokenKind::Or => (BinaryOp::Or, 1),
        TokenKind::And => (BinaryOp::And, 2),
        TokenKind::Eq => (BinaryOp::Cmp(Cmp::Eq), 4),
        TokenKind::Ne => (BinaryOp::Cmp(Cmp::Ne), 4),
        TokenKind::Lt => (BinaryOp::Cmp(Cmp::Lt), 4),
        TokenKind::Le => (BinaryOp::Cmp(Cmp::Le), 4),
        TokenKind::Gt => (BinaryOp::Cmp(Cmp::Gt), 4),
        TokenKind::Ge => (BinaryOp::Cmp(Cmp::Ge), 4),
        TokenKind::Plus => (BinaryOp::Arith(Arith::Add), 5),
        TokenKind::Minus => (BinaryOp::Arith(Arith::Sub), 5),
        TokenKind::Star => (BinaryOp::Arith(Arith::Mul), 6),
        TokenKind::Slash => (BinaryOp::Arith(Arith::Div), 6),
        TokenKind::Percent => (BinaryOp::Arith(Arith::Rem), 6),
        _ => return None,
    };
    Some((op, 2 * level, 2 * level + 1))
}

/// `!` takes comparisons into its operand (level 4) but stops at `&&` (level 2).
const NOT_OPERAND: u8 = 2 * 3;
/// `-` takes only a primary (or another prefix) as its operand.
const NEG_OPERAND: u8 = 2 * 7;

/// Parses a whole filter.
pub(super) fn parse(source: &str) -> Result<Expr, FilterError> {
    let tokens = tokenize(source)?;
    let end = Span { start: source.len(), end: source.len() };
    let mut parser = Parser {
        source,
        tokens,
        next: 0,
        eof: Token { kind: TokenKind::Eof, span: end },
        nesting: 0,
    };
    let expr = parser.expr(0)?;
    let token = parser.peek();
    if token.kind != TokenKind::Eof {
        return Err(parser.error(
            token,
            format!(
                "unexpected {}: expected an operator or the end of the filter",
                parser.describe(token)
            ),
        ));
    }
    Ok(expr)
}

struct Parser<'a> {
    source: &'a str,
    tokens: Vec<Token>,
    next: usize,
    eof: Token,
    /// Current recursion depth of `expr`; parentheses recurse without adding nodes.
    nesting: usize,
}

impl Parser<'_> {
    fn peek(&self) -> &Token {
        self.tokens.get(self.next).unwrap_or(&self.eof)
    }

    fn bump(&mut self) -> Token {
        let token = self.peek().clone();
        self.next += 1;
        token
    }

    fn text(&self, span: Span) -> &str {
        self.source.get(span.start..span.end).unwrap_or_default()
    }

    fn describe(&self, token: &Token) -> String {
        match token.kind {
            TokenKind::Eof => "the end of the filter".to_owned(),
            _ => format!("`{}`", self.text(token.span)),
        }
    }

    fn error(&self, at: &Token, message: impl Into<String>) -> FilterError {
        FilterError::syntax(self.source, at.span.start, message)
    }

    fn too_deep(&self, at: Span) -> FilterError {
        let message = format!("the filter is nested too deeply (more than {MAX_DEPTH} levels)");
        FilterError::syntax(self.source, at.start, message)
    }

    /// The depth of a node over children of these depths, refused beyond [`MAX_DEPTH`].
    fn depth(
        &self,
        span: Span,
        children: impl IntoIterator<Item = usize>,
    ) -> Result<usize, FilterError> {
        let depth = 1 + children.into_iter().max().unwrap_or(0);
        if depth > MAX_DEPTH { Err(self.too_deep(span)) } else { Ok(depth) }
    }

    fn leaf(kind: ExprKind, span: Span) -> Expr {
        Expr { kind, span, depth: 1 }
    }

    fn expr(&mut self, min_power: u8) -> Result<Expr, FilterError> {
        self.nesting += 1;
        let result = if self.nesting > MAX_DEPTH {
            Err(self.too_deep(self.peek().span))
        } else {
            self.expr_inner(min_power)
        };
        self.nesting -= 1;
        result
    }

    fn expr_inner(&mut self, min_power: u8) -> Result<Expr, FilterError> {
        let mut lhs = self.prefix()?;
        while let Some((op, left, right)) = infix(&self.peek().kind) {
            if left < min_power {
                break;
            }
            self.bump();
            let rhs = self.expr(right)?;
            let span = lhs.span.to(rhs.span);
            let depth = self.depth(span, [lhs.depth, rhs.depth])?;
            let kind = ExprKind::Binary { op, lhs: Box::new(lhs), rhs: Box::new(rhs) };
            lhs = Expr { kind, span, depth };
            if let (BinaryOp::Cmp(_), Some((BinaryOp::Cmp(_), ..))) = (op, infix(&self.peek().kind))
            {
                return Err(self.error(
                    self.peek(),
                    "comparisons cannot be chained: join them with `&&`, or add parentheses",
                ));
            }
        }
        Ok(lhs)
    }

    fn prefix(&mut self) -> Result<Expr, FilterError> {
        let token = self.bump();
        let span = token.span;
        match token.kind {
            TokenKind::Int(v) => match i64::try_from(v) {
                Ok(v) => Ok(Self::leaf(ExprKind::Int(v), span)),
                // Out of range is the only way `try_from` fails, and the message says so.
                Err(_) => Err(self.error(&token, format!("integer `{v}` is out of range"))),
            },
            TokenKind::Float(v) => Ok(Self::leaf(ExprKind::Float(v), span)),
            TokenKind::Str(s) => Ok(Self::leaf(ExprKind::Str(s), span)),
            TokenKind::True => Ok(Self::leaf(ExprKind::Bool(true), span)),
            TokenKind::False => Ok(Self::leaf(ExprKind::Bool(false), span)),
            TokenKind::Not => self.unary(UnaryOp::Not, span, NOT_OPERAND),
            TokenKind::Minus => {
                // A negative literal is one literal, so that `-9223372036854775808` works.
                if let TokenKind::Int(v) = self.peek().kind {
                    if let Some(v) = 0i64.checked_sub_unsigned(v) {
                        let literal = self.bump();
                        return Ok(Self::leaf(ExprKind::Int(v), span.to(literal.span)));
                    }
                }
                self.unary(UnaryOp::Neg, span, NEG_OPERAND)
            }
            TokenKind::LParen => {
                let inner = self.expr(0)?;
                let close = self.peek();
                if close.kind != TokenKind::RParen {
                    return Err(self.error(
                        close,
                        format!(
                            "expected `)` to close the `(` at byte {}, found {}",
                            span.start,
                            self.describe(close)
                        ),
                    ));
                }
                let close = self.bump();
                Ok(Expr { span: span.to(close.span), ..inner })
            }
            TokenKind::Ident => {
                let ident = Ident { name: self.text(span).to_owned(), span };
                if self.peek().kind == TokenKind::LParen {
                    self.call(ident)
                } else {
                    self.path(ident)
                }
            }
            _ => Err(self
                .error(&token, format!("expected an expression, found {}", self.describe(&token)))),
        }
    }

    fn unary(&mut self, op: UnaryOp, span: Span, operand_power: u8) -> Result<Expr, FilterError> {
        let operand = self.expr(operand_power)?;
        let span = span.to(operand.span);
        let depth = self.depth(span, [operand.depth])?;
        Ok(Expr { kind: ExprKind::Unary { op, operand: Box::new(operand) }, span, depth })
    }

    fn path(&mut self, first: Ident) -> Result<Expr, FilterError> {
        let mut span = first.span;
        let mut segments = vec![first];
        while self.peek().kind == TokenKind::Dot {
            self.bump();
            let token = self.bump();
            if token.kind != TokenKind::Ident {
                return Err(self.error(
                    &token,
                    format!(
                        "expected an attribute name after `.`, found {}",
                        self.describe(&token)
                    ),
                ));
            }
            span = span.to(token.span);
            segments.push(Ident { name: self.text(token.span).to_owned(), span: token.span });
        }
        Ok(Self::leaf(ExprKind::Path(segments), span))
    }

    fn call(&mut self, function: Ident) -> Result<Expr, FilterError> {
        self.bump(); // `(`
        let mut args = Vec::new();
        if self.peek().kind != TokenKind::RParen {
            loop {
                args.push(self.expr(0)?);
                let token = self.peek();
                match token.kind {
                    TokenKind::Comma => {
                        self.bump();
                    }
                    TokenKind::RParen => break,
                    _ => {
                        return Err(self.error(
                            token,
                            format!(
                                "expected `,` or `)` in the arguments of `{}`, found {}",
                                function.name,
                                self.describe(token)
                            ),
                        ));
                    }
                }
            }
        }
        let close = self.bump();
        let span = function.span.to(close.span);
        let depth = self.depth(span, args.iter().map(|a| a.depth))?;
        Ok(Expr { kind: ExprKind::Call { function, args }, span, depth })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tree as an S-expression, to make precedence visible.
    fn sexpr(e: &Expr) -> String {
        match &e.kind {
            ExprKind::Int(v) => v.to_string(),
            ExprKind::Float(v) => format!("{v:?}"),
            ExprKind::Bool(v) => v.to_string(),
            ExprKind::Str(v) => format!("{v:?}"),
            ExprKind::Path(segments) => {
                segments.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(".")
            }
            ExprKind::Call { function, args } => {
                let args: Vec<_> = args.iter().map(sexpr).collect();
                format!("({} {})", function.name, args.join(" "))
            }
            ExprKind::Unary { op, operand } => {
                let op = if *op == UnaryOp::Not { "!" } else { "neg" };
                format!("({op} {})", sexpr(operand))
            }
            ExprKind::Binary { op, lhs, rhs } => {
                let op = match op {
                    BinaryOp::Or => "||",
                    BinaryOp::And => "&&",
                    BinaryOp::Cmp(c) => c.symbol(),
                    BinaryOp::Arith(Arith::Add) => "+",
                    BinaryOp::Arith(Arith::Sub) => "-",
                    BinaryOp::Arith(Arith::Mul) => "*",
                    BinaryOp::Arith(Arith::Div) => "/",
                    BinaryOp::Arith(Arith::Rem) => "%",
                };
                format!("({op} {} {})", sexpr(lhs), sexpr(rhs))
            }
        }
    }

    fn p(source: &str) -> String {
        match parse(source) {
            Ok(e) => sexpr(&e),
            Err(e) => panic!("`{source}` does not parse: {e}"),
        }
    }

    fn error_at(source: &str) -> (usize, String) {
        match parse(source) {
            Err(FilterError::Syntax { filter, position, message }) => {
                assert_eq!(filter, source);
                (position, message)
            }
            other => panic!("expected a syntax error for `{source}`, got {other:?}"),
        }
    }

    #[test]
    fn precedence_of_every_level() {
        assert_eq!(p("a || b && c"), "(|| a (&& b c))");
        assert_eq!(p("a && b || c"), "(|| (&& a b) c)");
        assert_eq!(p("a or b and not c"), "(|| a (&& b (! c)))");
        assert_eq!(p("!a && b"), "(&& (! a) b)");
        assert_eq!(p("!size > 3"), "(! (> size 3))");
        assert_eq!(p("not a == b || c"), "(|| (! (== a b)) c)");
        assert_eq!(p("a + b * c - d"), "(- (+ a (* b c)) d)");
        assert_eq!(p("a < b + 1"), "(< a (+ b 1))");
        assert_eq!(p("a - b - c"), "(- (- a b) c)");
        assert_eq!(p("a / b % c * d"), "(* (% (/ a b) c) d)");
        assert_eq!(p("-a * b"), "(* (neg a) b)");
        assert_eq!(p("- -a"), "(neg (neg a))");
        assert_eq!(p("(a + b) * c"), "(* (+ a b) c)");
        assert_eq!(p("a == (b < c)"), "(== a (< b c))");
        assert_eq!(p("x >= 1 && y <= 2 && z != 3"), "(&& (&& (>= x 1) (<= y 2)) (!= z 3))");
    }

    #[test]
    fn every_operator_parses() {
        for op in ["==", "!=", "<", "<=", ">", ">=", "+", "-", "*", "/", "%", "&&", "||"] {
            assert_eq!(p(&format!("a {op} b")), format!("({op} a b)"));
        }
        assert_eq!(p("a and b"), "(&& a b)");
        assert_eq!(p("a or b"), "(|| a b)");
        assert_eq!(p("not a"), "(! a)");
        assert_eq!(p("!a"), "(! a)");
    }

    #[test]
    fn literals_paths_and_calls() {
        assert_eq!(p("-5"), "-5");
        assert_eq!(p("-9223372036854775808"), i64::MIN.to_string());
        assert_eq!(p("9223372036854775807"), i64::MAX.to_string());
        assert_eq!(p("-2.5"), "(neg 2.5)");
        assert_eq!(p("true != false"), "(!= true false)");
        assert_eq!(p(r#"name == "a\"b""#), r#"(== name "a\"b")"#);
        assert_eq!(p("pose.position.north > 1"), "(> pose.position.north 1)");
        assert_eq!(p("len(items) > 0"), "(> (len items) 0)");
        assert_eq!(p("abs(x - 3) < len(best.name)"), "(< (abs (- x 3)) (len best.name))");
        assert_eq!(p("f()"), "(f )");
        assert_eq!(p("f(a, b + 1)"), "(f a (+ b 1))");
        assert_eq!(p("len"), "len");
    }

    #[test]
    fn spans_cover_parentheses_and_operands() {
        let e = parse(" (a + b) * c ").unwrap();
        assert_eq!((e.span.start, e.span.end), (1, 12));
        let ExprKind::Binary { lhs, .. } = &e.kind else { panic!("not binary") };
        assert_eq!((lhs.span.start, lhs.span.end), (1, 8));
    }

    #[test]
    fn syntax_errors_point_at_the_problem() {
        assert_eq!(
            error_at("size >"),
            (6, "expected an expression, found the end of the filter".into())
        );
        let (position, message) = error_at("(x < 3");
        assert_eq!(position, 6);
        assert!(message.contains("expected `)` to close the `(` at byte 0"), "{message}");
        assert_eq!(error_at("x < 3 &&& y").0, 8);
        let (position, message) = error_at("a < b < c");
        assert_eq!(position, 6);
        assert!(message.contains("cannot be chained"), "{message}");
        assert_eq!(error_at("a == b != c").0, 7);
        assert_eq!(error_at("").0, 0);
        assert_eq!(error_at("   ").0, 3);
        assert_eq!(error_at("x.").0, 2);
        assert_eq!(error_at("x.3").0, 2);
        assert_eq!(error_at("len(x").0, 5);
        assert_eq!(error_at("len(x y)").0, 6);
        assert_eq!(
            error_at("3 4").1,
            "unexpected `4`: expected an operator or the end of the filter"
        );
        assert_eq!(error_at("a )").0, 2);
        assert_eq!(error_at("9223372036854775808 > x").0, 0);
        assert_eq!(error_at("x > * 3").0, 4);
        assert_eq!(error_at("and").0, 0);
    }

    #[test]
    fn nesting_is_bounded() {
        let deep_parens = format!("{}x{}", "(".repeat(10_000), ")".repeat(10_000));
        assert!(error_at(&deep_parens).1.contains("nested too deeply"));
        let long_chain = vec!["x"; 10_000].join(" + ");
        assert!(error_at(&long_chain).1.contains("nested too deeply"));
        let many_nots = format!("{}flag", "!".repeat(10_000));
        assert!(error_at(&many_nots).1.contains("nested too deeply"));
        let fine = vec!["x"; 50].join(" + ");
        assert!(parse(&fine).is_ok());
    }
}
