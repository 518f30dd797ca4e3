//! The condition language of behavior preconditions (`pre`), termination
//! conditions (`until`) and utilities.
//!
//! A condition such as `distance_walked >= 6 && peers_located` is parsed and
//! checked once, when the behavior graph is loaded, into an [`Expr`]: a flat
//! array of nodes that evaluates without allocating. Names are resolved while
//! parsing through a [`Resolver`]; values are read while evaluating through an
//! [`Env`].
//!
//! Semantics are *closed world*: a belief that is not set is unknown, and
//! unknown counts as false wherever a truth value is needed, so
//! `not obstacle_near` holds while nothing is known about obstacles.
//! Evaluation never panics. The user reference is `docs/conditions.md`.
//!
//! ```
//! use bite_core::cond::{Env, Expr, Resolver};
//! use bite_core::ids::{BehaviorId, BeliefId};
//! use bite_core::value::Value;
//!
//! struct Names(Vec<String>);
//! impl Resolver for Names {
//!     fn belief(&mut self, name: &str) -> BeliefId {
//!         let i = self.0.iter().position(|n| n == name).unwrap_or_else(|| {
//!             self.0.push(name.to_owned());
//!             self.0.len() - 1
//!         });
//!         BeliefId(i as u32)
//!     }
//!     fn behavior(&self, _name: &str) -> Option<BehaviorId> {
//!         None
//!     }
//! }
//! struct World(Vec<Option<Value>>);
//! impl Env for World {
//!     fn belief(&self, id: BeliefId) -> Option<&Value> {
//!         self.0.get(id.index())?.as_ref()
//!     }
//!     fn belief_age(&self, _id: BeliefId) -> Option<f64> {
//!         None
//!     }
//!     fn elapsed(&self) -> f64 {
//!         0.0
//!     }
//!     fn runs(&self, _b: Option<BehaviorId>) -> u32 {
//!         1
//!     }
//! }
//!
//! let mut names = Names(Vec::new());
//! let e = Expr::parse("distance_walked >= 6 && peers_located", &mut names)?;
//! let world = World(vec![Some(Value::Num(7.5)), Some(Value::Bool(true))]);
//! assert!(e.eval(&world));
//! assert!(!e.eval(&World(vec![Some(Value::Num(7.5)), None])));
//! # Ok::<(), bite_core::cond::CondError>(())
//! ```

mod eval;
mod lexer;
mod node;
mod parser;
#[cfg(test)]
mod prop_tests;
#[cfg(test)]
mod tests;

use crate::ids::{BehaviorId, BeliefId};
use crate::value::Value;
use node::{Node, Ty};
use std::fmt;
use std::ops::Range;

/// True when a condition can name a belief `name`: the lexer reads all of
/// it as one name (ASCII letters, digits and `_`, not starting with a
/// digit), and it is no keyword (`and`, `or`, `not`, `true`, `false`).
pub fn readable_name(name: &str) -> bool {
    lexer::lex(name).is_ok_and(|l| {
        matches!(
            l.toks.as_slice(),
            [w, e] if w.tok == lexer::Tok::Ident && w.start == 0 && w.end == name.len()
                && e.tok == lexer::Tok::Eof
        )
    })
}

/// Longest accepted source, in bytes.
pub const MAX_SOURCE_LEN: usize = 4096;
/// Most tokens in one expression.
pub const MAX_TOKENS: usize = 1024;
/// Deepest nesting of the expression tree (parentheses, brackets, calls,
/// unary operators and binary operators; a chain of `&&` or of `||` counts
/// as one level).
pub const MAX_DEPTH: u32 = 64;

/// Resolves names while parsing. Implemented by the graph loader.
pub trait Resolver {
    /// Intern a belief name, returning its id (always succeeds).
    ///
    /// Called only when the whole expression parses, once per distinct
    /// name, in order of first appearance.
    fn belief(&mut self, name: &str) -> BeliefId;

    /// Look up a behavior by name (for `runs(name)`); None if unknown.
    fn behavior(&self, name: &str) -> Option<BehaviorId>;

    /// The names of all behaviors, used only to suggest a correction for an
    /// unknown behavior name. The default suggests nothing.
    fn behavior_names(&self) -> Vec<&str> {
        Vec::new()
    }
}

/// What an expression can read while being evaluated. Implemented by the
/// kernel.
pub trait Env {
    /// The current value of belief `id`, None if unset.
    fn belief(&self, id: BeliefId) -> Option<&Value>;
    /// Seconds since belief `id` was last set, None if unset.
    fn belief_age(&self, id: BeliefId) -> Option<f64>;
    /// Seconds since the behavior that owns this condition started.
    fn elapsed(&self) -> f64;
    /// How many times behavior `b` (None = the behavior that owns the
    /// condition) has been started in the current execution of its parent
    /// behavior (a loop count that restarts with the enclosing behavior),
    /// counting the current
    /// run.
    fn runs(&self, b: Option<BehaviorId>) -> u32;
}

/// A parsed and checked condition (or numeric utility) expression.
///
/// Cheap to evaluate: a flat array of nodes with `u32` child indices;
/// evaluation does not allocate.
#[derive(Clone, Debug)]
pub struct Expr {
    src: Box<str>,
    nodes: Box<[Node]>,
    lists: Box<[u32]>,
    root: u32,
    beliefs: Box<[BeliefId]>,
    time: bool,
    runs: bool,
    ty: Ty,
}

impl Expr {
    /// Parse and check `src`. Errors carry a byte span into `src`.
    ///
    /// Belief names are interned through `resolver` only if parsing
    /// succeeds.
    pub fn parse(src: &str, resolver: &mut dyn Resolver) -> Result<Expr, CondError> {
        parser::parse(src, resolver)
    }

    /// The source text.
    pub fn source(&self) -> &str {
        &self.src
    }

    /// Evaluate as a condition: true only if the result is `Bool(true)`.
    /// Unknown, numbers, vectors and text all count as false.
    #[inline]
    pub fn eval<E: Env + ?Sized>(&self, env: &E) -> bool {
        self.truth(self.root, env)
    }

    /// Evaluate to a value (None = unknown). Used for numeric `utility`
    /// expressions.
    pub fn eval_value<E: Env + ?Sized>(&self, env: &E) -> Option<Value> {
        self.value(self.root, env).to_value()
    }

    /// Every belief the expression reads, sorted and deduplicated (the world
    /// model shares only these).
    pub fn beliefs(&self) -> &[BeliefId] {
        &self.beliefs
    }

    /// Give every belief `id` it reads the id `map[id]`: an expression parsed
    /// against one table of names, moved to another that holds the same
    /// names under other ids (the graph loader parses behaviors side by
    /// side, each with its own table of names, then numbers the names in
    /// the behaviors' order). `map` must be one-to-one and cover every id
    /// read.
    pub fn remap_beliefs(&mut self, map: &[BeliefId]) {
        let to = |id: &mut BeliefId| {
            if let Some(m) = map.get(id.index()) {
                *id = *m;
            }
        };
        for node in self.nodes.iter_mut() {
            match node {
                Node::Belief(id) | Node::Known(id) | Node::Age(id) | Node::CmpBelief(_, id, _) => {
                    to(id)
                }
                _ => {}
            }
        }
        self.beliefs.iter_mut().for_each(to);
        self.beliefs.sort_unstable();
    }

    /// True if the result can change with time alone (uses `elapsed` or
    /// `age(..)`), so the kernel must re-evaluate it every tick even when no
    /// belief changed.
    pub fn depends_on_time(&self) -> bool {
        self.time
    }

    /// True if it reads `runs`.
    pub fn depends_on_runs(&self) -> bool {
        self.runs
    }

    /// The static result type if known (`"bool"`, `"number"`, `"vector"`,
    /// `"text"`, as [`Value::type_name`]), for checks like "a condition must
    /// be boolean". None when the result is a bare belief (dynamically
    /// typed). A known type still allows an unknown result at run time.
    pub fn static_type(&self) -> Option<&'static str> {
        self.ty.name()
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.src)
    }
}

/// A parse or type error, pointing into the source.
#[derive(Clone, Debug, PartialEq)]
pub struct CondError {
    /// Byte range in the source that the error points at (may be empty at
    /// end of input). Always on char boundaries within `0..=src.len()`.
    pub span: Range<usize>,
    /// What is wrong, e.g. "expected an operand after `&&`, found end of
    /// expression".
    pub message: String,
    /// Optional hint, e.g. "did you mean `&&`?" or "use `==` to compare".
    pub hint: Option<String>,
}

impl fmt::Display for CondError {
    /// `col N: message` (N is the 1-based byte column of the span start),
    /// followed by ` (hint)` if there is a hint.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "col {}: {}", self.span.start + 1, self.message)?;
        if let Some(h) = &self.hint {
            write!(f, " ({h})")?;
        }
        Ok(())
    }
}

impl std::error::Error for CondError {}

impl CondError {
    /// Render the source with a caret line under the span, for CLI messages:
    ///
    /// ```text
    /// distance >= && x
    ///             ^^ expected an operand after `>=`, found `&&`
    /// ```
    ///
    /// A hint follows on its own line (`help: ...`). For a multi-line source
    /// only the line holding the span start is shown, after a `line N:`
    /// header. Never panics, even if `src` is not the parsed source.
    pub fn render(&self, src: &str) -> String {
        let floor = |mut i: usize| {
            i = i.min(src.len());
            while !src.is_char_boundary(i) {
                i -= 1;
            }
            i
        };
        let start = floor(self.span.start);
        let end = floor(self.span.end.max(start));
        let line_start = src
            .get(..start)
            .and_then(|s| s.rfind('\n'))
            .map_or(0, |i| i + 1);
        let line_end = src
            .get(start..)
            .and_then(|s| s.find('\n'))
            .map_or(src.len(), |i| start + i);
        let line = src.get(line_start..line_end).unwrap_or("");
        let mut out = String::new();
        if src.contains('\n') {
            let n = src.get(..start).map_or(0, |s| s.matches('\n').count()) + 1;
            out.push_str(&format!("line {n}:\n"));
        }
        out.push_str(line.strip_suffix('\r').unwrap_or(line));
        out.push('\n');
        let pad: String = src
            .get(line_start..start)
            .unwrap_or("")
            .chars()
            .map(|c| if c == '\t' { '\t' } else { ' ' })
            .collect();
        let carets = src
            .get(start..end.min(line_end))
            .map_or(0, |s| s.chars().count())
            .max(1);
        out.push_str(&pad);
        out.push_str(&"^".repeat(carets));
        out.push(' ');
        out.push_str(&self.message);
        if let Some(h) = &self.hint {
            out.push('\n');
            out.push_str(&pad);
            out.push_str("help: ");
            out.push_str(h);
        }
        out
    }
}
