//! Templates of the command library: text with `{expression}` placeholders
//! that the code generator fills in for each command, and `if:` guards.
//!
//! A placeholder holds a small arithmetic expression over the command's
//! variables: `{goal}`, `{object}_pos`, `{y0 + (y1 - y0) * i / n}`.
//! Values are numbers, text (names, colours, choices) or points `[x, y]`;
//! `+ - * /` and unary `-` work on numbers. In a JSON value (a schema
//! parameter), a string that is exactly one placeholder becomes the value
//! itself (`goal: "{goal}"` becomes `goal: [6.2, 2]`); anywhere else the
//! value is written out as text.

use std::fmt::Write as _;
use thiserror::Error;

/// A template value.
#[derive(Clone, Debug, PartialEq)]
pub enum Val {
    /// A number.
    Num(f64),
    /// Text: a name, a colour, a choice.
    Text(String),
    /// A point `[x, y]` (metres, absolute: the origin already added).
    Point([f64; 2]),
}

impl Val {
    /// The value as text (numbers rounded to 1e-9 and without a trailing
    /// `.0`, points as `[x, y]`).
    pub fn to_text(&self) -> String {
        match self {
            Val::Text(t) => t.clone(),
            _ => {
                let mut s = String::new();
                self.write_text(&mut s);
                s
            }
        }
    }

    /// [`Val::to_text`] written at the end of `out`.
    pub fn write_text(&self, out: &mut String) {
        match self {
            Val::Num(x) => {
                let _ = write!(out, "{}", round(*x));
            }
            Val::Text(t) => out.push_str(t),
            Val::Point([x, y]) => {
                let _ = write!(out, "[{}, {}]", round(*x), round(*y));
            }
        }
    }
}

/// Round away float noise (`0.1 + 0.2`), and `-0` to `0`.
pub fn round(x: f64) -> f64 {
    let r = (x * 1e9).round() / 1e9;
    if r == 0.0 { 0.0 } else { r }
}

/// A number as text: `2`, `6.2`, `-0.5`.
pub fn fmt_num(x: f64) -> String {
    format!("{}", round(x))
}

/// A number as JSON: an integer when it is one.
pub fn num_json(x: f64) -> serde_json::Value {
    let r = round(x);
    if r.fract() == 0.0 && r.abs() < 9.0e15 {
        // Exact: |r| < 2^53.
        #[allow(clippy::cast_possible_truncation)]
        return serde_json::Value::from(r as i64);
    }
    serde_json::Number::from_f64(r).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

/// Where the variables of a template come from.
pub trait Env {
    /// The value of `name`; `None` when it is unknown (an optional
    /// parameter left empty).
    fn get(&mut self, name: &str) -> Option<Val>;

    /// The same, borrowed where the environment holds it: guards and text
    /// read values without copying them.
    fn get_cow(&mut self, name: &str) -> Option<std::borrow::Cow<'_, Val>> {
        self.get(name).map(std::borrow::Cow::Owned)
    }

    /// `name`'s value as text ([`Val::to_text`]) written at the end of
    /// `out`; `None` (and nothing written) when it is unknown.
    fn write(&mut self, name: &str, out: &mut String) -> Option<()> {
        self.get_cow(name)?.write_text(out);
        Some(())
    }
}

/// Why a template could not be filled in.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum EvalError {
    /// A variable has no value for this command.
    #[error("`{0}` is unknown for this command")]
    Unknown(String),
    /// An operator got a value it cannot use.
    #[error("`{op}` needs numbers, but `{var}` is {what}")]
    Type {
        /// The operator.
        op: char,
        /// The offending variable or value.
        var: String,
        /// What it is.
        what: &'static str,
    },
    /// A function got a value it cannot use.
    #[error("`{func}` needs numbers, but `{var}` is {what}")]
    Arg {
        /// The function.
        func: &'static str,
        /// The offending variable or value.
        var: String,
        /// What it is.
        what: &'static str,
    },
    /// Division by zero or overflow.
    #[error("the expression has no finite value")]
    NotFinite,
}

/// A syntax error in a template, at a byte offset of the template text.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{message}")]
pub struct SyntaxError {
    /// Byte offset in the template text.
    pub at: usize,
    /// What is wrong.
    pub message: String,
}

/// An arithmetic operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
}

impl Op {
    fn char(self) -> char {
        match self {
            Op::Add => '+',
            Op::Sub => '-',
            Op::Mul => '*',
            Op::Div => '/',
        }
    }
}

/// An expression inside `{}`.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A number.
    Num(f64),
    /// A variable, with its byte offset in the template text.
    Var(String, usize),
    /// `-e`
    Neg(Box<Expr>),
    /// `a op b`
    Bin(Op, Box<Expr>, Box<Expr>),
    /// `min(a, b)`, `max(a, b)`, `sqrt(a)`.
    Call(Func, Vec<Expr>),
}

/// A function of the template language.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Func {
    /// The smaller of two numbers.
    Min,
    /// The larger of two numbers.
    Max,
    /// The square root of a number (not negative).
    Sqrt,
}

impl Func {
    /// Its name in templates.
    pub fn name(self) -> &'static str {
        match self {
            Func::Min => "min",
            Func::Max => "max",
            Func::Sqrt => "sqrt",
        }
    }

    /// The function a name calls, and how many arguments it takes.
    fn of(name: &str) -> Option<(Func, usize)> {
        match name {
            "min" => Some((Func::Min, 2)),
            "max" => Some((Func::Max, 2)),
            "sqrt" => Some((Func::Sqrt, 1)),
            _ => None,
        }
    }
}

impl Expr {
    /// Every variable the expression reads, with its offset.
    pub fn vars<'a>(&'a self, out: &mut Vec<(&'a str, usize)>) {
        match self {
            Expr::Num(_) => {}
            Expr::Var(v, at) => out.push((v, *at)),
            Expr::Neg(e) => e.vars(out),
            Expr::Bin(_, a, b) => {
                a.vars(out);
                b.vars(out);
            }
            Expr::Call(_, args) => args.iter().for_each(|a| a.vars(out)),
        }
    }

    /// Evaluate.
    pub fn eval(&self, env: &mut dyn Env) -> Result<Val, EvalError> {
        match self {
            Expr::Num(x) => Ok(Val::Num(*x)),
            Expr::Var(v, _) => env.get(v).ok_or_else(|| EvalError::Unknown(v.clone())),
            Expr::Neg(e) => {
                let x = num(&e.eval(env)?, '-', e)?;
                Ok(Val::Num(-x))
            }
            Expr::Bin(op, a, b) => {
                let x = num(&a.eval(env)?, op.char(), a)?;
                let y = num(&b.eval(env)?, op.char(), b)?;
                finite(match op {
                    Op::Add => x + y,
                    Op::Sub => x - y,
                    Op::Mul => x * y,
                    Op::Div => x / y,
                })
            }
            Expr::Call(f, args) => {
                let mut x = [0.0; 2];
                for (slot, a) in x.iter_mut().zip(args) {
                    *slot = num(&a.eval(env)?, '(', a).map_err(|e| match e {
                        EvalError::Type { var, what, .. } => EvalError::Arg {
                            func: f.name(),
                            var,
                            what,
                        },
                        e => e,
                    })?;
                }
                finite(match f {
                    Func::Min => x[0].min(x[1]),
                    Func::Max => x[0].max(x[1]),
                    Func::Sqrt => x[0].sqrt(),
                })
            }
        }
    }
}

/// A result, if it is a finite number.
fn finite(r: f64) -> Result<Val, EvalError> {
    if r.is_finite() {
        Ok(Val::Num(r))
    } else {
        Err(EvalError::NotFinite)
    }
}

fn num(v: &Val, op: char, e: &Expr) -> Result<f64, EvalError> {
    let what = match v {
        Val::Num(x) => return Ok(*x),
        Val::Text(_) => "text",
        Val::Point(_) => "a point",
    };
    let var = match e {
        Expr::Var(n, _) => n.clone(),
        _ => v.to_text(),
    };
    Err(EvalError::Type { op, var, what })
}

/// One piece of a template.
#[derive(Clone, Debug, PartialEq)]
pub enum Part {
    /// Literal text.
    Lit(String),
    /// A placeholder.
    Expr(Expr),
}

/// A parsed template.
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    /// Its pieces, in order.
    pub parts: Vec<Part>,
}

impl Template {
    /// Parse `text`. `{{` and `}}` stand for literal braces.
    pub fn parse(text: &str) -> Result<Template, SyntaxError> {
        let mut parts = Vec::new();
        let mut lit = String::new();
        let b = text.as_bytes();
        let mut i = 0;
        while i < b.len() {
            match b[i] {
                b'{' if b.get(i + 1) == Some(&b'{') => {
                    lit.push('{');
                    i += 2;
                }
                b'}' if b.get(i + 1) == Some(&b'}') => {
                    lit.push('}');
                    i += 2;
                }
                b'{' => {
                    let close = text[i..].find('}').ok_or_else(|| SyntaxError {
                        at: i,
                        message: "`{` without a closing `}`".into(),
                    })?;
                    let inner = &text[i + 1..i + close];
                    let expr = ExprParser::new(inner, i + 1).parse()?;
                    if !lit.is_empty() {
                        parts.push(Part::Lit(std::mem::take(&mut lit)));
                    }
                    parts.push(Part::Expr(expr));
                    i += close + 1;
                }
                b'}' => {
                    return Err(SyntaxError {
                        at: i,
                        message: "`}` without an opening `{` (write `}}` for a brace)".into(),
                    });
                }
                _ => {
                    let c = text[i..].chars().next().unwrap_or(' ');
                    lit.push(c);
                    i += c.len_utf8();
                }
            }
        }
        if !lit.is_empty() {
            parts.push(Part::Lit(lit));
        }
        Ok(Template { parts })
    }

    /// The expression, when the template is exactly one placeholder.
    pub fn whole(&self) -> Option<&Expr> {
        match self.parts.as_slice() {
            [Part::Expr(e)] => Some(e),
            _ => None,
        }
    }

    /// Every variable the template reads, with its byte offset.
    pub fn vars(&self) -> Vec<(&str, usize)> {
        let mut out = Vec::new();
        for p in &self.parts {
            if let Part::Expr(e) = p {
                e.vars(&mut out);
            }
        }
        out
    }

    /// Fill in the placeholders, as text.
    pub fn render(&self, env: &mut dyn Env) -> Result<String, EvalError> {
        // Sized once for the usual case (a name or a number per
        // placeholder).
        let size = (self.parts.iter())
            .map(|p| match p {
                Part::Lit(l) => l.len(),
                Part::Expr(_) => 16,
            })
            .sum();
        let mut s = String::with_capacity(size);
        for p in &self.parts {
            match p {
                Part::Lit(l) => s.push_str(l),
                Part::Expr(Expr::Var(v, _)) => {
                    env.write(v, &mut s)
                        .ok_or_else(|| EvalError::Unknown(v.clone()))?;
                }
                Part::Expr(e) => e.eval(env)?.write_text(&mut s),
            }
        }
        Ok(s)
    }

    /// Evaluate a template that must be a single placeholder, or render it
    /// as text otherwise.
    pub fn value(&self, env: &mut dyn Env) -> Result<Val, EvalError> {
        match self.whole() {
            Some(e) => e.eval(env),
            None => self.render(env).map(Val::Text),
        }
    }
}

struct ExprParser<'a> {
    s: &'a [u8],
    text: &'a str,
    pos: usize,
    /// Offset of `text` in the whole template.
    base: usize,
    depth: usize,
}

impl<'a> ExprParser<'a> {
    fn new(text: &'a str, base: usize) -> Self {
        ExprParser {
            s: text.as_bytes(),
            text,
            pos: 0,
            base,
            depth: 0,
        }
    }

    fn err(&self, message: impl Into<String>) -> SyntaxError {
        SyntaxError {
            at: self.base + self.pos,
            message: message.into(),
        }
    }

    fn ws(&mut self) {
        while self
            .s
            .get(self.pos)
            .is_some_and(|b| *b == b' ' || *b == b'\t')
        {
            self.pos += 1;
        }
    }

    fn parse(mut self) -> Result<Expr, SyntaxError> {
        let e = self.sum()?;
        self.ws();
        if self.pos < self.s.len() {
            return Err(self.err(format!(
                "unexpected `{}` in a placeholder",
                &self.text[self.pos..]
            )));
        }
        Ok(e)
    }

    fn sum(&mut self) -> Result<Expr, SyntaxError> {
        let mut a = self.product()?;
        loop {
            self.ws();
            let op = match self.s.get(self.pos) {
                Some(b'+') => Op::Add,
                Some(b'-') => Op::Sub,
                _ => return Ok(a),
            };
            self.pos += 1;
            let b = self.product()?;
            a = Expr::Bin(op, Box::new(a), Box::new(b));
        }
    }

    fn product(&mut self) -> Result<Expr, SyntaxError> {
        let mut a = self.unary()?;
        loop {
            self.ws();
            let op = match self.s.get(self.pos) {
                Some(b'*') => Op::Mul,
                Some(b'/') => Op::Div,
                _ => return Ok(a),
            };
            self.pos += 1;
            let b = self.unary()?;
            a = Expr::Bin(op, Box::new(a), Box::new(b));
        }
    }

    fn unary(&mut self) -> Result<Expr, SyntaxError> {
        self.ws();
        self.depth += 1;
        if self.depth > 32 {
            return Err(self.err("the placeholder nests too deeply"));
        }
        let r = if self.s.get(self.pos) == Some(&b'-') {
            self.pos += 1;
            self.unary().map(|e| Expr::Neg(Box::new(e)))
        } else {
            self.atom()
        };
        self.depth -= 1;
        r
    }

    fn atom(&mut self) -> Result<Expr, SyntaxError> {
        self.ws();
        let start = self.pos;
        match self.s.get(self.pos) {
            Some(b'(') => {
                self.pos += 1;
                let e = self.sum()?;
                self.ws();
                if self.s.get(self.pos) != Some(&b')') {
                    return Err(self.err("expected `)`"));
                }
                self.pos += 1;
                Ok(e)
            }
            Some(b) if b.is_ascii_digit() || *b == b'.' => {
                while self
                    .s
                    .get(self.pos)
                    .is_some_and(|b| b.is_ascii_digit() || *b == b'.')
                {
                    self.pos += 1;
                }
                self.text[start..self.pos]
                    .parse::<f64>()
                    .map(Expr::Num)
                    .map_err(|_| SyntaxError {
                        at: self.base + start,
                        message: format!("`{}` is not a number", &self.text[start..self.pos]),
                    })
            }
            Some(b) if b.is_ascii_alphabetic() || *b == b'_' => {
                while self
                    .s
                    .get(self.pos)
                    .is_some_and(|b| b.is_ascii_alphanumeric() || *b == b'_')
                {
                    self.pos += 1;
                }
                let name = &self.text[start..self.pos];
                let end = self.pos;
                self.ws();
                if self.s.get(self.pos) != Some(&b'(') {
                    self.pos = end;
                    return Ok(Expr::Var(name.to_string(), self.base + start));
                }
                let Some((f, arity)) = Func::of(name) else {
                    return Err(SyntaxError {
                        at: self.base + start,
                        message: format!(
                            "`{name}` is not a function of templates (min, max, sqrt)"
                        ),
                    });
                };
                self.pos += 1;
                let mut args = Vec::new();
                loop {
                    args.push(self.sum()?);
                    self.ws();
                    match self.s.get(self.pos) {
                        Some(b',') => self.pos += 1,
                        Some(b')') => {
                            self.pos += 1;
                            break;
                        }
                        _ => return Err(self.err("expected `,` or `)`")),
                    }
                }
                if args.len() != arity {
                    return Err(SyntaxError {
                        at: self.base + start,
                        message: format!(
                            "`{name}` takes {arity} argument{}, not {}",
                            if arity == 1 { "" } else { "s" },
                            args.len()
                        ),
                    });
                }
                Ok(Expr::Call(f, args))
            }
            None => Err(self.err("expected a name or a number in the placeholder")),
            Some(_) => Err(self.err(format!(
                "expected a name or a number, found `{}`",
                self.text[self.pos..].chars().next().unwrap_or(' ')
            ))),
        }
    }
}

/// A JSON value as a template renders it (a motor schema and its
/// parameters): what a `serde_json::Value` holds, with the template's
/// constant parts shared rather than copied. A mapping's keys are the
/// template's own, and a part that reads no variable is the template's
/// value itself, so rendering a schema allocates for what the command
/// changes only (its values, a point), not for every key and name of it.
///
/// Two values are equal when they hold the same JSON, however it is
/// shared. [`Json::to_json`] gives it as a `serde_json::Value`.
#[derive(Clone, Debug)]
pub enum Json {
    /// A part of the template that reads no variable.
    Constant(std::sync::Arc<serde_json::Value>),
    /// `null`: a number that has no finite value as JSON.
    Null,
    /// A number.
    Number(serde_json::Number),
    /// A string.
    String(String),
    /// A list.
    Array(Box<[Json]>),
    /// A mapping: the template's keys, in order, and their values.
    Object(std::sync::Arc<[String]>, Box<[Json]>),
}

impl Json {
    /// The value as a `serde_json::Value` (a copy).
    pub fn to_json(&self) -> serde_json::Value {
        match self {
            Json::Constant(v) => (**v).clone(),
            Json::Null => serde_json::Value::Null,
            Json::Number(n) => serde_json::Value::Number(n.clone()),
            Json::String(s) => serde_json::Value::String(s.clone()),
            Json::Array(a) => serde_json::Value::Array(a.iter().map(Json::to_json).collect()),
            Json::Object(keys, values) => serde_json::Value::Object(
                keys.iter()
                    .zip(values.iter())
                    .map(|(k, v)| (k.clone(), v.to_json()))
                    .collect(),
            ),
        }
    }

    /// A number as JSON: an integer when it is one (see [`num_json`]).
    fn number(x: f64) -> Json {
        match num_json(x) {
            serde_json::Value::Number(n) => Json::Number(n),
            _ => Json::Null,
        }
    }

    /// A template value as JSON (integral numbers as integers).
    fn of(v: Val) -> Json {
        match v {
            Val::Num(x) => Json::number(x),
            Val::Text(t) => Json::String(t),
            Val::Point([x, y]) => Json::Array(Box::new([Json::number(x), Json::number(y)])),
        }
    }
}

impl PartialEq for Json {
    fn eq(&self, other: &Json) -> bool {
        match (self, other) {
            (Json::Constant(a), Json::Constant(b)) => a == b,
            (Json::Null, Json::Null) => true,
            (Json::Number(a), Json::Number(b)) => a == b,
            (Json::String(a), Json::String(b)) => a == b,
            (Json::Array(a), Json::Array(b)) => a == b,
            (Json::Object(ka, va), Json::Object(kb, vb)) => ka == kb && va == vb,
            // The same value, one of them shared with its template.
            (a, b) => a.to_json() == b.to_json(),
        }
    }
}

impl PartialEq<serde_json::Value> for Json {
    fn eq(&self, other: &serde_json::Value) -> bool {
        self.to_json() == *other
    }
}

/// A template over a JSON value (a motor schema): strings are templates.
#[derive(Clone, Debug, PartialEq)]
pub enum JsonTemplate {
    /// A value as is: a number, bool or null, or a string, list or mapping
    /// without placeholders (folded when parsed), shared by every rendering.
    Lit(std::sync::Arc<serde_json::Value>),
    /// A string template.
    Str(Template),
    /// A list.
    Arr(Vec<JsonTemplate>),
    /// A mapping, in order: its keys and their templates.
    Obj(std::sync::Arc<[String]>, Vec<JsonTemplate>),
}

impl JsonTemplate {
    /// Parse every string of `v` as a template. A part without
    /// placeholders is kept as its value ([`JsonTemplate::Lit`]), so that
    /// rendering it shares it.
    pub fn parse(v: &serde_json::Value) -> Result<JsonTemplate, SyntaxError> {
        let t = match v {
            serde_json::Value::String(s) => JsonTemplate::Str(Template::parse(s)?),
            serde_json::Value::Array(a) => JsonTemplate::Arr(
                a.iter()
                    .map(JsonTemplate::parse)
                    .collect::<Result<_, _>>()?,
            ),
            serde_json::Value::Object(m) => JsonTemplate::Obj(
                m.keys().cloned().collect(),
                m.values()
                    .map(JsonTemplate::parse)
                    .collect::<Result<_, _>>()?,
            ),
            other => JsonTemplate::Lit(std::sync::Arc::new(other.clone())),
        };
        Ok(t.folded())
    }

    /// Itself, or its value when it reads no variable.
    fn folded(self) -> JsonTemplate {
        let lit = |t: &JsonTemplate| matches!(t, JsonTemplate::Lit(_));
        let constant = match &self {
            JsonTemplate::Lit(_) => false,
            JsonTemplate::Str(t) => t.parts.iter().all(|p| matches!(p, Part::Lit(_))),
            JsonTemplate::Arr(a) => a.iter().all(lit),
            JsonTemplate::Obj(_, values) => values.iter().all(lit),
        };
        if !constant {
            return self;
        }
        let mut none = NoVars;
        match self.render(&mut none) {
            Ok(v) => JsonTemplate::Lit(std::sync::Arc::new(v.to_json())),
            Err(_) => self,
        }
    }

    /// Every variable read anywhere in it.
    pub fn vars(&self) -> Vec<&str> {
        let mut out = Vec::new();
        self.collect(&mut out);
        out
    }

    fn collect<'a>(&'a self, out: &mut Vec<&'a str>) {
        match self {
            JsonTemplate::Lit(_) => {}
            JsonTemplate::Str(t) => out.extend(t.vars().into_iter().map(|(v, _)| v)),
            JsonTemplate::Arr(a) => a.iter().for_each(|t| t.collect(out)),
            JsonTemplate::Obj(_, values) => values.iter().for_each(|t| t.collect(out)),
        }
    }

    /// Fill in: a string that is one placeholder becomes its value.
    pub fn render(&self, env: &mut dyn Env) -> Result<Json, EvalError> {
        Ok(match self {
            JsonTemplate::Lit(v) => Json::Constant(std::sync::Arc::clone(v)),
            JsonTemplate::Str(t) => match t.whole() {
                Some(e) => Json::of(e.eval(env)?),
                None => Json::String(t.render(env)?),
            },
            JsonTemplate::Arr(a) => {
                Json::Array(a.iter().map(|t| t.render(env)).collect::<Result<_, _>>()?)
            }
            JsonTemplate::Obj(keys, values) => Json::Object(
                std::sync::Arc::clone(keys),
                values
                    .iter()
                    .map(|t| t.render(env))
                    .collect::<Result<_, _>>()?,
            ),
        })
    }
}

/// No variables: what a template without placeholders is rendered in.
struct NoVars;

impl Env for NoVars {
    fn get(&mut self, _: &str) -> Option<Val> {
        None
    }
}

/// An `if:` guard: whether a phase, child or schema is part of this
/// command's decomposition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Guard {
    /// `name`: the parameter was given.
    Known(String),
    /// `not name` / `!name`: it was left empty.
    Unknown(String),
    /// `name == value` (or `!=`), compared without case.
    Eq {
        /// The variable.
        var: String,
        /// The value compared with.
        value: String,
        /// `!=`.
        negated: bool,
    },
}

impl Guard {
    /// Parse `name`, `not name`, `!name`, `name == value`, `name != value`.
    pub fn parse(text: &str) -> Result<Guard, String> {
        let t = text.trim();
        let ident = |s: &str| {
            let s = s.trim();
            (!s.is_empty()
                && s.chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
            .then(|| s.to_string())
        };
        let expected = || {
            format!("`if: {t}`: expected `name`, `not name`, `name == value` or `name != value`")
        };
        for (sep, negated) in [("==", false), ("!=", true)] {
            if let Some((a, b)) = t.split_once(sep) {
                let (Some(var), Some(value)) = (ident(a), ident(b)) else {
                    return Err(expected());
                };
                return Ok(Guard::Eq {
                    var,
                    value: value.to_ascii_lowercase(),
                    negated,
                });
            }
        }
        if let Some(rest) = t.strip_prefix('!').or_else(|| t.strip_prefix("not ")) {
            return ident(rest).map(Guard::Unknown).ok_or_else(expected);
        }
        ident(t).map(Guard::Known).ok_or_else(expected)
    }

    /// The variable the guard tests.
    pub fn var(&self) -> &str {
        match self {
            Guard::Known(v) | Guard::Unknown(v) | Guard::Eq { var: v, .. } => v,
        }
    }

    /// Does it hold?
    pub fn holds(&self, env: &mut dyn Env) -> bool {
        match self {
            Guard::Known(v) => env.get_cow(v).is_some(),
            Guard::Unknown(v) => env.get_cow(v).is_none(),
            Guard::Eq {
                var,
                value,
                negated,
            } => {
                let eq = env.get_cow(var).is_some_and(|v| match &*v {
                    Val::Text(t) => t.eq_ignore_ascii_case(value),
                    v => v.to_text().eq_ignore_ascii_case(value),
                });
                eq != *negated
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    struct Map(BTreeMap<&'static str, Val>);
    impl Env for Map {
        fn get(&mut self, name: &str) -> Option<Val> {
            self.0.get(name).cloned()
        }
    }

    fn env() -> Map {
        Map(BTreeMap::from([
            ("object", Val::Text("box".into())),
            ("goal", Val::Point([6.2, 2.0])),
            ("y0", Val::Num(1.0)),
            ("y1", Val::Num(4.0)),
            ("i", Val::Num(2.0)),
            ("n", Val::Num(3.0)),
            ("shape", Val::Text("triangle".into())),
        ]))
    }

    #[test]
    fn renders_text_and_arithmetic() {
        let t = Template::parse("dist({object}_pos, {goal}) < {0.1 + 0.2}").expect("parses");
        assert_eq!(
            t.render(&mut env()),
            Ok("dist(box_pos, [6.2, 2]) < 0.3".to_string())
        );
        let lane = Template::parse("{y0 + (y1 - y0) * (i - 1) / n}").expect("parses");
        assert_eq!(lane.value(&mut env()), Ok(Val::Num(2.0)));
        let neg = Template::parse("{-i * -2}").expect("parses");
        assert_eq!(neg.value(&mut env()), Ok(Val::Num(4.0)));
        let braces = Template::parse("{{x}}").expect("parses");
        assert_eq!(braces.render(&mut env()), Ok("{x}".to_string()));
    }

    #[test]
    fn functions_take_their_arguments() {
        let t = Template::parse("{0.3 + min(0.15 * n, 0.5 * sqrt (n + 1))}").expect("parses");
        assert_eq!(t.value(&mut env()), Ok(Val::Num(0.75)));
        let t = Template::parse("{max(i, n) - min(i, n)}").expect("parses");
        assert_eq!(t.value(&mut env()), Ok(Val::Num(1.0)));
        let mut vars = t.vars();
        vars.sort_unstable();
        assert_eq!(vars, [("i", 5), ("i", 17), ("n", 8), ("n", 20)]);
        // A variable that happens to be named like a function is still one.
        let t = Template::parse("{min + 1}").expect("parses");
        assert_eq!(t.vars(), [("min", 1)]);
        // Mistakes, where they are.
        let at = |text: &str| Template::parse(text).map_err(|e| (e.at, e.message));
        assert_eq!(at("{sqrt(1, 2)}").map_err(|e| e.0), Err(1));
        assert!(at("{sqrt(1, 2)}").is_err_and(|e| e.1.contains("takes 1 argument, not 2")));
        assert!(at("{cos(1)}").is_err_and(|e| e.1.contains("not a function of templates")));
        assert_eq!(at("{min(1 2)}").map_err(|e| e.0), Err(7));
        let t = Template::parse("{sqrt(0 - n)}").expect("parses");
        assert_eq!(t.value(&mut env()), Err(EvalError::NotFinite));
        let t = Template::parse("{min(object, 1)}").expect("parses");
        assert!(matches!(
            t.value(&mut env()),
            Err(EvalError::Arg { func: "min", .. })
        ));
    }

    #[test]
    fn json_placeholders_keep_their_type() {
        let v = serde_json::json!({"schema": "push", "object": "{object}", "goal": "{goal}",
            "region": ["{y0}", "{y1 / 2}"], "label": "to {object}", "layer": 2});
        let t = JsonTemplate::parse(&v).expect("parses");
        assert_eq!(
            t.render(&mut env()).map(|v| v.to_json()),
            Ok(
                serde_json::json!({"schema": "push", "object": "box", "goal": [6.2, 2],
                "region": [1, 2], "label": "to box", "layer": 2})
            )
        );
        let mut vars = t.vars();
        vars.sort_unstable();
        assert_eq!(vars, ["goal", "object", "object", "y0", "y1"]);
    }

    #[test]
    fn errors() {
        assert_eq!(
            Template::parse("a {b").map_err(|e| e.at),
            Err(2),
            "unclosed"
        );
        assert_eq!(Template::parse("a } b").map_err(|e| e.at), Err(2));
        assert_eq!(Template::parse("{a +}").map_err(|e| e.at), Err(4));
        assert_eq!(Template::parse("{a b}").map_err(|e| e.at), Err(3));
        assert_eq!(Template::parse("{(a}").map_err(|e| e.at), Err(3));
        let t = Template::parse("{missing}").expect("parses");
        assert_eq!(
            t.render(&mut env()),
            Err(EvalError::Unknown("missing".into()))
        );
        let t = Template::parse("{object + 1}").expect("parses");
        assert!(matches!(
            t.render(&mut env()),
            Err(EvalError::Type { op: '+', .. })
        ));
        let t = Template::parse("{1 / (i - 2)}").expect("parses");
        assert_eq!(t.render(&mut env()), Err(EvalError::NotFinite));
    }

    #[test]
    fn guards() {
        let mut e = env();
        assert!(Guard::parse("goal").expect("guard").holds(&mut e));
        assert!(!Guard::parse("x").expect("guard").holds(&mut e));
        assert!(Guard::parse("not x").expect("guard").holds(&mut e));
        assert!(Guard::parse("!x").expect("guard").holds(&mut e));
        assert!(
            Guard::parse("shape == Triangle")
                .expect("guard")
                .holds(&mut e)
        );
        assert!(Guard::parse("shape != line").expect("guard").holds(&mut e));
        assert!(Guard::parse("a ==").is_err());
        assert!(Guard::parse("").is_err());
    }

    #[test]
    fn numbers_format_cleanly() {
        assert_eq!(fmt_num(0.1 + 0.2), "0.3");
        assert_eq!(fmt_num(-0.0), "0");
        assert_eq!(fmt_num(6.7 - 0.5), "6.2");
        assert_eq!(num_json(3.0), serde_json::json!(3));
        assert_eq!(num_json(0.25), serde_json::json!(0.25));
    }
}
