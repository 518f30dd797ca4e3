//! The syntax tree of a mission, with source spans.

use crate::source::Span;

/// A mission: its commands in the order written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mission {
    /// The commands that parsed.
    pub commands: Vec<Command>,
    /// Result names (`=>name`) found on lines that did not parse, so the
    /// checker does not report every later use of them as undefined.
    pub recovered: Vec<Name>,
}

/// One command line: `name:param:param...=>result`.
#[derive(Clone, Debug, PartialEq)]
pub struct Command {
    /// The command word, as written (`find`, `Move`).
    pub name: Name,
    /// The parameters after the command word, in order; an empty one
    /// (`find::::yellow`) is [`ParamKind::Empty`].
    pub params: Vec<Param>,
    /// The name given to the command's result (`=>box`).
    pub result: Option<Name>,
    /// From the command word to the end of its last token.
    pub span: Span,
    /// 1-based line.
    pub line: u32,
}

/// A name or word, with where it was written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Name {
    /// The text as written.
    pub text: String,
    /// Where.
    pub span: Span,
}

/// One parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// What was written.
    pub kind: ParamKind,
    /// Where (an empty span just after its `:` when it is empty).
    pub span: Span,
}

/// What a parameter is, syntactically. Its meaning (a colour, a result
/// name, a choice) depends on the command, and is decided by the checker.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    /// Nothing between two colons: unknown.
    Empty,
    /// A number (metres, seconds, ...).
    Number(f64),
    /// A word: a colour, a choice, or the name of an earlier result.
    Word(String),
}

impl ParamKind {
    /// How the parameter is described in messages.
    pub fn describe(&self) -> String {
        match self {
            ParamKind::Empty => "an empty parameter".into(),
            ParamKind::Number(_) => "a number".into(),
            ParamKind::Word(w) => format!("`{w}`"),
        }
    }
}
