//! Fuzzing the lexer, parser, checker and code generator with proptest:
//! random bytes, random token streams and random (mostly well-formed)
//! command lines. Whatever the input:
//!
//! - nothing panics;
//! - the lexer's tokens tile the text in order, end with `Eof`, and their
//!   lines and columns agree with the source map;
//! - a failure is a list of diagnostics, at least one an error, each with
//!   a known location (line ≥ 1, within the file) and a stable code;
//! - a success is a graph that `bite_core::graph::load_str` loads without
//!   an error or a warning, whose protocols resolve, and compiling again
//!   gives the same output.
//!
//! `PROPTEST_CASES=200000 cargo test -p bite-rtcl --release --test fuzz`
//! runs it for longer.

use bite_rtcl::lexer::TokenKind;
use bite_rtcl::{CompileOptions, Library, SourceMap, compile, lex};
use proptest::prelude::*;
use std::sync::{Arc, LazyLock};

static LIB: LazyLock<Library> = LazyLock::new(Library::builtin);
static REGISTRY: LazyLock<bite_core::interaction::Registry> =
    LazyLock::new(bite_protocols::registry);

const CODES: &[&str] = &[
    "bad-character",
    "bad-number",
    "unexpected-token",
    "unknown-command",
    "too-many-params",
    "missing-param",
    "bad-type",
    "bad-value",
    "undefined-name",
    "redefined-name",
    "no-result",
    "bad-name",
    "empty-mission",
    "too-large",
    "library",
    "vague-target",
    "too-few-robots",
];

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(512)
}

fn lexer_invariants(src: &str) {
    let toks = lex(src);
    let map = SourceMap::new("f.rtcl", src);
    assert_eq!(toks.last().map(|t| &t.kind), Some(&TokenKind::Eof));
    let mut at = 0;
    for t in &toks {
        assert!(t.span.start >= at, "tokens overlap or go back: {t:?}");
        assert!(t.span.end >= t.span.start && t.span.end <= src.len());
        assert!(src.is_char_boundary(t.span.start) && src.is_char_boundary(t.span.end));
        // Only blanks (and a leading byte-order mark) between tokens.
        let gap = &src[at..t.span.start];
        assert!(
            gap.chars()
                .all(|c| c == ' ' || c == '\t' || c == '\u{feff}'),
            "unlexed text {gap:?}"
        );
        let loc = map.loc(t.span.start);
        assert_eq!((loc.line, loc.col), (t.line, t.col), "{t:?} in {src:?}");
        at = t.span.end;
    }
    assert_eq!(at, src.len());
}

fn outcome(src: &str, opts: &CompileOptions) -> Result<(), TestCaseError> {
    lexer_invariants(src);
    let lines = SourceMap::new("f.rtcl", src).line_count() as u32;
    match compile("f.rtcl", src, &LIB, opts) {
        Err(d) => {
            prop_assert!(d.errors().next().is_some(), "no error in {d:?}");
            for e in &d.0 {
                prop_assert!(
                    e.loc.line >= 1 && e.loc.line <= lines && e.loc.col >= 1,
                    "bad location {:?} for {e}",
                    e.loc
                );
                prop_assert!(CODES.contains(&e.code), "unknown code {}", e.code);
                // The detail shows the line with a caret.
                prop_assert!(
                    e.detail.as_deref().is_some_and(|d| d.contains('^'))
                        || e.code == "empty-mission"
                );
            }
        }
        Ok(out) => {
            let g =
                bite_core::graph::load_str(&Arc::from("f.yaml"), &out.graph()).map_err(|e| {
                    TestCaseError::fail(format!(
                        "graph does not load:\n{e}\n--- mission:\n{src}\n--- graph:\n{}",
                        out.graph()
                    ))
                })?;
            prop_assert!(
                g.warnings().is_empty(),
                "{:?}\n{}",
                g.warnings(),
                out.graph()
            );
            bite_core::Mission::new(g, &REGISTRY)
                .map_err(|e| TestCaseError::fail(format!("protocols: {e}")))?;
            for w in &out.warnings {
                prop_assert!(w.loc.line >= 1 && CODES.contains(&w.code));
            }
            let again = compile("f.rtcl", src, &LIB, opts)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(again, out);
        }
    }
    Ok(())
}

/// Pieces of missions, right and wrong.
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => prop::sample::select(vec![
            "find", "move", "goto", "scan", "wait", "formation", "follow", "FIND", "Move",
            "mvoe", "fly", "_x",
        ]).prop_map(String::from),
        6 => Just(":".to_string()),
        2 => Just("=>".to_string()),
        3 => Just("\n".to_string()),
        2 => Just(" ".to_string()),
        3 => prop::sample::select(vec![
            "box", "cube", "Box", "b2", "red", "yellow", "Yellow", "triangle", "line", "column",
            "skill", "crate",
        ]).prop_map(String::from),
        3 => prop::sample::select(vec![
            "0", "1", "-.5", ".25", "+2", "5.", "1e-1", "3x", "1e999", "1e-400", "-0", "2.5E3",
            "1000001", "-1", "1.2.3", "4_0",
        ]).prop_map(String::from),
        1 => any::<f64>().prop_map(|x| x.to_string()),
        1 => prop::sample::select(vec![
            "#", "# c", ";", "=", ">", "é", "\t", "\r", "\r\n", "\u{feff}", "-", "+", ",", "\"",
            "{", "}", "\u{0}", "/",
        ]).prop_map(String::from),
    ]
}

/// A command line that is often right.
fn line() -> impl Strategy<Value = String> {
    let cmd = prop::sample::select(vec![
        "find",
        "move",
        "goto",
        "scan",
        "wait",
        "formation",
        "follow",
    ]);
    let param = prop_oneof![
        2 => Just(String::new()),
        4 => prop::sample::select(vec!["0", "1", "-.5", ".25", "2", "3.5", "-2", "0.6"]).prop_map(String::from),
        3 => prop::sample::select(vec![
            "box", "cube", "red", "yellow", "blue", "triangle", "line", "column",
        ]).prop_map(String::from),
    ];
    let result =
        prop::option::weighted(0.4, prop::sample::select(vec!["box", "cube", "thing", "b"]));
    (cmd, prop::collection::vec(param, 0..6), result).prop_map(|(c, ps, r)| {
        let mut s = c.to_string();
        for p in ps {
            s.push(':');
            s.push_str(&p);
        }
        if let Some(r) = r {
            s.push_str("=>");
            s.push_str(r);
        }
        s
    })
}

/// A mission built from the library: each parameter gets a value of its
/// type (numbers, colours, choices, names defined earlier), left empty
/// where optional, and now and then a mistake.
fn mission() -> impl Strategy<Value = String> {
    prop::collection::vec((any::<u8>(), prop::collection::vec(any::<u16>(), 8)), 1..16).prop_map(
        |plan| {
            use bite_rtcl::library::ParamType;
            let names: Vec<&str> = LIB.names().collect();
            let mut defined: Vec<String> = Vec::new();
            let mut out = String::new();
            for (k, (c, picks)) in plan.iter().enumerate() {
                let def = LIB
                    .command(names[*c as usize % names.len()])
                    .expect("command");
                if defined.is_empty() && def.params.iter().any(|p| p.ty == ParamType::Name) {
                    out.push_str("find::::red=>first\n");
                    defined.push("first".into());
                }
                let mut line = def.name.clone();
                let mut last = 0;
                let mut params = Vec::new();
                for (i, p) in def.params.iter().enumerate() {
                    let r = picks[i % picks.len()];
                    let mistake = r % 151 == 0;
                    let v = if p.optional && r % 3 == 0 {
                        String::new()
                    } else if mistake {
                        ["", "x", "-1", "nowhere", "1e9"][usize::from(r / 151) % 5].to_string()
                    } else {
                        let f = f64::from(r % 80) / 10.0 - 2.0;
                        match &p.ty {
                            ParamType::Distance | ParamType::Duration => format!("{}", f.abs()),
                            ParamType::Number | ParamType::X | ParamType::Y => format!("{f}"),
                            ParamType::Colour => {
                                LIB.colours[usize::from(r) % LIB.colours.len()].clone()
                            }
                            ParamType::Choice(v) => v[usize::from(r) % v.len()].clone(),
                            ParamType::Name => defined
                                .get(usize::from(r) % defined.len().max(1))
                                .cloned()
                                .unwrap_or_else(|| "ghost".into()),
                        }
                    };
                    if !v.is_empty() {
                        last = i + 1;
                    }
                    params.push(v);
                }
                // Trailing optional parameters are left out.
                for v in &params[..last] {
                    line.push(':');
                    line.push_str(v);
                }
                if def.result.is_some() && picks[7] % 4 != 0 {
                    let n = format!("t{k}");
                    line.push_str("=>");
                    line.push_str(&n);
                    defined.push(n);
                }
                out.push_str(&line);
                out.push('\n');
            }
            out
        },
    )
}

fn options() -> impl Strategy<Value = CompileOptions> {
    (1usize..6, -10.0f64..10.0, -10.0f64..10.0).prop_map(|(robots, x, y)| CompileOptions {
        origin: [x, y],
        robots,
    })
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: cases(),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let src = String::from_utf8_lossy(&bytes);
        outcome(&src, &CompileOptions::default())?;
    }

    #[test]
    fn random_token_streams(toks in prop::collection::vec(token(), 0..60), opts in options()) {
        outcome(&toks.concat(), &opts)?;
    }

    #[test]
    fn random_command_lines(lines in prop::collection::vec(line(), 1..12), opts in options()) {
        outcome(&lines.join("\n"), &opts)?;
    }

    #[test]
    fn random_missions(src in mission(), opts in options()) {
        outcome(&src, &opts)?;
    }
}
