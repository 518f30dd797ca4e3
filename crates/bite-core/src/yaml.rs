//! Reading user files: YAML with locations, limits and clear errors.
//!
//! Shared by every file format of the engine (graphs, configurations,
//! scenarios), so that all of them report problems the same way: file,
//! line, column, what was expected, with a snippet.

use crate::diag::{Diagnostic, Diagnostics, Loc};
use crate::value::Value;
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, Visitor};
use serde_saphyr::Spanned;
use std::fmt;
use std::marker::PhantomData;
use std::path::Path;
use std::sync::Arc;

/// Largest file accepted, in bytes.
pub const MAX_FILE_BYTES: usize = 16 * 1024 * 1024;

/// Deepest nesting accepted (mappings and sequences, block or flow).
pub const MAX_DEPTH: usize = 64;

/// Read a file for parsing: its display name and text.
pub fn read_file(path: &Path) -> Result<(Arc<str>, String), Diagnostics> {
    let file: Arc<str> = Arc::from(path.display().to_string());
    let text = read_text(&file, path)?;
    Ok((file, text))
}

/// Read a user file with a size limit, as a diagnostic on failure.
///
/// The file is read through a reader that stops one byte past
/// [`MAX_FILE_BYTES`], whatever the file is: a regular file, a device
/// (`/dev/zero`), a FIFO or a pipe that never ends are all refused at the
/// cap (`too-large`) rather than read without bound. Text that is not
/// UTF-8 is refused with the line and column of its first bad byte
/// (`invalid-utf8`).
pub fn read_text(file: &Arc<str>, path: &Path) -> Result<String, Diagnostics> {
    let bytes = read_bytes(file, path)?;
    utf8(file, bytes)
}

/// Read at most [`MAX_FILE_BYTES`] of a user file, as bytes; larger files
/// and endless streams are a `too-large` diagnostic.
pub fn read_bytes(file: &Arc<str>, path: &Path) -> Result<Vec<u8>, Diagnostics> {
    use std::io::Read as _;
    let f = std::fs::File::open(path).map_err(|e| io_error(file, &e))?;
    // A regular file says its size: refuse a large one before reading it.
    if let Ok(meta) = f.metadata()
        && meta.is_file()
    {
        check_size(file, meta.len())?;
    }
    let cap = MAX_FILE_BYTES as u64 + 1;
    let mut bytes = Vec::new();
    f.take(cap)
        .read_to_end(&mut bytes)
        .map_err(|e| io_error(file, &e))?;
    if bytes.len() > MAX_FILE_BYTES {
        return Err(Diagnostics(vec![
            Diagnostic::error(
                file,
                Loc::UNKNOWN,
                "too-large",
                format!(
                    "file is more than {MAX_FILE_BYTES} bytes (reading stopped there); the limit is {MAX_FILE_BYTES}"
                ),
            )
            .with_hint("a device, a FIFO or a stream that does not end is read up to the limit only"),
        ]));
    }
    Ok(bytes)
}

/// Bytes as text, or an `invalid-utf8` diagnostic at the first bad byte.
pub fn utf8(file: &Arc<str>, bytes: Vec<u8>) -> Result<String, Diagnostics> {
    String::from_utf8(bytes).map_err(|e| {
        let bytes = e.as_bytes();
        let bad = e.utf8_error().valid_up_to();
        Diagnostics(vec![utf8_diagnostic(file, bytes, bad)])
    })
}

/// The diagnostic for text whose first invalid UTF-8 byte is at `bad`.
pub fn utf8_diagnostic(file: &Arc<str>, bytes: &[u8], bad: usize) -> Diagnostic {
    // Everything before `bad` is valid UTF-8.
    let valid = std::str::from_utf8(&bytes[..bad]).unwrap_or_default();
    let loc = loc_at(valid, valid.len());
    let line_start = valid.rfind(['\n', '\r']).map_or(0, |i| i + 1);
    let byte = bytes.get(bad).copied().unwrap_or(0);
    // The line up to the bad byte (its last 60 characters), with control
    // characters (a random file may hold terminal escapes) shown as spaces.
    let line = &valid[line_start..];
    let n = line.chars().count();
    let mut shown: String = if n > 60 { "…".into() } else { String::new() };
    shown.extend(
        line.chars()
            .skip(n.saturating_sub(60))
            .map(|c| if c.is_control() && c != '\t' { ' ' } else { c }),
    );
    let width = loc.line.to_string().len();
    Diagnostic::error(
        file,
        loc,
        "invalid-utf8",
        format!("the file is not valid UTF-8 (its first bad byte is 0x{byte:02x})"),
    )
    .with_detail(format!(
        "{} | {shown}\n{:>width$} | {}^",
        loc.line,
        "",
        " ".repeat(shown.chars().count())
    ))
    .with_hint("save the file as UTF-8 text")
}

/// The 1-based line and column (in characters) of byte `at` of `text`,
/// counting lines as [`lines`] does (`\n`, `\r\n` or a lone `\r`).
pub fn loc_at(text: &str, at: usize) -> Loc {
    let at = at.min(text.len());
    let before = text.get(..at).unwrap_or(text);
    let b = before.as_bytes();
    let mut line = 1u32;
    let mut start = 0;
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'\r' if b.get(i + 1) == Some(&b'\n') => {
                line = line.saturating_add(1);
                i += 1;
                start = i + 1;
            }
            b'\n' | b'\r' => {
                line = line.saturating_add(1);
                start = i + 1;
            }
            _ => {}
        }
        i += 1;
    }
    let col = before[start.min(before.len())..].chars().count();
    Loc::new(line, u32::try_from(col + 1).unwrap_or(u32::MAX))
}

/// Reject a file over [`MAX_FILE_BYTES`] before doing any work on it.
fn check_size(file: &Arc<str>, len: u64) -> Result<(), Diagnostics> {
    if len > MAX_FILE_BYTES as u64 {
        return Err(Diagnostics(vec![Diagnostic::error(
            file,
            Loc::UNKNOWN,
            "too-large",
            format!("file is {len} bytes; the limit is {MAX_FILE_BYTES}"),
        )]));
    }
    Ok(())
}

fn io_error(file: &Arc<str>, e: &std::io::Error) -> Diagnostics {
    Diagnostics(vec![Diagnostic::error(
        file,
        Loc::UNKNOWN,
        "io",
        format!("cannot read the file: {e}"),
    )])
}

/// Parse YAML text into a spec type, turning syntax and shape errors into a
/// diagnostic with location and snippet.
pub fn parse<T: serde::de::DeserializeOwned>(
    file: &Arc<str>,
    text: &str,
) -> Result<T, Diagnostics> {
    check_size(file, text.len() as u64)?;
    let mut budget = serde_saphyr::Budget::default();
    budget.max_depth = MAX_DEPTH;
    // Room for the largest graph accepted (100,000 behaviors); the file
    // size limit bounds the work anyway.
    budget.max_nodes = 10_000_000;
    budget.max_events = 20_000_000;
    budget.max_aliases = 1_000;
    budget.max_anchors = 1_000;
    let mut options = serde_saphyr::Options::default();
    options.budget = Some(budget);
    // YAML 1.2 booleans only: `y`, `no`, `on` stay text (a behavior or skill
    // may well be called `on`), and `yes` for a boolean is an error rather
    // than a silent surprise.
    options.strict_booleans = true;
    serde_saphyr::from_str_with_options::<T>(text, options).map_err(|e| {
        let loc = e.location().map(Loc::from).unwrap_or(Loc::UNKNOWN);
        let plain = e.render_with_options(serde_saphyr::render_options! {
            snippets: serde_saphyr::SnippetMode::Off,
        });
        // The plain rendering ends with " at line L column C"; we print the
        // location ourselves.
        let message = match plain.find(" at line ") {
            Some(i) => plain[..i].to_string(),
            None => plain.clone(),
        };
        let message = message
            .trim_start_matches("error: ")
            .trim_start_matches(|c: char| c.is_ascii_digit() || c == ':' || c == ' ')
            .to_string();
        let message = strip_line_col_prefix(&message);
        let (message, hint) = explain(&message);
        let snippet = snippet(text, loc);
        let mut d = Diagnostic::error(file, loc, "yaml", message).with_detail(snippet);
        d.hint = hint;
        Diagnostics(vec![d])
    })
}

/// The lines of a file as YAML counts them: a line ends at `\n`, `\r\n`
/// or a lone `\r` (so reported line numbers match the text shown).
pub fn lines(text: &str) -> impl Iterator<Item = &str> {
    let mut rest = Some(text);
    std::iter::from_fn(move || {
        let t = rest?;
        match t.find(['\n', '\r']) {
            Some(i) => {
                let next = if t[i..].starts_with("\r\n") {
                    i + 2
                } else {
                    i + 1
                };
                rest = Some(&t[next..]);
                Some(&t[..i])
            }
            None => {
                rest = None;
                (!t.is_empty()).then_some(t)
            }
        }
    })
}

/// The source lines around `loc` with a caret under its column:
///
/// ```text
///  4 |   a:
///  5 |     nxt: [b]
///    |     ^
/// ```
pub fn snippet(text: &str, loc: Loc) -> String {
    if !loc.is_known() {
        return String::new();
    }
    let line = loc.line as usize;
    let width = line.to_string().len();
    let mut out = String::new();
    for (i, l) in text
        .lines()
        .enumerate()
        .skip(line.saturating_sub(2))
        .take(2)
    {
        if i + 1 > line {
            break;
        }
        out.push_str(&format!("{:>width$} | {l}\n", i + 1));
    }
    out.push_str(&format!(
        "{:>width$} | {}^",
        "",
        " ".repeat(loc.col.saturating_sub(1) as usize)
    ));
    out
}

/// Turn the YAML library's wording into the user's: what is wrong in
/// their file, and how to fix it.
fn explain(m: &str) -> (String, Option<String>) {
    if let Some(rest) = m.strip_prefix("duplicate mapping key: ") {
        let key = rest.split(',').next().unwrap_or(rest).trim();
        return (
            format!("`{key}` is defined twice in the same mapping"),
            Some("names must be unique: rename or merge the two entries".into()),
        );
    }
    if let Some(rest) = m.strip_prefix("budget breached: ") {
        let what = rest.split([' ', '{']).next().unwrap_or(rest);
        let limit = match what {
            "Depth" => "nesting deeper than 64 levels",
            "Events" | "Nodes" => "too many YAML elements",
            "Aliases" => "too many aliases",
            "Anchors" => "too many anchors",
            _ => "a YAML safety limit",
        };
        return (format!("the file exceeds a limit: {limit}"), None);
    }
    if let Some(rest) = m.strip_prefix("unknown field `")
        && let Some((field, expected)) = rest.split_once('`')
    {
        // "..., expected one of a, b, c" (with or without backticks).
        let list = expected
            .split_once("expected one of ")
            .or_else(|| expected.split_once("expected "))
            .map_or("", |(_, l)| l);
        let options: Vec<&str> = list
            .split(',')
            .map(|o| o.trim().trim_matches('`'))
            .filter(|o| !o.is_empty())
            .collect();
        let hint = crate::diag::did_you_mean(field, options.iter().copied()).or_else(|| {
            (!options.is_empty()).then(|| format!("the known keys are: {}", options.join(", ")))
        });
        return (format!("unknown key `{field}`"), hint);
    }
    // The library's own wording, in the user's terms (input audit,
    // 2026-12-07: these reached users as the library wrote them).
    if m.starts_with("multiple YAML documents detected") {
        return (
            "the file holds more than one YAML document (a `---` line starts another)".into(),
            Some("keep one document per file".into()),
        );
    }
    if m.starts_with("cannot deserialize null into ") {
        return ("a value is missing here (it is empty or `~`)".into(), None);
    }
    if m.starts_with("recursive references require") {
        return (
            "an alias refers to the node that holds it (a recursive alias)".into(),
            None,
        );
    }
    if m.starts_with("data did not match any variant of untagged enum") {
        return (
            "this value has none of the forms accepted here".into(),
            None,
        );
    }
    if let Some(ty) = m.strip_prefix("invalid ") {
        let max = match ty {
            "u8" => Some(u64::from(u8::MAX)),
            "u16" => Some(u64::from(u16::MAX)),
            "u32" => Some(u64::from(u32::MAX)),
            "u64" | "usize" => Some(u64::MAX),
            _ => None,
        };
        if let Some(max) = max {
            return (format!("expected a whole number from 0 to {max}"), None);
        }
    }
    if let Some(rest) = m.strip_prefix("invalid type: floating point `")
        && let Some((n, expected)) = rest.split_once('`')
        && n.parse::<f64>().is_ok_and(|x| x.abs() >= 1e15)
    {
        return (format!("`{n}` is too large{expected}"), None);
    }
    (m.to_string(), None)
}

fn strip_line_col_prefix(m: &str) -> String {
    // "line 3 column 11: invalid boolean" -> "invalid boolean"
    if let Some(rest) = m.strip_prefix("line ")
        && let Some(i) = rest.find(": ")
        && rest[..i].contains("column")
    {
        return rest[i + 2..].to_string();
    }
    m.to_string()
}

/// A JSON value from a file as a belief value.
pub fn json_to_value(v: &serde_json::Value) -> Option<Value> {
    match v {
        serde_json::Value::Bool(b) => Some(Value::Bool(*b)),
        serde_json::Value::Number(n) => n.as_f64().map(Value::Num),
        serde_json::Value::String(s) => Some(Value::Text(Arc::from(s.as_str()))),
        serde_json::Value::Array(a) if a.len() == 2 => {
            Some(Value::Vec2([a[0].as_f64()?, a[1].as_f64()?]))
        }
        _ => None,
    }
}

/// A YAML mapping whose entries keep their file order and locations.
#[derive(Debug)]
pub struct Ordered<T>(pub Vec<(Spanned<String>, Spanned<T>)>);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Ordered<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Ordered<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a mapping of names to entries")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Ordered<T>, A::Error> {
                let mut v = Vec::new();
                while let Some(entry) = m.next_entry()? {
                    v.push(entry);
                }
                Ok(Ordered(v))
            }
        }
        d.deserialize_map(V(PhantomData))
    }
}

impl<T> Default for Ordered<T> {
    fn default() -> Self {
        Ordered(Vec::new())
    }
}

/// A duration written as a number (seconds) or text (`250ms`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DurationText(pub String);

impl<'de> Deserialize<'de> for DurationText {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = DurationText;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a duration such as `2s`, `250ms` or a number of seconds")
            }
            fn visit_u64<E: de::Error>(self, n: u64) -> Result<DurationText, E> {
                Ok(DurationText(n.to_string()))
            }
            fn visit_i64<E: de::Error>(self, n: i64) -> Result<DurationText, E> {
                Ok(DurationText(n.to_string()))
            }
            fn visit_f64<E: de::Error>(self, n: f64) -> Result<DurationText, E> {
                Ok(DurationText(n.to_string()))
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<DurationText, E> {
                Ok(DurationText(s.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_end_like_yaml_lines() {
        let v: Vec<&str> = lines("a\nb\r\nc\rd").collect();
        assert_eq!(v, ["a", "b", "c", "d"]);
        assert_eq!(lines("x\n").collect::<Vec<_>>(), ["x"]);
        assert_eq!(lines("").count(), 0);
        assert_eq!(lines("\r\r").collect::<Vec<_>>(), ["", ""]);
    }

    #[test]
    fn the_first_bad_utf8_byte_is_located() {
        let f: Arc<str> = Arc::from("m.yaml");
        // Line ends of every kind; columns count characters.
        let bytes = b"a: 1\r\nb: 2\rc: \xc3\xa9\xe2\x82\n".to_vec();
        let e = utf8(&f, bytes).expect_err("truncated sequence");
        let d = &e.0[0];
        assert_eq!((d.code, d.loc), ("invalid-utf8", Loc::new(3, 5)), "{d}");
        assert!(d.message.contains("0xe2"), "{d}");
        assert!(d.to_string().starts_with("m.yaml:3:5: error[invalid-utf8]"));
        let e = utf8(&f, vec![0xff]).expect_err("bad first byte");
        assert_eq!(e.0[0].loc, Loc::new(1, 1));
        assert_eq!(utf8(&f, "ok ✓".into()).as_deref(), Ok("ok ✓"));
        assert_eq!(loc_at("ab\ncd", 4), Loc::new(2, 2));
    }

    /// Thousands of nested brackets (or keys) are left to the library,
    /// which refuses them with a location, instead of overflowing the
    /// fast reader's stack: a graph of `start: ` and 30,000 `[` aborted
    /// `bite check` (found by an input audit, 2026-12-07).
    #[test]
    fn deep_nesting_is_left_to_the_library() {
        for text in [
            format!("start: {}", "[".repeat(30_000)),
            format!("a: {}1{}", "[".repeat(MAX_DEPTH), "]".repeat(MAX_DEPTH)),
            format!("a: {{b: {}", "{c: ".repeat(100_000)),
            (0..MAX_DEPTH + 1)
                .map(|i| format!("{}k{i}:\n", " ".repeat(i)))
                .collect::<String>()
                + &" ".repeat(MAX_DEPTH + 1)
                + "v: 1\n",
        ] {
            assert!(fast::parse(&text).is_none(), "{}", &text[..40]);
            let f: Arc<str> = Arc::from("deep.yaml");
            let e = parse::<serde_json::Value>(&f, &text).expect_err("too deep");
            assert!(
                e.to_string().contains("deep.yaml:1:") || e.to_string().contains("deeper"),
                "{e}"
            );
        }
        // At the limit (the top mapping, its value, then the brackets),
        // the fast reader still reads it.
        let ok = format!(
            "a: {}1{}",
            "[".repeat(MAX_DEPTH - 2),
            "]".repeat(MAX_DEPTH - 2)
        );
        assert!(fast::parse(&ok).is_some());
    }

    /// The library's wording reaches the user in the user's terms.
    #[test]
    fn library_messages_are_explained() {
        let f: Arc<str> = Arc::from("x.yaml");
        let said = |text: &str| {
            parse::<std::collections::BTreeMap<String, u64>>(&f, text)
                .expect_err(text)
                .to_string()
        };
        let m = said("a: 1\n---\nb: 2\n");
        assert!(m.contains("more than one YAML document"), "{m}");
        for n in ["-1", "99999999999999999999"] {
            let m = said(&format!("a: {n}\n"));
            assert!(
                m.contains("expected a whole number from 0 to 18446744073709551615"),
                "{m}"
            );
        }
        let m = parse::<std::collections::BTreeMap<String, String>>(&f, "a: ~\n")
            .expect_err("null")
            .to_string();
        assert!(m.contains("a value is missing here"), "{m}");
    }

    #[test]
    fn endless_files_are_read_up_to_the_cap_only() {
        let f: Arc<str> = Arc::from("/dev/zero");
        let e = read_text(&f, Path::new("/dev/zero")).expect_err("refused");
        assert_eq!(e.0[0].code, "too-large", "{e}");
        let f: Arc<str> = Arc::from("nowhere");
        let e = read_text(&f, Path::new("/no/such/file.yaml")).expect_err("missing");
        assert_eq!(e.0[0].code, "io");
    }
}

/// A fast reader for the plain subset of YAML that generated graphs (and
/// most hand-written ones) use, for large files: block mappings of plain
/// keys, single-line flow sequences and mappings, plain and double-quoted
/// single-line scalars, comments.
///
/// It answers `None` for anything outside that subset (block sequences,
/// anchors, tags, single quotes, block or multi-line scalars, empty
/// values, tabs, `\r`, directives, duplicate keys, odd plain scalars...)
/// and for anything wrong: the caller then parses the text with the full
/// YAML library, which gives the same value, or the error message with
/// its location, as it always did. What it accepts it reads as that
/// library does, with the same line and column for every node.
pub(crate) mod fast {
    use super::MAX_DEPTH;
    use serde_saphyr::Location;
    use std::borrow::Cow;

    /// A scalar and where it starts (1-based line and column, characters).
    #[derive(Debug)]
    pub struct Scalar<'a> {
        pub text: Cow<'a, str>,
        pub quoted: bool,
        pub line: u32,
        pub col: u32,
    }

    /// A node of the subset.
    #[derive(Debug)]
    pub enum Node<'a> {
        Scalar(Scalar<'a>),
        /// A flow sequence, its items, and where its `[` is.
        Seq(Vec<Node<'a>>, u32, u32),
        /// A mapping (block or flow), its entries in order, and where it
        /// starts: its first key (block) or its `{` (flow).
        Map(Vec<(Scalar<'a>, Node<'a>)>, u32, u32),
    }

    impl<'a> Node<'a> {
        pub fn loc(&self) -> (u32, u32) {
            match self {
                Node::Scalar(s) => (s.line, s.col),
                Node::Seq(_, l, c) | Node::Map(_, l, c) => (*l, *c),
            }
        }
    }

    /// A location as the YAML library makes it (line and column only).
    pub fn location(line: u32, col: u32) -> Location {
        use serde::Deserialize as _;
        use serde::de::value::{Error, MapDeserializer};
        let d = MapDeserializer::<_, Error>::new([("line", line), ("column", col)].into_iter());
        Location::deserialize(d).unwrap_or(Location::UNKNOWN)
    }

    struct Line<'a> {
        no: u32,
        indent: usize,
        /// The line from its first non-space character.
        body: &'a str,
        ascii: bool,
        full: &'a str,
    }

    impl Line<'_> {
        /// 1-based column (characters) of byte `at` of the body.
        fn col(&self, at: usize) -> u32 {
            let byte = self.indent + at;
            let n = if self.ascii {
                byte
            } else {
                self.full.get(..byte).map_or(byte, |p| p.chars().count())
            };
            u32::try_from(n + 1).unwrap_or(u32::MAX)
        }
    }

    /// The root block mapping of `text`, or `None` (see the module).
    pub fn parse(text: &str) -> Option<Node<'_>> {
        // Only printable characters (as YAML defines them) and `\n`: tabs,
        // `\r`, a byte-order mark and the rest are the library's to read.
        if text.bytes().any(|b| (b < b' ' && b != b'\n') || b == 0x7f)
            || (!text.is_ascii()
                && text.chars().any(|c| {
                    matches!(c, '\u{80}'..='\u{84}' | '\u{86}'..='\u{9f}' | '\u{feff}' | '\u{fffe}' | '\u{ffff}')
                }))
        {
            return None;
        }
        let mut lines = Vec::new();
        for (i, full) in text.split('\n').enumerate() {
            let body = full.trim_start_matches(' ');
            if body.is_empty() || body.starts_with('#') {
                continue;
            }
            let indent = full.len() - body.len();
            if indent == 0
                && (body.starts_with("---") || body.starts_with("...") || body.starts_with('%'))
            {
                return None;
            }
            lines.push(Line {
                no: u32::try_from(i + 1).ok()?,
                indent,
                body,
                ascii: full.is_ascii(),
                full,
            });
        }
        if lines.first()?.indent != 0 {
            return None;
        }
        let mut pos = 0;
        let root = block_map(&lines, &mut pos, 0, 1)?;
        (pos == lines.len()).then_some(root)
    }

    /// A block mapping at nesting `depth` (the top one 1). Deeper than
    /// [`MAX_DEPTH`]: `None`, and the library reports it (its budget has
    /// the same limit), so that a file of thousands of nested brackets
    /// cannot overflow the stack here first.
    fn block_map<'a>(
        lines: &[Line<'a>],
        pos: &mut usize,
        indent: usize,
        depth: usize,
    ) -> Option<Node<'a>> {
        if depth > MAX_DEPTH {
            return None;
        }
        let first = lines.get(*pos)?;
        let (line0, col0) = (first.no, first.col(0));
        let mut entries: Vec<(Scalar<'a>, Node<'a>)> = Vec::new();
        while let Some(l) = lines.get(*pos) {
            if l.indent < indent {
                break;
            }
            if l.indent > indent {
                return None;
            }
            let body = l.body;
            let klen = body
                .bytes()
                .position(|b| !(b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.')))?;
            if klen == 0
                || !(body.as_bytes()[0].is_ascii_alphabetic() || body.as_bytes()[0] == b'_')
            {
                return None;
            }
            let rest = body[klen..].strip_prefix(':')?;
            let key = Scalar {
                text: Cow::Borrowed(&body[..klen]),
                quoted: false,
                line: l.no,
                col: l.col(0),
            };
            *pos += 1;
            let after = rest.trim_start_matches(' ');
            let value = if after.is_empty() || (after.starts_with('#') && rest.starts_with(' ')) {
                // A nested block mapping on the lines below.
                let next = lines.get(*pos)?;
                if next.indent <= indent {
                    return None;
                }
                block_map(lines, pos, next.indent, depth + 1)?
            } else {
                if !rest.starts_with(' ') {
                    return None;
                }
                let at = body.len() - after.len();
                let mut cur = Cursor { line: l, at };
                let v = cur.value(false, depth + 1)?;
                cur.end_of_line()?;
                if lines.get(*pos).is_some_and(|n| n.indent > indent) {
                    return None;
                }
                v
            };
            entries.push((key, value));
        }
        unique(&entries)?;
        Some(Node::Map(entries, line0, col0))
    }

    /// `None` when a key is given twice (the library says where).
    fn unique(entries: &[(Scalar<'_>, Node<'_>)]) -> Option<()> {
        if entries.len() <= 16 {
            for (i, (k, _)) in entries.iter().enumerate() {
                if entries[..i].iter().any(|(o, _)| o.text == k.text) {
                    return None;
                }
            }
            return Some(());
        }
        let mut keys: Vec<&str> = entries.iter().map(|(k, _)| k.text.as_ref()).collect();
        keys.sort_unstable();
        keys.windows(2).all(|w| w[0] != w[1]).then_some(())
    }

    struct Cursor<'l, 'a> {
        line: &'l Line<'a>,
        at: usize,
    }

    impl<'a> Cursor<'_, 'a> {
        fn rest(&self) -> &'a str {
            &self.line.body[self.at..]
        }
        fn skip_spaces(&mut self) {
            let r = self.rest();
            self.at += r.len() - r.trim_start_matches(' ').len();
        }
        /// Only spaces and a comment may follow.
        fn end_of_line(&mut self) -> Option<()> {
            let before = self.at;
            self.skip_spaces();
            let r = self.rest();
            (r.is_empty() || (r.starts_with('#') && self.at > before)).then_some(())
        }
        /// A value at nesting `depth` (see `block_map`).
        fn value(&mut self, flow: bool, depth: usize) -> Option<Node<'a>> {
            if depth > MAX_DEPTH {
                return None;
            }
            let (line, col) = (self.line.no, self.line.col(self.at));
            let r = self.rest();
            match r.as_bytes().first()? {
                b'[' => {
                    self.at += 1;
                    let mut items = Vec::new();
                    self.skip_spaces();
                    if self.rest().starts_with(']') {
                        self.at += 1;
                        return Some(Node::Seq(items, line, col));
                    }
                    loop {
                        self.skip_spaces();
                        items.push(self.value(true, depth + 1)?);
                        self.skip_spaces();
                        match self.rest().as_bytes().first()? {
                            b',' => self.at += 1,
                            b']' => {
                                self.at += 1;
                                return Some(Node::Seq(items, line, col));
                            }
                            _ => return None,
                        }
                    }
                }
                b'{' => {
                    self.at += 1;
                    let mut entries = Vec::new();
                    self.skip_spaces();
                    if self.rest().starts_with('}') {
                        self.at += 1;
                        return Some(Node::Map(entries, line, col));
                    }
                    loop {
                        self.skip_spaces();
                        let Node::Scalar(key) = self.value(true, depth + 1)? else {
                            return None;
                        };
                        if key.quoted || !self.rest().starts_with(": ") {
                            return None;
                        }
                        self.at += 2;
                        self.skip_spaces();
                        let v = self.value(true, depth + 1)?;
                        entries.push((key, v));
                        self.skip_spaces();
                        match self.rest().as_bytes().first()? {
                            b',' => self.at += 1,
                            b'}' => {
                                self.at += 1;
                                unique(&entries)?;
                                return Some(Node::Map(entries, line, col));
                            }
                            _ => return None,
                        }
                    }
                }
                b'"' => {
                    let (text, len) = double_quoted(r)?;
                    self.at += len;
                    Some(Node::Scalar(Scalar {
                        text,
                        quoted: true,
                        line,
                        col,
                    }))
                }
                c if c.is_ascii_alphanumeric() || *c == b'_' => {
                    let b = r.as_bytes();
                    let mut end = 0;
                    while end < b.len() {
                        match b[end] {
                            b':' if b.get(end + 1).is_none_or(|n| {
                                *n == b' ' || (flow && matches!(n, b',' | b']' | b'}'))
                            }) =>
                            {
                                break;
                            }
                            b'#' if b[end - 1] == b' ' => break,
                            b',' | b']' | b'}' if flow => break,
                            b'[' | b'{' if flow => return None,
                            b'"' | b'\'' | b'`' | b'@' | b'|' | b'>' | b'!' | b'&' | b'*'
                            | b'%' | b'\\' => return None,
                            c if c < b' ' || c == 0x7f => return None,
                            _ => {}
                        }
                        end += 1;
                    }
                    let text = r[..end].trim_end_matches(' ');
                    self.at += text.len();
                    Some(Node::Scalar(Scalar {
                        text: Cow::Borrowed(text),
                        quoted: false,
                        line,
                        col,
                    }))
                }
                _ => None,
            }
        }
    }

    /// A double-quoted scalar at the start of `s`: its text and length.
    fn double_quoted(s: &str) -> Option<(Cow<'_, str>, usize)> {
        let body = &s[1..];
        let end = body.find(['"', '\\'])?;
        if body.as_bytes()[end] == b'"' {
            let t = &body[..end];
            if t.chars().any(|c| c.is_control()) {
                return None;
            }
            return Some((Cow::Borrowed(t), end + 2));
        }
        let mut out = String::with_capacity(body.len());
        let mut chars = body.char_indices();
        while let Some((i, c)) = chars.next() {
            match c {
                '"' => return Some((Cow::Owned(out), i + 2)),
                '\\' => {
                    let (_, e) = chars.next()?;
                    match e {
                        '"' => out.push('"'),
                        '\\' => out.push('\\'),
                        '/' => out.push('/'),
                        'n' => out.push('\n'),
                        't' => out.push('\t'),
                        'u' => {
                            let mut v = 0u32;
                            for _ in 0..4 {
                                let (_, h) = chars.next()?;
                                v = v * 16 + h.to_digit(16)?;
                            }
                            out.push(char::from_u32(v)?);
                        }
                        _ => return None,
                    }
                }
                c if c.is_control() => return None,
                c => out.push(c),
            }
        }
        None
    }
}
