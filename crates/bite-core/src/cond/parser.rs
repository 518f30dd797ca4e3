//! Recursive-descent parser and static checker. Builds the flat node array
//! of an [`Expr`] directly, children before parents.

use super::lexer::{Lexed, Tok, Token, clip, lex};
use super::node::{ArithOp, CmpOp, Fn1, Fn2, Node, Ty};
use super::{CondError, Expr, MAX_DEPTH, MAX_SOURCE_LEN, Resolver};
use crate::ids::BeliefId;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The functions, for "unknown function" messages.
const FUNCTIONS: [&str; 8] = ["abs", "min", "max", "norm", "dist", "known", "age", "runs"];

/// A parsed sub-expression: its node, static type, span and nesting depth.
#[derive(Clone, Copy, Debug)]
struct Sub {
    node: u32,
    ty: Ty,
    start: usize,
    end: usize,
    depth: u32,
}

struct Parser<'s, 'r> {
    src: &'s str,
    toks: Vec<Token>,
    strs: Vec<String>,
    pos: usize,
    /// Nesting constructs currently open (guards the parser's own recursion).
    nest: u32,
    nodes: Vec<Node>,
    lists: Vec<u32>,
    /// Belief names in order of first appearance; `Belief`, `Known` and `Age`
    /// nodes hold indices into this until the parse succeeds.
    names: Vec<&'s str>,
    name_index: BTreeMap<&'s str, u32>,
    time: bool,
    runs: bool,
    resolver: &'r dyn Resolver,
}

fn error(start: usize, end: usize, message: impl Into<String>) -> CondError {
    CondError {
        span: start..end,
        message: message.into(),
        hint: None,
    }
}

fn hinted(mut e: CondError, hint: impl Into<String>) -> CondError {
    e.hint = Some(hint.into());
    e
}

fn too_deep(start: usize, end: usize) -> CondError {
    hinted(
        error(
            start,
            end,
            format!("expression nests too deeply (limit {MAX_DEPTH})"),
        ),
        "simplify the expression, or move part of it into a belief",
    )
}

/// The largest char boundary of `s` that is `<= i`.
fn floor_boundary(s: &str, i: usize) -> usize {
    let mut i = i.min(s.len());
    while !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

fn as_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Parses and checks `src` (see [`Expr::parse`]).
pub(super) fn parse(src: &str, resolver: &mut dyn Resolver) -> Result<Expr, CondError> {
    if src.len() > MAX_SOURCE_LEN {
        return Err(hinted(
            error(
                floor_boundary(src, MAX_SOURCE_LEN),
                src.len(),
                format!(
                    "expression is too long ({} bytes, limit {MAX_SOURCE_LEN})",
                    src.len()
                ),
            ),
            "split the condition, or move logic into a belief",
        ));
    }
    let Lexed { toks, strs } = lex(src)?;
    let mut p = Parser {
        src,
        toks,
        strs,
        pos: 0,
        nest: 0,
        nodes: Vec::new(),
        lists: Vec::new(),
        names: Vec::new(),
        name_index: BTreeMap::new(),
        time: false,
        runs: false,
        resolver: &*resolver,
    };
    if p.peek().tok == Tok::Eof {
        return Err(error(0, src.len(), "empty expression"));
    }
    let root = p.parse_or()?;
    p.expect_end()?;
    let Parser {
        mut nodes,
        lists,
        names,
        time,
        runs,
        ..
    } = p;
    // Intern only now, so that a failed parse leaves the resolver untouched.
    let ids: Vec<BeliefId> = names.iter().map(|n| resolver.belief(n)).collect();
    for node in &mut nodes {
        if let Node::Belief(id) | Node::Known(id) | Node::Age(id) = node
            && let Some(global) = ids.get(id.index())
        {
            *id = *global;
        }
    }
    fuse(&mut nodes);
    let mut beliefs = ids;
    beliefs.sort_unstable();
    beliefs.dedup();
    Ok(Expr {
        src: src.into(),
        nodes: nodes.into_boxed_slice(),
        lists: lists.into_boxed_slice(),
        root: root.node,
        beliefs: beliefs.into_boxed_slice(),
        time,
        runs,
        ty: root.ty,
    })
}

impl<'s> Parser<'s, '_> {
    // ---- token access -------------------------------------------------

    fn eof(&self) -> Token {
        Token {
            tok: Tok::Eof,
            start: self.src.len(),
            end: self.src.len(),
        }
    }

    fn peek(&self) -> Token {
        self.toks
            .get(self.pos)
            .copied()
            .unwrap_or_else(|| self.eof())
    }

    fn peek2(&self) -> Token {
        self.toks
            .get(self.pos + 1)
            .copied()
            .unwrap_or_else(|| self.eof())
    }

    fn prev(&self) -> Option<Token> {
        self.pos
            .checked_sub(1)
            .and_then(|i| self.toks.get(i).copied())
    }

    fn bump(&mut self) -> Token {
        let t = self.peek();
        if t.tok != Tok::Eof {
            self.pos += 1;
        }
        t
    }

    fn text(&self, t: Token) -> &'s str {
        self.src.get(t.start..t.end).unwrap_or("")
    }

    /// How a token is named in messages.
    fn describe(&self, t: Token) -> String {
        match t.tok {
            Tok::Eof => "end of expression".to_owned(),
            Tok::Str(_) => "a string".to_owned(),
            _ => format!("`{}`", clip(self.text(t))),
        }
    }

    fn col(&self, t: Token) -> usize {
        self.src.get(..t.start).map_or(0, |s| s.chars().count()) + 1
    }

    // ---- building -------------------------------------------------------

    /// Enters a nesting construct opened by `t`.
    fn enter(&mut self, t: Token) -> Result<(), CondError> {
        if self.nest >= MAX_DEPTH {
            return Err(too_deep(t.start, t.end));
        }
        self.nest += 1;
        Ok(())
    }

    fn leave(&mut self) {
        self.nest = self.nest.saturating_sub(1);
    }

    fn push(
        &mut self,
        node: Node,
        ty: Ty,
        start: usize,
        end: usize,
        depth: u32,
    ) -> Result<Sub, CondError> {
        if depth > MAX_DEPTH {
            return Err(too_deep(start, end));
        }
        self.nodes.push(node);
        Ok(Sub {
            node: as_u32(self.nodes.len() - 1),
            ty,
            start,
            end,
            depth,
        })
    }

    fn local_belief(&mut self, name: &'s str) -> BeliefId {
        if let Some(i) = self.name_index.get(name) {
            return BeliefId(*i);
        }
        let i = as_u32(self.names.len());
        self.names.push(name);
        self.name_index.insert(name, i);
        BeliefId(i)
    }

    /// The node of `s` if it is the last one pushed (so it can be folded).
    fn last_const(&self, s: Sub) -> Option<&Node> {
        if s.node as usize + 1 == self.nodes.len() {
            self.nodes.last()
        } else {
            None
        }
    }

    // ---- grammar ----------------------------------------------------------

    fn expect_end(&mut self) -> Result<(), CondError> {
        let t = self.peek();
        match t.tok {
            Tok::Eof => Ok(()),
            Tok::RParen => Err(hinted(
                error(t.start, t.end, "unmatched `)`"),
                "remove it, or add the matching `(`",
            )),
            _ => Err(self.expected_operator(t, "end of expression")),
        }
    }

    /// The error for a token where an operator (or `what`) was expected.
    fn expected_operator(&self, t: Token, what: &str) -> CondError {
        let e = error(
            t.start,
            t.end,
            format!("expected an operator or {what}, found {}", self.describe(t)),
        );
        let word = self.text(t);
        if t.tok == Tok::Ident {
            for kw in ["and", "or", "not", "true", "false"] {
                if word.eq_ignore_ascii_case(kw) {
                    return hinted(e, format!("did you mean `{kw}`? Keywords are lower-case"));
                }
            }
        }
        if starts_operand(t.tok) {
            hinted(e, "join conditions with `&&` or `||`")
        } else {
            e
        }
    }

    fn parse_or(&mut self) -> Result<Sub, CondError> {
        self.parse_chain(true)
    }

    fn parse_and(&mut self) -> Result<Sub, CondError> {
        self.parse_chain(false)
    }

    /// `and_expr ( || and_expr )*` or `not_expr ( && not_expr )*`, as one
    /// n-ary node.
    fn parse_chain(&mut self, or: bool) -> Result<Sub, CondError> {
        let (op, first) = if or {
            (Tok::Or, self.parse_and()?)
        } else {
            (Tok::And, self.parse_not()?)
        };
        if self.peek().tok != op {
            return Ok(first);
        }
        let op_tok = self.peek();
        self.check_bool(first, op_tok)?;
        let mut items = vec![first];
        while self.peek().tok == op {
            let t = self.bump();
            let next = if or {
                self.parse_and()?
            } else {
                self.parse_not()?
            };
            self.check_bool(next, t)?;
            items.push(next);
        }
        let start = self.lists.len();
        self.lists.extend(items.iter().map(|s| s.node));
        let (s, n) = (as_u32(start), as_u32(items.len()));
        let depth = items.iter().map(|s| s.depth).max().unwrap_or(0) + 1;
        let end = items.last().map_or(first.end, |s| s.end);
        let node = if or { Node::Or(s, n) } else { Node::And(s, n) };
        self.push(node, Ty::Bool, first.start, end, depth)
    }

    fn check_bool(&self, s: Sub, op: Token) -> Result<(), CondError> {
        if matches!(s.ty, Ty::Bool | Ty::Any) {
            return Ok(());
        }
        let e = error(
            s.start,
            s.end,
            format!(
                "`{}` needs a boolean operand, found {}",
                self.text(op),
                s.ty.describe()
            ),
        );
        Err(match s.ty {
            Ty::Num => hinted(e, "a number is not a condition; compare it, e.g. `x > 0`"),
            Ty::Text => hinted(
                e,
                "text is not a condition; compare it, e.g. `x == \"red\"`",
            ),
            _ => e,
        })
    }

    fn parse_not(&mut self) -> Result<Sub, CondError> {
        if self.peek().tok != Tok::Not {
            return self.parse_cmp();
        }
        let op = self.bump();
        self.enter(op)?;
        let inner = self.parse_not()?;
        self.leave();
        self.check_bool(inner, op)?;
        if let Some(Node::Bool(b)) = self.last_const(inner) {
            let folded = Node::Bool(!*b);
            self.nodes.pop();
            return self.push(folded, Ty::Bool, op.start, inner.end, inner.depth);
        }
        self.push(
            Node::Not(inner.node),
            Ty::Bool,
            op.start,
            inner.end,
            inner.depth + 1,
        )
    }

    fn parse_cmp(&mut self) -> Result<Sub, CondError> {
        let lhs = self.parse_add()?;
        let Some(op) = cmp_op(self.peek().tok) else {
            return Ok(lhs);
        };
        let op_tok = self.bump();
        let rhs = self.parse_add()?;
        self.check_cmp(op, op_tok, lhs, rhs)?;
        let depth = lhs.depth.max(rhs.depth) + 1;
        let node = if lhs.ty == Ty::Num && rhs.ty == Ty::Num {
            Node::CmpNums(op, lhs.node, rhs.node)
        } else {
            Node::Cmp(op, lhs.node, rhs.node)
        };
        let sub = self.push(node, Ty::Bool, lhs.start, rhs.end, depth)?;
        let t = self.peek();
        if cmp_op(t.tok).is_some() {
            return Err(hinted(
                error(t.start, t.end, "comparison operators cannot be chained"),
                "split it with `&&`, e.g. `a < b && b < c`",
            ));
        }
        Ok(sub)
    }

    fn check_cmp(&self, op: CmpOp, op_tok: Token, l: Sub, r: Sub) -> Result<(), CondError> {
        let sym = self.text(op_tok);
        if !matches!(op, CmpOp::Eq | CmpOp::Ne) {
            for s in [l, r] {
                if matches!(s.ty, Ty::Bool | Ty::Vec) {
                    let e = error(
                        s.start,
                        s.end,
                        format!("`{sym}` cannot order {} values", s.ty.describe()),
                    );
                    let hint = if s.ty == Ty::Vec {
                        "ordering works on numbers and text; compare lengths with `norm(v)`"
                    } else {
                        "ordering works on numbers and text"
                    };
                    return Err(hinted(e, hint));
                }
            }
        }
        if l.ty != Ty::Any && r.ty != Ty::Any && l.ty != r.ty {
            return Err(hinted(
                error(
                    l.start,
                    r.end,
                    format!(
                        "cannot compare {} with {}",
                        l.ty.describe(),
                        r.ty.describe()
                    ),
                ),
                "the two sides have different types",
            ));
        }
        Ok(())
    }

    fn parse_add(&mut self) -> Result<Sub, CondError> {
        let mut lhs = self.parse_mul()?;
        loop {
            let op = match self.peek().tok {
                Tok::Plus => ArithOp::Add,
                Tok::Minus => ArithOp::Sub,
                _ => return Ok(lhs),
            };
            let t = self.bump();
            let rhs = self.parse_mul()?;
            lhs = self.arith(op, t, lhs, rhs)?;
        }
    }

    fn parse_mul(&mut self) -> Result<Sub, CondError> {
        let mut lhs = self.parse_unary()?;
        loop {
            let op = match self.peek().tok {
                Tok::Star => ArithOp::Mul,
                Tok::Slash => ArithOp::Div,
                _ => return Ok(lhs),
            };
            let t = self.bump();
            let rhs = self.parse_unary()?;
            lhs = self.arith(op, t, lhs, rhs)?;
        }
    }

    /// Type-checks and builds a binary arithmetic node.
    fn arith(&mut self, op: ArithOp, t: Token, l: Sub, r: Sub) -> Result<Sub, CondError> {
        let sym = self.text(t);
        for s in [l, r] {
            if matches!(s.ty, Ty::Bool | Ty::Text) {
                return Err(hinted(
                    error(
                        s.start,
                        s.end,
                        format!("cannot apply `{sym}` to {}", s.ty.describe()),
                    ),
                    "arithmetic works on numbers and vectors",
                ));
            }
        }
        use Ty::{Any, Num, Vec};
        let mismatch = |msg: &str, hint: &str| {
            Err(hinted(
                error(l.start, r.end, msg.to_owned()),
                hint.to_owned(),
            ))
        };
        let ty = match op {
            ArithOp::Add | ArithOp::Sub => match (l.ty, r.ty) {
                (Num, Num) | (Num, Any) | (Any, Num) => Num,
                (Vec, Vec) | (Vec, Any) | (Any, Vec) => Vec,
                (Num, Vec) | (Vec, Num) => {
                    return mismatch(
                        &format!(
                            "cannot apply `{sym}` to {} and {}",
                            l.ty.describe(),
                            r.ty.describe()
                        ),
                        "add numbers to numbers and vectors to vectors",
                    );
                }
                _ => Any,
            },
            ArithOp::Mul => match (l.ty, r.ty) {
                (Num, Num) => Num,
                (Vec, Vec) => {
                    return mismatch(
                        "cannot multiply two vectors",
                        "scale a vector by a number; use `norm` or `dist` for lengths",
                    );
                }
                (Vec, _) | (_, Vec) => Vec,
                _ => Any,
            },
            ArithOp::Div => match (l.ty, r.ty) {
                (_, Vec) => {
                    return Err(hinted(
                        error(r.start, r.end, "cannot divide by a vector"),
                        "divide a vector by a number",
                    ));
                }
                (Num, _) => Num,
                (Vec, _) => Vec,
                _ => Any,
            },
        };
        let depth = l.depth.max(r.depth) + 1;
        self.push(Node::Arith(op, l.node, r.node), ty, l.start, r.end, depth)
    }

    fn parse_unary(&mut self) -> Result<Sub, CondError> {
        if self.peek().tok != Tok::Minus {
            return self.parse_postfix();
        }
        let op = self.bump();
        self.enter(op)?;
        let inner = self.parse_unary()?;
        self.leave();
        if matches!(inner.ty, Ty::Bool | Ty::Text) {
            return Err(hinted(
                error(
                    inner.start,
                    inner.end,
                    format!("cannot negate {}", inner.ty.describe()),
                ),
                "`-` works on numbers and vectors; use `!` or `not` to negate a condition",
            ));
        }
        let folded = match self.last_const(inner) {
            Some(Node::Num(n)) => Some(Node::Num(-*n)),
            Some(Node::Vec2([x, y])) => Some(Node::Vec2([-*x, -*y])),
            _ => None,
        };
        if let Some(node) = folded {
            self.nodes.pop();
            return self.push(node, inner.ty, op.start, inner.end, inner.depth);
        }
        self.push(
            Node::Neg(inner.node),
            inner.ty,
            op.start,
            inner.end,
            inner.depth + 1,
        )
    }

    fn parse_postfix(&mut self) -> Result<Sub, CondError> {
        let mut base = self.parse_primary()?;
        while self.peek().tok == Tok::Dot {
            self.bump();
            let c = self.peek();
            let which = match (c.tok, self.text(c)) {
                (Tok::Ident, "x") => 0u8,
                (Tok::Ident, "y") => 1u8,
                _ => {
                    return Err(hinted(
                        error(
                            c.start,
                            c.end,
                            format!("expected `x` or `y` after `.`, found {}", self.describe(c)),
                        ),
                        "vectors have the components `.x` and `.y`",
                    ));
                }
            };
            self.bump();
            if !matches!(base.ty, Ty::Vec | Ty::Any) {
                return Err(hinted(
                    error(
                        base.start,
                        base.end,
                        format!(
                            "`.{}` needs a vector, found {}",
                            self.text(c),
                            base.ty.describe()
                        ),
                    ),
                    "only vectors have components",
                ));
            }
            if let Some(Node::Vec2(v)) = self.last_const(base) {
                let n = if which == 0 { v[0] } else { v[1] };
                self.nodes.pop();
                base = self.push(Node::Num(n), Ty::Num, base.start, c.end, base.depth)?;
            } else {
                base = self.push(
                    Node::Comp(base.node, which),
                    Ty::Num,
                    base.start,
                    c.end,
                    base.depth + 1,
                )?;
            }
        }
        Ok(base)
    }

    fn parse_primary(&mut self) -> Result<Sub, CondError> {
        let t = self.peek();
        match t.tok {
            Tok::Num(n) => {
                self.bump();
                self.push(Node::Num(n), Ty::Num, t.start, t.end, 0)
            }
            Tok::Str(i) => {
                self.bump();
                let s: Arc<str> = Arc::from(self.strs.get(i as usize).map_or("", String::as_str));
                self.push(Node::Text(s), Ty::Text, t.start, t.end, 0)
            }
            Tok::True | Tok::False => {
                self.bump();
                self.push(Node::Bool(t.tok == Tok::True), Ty::Bool, t.start, t.end, 0)
            }
            Tok::LParen => {
                self.bump();
                self.enter(t)?;
                let inner = self.parse_or()?;
                let close = self.peek();
                if close.tok != Tok::RParen {
                    return Err(self.unclosed(t, close, ")"));
                }
                self.bump();
                self.leave();
                let depth = inner.depth + 1;
                if depth > MAX_DEPTH {
                    return Err(too_deep(t.start, close.end));
                }
                Ok(Sub {
                    start: t.start,
                    end: close.end,
                    depth,
                    ..inner
                })
            }
            Tok::LBracket => self.parse_vector(t),
            Tok::Ident => {
                let name = self.text(t);
                if self.peek2().tok == Tok::LParen {
                    return self.parse_call(t, name);
                }
                self.bump();
                match name {
                    "elapsed" => {
                        self.time = true;
                        self.push(Node::Elapsed, Ty::Num, t.start, t.end, 0)
                    }
                    "runs" => {
                        self.runs = true;
                        self.push(Node::Runs(None), Ty::Num, t.start, t.end, 0)
                    }
                    _ => {
                        let id = self.local_belief(name);
                        self.push(Node::Belief(id), Ty::Any, t.start, t.end, 0)
                    }
                }
            }
            _ => Err(self.missing_operand(t)),
        }
    }

    /// The error for a token that cannot start an operand.
    fn missing_operand(&self, t: Token) -> CondError {
        let found = self.describe(t);
        let message = match self.prev() {
            Some(p) if !matches!(p.tok, Tok::LParen | Tok::LBracket | Tok::Comma) => {
                format!(
                    "expected an operand after `{}`, found {found}",
                    self.text(p)
                )
            }
            _ => format!("expected an expression, found {found}"),
        };
        let e = error(t.start, t.end, message);
        match t.tok {
            Tok::Not => {
                let op = self.text(t);
                let example = if op == "!" { "(!x)" } else { "(not x)" };
                hinted(
                    e,
                    format!(
                        "`{op}` binds more loosely than comparisons and arithmetic; wrap it in parentheses, e.g. `{example}`"
                    ),
                )
            }
            Tok::RParen if self.prev().is_some_and(|p| p.tok == Tok::LParen) => {
                hinted(e, "empty parentheses")
            }
            _ => e,
        }
    }

    /// The error for a missing closing bracket.
    fn unclosed(&self, open: Token, found: Token, close: &str) -> CondError {
        let e = error(
            found.start,
            found.end,
            format!(
                "expected `{close}` to close the `{}` at col {}, found {}",
                self.text(open),
                self.col(open),
                self.describe(found)
            ),
        );
        if starts_operand(found.tok) {
            hinted(e, "join conditions with `&&` or `||`")
        } else {
            e
        }
    }

    fn parse_vector(&mut self, open: Token) -> Result<Sub, CondError> {
        self.bump();
        self.enter(open)?;
        let a = self.parse_or()?;
        let sep = self.peek();
        match sep.tok {
            Tok::Comma => {}
            Tok::RBracket => {
                return Err(hinted(
                    error(open.start, sep.end, "a vector needs two components"),
                    "write it as `[x, y]`",
                ));
            }
            _ => {
                return Err(error(
                    sep.start,
                    sep.end,
                    format!(
                        "expected `,` between vector components, found {}",
                        self.describe(sep)
                    ),
                ));
            }
        }
        self.bump();
        let b = self.parse_or()?;
        let close = self.peek();
        match close.tok {
            Tok::RBracket => {}
            Tok::Comma => {
                return Err(hinted(
                    error(
                        close.start,
                        close.end,
                        "a vector has exactly two components",
                    ),
                    "write it as `[x, y]`",
                ));
            }
            _ => return Err(self.unclosed(open, close, "]")),
        }
        self.bump();
        self.leave();
        for s in [a, b] {
            if !matches!(s.ty, Ty::Num | Ty::Any) {
                return Err(error(
                    s.start,
                    s.end,
                    format!(
                        "a vector component must be a number, found {}",
                        s.ty.describe()
                    ),
                ));
            }
        }
        let consts = match (self.nodes.get(a.node as usize), self.last_const(b)) {
            (Some(Node::Num(x)), Some(Node::Num(y))) if a.node + 1 == b.node => Some([*x, *y]),
            _ => None,
        };
        if let Some(v) = consts {
            self.nodes.truncate(a.node as usize);
            return self.push(Node::Vec2(v), Ty::Vec, open.start, close.end, 0);
        }
        let depth = a.depth.max(b.depth) + 1;
        self.push(
            Node::MakeVec(a.node, b.node),
            Ty::Vec,
            open.start,
            close.end,
            depth,
        )
    }

    /// A call `name(...)`; the current token is `name`, the next `(`.
    fn parse_call(&mut self, t: Token, name: &'s str) -> Result<Sub, CondError> {
        match name {
            "known" | "age" | "runs" | "abs" | "norm" | "min" | "max" | "dist" => {}
            "elapsed" => {
                return Err(hinted(
                    error(t.start, t.end, "`elapsed` is not a function"),
                    "write `elapsed` without parentheses",
                ));
            }
            _ => {
                let mut hint = format!("the functions are {}", FUNCTIONS.join(", "));
                if let Some(s) = suggest(name, FUNCTIONS.iter().copied()) {
                    hint = format!("did you mean `{s}`? {hint}");
                }
                return Err(hinted(
                    error(t.start, t.end, format!("unknown function `{}`", clip(name))),
                    hint,
                ));
            }
        }
        self.bump();
        let open = self.bump();
        self.enter(open)?;
        let sub = match name {
            "known" | "age" => self.call_belief(t, name)?,
            "runs" => self.call_runs(t)?,
            _ => self.call_numeric(t, name)?,
        };
        self.leave();
        Ok(sub)
    }

    /// Expects the `)` that ends the call of `name`.
    fn close_call(&mut self, name: &str, what: &str) -> Result<Token, CondError> {
        let c = self.peek();
        if c.tok != Tok::RParen {
            return Err(hinted(
                error(
                    c.start,
                    c.end,
                    format!(
                        "expected `)` after the argument of `{name}`, found {}",
                        self.describe(c)
                    ),
                ),
                format!("`{name}` takes {what}"),
            ));
        }
        self.bump();
        Ok(c)
    }

    /// `known(belief)` or `age(belief)`.
    fn call_belief(&mut self, t: Token, name: &'s str) -> Result<Sub, CondError> {
        let arg = self.peek();
        let word = self.text(arg);
        if arg.tok != Tok::Ident || matches!(word, "elapsed" | "runs") {
            let found = if arg.tok == Tok::Ident {
                format!("the builtin `{word}`")
            } else {
                self.describe(arg)
            };
            return Err(hinted(
                error(
                    arg.start,
                    arg.end,
                    format!("`{name}` needs a belief name, found {found}"),
                ),
                format!("write e.g. `{name}(target_pos)`"),
            ));
        }
        self.bump();
        let close = self.close_call(name, "exactly one belief name")?;
        let id = self.local_belief(word);
        if name == "age" {
            self.time = true;
            self.push(Node::Age(id), Ty::Num, t.start, close.end, 1)
        } else {
            self.push(Node::Known(id), Ty::Bool, t.start, close.end, 1)
        }
    }

    /// `runs()` or `runs(behavior)`.
    fn call_runs(&mut self, t: Token) -> Result<Sub, CondError> {
        self.runs = true;
        let arg = self.peek();
        let target = match arg.tok {
            Tok::RParen => None,
            Tok::Ident => {
                let word = self.text(arg);
                let Some(b) = self.resolver.behavior(word) else {
                    let e = error(
                        arg.start,
                        arg.end,
                        format!("unknown behavior `{}`", clip(word)),
                    );
                    let names = self.resolver.behavior_names();
                    return Err(match suggest(word, names.iter().copied()) {
                        Some(s) => hinted(e, format!("did you mean `{s}`?")),
                        None => e,
                    });
                };
                self.bump();
                Some(b)
            }
            _ => {
                return Err(hinted(
                    error(
                        arg.start,
                        arg.end,
                        format!("`runs` needs a behavior name, found {}", self.describe(arg)),
                    ),
                    "write `runs()` for this behavior or `runs(name)` for another",
                ));
            }
        };
        let close = self.close_call("runs", "one behavior name, or nothing")?;
        self.push(Node::Runs(target), Ty::Num, t.start, close.end, 1)
    }

    /// `abs(x)`, `norm(v)`, `min(a, b)`, `max(a, b)`, `dist(a, b)`.
    fn call_numeric(&mut self, t: Token, name: &'s str) -> Result<Sub, CondError> {
        let mut args: Vec<Sub> = Vec::new();
        if self.peek().tok != Tok::RParen {
            loop {
                args.push(self.parse_or()?);
                if self.peek().tok != Tok::Comma {
                    break;
                }
                self.bump();
            }
        }
        let close = self.peek();
        if close.tok != Tok::RParen {
            return Err(error(
                close.start,
                close.end,
                format!(
                    "expected `,` or `)` in the arguments of `{name}`, found {}",
                    self.describe(close)
                ),
            ));
        }
        self.bump();
        let (arity, want) = match name {
            "abs" => (1, Ty::Num),
            "norm" => (1, Ty::Vec),
            "dist" => (2, Ty::Vec),
            _ => (2, Ty::Num),
        };
        if args.len() != arity {
            let plural = if arity == 1 { "argument" } else { "arguments" };
            return Err(error(
                t.start,
                close.end,
                format!("`{name}` takes {arity} {plural}, found {}", args.len()),
            ));
        }
        for s in &args {
            if s.ty != want && s.ty != Ty::Any {
                let e = error(
                    s.start,
                    s.end,
                    format!(
                        "`{name}` needs a {}, found {}",
                        want.describe(),
                        s.ty.describe()
                    ),
                );
                return Err(match (name, s.ty) {
                    ("abs", Ty::Vec) => hinted(e, "use `norm(v)` for the length of a vector"),
                    _ => e,
                });
            }
        }
        let depth = args.iter().map(|s| s.depth).max().unwrap_or(0) + 1;
        let node = match (name, args.as_slice()) {
            ("abs", [a]) => Node::Call1(Fn1::Abs, a.node),
            ("norm", [a]) => Node::Call1(Fn1::Norm, a.node),
            ("min", [a, b]) => Node::Call2(Fn2::Min, a.node, b.node),
            ("max", [a, b]) => Node::Call2(Fn2::Max, a.node, b.node),
            (_, [a, b]) => Node::Call2(Fn2::Dist, a.node, b.node),
            _ => return Err(error(t.start, close.end, "malformed call")),
        };
        self.push(node, Ty::Num, t.start, close.end, depth)
    }
}

/// Replaces comparisons with a number constant by fused nodes, the most
/// common shape of a condition (`distance_walked >= 6`).
fn fuse(nodes: &mut [Node]) {
    for i in 0..nodes.len() {
        let Some(Node::Cmp(op, a, b) | Node::CmpNums(op, a, b)) = nodes.get(i) else {
            continue;
        };
        let (op, a, b) = (*op, *a, *b);
        let (op, other, k) = match (nodes.get(a as usize), nodes.get(b as usize)) {
            (_, Some(Node::Num(k))) => (op, a, *k),
            (Some(Node::Num(k)), _) => (op.flip(), b, *k),
            _ => continue,
        };
        let fused = match nodes.get(other as usize) {
            Some(Node::Belief(id)) => Node::CmpBelief(op, *id, k),
            _ => Node::CmpNum(op, other, k),
        };
        if let Some(slot) = nodes.get_mut(i) {
            *slot = fused;
        }
    }
}

fn cmp_op(t: Tok) -> Option<CmpOp> {
    Some(match t {
        Tok::EqEq => CmpOp::Eq,
        Tok::Ne => CmpOp::Ne,
        Tok::Lt => CmpOp::Lt,
        Tok::Le => CmpOp::Le,
        Tok::Gt => CmpOp::Gt,
        Tok::Ge => CmpOp::Ge,
        _ => return None,
    })
}

/// True if `t` can begin an operand (used for "missing operator" hints).
fn starts_operand(t: Tok) -> bool {
    matches!(
        t,
        Tok::Num(_)
            | Tok::Str(_)
            | Tok::Ident
            | Tok::True
            | Tok::False
            | Tok::Not
            | Tok::LParen
            | Tok::LBracket
    )
}

/// The candidate closest to `word` by edit distance, if it is close enough.
pub(super) fn suggest<'a>(
    word: &str,
    candidates: impl Iterator<Item = &'a str>,
) -> Option<&'a str> {
    let limit = (word.chars().count() / 3).clamp(1, 3);
    let mut best: Option<(usize, &'a str)> = None;
    for c in candidates {
        let d = levenshtein(word, c);
        if d <= limit && best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    best.map(|(_, c)| c)
}

/// Edit distance between two short strings (by chars).
fn levenshtein(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diag = row.first().copied().unwrap_or(0);
        if let Some(first) = row.first_mut() {
            *first = i + 1;
        }
        for (j, cb) in b.iter().enumerate() {
            let above = row.get(j + 1).copied().unwrap_or(0);
            let left = row.get(j).copied().unwrap_or(0);
            let v = (diag + usize::from(ca != *cb)).min(above + 1).min(left + 1);
            diag = above;
            if let Some(cell) = row.get_mut(j + 1) {
                *cell = v;
            }
        }
    }
    row.last().copied().unwrap_or(0)
}
