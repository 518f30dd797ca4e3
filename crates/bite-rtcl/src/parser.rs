//! The parser: tokens to a [`Mission`].
//!
//! ```text
//! mission = { line }
//! line    = [ command ] [ comment ] newline
//! command = word { ":" [ param ] } [ "=>" word ]
//! param   = number | word
//! ```
//!
//! An error skips the rest of its line (recovery at line ends), so one pass
//! reports a problem on every broken line. A `=>name` found on a broken line
//! is still recorded ([`Mission::recovered`]) so later uses of the name are
//! not reported as well.

use crate::ast::{Command, Mission, Name, Param, ParamKind};
use crate::lexer::{LexError, Token, TokenKind, lex};
use crate::source::{SourceMap, Span};
use bite_core::diag::Diagnostic;

/// Most commands in one mission.
pub const MAX_COMMANDS: usize = 20_000;

/// Lex and parse a mission. Returns the commands that parsed and a
/// diagnostic for every line that did not.
pub fn parse(file: &str, source: &str) -> (Mission, Vec<Diagnostic>) {
    let map = SourceMap::new(file, source);
    let tokens = lex(source);
    parse_tokens(&map, &tokens)
}

/// Parse tokens from [`lex`]; `map` is their source.
pub fn parse_tokens(map: &SourceMap<'_>, tokens: &[Token]) -> (Mission, Vec<Diagnostic>) {
    let mut p = Parser {
        map,
        // Comments are trivia.
        toks: tokens
            .iter()
            .filter(|t| t.kind != TokenKind::Comment)
            .collect(),
        pos: 0,
        mission: Mission::default(),
        diags: Vec::new(),
    };
    p.run();
    (p.mission, p.diags)
}

struct Parser<'a, 's> {
    map: &'a SourceMap<'s>,
    toks: Vec<&'a Token>,
    pos: usize,
    mission: Mission,
    diags: Vec<Diagnostic>,
}

/// How a token is named in "expected ..., found ..." messages.
fn describe(t: &Token, src: &str) -> String {
    match &t.kind {
        TokenKind::Word => format!("`{}`", t.text(src)),
        TokenKind::Number(_) => format!("the number `{}`", t.text(src)),
        TokenKind::Colon => "`:`".into(),
        TokenKind::Arrow => "`=>`".into(),
        TokenKind::Comment => "a comment".into(),
        TokenKind::Newline => "the end of the line".into(),
        TokenKind::Eof => "the end of the file".into(),
        TokenKind::Error(_) => format!("`{}`", t.text(src)),
    }
}

impl<'a> Parser<'a, '_> {
    fn peek(&self) -> &'a Token {
        // `lex` always ends with Eof; keep returning it.
        self.toks
            .get(self.pos)
            .or_else(|| self.toks.last())
            .copied()
            .unwrap_or(&EOF)
    }

    fn advance(&mut self) -> &'a Token {
        let t = self.peek();
        if self.pos < self.toks.len() {
            self.pos += 1;
        }
        t
    }

    fn at_line_end(&self) -> bool {
        matches!(self.peek().kind, TokenKind::Newline | TokenKind::Eof)
    }

    fn run(&mut self) {
        loop {
            match self.peek().kind {
                TokenKind::Eof => break,
                TokenKind::Newline => {
                    self.advance();
                }
                _ => {
                    if let Err(d) = self.command() {
                        self.diags.push(*d);
                        self.recover();
                    }
                    if self.mission.commands.len() > MAX_COMMANDS {
                        let t = self.peek();
                        self.diags.push(
                            self.map
                                .error(
                                    t.span,
                                    "too-large",
                                    format!("the mission has more than {MAX_COMMANDS} commands"),
                                )
                                .with_hint("split it into several missions"),
                        );
                        return;
                    }
                }
            }
        }
    }

    /// Skip to the end of the line, remembering a `=> name` on the way.
    fn recover(&mut self) {
        while !self.at_line_end() {
            let t = self.advance();
            if t.kind == TokenKind::Arrow && self.peek().kind == TokenKind::Word {
                let n = self.advance();
                self.mission.recovered.push(Name {
                    text: n.text(self.map.text()).to_string(),
                    span: n.span,
                });
            }
        }
    }

    /// The error for an unexpected token, with a hint for the usual slips.
    fn unexpected(&self, t: &Token, expected: &str) -> Box<Diagnostic> {
        let src = self.map.text();
        if let TokenKind::Error(e) = &t.kind {
            return Box::new(lex_error(self.map, t, e));
        }
        let mut d = self.map.error(
            t.span,
            "unexpected-token",
            format!("expected {expected}, found {}", describe(t, src)),
        );
        if matches!(t.kind, TokenKind::Word | TokenKind::Number(_)) && expected.contains("`:`") {
            d = d.with_hint("did you forget a `:`? Parameters are separated by `:`");
        }
        Box::new(d)
    }

    fn command(&mut self) -> Result<(), Box<Diagnostic>> {
        let src = self.map.text();
        let head = self.advance();
        if head.kind != TokenKind::Word {
            let mut d = self.unexpected(head, "a command name at the start of the line");
            if head.kind == TokenKind::Colon && d.code == "unexpected-token" {
                d.hint = Some("a line starts with the command: `find::::yellow`".into());
            }
            return Err(d);
        }
        let name = Name {
            text: head.text(src).to_string(),
            span: head.span,
        };
        // One parameter per `:` before the end of the line: the list is
        // made at its size.
        let colons = (self.toks.get(self.pos..).unwrap_or_default().iter())
            .take_while(|t| !matches!(t.kind, TokenKind::Newline | TokenKind::Eof))
            .filter(|t| t.kind == TokenKind::Colon)
            .count();
        let mut params = Vec::with_capacity(colons);
        let mut result = None;
        let mut end = head.span;
        loop {
            let t = self.peek();
            match &t.kind {
                TokenKind::Newline | TokenKind::Eof => break,
                TokenKind::Colon => {
                    self.advance();
                    end = t.span;
                    let v = self.peek();
                    let param = match &v.kind {
                        TokenKind::Number(x) => {
                            self.advance();
                            Param {
                                kind: ParamKind::Number(*x),
                                span: v.span,
                            }
                        }
                        TokenKind::Word => {
                            self.advance();
                            Param {
                                kind: ParamKind::Word(v.text(src).to_string()),
                                span: v.span,
                            }
                        }
                        TokenKind::Colon
                        | TokenKind::Arrow
                        | TokenKind::Newline
                        | TokenKind::Eof => Param {
                            kind: ParamKind::Empty,
                            span: Span::point(t.span.end),
                        },
                        _ => return Err(self.unexpected(v, "a parameter (a number or a name)")),
                    };
                    end = end.to(param.span);
                    params.push(param);
                }
                TokenKind::Arrow => {
                    self.advance();
                    let n = self.peek();
                    if n.kind != TokenKind::Word {
                        let mut d = self.unexpected(n, "a name after `=>`");
                        if d.code == "unexpected-token" {
                            d.hint = Some(
                                "`=>name` names the command's result: `find::::yellow=>box`".into(),
                            );
                        }
                        return Err(d);
                    }
                    self.advance();
                    end = n.span;
                    result = Some(Name {
                        text: n.text(src).to_string(),
                        span: n.span,
                    });
                    if !self.at_line_end() {
                        let t = self.peek();
                        let mut d = self.unexpected(t, "the end of the line after the result name");
                        if d.code == "unexpected-token" {
                            d.hint = Some("`=>name` comes last on the line".into());
                        }
                        return Err(d);
                    }
                    break;
                }
                _ => {
                    let what = if params.is_empty() {
                        "`:`, `=>` or the end of the line after the command"
                    } else {
                        "`:`, `=>` or the end of the line after a parameter"
                    };
                    return Err(self.unexpected(t, what));
                }
            }
        }
        self.mission.commands.push(Command {
            name,
            params,
            result,
            span: head.span.to(end),
            line: head.line,
        });
        Ok(())
    }
}

static EOF: Token = Token {
    kind: TokenKind::Eof,
    span: Span { start: 0, end: 0 },
    line: 1,
    col: 1,
};

/// The diagnostic for a lexer error token.
fn lex_error(map: &SourceMap<'_>, t: &Token, e: &LexError) -> Diagnostic {
    match e {
        LexError::Number => {
            let text = t.text(map.text());
            let d = map.error(t.span, "bad-number", format!("`{text}` is not a number"));
            let digits: String = text
                .chars()
                .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+'))
                .collect();
            if !digits.is_empty()
                && digits.len() < text.len()
                && text[digits.len()..]
                    .chars()
                    .all(|c| c.is_ascii_alphabetic())
            {
                d.with_hint(format!(
                    "numbers have no units (metres and seconds are implied): write `{digits}`"
                ))
            } else {
                d.with_hint("numbers are written like `3`, `-.5`, `0.25` or `1e-1`")
            }
        }
        LexError::Char(c) => {
            let d = map.error(
                t.span,
                "bad-character",
                format!("unexpected character `{}`", c.escape_debug()),
            );
            let hint = match c {
                '=' | '>' => Some("a result is named with `=>`: `find::::red=>cube`".to_string()),
                ',' | ';' => Some("parameters are separated by `:`, commands by line ends".into()),
                '-' | '+' => Some("a sign must be followed by a number: `-.5`".into()),
                '"' | '\'' => Some("colours and names are written without quotes".into()),
                '/' => Some("comments start with `#`".into()),
                c if c.is_alphabetic() => {
                    Some("names are ASCII letters, digits and `_`".to_string())
                }
                _ => None,
            };
            match hint {
                Some(h) => d.with_hint(h),
                None => d,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(src: &str) -> Mission {
        let (m, d) = parse("t.rtcl", src);
        assert!(d.is_empty(), "{d:?}");
        m
    }

    #[test]
    fn parses_the_papers_mission() {
        let m = ok("find::::yellow=>box  # the box\n\nmove:box:-.5:.5\n");
        assert_eq!(m.commands.len(), 2);
        let find = &m.commands[0];
        assert_eq!(find.name.text, "find");
        assert_eq!(find.params.len(), 4);
        assert!(find.params[..3].iter().all(|p| p.kind == ParamKind::Empty));
        assert_eq!(find.params[3].kind, ParamKind::Word("yellow".into()));
        assert_eq!(find.result.as_ref().map(|r| r.text.as_str()), Some("box"));
        assert_eq!(find.line, 1);
        let mv = &m.commands[1];
        assert_eq!(mv.line, 3);
        assert_eq!(
            mv.params.iter().map(|p| p.kind.clone()).collect::<Vec<_>>(),
            vec![
                ParamKind::Word("box".into()),
                ParamKind::Number(-0.5),
                ParamKind::Number(0.5)
            ]
        );
    }

    #[test]
    fn spaces_around_separators_and_trailing_colons() {
        let m = ok("goto : 1 : 2 \nfind:\nwait");
        assert_eq!(m.commands[0].params.len(), 2);
        // `find:` has one empty parameter; `wait` none.
        assert_eq!(
            m.commands[1].params,
            vec![Param {
                kind: ParamKind::Empty,
                span: Span::point(19)
            }]
        );
        assert!(m.commands[2].params.is_empty());
    }

    #[test]
    fn empty_parameter_points_after_its_colon() {
        let m = ok("find::=>x");
        assert_eq!(m.commands[0].params.len(), 2);
        assert_eq!(m.commands[0].params[0].span, Span::point(5));
        assert_eq!(m.commands[0].params[1].span, Span::point(6));
    }

    #[test]
    fn recovers_at_line_ends_and_reports_every_broken_line() {
        let (m, d) = parse(
            "t.rtcl",
            "find::::red=>cube extra\n:move\ngoto:1 2\nwait:3\nfind;=>b\n",
        );
        let codes: Vec<_> = d.iter().map(|d| (d.code, d.loc.line, d.loc.col)).collect();
        assert_eq!(
            codes,
            vec![
                ("unexpected-token", 1, 19),
                ("unexpected-token", 2, 1),
                ("unexpected-token", 3, 8),
                ("bad-character", 5, 5)
            ]
        );
        assert_eq!(m.commands.len(), 1);
        assert_eq!(m.commands[0].name.text, "wait");
        // `=>b` after the error on line 5 is still known.
        assert_eq!(
            m.recovered
                .iter()
                .map(|n| n.text.as_str())
                .collect::<Vec<_>>(),
            vec!["b"]
        );
    }

    #[test]
    fn result_needs_a_name() {
        let (_, d) = parse("t.rtcl", "find::::red=>\n");
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].code, "unexpected-token");
        assert_eq!((d[0].loc.line, d[0].loc.col), (1, 14));
        assert!(
            d[0].message.contains("a name after `=>`"),
            "{}",
            d[0].message
        );
    }

    #[test]
    fn malformed_numbers_get_a_hint() {
        let (_, d) = parse("t.rtcl", "wait:30s\n");
        assert_eq!(d[0].code, "bad-number");
        assert_eq!(
            d[0].hint.as_deref(),
            Some("numbers have no units (metres and seconds are implied): write `30`")
        );
    }
}
