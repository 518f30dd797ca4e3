//! Splits a condition into tokens. Every token carries its byte span.

use super::{CondError, MAX_TOKENS};

/// A token kind. Word and symbol spellings of the same operator share a kind
/// (`and`/`&&`, `or`/`||`, `not`/`!`); messages quote the source text.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Tok {
    Num(f64),
    /// A string literal: index into [`Lexed::strs`] (escapes resolved).
    Str(u32),
    Ident,
    And,
    Or,
    Not,
    True,
    False,
    EqEq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Plus,
    Minus,
    Star,
    Slash,
    Dot,
    LParen,
    RParen,
    LBracket,
    RBracket,
    Comma,
    Eof,
}

/// A token and its byte span in the source.
#[derive(Clone, Copy, Debug)]
pub(super) struct Token {
    pub(super) tok: Tok,
    pub(super) start: usize,
    pub(super) end: usize,
}

/// The tokens of a source, ending with [`Tok::Eof`], and its string literals.
pub(super) struct Lexed {
    pub(super) toks: Vec<Token>,
    pub(super) strs: Vec<String>,
}

fn err(start: usize, end: usize, message: impl Into<String>, hint: Option<&str>) -> CondError {
    CondError {
        span: start..end,
        message: message.into(),
        hint: hint.map(str::to_owned),
    }
}

/// Tokenizes `src`.
pub(super) fn lex(src: &str) -> Result<Lexed, CondError> {
    let b = src.as_bytes();
    let at = |i: usize| b.get(i).copied().unwrap_or(0);
    let mut toks = Vec::new();
    let mut strs = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = at(i);
        if c.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        let start = i;
        let next = at(i + 1);
        let (tok, len) = match c {
            b'(' => (Tok::LParen, 1),
            b')' => (Tok::RParen, 1),
            b'[' => (Tok::LBracket, 1),
            b']' => (Tok::RBracket, 1),
            b',' => (Tok::Comma, 1),
            b'+' => (Tok::Plus, 1),
            b'-' => (Tok::Minus, 1),
            b'*' => (Tok::Star, 1),
            b'/' => (Tok::Slash, 1),
            b'&' if next == b'&' => (Tok::And, 2),
            b'&' => {
                return Err(err(
                    i,
                    i + 1,
                    "unexpected character `&`",
                    Some("did you mean `&&`?"),
                ));
            }
            b'|' if next == b'|' => (Tok::Or, 2),
            b'|' => {
                return Err(err(
                    i,
                    i + 1,
                    "unexpected character `|`",
                    Some("did you mean `||`?"),
                ));
            }
            b'=' if next == b'=' => (Tok::EqEq, 2),
            b'=' => {
                let hint = match next {
                    b'<' => "did you mean `<=`?",
                    b'>' => "did you mean `>=`?",
                    _ => "use `==` to compare",
                };
                return Err(err(i, i + 1, "unexpected character `=`", Some(hint)));
            }
            b'!' if next == b'=' => (Tok::Ne, 2),
            b'!' => (Tok::Not, 1),
            b'<' if next == b'=' => (Tok::Le, 2),
            b'<' => (Tok::Lt, 1),
            b'>' if next == b'=' => (Tok::Ge, 2),
            b'>' => (Tok::Gt, 1),
            b'.' if !next.is_ascii_digit() => (Tok::Dot, 1),
            b'.' | b'0'..=b'9' => {
                let (n, end) = number(src, start)?;
                (Tok::Num(n), end - start)
            }
            b'"' | b'\'' => {
                let (s, end) = string(src, start, c)?;
                strs.push(s);
                let idx = u32::try_from(strs.len() - 1).unwrap_or(u32::MAX);
                (Tok::Str(idx), end - start)
            }
            b'a'..=b'z' | b'A'..=b'Z' | b'_' => {
                let mut end = i + 1;
                while at(end).is_ascii_alphanumeric() || at(end) == b'_' {
                    end += 1;
                }
                let tok = match src.get(start..end).unwrap_or("") {
                    "and" => Tok::And,
                    "or" => Tok::Or,
                    "not" => Tok::Not,
                    "true" => Tok::True,
                    "false" => Tok::False,
                    _ => Tok::Ident,
                };
                (tok, end - start)
            }
            _ => return Err(unexpected_char(src, start)),
        };
        i += len;
        toks.push(Token { tok, start, end: i });
        if toks.len() > MAX_TOKENS {
            return Err(err(
                start,
                i,
                format!("expression has too many tokens (limit {MAX_TOKENS})"),
                Some("split the condition, or move logic into a belief"),
            ));
        }
    }
    toks.push(Token {
        tok: Tok::Eof,
        start: b.len(),
        end: b.len(),
    });
    Ok(Lexed { toks, strs })
}

/// The error for a character that starts no token.
fn unexpected_char(src: &str, start: usize) -> CondError {
    let ch = src
        .get(start..)
        .and_then(|rest| rest.chars().next())
        .unwrap_or('\u{fffd}');
    let end = (start + ch.len_utf8()).min(src.len());
    let hint = match ch {
        '\u{2018}' | '\u{2019}' | '\u{201c}' | '\u{201d}' => {
            Some("use straight quotes `\"` or `'` for text")
        }
        '%' | '^' => Some("the arithmetic operators are `+`, `-`, `*` and `/`"),
        ';' => Some("combine conditions with `&&` or `||`"),
        c if c.is_whitespace() => Some("this is not a plain space; retype it"),
        c if c.is_alphabetic() => Some("names may use only ASCII letters, digits and `_`"),
        _ => None,
    };
    let shown = if ch.is_control() || ch.is_whitespace() {
        format!("{:?}", ch)
    } else {
        format!("`{ch}`")
    };
    err(start, end, format!("unexpected character {shown}"), hint)
}

/// Lexes a number starting at `start` (a digit, or `.` before a digit).
fn number(src: &str, start: usize) -> Result<(f64, usize), CondError> {
    let b = src.as_bytes();
    let at = |i: usize| b.get(i).copied().unwrap_or(0);
    let mut i = start;
    while at(i).is_ascii_digit() {
        i += 1;
    }
    if at(i) == b'.' && at(i + 1).is_ascii_digit() {
        i += 1;
        while at(i).is_ascii_digit() {
            i += 1;
        }
    }
    if matches!(at(i), b'e' | b'E') {
        let mut j = i + 1;
        if matches!(at(j), b'+' | b'-') {
            j += 1;
        }
        if at(j).is_ascii_digit() {
            i = j;
            while at(i).is_ascii_digit() {
                i += 1;
            }
        }
    }
    if at(i).is_ascii_alphanumeric() || at(i) == b'_' {
        let mut j = i;
        while at(j).is_ascii_alphanumeric() || at(j) == b'_' {
            j += 1;
        }
        let text = src.get(start..j).unwrap_or("");
        let hint = if text
            .bytes()
            .any(|c| c.is_ascii_alphabetic() && c != b'e' && c != b'E')
        {
            "a name cannot start with a digit"
        } else {
            "write exponents like `1e3` or `2.5e-2`"
        };
        return Err(err(
            start,
            j,
            format!("invalid number `{}`", clip(text)),
            Some(hint),
        ));
    }
    let text = src.get(start..i).unwrap_or("");
    match text.parse::<f64>() {
        Ok(n) if n.is_finite() => Ok((n, i)),
        Ok(_) => Err(err(
            start,
            i,
            format!("number `{}` is too large", clip(text)),
            None,
        )),
        Err(_) => Err(err(
            start,
            i,
            format!("invalid number `{}`", clip(text)),
            None,
        )),
    }
}

/// Lexes a string literal opened by `quote` at `start`; returns its content.
fn string(src: &str, start: usize, quote: u8) -> Result<(String, usize), CondError> {
    let q = char::from(quote);
    let unterminated = || {
        err(
            start,
            src.len(),
            "unterminated string",
            Some(if q == '"' {
                "close it with `\"`"
            } else {
                "close it with `'`"
            }),
        )
    };
    let mut s = String::new();
    let mut i = start + 1;
    loop {
        let Some(ch) = src.get(i..).and_then(|r| r.chars().next()) else {
            return Err(unterminated());
        };
        if ch == q {
            return Ok((s, i + 1));
        }
        if ch != '\\' {
            s.push(ch);
            i += ch.len_utf8();
            continue;
        }
        let Some(esc) = src.get(i + 1..).and_then(|r| r.chars().next()) else {
            return Err(unterminated());
        };
        match esc {
            '"' | '\'' | '\\' => s.push(esc),
            'n' => s.push('\n'),
            _ => {
                return Err(err(
                    i,
                    i + 1 + esc.len_utf8(),
                    format!("unknown escape `\\{esc}` in string"),
                    Some("the escapes are `\\\"`, `\\'`, `\\\\` and `\\n`"),
                ));
            }
        }
        i += 1 + esc.len_utf8();
    }
}

/// At most 32 characters of `text`, for messages.
pub(super) fn clip(text: &str) -> String {
    let mut it = text.char_indices();
    match it.nth(32) {
        Some((cut, _)) => format!("{}…", text.get(..cut).unwrap_or("")),
        None => text.to_owned(),
    }
}
