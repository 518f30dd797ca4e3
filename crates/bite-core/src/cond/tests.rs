//! Unit tests of the condition language.

use super::*;
use std::sync::Arc;

/// A resolver with two behaviors, `search` and `push_box`.
#[derive(Default)]
pub(super) struct Names {
    pub(super) beliefs: Vec<String>,
}

pub(super) const BEHAVIORS: [&str; 2] = ["search", "push_box"];

impl Resolver for Names {
    fn belief(&mut self, name: &str) -> BeliefId {
        let i = match self.beliefs.iter().position(|n| n == name) {
            Some(i) => i,
            None => {
                self.beliefs.push(name.to_owned());
                self.beliefs.len() - 1
            }
        };
        BeliefId(i as u32)
    }
    fn behavior(&self, name: &str) -> Option<BehaviorId> {
        BEHAVIORS
            .iter()
            .position(|b| *b == name)
            .map(|i| BehaviorId(i as u32))
    }
    fn behavior_names(&self) -> Vec<&str> {
        BEHAVIORS.to_vec()
    }
}

/// An environment: beliefs by id, each set belief 2 s old unless `ages`
/// says otherwise; `elapsed` 5 s; own runs 3; runs of behavior i = 10 + i.
#[derive(Default, Debug, Clone)]
pub(super) struct World {
    pub(super) vals: Vec<Option<Value>>,
    pub(super) ages: Vec<Option<f64>>,
    pub(super) elapsed: f64,
    pub(super) runs_own: u32,
}

impl Env for World {
    fn belief(&self, id: BeliefId) -> Option<&Value> {
        self.vals.get(id.index())?.as_ref()
    }
    fn belief_age(&self, id: BeliefId) -> Option<f64> {
        self.belief(id)?;
        Some(self.ages.get(id.index()).copied().flatten().unwrap_or(2.0))
    }
    fn elapsed(&self) -> f64 {
        self.elapsed
    }
    fn runs(&self, b: Option<BehaviorId>) -> u32 {
        match b {
            None => self.runs_own,
            Some(b) => 10 + b.0,
        }
    }
}

fn parse(src: &str) -> Result<Expr, CondError> {
    Expr::parse(src, &mut Names::default())
}

fn world(names: &Names, set: &[(&str, Value)]) -> World {
    let mut w = World {
        vals: vec![None; names.beliefs.len()],
        ages: vec![None; names.beliefs.len()],
        elapsed: 5.0,
        runs_own: 3,
    };
    for (name, v) in set {
        if let Some(i) = names.beliefs.iter().position(|n| n == name) {
            w.vals[i] = Some(v.clone());
        }
    }
    w
}

/// Evaluates `src` as a value with the given beliefs set.
fn val(src: &str, set: &[(&str, Value)]) -> Option<Value> {
    let mut names = Names::default();
    let e = Expr::parse(src, &mut names).unwrap_or_else(|e| panic!("{src}: {e}"));
    e.eval_value(&world(&names, set))
}

/// Evaluates `src` as a condition with the given beliefs set.
fn holds(src: &str, set: &[(&str, Value)]) -> bool {
    let mut names = Names::default();
    let e = Expr::parse(src, &mut names).unwrap_or_else(|e| panic!("{src}: {e}"));
    let w = world(&names, set);
    let b = e.eval(&w);
    assert_eq!(b, e.eval_value(&w) == Some(Value::Bool(true)), "{src}");
    b
}

fn num(src: &str) -> Option<f64> {
    val(src, &[]).and_then(|v| v.as_num())
}

/// Asserts that `src` fails with `message` (a substring) at `span`.
fn fails(src: &str, span: std::ops::Range<usize>, message: &str) -> CondError {
    let e = match parse(src) {
        Ok(_) => panic!("`{src}` parsed"),
        Err(e) => e,
    };
    assert!(
        e.message.contains(message),
        "`{src}`: message {:?} lacks {message:?}",
        e.message
    );
    assert_eq!(e.span, span, "`{src}`: {e}");
    e
}

fn hint(e: &CondError) -> &str {
    e.hint.as_deref().unwrap_or("")
}

fn t(s: &str) -> Value {
    Value::Text(Arc::from(s))
}

// ---- precedence and associativity ------------------------------------

#[test]
fn arithmetic_precedence_and_associativity() {
    assert_eq!(num("1 + 2 * 3"), Some(7.0));
    assert_eq!(num("(1 + 2) * 3"), Some(9.0));
    assert_eq!(num("10 - 4 - 3"), Some(3.0));
    assert_eq!(num("10 - (4 - 3)"), Some(9.0));
    assert_eq!(num("8 / 4 / 2"), Some(1.0));
    assert_eq!(num("8 / (4 / 2)"), Some(4.0));
    assert_eq!(num("2 * 3 - 4 / 2"), Some(4.0));
    assert_eq!(num("-2 * 3"), Some(-6.0));
    assert_eq!(num("- -2"), Some(2.0));
    assert_eq!(num("2 - -2"), Some(4.0));
    assert_eq!(num("-[1, 2].y"), Some(-2.0));
    assert_eq!(num("(-[1, 2]).y"), Some(-2.0));
    assert_eq!(num("1e3 + .25 + -0.5"), Some(999.75));
    assert_eq!(num("2.5E-1"), Some(0.25));
}

#[test]
fn logical_precedence() {
    let ff = [("a", true.into()), ("b", false.into()), ("c", false.into())];
    assert!(holds("a || b && c", &ff));
    assert!(!holds("(a || b) && c", &ff));
    assert!(holds("c && b || a", &ff));
    assert!(holds("a or b and c", &ff));
    // `not` binds tighter than `&&` but looser than comparisons.
    assert!(!holds("not a && b", &ff));
    assert!(holds("not (a && b)", &ff));
    assert!(holds("!b && !c", &ff));
    assert!(holds("not 1 == 2", &[]));
    assert!(holds("!1 + 1 == 3", &[]));
    assert!(holds("not not a", &ff));
    assert!(parse("1 < 2 == true").is_err());
    assert!(holds("(1 < 2) == true", &[]));
    // Comparison binds looser than arithmetic.
    assert!(holds("1 + 1 == 2 && 2 * 2 >= 4", &[]));
}

#[test]
fn and_or_chains_flatten() {
    let src = (0..100)
        .map(|i| format!("b{i}"))
        .collect::<Vec<_>>()
        .join(" && ");
    let mut names = Names::default();
    let e = Expr::parse(&src, &mut names).unwrap();
    let mut w = world(&names, &[]);
    assert!(!e.eval(&w));
    w.vals = vec![Some(Value::Bool(true)); 100];
    assert!(e.eval(&w));
    assert_eq!(e.beliefs().len(), 100);
}

// ---- operators ----------------------------------------------------------

#[test]
fn comparisons() {
    for (src, want) in [
        ("1 == 1", true),
        ("1 == 2", false),
        ("1 != 2", true),
        ("1 != 1", false),
        ("1 < 2", true),
        ("2 < 2", false),
        ("2 <= 2", true),
        ("3 <= 2", false),
        ("3 > 2", true),
        ("2 > 2", false),
        ("2 >= 2", true),
        ("1 >= 2", false),
        ("true == true", true),
        ("true != false", true),
        ("[1, 2] == [1, 2]", true),
        ("[1, 2] == [1, 3]", false),
        ("[1, 2] != [2, 1]", true),
        ("'red' == \"red\"", true),
        ("'red' != 'blue'", true),
        ("'apple' < 'banana'", true),
        ("'b' >= 'ab'", true),
        ("'é' > 'z'", true),
    ] {
        assert_eq!(holds(src, &[]), want, "{src}");
    }
}

#[test]
fn arithmetic_on_numbers_and_vectors() {
    assert_eq!(num("7 - 2"), Some(5.0));
    assert_eq!(num("7 / 2"), Some(3.5));
    assert_eq!(val("[1, 2] + [3, 4]", &[]), Some(Value::Vec2([4.0, 6.0])));
    assert_eq!(val("[1, 2] - [3, 5]", &[]), Some(Value::Vec2([-2.0, -3.0])));
    assert_eq!(val("[1, 2] * 2", &[]), Some(Value::Vec2([2.0, 4.0])));
    assert_eq!(val("2 * [1, 2]", &[]), Some(Value::Vec2([2.0, 4.0])));
    assert_eq!(val("[1, 2] / 2", &[]), Some(Value::Vec2([0.5, 1.0])));
    assert_eq!(val("-[1, 2]", &[]), Some(Value::Vec2([-1.0, -2.0])));
    let p = [("p", Value::Vec2([3.0, 4.0])), ("k", Value::Num(2.0))];
    assert_eq!(val("p * k", &p), Some(Value::Vec2([6.0, 8.0])));
    assert_eq!(val("[p.x + k, p.y]", &p), Some(Value::Vec2([5.0, 4.0])));
    assert_eq!(val("p.x", &p), Some(Value::Num(3.0)));
    assert_eq!(val("p.y", &p), Some(Value::Num(4.0)));
    assert_eq!(val("(p + p).y", &p), Some(Value::Num(8.0)));
    assert_eq!(val("-p", &p), Some(Value::Vec2([-3.0, -4.0])));
}

#[test]
fn functions() {
    assert_eq!(num("abs(-3)"), Some(3.0));
    assert_eq!(num("min(2, 3)"), Some(2.0));
    assert_eq!(num("max(2, 3)"), Some(3.0));
    assert_eq!(num("norm([3, 4])"), Some(5.0));
    assert_eq!(num("dist([1, 1], [4, 5])"), Some(5.0));
    assert_eq!(num("elapsed"), Some(5.0));
    assert_eq!(num("runs"), Some(3.0));
    assert_eq!(num("runs()"), Some(3.0));
    assert_eq!(num("runs(search)"), Some(10.0));
    assert_eq!(num("runs(push_box)"), Some(11.0));
    let set = [("seen", Value::Bool(false))];
    assert!(holds("known(seen)", &set));
    assert!(!holds("known(other)", &set));
    assert_eq!(val("age(seen)", &set), Some(Value::Num(2.0)));
    assert_eq!(val("age(other)", &set), None);
    assert!(holds("known(seen) && age(seen) < 3", &set));
    assert!(holds("abs(x) <= 1", &[("x", Value::Num(-0.5))]));
    // Function names without a call are plain beliefs.
    assert!(holds("max > 1", &[("max", Value::Num(2.0))]));
}

// ---- closed-world semantics -------------------------------------------

#[test]
fn unset_beliefs_are_unknown_and_false() {
    assert!(holds("not obstacle_near", &[]));
    assert!(holds("!obstacle_near", &[]));
    assert!(!holds("obstacle_near", &[]));
    assert!(!holds("x > 3", &[]));
    assert!(!holds("x <= 3", &[]));
    assert!(!holds("x == 3", &[]));
    assert!(!holds("x != 3", &[]), "!= with unknown is false");
    assert!(!holds("x == x", &[]));
    assert!(holds("!(x > 3)", &[]));
    assert!(!holds("a && b", &[("a", true.into())]));
    assert!(holds("a || b", &[("a", true.into())]));
    assert_eq!(val("x + 1", &[]), None);
    assert_eq!(val("abs(x)", &[]), None);
    assert_eq!(val("min(x, 1)", &[]), None);
    assert_eq!(val("[x, 1]", &[]), None);
    assert_eq!(val("p.x", &[]), None);
    assert_eq!(val("-p", &[]), None);
    assert_eq!(val("norm(p)", &[]), None);
    assert_eq!(val("dist(p, [0, 0])", &[]), None);
    assert_eq!(val("x", &[]), None);
}

#[test]
fn runtime_type_mismatches() {
    let set = [
        ("n", Value::Num(2.0)),
        ("s", t("red")),
        ("b", Value::Bool(true)),
        ("v", Value::Vec2([1.0, 2.0])),
    ];
    // A number (or vector, or text) in boolean position is false.
    assert!(!holds("n", &set));
    assert!(!holds("n && b", &set));
    assert!(holds("!n", &set));
    assert!(!holds("v || s", &set));
    // Equality across types: never equal; `!=` is true.
    assert!(!holds("n == s", &set));
    assert!(holds("n != s", &set));
    assert!(holds("s == 'red'", &set));
    assert!(holds("s != 'blue'", &set));
    // Ordering of anything but numbers and text is false.
    assert!(!holds("n < s", &set));
    assert!(!holds("v < v", &set));
    assert!(!holds("b >= b", &set));
    // Arithmetic with wrong types is unknown.
    assert_eq!(val("n + s", &set), None);
    assert_eq!(val("n + v", &set), None);
    assert_eq!(val("v * v", &set), None);
    assert_eq!(val("n / v", &set), None);
    assert_eq!(val("-s", &set), None);
    assert_eq!(val("s.x", &set), None);
    assert_eq!(val("abs(v)", &set), None);
    assert_eq!(val("norm(n)", &set), None);
    assert_eq!(val("[s, 1]", &set), None);
}

#[test]
fn comparisons_with_constants() {
    // These compile to fused nodes; the semantics must not change.
    let set = [
        ("n", Value::Num(2.0)),
        ("s", t("red")),
        ("v", Value::Vec2([1.0, 2.0])),
    ];
    assert!(holds("3 > n", &set));
    assert!(holds("2 >= n && 2 <= n && 2 == n", &set));
    assert!(!holds("1 >= n", &set));
    assert!(holds("s != 3", &set));
    assert!(holds("3 != s", &set));
    assert!(!holds("s == 3", &set));
    assert!(!holds("s < 3", &set));
    assert!(!holds("u != 3", &set));
    assert!(holds("n * 2 == 4", &set));
    assert!(holds("v * 2 != 4", &set), "a vector is known and not 4");
    assert!(!holds("v * 2 < 4", &set));
    assert!(!holds("u * 2 != 4", &set), "unknown");
    assert!(holds("n + 1 > n", &set));
    assert!(!holds("n / 0 < n", &set));
    assert!(!holds("n / 0 != n", &set));
    assert!(holds("elapsed > runs", &set));
}

#[test]
fn documented_examples() {
    // The examples of docs/conditions.md.
    let set = [("n", Value::Num(2.0)), ("s", t("red"))];
    for (src, want) in [
        ("x", None),
        ("not x", Some(Value::Bool(true))),
        ("x > 3", Some(Value::Bool(false))),
        ("x <= 3", Some(Value::Bool(false))),
        ("x == 3", Some(Value::Bool(false))),
        ("x != 3", Some(Value::Bool(false))),
        ("not (x > 3)", Some(Value::Bool(true))),
        ("x + 1", None),
        ("n / 0", None),
        ("n / 0 > 0", Some(Value::Bool(false))),
        ("s == 3", Some(Value::Bool(false))),
        ("s != 3", Some(Value::Bool(true))),
        ("n && true", Some(Value::Bool(false))),
        ("known(x) || n > 1", Some(Value::Bool(true))),
        ("'B' < 'a'", Some(Value::Bool(true))),
        ("1 + 2 * 3", Some(Value::Num(7.0))),
        ("10 - 4 - 3", Some(Value::Num(3.0))),
        ("8 / 4 / 2", Some(Value::Num(1.0))),
        ("not x == 3", Some(Value::Bool(true))),
    ] {
        assert_eq!(val(src, &set), want, "{src}");
    }
    let mut names = Names::default();
    for src in [
        "box_seen && dist(pos, box_pos) < 0.5",
        "not known(target) || age(target) > 10",
        "elapsed > 30 && runs < 3",
        "colour == \"red\" and abs(heading - goal_heading) <= 0.1",
        "norm(velocity) < 0.05 && (battery < 0.2 || runs(search) == 0)",
        "[pos.x, 0] == [0, 0]",
        "peers_located && not obstacle_near",
        "distance_walked >= 6 || elapsed > 120",
        "10 - dist(pos, box_pos)",
        "a == (!b)",
    ] {
        assert!(Expr::parse(src, &mut names).is_ok(), "{src}");
    }
    for src in ["a == !b", "a < b < c", "until: x", "x # comment"] {
        assert!(parse(src).is_err(), "{src}");
    }
    assert_eq!(parse("elapsed + 1").unwrap().static_type(), Some("number"));
    assert_eq!(parse("arrived").unwrap().static_type(), None);
}

#[test]
fn expr_is_send_sync_and_clone() {
    fn check<T: Send + Sync + Clone + std::fmt::Debug>() {}
    check::<Expr>();
    check::<CondError>();
}

#[test]
fn division_by_zero_and_overflow_are_unknown() {
    assert_eq!(num("1 / 0"), None);
    assert_eq!(num("0 / 0"), None);
    assert_eq!(val("[1, 2] / 0", &[]), None);
    assert!(!holds("1 / 0 > 0", &[]));
    assert!(!holds("1 / 0 != 1", &[]));
    let big = [("x", Value::Num(1e300))];
    assert_eq!(val("x * x", &big), None);
    assert_eq!(val("x * 2", &big), Some(Value::Num(2e300)));
}

#[test]
fn eval_value_returns_text_and_bools() {
    assert_eq!(val("s", &[("s", t("hi"))]), Some(t("hi")));
    assert_eq!(val("'a\\'b\\\"c\\\\d\\n'", &[]), Some(t("a'b\"c\\d\n")));
    assert_eq!(
        val("\"h\u{e9}llo \u{1f916}\"", &[]),
        Some(t("h\u{e9}llo \u{1f916}"))
    );
    assert_eq!(val("1 < 2", &[]), Some(Value::Bool(true)));
    assert_eq!(val("not x", &[]), Some(Value::Bool(true)));
    assert_eq!(val("x && true", &[]), Some(Value::Bool(false)));
}

// ---- metadata -------------------------------------------------------------

#[test]
fn beliefs_are_sorted_and_deduplicated() {
    let mut names = Names::default();
    names.belief("zeta");
    let e = Expr::parse(
        "b > 1 && a.x < b || known(zeta) && age(c) < 2 || elapsed > runs(search) + runs",
        &mut names,
    )
    .unwrap();
    assert_eq!(names.beliefs, ["zeta", "b", "a", "c"]);
    assert_eq!(
        e.beliefs(),
        &[BeliefId(0), BeliefId(1), BeliefId(2), BeliefId(3)]
    );
    let e = Expr::parse("1 + 2 > elapsed", &mut names).unwrap();
    assert!(e.beliefs().is_empty());
}

#[test]
fn failed_parse_interns_nothing() {
    let mut names = Names::default();
    assert!(Expr::parse("alpha && beta &&", &mut names).is_err());
    assert!(names.beliefs.is_empty());
}

#[test]
fn time_and_runs_dependencies() {
    let e = |s: &str| parse(s).unwrap();
    assert!(!e("a && b > 2").depends_on_time());
    assert!(e("elapsed > 10").depends_on_time());
    assert!(e("x || age(y) < 1").depends_on_time());
    assert!(!e("known(y)").depends_on_time());
    assert!(!e("elapsed > 1").depends_on_runs());
    assert!(e("runs < 2").depends_on_runs());
    assert!(e("runs() < 2").depends_on_runs());
    assert!(e("runs(search) < 2").depends_on_runs());
    assert!(!e("search < 2").depends_on_runs());
}

#[test]
fn static_types() {
    let ty = |s: &str| parse(s).unwrap().static_type();
    assert_eq!(ty("a && b"), Some("bool"));
    assert_eq!(ty("not a"), Some("bool"));
    assert_eq!(ty("a < 1"), Some("bool"));
    assert_eq!(ty("known(a)"), Some("bool"));
    assert_eq!(ty("a"), None);
    assert_eq!(ty("(a)"), None);
    assert_eq!(ty("a + 1"), Some("number"));
    assert_eq!(ty("a * 2"), None);
    assert_eq!(ty("a * [1, 2]"), Some("vector"));
    assert_eq!(ty("[a, 2]"), Some("vector"));
    assert_eq!(ty("a.x"), Some("number"));
    assert_eq!(ty("elapsed / 2"), Some("number"));
    assert_eq!(ty("dist(a, b)"), Some("number"));
    assert_eq!(ty("'x'"), Some("text"));
    assert_eq!(ty("-3"), Some("number"));
}

#[test]
fn source_and_display() {
    let e = parse("  a  &&  b ").unwrap();
    assert_eq!(e.source(), "  a  &&  b ");
    assert_eq!(e.to_string(), "  a  &&  b ");
}

// ---- errors -----------------------------------------------------------------

#[test]
fn lexical_errors_with_hints() {
    let e = fails("a & b", 2..3, "unexpected character `&`");
    assert_eq!(hint(&e), "did you mean `&&`?");
    let e = fails("a | b", 2..3, "unexpected character `|`");
    assert_eq!(hint(&e), "did you mean `||`?");
    let e = fails("a = 1", 2..3, "unexpected character `=`");
    assert_eq!(hint(&e), "use `==` to compare");
    let e = fails("a => 1", 2..3, "unexpected character `=`");
    assert_eq!(hint(&e), "did you mean `>=`?");
    let e = fails("a =< 1", 2..3, "unexpected character `=`");
    assert_eq!(hint(&e), "did you mean `<=`?");
    fails("a # b", 2..3, "unexpected character `#`");
    let e = fails("a && \u{e9}t\u{e9}", 5..7, "unexpected character `\u{e9}`");
    assert!(hint(&e).contains("ASCII"));
    let e = fails("x == \u{201c}red\u{201d}", 5..8, "unexpected character");
    assert!(hint(&e).contains("straight quotes"));
    fails("a\u{a0}&& b", 1..3, "unexpected character");
    let e = fails("s == 'red", 5..9, "unterminated string");
    assert_eq!(hint(&e), "close it with `'`");
    fails("s == \"a\\", 5..8, "unterminated string");
    let e = fails("s == 'a\\qb'", 7..9, "unknown escape `\\q`");
    assert!(hint(&e).contains("escapes"));
    fails("s == 'a\\\u{e9}'", 7..10, "unknown escape");
    let e = fails("3x > 1", 0..2, "invalid number `3x`");
    assert_eq!(hint(&e), "a name cannot start with a digit");
    fails("1e > 1", 0..2, "invalid number `1e`");
    fails("1e999 > 1", 0..5, "too large");
}

#[test]
fn syntax_errors() {
    fails("", 0..0, "empty expression");
    fails("   ", 0..3, "empty expression");
    fails(
        "distance >= && x",
        12..14,
        "expected an operand after `>=`, found `&&`",
    );
    fails(
        "a &&",
        4..4,
        "expected an operand after `&&`, found end of expression",
    );
    fails(
        "a and",
        5..5,
        "expected an operand after `and`, found end of expression",
    );
    fails("&& a", 0..2, "expected an expression, found `&&`");
    fails(
        "(a",
        2..2,
        "expected `)` to close the `(` at col 1, found end of expression",
    );
    let e = fails(
        "(a b)",
        3..4,
        "expected `)` to close the `(` at col 1, found `b`",
    );
    assert!(hint(&e).contains("&&"));
    fails("()", 1..2, "expected an expression, found `)`");
    let e = fails("a)", 1..2, "unmatched `)`");
    assert!(e.hint.is_some());
    let e = fails(
        "a b",
        2..3,
        "expected an operator or end of expression, found `b`",
    );
    assert_eq!(hint(&e), "join conditions with `&&` or `||`");
    let e = fails("a AND b", 2..5, "found `AND`");
    assert_eq!(hint(&e), "did you mean `and`? Keywords are lower-case");
    let e = fails("a < b < c", 6..7, "comparison operators cannot be chained");
    assert!(hint(&e).contains("a < b && b < c"));
    fails("a == b != c", 7..9, "cannot be chained");
    let e = fails(
        "a == not b",
        5..8,
        "expected an operand after `==`, found `not`",
    );
    assert!(hint(&e).contains("parentheses"));
    fails("p.z", 2..3, "expected `x` or `y` after `.`, found `z`");
    fails("p.", 2..2, "expected `x` or `y` after `.`");
    fails("[1]", 0..3, "a vector needs two components");
    fails("[1, 2, 3]", 5..6, "a vector has exactly two components");
    fails(
        "[1 2]",
        3..4,
        "expected `,` between vector components, found `2`",
    );
    fails("[1, 2", 5..5, "expected `]` to close the `[` at col 1");
    fails(
        "min(1 2)",
        6..7,
        "expected `,` or `)` in the arguments of `min`",
    );
    fails(
        "x.5",
        1..3,
        "expected an operator or end of expression, found `.5`",
    );
}

#[test]
fn call_errors() {
    let e = fails("foo(1)", 0..3, "unknown function `foo`");
    assert_eq!(
        hint(&e),
        "the functions are abs, min, max, norm, dist, known, age, runs"
    );
    let e = fails("mx(1, 2)", 0..2, "unknown function `mx`");
    assert!(hint(&e).starts_with("did you mean `max`?"), "{e:?}");
    fails("min(1)", 0..6, "`min` takes 2 arguments, found 1");
    fails("abs(1, 2)", 0..9, "`abs` takes 1 argument, found 2");
    fails("dist()", 0..6, "`dist` takes 2 arguments, found 0");
    fails("known(3)", 6..7, "`known` needs a belief name, found `3`");
    fails(
        "age(elapsed)",
        4..11,
        "`age` needs a belief name, found the builtin `elapsed`",
    );
    let e = fails(
        "known(a, b)",
        7..8,
        "expected `)` after the argument of `known`, found `,`",
    );
    assert_eq!(hint(&e), "`known` takes exactly one belief name");
    fails(
        "known(a.x)",
        7..8,
        "expected `)` after the argument of `known`",
    );
    let e = fails("runs(serch) > 1", 5..10, "unknown behavior `serch`");
    assert_eq!(hint(&e), "did you mean `search`?");
    let e = fails("runs(zzzzzz) > 1", 5..11, "unknown behavior `zzzzzz`");
    assert_eq!(e.hint, None);
    fails("runs(1)", 5..6, "`runs` needs a behavior name, found `1`");
    fails(
        "runs(search, push_box)",
        11..12,
        "expected `)` after the argument of `runs`",
    );
    let e = fails("elapsed() > 1", 0..7, "`elapsed` is not a function");
    assert_eq!(hint(&e), "write `elapsed` without parentheses");
}

#[test]
fn type_errors_at_parse_time() {
    let e = fails("!3", 1..2, "`!` needs a boolean operand, found number");
    assert!(hint(&e).contains("x > 0"));
    fails("not 'x'", 4..7, "`not` needs a boolean operand, found text");
    fails("a && 3", 5..6, "`&&` needs a boolean operand, found number");
    fails(
        "1 + 2 || a",
        0..5,
        "`||` needs a boolean operand, found number",
    );
    fails(
        "a and [1, 2]",
        6..12,
        "`and` needs a boolean operand, found vector",
    );
    fails("'a' + 1", 0..3, "cannot apply `+` to text");
    fails("x * true", 4..8, "cannot apply `*` to bool");
    fails("1 + [1, 2]", 0..10, "cannot apply `+` to number and vector");
    fails("[1, 2] - 1", 0..10, "cannot apply `-` to vector and number");
    fails("[1, 2] * [3, 4]", 0..15, "cannot multiply two vectors");
    fails("1 / [1, 2]", 4..10, "cannot divide by a vector");
    fails("-'a'", 1..4, "cannot negate text");
    fails("-(a < b)", 1..8, "cannot negate bool");
    fails("true == 1", 0..9, "cannot compare bool with number");
    fails("'a' != [1, 2]", 0..13, "cannot compare text with vector");
    fails("x < 'a' + 1", 4..7, "cannot apply `+` to text");
    fails("1 < 'a'", 0..7, "cannot compare number with text");
    fails("true < x", 0..4, "`<` cannot order bool values");
    let e = fails("x >= [1, 2]", 5..11, "`>=` cannot order vector values");
    assert!(hint(&e).contains("norm"));
    fails("3.x", 0..1, "`.x` needs a vector, found number");
    fails("(a < b).y", 0..7, "`.y` needs a vector, found bool");
    let e = fails("abs([1, 2])", 4..10, "`abs` needs a number, found vector");
    assert!(hint(&e).contains("norm"));
    fails("norm(3)", 5..6, "`norm` needs a vector, found number");
    fails("dist(a, 'b')", 8..11, "`dist` needs a vector, found text");
    fails("min(a, true)", 7..11, "`min` needs a number, found bool");
    fails(
        "[1, true]",
        4..8,
        "a vector component must be a number, found bool",
    );
    fails("known(a) + 1", 0..8, "cannot apply `+` to bool");
    fails(
        "age(a) && b",
        0..6,
        "`&&` needs a boolean operand, found number",
    );
}

#[test]
fn length_and_token_limits() {
    let ok = format!("a{}", " ".repeat(MAX_SOURCE_LEN - 1));
    assert!(parse(&ok).is_ok());
    let long = format!("a{}", " ".repeat(MAX_SOURCE_LEN));
    let e = fails(
        &long,
        MAX_SOURCE_LEN..MAX_SOURCE_LEN + 1,
        "too long (4097 bytes, limit 4096)",
    );
    assert!(e.hint.is_some());
    // The span stays on a char boundary.
    let long = format!("'{}'", "\u{e9}".repeat(MAX_SOURCE_LEN / 2));
    let e = parse(&long).unwrap_err();
    assert!(long.is_char_boundary(e.span.start));
    assert_eq!(e.span.end, long.len());
    // 1024 tokens: a && a && ... (512 operands, 511 operators) + `&& 1` ...
    let toks = |n: usize| {
        let mut s = String::from("a");
        for _ in 0..(n - 1) / 2 {
            s.push_str("&&a");
        }
        s
    };
    assert!(parse(&toks(1023)).is_ok());
    let src = format!("{}+", toks(1023)); // 1024 tokens, fails later
    assert!(!parse(&src).unwrap_err().message.contains("tokens"));
    let src = format!("{}&&", toks(1023));
    let e = fails(
        &format!("{src}b"),
        1536..1537,
        "too many tokens (limit 1024)",
    );
    assert!(e.hint.is_some());
}

fn depth_of(src: &str) -> Result<(), CondError> {
    parse(src).map(|_| ())
}

#[test]
fn depth_limit() {
    let d = MAX_DEPTH as usize;
    // Parentheses.
    let ok = format!("{}a{}", "(".repeat(d), ")".repeat(d));
    assert!(depth_of(&ok).is_ok());
    let deep = format!("{}a{}", "(".repeat(d + 1), ")".repeat(d + 1));
    let e = fails(&deep, d..d + 1, "expression nests too deeply (limit 64)");
    assert!(e.hint.is_some());
    // Unary chains.
    assert!(depth_of(&format!("{}a", "!".repeat(d))).is_ok());
    fails(
        &format!("{}a", "!".repeat(d + 1)),
        d..d + 1,
        "nests too deeply",
    );
    fails(
        &format!("{}a", "not ".repeat(d + 1)),
        4 * d..4 * d + 3,
        "nests too deeply",
    );
    fails(
        &format!("{}a", "-".repeat(d + 1)),
        d..d + 1,
        "nests too deeply",
    );
    // Brackets and calls.
    let vec = format!("{}a{}", "[".repeat(d + 1), ", 1]".repeat(d + 1));
    fails(&vec, d..d + 1, "nests too deeply");
    let calls = format!("{}a{}", "abs(".repeat(d + 1), ")".repeat(d + 1));
    fails(&calls, 4 * d + 3..4 * d + 4, "nests too deeply");
    // Long left-leaning arithmetic chains count too; && and || chains do not.
    let chain = |n: usize| format!("a{}", " + a".repeat(n));
    assert!(depth_of(&chain(d)).is_ok());
    fails(&chain(d + 1), 0..4 * (d + 1) + 1, "nests too deeply");
    assert!(depth_of(&format!("a{}", " || a".repeat(300))).is_ok());
    // Parentheses around a deep chain add to its depth.
    let e = depth_of(&format!("({})", chain(d))).unwrap_err();
    assert!(e.message.contains("nests too deeply"));
    // No stack overflow on pathological input of the maximum size.
    for unit in ["(", "!", "-", "[", "not ", "abs(", "(-!["] {
        let src = unit.repeat(MAX_SOURCE_LEN / unit.len());
        let e = depth_of(&src).unwrap_err();
        assert!(e.span.end <= src.len(), "{unit}");
    }
}

#[test]
fn display_and_render() {
    let e = parse("distance >= && x").unwrap_err();
    assert_eq!(
        e.to_string(),
        "col 13: expected an operand after `>=`, found `&&`"
    );
    assert_eq!(
        e.render("distance >= && x"),
        "distance >= && x\n            ^^ expected an operand after `>=`, found `&&`"
    );
    let src = "ready & done";
    let e = parse(src).unwrap_err();
    assert_eq!(
        e.to_string(),
        "col 7: unexpected character `&` (did you mean `&&`?)"
    );
    assert_eq!(
        e.render(src),
        "ready & done\n      ^ unexpected character `&`\n      help: did you mean `&&`?"
    );
    // At end of input: one caret after the last character.
    let src = "a &&";
    assert_eq!(
        parse(src).unwrap_err().render(src),
        "a &&\n    ^ expected an operand after `&&`, found end of expression"
    );
    // Multi-byte characters before the span count as one column each.
    let src = "s == '\u{e9}\u{e9}' && = 1";
    let r = parse(src).unwrap_err().render(src);
    assert_eq!(
        r,
        "s == '\u{e9}\u{e9}' && = 1\n             ^ unexpected character `=`\n             help: use `==` to compare"
    );
    // Multi-line sources show the line of the error.
    let src = "a &&\n\tb &&\n\t(c ||)";
    let r = parse(src).unwrap_err().render(src);
    assert_eq!(
        r,
        "line 3:\n\t(c ||)\n\t     ^ expected an operand after `||`, found `)`"
    );
    // Rendering against the wrong source never panics.
    let e = CondError {
        span: 3..99,
        message: "m".into(),
        hint: None,
    };
    assert_eq!(e.render("\u{e9}\u{e9}"), "\u{e9}\u{e9}\n ^ m");
    assert_eq!(e.render(""), "\n^ m");
}

#[test]
fn whitespace_is_free() {
    assert!(holds("\t1<2\n&&\r\n2>1 ", &[]));
    assert!(holds("!(1>2)", &[]));
    assert!(holds("p.x==1", &[("p", Value::Vec2([1.0, 0.0]))]));
    assert!(holds("p . y == 0", &[("p", Value::Vec2([1.0, 0.0]))]));
}

#[test]
fn eval_through_dyn_env() {
    let mut names = Names::default();
    let e = Expr::parse("x > 1", &mut names).unwrap();
    let w = world(&names, &[("x", Value::Num(2.0))]);
    let env: &dyn Env = &w;
    assert!(e.eval(env));
    assert_eq!(e.eval_value(env), Some(Value::Bool(true)));
}

#[test]
fn readable_names_are_what_a_condition_can_name() {
    for ok in ["a", "box_found", "_x", "b2", "runs", "X_1"] {
        assert!(readable_name(ok), "{ok}");
    }
    for bad in [
        "", "a b", "mode-b", "2a", "and", "not", "true", "false", "or", "a.x", " a", "é", "a;",
    ] {
        assert!(!readable_name(bad), "{bad:?}");
    }
}
