//! Diagnostics: what is wrong with a user's file, and where.
//!
//! Every error a user can cause by writing a file names the file, the line
//! and the column, says what was expected, and where possible how to fix it.

use serde::Serialize;
use std::fmt;
use std::sync::Arc;

/// A position in a source file (1-based line and column; 0 = unknown).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct Loc {
    /// 1-based line.
    pub line: u32,
    /// 1-based column (in characters).
    pub col: u32,
}

impl Loc {
    /// A known position.
    pub const fn new(line: u32, col: u32) -> Self {
        Loc { line, col }
    }
    /// Unknown position.
    pub const UNKNOWN: Loc = Loc { line: 0, col: 0 };
    /// True when the position is known.
    pub fn is_known(&self) -> bool {
        self.line > 0
    }
}

impl From<serde_saphyr::Location> for Loc {
    fn from(l: serde_saphyr::Location) -> Self {
        Loc {
            line: u32::try_from(l.line()).unwrap_or(u32::MAX),
            col: u32::try_from(l.column()).unwrap_or(u32::MAX),
        }
    }
}

/// How bad a diagnostic is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The file is still usable.
    Warning,
    /// The file is rejected.
    Error,
}

/// One finding about a file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Diagnostic {
    /// Error or warning.
    pub severity: Severity,
    /// The file, as the user named it.
    pub file: Arc<str>,
    /// Where in it.
    pub loc: Loc,
    /// What is wrong / what was expected.
    pub message: String,
    /// How to fix it, when we can tell.
    pub hint: Option<String>,
    /// More text shown under the message (a caret under an expression, a
    /// YAML snippet).
    pub detail: Option<String>,
    /// A short stable code naming the rule (`unknown-reference`, ...), for
    /// tests and for users searching the docs.
    pub code: &'static str,
}

impl Diagnostic {
    /// An error.
    pub fn error(
        file: &Arc<str>,
        loc: Loc,
        code: &'static str,
        message: impl Into<String>,
    ) -> Self {
        Diagnostic {
            severity: Severity::Error,
            file: file.clone(),
            loc,
            message: message.into(),
            hint: None,
            detail: None,
            code,
        }
    }
    /// A warning.
    pub fn warning(
        file: &Arc<str>,
        loc: Loc,
        code: &'static str,
        message: impl Into<String>,
    ) -> Self {
        Diagnostic {
            severity: Severity::Warning,
            ..Diagnostic::error(file, loc, code, message)
        }
    }
    /// Attach a hint.
    pub fn with_hint(mut self, hint: impl Into<String>) -> Self {
        self.hint = Some(hint.into());
        self
    }
    /// Attach more text (shown indented under the message).
    pub fn with_detail(mut self, detail: impl Into<String>) -> Self {
        self.detail = Some(detail.into());
        self
    }
    /// True for errors.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sev = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        if self.loc.is_known() {
            write!(f, "{}:{}:{}: ", self.file, self.loc.line, self.loc.col)?;
        } else {
            write!(f, "{}: ", self.file)?;
        }
        write!(f, "{sev}[{}]: {}", self.code, clip(&self.message))?;
        if let Some(d) = &self.detail {
            for line in around_carets(d) {
                write!(f, "\n    {}", clip(&line))?;
            }
        }
        if let Some(h) = &self.hint {
            write!(f, "\n  hint: {h}")?;
        }
        Ok(())
    }
}

/// Longest line of a diagnostic shown, in characters.
pub const MAX_SHOWN: usize = 300;

/// `line` cut to [`MAX_SHOWN`] characters, saying how many were left out:
/// a snippet of a 10 MB line (or a message quoting it) printed it whole.
fn clip(line: &str) -> std::borrow::Cow<'_, str> {
    match line.char_indices().nth(MAX_SHOWN) {
        None => line.into(),
        Some((at, _)) => {
            let more = line[at..].chars().count();
            format!("{}… ({more} more characters)", &line[..at]).into()
        }
    }
}

/// Where a snippet's caret line points: the character index of its first
/// `^`, if everything before it is gutter (`12 | `) or blanks.
fn caret_at(line: &str) -> Option<usize> {
    let i = line.chars().position(|c| c == '^')?;
    line.chars()
        .take(i)
        .all(|c| matches!(c, ' ' | '\t' | '|') || c.is_ascii_digit())
        .then_some(i)
}

/// The width of a snippet line's gutter (`12 | `, `   | `): 0 if none.
fn gutter(line: &str) -> usize {
    match line.find("| ") {
        Some(i) if i < 16 && line[..i].chars().all(|c| c == ' ' || c.is_ascii_digit()) => i + 2,
        _ => 0,
    }
}

/// A detail's lines, each source line over a caret that [`clip`] would
/// cut away shown from a window around the caret instead (`…` where the
/// window starts), the caret line moved with it: an error at column 5,000
/// of a long line still points at its place.
fn around_carets(detail: &str) -> Vec<std::borrow::Cow<'_, str>> {
    let lines: Vec<&str> = detail.lines().collect();
    let mut out: Vec<std::borrow::Cow<'_, str>> = lines.iter().map(|l| (*l).into()).collect();
    let mut above = 0;
    for (i, line) in lines.iter().enumerate() {
        let Some(c) = caret_at(line) else {
            continue;
        };
        let g = gutter(line);
        let from = above;
        above = i + 1;
        if c < MAX_SHOWN.saturating_sub(MAX_SHOWN / 4) {
            continue;
        }
        // Characters of each line's body (after the gutter) left out.
        let skip = c.saturating_sub(g + MAX_SHOWN / 2);
        let cut = |l: &str| -> String {
            let head: String = l.chars().take(g).collect();
            let body: String = l.chars().skip(g + skip).collect();
            format!("{head}…{body}")
        };
        for j in from..i {
            if gutter(lines[j]) == g {
                out[j] = cut(lines[j]).into();
            }
        }
        let head: String = line.chars().take(g).collect();
        let body: String = line.chars().skip(g + skip).collect();
        out[i] = format!("{head} {body}").into();
    }
    out
}

/// Several diagnostics, at least one of them an error.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnostics(pub Vec<Diagnostic>);

impl Diagnostics {
    /// The errors only.
    pub fn errors(&self) -> impl Iterator<Item = &Diagnostic> {
        self.0.iter().filter(|d| d.is_error())
    }
    /// True when some diagnostic has this code.
    pub fn has(&self, code: &str) -> bool {
        self.0.iter().any(|d| d.code == code)
    }
}

impl fmt::Display for Diagnostics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{d}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Diagnostics {}

/// "did you mean `x`?" for a misspelt name, if one of `candidates` is close.
pub fn did_you_mean<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<String> {
    let mut best: Option<(f64, &str)> = None;
    for c in candidates {
        let score = strsim::jaro_winkler(name, c);
        if score > 0.8 && best.is_none_or(|(s, _)| score > s) {
            best = Some((score, c));
        }
    }
    best.map(|(_, c)| format!("did you mean `{c}`?"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A snippet of an enormous line, or a message quoting it, is cut:
    /// a 10 MB line of a mission printed 20 MB of errors (input audit).
    #[test]
    fn long_lines_are_cut_where_shown() {
        let f: Arc<str> = Arc::from("m.rtcl");
        let long = "é".repeat(10_000);
        let d = Diagnostic::error(&f, Loc::new(1, 1), "x", format!("bad `{long}`"))
            .with_detail(format!("{long}\n^"));
        let text = d.to_string();
        assert!(text.len() < 3 * MAX_SHOWN * 2, "{}", text.len());
        assert!(text.contains("(9706 more characters)"), "{text}");
        assert!(text.contains("(9700 more characters)"), "{text}");
        assert!(text.ends_with("\n    ^"), "{text}");
        assert_eq!(clip("short"), "short");
    }

    /// An error far along a long line keeps its caret under the place:
    /// the line is shown from a window around it (input audit).
    #[test]
    fn a_caret_past_the_cut_is_kept_under_its_place() {
        let f: Arc<str> = Arc::from("m.rtcl");
        let line = format!("{}X{}", "a".repeat(5_000), "b".repeat(5_000));
        let detail = format!("1 | {line}\n  | {}^", " ".repeat(5_000));
        let d = Diagnostic::error(&f, Loc::new(1, 5_001), "x", "bad").with_detail(detail);
        let text = d.to_string();
        let lines: Vec<&str> = text.lines().collect();
        let src = lines[1].strip_prefix("    1 | …").expect(&text);
        let caret = lines[2].strip_prefix("      |  ").expect(&text);
        let col = caret.chars().position(|c| c == '^').expect(&text);
        assert_eq!(src.chars().nth(col), Some('X'), "{text}");
        assert!(lines[1].chars().count() < MAX_SHOWN + 40, "{text}");
        // A caret near the start is left as it was.
        let d =
            Diagnostic::error(&f, Loc::new(1, 3), "x", "bad").with_detail("1 | abcdef\n  |   ^");
        assert!(
            d.to_string().ends_with("    1 | abcdef\n      |   ^"),
            "{d}"
        );
        // A condition's snippet, no gutter.
        let cond = format!(
            "{}x >= && y\n{}^^ expected an operand",
            "a".repeat(400),
            " ".repeat(402)
        );
        let d = Diagnostic::error(&f, Loc::new(1, 1), "x", "bad").with_detail(cond);
        let text = d.to_string();
        let lines: Vec<&str> = text.lines().collect();
        let src = lines[1].strip_prefix("    …").expect(&text);
        let caret = lines[2].strip_prefix("     ").expect(&text);
        let col = caret.chars().position(|c| c == '^').expect(&text);
        assert_eq!(&src[col..col + 2], ">=", "{text}");
    }

    #[test]
    fn display_names_file_line_col_and_hint() {
        let f: Arc<str> = Arc::from("g.yaml");
        let d = Diagnostic::error(
            &f,
            Loc::new(3, 7),
            "unknown-reference",
            "no behavior `wlak`",
        )
        .with_hint("did you mean `walk`?");
        assert_eq!(
            d.to_string(),
            "g.yaml:3:7: error[unknown-reference]: no behavior `wlak`\n  hint: did you mean `walk`?"
        );
        assert_eq!(
            did_you_mean("wlak", ["walk", "search"]),
            Some("did you mean `walk`?".into())
        );
        assert_eq!(did_you_mean("zzz", ["walk"]), None);
    }
}
