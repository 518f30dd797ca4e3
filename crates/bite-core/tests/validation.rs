//! One malformed file per validation rule of behavior graphs, configuration
//! files and mission binding, each checked for its diagnostic code, the
//! exact line and column it points at, and the key words of its message and
//! hint. The files live in `tests/fixtures/`; their first line is a comment
//! naming the rule, so line numbers below count it.
//!

use bite_core::diag::{Diagnostic, Diagnostics, Severity};
use bite_core::graph::{BehaviorGraph, Config, load, load_str};
use bite_core::interaction::{Factory, Params, Protocol, Registry};
use bite_core::msg::Kind;
use bite_core::{BehaviorId, Mission};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// `(name, text)` of a fixture file, compiled into the test binary.
macro_rules! fixture {
    ($f:literal) => {
        (
            concat!("fixtures/", $f),
            include_str!(concat!("fixtures/", $f)),
        )
    };
}

const FORMATION: (&str, &str) = (
    "examples/formation.yaml",
    include_str!("../../../examples/formation.yaml"),
);

type Src = (&'static str, &'static str);

fn try_graph(name: &str, text: &str) -> Result<BehaviorGraph, Diagnostics> {
    load_str(&Arc::from(name), text)
}

/// A graph that must load; its warnings must print well too.
fn graph_ok(name: &str, text: &str) -> BehaviorGraph {
    match try_graph(name, text) {
        Ok(g) => {
            check_display(g.warnings());
            g
        }
        Err(e) => panic!("`{name}` should load, but:\n{e}"),
    }
}

/// The diagnostics of a graph that must be rejected.
fn graph_err(name: &str, text: &str) -> Diagnostics {
    match try_graph(name, text) {
        Ok(g) => panic!("`{name}` should be rejected, but it loaded: {g}"),
        Err(e) => {
            check_display(&e.0);
            e
        }
    }
}

fn fixture_err(src: Src) -> Diagnostics {
    graph_err(src.0, src.1)
}

fn formation() -> BehaviorGraph {
    graph_ok(FORMATION.0, FORMATION.1)
}

/// The diagnostics of applying a configuration to the formation graph.
fn config_err(src: Src) -> Diagnostics {
    let result = Config::load_str(&Arc::from(src.0), src.1)
        .and_then(|cfg| formation().with_config(&cfg).map(|_| ()));
    match result {
        Ok(()) => panic!("configuration `{}` should be rejected", src.0),
        Err(e) => {
            check_display(&e.0);
            e
        }
    }
}

/// The diagnostics of resolving the bindings of a graph that loads.
fn mission_err(src: Src, registry: &Registry) -> Diagnostics {
    let g = graph_ok(src.0, src.1);
    match Mission::new(g, registry) {
        Ok(_) => panic!("mission `{}` should be rejected", src.0),
        Err(e) => {
            check_display(&e.0);
            e
        }
    }
}

/// Every diagnostic prints as `file:line:col: severity[code]: message`.
fn check_display(ds: &[Diagnostic]) {
    for d in ds {
        assert!(d.loc.is_known(), "diagnostic without a location:\n{d}");
        let sev = match d.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        let want = format!(
            "{}:{}:{}: {sev}[{}]: {}",
            d.file, d.loc.line, d.loc.col, d.code, d.message
        );
        let shown = d.to_string();
        assert!(
            shown.starts_with(&want),
            "Display should start with {want:?}, got {shown:?}"
        );
        if let Some(h) = &d.hint {
            assert!(
                shown.ends_with(&format!("\n  hint: {h}")),
                "hint not shown: {shown:?}"
            );
        }
    }
}

/// The one diagnostic with `code` (the others are listed if it is missing).
fn one<'a>(ds: &'a [Diagnostic], code: &str) -> &'a Diagnostic {
    let found: Vec<&Diagnostic> = ds.iter().filter(|d| d.code == code).collect();
    assert_eq!(
        found.len(),
        1,
        "expected exactly one `{code}` diagnostic, got:\n{}",
        Diagnostics(ds.to_vec())
    );
    found[0]
}

fn at(d: &Diagnostic, line: u32, col: u32) {
    assert_eq!(
        (d.loc.line, d.loc.col),
        (line, col),
        "wrong position (want {line}:{col}) for:\n{d}"
    );
}

fn says(d: &Diagnostic, words: &[&str]) {
    for w in words {
        assert!(d.message.contains(w), "message should contain {w:?}:\n{d}");
    }
}

fn hints(d: &Diagnostic, words: &[&str]) {
    let h = d
        .hint
        .as_deref()
        .unwrap_or_else(|| panic!("expected a hint:\n{d}"));
    for w in words {
        assert!(h.contains(w), "hint should contain {w:?}:\n{d}");
    }
}

fn is_error(d: &Diagnostic) {
    assert_eq!(d.severity, Severity::Error, "should be an error:\n{d}");
}

fn is_warning(d: &Diagnostic) {
    assert_eq!(d.severity, Severity::Warning, "should be a warning:\n{d}");
}

/// `b0` with a chain of `levels` nested children below it.
fn nested_chain(levels: usize) -> String {
    let mut s = String::from("start: b0\nbehaviors:\n");
    for i in 0..levels {
        s.push_str(&format!("  b{i}:\n    children: [b{}]\n", i + 1));
    }
    s.push_str(&format!("  b{levels}: {{}}\n"));
    s
}

/// Stand-in for `term.wait-all` (from `bite-protocols`, which bite-core
/// does not depend on): behaves like `term.local`, which is all binding
/// resolution needs.
struct WaitAllStandIn;

impl Protocol for WaitAllStandIn {
    fn name(&self) -> &'static str {
        "term.wait-all"
    }
    fn kind(&self) -> Kind {
        Kind::Terminate
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "test stand-in for term.wait-all"
    }
    fn configure(
        &self,
        params: &Params,
        setup: &mut bite_core::interaction::Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        bite_core::rules::TermLocal.configure(params, setup)
    }
}

/// Stand-in for `term.first-wins`, as [`WaitAllStandIn`] is for wait-all.
struct FirstWinsStandIn;

impl Protocol for FirstWinsStandIn {
    fn name(&self) -> &'static str {
        "term.first-wins"
    }
    fn kind(&self) -> Kind {
        Kind::Terminate
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "test stand-in for term.first-wins"
    }
    fn configure(
        &self,
        params: &Params,
        setup: &mut bite_core::interaction::Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        bite_core::rules::TermLocal.configure(params, setup)
    }
}

fn registry() -> Registry {
    let mut r = Registry::core();
    r.register(Arc::new(WaitAllStandIn));
    r.register(Arc::new(FirstWinsStandIn));
    r
}

fn id(g: &BehaviorGraph, name: &str) -> BehaviorId {
    g.find(name)
        .unwrap_or_else(|| panic!("behavior `{name}` not found"))
}

// ----- YAML shape -----------------------------------------------------------

#[test]
fn yaml_syntax_error_has_position_and_snippet() {
    let e = fixture_err(fixture!("yaml-syntax.yaml"));
    let d = one(&e.0, "yaml");
    is_error(d);
    //   a: {team: true}}
    //                  ^ column 18
    at(d, 4, 18);
    says(d, &["misplaced bracket"]);
    assert!(
        !d.message.contains("line 4"),
        "location repeated in message: {d}"
    );
    let detail = d.detail.as_deref().unwrap_or("");
    assert!(
        detail.contains("a: {team: true}}"),
        "the detail should show the offending line:\n{detail}"
    );
}

#[test]
fn unknown_field_lists_the_expected_keys() {
    let e = fixture_err(fixture!("unknown-field.yaml"));
    let d = one(&e.0, "yaml");
    //     nxt: [b]
    at(d, 5, 5);
    says(d, &["unknown key `nxt`"]);
    hints(d, &["did you mean `next`?"]);
}

#[test]
fn unknown_top_level_field() {
    let e = graph_err("t.yaml", "start: a\nbehaviours:\n  a: {}\n");
    let d = one(&e.0, "yaml");
    at(d, 2, 1);
    says(d, &["unknown key `behaviours`"]);
    hints(d, &["did you mean `behaviors`?"]);
}

#[test]
fn duplicate_behavior_name_is_a_duplicate_key() {
    let e = fixture_err(fixture!("duplicate-behavior.yaml"));
    let d = one(&e.0, "yaml");
    // The second `walk:`.
    at(d, 7, 3);
    says(d, &["`walk` is defined twice"]);
    hints(d, &["names must be unique"]);
}

#[test]
fn duplicate_behavior_message_speaks_to_users() {
    let e = fixture_err(fixture!("duplicate-behavior.yaml"));
    let d = one(&e.0, "yaml");
    assert!(
        !d.message.contains("DuplicateKeyPolicy") && !d.message.contains("Options"),
        "message leaks a library setting the user cannot change:\n{d}"
    );
    says(d, &["walk"]);
}

#[test]
fn members_errors() {
    for (members, words) in [
        ("0", &["at least one member"][..]),
        (
            "3..1",
            &["`members: 3..1`", "maximum below its minimum"][..],
        ),
        ("x", &["expected a member count", "`2..4`", "found `x`"][..]),
    ] {
        let text = format!(
            "start: p\nbehaviors:\n  p:\n    children: [x, y]\n  x:\n    members: {members}\n  y: {{}}\n"
        );
        let e = graph_err("members.yaml", &text);
        let d = one(&e.0, "yaml");
        //     members: 0
        //              ^ column 14
        at(d, 6, 14);
        says(d, words);
    }
}

#[test]
fn members_ranges_parse() {
    let text = "start: p\nbehaviors:\n  p:\n    children: [a, b, c, d]\n  a: { members: 2 }\n  b: { members: \"2..4\" }\n  c: { members: 2.. }\n  d: { members: 2..=4 }\n";
    let g = graph_ok("members.yaml", text);
    let m = |n| g.behavior(id(&g, n)).members;
    assert_eq!(m("a"), (2, 2));
    assert_eq!(m("b"), (2, 4));
    assert_eq!(m("c"), (2, u32::MAX));
    assert_eq!(m("d"), (2, 4));
    assert!(g.warnings().is_empty(), "{:?}", g.warnings());
}

// ----- behaviors and edges --------------------------------------------------

#[test]
fn no_behaviors_section() {
    let e = fixture_err(fixture!("no-behaviors.yaml"));
    let d = one(&e.0, "no-behaviors");
    at(d, 1, 1);
    says(d, &["no `behaviors:` section"]);
}

#[test]
fn empty_behaviors_section() {
    let e = fixture_err(fixture!("no-behaviors-empty.yaml"));
    let d = one(&e.0, "no-behaviors");
    // behaviors: {}
    //            ^ column 12
    at(d, 4, 12);
    says(d, &["`behaviors:` is empty"]);
}

/// A robot's name is a chunk of its network keys and its log's file
/// name: an empty one, or one with `/` or `*`, is refused where it is.
#[test]
fn bad_robot_names() {
    for bad in ["\"\"", "\"r/1\"", "\"r*\"", "\"two words\""] {
        let text = format!(
            "graph: g\nteam:\n  robots:\n    - {{ name: r0 }}\n    - {{ name: {bad} }}\nbehaviors:\n  a: {{ team: true }}\n"
        );
        let e = graph_err("robots.yaml", &text);
        let d = one(&e.0, "bad-name");
        at(d, 5, 7);
        says(d, &["is not a valid robot name"]);
    }
}

#[test]
fn bad_behavior_name() {
    let e = fixture_err(fixture!("bad-name.yaml"));
    let d = one(&e.0, "bad-name");
    // The definition `2go:`, not the reference in `next`.
    at(d, 6, 3);
    says(
        d,
        &[
            "`2go` is not a valid behavior name",
            "starting with a letter",
        ],
    );
}

#[test]
fn unknown_reference_in_children() {
    let e = fixture_err(fixture!("unknown-reference-children.yaml"));
    let d = one(&e.0, "unknown-reference");
    //     children: [leader, folower]
    //                        ^ column 24
    at(d, 5, 24);
    says(
        d,
        &[
            "`team` names `folower` as a child",
            "no behavior is called `folower`",
        ],
    );
    hints(d, &["did you mean `follower`?"]);
}

#[test]
fn unknown_reference_in_next() {
    let e = fixture_err(fixture!("unknown-reference-next.yaml"));
    let d = one(&e.0, "unknown-reference");
    //     next: [walk, linewalk]
    //                  ^ column 18
    at(d, 5, 18);
    says(d, &["`search` names `linewalk` as a successor"]);
    hints(d, &["did you mean `line_walk`?"]);
}

#[test]
fn unknown_reference_in_start() {
    let e = fixture_err(fixture!("unknown-reference-start.yaml"));
    let d = one(&e.0, "unknown-reference");
    // start: serach
    //        ^ column 8
    at(d, 2, 8);
    says(d, &["start behavior `serach` is not defined"]);
    hints(d, &["did you mean `search`?"]);
}

#[test]
fn duplicate_edge() {
    let e = fixture_err(fixture!("duplicate-edge.yaml"));
    let d = one(&e.0, "duplicate-edge");
    //     next: [b, c, b]
    //                  ^ column 18: the second `b`
    at(d, 5, 18);
    says(d, &["`b` is listed twice as a successor of `a`"]);
}

#[test]
fn sequential_and_decomposition_edge() {
    let e = fixture_err(fixture!("sequential-and-decomposition.yaml"));
    let d = one(&e.0, "sequential-and-decomposition");
    //     children: [b, c]
    //                   ^ column 19
    at(d, 5, 19);
    says(
        d,
        &[
            "`c` is both a child and a sequential successor of `a`",
            "S ∩ V",
        ],
    );
    hints(d, &["either `children`", "or `next`"]);
}

#[test]
fn sequential_and_decomposition_is_reported_once() {
    let e = fixture_err(fixture!("sequential-and-decomposition.yaml"));
    assert_eq!(e.errors().count(), 1, "one mistake, one error:\n{e}");
}

#[test]
fn missing_start_names_the_roots() {
    let e = fixture_err(fixture!("missing-start.yaml"));
    let d = one(&e.0, "missing-start");
    at(d, 1, 1);
    says(d, &["no `start:` behavior"]);
    hints(
        d,
        &["add `start: mission`", "nothing leads to: mission, spare"],
    );
}

#[test]
fn decomposition_cycle_lists_the_path() {
    let e = fixture_err(fixture!("decomposition-cycle.yaml"));
    let d = one(&e.0, "decomposition-cycle");
    // The edge that closes the cycle, in `c`:
    //     children: [a]
    //                ^ column 16
    at(d, 9, 16);
    says(
        d,
        &["decomposition cycle: a → b → c → a", "its own ancestor"],
    );
    hints(d, &["`next`"]);
}

#[test]
fn decomposition_self_cycle() {
    let e = graph_err(
        "self.yaml",
        "start: a\nbehaviors:\n  a:\n    children: [a]\n",
    );
    let d = one(&e.0, "decomposition-cycle");
    at(d, 4, 16);
    says(d, &["a → a"]);
}

#[test]
fn loop_back_to_an_ancestor_is_refused_at_the_next_entry() {
    let e = fixture_err(fixture!("loop-to-ancestor.yaml"));
    let d = one(&e.0, "loop-to-ancestor");
    // The `next` entry that closes the loop, in `work`:
    //     next: [mission]
    //            ^ column 12
    at(d, 8, 12);
    says(
        d,
        &[
            "`work` -> `mission` loops back to an ancestor",
            "`mission` is an ancestor of `work` (mission > work)",
            "1 level deeper",
        ],
    );
    hints(d, &["same level"]);
}

#[test]
fn loop_to_an_ancestor_names_the_whole_loop() {
    // Two levels down, through a sibling's chain: `a > b -> c > d`, then
    // `d -> a`.
    let e = graph_err(
        "deep-loop.yaml",
        "start: a\nbehaviors:\n  a:\n    children: [b]\n  b:\n    next: [c]\n  c:\n    children: [d]\n  d:\n    next: [e, a]\n  e: {}\n",
    );
    let d = one(&e.0, "loop-to-ancestor");
    at(d, 10, 15);
    says(d, &["`d` -> `a`", "(a > b -> c > d)", "2 levels deeper"]);
    // The loop closes at a behavior's own level: legal.
    graph_ok(
        "level-loop.yaml",
        "start: a\nbehaviors:\n  a:\n    children: [b]\n    next: [a]\n  b:\n    next: [c]\n  c:\n    next: [b]\n",
    );
}

#[test]
fn sequential_cycles_among_siblings_stay_legal() {
    graph_ok(
        "patrol-loop.yaml",
        "start: mission\nbehaviors:\n  mission:\n    team: true\n    children: [a]\n  a:\n    next: [b]\n  b:\n    next: [a, c]\n  c: {}\n",
    );
}

#[test]
fn a_long_loop_to_an_ancestor_is_found_and_shown_by_its_ends() {
    // 100,000 behaviors: `top > c0 -> c1 -> ... -> c99998 -> top`.
    let n = 99_999;
    let mut text = String::from("start: top\nbehaviors:\n  top:\n    children: [c0]\n");
    for i in 0..n - 1 {
        text.push_str(&format!("  c{i}: {{next: [c{}]}}\n", i + 1));
    }
    text.push_str(&format!("  c{}: {{next: [top]}}\n", n - 1));
    let e = graph_err("long-loop.yaml", &text);
    let d = one(&e.0, "loop-to-ancestor");
    says(
        d,
        &[
            &format!("`c{}` -> `top`", n - 1),
            "(top > c0 -> c1",
            &format!("({} more)", n - 12),
            &format!("-> c{})", n - 1),
        ],
    );
}

#[test]
fn depth_counts_levels_reached_through_next() {
    // `top > x -> y`, and 64 levels of decomposition below `y`: `y` runs
    // one level below `top`, so the stack can be 65 levels deep.
    let mut text = String::from(
        "start: top\nbehaviors:\n  top:\n    children: [x]\n  x:\n    next: [y]\n  y:\n    children: [b0]\n",
    );
    let chain = nested_chain(63);
    text.push_str(chain.split_once("behaviors:\n").map_or("", |(_, b)| b));
    let e = graph_err("deep-via-next.yaml", &text);
    let d = one(&e.0, "too-deep");
    at(d, 3, 3);
    says(
        d,
        &[
            "decomposition below `top` is 65 levels deep",
            "the limit is 64",
        ],
    );
}

#[test]
fn child_entered_from_a_sibling_chain() {
    let e = fixture_err(fixture!("child-not-chain-head.yaml"));
    let d = one(&e.0, "child-not-chain-head");
    //     children: [x, y]
    //                   ^ column 19
    at(d, 6, 19);
    says(
        d,
        &[
            "`y` is a child of `p`",
            "head an execution chain",
            "`x` leads into it sequentially",
        ],
    );
    hints(d, &["remove `y` from the `next` of `x`"]);
}

#[test]
fn child_not_chain_head_hint_is_applicable() {
    let e = fixture_err(fixture!("child-not-chain-head.yaml"));
    let d = one(&e.0, "child-not-chain-head");
    hints(d, &["remove `y` from the `next` of `x`"]);
    let h = d.hint.as_deref().unwrap_or("");
    assert!(
        !h.contains("make `x` the child"),
        "`x` is already a child of `p`: {h}"
    );
}

#[test]
fn sequential_cycle_back_to_the_chain_head_is_legal() {
    let (name, text) = fixture!("sequential-cycle-ok.yaml");
    let g = graph_ok(name, text);
    assert!(g.warnings().is_empty(), "{:?}", g.warnings());
    assert_eq!(g.name(), "patrol");
    assert_eq!(g.roster().len(), 2);
    assert_eq!(g.initial_beliefs().len(), 2);
    let (patrol, report) = (id(&g, "patrol"), id(&g, "report"));
    assert_eq!(g.behavior(report).next, vec![patrol, id(&g, "home")]);
    assert!(g.is_sync_point(report), "report chooses patrol or home");
    let names: Vec<String> = g.points().into_iter().map(|p| p.name).collect();
    assert_eq!(
        names,
        [
            "mission.terminate",
            "patrol.terminate",
            "report.sync",
            "report.terminate",
            "home.terminate"
        ]
    );
}

// ----- conditions -----------------------------------------------------------

#[test]
fn bad_condition_in_a_plain_scalar_points_at_the_token() {
    let e = fixture_err(fixture!("bad-condition-plain.yaml"));
    let d = one(&e.0, "bad-condition");
    //     pre: ready && >= 3
    //                   ^ column 19
    at(d, 5, 19);
    says(
        d,
        &["in `pre`", "expected an operand after `&&`, found `>=`"],
    );
    let detail = d.detail.as_deref().unwrap_or("");
    assert!(
        detail.contains("ready && >= 3") && detail.contains("^^"),
        "{detail}"
    );
}

#[test]
fn bad_condition_in_a_quoted_scalar_points_at_the_token() {
    let e = fixture_err(fixture!("bad-condition-quoted.yaml"));
    let d = one(&e.0, "bad-condition");
    //     until: "ready & done"
    //                   ^ column 19
    at(d, 5, 19);
    says(d, &["in `until`", "unexpected character `&`"]);
    hints(d, &["did you mean `&&`?"]);
}

#[test]
fn bad_condition_in_a_folded_scalar_reports_its_line() {
    let e = fixture_err(fixture!("bad-condition-folded.yaml"));
    let d = one(&e.0, "bad-condition");
    //       oops(3)     (line 8)
    at(d, 8, 7);
    says(d, &["in `until`", "unknown function `oops`"]);
    hints(d, &["the functions are"]);
}

#[test]
fn bad_condition_in_a_folded_scalar_with_a_repeated_token() {
    let e = fixture_err(fixture!("bad-condition-folded-repeat.yaml"));
    let d = one(&e.0, "bad-condition");
    //       distance >= && done     (line 7)
    //                   ^ column 19
    at(d, 7, 19);
}

#[test]
fn bad_condition_in_a_multi_line_plain_scalar() {
    let text = "start: a\nbehaviors:\n  a:\n    until: ready &&\n      oops(3)\n";
    let e = graph_err("plain2.yaml", text);
    let d = one(&e.0, "bad-condition");
    at(d, 5, 7);
}

#[test]
fn bad_condition_unknown_behavior_in_runs() {
    let text =
        "start: a\nbehaviors:\n  a:\n    next: [walk]\n    until: runs(wlk) > 1\n  walk: {}\n";
    let e = graph_err("runs.yaml", text);
    let d = one(&e.0, "bad-condition");
    //     until: runs(wlk) > 1
    //                 ^ column 17
    at(d, 5, 17);
    says(d, &["unknown behavior `wlk`"]);
    hints(d, &["did you mean `walk`?"]);
}

#[test]
fn condition_of_the_wrong_type() {
    let e = fixture_err(fixture!("condition-type.yaml"));
    let d = one(&e.0, "condition-type");
    //     until: 3 + 4
    //            ^ column 12
    at(d, 5, 12);
    says(
        d,
        &["`until` must be a bool expression", "`3 + 4` is a number"],
    );

    let e = fixture_err(fixture!("condition-type-utility.yaml"));
    let d = one(&e.0, "condition-type");
    at(d, 5, 14);
    says(d, &["`utility` must be a number expression", "is a bool"]);
}

// ----- bindings, points, team, beliefs --------------------------------------

#[test]
fn bad_duration_in_a_binding() {
    let e = fixture_err(fixture!("bad-duration.yaml"));
    let d = one(&e.0, "bad-duration");
    //     terminate: { protocol: term.local, deadline: 5 parsecs }
    //                                                  ^ column 50
    at(d, 6, 50);
    says(
        d,
        &[
            "`deadline`",
            "unknown duration unit `parsecs`",
            "`5 parsecs`",
        ],
    );
}

#[test]
fn bad_duration_in_a_block_binding_points_at_the_value() {
    let e = fixture_err(fixture!("bad-duration-block.yaml"));
    let d = one(&e.0, "bad-duration");
    //       deadline: 5 parsecs     (line 8)
    //                 ^ column 17
    at(d, 8, 17);
}

#[test]
fn bad_duration_in_defaults() {
    let e = fixture_err(fixture!("bad-duration-retry.yaml"));
    let d = one(&e.0, "bad-duration");
    // The `-1s` value itself.
    at(d, 4, 18);
    says(d, &["`retry`", "non-negative", "`-1s`"]);
}

#[test]
fn durations_accept_units_and_bare_seconds() {
    let text = "defaults:\n  terminate: { protocol: term.local, deadline: 1.5min, retry: 250ms }\n  sync: { deadline: 3, retry: 0.5 }\nstart: a\nbehaviors:\n  a: { team: true }\n";
    let g = graph_ok("d.yaml", text);
    let t = g
        .default_binding(Kind::Terminate)
        .expect("default terminate binding");
    assert_eq!(t.deadline, Some(Duration::from_secs(90)));
    assert_eq!(t.retry, Some(Duration::from_millis(250)));
    let s = g.default_binding(Kind::Sync).expect("default sync binding");
    assert_eq!(s.deadline, Some(Duration::from_secs(3)));
    assert_eq!(s.retry, Some(Duration::from_millis(500)));
}

#[test]
fn duplicate_point_label() {
    let e = fixture_err(fixture!("duplicate-point.yaml"));
    let d = one(&e.0, "duplicate-point");
    //     allocate: { point: A }    (the second use; the label itself)
    at(d, 11, 24);
    says(d, &["point label `A` is used by `search` and `walk`"]);
}

#[test]
fn bad_point_label() {
    let e = fixture_err(fixture!("bad-point-label.yaml"));
    let d = one(&e.0, "bad-name");
    // The label itself.
    at(d, 6, 25);
    says(d, &["point label `end of a`"]);
}

#[test]
fn default_binding_with_a_point_label() {
    let e = fixture_err(fixture!("default-with-point.yaml"));
    let d = one(&e.0, "bad-binding");
    // The label itself.
    at(d, 4, 42);
    says(d, &["default binding cannot carry a `point` label"]);
}

#[test]
fn empty_team() {
    let e = fixture_err(fixture!("empty-team.yaml"));
    let d = one(&e.0, "empty-team");
    //   robots: 0
    //           ^ column 11
    at(d, 3, 11);
    says(d, &["at least one robot"]);

    let e = graph_err(
        "t.yaml",
        "team:\n  robots: []\nstart: a\nbehaviors:\n  a: {}\n",
    );
    at(one(&e.0, "empty-team"), 2, 11);
}

#[test]
fn negative_team_size() {
    let e = graph_err(
        "t.yaml",
        "team:\n  robots: -2\nstart: a\nbehaviors:\n  a: {}\n",
    );
    let d = one(&e.0, "yaml");
    at(d, 2, 11);
    says(d, &["cannot be negative"]);
}

#[test]
fn duplicate_robot() {
    let e = fixture_err(fixture!("duplicate-robot.yaml"));
    let d = one(&e.0, "duplicate-robot");
    //     - name: r1     (the third robot)
    //       ^ column 7
    at(d, 7, 7);
    says(d, &["robot `r1` is listed twice"]);
}

#[test]
fn robot_attribute_must_be_a_value() {
    let text = "team:\n  robots:\n    - name: r1\n      attributes: { pos: { x: 1 } }\nstart: a\nbehaviors:\n  a: {}\n";
    let e = graph_err("attr.yaml", text);
    let d = one(&e.0, "bad-value");
    at(d, 3, 7);
    says(
        d,
        &[
            "attribute `pos` of robot `r1`",
            "bool, number, text or [x, y]",
        ],
    );
}

#[test]
fn initial_belief_that_is_a_map() {
    let e = fixture_err(fixture!("bad-value-belief.yaml"));
    let d = one(&e.0, "bad-value");
    //   home: { x: 1, y: 2 }
    //         ^ column 9
    at(d, 5, 9);
    says(
        d,
        &["initial belief `home`", "bool, number, text or [x, y]"],
    );
}

// ----- limits ---------------------------------------------------------------

#[test]
fn decomposition_too_deep() {
    let e = graph_err("deep.yaml", &nested_chain(70));
    let d = one(&e.0, "too-deep");
    // The top of the too-deep decomposition: `b0:` on line 3.
    at(d, 3, 3);
    says(d, &["decomposition below `b0`", "the limit is 64"]);
}

#[test]
fn decomposition_depth_limit_counts_levels() {
    // MAX_DEPTH is documented as "levels below the start behavior".
    graph_ok("deep64.yaml", &nested_chain(64));
    let e = graph_err("deep65.yaml", &nested_chain(65));
    says(one(&e.0, "too-deep"), &["65 levels deep"]);
    let e = graph_err("deep70.yaml", &nested_chain(70));
    says(one(&e.0, "too-deep"), &["70 levels deep"]);
}

#[test]
fn decomposition_just_under_the_limit_loads() {
    graph_ok("deep63.yaml", &nested_chain(63));
}

#[test]
fn yaml_nesting_budget() {
    let mut text = String::from("start: a\nbeliefs:\n  x: ");
    text.push_str(&"[".repeat(70));
    text.push_str(&"]".repeat(70));
    text.push_str("\nbehaviors:\n  a: {}\n");
    let e = graph_err("nest.yaml", &text);
    let d = one(&e.0, "yaml");
    assert_eq!(d.loc.line, 3, "{d}");
    says(d, &["exceeds a limit", "nesting deeper than 64 levels"]);
}

#[test]
fn file_too_large() {
    let text = "#".repeat(16 * 1024 * 1024 + 1);
    let e = try_graph("big.yaml", &text).expect_err("a file over 16 MiB is rejected");
    let d = one(&e.0, "too-large");
    assert!(!d.loc.is_known());
    says(d, &["16777217 bytes", "the limit is 16777216"]);
    assert_eq!(
        d.to_string(),
        "big.yaml: error[too-large]: file is 16777217 bytes; the limit is 16777216"
    );
}

#[test]
fn too_many_robots() {
    let e = graph_err(
        "t.yaml",
        "team:\n  robots: 1000001\nstart: a\nbehaviors:\n  a: {}\n",
    );
    let d = one(&e.0, "too-large");
    at(d, 2, 11);
    says(d, &["1000001 robots", "the limit is 1000000"]);
}

#[test]
fn too_many_behaviors() {
    let mut text = String::from("start: b0\nbehaviors:\n");
    for i in 0..100_001 {
        text.push_str(&format!("  b{i}: {{}}\n"));
    }
    let e = graph_err("many.yaml", &text);
    let d = one(&e.0, "too-large");
    at(d, 3, 3);
    says(d, &["100001 behaviors", "the limit is 100000"]);
}

#[test]
fn large_graph_under_the_behavior_limit_loads() {
    let n = 95_000;
    let mut text = String::from("start: b0\nbehaviors:\n");
    for i in 0..n {
        text.push_str(&format!(
            "  b{i}: {{team: true, next: [b{}], until: done}}\n",
            (i + 1) % n
        ));
    }
    assert!(text.len() < 16 * 1024 * 1024);
    let g = graph_ok("many.yaml", &text);
    assert_eq!(g.len(), n);
}

// ----- warnings -------------------------------------------------------------

#[test]
fn unreachable_behavior_is_a_warning() {
    let (name, text) = fixture!("unreachable.yaml");
    let g = graph_ok(name, text);
    let d = one(g.warnings(), "unreachable");
    is_warning(d);
    at(d, 5, 3);
    says(d, &["`lost` can never run", "from `a`"]);
    assert!(
        d.to_string()
            .starts_with("fixtures/unreachable.yaml:5:3: warning[unreachable]: ")
    );
}

#[test]
fn initial_belief_no_condition_can_read_is_a_warning() {
    let (name, text) = fixture!("unreadable-belief.yaml");
    let g = graph_ok(name, text);
    let ws: Vec<&Diagnostic> = (g.warnings().iter())
        .filter(|d| d.code == "unreadable-belief")
        .collect();
    assert_eq!(ws.len(), 2, "{:?}", g.warnings());
    is_warning(ws[0]);
    at(ws[0], 4, 3);
    says(ws[0], &["`box found`", "no condition can read"]);
    // A condition reads the name with `_`: the hint names it.
    let hint = ws[0].hint.as_deref().unwrap_or("");
    assert!(hint.contains("did you mean `box_found`"), "{hint}");
    at(ws[1], 5, 3);
    let hint = ws[1].hint.as_deref().unwrap_or("");
    assert!(hint.contains("letters, digits and `_`"), "{hint}");
    // `ready` is a name a condition reads: no warning for it.
    assert!(!(ws.iter()).any(|d| d.message.contains("`ready`")));
}

#[test]
fn binding_on_a_behavior_that_is_no_point_is_a_warning() {
    let (name, text) = fixture!("binding-unused.yaml");
    let g = graph_ok(name, text);
    let d = one(g.warnings(), "binding-unused");
    is_warning(d);
    //     sync: sync.by-rule
    //           ^ column 11
    at(d, 6, 11);
    says(
        d,
        &[
            "`a` binds a synchronization protocol",
            "not a synchronization point",
            "0 team successor(s)",
            "two or more",
        ],
    );
    // An unused binding does not stop the mission.
    Mission::new(g, &registry()).expect("the unused binding is ignored");
}

#[test]
fn binding_unused_for_each_kind() {
    let text = "start: a\nbehaviors:\n  a:\n    children: [b]\n    allocate: alloc.by-id\n    terminate: term.local\n  b: {}\n";
    let g = graph_ok("u.yaml", text);
    let ws: Vec<&Diagnostic> = g
        .warnings()
        .iter()
        .filter(|d| d.code == "binding-unused")
        .collect();
    assert_eq!(ws.len(), 2, "{:?}", g.warnings());
    at(ws[0], 5, 15);
    says(
        ws[0],
        &[
            "binds an allocation protocol",
            "not an allocation point",
            "1 child(ren)",
            "two or more",
        ],
    );
    at(ws[1], 6, 16);
    says(
        ws[1],
        &[
            "not a termination point",
            "not a team behavior",
            "team: true",
        ],
    );
}

#[test]
fn members_on_a_child_that_is_never_allocated_is_a_warning() {
    let (name, text) = fixture!("members-unused.yaml");
    let g = graph_ok(name, text);
    let d = one(g.warnings(), "members-unused");
    is_warning(d);
    //     members: 2
    //              ^ column 14
    at(d, 7, 14);
    says(
        d,
        &["`b` sets `members`", "never a child of an allocation point"],
    );
}

// ----- configuration files --------------------------------------------------

#[test]
fn config_unknown_point() {
    let e = config_err(fixture!("config-unknown-point.yaml"));
    let d = one(&e.0, "unknown-point");
    at(d, 5, 3);
    says(
        d,
        &["`search.termnate` is not a point of graph `formation`"],
    );
    hints(d, &["did you mean `search.terminate`?"]);
}

/// A point answers to its label and to `behavior.kind`: binding two of
/// its names in one file is an error at the second (the last one won,
/// silently).
#[test]
fn config_binds_one_point_under_two_names() {
    let e = config_err(fixture!("config-duplicate-binding.yaml"));
    let dups: Vec<_> =
        e.0.iter()
            .filter(|d| d.code == "duplicate-binding")
            .collect();
    assert_eq!(dups.len(), 2, "{e}");
    at(dups[0], 5, 3);
    says(
        dups[0],
        &["`search.sync` is the point `A` bound at line 4 already"],
    );
    at(dups[1], 7, 3);
    says(
        dups[1],
        &["`walk.alloc` is the point `C` bound at line 6 already"],
    );
}

#[test]
fn config_unknown_point_suggests_behavior_kind_of_a_labelled_point() {
    let e = config_err(fixture!("config-unknown-point-labelled.yaml"));
    let d = one(&e.0, "unknown-point");
    at(d, 3, 3);
    hints(d, &["did you mean `walk.sync`?"]);
}

#[test]
fn config_unknown_point_without_a_close_name_lists_the_points() {
    let e = config_err(("q.yaml", "bindings:\n  Q: sync.by-rule\n"));
    let d = one(&e.0, "unknown-point");
    at(d, 2, 3);
    hints(d, &["the points are:", "A", "walk.terminate", "E"]);
}

#[test]
fn config_binds_a_point_of_the_wrong_kind() {
    let e = config_err(fixture!("config-not-a-point.yaml"));
    let d = one(&e.0, "not-a-point");
    at(d, 3, 3);
    says(
        d,
        &["`lead.sync` is not a synchronization point of graph `formation`"],
    );
    hints(d, &["the points are:", "search.terminate", "C"]);
}

#[test]
fn config_cannot_relabel_points() {
    let e = config_err(fixture!("config-bad-binding.yaml"));
    let d = one(&e.0, "bad-binding");
    //   A: { protocol: sync.by-rule, point: Z }
    //                                       ^ column 39
    at(d, 3, 39);
    says(d, &["cannot relabel", "`point:`"]);
}

#[test]
fn config_table2_binds_points_a_to_e() {
    let (name, text) = fixture!("config-table2.yaml");
    let cfg = Config::load_str(&Arc::from(name), text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(cfg.name, "table2-example");
    assert_eq!(
        cfg.points().collect::<Vec<_>>(),
        ["A", "B", "C", "D", "E", "walk.terminate"]
    );
    let g = formation()
        .with_config(&cfg)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.config_name(), Some("table2-example"));
    let m = Mission::new(g, &registry()).unwrap_or_else(|e| panic!("{e}"));
    let g = m.graph().clone();
    let bound = |b: &str, k: Kind| {
        m.bound(id(&g, b), k)
            .unwrap_or_else(|| panic!("{b}.{k} is not bound"))
    };
    let b = bound("walk", Kind::Sync);
    assert_eq!((b.point.as_str(), b.protocol.name()), ("B", "sync.by-rule"));
    assert_eq!(b.deadline, Duration::from_secs(2));
    let e = bound("linewalk", Kind::Allocate);
    assert_eq!((e.point.as_str(), e.protocol.name()), ("E", "alloc.by-id"));
    assert_eq!(
        (e.deadline, e.retry),
        (Duration::from_secs(90), Duration::from_millis(250))
    );
    assert_eq!(bound("walk", Kind::Terminate).protocol.name(), "term.local");
    // The graph's own binding stands; unbound points take the defaults.
    assert_eq!(
        bound("formation", Kind::Terminate).protocol.name(),
        "term.first-wins"
    );
    assert_eq!(
        bound("triangle", Kind::Terminate).protocol.name(),
        "term.wait-all"
    );
}

#[test]
fn config_point_names_accept_short_kinds() {
    let text = "bindings:\n  walk.term: term.local\n  walk.alloc: alloc.by-id\n  walk.sync: sync.by-rule\n";
    let cfg = Config::load_str(&Arc::from("short.yaml"), text).unwrap_or_else(|e| panic!("{e}"));
    formation().with_config(&cfg).unwrap_or_else(|e| {
        panic!("`walk.term`, `walk.alloc` and `walk.sync` (= B) are points:\n{e}")
    });
}

#[test]
fn config_binding_replaces_the_graph_binding() {
    let text = "defaults:\n  terminate: term.local\nstart: s\nbehaviors:\n  s:\n    team: true\n    next: [a, b]\n    sync: { point: A, protocol: sync.by-rule, deadline: 9s, retry: 50ms }\n  a: { team: true }\n  b: { team: true }\n";
    let g = graph_ok("r.yaml", text);
    let cfg = Config::load_str(&Arc::from("r-cfg.yaml"), "bindings:\n  A: SF1\n")
        .unwrap_or_else(|e| panic!("{e}"));
    let g = g.with_config(&cfg).unwrap_or_else(|e| panic!("{e}"));
    let s = id(&g, "s");
    assert_eq!(g.point_name(s, Kind::Sync), "A", "the label stays");
    let m = Mission::new(g, &registry()).unwrap_or_else(|e| panic!("{e}"));
    let b = m.bound(s, Kind::Sync).expect("A is bound");
    // The graph's 9 s / 50 ms went with the replaced binding.
    assert_eq!(
        (b.deadline, b.retry),
        (Duration::from_secs(5), Duration::from_millis(500))
    );
}

#[test]
fn config_binding_errors_point_into_the_config_file() {
    let cfg = Config::load_str(
        &Arc::from("cfg.yaml"),
        "config: wrong\nbindings:\n  C: sync.by-rule\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let g = formation()
        .with_config(&cfg)
        .unwrap_or_else(|e| panic!("{e}"));
    let e = Mission::new(g, &registry()).expect_err("sync protocol at an allocation point");
    check_display(&e.0);
    let d = one(&e.0, "binding-kind-mismatch");
    assert_eq!(&*d.file, "cfg.yaml");
    at(d, 3, 3);
    says(
        d,
        &[
            "`sync.by-rule` is a synchronization protocol",
            "`C` is an allocation point",
        ],
    );
}

// ----- mission binding resolution -------------------------------------------

#[test]
fn unknown_protocol() {
    let e = mission_err(fixture!("mission-unknown-protocol.yaml"), &registry());
    let d = one(&e.0, "unknown-protocol");
    //     sync: sync.by-rul
    //           ^ column 11
    at(d, 9, 11);
    says(
        d,
        &["no protocol called `sync.by-rul`", "bound at search.sync"],
    );
    hints(d, &["did you mean `sync.by-rule`?"]);
}

#[test]
fn unknown_protocol_without_a_close_name_lists_the_kind() {
    let text = include_str!("fixtures/mission-unknown-protocol.yaml")
        .replace("sync.by-rul", "sync.zzzzzz");
    let g = graph_ok("m.yaml", &text);
    let e = Mission::new(g, &registry()).expect_err("unknown protocol");
    hints(
        one(&e.0, "unknown-protocol"),
        &["sync protocols: sync.by-rule"],
    );
}

#[test]
fn allocation_protocol_at_a_sync_point() {
    let e = mission_err(fixture!("mission-kind-mismatch.yaml"), &registry());
    let d = one(&e.0, "binding-kind-mismatch");
    at(d, 9, 11);
    says(
        d,
        &[
            "`alloc.by-id` is an allocation protocol",
            "`search.sync` is a synchronization point",
        ],
    );
    hints(d, &["`sync.by-rule`"]);
}

#[test]
fn parameters_given_to_a_protocol_that_takes_none() {
    let e = mission_err(fixture!("mission-bad-params.yaml"), &registry());
    let d = one(&e.0, "bad-params");
    at(d, 9, 11);
    says(
        d,
        &[
            "parameters of `sync.by-rule` at search.sync",
            "takes no parameters",
        ],
    );
}

#[test]
fn zero_deadline_is_rejected_by_the_mission() {
    let text = include_str!("fixtures/mission-unknown-protocol.yaml")
        .replace("sync: sync.by-rul", "sync: { deadline: 0s }");
    let g = graph_ok("m.yaml", &text);
    let e = Mission::new(g, &registry()).expect_err("zero deadline");
    let d = one(&e.0, "bad-duration");
    at(d, 9, 11);
    says(d, &["at search.sync", "deadline must be positive"]);
}

#[test]
fn built_in_default_termination_is_term_wait_all() {
    // Registry::core() has no `term.wait-all`: the built-in default of a
    // termination point is what is missing, reported at the behavior.
    let e = mission_err(
        ("w.yaml", "start: p\nbehaviors:\n  p:\n    team: true\n"),
        &Registry::core(),
    );
    let d = one(&e.0, "unknown-protocol");
    at(d, 3, 3);
    says(d, &["`term.wait-all`", "p.terminate"]);
}

#[test]
fn binding_resolution_order() {
    let text = "\
defaults:
  sync: { protocol: SF1, deadline: 2s, retry: 100ms }
start: s
behaviors:
  s:
    team: true
    next: [a, b]
    sync: { deadline: 7s }
  a:
    team: true
    next: [a, b]
  b: { team: true }
";
    let g = graph_ok("order.yaml", text);
    let m = Mission::new(g, &registry()).unwrap_or_else(|e| panic!("{e}"));
    let g = m.graph().clone();
    let bound = |b: &str, k: Kind| m.bound(id(&g, b), k).unwrap_or_else(|| panic!("{b}.{k}"));
    // Own deadline, protocol and retry from the defaults (alias resolved).
    let s = bound("s", Kind::Sync);
    assert_eq!(s.protocol.name(), "sync.by-rule");
    assert_eq!(
        (s.deadline, s.retry),
        (Duration::from_secs(7), Duration::from_millis(100))
    );
    // Nothing of its own: all from the defaults.
    let a = bound("a", Kind::Sync);
    assert_eq!(
        (a.deadline, a.retry),
        (Duration::from_secs(2), Duration::from_millis(100))
    );
    // No binding, no default: built-in protocol, its deadline (5 s), 500 ms retry.
    let t = bound("b", Kind::Terminate);
    assert_eq!(t.protocol.name(), "term.wait-all");
    assert_eq!(
        (t.deadline, t.retry),
        (Duration::from_secs(5), Duration::from_millis(500))
    );
    assert_eq!(m.points().len(), 5, "s.sync, a.sync and three terminations");
}

// ----- the shipped example --------------------------------------------------

#[test]
fn formation_example_loads_with_points_a_to_e() {
    let g = formation();
    assert!(g.warnings().is_empty(), "{:?}", g.warnings());
    assert_eq!(g.name(), "formation");
    assert_eq!(g.roster().len(), 3);
    assert_eq!(g.name_of(g.start()), "formation");
    let points = g.points();
    let of = |kind: Kind| -> Vec<(String, String)> {
        points
            .iter()
            .filter(|p| p.kind == kind)
            .map(|p| (p.name.clone(), g.name_of(p.behavior).to_string()))
            .collect()
    };
    let pairs = |v: &[(&str, &str)]| -> Vec<(String, String)> {
        v.iter()
            .map(|(a, b)| ((*a).to_string(), (*b).to_string()))
            .collect()
    };
    assert_eq!(
        of(Kind::Sync),
        pairs(&[("A", "search"), ("B", "walk"), ("D", "linewalk")])
    );
    assert_eq!(
        of(Kind::Allocate),
        pairs(&[("C", "walk"), ("E", "linewalk")])
    );
    let team: Vec<&str> = g
        .behaviors()
        .iter()
        .filter(|b| b.team)
        .map(|b| b.name.as_str())
        .collect();
    assert_eq!(
        team,
        [
            "formation",
            "triangle",
            "line",
            "search",
            "walk",
            "linewalk"
        ]
    );
    let term: Vec<String> = of(Kind::Terminate).into_iter().map(|(_, b)| b).collect();
    assert_eq!(term, team, "a termination point per team behavior");
    assert_eq!(points.len(), 11);

    let walk = id(&g, "walk");
    assert_eq!(g.find_point("A"), Some((id(&g, "search"), Kind::Sync)));
    assert_eq!(g.find_point("walk.allocate"), Some((walk, Kind::Allocate)));
    assert_eq!(g.find_point("C"), Some((walk, Kind::Allocate)));
    assert_eq!(
        g.find_point("walk.terminate"),
        Some((walk, Kind::Terminate))
    );
    assert_eq!(g.find_point("Z"), None);
    assert_eq!(g.point_name(walk, Kind::Terminate), "walk.terminate");

    let m = Mission::new(g, &registry()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.points().len(), 11);
    let slots: Vec<(u32, u32)> = m.child_slots(walk).iter().map(|s| (s.min, s.max)).collect();
    assert_eq!(slots, [(1, 1), (1, 1), (1, u32::MAX)]);
}

#[test]
fn load_from_a_file_names_the_path() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/duplicate-edge.yaml");
    let e = load(&path).expect_err("duplicate edge");
    let d = one(&e.0, "duplicate-edge");
    assert_eq!(&*d.file, path.display().to_string());
    assert!(
        d.to_string()
            .starts_with(&format!("{}:5:18: error[duplicate-edge]: ", path.display()))
    );
    let e = load(Path::new("tests/fixtures/no-such-file.yaml")).expect_err("missing file");
    assert_eq!(e.0[0].code, "io");
}

/// Every error fixture, for the Display format check below.
const ERROR_FIXTURES: &[Src] = &[
    fixture!("yaml-syntax.yaml"),
    fixture!("unknown-field.yaml"),
    fixture!("duplicate-behavior.yaml"),
    fixture!("no-behaviors.yaml"),
    fixture!("no-behaviors-empty.yaml"),
    fixture!("bad-name.yaml"),
    fixture!("unknown-reference-children.yaml"),
    fixture!("unknown-reference-next.yaml"),
    fixture!("unknown-reference-start.yaml"),
    fixture!("duplicate-edge.yaml"),
    fixture!("sequential-and-decomposition.yaml"),
    fixture!("missing-start.yaml"),
    fixture!("decomposition-cycle.yaml"),
    fixture!("loop-to-ancestor.yaml"),
    fixture!("child-not-chain-head.yaml"),
    fixture!("bad-condition-plain.yaml"),
    fixture!("bad-condition-quoted.yaml"),
    fixture!("bad-condition-folded.yaml"),
    fixture!("bad-condition-folded-repeat.yaml"),
    fixture!("condition-type.yaml"),
    fixture!("condition-type-utility.yaml"),
    fixture!("bad-duration.yaml"),
    fixture!("bad-duration-block.yaml"),
    fixture!("bad-duration-retry.yaml"),
    fixture!("duplicate-point.yaml"),
    fixture!("bad-point-label.yaml"),
    fixture!("default-with-point.yaml"),
    fixture!("empty-team.yaml"),
    fixture!("duplicate-robot.yaml"),
    fixture!("bad-value-belief.yaml"),
];

#[test]
fn every_diagnostic_prints_file_line_col_severity_and_code() {
    for (name, text) in ERROR_FIXTURES {
        let e = graph_err(name, text);
        let first_line = text.lines().next().unwrap_or("");
        let code = first_line
            .trim_start_matches("# ")
            .split([':', ' '])
            .next()
            .unwrap_or("");
        assert!(e.has(code), "{name} says it shows `{code}`, but got:\n{e}");
        for d in e.errors() {
            let prefix = format!("{name}:{}:{}: error[{}]: ", d.loc.line, d.loc.col, d.code);
            assert!(d.to_string().starts_with(&prefix), "{d}");
        }
    }
}

#[test]
fn runs_of_a_behavior_outside_the_parent_is_an_error() {
    let text = "start: root\nbehaviors:\n  root: { team: true, children: [a], until: 'runs(work) >= 2' }\n  a: { team: true, children: [work], next: [a] }\n  work: { until: done }\n";
    let e = graph_err("runs.yaml", text);
    let d = one(&e.0, "runs-out-of-scope");
    at(d, 3, 45);
    says(d, &["`runs(work)` in the `until` of `root` is always 0"]);
    // A sibling in the same chain, and the behavior itself, are fine.
    graph_ok(
        "runs-ok.yaml",
        "start: root\nbehaviors:\n  root: { team: true, children: [a] }\n  a: { pre: 'runs < 3', next: [a, b] }\n  b: { pre: 'runs(a) >= 3' }\n",
    );
}
