//! Property tests: the parser never panics and reports valid spans, and
//! evaluation agrees with a straightforward reference evaluator.

use super::tests::{BEHAVIORS, Names, World};
use super::*;
use proptest::prelude::*;
use std::sync::Arc;

fn check_span(src: &str, e: &CondError) -> Result<(), TestCaseError> {
    prop_assert!(e.span.start <= e.span.end, "{e:?}");
    prop_assert!(e.span.end <= src.len(), "{e:?}");
    prop_assert!(src.is_char_boundary(e.span.start), "{e:?}");
    prop_assert!(src.is_char_boundary(e.span.end), "{e:?}");
    prop_assert!(!e.message.is_empty());
    let _ = e.render(src);
    Ok(())
}

/// Parses `src`; on success evaluates it against a few environments.
fn parse_any(src: &str) -> Result<(), TestCaseError> {
    let mut names = Names::default();
    match Expr::parse(src, &mut names) {
        Err(e) => check_span(src, &e),
        Ok(e) => {
            prop_assert_eq!(e.source(), src);
            let n = names.beliefs.len();
            for v in [
                None,
                Some(Value::Bool(true)),
                Some(Value::Num(0.0)),
                Some(Value::Vec2([1.0, -1.0])),
                Some(Value::Text(Arc::from("x"))),
            ] {
                let w = World {
                    vals: vec![v; n],
                    ages: vec![Some(1.0); n],
                    elapsed: 1.0,
                    runs_own: 1,
                };
                let b = e.eval(&w);
                prop_assert_eq!(b, e.eval_value(&w) == Some(Value::Bool(true)));
            }
            Ok(())
        }
    }
}

const SOUP: &[&str] = &[
    "(",
    ")",
    "(",
    ")",
    "[",
    "]",
    ",",
    "&&",
    "||",
    "!",
    "not",
    "and",
    "or",
    "x",
    "y",
    "pos",
    "x",
    "3",
    ".5",
    "1e3",
    "-",
    "+",
    "*",
    "/",
    ".x",
    ".y",
    ".",
    "==",
    "!=",
    "<",
    "<=",
    ">",
    ">=",
    "true",
    "false",
    "abs",
    "min",
    "max",
    "norm",
    "dist",
    "known",
    "age",
    "runs",
    "elapsed",
    "search",
    "\"s\"",
    "'\u{e9}'",
    "'",
    "\"",
    "\\",
    "=",
    "&",
    "|",
    "\u{e9}",
    "\u{1f916}",
    "0",
    "1e999",
    "3x",
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let src = String::from_utf8_lossy(&bytes);
        parse_any(&src)?;
    }

    #[test]
    fn random_strings_never_panic(src in any::<String>()) {
        parse_any(&src)?;
    }

    #[test]
    fn token_soup_never_panics(
        toks in prop::collection::vec((prop::sample::select(SOUP), any::<bool>()), 0..80)
    ) {
        let mut src = String::new();
        for (t, space) in toks {
            src.push_str(t);
            if space {
                src.push(' ');
            }
        }
        parse_any(&src)?;
    }

    #[test]
    fn deep_soup_never_overflows(
        unit in prop::sample::select(&["(", "!", "-", "[", "not ", "abs(", "[1,", "min(1,"][..]),
        n in 0usize..1500,
    ) {
        let src = format!("{}x", unit.repeat(n));
        parse_any(&src)?;
    }
}

// ---- generated well-formed expressions --------------------------------

/// Belief names used by generated expressions.
const BELIEFS: [&str; 6] = ["a", "b", "c", "p", "q", "x"];

#[derive(Clone, Copy, Debug)]
enum Arith {
    Add,
    Sub,
    Mul,
    Div,
}

#[derive(Clone, Copy, Debug)]
enum Cmp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

/// A well-typed expression tree.
#[derive(Clone, Debug)]
enum A {
    Num(f64),
    Bool(bool),
    Text(String),
    Vec(Box<A>, Box<A>),
    Belief(usize),
    Elapsed,
    RunsOwn(bool),
    RunsOf(usize),
    Known(usize),
    Age(usize),
    Not(Box<A>, bool),
    And(Box<A>, Box<A>, bool),
    Or(Box<A>, Box<A>, bool),
    Cmp(Cmp, Box<A>, Box<A>),
    Arith(Arith, Box<A>, Box<A>),
    Neg(Box<A>),
    Comp(Box<A>, bool),
    Abs(Box<A>),
    Norm(Box<A>),
    Min(Box<A>, Box<A>),
    Max(Box<A>, Box<A>),
    Dist(Box<A>, Box<A>),
    Paren(Box<A>),
}

fn b(a: A) -> Box<A> {
    Box::new(a)
}

/// Generators of booleans, numbers, vectors and text, `depth` levels deep.
#[derive(Clone)]
struct Gens {
    bool: BoxedStrategy<A>,
    num: BoxedStrategy<A>,
    vec: BoxedStrategy<A>,
    text: BoxedStrategy<A>,
}

fn belief() -> BoxedStrategy<A> {
    (0..BELIEFS.len()).prop_map(A::Belief).boxed()
}

fn leaves() -> Gens {
    let num_lit = prop::sample::select(&[0.0, 1.0, 2.0, 0.5, 3.25, 10.0, -1.0, -0.5, 1e6][..]);
    Gens {
        bool: prop_oneof![
            any::<bool>().prop_map(A::Bool),
            belief(),
            (0..BELIEFS.len()).prop_map(A::Known),
        ]
        .boxed(),
        num: prop_oneof![
            num_lit.clone().prop_map(A::Num),
            belief(),
            Just(A::Elapsed),
            any::<bool>().prop_map(A::RunsOwn),
            (0..BEHAVIORS.len()).prop_map(A::RunsOf),
            (0..BELIEFS.len()).prop_map(A::Age),
        ]
        .boxed(),
        vec: prop_oneof![
            (num_lit.clone(), num_lit).prop_map(|(x, y)| A::Vec(b(A::Num(x)), b(A::Num(y)))),
            belief(),
        ]
        .boxed(),
        text: prop_oneof![
            prop::sample::select(&["red", "blue", "", "it's", "\u{e9}\"\\\n"][..])
                .prop_map(|s| A::Text(s.to_owned())),
            belief(),
        ]
        .boxed(),
    }
}

fn level(g: Gens) -> Gens {
    let arith = prop::sample::select(&[Arith::Add, Arith::Sub, Arith::Mul, Arith::Div][..]);
    let order = prop::sample::select(&[Cmp::Lt, Cmp::Le, Cmp::Gt, Cmp::Ge][..]);
    let all = prop::sample::select(&[Cmp::Eq, Cmp::Ne, Cmp::Lt, Cmp::Le, Cmp::Gt, Cmp::Ge][..]);
    let eq = prop::sample::select(&[Cmp::Eq, Cmp::Ne][..]);
    let Gens {
        bool,
        num,
        vec,
        text,
    } = g.clone();
    let bool2 = prop_oneof![
        2 => bool.clone(),
        1 => (bool.clone(), any::<bool>()).prop_map(|(a, w)| A::Not(b(a), w)),
        1 => (bool.clone(), bool.clone(), any::<bool>()).prop_map(|(l, r, w)| A::And(b(l), b(r), w)),
        1 => (bool.clone(), bool.clone(), any::<bool>()).prop_map(|(l, r, w)| A::Or(b(l), b(r), w)),
        1 => (order, num.clone(), num.clone()).prop_map(|(o, l, r)| A::Cmp(o, b(l), b(r))),
        1 => (all, text.clone(), text.clone()).prop_map(|(o, l, r)| A::Cmp(o, b(l), b(r))),
        1 => (eq.clone(), num.clone(), num.clone()).prop_map(|(o, l, r)| A::Cmp(o, b(l), b(r))),
        1 => (eq.clone(), vec.clone(), vec.clone()).prop_map(|(o, l, r)| A::Cmp(o, b(l), b(r))),
        1 => (eq, bool.clone(), bool.clone()).prop_map(|(o, l, r)| A::Cmp(o, b(l), b(r))),
        1 => bool.clone().prop_map(|a| A::Paren(b(a))),
    ]
    .boxed();
    let num2 = prop_oneof![
        3 => num.clone(),
        2 => (arith, num.clone(), num.clone()).prop_map(|(o, l, r)| A::Arith(o, b(l), b(r))),
        1 => num.clone().prop_map(|a| A::Neg(b(a))),
        1 => (vec.clone(), any::<bool>()).prop_map(|(v, y)| A::Comp(b(v), y)),
        1 => num.clone().prop_map(|a| A::Abs(b(a))),
        1 => vec.clone().prop_map(|a| A::Norm(b(a))),
        1 => (num.clone(), num.clone()).prop_map(|(l, r)| A::Min(b(l), b(r))),
        1 => (num.clone(), num.clone()).prop_map(|(l, r)| A::Max(b(l), b(r))),
        1 => (vec.clone(), vec.clone()).prop_map(|(l, r)| A::Dist(b(l), b(r))),
        1 => num.clone().prop_map(|a| A::Paren(b(a))),
    ]
    .boxed();
    let add = prop::sample::select(&[Arith::Add, Arith::Sub][..]);
    let vec2 = prop_oneof![
        2 => vec.clone(),
        1 => (num.clone(), num.clone()).prop_map(|(x, y)| A::Vec(b(x), b(y))),
        1 => (add, vec.clone(), vec.clone()).prop_map(|(o, l, r)| A::Arith(o, b(l), b(r))),
        1 => (vec.clone(), num.clone()).prop_map(|(l, r)| A::Arith(Arith::Mul, b(l), b(r))),
        1 => (num.clone(), vec.clone()).prop_map(|(l, r)| A::Arith(Arith::Mul, b(l), b(r))),
        1 => (vec.clone(), num.clone()).prop_map(|(l, r)| A::Arith(Arith::Div, b(l), b(r))),
        1 => vec.clone().prop_map(|a| A::Neg(b(a))),
    ]
    .boxed();
    Gens {
        bool: bool2,
        num: num2,
        vec: vec2,
        text,
    }
}

fn gens(depth: usize) -> Gens {
    let mut g = leaves();
    for _ in 0..depth {
        g = level(g);
    }
    g
}

// Printing with minimal parentheses. Precedence levels: 1 `||`, 2 `&&`,
// 3 `!`, 4 comparison, 5 `+ -`, 6 `* /`, 7 unary `-`, 8 postfix, 9 primary.

fn print(a: &A) -> String {
    print_prec(a).0
}

fn slot(a: &A, min: u8) -> String {
    let (s, p) = print_prec(a);
    if p < min { format!("({s})") } else { s }
}

fn text_lit(s: &str, single: bool) -> String {
    let q = if single { '\'' } else { '"' };
    let mut out = String::from(q);
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c if c == q => {
                out.push('\\');
                out.push(c);
            }
            c => out.push(c),
        }
    }
    out.push(q);
    out
}

fn print_prec(a: &A) -> (String, u8) {
    match a {
        A::Num(n) if *n < 0.0 => (format!("-{}", -n), 7),
        A::Num(n) => (format!("{n}"), 9),
        A::Bool(v) => (v.to_string(), 9),
        A::Text(s) => (text_lit(s, s.len() % 2 == 0), 9),
        A::Vec(x, y) => (format!("[{}, {}]", print(x), print(y)), 9),
        A::Belief(i) => (BELIEFS[*i].to_owned(), 9),
        A::Elapsed => ("elapsed".to_owned(), 9),
        A::RunsOwn(call) => ((if *call { "runs()" } else { "runs" }).to_owned(), 9),
        A::RunsOf(i) => (format!("runs({})", BEHAVIORS[*i]), 9),
        A::Known(i) => (format!("known({})", BELIEFS[*i]), 9),
        A::Age(i) => (format!("age({})", BELIEFS[*i]), 9),
        A::Not(x, word) => {
            let op = if *word { "not " } else { "!" };
            (format!("{op}{}", slot(x, 3)), 3)
        }
        A::And(l, r, word) => {
            let op = if *word { "and" } else { "&&" };
            (format!("{} {op} {}", slot(l, 2), slot(r, 3)), 2)
        }
        A::Or(l, r, word) => {
            let op = if *word { "or" } else { "||" };
            (format!("{} {op} {}", slot(l, 1), slot(r, 2)), 1)
        }
        A::Cmp(op, l, r) => {
            let op = match op {
                Cmp::Eq => "==",
                Cmp::Ne => "!=",
                Cmp::Lt => "<",
                Cmp::Le => "<=",
                Cmp::Gt => ">",
                Cmp::Ge => ">=",
            };
            (format!("{} {op} {}", slot(l, 5), slot(r, 5)), 4)
        }
        A::Arith(op, l, r) => {
            let (sym, p) = match op {
                Arith::Add => ("+", 5),
                Arith::Sub => ("-", 5),
                Arith::Mul => ("*", 6),
                Arith::Div => ("/", 6),
            };
            (format!("{} {sym} {}", slot(l, p), slot(r, p + 1)), p)
        }
        A::Neg(x) => (format!("- {}", slot(x, 7)), 7),
        A::Comp(x, y) => (format!("{}.{}", slot(x, 8), if *y { "y" } else { "x" }), 8),
        A::Abs(x) => (format!("abs({})", print(x)), 9),
        A::Norm(x) => (format!("norm({})", print(x)), 9),
        A::Min(x, y) => (format!("min({}, {})", print(x), print(y)), 9),
        A::Max(x, y) => (format!("max({}, {})", print(x), print(y)), 9),
        A::Dist(x, y) => (format!("dist({}, {})", print(x), print(y)), 9),
        A::Paren(x) => (format!("({})", print(x)), 9),
    }
}

// The reference evaluator: the documented semantics, written plainly.

#[derive(Debug)]
struct RefEnv {
    vals: Vec<Option<Value>>,
    ages: Vec<f64>,
    elapsed: f64,
    runs_own: u32,
}

fn finite(n: f64) -> Option<Value> {
    n.is_finite().then_some(Value::Num(n))
}

fn finite2(x: f64, y: f64) -> Option<Value> {
    (x.is_finite() && y.is_finite()).then_some(Value::Vec2([x, y]))
}

fn truthy(v: &Option<Value>) -> bool {
    *v == Some(Value::Bool(true))
}

fn reference(a: &A, env: &RefEnv) -> Option<Value> {
    let r = |a: &A| reference(a, env);
    let n = |a: &A| r(a).and_then(|v| v.as_num());
    let v = |a: &A| r(a).and_then(|v| v.as_vec2());
    match a {
        A::Num(x) => Some(Value::Num(*x)),
        A::Bool(x) => Some(Value::Bool(*x)),
        A::Text(s) => Some(Value::Text(Arc::from(s.as_str()))),
        A::Vec(x, y) => Some(Value::Vec2([n(x)?, n(y)?])),
        A::Belief(i) => env.vals[*i].clone(),
        A::Elapsed => Some(Value::Num(env.elapsed)),
        A::RunsOwn(_) => Some(Value::Num(f64::from(env.runs_own))),
        A::RunsOf(i) => Some(Value::Num(10.0 + *i as f64)),
        A::Known(i) => Some(Value::Bool(env.vals[*i].is_some())),
        A::Age(i) => env.vals[*i].as_ref().map(|_| Value::Num(env.ages[*i])),
        A::Not(x, _) => Some(Value::Bool(!truthy(&r(x)))),
        A::And(x, y, _) => Some(Value::Bool(truthy(&r(x)) && truthy(&r(y)))),
        A::Or(x, y, _) => Some(Value::Bool(truthy(&r(x)) || truthy(&r(y)))),
        A::Cmp(op, x, y) => {
            let (Some(x), Some(y)) = (r(x), r(y)) else {
                return Some(Value::Bool(false));
            };
            let ord = match (&x, &y) {
                (Value::Num(a), Value::Num(b)) => a.partial_cmp(b),
                (Value::Text(a), Value::Text(b)) => Some(a.cmp(b)),
                _ => None,
            };
            let res = match op {
                Cmp::Eq => x == y,
                Cmp::Ne => x != y,
                Cmp::Lt => ord.is_some_and(|o| o.is_lt()),
                Cmp::Le => ord.is_some_and(|o| o.is_le()),
                Cmp::Gt => ord.is_some_and(|o| o.is_gt()),
                Cmp::Ge => ord.is_some_and(|o| o.is_ge()),
            };
            Some(Value::Bool(res))
        }
        A::Arith(op, x, y) => match (op, r(x)?, r(y)?) {
            (Arith::Add, Value::Num(a), Value::Num(b)) => finite(a + b),
            (Arith::Sub, Value::Num(a), Value::Num(b)) => finite(a - b),
            (Arith::Mul, Value::Num(a), Value::Num(b)) => finite(a * b),
            (Arith::Div, Value::Num(a), Value::Num(b)) if b != 0.0 => finite(a / b),
            (Arith::Add, Value::Vec2(a), Value::Vec2(b)) => finite2(a[0] + b[0], a[1] + b[1]),
            (Arith::Sub, Value::Vec2(a), Value::Vec2(b)) => finite2(a[0] - b[0], a[1] - b[1]),
            (Arith::Mul, Value::Vec2(a), Value::Num(k)) => finite2(a[0] * k, a[1] * k),
            (Arith::Mul, Value::Num(k), Value::Vec2(a)) => finite2(k * a[0], k * a[1]),
            (Arith::Div, Value::Vec2(a), Value::Num(k)) if k != 0.0 => finite2(a[0] / k, a[1] / k),
            _ => None,
        },
        A::Neg(x) => match r(x)? {
            Value::Num(a) => finite(-a),
            Value::Vec2(a) => finite2(-a[0], -a[1]),
            _ => None,
        },
        A::Comp(x, y) => v(x).map(|p| Value::Num(if *y { p[1] } else { p[0] })),
        A::Abs(x) => finite(n(x)?.abs()),
        A::Norm(x) => v(x).and_then(|p| finite((p[0] * p[0] + p[1] * p[1]).sqrt())),
        A::Min(x, y) => finite(n(x)?.min(n(y)?)),
        A::Max(x, y) => finite(n(x)?.max(n(y)?)),
        A::Dist(x, y) => {
            let (p, q) = (v(x)?, v(y)?);
            finite(((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
        }
        A::Paren(x) => r(x),
    }
}

/// Numbers equal up to rounding.
fn close(a: &Option<Value>, b: &Option<Value>) -> bool {
    let near = |x: f64, y: f64| x == y || (x - y).abs() <= 1e-9 * x.abs().max(y.abs());
    match (a, b) {
        (Some(Value::Num(x)), Some(Value::Num(y))) => near(*x, *y),
        (Some(Value::Vec2(x)), Some(Value::Vec2(y))) => near(x[0], y[0]) && near(x[1], y[1]),
        _ => a == b,
    }
}

fn arb_value() -> impl Strategy<Value = Option<Value>> {
    let n = prop::sample::select(&[0.0, 1.0, 2.0, -2.5, 0.5, 10.0, 1e300][..]);
    prop_oneof![
        2 => Just(None),
        1 => any::<bool>().prop_map(|b| Some(Value::Bool(b))),
        2 => n.clone().prop_map(|x| Some(Value::Num(x))),
        1 => (n.clone(), n).prop_map(|(x, y)| Some(Value::Vec2([x, y]))),
        1 => prop::sample::select(&["red", "blue", "it's"][..])
            .prop_map(|s| Some(Value::Text(Arc::from(s)))),
    ]
}

fn arb_env() -> impl Strategy<Value = RefEnv> {
    (
        prop::collection::vec(arb_value(), BELIEFS.len()),
        prop::collection::vec(0.0f64..100.0, BELIEFS.len()),
        0.0f64..100.0,
        0u32..5,
    )
        .prop_map(|(vals, ages, elapsed, runs_own)| RefEnv {
            vals,
            ages,
            elapsed,
            runs_own,
        })
}

fn arb_expr() -> impl Strategy<Value = A> {
    let g = gens(4);
    prop_oneof![g.bool, g.num, g.vec]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]

    #[test]
    fn printed_expressions_evaluate_like_the_reference(a in arb_expr(), env in arb_env()) {
        let src = print(&a);
        let mut names = Names::default();
        let e = match Expr::parse(&src, &mut names) {
            Ok(e) => e,
            Err(err) => return Err(TestCaseError::fail(format!("{}\n{a:?}", err.render(&src)))),
        };
        // Map the resolver's ids back to the generator's belief indices.
        let mut w = World {
            vals: vec![None; names.beliefs.len()],
            ages: vec![None; names.beliefs.len()],
            elapsed: env.elapsed,
            runs_own: env.runs_own,
        };
        for (id, name) in names.beliefs.iter().enumerate() {
            let i = BELIEFS.iter().position(|b| b == name).unwrap_or(0);
            w.vals[id] = env.vals[i].clone();
            w.ages[id] = Some(env.ages[i]);
        }
        let want = reference(&a, &env);
        let got = e.eval_value(&w);
        prop_assert!(close(&got, &want), "{src}: got {got:?}, want {want:?}");
        prop_assert_eq!(e.eval(&w), truthy(&want), "{}", src);
        let mut ids = e.beliefs().to_vec();
        ids.dedup();
        prop_assert_eq!(ids.len(), names.beliefs.len());
    }
}
