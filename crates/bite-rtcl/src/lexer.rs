//! The lexer: source text to tokens, each with its byte span and its
//! 1-based line and column.
//!
//! Tokens: words (command names, colours, result names), numbers, `:`,
//! `=>`, comments (`#` to the end of the line), line ends, and error tokens
//! for anything else. The lexer never fails: a character it does not know
//! becomes an [`TokenKind::Error`] token that the parser reports, so one
//! pass finds every problem.

use crate::source::Span;

/// What a token is.
#[derive(Clone, Debug, PartialEq)]
pub enum TokenKind {
    /// A name: `find`, `yellow`, `box`: an ASCII letter or `_`, then
    /// letters, digits and `_`.
    Word,
    /// A number: `3`, `-.5`, `.25`, `+2`, `5.`, `1e-1`, `2.5E3`.
    Number(f64),
    /// `:`, between a command and its parameters.
    Colon,
    /// `=>`, before the name of a command's result.
    Arrow,
    /// `#` and the rest of the line.
    Comment,
    /// A line end (`\n`, `\r\n` or `\r`).
    Newline,
    /// Something that is not a token.
    Error(LexError),
    /// The end of the text (always the last token).
    Eof,
}

/// Why some text is not a token.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LexError {
    /// A character that starts no token.
    Char(char),
    /// A number followed by letters, digits or dots that do not belong to
    /// it (`3x`, `1.2.3`, `2m`, `1e`).
    Number,
}

/// One token.
#[derive(Clone, Debug, PartialEq)]
pub struct Token {
    /// Its kind.
    pub kind: TokenKind,
    /// Its bytes in the source.
    pub span: Span,
    /// 1-based line.
    pub line: u32,
    /// 1-based column, in characters.
    pub col: u32,
}

impl Token {
    /// The token's text in `source`.
    pub fn text<'s>(&self, source: &'s str) -> &'s str {
        source.get(self.span.start..self.span.end).unwrap_or("")
    }
}

/// Split `source` into tokens. Spaces and tabs between tokens are skipped;
/// a byte-order mark at the very start is ignored. The result always ends
/// with [`TokenKind::Eof`].
pub fn lex(source: &str) -> Vec<Token> {
    Lexer::new(source).run()
}

struct Lexer<'s> {
    src: &'s str,
    bytes: &'s [u8],
    pos: usize,
    line: u32,
    col: u32,
    out: Vec<Token>,
}

fn is_word_start(b: u8) -> bool {
    b.is_ascii_alphabetic() || b == b'_'
}

fn is_word(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

impl<'s> Lexer<'s> {
    fn new(src: &'s str) -> Self {
        Lexer {
            src,
            bytes: src.as_bytes(),
            pos: 0,
            line: 1,
            col: 1,
            out: Vec::with_capacity(src.len() / 3 + 1),
        }
    }

    fn peek(&self, ahead: usize) -> Option<u8> {
        self.bytes.get(self.pos + ahead).copied()
    }

    fn push(&mut self, kind: TokenKind, start: usize, start_col: u32) {
        self.out.push(Token {
            kind,
            span: Span::new(start, self.pos),
            line: self.line,
            col: start_col,
        });
    }

    /// Advance over ASCII bytes (one column each).
    fn bump(&mut self, n: usize) {
        self.pos += n;
        self.col += u32::try_from(n).unwrap_or(u32::MAX);
    }

    fn run(mut self) -> Vec<Token> {
        if self.src.starts_with('\u{feff}') {
            self.pos = '\u{feff}'.len_utf8();
        }
        while let Some(b) = self.peek(0) {
            let start = self.pos;
            let col = self.col;
            match b {
                b' ' | b'\t' => self.bump(1),
                b'\n' | b'\r' => {
                    let n = if b == b'\r' && self.peek(1) == Some(b'\n') {
                        2
                    } else {
                        1
                    };
                    self.pos += n;
                    self.push(TokenKind::Newline, start, col);
                    self.line = self.line.saturating_add(1);
                    self.col = 1;
                }
                b'#' => {
                    let rest = &self.src[self.pos..];
                    let len = rest.find(['\n', '\r']).unwrap_or(rest.len());
                    self.pos += len;
                    self.col = self.col.saturating_add(
                        u32::try_from(rest[..len].chars().count()).unwrap_or(u32::MAX),
                    );
                    self.push(TokenKind::Comment, start, col);
                }
                b':' => {
                    self.bump(1);
                    self.push(TokenKind::Colon, start, col);
                }
                b'=' if self.peek(1) == Some(b'>') => {
                    self.bump(2);
                    self.push(TokenKind::Arrow, start, col);
                }
                b if is_word_start(b) => {
                    while self.peek(0).is_some_and(is_word) {
                        self.bump(1);
                    }
                    self.push(TokenKind::Word, start, col);
                }
                _ if self.number_starts() => {
                    let kind = self.number();
                    self.push(kind, start, col);
                }
                _ => {
                    // One character, whatever its UTF-8 length.
                    let c = self.src[self.pos..].chars().next().unwrap_or('\u{fffd}');
                    self.pos += c.len_utf8();
                    self.col = self.col.saturating_add(1);
                    self.push(TokenKind::Error(LexError::Char(c)), start, col);
                }
            }
        }
        let (pos, col) = (self.pos, self.col);
        self.push(TokenKind::Eof, pos, col);
        self.out
    }

    /// A number starts here: a digit, `.digit`, or a sign before either.
    fn number_starts(&self) -> bool {
        let digit_at = |i: usize| self.peek(i).is_some_and(|b| b.is_ascii_digit());
        let unsigned_at = |i: usize| digit_at(i) || (self.peek(i) == Some(b'.') && digit_at(i + 1));
        match self.peek(0) {
            Some(b'+' | b'-') => unsigned_at(1),
            _ => unsigned_at(0),
        }
    }

    fn digits(&mut self) {
        while self.peek(0).is_some_and(|b| b.is_ascii_digit()) {
            self.bump(1);
        }
    }

    fn number(&mut self) -> TokenKind {
        let start = self.pos;
        if matches!(self.peek(0), Some(b'+' | b'-')) {
            self.bump(1);
        }
        self.digits();
        if self.peek(0) == Some(b'.') {
            self.bump(1);
            self.digits();
        }
        if matches!(self.peek(0), Some(b'e' | b'E')) {
            let sign = usize::from(matches!(self.peek(1), Some(b'+' | b'-')));
            if self.peek(1 + sign).is_some_and(|b| b.is_ascii_digit()) {
                self.bump(1 + sign);
                self.digits();
            }
        }
        // Anything glued to the number makes it malformed: `3x`, `1.2.3`.
        if self.peek(0).is_some_and(|b| is_word(b) || b == b'.') {
            while self.peek(0).is_some_and(|b| is_word(b) || b == b'.') {
                self.bump(1);
            }
            return TokenKind::Error(LexError::Number);
        }
        match self.src[start..self.pos].parse::<f64>() {
            Ok(v) => TokenKind::Number(v),
            Err(_) => TokenKind::Error(LexError::Number),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(s: &str) -> Vec<TokenKind> {
        lex(s).into_iter().map(|t| t.kind).collect()
    }

    #[test]
    fn the_papers_commands() {
        use TokenKind::*;
        assert_eq!(
            kinds("find::::yellow=>box\nmove:box:-.5:.5"),
            vec![
                Word,
                Colon,
                Colon,
                Colon,
                Colon,
                Word,
                Arrow,
                Word,
                Newline,
                Word,
                Colon,
                Word,
                Colon,
                Number(-0.5),
                Colon,
                Number(0.25 * 2.0),
                Eof
            ]
        );
    }

    #[test]
    fn numbers() {
        for (s, v) in [
            ("3", 3.0),
            (".25", 0.25),
            ("-.5", -0.5),
            ("+2", 2.0),
            ("5.", 5.0),
            ("1e-1", 0.1),
            ("2.5E3", 2500.0),
            ("-0", -0.0),
        ] {
            assert_eq!(kinds(s), vec![TokenKind::Number(v), TokenKind::Eof], "{s}");
        }
        for s in ["3x", "1.2.3", "2m", "1e", "0x10", "4_000"] {
            assert_eq!(
                kinds(s),
                vec![TokenKind::Error(LexError::Number), TokenKind::Eof],
                "{s}"
            );
        }
    }

    #[test]
    fn spans_lines_and_columns() {
        let src = "  goto : 1:2  # there\r\nwait:é";
        let t = lex(src);
        let word = &t[0];
        assert_eq!((word.line, word.col, word.text(src)), (1, 3, "goto"));
        let colon = &t[1];
        assert_eq!((colon.col, colon.text(src)), (8, ":"));
        let comment = t
            .iter()
            .find(|t| t.kind == TokenKind::Comment)
            .expect("comment");
        assert_eq!((comment.col, comment.text(src)), (15, "# there"));
        let nl = t
            .iter()
            .find(|t| t.kind == TokenKind::Newline)
            .expect("newline");
        assert_eq!(nl.text(src), "\r\n");
        let bad = &t[t.len() - 2];
        assert_eq!(bad.kind, TokenKind::Error(LexError::Char('é')));
        assert_eq!((bad.line, bad.col), (2, 6));
        assert_eq!(t.last().map(|t| t.kind.clone()), Some(TokenKind::Eof));
    }

    #[test]
    fn stray_characters_are_error_tokens() {
        use TokenKind::*;
        assert_eq!(
            kinds("a=b>c;-"),
            vec![
                Word,
                Error(LexError::Char('=')),
                Word,
                Error(LexError::Char('>')),
                Word,
                Error(LexError::Char(';')),
                Error(LexError::Char('-')),
                Eof
            ]
        );
    }

    #[test]
    fn byte_order_mark_is_skipped() {
        let t = lex("\u{feff}wait:1");
        assert_eq!(t[0].kind, TokenKind::Word);
        assert_eq!(t[0].col, 1);
    }
}
