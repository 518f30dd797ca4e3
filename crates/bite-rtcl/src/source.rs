//! Source text: byte spans, line/column positions, and the snippet with a
//! caret under the offending token that every diagnostic carries.

use bite_core::diag::{Diagnostic, Loc};
use std::sync::Arc;

/// A range of bytes in the source, `start..end` (`start == end` for a
/// position between two tokens, such as an empty parameter).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Span {
    /// First byte.
    pub start: usize,
    /// One past the last byte.
    pub end: usize,
}

impl Span {
    /// A span.
    pub const fn new(start: usize, end: usize) -> Self {
        Span { start, end }
    }
    /// An empty span at `at`.
    pub const fn point(at: usize) -> Self {
        Span { start: at, end: at }
    }
    /// The smallest span covering both.
    pub fn to(self, other: Span) -> Span {
        Span {
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }
    /// True for an empty span.
    pub fn is_empty(&self) -> bool {
        self.start >= self.end
    }
}

/// Where each line of a source text starts, to turn byte offsets into
/// 1-based lines and columns (in characters) and to show a line.
///
/// Lines end at `\n`, `\r\n` or a lone `\r`, as in the lexer.
#[derive(Clone, Debug)]
pub struct SourceMap<'a> {
    file: Arc<str>,
    text: &'a str,
    /// Byte offset of the start of each line.
    starts: Vec<usize>,
}

impl<'a> SourceMap<'a> {
    /// Index a source text.
    pub fn new(file: &str, text: &'a str) -> Self {
        let mut starts = vec![0];
        let b = text.as_bytes();
        let mut i = 0;
        while i < b.len() {
            match b[i] {
                b'\n' => starts.push(i + 1),
                b'\r' if b.get(i + 1) == Some(&b'\n') => {
                    starts.push(i + 2);
                    i += 1;
                }
                b'\r' => starts.push(i + 1),
                _ => {}
            }
            i += 1;
        }
        SourceMap {
            file: Arc::from(file),
            text,
            starts,
        }
    }

    /// The file name, as given.
    pub fn file(&self) -> &Arc<str> {
        &self.file
    }

    /// The source text.
    pub fn text(&self) -> &'a str {
        self.text
    }

    /// 0-based index of the line holding byte `at`.
    fn line_index(&self, at: usize) -> usize {
        match self.starts.binary_search(&at) {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        }
    }

    /// 1-based line and column (in characters) of byte `at`.
    pub fn loc(&self, at: usize) -> Loc {
        let at = at.min(self.text.len());
        let li = self.line_index(at);
        let mut start = self.starts[li];
        // A byte-order mark is not a column.
        if li == 0 && self.text.starts_with('\u{feff}') && at >= 3 {
            start = 3;
        }
        let col = self
            .text
            .get(start..at)
            .map_or(at - start, |s| s.chars().count());
        Loc::new(
            u32::try_from(li + 1).unwrap_or(u32::MAX),
            u32::try_from(col + 1).unwrap_or(u32::MAX),
        )
    }

    /// The text of 1-based line `line`, without its line ending.
    pub fn line(&self, line: u32) -> &'a str {
        let Some(li) = (line as usize).checked_sub(1) else {
            return "";
        };
        let Some(&start) = self.starts.get(li) else {
            return "";
        };
        let end = self.starts.get(li + 1).copied().unwrap_or(self.text.len());
        let s = self.text.get(start..end).unwrap_or("");
        s.trim_end_matches(['\n', '\r'])
    }

    /// Number of lines.
    pub fn line_count(&self) -> usize {
        self.starts.len()
    }

    /// The line holding `span` with carets under it:
    ///
    /// ```text
    /// 4 | mvoe:box:1:2
    ///   | ^^^^
    /// ```
    pub fn snippet(&self, span: Span) -> String {
        let loc = self.loc(span.start);
        let line = self.line(loc.line);
        let shown = printable(line);
        let width = loc.line.to_string().len();
        let col = loc.col.saturating_sub(1) as usize;
        // Carets under the span's characters on this line (at least one).
        let line_chars = line.chars().count();
        let span_chars = self
            .text
            .get(span.start..span.end.max(span.start))
            .map_or(1, |s| {
                s.chars().take_while(|c| *c != '\n' && *c != '\r').count()
            })
            .min(line_chars.saturating_sub(col))
            .max(1);
        format!(
            "{:>width$} | {shown}\n{:>width$} | {}{}",
            loc.line,
            "",
            " ".repeat(col),
            "^".repeat(span_chars)
        )
    }

    /// An error at `span`, with the snippet as its detail.
    pub fn error(&self, span: Span, code: &'static str, message: impl Into<String>) -> Diagnostic {
        Diagnostic::error(&self.file, self.loc(span.start), code, message)
            .with_detail(self.snippet(span))
    }

    /// A warning at `span`, with the snippet as its detail.
    pub fn warning(
        &self,
        span: Span,
        code: &'static str,
        message: impl Into<String>,
    ) -> Diagnostic {
        Diagnostic::warning(&self.file, self.loc(span.start), code, message)
            .with_detail(self.snippet(span))
    }
}

/// A line as it can be shown in a terminal or a YAML comment: tabs become
/// one space (so carets line up with columns counted in characters) and
/// control or non-printable characters become `?`.
pub fn printable(line: &str) -> String {
    line.chars()
        .filter(|c| *c != '\u{feff}')
        .map(|c| match c {
            '\t' => ' ',
            c if c.is_control() || c == '\u{fffe}' || c == '\u{ffff}' => '?',
            c => c,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_and_columns_count_characters() {
        let m = SourceMap::new("m.rtcl", "ab\r\ncé:d\rx\n");
        assert_eq!(m.loc(0), Loc::new(1, 1));
        assert_eq!(m.loc(4), Loc::new(2, 1));
        // `:` after `cé` (é is two bytes) is column 3.
        assert_eq!(m.loc(7), Loc::new(2, 3));
        assert_eq!(m.loc(10), Loc::new(3, 1));
        assert_eq!(m.line(2), "cé:d");
        assert_eq!(m.line(3), "x");
        assert_eq!(m.line(9), "");
        assert_eq!(m.line_count(), 4);
    }

    #[test]
    fn snippet_puts_carets_under_the_span() {
        let m = SourceMap::new("m.rtcl", "find::::yellow\nmvoe:box:1:2\n");
        assert_eq!(m.snippet(Span::new(15, 19)), "2 | mvoe:box:1:2\n  | ^^^^");
        // An empty span still gets one caret.
        assert_eq!(m.snippet(Span::point(5)), "1 | find::::yellow\n  |      ^");
    }

    #[test]
    fn printable_hides_control_characters() {
        assert_eq!(printable("a\tb\u{7}c"), "a b?c");
    }
}
