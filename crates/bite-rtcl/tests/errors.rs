//! One test per error kind: its code, line, column, message and hint, as a
//! compiler gives them.

use bite_core::diag::Diagnostic;
use bite_rtcl::{CompileOptions, Library, compile};

fn errors(src: &str) -> Vec<Diagnostic> {
    match compile(
        "m.rtcl",
        src,
        &Library::builtin(),
        &CompileOptions::default(),
    ) {
        Ok(out) => panic!("expected errors, compiled:\n{}", out.graph()),
        Err(d) => d.0,
    }
}

/// The single error of `src`: (code, line, column, hint).
fn one(src: &str) -> (&'static str, u32, u32, Option<String>, String) {
    let e = errors(src);
    assert_eq!(e.len(), 1, "{e:#?}");
    let d = &e[0];
    (
        d.code,
        d.loc.line,
        d.loc.col,
        d.hint.clone(),
        d.message.clone(),
    )
}

#[test]
fn display_is_file_line_col_code_message_caret_hint() {
    let e = errors("find::::yellow=>box\nmvoe:box:1:2\n");
    assert_eq!(
        e[0].to_string(),
        "m.rtcl:2:1: error[unknown-command]: unknown command `mvoe`\n    \
         2 | mvoe:box:1:2\n      \
           | ^^^^\n  \
         hint: did you mean `move`?"
    );
}

#[test]
fn bad_character() {
    let (code, line, col, hint, msg) = one("find::::red=>cube\nmove:cube;0:0\n");
    assert_eq!((code, line, col), ("bad-character", 2, 10));
    assert_eq!(msg, "unexpected character `;`");
    assert_eq!(
        hint.as_deref(),
        Some("parameters are separated by `:`, commands by line ends")
    );
}

#[test]
fn bad_number() {
    let (code, line, col, hint, msg) = one("wait:30s\n");
    assert_eq!((code, line, col), ("bad-number", 1, 6));
    assert_eq!(msg, "`30s` is not a number");
    assert_eq!(
        hint.as_deref(),
        Some("numbers have no units (metres and seconds are implied): write `30`")
    );
    let (code, _, col, hint, _) = one("goto:1.2.3:0\n");
    assert_eq!((code, col), ("bad-number", 6));
    assert_eq!(
        hint.as_deref(),
        Some("numbers are written like `3`, `-.5`, `0.25` or `1e-1`")
    );
}

#[test]
fn unexpected_token() {
    let (code, line, col, hint, msg) = one("\n  goto:1 2\n");
    assert_eq!((code, line, col), ("unexpected-token", 2, 10));
    assert_eq!(
        msg,
        "expected `:`, `=>` or the end of the line after a parameter, found the number `2`"
    );
    assert_eq!(
        hint.as_deref(),
        Some("did you forget a `:`? Parameters are separated by `:`")
    );
    let (code, _, col, hint, _) = one("find::::red=>\n");
    assert_eq!((code, col), ("unexpected-token", 14));
    assert_eq!(
        hint.as_deref(),
        Some("`=>name` names the command's result: `find::::yellow=>box`")
    );
    let (code, _, col, _, msg) = one(":find\n");
    assert_eq!((code, col), ("unexpected-token", 1));
    assert_eq!(
        msg,
        "expected a command name at the start of the line, found `:`"
    );
}

#[test]
fn unknown_command() {
    let (code, line, col, hint, _) = one("# comment\nFnid::::red\n");
    assert_eq!((code, line, col), ("unknown-command", 2, 1));
    assert_eq!(hint.as_deref(), Some("did you mean `find`?"));
    // A name alone on a line.
    let (code, _, _, hint, _) = one("find::::red=>cube\ncube\n");
    assert_eq!(code, "unknown-command");
    assert_eq!(
        hint.as_deref(),
        Some(
            "`cube` names an object; a line starts with a command that uses it, e.g. `move:cube:0:0`"
        )
    );
    let (_, _, _, hint, _) = one("fly:1:2\n");
    assert_eq!(
        hint.as_deref(),
        Some("the commands are: find, follow, formation, goto, move, scan, wait")
    );
}

#[test]
fn too_many_params() {
    let (code, line, col, hint, msg) = one("goto:1:2:3\n");
    assert_eq!((code, line, col), ("too-many-params", 1, 10));
    assert_eq!(msg, "`goto` takes 2 parameters, found 3");
    assert_eq!(hint.as_deref(), Some("usage: `goto:x:y`"));
    let (code, _, col, hint, _) = one("goto:1:2:\n");
    assert_eq!((code, col), ("too-many-params", 10));
    assert_eq!(
        hint.as_deref(),
        Some("remove the trailing `:`; usage: `goto:x:y`")
    );
}

#[test]
fn missing_param() {
    let (code, line, col, hint, msg) = one("find::::red=>cube\nmove:cube:1\n");
    assert_eq!((code, line, col), ("missing-param", 2, 12));
    assert_eq!(
        msg,
        "`move` needs `y`: the goal's y, in metres from the origin"
    );
    assert_eq!(hint.as_deref(), Some("usage: `move:object:x:y`"));
    // An empty parameter where the command needs one.
    let (code, _, col, _, msg) = one("wait:\n");
    assert_eq!((code, col), ("missing-param", 6));
    assert_eq!(
        msg,
        "`wait` cannot be left empty: `seconds` must be known: how long, in seconds"
    );
    // Half a point.
    let (code, _, col, _, msg) = one("formation:line::3\n");
    assert_eq!((code, col), ("missing-param", 18));
    assert_eq!(
        msg,
        "`formation` needs `y` too: `x` and `y` make the point `goal`, and `x` is given"
    );
}

#[test]
fn bad_type() {
    let (code, line, col, hint, msg) = one("find::::red=>cube\ngoto:cube:1\n");
    assert_eq!((code, line, col), ("bad-type", 2, 6));
    assert_eq!(
        msg,
        "`goto` expects an x coordinate in metres for `x`, found the name `cube`"
    );
    assert_eq!(
        hint.as_deref(),
        Some("numbers are written like `3`, `-.5` or `0.25`")
    );
    let (code, _, col, hint, msg) = one("move:3:1:1\n");
    assert_eq!((code, col), ("bad-type", 6));
    assert_eq!(
        msg,
        "`move` expects the name of an earlier result for `object`, found a number"
    );
    assert_eq!(
        hint.as_deref(),
        Some("name the object first, e.g. `find::::red=>cube`, then use `cube`")
    );
}

#[test]
fn bad_value() {
    let (code, line, col, hint, msg) = one("find::::yelow=>box\n");
    assert_eq!((code, line, col), ("bad-value", 1, 9));
    assert_eq!(msg, "`yelow` is not a colour the robots know");
    assert_eq!(hint.as_deref(), Some("did you mean `yellow`?"));
    let (code, _, col, hint, _) = one("formation:circle\n");
    assert_eq!((code, col), ("bad-value", 11));
    assert_eq!(
        hint.as_deref(),
        Some("`shape` is one of: triangle, line, column")
    );
    let (code, _, col, _, msg) = one("wait:-1\n");
    assert_eq!((code, col), ("bad-value", 6));
    assert_eq!(
        msg,
        "`seconds` is a duration in seconds, which cannot be negative"
    );
    let (code, _, _, _, msg) = one("goto:1e7:0\n");
    assert_eq!(code, "bad-value");
    assert_eq!(
        msg,
        "`x` is out of range: numbers are at most 1000000 in size"
    );
}

#[test]
fn undefined_name() {
    let (code, line, col, hint, msg) = one("find::::red=>cube\nmove:cub:0:0\n");
    assert_eq!((code, line, col), ("undefined-name", 2, 6));
    assert_eq!(msg, "`cub` is not defined");
    assert_eq!(hint.as_deref(), Some("did you mean `cube`?"));
    // Used before it is defined.
    let e = errors("move:cube:0:0\nfind::::red=>cube\n");
    assert_eq!(e.len(), 1);
    assert_eq!(
        (e[0].code, e[0].loc.line, e[0].loc.col),
        ("undefined-name", 1, 6)
    );
    assert_eq!(
        e[0].hint.as_deref(),
        Some("`cube` is named on line 2, after this command: commands run in the order written")
    );
    // Names are case-sensitive.
    let (_, _, _, hint, _) = one("find::::red=>Cube\nmove:cube:0:0\n");
    assert_eq!(
        hint.as_deref(),
        Some("names are case-sensitive: did you mean `Cube`?")
    );
}

#[test]
fn redefined_name() {
    let (code, line, col, hint, msg) = one("find::::red=>cube\nfind::::blue=>cube\n");
    assert_eq!((code, line, col), ("redefined-name", 2, 15));
    assert_eq!(msg, "`cube` is already defined, on line 1");
    assert_eq!(
        hint.as_deref(),
        Some(
            "a name is given once, so it always means the same object; choose another, e.g. `cube2`"
        )
    );
}

#[test]
fn no_result() {
    let (code, line, col, hint, msg) = one("goto:1:1=>there\n");
    assert_eq!((code, line, col), ("no-result", 1, 11));
    assert_eq!(msg, "`goto` produces no result to name");
    assert_eq!(
        hint.as_deref(),
        Some("remove `=>there`; only commands that find something name it (`find`)")
    );
}

#[test]
fn bad_name() {
    let (code, line, col, hint, msg) = one("find::::red=>Yellow\n");
    assert_eq!((code, line, col), ("bad-name", 1, 14));
    assert_eq!(
        msg,
        "`Yellow` cannot name a result: it is a colour, and `Yellow_pos` would be ambiguous"
    );
    assert_eq!(
        hint.as_deref(),
        Some("choose another name, e.g. `Yellow_1`")
    );
    let long = "n".repeat(65);
    let (code, _, col, _, msg) = one(&format!("find::::red=>{long}\n"));
    assert_eq!((code, col), ("bad-name", 14));
    assert_eq!(msg, "a name is at most 64 characters; this one has 65");
    let (code, _, _, _, msg) = one("find::::red=>skill\n");
    assert_eq!(code, "bad-name");
    assert_eq!(
        msg,
        "`skill` cannot name a result: it is a percept of the robots, and `skill_pos` would be ambiguous"
    );
    // `find_2` is what the unnamed result of the second command is called.
    let (code, line, col, hint, msg) = one("find::::red=>find_2\nfind::::blue\n");
    assert_eq!((code, line, col), ("bad-name", 1, 14));
    assert!(msg.contains("the compiler's"), "{msg}");
    assert_eq!(
        hint.as_deref(),
        Some("choose another name, e.g. `find_target2`")
    );
}

#[test]
fn empty_mission() {
    let (code, line, col, hint, _) = one("# nothing to do\n\n   \n");
    assert_eq!((code, line, col), ("empty-mission", 1, 1));
    assert_eq!(
        hint.as_deref(),
        Some("write one command a line, e.g. `find::::yellow=>box`")
    );
}

#[test]
fn too_large() {
    let src = "wait:1\n".repeat(bite_rtcl::parser::MAX_COMMANDS + 1);
    let e = errors(&src);
    let d = e.iter().find(|d| d.code == "too-large").expect("too-large");
    assert!(d.loc.line > 1);
    assert_eq!(
        d.message,
        format!(
            "the mission has more than {} commands",
            bite_rtcl::parser::MAX_COMMANDS
        )
    );
    let huge = " ".repeat(bite_rtcl::MAX_SOURCE_BYTES + 1);
    let e = errors(&huge);
    assert_eq!(e[0].code, "too-large");
}

/// A library of one command that splits the team into `count` parts.
const SPREAD: &str = "\
commands:
  spread:
    params:
      - { name: count, type: number }
    phases:
      - name: split
        children:
          - name: part
            repeat: \"{count}\"
            members: 1
            until: \"elapsed > 1\"
            skill:
              - { schema: stop, layer: 1 }
";

/// A library entry that cannot be generated for a use of it is reported at
/// the command, pointing into the library.
#[test]
fn library() {
    let lib = Library::from_str("lib.yaml", SPREAD).unwrap_or_else(|e| panic!("{e}"));
    let e = compile("m.rtcl", "spread:2.5\n", &lib, &CompileOptions::default())
        .expect_err("2.5 copies");
    assert_eq!(
        (e.0[0].code, e.0[0].loc.line, e.0[0].loc.col),
        ("library", 1, 1)
    );
    assert_eq!(
        e.0[0].message,
        "the library's `spread` cannot be generated for this command: `repeat` of `part` is `2.5`, not a count from 0 to 10000"
    );
    assert_eq!(e.0[0].hint.as_deref(), Some("see lib.yaml:8:13"));
    assert!(compile("m.rtcl", "spread:3\n", &lib, &CompileOptions::default()).is_ok());
}

#[test]
fn vague_target_is_a_warning() {
    let out = compile(
        "m.rtcl",
        "find=>thing\n",
        &Library::builtin(),
        &CompileOptions::default(),
    )
    .expect("compiles");
    assert_eq!(out.warnings.len(), 1);
    let w = &out.warnings[0];
    assert_eq!((w.code, w.loc.line, w.loc.col), ("vague-target", 1, 1));
    assert!(!w.is_error());
}

/// Several errors, on several lines, in one pass, in the order of the file.
#[test]
fn every_error_in_one_pass() {
    let e = errors(
        "find::::yelow=>box   # a typo\n\
         move:box:1:2:3\n\
         goto:1 2\n\
         mvoe:box:1:2\n\
         wait:-3\n\
         follow:crate\n",
    );
    let got: Vec<_> = e.iter().map(|d| (d.code, d.loc.line, d.loc.col)).collect();
    assert_eq!(
        got,
        [
            ("bad-value", 1, 9),
            ("too-many-params", 2, 14),
            ("unexpected-token", 3, 8),
            ("unknown-command", 4, 1),
            ("bad-value", 5, 6),
            ("undefined-name", 6, 8),
        ]
    );
}

/// Library files report YAML and semantic errors with their location.
#[test]
fn library_files_are_checked() {
    let e =
        Library::from_str("lib.yaml", "commands:\n  go:\n    parms: []\n").expect_err("bad key");
    assert_eq!(
        (e.0[0].code, e.0[0].loc.line, e.0[0].loc.col),
        ("yaml", 3, 5)
    );
    let e = Library::from_str(
        "lib.yaml",
        "commands:\n  go:\n    phases:\n      - name: a\n        skill: [{ schema: wandr, layer: 1 }]\n        until: \"{arived}\"\n",
    )
    .expect_err("bad schema and variable");
    let got: Vec<_> =
        e.0.iter()
            .map(|d| (d.code, d.loc.line, d.loc.col, d.hint.clone()))
            .collect();
    assert_eq!(
        got,
        [
            ("library", 5, 17, Some("did you mean `wander`?".to_string())),
            (
                "library",
                6,
                18,
                Some("the variables of this command are: index, result, robots, step".to_string())
            ),
        ]
    );
}

#[test]
fn too_few_robots_is_a_warning() {
    let out = compile(
        "m.rtcl",
        "find::::red=>cube\nmove:cube:0:0\n",
        &Library::builtin(),
        &CompileOptions {
            robots: 1,
            ..CompileOptions::default()
        },
    )
    .expect("compiles");
    let w: Vec<_> = out
        .warnings
        .iter()
        .map(|w| (w.code, w.loc.line, w.loc.col))
        .collect();
    assert_eq!(w, [("too-few-robots", 2, 1)]);
    assert_eq!(
        out.warnings[0].message,
        "`move` needs a team of 2 robots or more; this one has 1"
    );
}

#[test]
fn bad_options() {
    let e = compile(
        "m.rtcl",
        "wait:1\n",
        &Library::builtin(),
        &CompileOptions {
            robots: 0,
            ..CompileOptions::default()
        },
    )
    .expect_err("no robots");
    assert_eq!(e.0[0].code, "bad-options");
    assert!(!e.0[0].loc.is_known());
}

/// Long missions are generated command by command side by side, then put
/// together in order: the errors are those of generating one command after
/// the other, a duplicate name found where it first appears, and nothing
/// reported past the command that made the graph too large.
#[test]
fn errors_of_a_long_mission_are_those_in_order() {
    // `twice`: `spread` with one more child, named as `spread`'s copies
    // are (`part_1`), so that `twice:1` makes a name twice.
    let twice = SPREAD.replacen("commands:\n  spread:", "  twice:", 1)
        + "          - name: part_1
            members: 1
            until: \"elapsed > 1\"
            skill:
              - { schema: stop, layer: 1 }
";
    let text = format!("{SPREAD}{twice}");
    let lib = Library::from_str("lib.yaml", &text).unwrap_or_else(|e| panic!("{e}"));
    // 1: an error; 2: a duplicate name; 3: fine; then twelve commands of
    // 10,000 behaviors each, the tenth (line 13) past the largest graph;
    // then more errors that must not be reported.
    let mut head = String::from("spread:2.5\ntwice:1\ntwice:0\n");
    head.push_str(&"spread:10000\n".repeat(12));
    let tail = "spread:2.5\ntwice:1\n".repeat(bite_rtcl::codegen::PARALLEL_FROM);
    let opts = CompileOptions::default();
    let short = compile("m.rtcl", &head, &lib, &opts).expect_err("too large");
    let long = compile("m.rtcl", &format!("{head}{tail}"), &lib, &opts).expect_err("too large");
    let codes: Vec<_> = long.0.iter().map(|d| (d.code, d.loc.line)).collect();
    assert_eq!(
        codes,
        [("too-large", 0), ("library", 1), ("library", 2)],
        "{long}"
    );
    assert!(
        long.0[2]
            .message
            .ends_with("two behaviors would be called `twice_2_part_1`"),
        "{}",
        long.0[2].message
    );
    assert_eq!(short, long);
}
