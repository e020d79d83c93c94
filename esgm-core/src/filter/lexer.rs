//! The lexer: filter text to tokens, each with the byte span it came from so that
//! errors can point at it.

use super::error::FilterError;

/// A byte range of the filter text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Span {
    pub start: usize,
    pub end: usize,
}

impl Span {
    /// From the start of `self` to the end of `other`.
    pub fn to(self, other: Span) -> Span {
        Span { start: self.start, end: other.end }
    }
}

/// What a token is. Identifiers carry no text: the parser reads it from the span.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum TokenKind {
    /// An integer literal, unsigned: the parser folds a leading `-` into it, so that
    /// `i64::MIN` can be written.
    Int(u64),
    Float(f64),
    Str(String),
    Ident,
    True,
    False,
    /// `&&` or `and`.
    And,
    /// `||` or `or`.
    Or,
    /// `!` or `not`.
    Not,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Plus,
    Minus,
    Star,
    Slash,
    Percent,
    LParen,
    RParen,
    Comma,
    Dot,
    Eof,
}

/// One token and where it is.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Token {
    pub kind: TokenKind,
    pub span: Span,
}

/// Splits `source` into tokens. The end of input is not a token here; the parser
/// supplies it.
pub(super) fn tokenize(source: &str) -> Result<Vec<Token>, FilterError> {
    let mut lexer = Lexer { source, pos: 0 };
    let mut tokens = Vec::new();
    while let Some(token) = lexer.next_token()? {
        tokens.push(token);
    }
    Ok(tokens)
}

struct Lexer<'a> {
    source: &'a str,
    pos: usize,
}

impl Lexer<'_> {
    fn rest(&self) -> &str {
        self.source.get(self.pos..).unwrap_or_default()
    }

    fn peek_char(&self) -> Option<char> {
        self.rest().chars().next()
    }

    fn peek_byte(&self) -> Option<u8> {
        self.source.as_bytes().get(self.pos).copied()
    }

    fn error(&self, position: usize, message: impl Into<String>) -> FilterError {
        FilterError::syntax(self.source, position, message)
    }

    fn next_token(&mut self) -> Result<Option<Token>, FilterError> {
        while let Some(c) = self.peek_char().filter(|c| c.is_whitespace()) {
            self.pos += c.len_utf8();
        }
        let start = self.pos;
        let Some(c) = self.peek_char() else { return Ok(None) };
        let kind = match c {
            '0'..='9' => self.number()?,
            '"' => self.string()?,
            c if c == '_' || c.is_ascii_alphabetic() => self.word(),
            c => self.operator(c)?,
        };
        Ok(Some(Token { kind, span: Span { start, end: self.pos } }))
    }

    fn eat_digits(&mut self) -> bool {
        let start = self.pos;
        while matches!(self.peek_byte(), Some(b'0'..=b'9')) {
            self.pos += 1;
        }
        self.pos > start
    }

    fn number(&mut self) -> Result<TokenKind, FilterError> {
        let start = self.pos;
        self.eat_digits();
        let mut is_float = false;
        if self.peek_byte() == Some(b'.') {
            self.pos += 1;
            if !self.eat_digits() {
                return Err(self.error(self.pos, "expected a digit after the decimal point"));
            }
            is_float = true;
        }
        if matches!(self.peek_byte(), Some(b'e' | b'E')) {
            self.pos += 1;
            if matches!(self.peek_byte(), Some(b'+' | b'-')) {
                self.pos += 1;
            }
            if !self.eat_digits() {
                return Err(self.error(self.pos, "expected the digits of an exponent"));
            }
            is_float = true;
        }
        let text = self.source.get(start..self.pos).unwrap_or_default();
        if is_float {
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(TokenKind::Float(v)),
                _ => Err(self.error(start, format!("number `{text}` is out of range"))),
            }
        } else {
            text.parse::<u64>()
                .map(TokenKind::Int)
                .map_err(|_| self.error(start, format!("integer `{text}` is out of range")))
        }
    }

    fn string(&mut self) -> Result<TokenKind, FilterError> {
        let start = self.pos;
        let unterminated = "unterminated string: close it with `\"`";
        self.pos += 1;
        let mut value = String::new();
        loop {
            let Some(c) = self.peek_char() else { return Err(self.error(start, unterminated)) };
            self.pos += c.len_utf8();
            match c {
                '"' => return Ok(TokenKind::Str(value)),
                '\\' => match self.peek_char() {
                    Some(e @ ('"' | '\\')) => {
                        value.push(e);
                        self.pos += 1;
                    }
                    Some(e) => {
                        return Err(self.error(
                            self.pos - 1,
                            format!("unknown escape `\\{e}`: only `\\\"` and `\\\\` are allowed"),
                        ));
                    }
                    None => return Err(self.error(start, unterminated)),
                },
                c => value.push(c),
            }
        }
    }

    fn word(&mut self) -> TokenKind {
        let start = self.pos;
        while matches!(self.peek_byte(), Some(b) if b == b'_' || b.is_ascii_alphanumeric()) {
            self.pos += 1;
        }
        match self.source.get(start..self.pos).unwrap_or_default() {
            "true" => TokenKind::True,
            "false" => TokenKind::False,
            "and" => TokenKind::And,
            "or" => TokenKind::Or,
            "not" => TokenKind::Not,
            _ => TokenKind::Ident,
        }
    }

    fn operator(&mut self, c: char) -> Result<TokenKind, FilterError> {
        let next = self.rest().chars().nth(1);
        let (kind, len) = match (c, next) {
            ('=', Some('=')) => (TokenKind::Eq, 2),
            ('!', Some('=')) => (TokenKind::Ne, 2),
            ('<', Some('=')) => (TokenKind::Le, 2),
            ('>', Some('=')) => (TokenKind::Ge, 2),
            ('&', Some('&')) => (TokenKind::And, 2),
            ('|', Some('|')) => (TokenKind::Or, 2),
            ('!', _) => (TokenKind::Not, 1),
            ('<', _) => (TokenKind::Lt, 1),
            ('>', _) => (TokenKind::Gt, 1),
            ('+', _) => (TokenKind::Plus, 1),
            ('-', _) => (TokenKind::Minus, 1),
            ('*', _) => (TokenKind::Star, 1),
            ('/', _) => (TokenKind::Slash, 1),
            ('%', _) => (TokenKind::Percent, 1),
            ('(', _) => (TokenKind::LParen, 1),
            (')', _) => (TokenKind::RParen, 1),
            (',', _) => (TokenKind::Comma, 1),
            ('.', _) => (TokenKind::Dot, 1),
            ('=', _) => {
                return Err(self.error(self.pos, "`=` is not an operator: compare with `==`"));
            }
            ('&', _) => {
                return Err(self.error(self.pos, "`&` is not an operator: use `&&` or `and`"));
            }
            ('|', _) => {
                return Err(self.error(self.pos, "`|` is not an operator: use `||` or `or`"));
            }
            (c, _) => return Err(self.error(self.pos, format!("unexpected character `{c}`"))),
        };
        self.pos += len;
        Ok(kind)
    }
}

#[cfg(test)]
mod tests {
    use super::TokenKind::*;
    use super::*;

    fn kinds(source: &str) -> Vec<TokenKind> {
        tokenize(source).unwrap().into_iter().map(|t| t.kind).collect()
    }

    fn error_at(source: &str) -> (usize, String) {
        match tokenize(source) {
            Err(FilterError::Syntax { position, message, .. }) => (position, message),
            other => panic!("expected a syntax error for {source:?}, got {other:?}"),
        }
    }

    #[test]
    fn operators_and_keywords() {
        assert_eq!(
            kinds("== != < <= > >= && || ! and or not + - * / % ( ) , ."),
            vec![
                Eq, Ne, Lt, Le, Gt, Ge, And, Or, Not, And, Or, Not, Plus, Minus, Star, Slash,
                Percent, LParen, RParen, Comma, Dot
            ]
        );
        assert_eq!(kinds("a<=b"), vec![Ident, Le, Ident]);
        assert_eq!(kinds("true false _x9 android"), vec![True, False, Ident, Ident]);
    }

    #[test]
    fn spans_are_byte_ranges() {
        let tokens = tokenize("  size >= 10").unwrap();
        let spans: Vec<_> = tokens.iter().map(|t| (t.span.start, t.span.end)).collect();
        assert_eq!(spans, vec![(2, 6), (7, 9), (10, 12)]);
    }

    #[test]
    fn numbers() {
        assert_eq!(kinds("0 42 18446744073709551615"), vec![Int(0), Int(42), Int(u64::MAX)]);
        assert_eq!(kinds("1.5 2e3 2.5E-1"), vec![Float(1.5), Float(2000.0), Float(0.25)]);
        assert_eq!(kinds("3x"), vec![Int(3), Ident]);
        assert_eq!(error_at("x > 18446744073709551616").0, 4);
        assert_eq!(error_at("1.").0, 2);
        assert_eq!(error_at("1e+").0, 3);
        assert_eq!(error_at("1e999").0, 0);
    }

    #[test]
    fn strings_and_escapes() {
        assert_eq!(kinds(r#""a \"b\" \\ é""#), vec![Str(r#"a "b" \ é"#.into())]);
        assert_eq!(kinds(r#""""#), vec![Str(String::new())]);
        assert_eq!(error_at(r#"name == "abc"#).0, 8);
        assert_eq!(error_at(r#""a\"#).0, 0);
        let (position, message) = error_at(r#""a\n""#);
        assert_eq!(position, 2);
        assert!(message.contains("unknown escape"), "{message}");
    }

    #[test]
    fn single_character_mistakes_are_explained() {
        assert_eq!(error_at("x < 3 &&& y").0, 8);
        assert!(error_at("x = 3").1.contains("`==`"));
        assert!(error_at("a | b").1.contains("`||`"));
        assert_eq!(error_at("size > 3 é").0, 9);
        assert_eq!(error_at("x # 3").1, "unexpected character `#`");
    }
}
