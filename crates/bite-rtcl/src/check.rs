//! Semantic checking: every command against the command library.
//!
//! - the command exists (`unknown-command`, with "did you mean");
//! - it has no more parameters than the library gives it
//!   (`too-many-params`) and every required one is there and not empty
//!   (`missing-param`); the coordinates of a point come together;
//! - each parameter has its type (`bad-type`: a word where a number goes)
//!   and a valid value (`bad-value`: a colour the robots do not know, a
//!   negative distance, a choice not offered, a number out of range);
//! - a name is defined by an earlier command's `=>name` before it is used
//!   (`undefined-name`), and only once (`redefined-name`); a result is
//!   named only where the command produces one (`no-result`), and not with
//!   a name its percepts would clash with (`bad-name`).
//!
//! Every command is checked, so one pass reports every problem.

use crate::ast::{Command, Mission, Name, ParamKind};
use crate::library::{CommandDef, Library, ParamType};
use crate::source::{SourceMap, Span};
use crate::template::Val;
use bite_core::diag::{Diagnostic, did_you_mean};
use std::collections::BTreeMap;

/// Largest number accepted in a mission (in magnitude).
pub const MAX_NUMBER: f64 = 1.0e6;

/// Longest result name.
pub const MAX_NAME: usize = 64;

/// Names a result cannot take: the percepts `<name>_seen`, `<name>_pos`,
/// `<name>_distance`, `<name>_bearing` of a target would clash with these
/// percepts of the physical world (and with colours').
pub const RESERVED_NAMES: &[&str] = &["skill", "teammates", "range", "reference", "obstacle"];

/// A checked command, ready for code generation.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Position in the mission, from 1.
    pub index: usize,
    /// The library command (lower case).
    pub command: String,
    /// 1-based line.
    pub line: u32,
    /// The command's span.
    pub span: Span,
    /// The command as written (without its comment).
    pub text: String,
    /// One value per library parameter, in order; `None` when unknown
    /// (left empty or left out). Coordinates are still relative to the
    /// mission origin; defaults are not applied yet.
    pub values: Vec<Option<Val>>,
    /// The name given with `=>`.
    pub result: Option<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Defined {
    /// By a command that names a target.
    Target,
    /// By a command that did not check (unknown, broken): uses are not
    /// reported again.
    Unknown,
}

/// Check a parsed mission against a library. Returns the steps of the
/// commands that checked, and every problem found (errors and warnings).
pub fn check(
    map: &SourceMap<'_>,
    mission: &Mission,
    lib: &Library,
) -> (Vec<Step>, Vec<Diagnostic>) {
    let mut c = Checker {
        map,
        lib,
        diags: Vec::new(),
        names: BTreeMap::new(),
        all_results: BTreeMap::new(),
    };
    for cmd in &mission.commands {
        if let Some(r) = &cmd.result {
            c.all_results.entry(r.text.clone()).or_insert(cmd.line);
        }
    }
    for r in &mission.recovered {
        c.all_results
            .entry(r.text.clone())
            .or_insert(map.loc(r.span.start).line);
    }
    let mut recovered = mission.recovered.iter().peekable();
    let mut steps = Vec::new();
    for cmd in &mission.commands {
        while let Some(r) = recovered.next_if(|r| r.span.start < cmd.span.start) {
            c.names
                .entry(r.text.clone())
                .or_insert((Defined::Unknown, map.loc(r.span.start).line));
        }
        if let Some(step) = c.command(cmd, steps.len() + 1) {
            steps.push(step);
        }
    }
    (steps, c.diags)
}

struct Checker<'a, 's> {
    map: &'a SourceMap<'s>,
    lib: &'a Library,
    diags: Vec<Diagnostic>,
    /// Names defined so far: kind, line.
    names: BTreeMap<String, (Defined, u32)>,
    /// Every `=>name` of the mission: first line.
    all_results: BTreeMap<String, u32>,
}

impl Checker<'_, '_> {
    fn error(
        &mut self,
        span: Span,
        code: &'static str,
        msg: impl Into<String>,
        hint: Option<String>,
    ) {
        let mut d = self.map.error(span, code, msg);
        d.hint = hint;
        self.diags.push(d);
    }

    fn command(&mut self, cmd: &Command, index: usize) -> Option<Step> {
        let Some(def) = self.lib.command(&cmd.name.text) else {
            let lc = cmd.name.text.to_ascii_lowercase();
            let hint = did_you_mean(&lc, self.lib.names()).unwrap_or_else(|| {
                format!(
                    "the commands are: {}",
                    self.lib.names().collect::<Vec<_>>().join(", ")
                )
            });
            let hint = if self.names.contains_key(&cmd.name.text) {
                format!(
                    "`{}` names an object; a line starts with a command that uses it, e.g. `move:{}:0:0`",
                    cmd.name.text, cmd.name.text
                )
            } else {
                hint
            };
            self.error(
                cmd.name.span,
                "unknown-command",
                format!("unknown command `{}`", cmd.name.text),
                Some(hint),
            );
            if let Some(r) = &cmd.result {
                self.names
                    .entry(r.text.clone())
                    .or_insert((Defined::Unknown, cmd.line));
            }
            return None;
        };
        let before = self.diags.len();
        // Made only for a message (most commands have none).
        let usage = || format!("usage: `{}`", def.usage());
        // Arity.
        if cmd.params.len() > def.params.len() {
            let extra = &cmd.params[def.params.len()..];
            let span = extra[0].span.to(extra[extra.len() - 1].span);
            let all_empty = extra.iter().all(|p| p.kind == ParamKind::Empty);
            let hint = if all_empty {
                format!("remove the trailing `:`; {}", usage())
            } else {
                usage()
            };
            self.error(
                span,
                "too-many-params",
                format!(
                    "`{}` takes {} parameter{}, found {}",
                    def.name,
                    def.params.len(),
                    if def.params.len() == 1 { "" } else { "s" },
                    cmd.params.len()
                ),
                Some(hint),
            );
        }
        // Where a missing parameter would go: after the last one written.
        let end = cmd.params.last().map_or(cmd.name.span.end, |p| p.span.end);
        let mut values = Vec::with_capacity(def.params.len());
        // Where parameter i is written (or would go), for messages.
        let span_of = |i: usize| cmd.params.get(i).map_or(Span::point(end), |g| g.span);
        for (i, p) in def.params.iter().enumerate() {
            let given = cmd.params.get(i);
            let span = span_of(i);
            let v = match given.map(|g| &g.kind) {
                None | Some(ParamKind::Empty) => {
                    if !p.optional {
                        let what = p
                            .doc
                            .as_deref()
                            .map(|d| format!(": {d}"))
                            .unwrap_or_default();
                        let msg = if given.is_some() {
                            format!(
                                "`{}` cannot be left empty: `{}` must be known{what}",
                                def.name, p.name
                            )
                        } else {
                            format!("`{}` needs `{}`{what}", def.name, p.name)
                        };
                        self.error(span, "missing-param", msg, Some(usage()));
                    }
                    None
                }
                Some(ParamKind::Number(x)) => self.number(def, &p.ty, &p.name, *x, span),
                Some(ParamKind::Word(w)) => self.word(def, &p.ty, &p.name, w, span),
            };
            values.push(v);
        }
        // The two coordinates of a point come together.
        for (point, [x, y]) in &def.points {
            let ix = def.params.iter().position(|p| &p.name == x);
            let iy = def.params.iter().position(|p| &p.name == y);
            let (Some(ix), Some(iy)) = (ix, iy) else {
                continue;
            };
            let known = |i: usize| values[i].is_some() || def.params[i].default.is_some();
            let missing = match (known(ix), known(iy)) {
                (true, false) => Some((iy, x)),
                (false, true) => Some((ix, y)),
                _ => None,
            };
            if let Some((i, other)) = missing {
                // Only when the parameter itself was not already reported.
                if def.params[i].optional {
                    self.error(
                        span_of(i),
                        "missing-param",
                        format!(
                            "`{}` needs `{}` too: `{x}` and `{y}` make the point `{point}`, and `{other}` is given",
                            def.name, def.params[i].name
                        ),
                        Some(usage()),
                    );
                }
            }
        }
        // The result.
        let mut result = None;
        if let Some(r) = &cmd.result {
            if def.result.is_none() {
                self.error(
                    r.span,
                    "no-result",
                    format!("`{}` produces no result to name", def.name),
                    Some(format!(
                        "remove `=>{}`; only commands that find something name it ({})",
                        r.text,
                        self.lib
                            .commands
                            .values()
                            .filter(|c| c.result.is_some())
                            .map(|c| format!("`{}`", c.name))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )),
                );
            } else if self.result_name(r, cmd.line) {
                result = Some(r.text.clone());
            }
        }
        // A find with no description at all.
        let failed = self.diags[before..].iter().any(Diagnostic::is_error);
        if let Some(rd) = def.result.as_ref().filter(|_| !failed) {
            let idx = |n: &Option<String>| {
                n.as_ref()
                    .and_then(|n| def.params.iter().position(|p| &p.name == n))
            };
            let colour = idx(&rd.colour).is_some_and(|i| values[i].is_some());
            let size = rd.size.as_ref().is_some_and(|s| {
                s.iter().any(|n| {
                    def.params
                        .iter()
                        .position(|p| &p.name == n)
                        .is_some_and(|i| values[i].is_some())
                })
            });
            if !colour && !size && (rd.colour.is_some() || rd.size.is_some()) {
                self.diags.push(
                    self.map
                        .warning(
                            cmd.name.span,
                            "vague-target",
                            format!(
                                "`{}` without a colour or a size: the robots take the first object they see",
                                def.name
                            ),
                        )
                        .with_hint(format!("describe it: {}", usage())),
                );
            }
        }
        if failed {
            return None;
        }
        Some(Step {
            index,
            command: def.name.clone(),
            line: cmd.line,
            span: cmd.span,
            text: self
                .map
                .text()
                .get(cmd.span.start..cmd.span.end)
                .unwrap_or("")
                .to_string(),
            values,
            result,
        })
    }

    /// Define a result name; false if it cannot be.
    fn result_name(&mut self, r: &Name, line: u32) -> bool {
        let lc = r.text.to_ascii_lowercase();
        if r.text.len() > MAX_NAME {
            self.error(
                r.span,
                "bad-name",
                format!(
                    "a name is at most {MAX_NAME} characters; this one has {}",
                    r.text.len()
                ),
                Some("choose a shorter name".into()),
            );
            self.names
                .entry(r.text.clone())
                .or_insert((Defined::Unknown, line));
            return false;
        }
        if self.lib.colours.contains(&lc) || RESERVED_NAMES.contains(&lc.as_str()) {
            let why = if self.lib.colours.contains(&lc) {
                "it is a colour"
            } else {
                "it is a percept of the robots"
            };
            self.error(
                r.span,
                "bad-name",
                format!(
                    "`{}` cannot name a result: {why}, and `{}_pos` would be ambiguous",
                    r.text, r.text
                ),
                Some(format!("choose another name, e.g. `{}_1`", r.text)),
            );
            // Still defined, so later uses are not reported too.
            self.names
                .entry(r.text.clone())
                .or_insert((Defined::Unknown, line));
            return false;
        }
        // `<command>_<n>` is what the compiler calls the unnamed result (and
        // the behaviors) of command n: a user's name must not collide.
        if let Some((cmd, n)) = lc.rsplit_once('_')
            && !n.is_empty()
            && n.bytes().all(|b| b.is_ascii_digit())
            && self.lib.command(cmd).is_some()
        {
            self.error(
                r.span,
                "bad-name",
                format!(
                    "`{}` cannot name a result: `<command>_<n>` names are the compiler's (the unnamed result of command n)",
                    r.text
                ),
                Some(format!("choose another name, e.g. `{cmd}_target{n}`")),
            );
            self.names
                .entry(r.text.clone())
                .or_insert((Defined::Unknown, line));
            return false;
        }
        if let Some((_, first)) = self.names.get(&r.text) {
            let first = *first;
            self.error(
                r.span,
                "redefined-name",
                format!("`{}` is already defined, on line {first}", r.text),
                Some(format!(
                    "a name is given once, so it always means the same object; choose another, e.g. `{}2`",
                    r.text
                )),
            );
            return false;
        }
        self.names.insert(r.text.clone(), (Defined::Target, line));
        true
    }

    fn number(
        &mut self,
        def: &CommandDef,
        ty: &ParamType,
        name: &str,
        x: f64,
        span: Span,
    ) -> Option<Val> {
        if !ty.is_numeric() {
            let hint = match ty {
                ParamType::Name => Some(
                    "name the object first, e.g. `find::::red=>cube`, then use `cube`".to_string(),
                ),
                _ => None,
            };
            self.error(
                span,
                "bad-type",
                format!(
                    "`{}` expects {} for `{name}`, found a number",
                    def.name,
                    ty.describe()
                ),
                hint,
            );
            return None;
        }
        if !x.is_finite() || x.abs() > MAX_NUMBER {
            self.error(
                span,
                "bad-value",
                format!("`{name}` is out of range: numbers are at most {MAX_NUMBER} in size"),
                None,
            );
            return None;
        }
        if matches!(ty, ParamType::Distance | ParamType::Duration) && x < 0.0 {
            self.error(
                span,
                "bad-value",
                format!("`{name}` is {}, which cannot be negative", ty.describe()),
                None,
            );
            return None;
        }
        Some(Val::Num(x))
    }

    fn word(
        &mut self,
        def: &CommandDef,
        ty: &ParamType,
        name: &str,
        w: &str,
        span: Span,
    ) -> Option<Val> {
        let lc = w.to_ascii_lowercase();
        match ty {
            ParamType::Colour => {
                if self.lib.colours.contains(&lc) {
                    return Some(Val::Text(lc));
                }
                if self.names.contains_key(w) {
                    self.error(
                        span,
                        "bad-type",
                        format!(
                            "`{}` expects a colour for `{name}`, found the name `{w}`",
                            def.name
                        ),
                        None,
                    );
                    return None;
                }
                let hint = did_you_mean(&lc, self.lib.colours.iter().map(String::as_str))
                    .unwrap_or_else(|| format!("the colours are: {}", self.lib.colours.join(", ")));
                self.error(
                    span,
                    "bad-value",
                    format!("`{w}` is not a colour the robots know"),
                    Some(hint),
                );
                None
            }
            ParamType::Choice(values) => {
                if values.contains(&lc) {
                    return Some(Val::Text(lc));
                }
                let hint = did_you_mean(&lc, values.iter().map(String::as_str))
                    .unwrap_or_else(|| format!("`{name}` is one of: {}", values.join(", ")));
                self.error(
                    span,
                    "bad-value",
                    format!("`{w}` is not a {name} `{}` knows", def.name),
                    Some(hint),
                );
                None
            }
            ParamType::Name => {
                if self.names.contains_key(w) {
                    return Some(Val::Text(w.to_string()));
                }
                let hint = if let Some(line) = self.all_results.get(w) {
                    Some(format!(
                        "`{w}` is named on line {line}, after this command: commands run in the order written"
                    ))
                } else if let Some(n) = self.names.keys().find(|n| n.eq_ignore_ascii_case(w)) {
                    Some(format!("names are case-sensitive: did you mean `{n}`?"))
                } else if let Some(h) = did_you_mean(w, self.names.keys().map(String::as_str)) {
                    Some(h)
                } else if self.lib.colours.contains(&lc) {
                    Some(format!(
                        "`{w}` is a colour; find the object and name it first: `find::::{lc}=>thing`"
                    ))
                } else {
                    Some(format!("name it first with `=>`: `find::::yellow=>{w}`"))
                };
                self.error(
                    span,
                    "undefined-name",
                    format!("`{w}` is not defined"),
                    hint,
                );
                None
            }
            _ => {
                let found = if self.names.contains_key(w) {
                    format!("the name `{w}`")
                } else {
                    format!("`{w}`")
                };
                self.error(
                    span,
                    "bad-type",
                    format!(
                        "`{}` expects {} for `{name}`, found {found}",
                        def.name,
                        ty.describe()
                    ),
                    Some("numbers are written like `3`, `-.5` or `0.25`".into()),
                );
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parser::parse;

    fn run(src: &str) -> (Vec<Step>, Vec<Diagnostic>) {
        let lib = Library::builtin();
        let (m, d) = parse("t.rtcl", src);
        assert!(d.is_empty(), "{d:?}");
        let map = SourceMap::new("t.rtcl", src);
        check(&map, &m, &lib)
    }

    fn codes(src: &str) -> Vec<(&'static str, u32, u32)> {
        run(src)
            .1
            .iter()
            .map(|d| (d.code, d.loc.line, d.loc.col))
            .collect()
    }

    #[test]
    fn the_papers_mission_checks() {
        let (steps, d) = run("find:.25:.25:.25:red=>cube\nmove:cube:0:0\n");
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(steps.len(), 2);
        assert_eq!(
            steps[0].values,
            vec![
                Some(Val::Num(0.25)),
                Some(Val::Num(0.25)),
                Some(Val::Num(0.25)),
                Some(Val::Text("red".into()))
            ]
        );
        assert_eq!(steps[0].result.as_deref(), Some("cube"));
        assert_eq!(steps[1].values[0], Some(Val::Text("cube".into())));
        assert_eq!(steps[1].text, "move:cube:0:0");
        assert_eq!(steps[1].index, 2);
    }

    #[test]
    fn commands_and_colours_ignore_case_names_do_not() {
        let (steps, d) = run("FIND::::Yellow=>Box\nMove:Box:1:1\n");
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(steps[0].values[3], Some(Val::Text("yellow".into())));
        let (_, d) = run("find::::yellow=>Box\nmove:box:1:1\n");
        assert_eq!(d[0].code, "undefined-name");
        assert_eq!(
            d[0].hint.as_deref(),
            Some("names are case-sensitive: did you mean `Box`?")
        );
    }

    #[test]
    fn every_problem_in_one_pass() {
        assert_eq!(
            codes("mvoe:box:1:2\nfind::::yelow=>box\nmove:box:1\ngoto:1:2:3\nwait:x=>w\n"),
            vec![
                ("unknown-command", 1, 1),
                ("bad-value", 2, 9),
                ("missing-param", 3, 11),
                ("too-many-params", 4, 10),
                ("bad-type", 5, 6),
                ("no-result", 5, 9),
            ]
        );
    }

    #[test]
    fn names_are_defined_once_before_use() {
        assert_eq!(
            codes("move:box:1:1\nfind::::red=>box\nfind::::blue=>box\nfind::::red=>red\n"),
            vec![
                ("undefined-name", 1, 6),
                ("redefined-name", 3, 15),
                ("bad-name", 4, 14),
            ]
        );
        let (_, d) = run("move:box:1:1\nfind::::red=>box\n");
        assert_eq!(
            d[0].hint.as_deref(),
            Some("`box` is named on line 2, after this command: commands run in the order written")
        );
    }

    #[test]
    fn optional_parameters_and_points() {
        assert!(codes("formation:line\nformation:column:1\nformation:triangle::2:3\n").is_empty());
        assert_eq!(
            codes("formation:triangle::2\nformation:line:.5::3\n"),
            vec![("missing-param", 1, 22), ("missing-param", 2, 19)]
        );
        assert_eq!(
            codes("move:::\nscan:0:0:1:-1:-2\n"),
            vec![
                ("missing-param", 1, 6),
                ("missing-param", 1, 7),
                ("missing-param", 1, 8),
                ("bad-value", 2, 15),
            ]
        );
    }

    #[test]
    fn a_vague_find_is_a_warning() {
        let (steps, d) = run("find=>thing\n");
        assert_eq!(steps.len(), 1);
        assert_eq!(d.len(), 1);
        assert!(!d[0].is_error());
        assert_eq!(d[0].code, "vague-target");
    }
}
