//! The command library (the paper's "precompiled repertoire"): for every
//! command, its parameters, the result it names, the mid-level behaviors it
//! decomposes into with their motor schemas and priorities, how they split
//! across the team, and when it is complete. All of it is data
//! (`commands.yaml`); a platform adds a command by adding an entry.
//!
//! The format is described in `docs/rtcl.md`. A library is checked when it
//! is loaded: every problem is reported with its file, line and column.

use crate::template::{Guard, JsonTemplate, Part, Template, Val};
use bite_core::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use bite_core::graph::spec::MembersSpec;
use bite_core::wm::Policy;
use bite_core::yaml::Ordered;
use serde::Deserialize;
use serde_saphyr::Spanned;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// The shipped library, `crates/bite-rtcl/commands.yaml`.
pub const BUILTIN: &str = include_str!("../commands.yaml");

/// Variables every command has: its behavior name, its position in the
/// mission, the name of its result, the size of the team.
pub const BUILTIN_VARS: &[&str] = &["step", "index", "result", "robots"];

/// Variables of a repeated child: which copy (1-based) and how many.
pub const REPEAT_VARS: &[&str] = &["i", "n"];

/// Motor schemas and their parameters, as the physical world
/// (`bite-sim`, `SchemaSpec::from_json`) takes them. Every schema also
/// takes `layer` (0-3) and `gain`.
pub const SCHEMAS: &[(&str, &[&str])] = &[
    ("move-to-goal", &["goal", "direction", "speed"]),
    ("avoid-obstacle", &["range"]),
    ("avoid-teammate", &["range"]),
    ("keep-slot", &["of", "side", "distance", "speed"]),
    ("follow", &["of", "distance", "speed"]),
    ("wander", &["speed", "period"]),
    ("scan", &["region", "spacing", "speed"]),
    ("face", &["target"]),
    ("look-around", &[]),
    ("push", &["object", "goal", "offset", "speed"]),
    ("stop", &[]),
];

/// What a parameter holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ParamType {
    /// Any number.
    Number,
    /// A length in metres, not negative.
    Distance,
    /// A time in seconds, not negative.
    Duration,
    /// An x coordinate in metres, relative to the mission origin.
    X,
    /// A y coordinate in metres, relative to the mission origin.
    Y,
    /// A colour from the library's list.
    Colour,
    /// The name of an earlier command's result.
    Name,
    /// One of a fixed set of words.
    Choice(Vec<String>),
}

impl ParamType {
    fn parse(s: &str, values: Option<&Vec<String>>) -> Option<ParamType> {
        Some(match s {
            "number" => ParamType::Number,
            "distance" => ParamType::Distance,
            "duration" => ParamType::Duration,
            "x" => ParamType::X,
            "y" => ParamType::Y,
            "colour" | "color" => ParamType::Colour,
            "name" => ParamType::Name,
            "choice" => ParamType::Choice(
                values
                    .map(|v| v.iter().map(|s| s.to_ascii_lowercase()).collect())
                    .unwrap_or_default(),
            ),
            _ => return None,
        })
    }

    /// True for the types written as numbers.
    pub fn is_numeric(&self) -> bool {
        matches!(
            self,
            ParamType::Number
                | ParamType::Distance
                | ParamType::Duration
                | ParamType::X
                | ParamType::Y
        )
    }

    /// How the type is named in messages: "a distance (metres)".
    pub fn describe(&self) -> String {
        match self {
            ParamType::Number => "a number".into(),
            ParamType::Distance => "a distance in metres".into(),
            ParamType::Duration => "a duration in seconds".into(),
            ParamType::X => "an x coordinate in metres".into(),
            ParamType::Y => "a y coordinate in metres".into(),
            ParamType::Colour => "a colour".into(),
            ParamType::Name => "the name of an earlier result".into(),
            ParamType::Choice(v) => format!("one of {}", v.join(", ")),
        }
    }
}

/// One parameter of a command.
#[derive(Clone, Debug)]
pub struct ParamDef {
    /// Its name (also its variable in templates).
    pub name: String,
    /// What it holds.
    pub ty: ParamType,
    /// May be left empty (unknown) or left out at the end of the line.
    pub optional: bool,
    /// The value used when it is left empty.
    pub default: Option<Val>,
    /// What it means, for messages and documentation.
    pub doc: Option<String>,
}

/// What a command's result designates.
#[derive(Clone, Debug)]
pub struct ResultDef {
    /// The parameter giving the target's colour.
    pub colour: Option<String>,
    /// The parameters giving its length, width and height.
    pub size: Option<[String; 3]>,
}

/// A motor schema of a skill, with its guard.
#[derive(Clone, Debug)]
pub struct SchemaDef {
    /// Included only when this holds.
    pub guard: Option<Guard>,
    /// The schema (`if` removed), strings as templates.
    pub template: JsonTemplate,
    /// Where it is written.
    pub loc: Loc,
}

/// A child of a split phase: an execution chain of one atomic behavior.
#[derive(Clone, Debug)]
pub struct ChildDef {
    /// Its name (the behavior is `{step}_{name}`, `{step}_{name}_{i}` when
    /// repeated).
    pub name: String,
    /// Included only when this holds.
    pub guard: Option<Guard>,
    /// Free text.
    pub description: Option<Template>,
    /// How many robots it takes.
    pub members: Option<MembersSpec>,
    /// Given its robots before the other children when the team is too
    /// small for all (`critical` in the graph).
    pub critical: bool,
    /// One copy per value of `i` = 1..=repeat.
    pub repeat: Option<Template>,
    /// Its own termination condition.
    pub until: Option<Template>,
    /// Its motor schemas.
    pub skill: Vec<SchemaDef>,
    /// Atomic behaviors that follow it in its execution chain (`next`),
    /// each when the one before ends.
    pub then: Vec<ThenDef>,
    /// Where it is written.
    pub loc: Loc,
}

/// A later step of a child's execution chain.
#[derive(Clone, Debug)]
pub struct ThenDef {
    /// Its name (the behavior is `{step}_{name}`, `{step}_{name}_{i}` in a
    /// repeated child).
    pub name: String,
    /// Free text.
    pub description: Option<Template>,
    /// Its termination condition (required but for the last step).
    pub until: Option<Template>,
    /// Its motor schemas.
    pub skill: Vec<SchemaDef>,
    /// Where it is written.
    pub loc: Loc,
}

/// What a phase consists of.
#[derive(Clone, Debug)]
pub enum Body {
    /// The whole team runs one skill.
    Skill(Vec<SchemaDef>),
    /// The team splits among children (an allocation point).
    Split(Vec<ChildDef>),
}

/// One mid-level team behavior of a command.
#[derive(Clone, Debug)]
pub struct PhaseDef {
    /// Its name (the behavior is `{step}_{name}` when the command has
    /// several phases).
    pub name: String,
    /// Included only when this holds.
    pub guard: Option<Guard>,
    /// Free text.
    pub description: Option<Template>,
    /// Its termination condition.
    pub until: Option<Template>,
    /// Termination protocol, if not the graph's default.
    pub terminate: Option<String>,
    /// Its skill or its children.
    pub body: Body,
    /// Where it is written.
    pub loc: Loc,
}

/// One command.
#[derive(Clone, Debug)]
pub struct CommandDef {
    /// Its name (lower case).
    pub name: String,
    /// One line on what it does.
    pub summary: Option<String>,
    /// Its parameters, in order.
    pub params: Vec<ParamDef>,
    /// Points made of two coordinate parameters: `goal: [x, y]`.
    pub points: Vec<(String, [String; 2])>,
    /// Constants and derived values, in order.
    pub lets: Vec<(String, Template)>,
    /// The result it names, if any.
    pub result: Option<ResultDef>,
    /// Beliefs it defines (`{step}_{name}`), as condition templates.
    pub beliefs: Vec<(String, Template)>,
    /// Termination condition of the whole command (with several phases).
    pub until: Option<Template>,
    /// Its mid-level behaviors, in order.
    pub phases: Vec<PhaseDef>,
    /// The smallest team it works with (a warning below).
    pub min_robots: usize,
    /// What the robots tell each other while it runs (`sharing:` in the
    /// library, a world-model policy): a mission's graph shares what any
    /// of its commands needs ([`bite_core::wm::Policy::union`]).
    pub sharing: Policy,
    /// Where it is written.
    pub loc: Loc,
}

impl CommandDef {
    /// `move:object:x:y`, with `[...]` around optional parameters.
    pub fn usage(&self) -> String {
        let mut s = self.name.clone();
        for p in &self.params {
            if p.optional {
                s.push_str(&format!(":[{}]", p.name));
            } else {
                s.push_str(&format!(":{}", p.name));
            }
        }
        if self.result.is_some() {
            s.push_str("[=>name]");
        }
        s
    }

    /// The parameter called `name`.
    pub fn param(&self, name: &str) -> Option<&ParamDef> {
        self.params.iter().find(|p| p.name == name)
    }
}

/// A command library.
#[derive(Clone, Debug)]
pub struct Library {
    /// The file it was read from.
    pub file: Arc<str>,
    /// Its name.
    pub name: String,
    /// Colours a `colour` parameter accepts (lower case).
    pub colours: Vec<String>,
    /// The commands, by name.
    pub commands: BTreeMap<String, CommandDef>,
}

// ---------------------------------------------------------------------------
// The file's shape.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LibrarySpec {
    library: Option<String>,
    #[allow(dead_code)]
    description: Option<String>,
    colours: Option<Vec<Spanned<String>>>,
    commands: Spanned<Ordered<CommandSpec>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CommandSpec {
    summary: Option<String>,
    #[serde(default)]
    params: Vec<Spanned<ParamSpec>>,
    #[serde(default)]
    points: Ordered<Vec<Spanned<String>>>,
    #[serde(default, rename = "let")]
    lets: Ordered<serde_json::Value>,
    result: Option<Spanned<ResultSpec>>,
    #[serde(default)]
    beliefs: Ordered<String>,
    until: Option<Spanned<String>>,
    min_robots: Option<usize>,
    sharing: Option<Spanned<String>>,
    phases: Option<Spanned<Vec<Spanned<PhaseSpec>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamSpec {
    name: Spanned<String>,
    #[serde(rename = "type")]
    ty: Spanned<String>,
    #[serde(default)]
    optional: bool,
    default: Option<Spanned<serde_json::Value>>,
    values: Option<Vec<String>>,
    doc: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ResultSpec {
    kind: Spanned<String>,
    colour: Option<Spanned<String>>,
    size: Option<Spanned<Vec<Spanned<String>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PhaseSpec {
    name: Spanned<String>,
    #[serde(rename = "if")]
    guard: Option<Spanned<String>>,
    description: Option<Spanned<String>>,
    until: Option<Spanned<String>>,
    terminate: Option<Spanned<String>>,
    skill: Option<Vec<Spanned<serde_json::Value>>>,
    children: Option<Vec<Spanned<ChildSpec>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ChildSpec {
    name: Spanned<String>,
    #[serde(rename = "if")]
    guard: Option<Spanned<String>>,
    description: Option<Spanned<String>>,
    members: Option<Spanned<MembersSpec>>,
    critical: Option<Spanned<bool>>,
    repeat: Option<Spanned<serde_json::Value>>,
    until: Option<Spanned<String>>,
    skill: Option<Vec<Spanned<serde_json::Value>>>,
    then: Option<Vec<Spanned<ThenSpec>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ThenSpec {
    name: Spanned<String>,
    description: Option<Spanned<String>>,
    until: Option<Spanned<String>>,
    skill: Option<Vec<Spanned<serde_json::Value>>>,
}

fn loc_of<T>(s: &Spanned<T>) -> Loc {
    Loc::from(s.referenced)
}

/// An identifier: ASCII letter or `_`, then letters, digits, `_`.
pub fn is_ident(s: &str) -> bool {
    let mut c = s.chars();
    c.next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && c.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Scope of a template: which variables it may read.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Scope {
    /// `let`: params, points, builtins, earlier lets.
    Let,
    /// A belief: anything but beliefs.
    Belief,
    /// Phases, children, schemas: everything.
    Body,
    /// Inside a repeated child: everything and `i`, `n`.
    Repeated,
}

/// A condition's names, all taken: a library's template is checked for
/// its syntax only (what a name means is known once it is filled in).
struct AnyName;

impl bite_core::cond::Resolver for AnyName {
    fn belief(&mut self, _: &str) -> bite_core::ids::BeliefId {
        bite_core::ids::BeliefId(0)
    }
    fn behavior(&self, _: &str) -> Option<bite_core::ids::BehaviorId> {
        Some(bite_core::ids::BehaviorId(0))
    }
}

struct Checker<'a> {
    file: Arc<str>,
    text: &'a str,
    diags: Vec<Diagnostic>,
}

impl Checker<'_> {
    fn err(&mut self, loc: Loc, message: impl Into<String>) -> &mut Diagnostic {
        let d = Diagnostic::error(&self.file, loc, "library", message)
            .with_detail(bite_core::yaml::snippet(self.text, loc));
        self.diags.push(d);
        let n = self.diags.len() - 1;
        &mut self.diags[n]
    }

    /// Where byte `offset` of a template written at `loc` is: the template
    /// text is looked for on that line (after the column), so that quoted
    /// and plain scalars both point at the right character.
    fn loc_in(&self, loc: Loc, template: &str, offset: usize) -> Loc {
        if !loc.is_known() {
            return loc;
        }
        let line = bite_core::yaml::lines(self.text)
            .nth(loc.line as usize - 1)
            .unwrap_or("");
        let from: usize = line
            .char_indices()
            .nth(loc.col.saturating_sub(1) as usize)
            .map_or(line.len(), |(i, _)| i);
        match line.get(from..).and_then(|rest| rest.find(template)) {
            Some(i) => {
                let byte = from + i + offset.min(template.len());
                let col = line.get(..byte).map_or(0, |s| s.chars().count());
                Loc::new(loc.line, u32::try_from(col + 1).unwrap_or(u32::MAX))
            }
            None => loc,
        }
    }

    fn template(&mut self, text: &str, loc: Loc, vars: &Vars, scope: Scope) -> Option<Template> {
        match Template::parse(text) {
            Ok(t) => {
                for (v, at) in t.vars() {
                    self.var(v, text, at, loc, vars, scope);
                }
                Some(t)
            }
            Err(e) => {
                let l = self.loc_in(loc, text, e.at);
                self.err(l, format!("in template `{text}`: {}", e.message));
                None
            }
        }
    }

    /// [`Checker::template`] for a condition (an `until`, a belief): it
    /// must also parse as one once its placeholders are filled in. The
    /// placeholders are tried as a name, as a number and as a comparison
    /// (a choice may be one), and only a condition that parses as none of
    /// them is an error, here at the library's line rather than in the
    /// compiled graph.
    fn condition(&mut self, text: &str, loc: Loc, vars: &Vars, scope: Scope) -> Option<Template> {
        let t = self.template(text, loc, vars, scope)?;
        // The distinct placeholders, each given a stand-in of its own:
        // every combination while there are few of them, the same one for
        // all beyond.
        const STAND_INS: [&str; 3] = ["x", "1", "=="];
        let mut distinct: Vec<&crate::template::Expr> = Vec::new();
        for p in &t.parts {
            if let Part::Expr(e) = p
                && !distinct.contains(&e)
            {
                distinct.push(e);
            }
        }
        // Combination `n`'s stand-in for distinct placeholder `k`.
        let each = distinct.len() <= 4;
        let pick = |n: usize, k: usize| match each {
            true => n / STAND_INS.len().pow(k as u32) % STAND_INS.len(),
            false => n,
        };
        let count = match each {
            true => STAND_INS.len().pow(distinct.len() as u32),
            false => STAND_INS.len(),
        };
        let mut err = None;
        for n in 0..count {
            let mut filled = String::new();
            for p in &t.parts {
                match p {
                    Part::Lit(l) => filled.push_str(l),
                    Part::Expr(e) => {
                        let k = distinct.iter().position(|d| d == &e).unwrap_or(0);
                        filled.push_str(STAND_INS[pick(n, k)]);
                    }
                }
            }
            match bite_core::cond::Expr::parse(&filled, &mut AnyName) {
                Ok(_) => return Some(t),
                Err(e) => err = err.or(Some(e)),
            }
        }
        if let Some(e) = err {
            let d = self.err(
                loc,
                format!(
                    "condition `{text}` does not parse (its placeholders read as names, numbers or comparisons): {}",
                    e.message
                ),
            );
            d.hint = e.hint;
        }
        None
    }

    fn var(&mut self, v: &str, text: &str, at: usize, loc: Loc, vars: &Vars, scope: Scope) {
        let l = self.loc_in(loc, text, at);
        let ok = match vars.kind.get(v) {
            Some(VarKind::Belief) => !matches!(scope, Scope::Let | Scope::Belief),
            Some(VarKind::Let(i)) if scope == Scope::Let => *i < vars.lets_done,
            Some(_) => true,
            None => REPEAT_VARS.contains(&v) && scope == Scope::Repeated,
        };
        if ok {
            return;
        }
        let msg = match (vars.kind.get(v), scope) {
            (Some(VarKind::Belief), Scope::Belief) => {
                format!("belief `{v}` is used in a belief; beliefs read percepts, not each other")
            }
            (Some(VarKind::Belief), _) => format!("belief `{v}` cannot be used in `let`"),
            (Some(VarKind::Let(_)), _) => format!("`{v}` is used before it is defined in `let`"),
            _ if REPEAT_VARS.contains(&v) => {
                format!("`{{{v}}}` is only known inside a child with `repeat`")
            }
            _ => format!("unknown variable `{{{v}}}`"),
        };
        let mut names: Vec<&str> = vars.kind.keys().map(String::as_str).collect();
        if scope == Scope::Repeated {
            names.extend(REPEAT_VARS);
        }
        let hint = did_you_mean(v, names.iter().copied())
            .unwrap_or_else(|| format!("the variables of this command are: {}", names.join(", ")));
        self.err(l, msg).hint = Some(hint);
    }

    fn guard(&mut self, g: &Option<Spanned<String>>, vars: &Vars) -> Option<Guard> {
        let g = g.as_ref()?;
        let loc = loc_of(g);
        match Guard::parse(&g.value) {
            Ok(guard) => {
                if !vars.kind.contains_key(guard.var()) {
                    let names: Vec<&str> = vars.kind.keys().map(String::as_str).collect();
                    let hint = did_you_mean(guard.var(), names.iter().copied());
                    let d = self.err(
                        loc,
                        format!(
                            "`if` tests `{}`, which this command does not have",
                            guard.var()
                        ),
                    );
                    d.hint = hint;
                }
                Some(guard)
            }
            Err(e) => {
                self.err(loc, e);
                None
            }
        }
    }

    fn schemas(
        &mut self,
        list: &[Spanned<serde_json::Value>],
        vars: &Vars,
        scope: Scope,
    ) -> Vec<SchemaDef> {
        let mut out = Vec::new();
        for s in list {
            let loc = loc_of(s);
            let serde_json::Value::Object(m) = &s.value else {
                self.err(
                    loc,
                    "a schema is a mapping: `{ schema: wander, speed: 0.25, layer: 1 }`",
                );
                continue;
            };
            let mut m = m.clone();
            let guard = match m.remove("if") {
                None => None,
                Some(serde_json::Value::String(g)) => {
                    let sp = Spanned::new(g, s.referenced, s.defined);
                    self.guard(&Some(sp), vars)
                }
                Some(_) => {
                    self.err(loc, "`if` is a test such as `goal` or `shape == line`");
                    None
                }
            };
            let Some(name) = m.get("schema").and_then(|v| v.as_str()).map(str::to_string) else {
                self.err(loc, "a schema needs `schema: <name>`");
                continue;
            };
            let Some((_, params)) = SCHEMAS.iter().find(|(n, _)| *n == name) else {
                let hint =
                    did_you_mean(&name, SCHEMAS.iter().map(|(n, _)| *n)).unwrap_or_else(|| {
                        format!(
                            "the schemas are: {}",
                            SCHEMAS
                                .iter()
                                .map(|(n, _)| *n)
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    });
                self.err(loc, format!("unknown schema `{name}`")).hint = Some(hint);
                continue;
            };
            match m.get("layer") {
                Some(l) if l.as_u64().is_some_and(|l| l <= 3) => {}
                Some(_) => {
                    self.err(loc, "`layer` is a priority from 0 to 3");
                }
                None => {
                    self.err(loc, format!("schema `{name}` needs a `layer` (its priority, 0 to 3)"))
                        .hint = Some(
                        "the layer is what makes the same schema rank differently in different commands"
                            .into(),
                    );
                }
            }
            if m.get("gain").is_some_and(|g| !g.is_number()) {
                self.err(loc, "`gain` must be a number");
            }
            for k in m.keys() {
                if !matches!(k.as_str(), "schema" | "layer" | "gain")
                    && !params.contains(&k.as_str())
                {
                    let hint = did_you_mean(k, params.iter().copied()).unwrap_or_else(|| {
                        if params.is_empty() {
                            "it takes none".into()
                        } else {
                            format!("its parameters are: {}", params.join(", "))
                        }
                    });
                    self.err(loc, format!("schema `{name}` has no parameter `{k}`"))
                        .hint = Some(hint);
                }
            }
            let value = serde_json::Value::Object(m);
            match JsonTemplate::parse(&value) {
                Ok(t) => {
                    // Check variables by walking the strings.
                    check_json_vars(self, &value, loc, vars, scope);
                    out.push(SchemaDef {
                        guard,
                        template: t,
                        loc,
                    });
                }
                Err(e) => {
                    self.err(loc, format!("in schema `{name}`: {}", e.message));
                }
            }
        }
        out
    }
}

fn check_json_vars(
    c: &mut Checker<'_>,
    v: &serde_json::Value,
    loc: Loc,
    vars: &Vars,
    scope: Scope,
) {
    match v {
        serde_json::Value::String(s) => {
            if let Ok(t) = Template::parse(s) {
                for (name, at) in t.vars() {
                    c.var(name, s, at, loc, vars, scope);
                }
            }
        }
        serde_json::Value::Array(a) => a
            .iter()
            .for_each(|x| check_json_vars(c, x, loc, vars, scope)),
        serde_json::Value::Object(m) => m
            .values()
            .for_each(|x| check_json_vars(c, x, loc, vars, scope)),
        _ => {}
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum VarKind {
    Builtin,
    Param,
    Point,
    Let(usize),
    Belief,
}

struct Vars {
    kind: BTreeMap<String, VarKind>,
    lets_done: usize,
}

impl Library {
    /// The shipped library (`commands.yaml`, compiled in).
    pub fn builtin() -> Library {
        static LIB: OnceLock<Library> = OnceLock::new();
        LIB.get_or_init(|| match Library::from_str("commands.yaml", BUILTIN) {
            Ok(l) => l,
            // The shipped file is tested; should it ever be broken, fail
            // loudly with the diagnostics.
            Err(e) => panic!("the built-in command library is invalid:\n{e}"),
        })
        .clone()
    }

    /// Read a library file.
    pub fn load(path: &Path) -> Result<Library, Diagnostics> {
        let (file, text) = bite_core::yaml::read_file(path)?;
        Library::from_str(&file, &text)
    }

    /// Read a library from text; `file` names it in messages.
    pub fn from_str(file: &str, text: &str) -> Result<Library, Diagnostics> {
        let file: Arc<str> = Arc::from(file);
        let spec: LibrarySpec = bite_core::yaml::parse(&file, text)?;
        let mut c = Checker {
            file: file.clone(),
            text,
            diags: Vec::new(),
        };
        let colours: Vec<String> = match &spec.colours {
            Some(list) => {
                let mut out = Vec::new();
                for col in list {
                    let lc = col.value.to_ascii_lowercase();
                    if !is_ident(&lc) {
                        c.err(loc_of(col), format!("colour `{}` is not a name", col.value));
                    } else if out.contains(&lc) {
                        c.err(loc_of(col), format!("colour `{lc}` is listed twice"));
                    } else {
                        out.push(lc);
                    }
                }
                out
            }
            None => Vec::new(),
        };
        let mut commands = BTreeMap::new();
        for (name, cmd) in &spec.commands.value.0 {
            let loc = loc_of(name);
            let lc = name.value.to_ascii_lowercase();
            if !is_ident(&name.value) || lc != name.value {
                c.err(
                    loc,
                    format!(
                        "command name `{}` must be a lower-case name (letters, digits, `_`)",
                        name.value
                    ),
                );
                continue;
            }
            if let Some(def) = command(&mut c, &lc, loc, &cmd.value, &colours) {
                commands.insert(lc, def);
            }
        }
        if commands.is_empty() && c.diags.is_empty() {
            c.err(loc_of(&spec.commands), "the library has no commands");
        }
        if !c.diags.is_empty() {
            c.diags.sort_by_key(|d| d.loc);
            return Err(Diagnostics(c.diags));
        }
        Ok(Library {
            file,
            name: spec.library.unwrap_or_else(|| "library".into()),
            colours,
            commands,
        })
    }

    /// The command called `name` (case-insensitive).
    pub fn command(&self, name: &str) -> Option<&CommandDef> {
        // Names are lower case; a command written in capitals is looked
        // up again.
        (self.commands.get(name)).or_else(|| {
            (name.bytes().any(|b| b.is_ascii_uppercase()))
                .then(|| self.commands.get(&name.to_ascii_lowercase()))
                .flatten()
        })
    }

    /// The command names, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.commands.keys().map(String::as_str)
    }
}

fn command(
    c: &mut Checker<'_>,
    name: &str,
    loc: Loc,
    cmd: &CommandSpec,
    colours: &[String],
) -> Option<CommandDef> {
    let before = c.diags.len();
    let mut vars = Vars {
        kind: BUILTIN_VARS
            .iter()
            .map(|v| (v.to_string(), VarKind::Builtin))
            .collect(),
        lets_done: 0,
    };
    let declare = |c: &mut Checker<'_>, vars: &mut Vars, n: &str, l: Loc, k: VarKind| {
        if !is_ident(n) {
            c.err(
                l,
                format!("`{n}` is not a valid name (letters, digits, `_`)"),
            );
        } else if REPEAT_VARS.contains(&n) {
            c.err(l, format!("`{n}` is reserved for repeated children"));
        } else if vars.kind.contains_key(n) {
            c.err(
                l,
                format!("`{n}` is defined twice in command `{name}` (or is a built-in variable)"),
            )
            .hint = Some(format!(
                "parameters, points, `let` values and beliefs share one namespace; the built-in variables are {}",
                BUILTIN_VARS.join(", ")
            ));
        } else {
            vars.kind.insert(n.to_string(), k);
        }
    };
    // Parameters.
    let mut params = Vec::new();
    for p in &cmd.params {
        let p = &p.value;
        let ploc = loc_of(&p.name);
        declare(c, &mut vars, &p.name.value, ploc, VarKind::Param);
        let Some(ty) = ParamType::parse(&p.ty.value, p.values.as_ref()) else {
            let types = [
                "number", "distance", "duration", "x", "y", "colour", "name", "choice",
            ];
            let hint = did_you_mean(&p.ty.value, types)
                .unwrap_or_else(|| format!("the types are: {}", types.join(", ")));
            c.err(
                loc_of(&p.ty),
                format!("unknown parameter type `{}`", p.ty.value),
            )
            .hint = Some(hint);
            continue;
        };
        match (&ty, &p.values) {
            (ParamType::Choice(v), _) if v.is_empty() || v.iter().any(|w| !is_ident(w)) => {
                c.err(
                    loc_of(&p.ty),
                    "a `choice` parameter needs `values:`, a list of names",
                );
            }
            (ParamType::Choice(_), _) | (_, None) => {}
            (_, Some(_)) => {
                c.err(loc_of(&p.ty), "`values` is only for `type: choice`");
            }
        }
        let default = match &p.default {
            None => None,
            Some(d) if !p.optional => {
                c.err(loc_of(d), "only an optional parameter has a default")
                    .hint = Some("add `optional: true`".into());
                None
            }
            Some(d) => default_value(c, &ty, d, colours),
        };
        params.push(ParamDef {
            name: p.name.value.clone(),
            ty,
            optional: p.optional,
            default,
            doc: p.doc.clone(),
        });
    }
    // Points.
    let mut points = Vec::new();
    for (pname, coords) in &cmd.points.0 {
        let ploc = loc_of(pname);
        declare(c, &mut vars, &pname.value, ploc, VarKind::Point);
        let ok = match coords.value.as_slice() {
            [x, y] => {
                let ty = |n: &str| params.iter().find(|p| p.name == n).map(|p| p.ty.clone());
                if ty(&x.value) != Some(ParamType::X) || ty(&y.value) != Some(ParamType::Y) {
                    c.err(
                        loc_of(coords),
                        format!(
                            "point `{}` is made of an `x` and a `y` parameter, in that order",
                            pname.value
                        ),
                    );
                    None
                } else {
                    Some([x.value.clone(), y.value.clone()])
                }
            }
            _ => {
                c.err(loc_of(coords), "a point is `[x_param, y_param]`");
                None
            }
        };
        if let Some(xy) = ok {
            points.push((pname.value.clone(), xy));
        }
    }
    // `let`, then beliefs (declared first, so that bodies may use them).
    for (i, (lname, _)) in cmd.lets.0.iter().enumerate() {
        declare(c, &mut vars, &lname.value, loc_of(lname), VarKind::Let(i));
    }
    for (bname, _) in &cmd.beliefs.0 {
        if matches!(
            bname.value.as_str(),
            "seen" | "pos" | "distance" | "bearing"
        ) {
            c.err(
                loc_of(bname),
                format!(
                    "a belief cannot be called `{}`: `{{step}}_{}` would clash with a target's percept",
                    bname.value, bname.value
                ),
            );
        }
        declare(c, &mut vars, &bname.value, loc_of(bname), VarKind::Belief);
    }
    let mut lets = Vec::new();
    for (i, (lname, v)) in cmd.lets.0.iter().enumerate() {
        vars.lets_done = i;
        let l = loc_of(v);
        let t = match &v.value {
            serde_json::Value::Number(n) => n.as_f64().map(|x| Template {
                parts: vec![crate::template::Part::Expr(crate::template::Expr::Num(x))],
            }),
            serde_json::Value::String(s) => c.template(s, l, &vars, Scope::Let),
            _ => {
                c.err(
                    l,
                    "a `let` value is a number or a template such as `\"{x + 1}\"`",
                );
                None
            }
        };
        if let Some(t) = t {
            lets.push((lname.value.clone(), t));
        }
    }
    vars.lets_done = cmd.lets.0.len();
    // Result.
    let result = cmd.result.as_ref().and_then(|r| {
        let rs = &r.value;
        if rs.kind.value != "target" {
            c.err(
                loc_of(&rs.kind),
                format!("unknown result kind `{}`", rs.kind.value),
            )
            .hint = Some("the only kind is `target` (an object the robots can perceive)".into());
            return None;
        }
        let typed = |c: &mut Checker<'_>,
                     n: &Spanned<String>,
                     want: &str,
                     ok: &dyn Fn(&ParamType) -> bool| {
            match params.iter().find(|p| p.name == n.value) {
                Some(p) if ok(&p.ty) => Some(n.value.clone()),
                _ => {
                    c.err(
                        loc_of(n),
                        format!("`{}` must be a parameter of type {want}", n.value),
                    );
                    None
                }
            }
        };
        let colour = rs
            .colour
            .as_ref()
            .and_then(|n| typed(c, n, "colour", &|t| *t == ParamType::Colour));
        let size = rs.size.as_ref().and_then(|s| match s.value.as_slice() {
            [l, w, h] => {
                let l = typed(c, l, "distance", &ParamType::is_numeric);
                let w = typed(c, w, "distance", &ParamType::is_numeric);
                let h = typed(c, h, "distance", &ParamType::is_numeric);
                Some([l?, w?, h?])
            }
            _ => {
                c.err(loc_of(s), "`size` is `[length, width, height]` parameters");
                None
            }
        });
        Some(ResultDef { colour, size })
    });
    // Beliefs.
    let mut beliefs = Vec::new();
    for (bname, b) in &cmd.beliefs.0 {
        if let Some(t) = c.condition(&b.value, loc_of(b), &vars, Scope::Belief) {
            beliefs.push((bname.value.clone(), t));
        }
    }
    let until = cmd
        .until
        .as_ref()
        .and_then(|u| c.condition(&u.value, loc_of(u), &vars, Scope::Body));
    // Phases.
    let mut phases = Vec::new();
    let mut names = BTreeSet::new();
    match &cmd.phases {
        None => {
            c.err(loc, format!("command `{name}` has no `phases`")).hint =
                Some("a command decomposes into at least one phase (a team behavior)".into());
        }
        Some(list) if list.value.is_empty() => {
            c.err(loc_of(list), format!("command `{name}` has no `phases`"));
        }
        Some(list) => {
            for ph in &list.value {
                if let Some(p) = phase(c, &ph.value, loc_of(ph), &vars, &mut names, until.is_some())
                {
                    phases.push(p);
                }
            }
        }
    }
    let sharing = match &cmd.sharing {
        None => Policy::None,
        Some(s) => Policy::parse(&s.value).unwrap_or_else(|| {
            let hint = did_you_mean(&s.value, Policy::NAMES)
                .unwrap_or_else(|| format!("the policies are: {}", Policy::NAMES.join(", ")));
            c.err(loc_of(s), format!("unknown sharing policy `{}`", s.value))
                .hint = Some(hint);
            Policy::None
        }),
    };
    if c.diags.len() > before {
        return None;
    }
    Some(CommandDef {
        name: name.to_string(),
        summary: cmd.summary.clone(),
        params,
        points,
        lets,
        result,
        beliefs,
        until,
        phases,
        min_robots: cmd.min_robots.unwrap_or(1),
        sharing,
        loc,
    })
}

fn behavior_name(c: &mut Checker<'_>, n: &Spanned<String>, names: &mut BTreeSet<String>) {
    if !is_ident(&n.value) {
        c.err(
            loc_of(n),
            format!(
                "`{}` is not a valid behavior name (letters, digits, `_`)",
                n.value
            ),
        );
    } else if !names.insert(n.value.clone()) {
        c.err(loc_of(n), format!("`{}` is used twice", n.value))
            .hint = Some("phase names are unique in a command, child names in a phase: they become `{step}_{name}`".into());
    }
}

fn phase(
    c: &mut Checker<'_>,
    p: &PhaseSpec,
    loc: Loc,
    vars: &Vars,
    names: &mut BTreeSet<String>,
    command_until: bool,
) -> Option<PhaseDef> {
    behavior_name(c, &p.name, names);
    let guard = c.guard(&p.guard, vars);
    let description = p
        .description
        .as_ref()
        .and_then(|d| c.template(&d.value, loc_of(d), vars, Scope::Body));
    let until = p
        .until
        .as_ref()
        .and_then(|u| c.condition(&u.value, loc_of(u), vars, Scope::Body));
    let terminate = p.terminate.as_ref().map(|t| {
        if !t
            .value
            .chars()
            .all(|ch| ch.is_ascii_alphanumeric() || matches!(ch, '.' | '-' | '_'))
            || t.value.is_empty()
        {
            c.err(loc_of(t), format!("`{}` is not a protocol name", t.value));
        }
        t.value.clone()
    });
    let body = match (&p.skill, &p.children) {
        (Some(s), None) => {
            if s.is_empty() {
                c.err(loc, "`skill` needs at least one schema");
            }
            if p.until.is_none() && !command_until {
                c.err(
                    loc,
                    format!(
                        "phase `{}` runs a skill but has no `until`: it would never end",
                        p.name.value
                    ),
                );
            }
            Body::Skill(c.schemas(s, vars, Scope::Body))
        }
        (None, Some(children)) => {
            if children.is_empty() {
                c.err(loc, "`children` needs at least one child");
            }
            let mut out = Vec::new();
            let mut child_names = BTreeSet::new();
            for ch in children {
                let cl = loc_of(ch);
                let ch = &ch.value;
                behavior_name(c, &ch.name, &mut child_names);
                let scope = if ch.repeat.is_some() {
                    Scope::Repeated
                } else {
                    Scope::Body
                };
                let guard = c.guard(&ch.guard, vars);
                let repeat = ch.repeat.as_ref().and_then(|r| match &r.value {
                    serde_json::Value::Number(n) if n.as_u64().is_some() => Some(Template {
                        parts: vec![crate::template::Part::Expr(crate::template::Expr::Num(
                            n.as_f64().unwrap_or(1.0),
                        ))],
                    }),
                    serde_json::Value::String(s) => c.template(s, loc_of(r), vars, Scope::Body),
                    _ => {
                        c.err(
                            loc_of(r),
                            "`repeat` is a count or a template such as `\"{robots}\"`",
                        );
                        None
                    }
                });
                let description = ch
                    .description
                    .as_ref()
                    .and_then(|d| c.template(&d.value, loc_of(d), vars, scope));
                let until = ch
                    .until
                    .as_ref()
                    .and_then(|u| c.condition(&u.value, loc_of(u), vars, scope));
                let then_list = ch.then.as_deref().unwrap_or_default();
                let last_until = then_list
                    .last()
                    .map_or(ch.until.is_some(), |t| t.value.until.is_some());
                if p.until.is_none() && !last_until && !command_until {
                    c.err(
                        cl,
                        format!(
                            "child `{}` has no `until` at the end of its chain, nor has its phase `{}`: it would never end",
                            ch.name.value, p.name.value
                        ),
                    );
                }
                if !then_list.is_empty() && ch.until.is_none() {
                    c.err(
                        cl,
                        format!(
                            "child `{}` is followed by `then` steps, so it needs an `until` (when to go on)",
                            ch.name.value
                        ),
                    );
                }
                let mut then = Vec::new();
                for (k, t) in then_list.iter().enumerate() {
                    let tl = loc_of(t);
                    let t = &t.value;
                    behavior_name(c, &t.name, &mut child_names);
                    if k + 1 < then_list.len() && t.until.is_none() {
                        c.err(
                            tl,
                            format!(
                                "step `{}` is followed by another, so it needs an `until`",
                                t.name.value
                            ),
                        );
                    }
                    let description = t
                        .description
                        .as_ref()
                        .and_then(|d| c.template(&d.value, loc_of(d), vars, scope));
                    let until = t
                        .until
                        .as_ref()
                        .and_then(|u| c.condition(&u.value, loc_of(u), vars, scope));
                    let skill = match &t.skill {
                        Some(s) if !s.is_empty() => c.schemas(s, vars, scope),
                        _ => {
                            c.err(
                                tl,
                                format!(
                                    "step `{}` needs a `skill` (a list of schemas)",
                                    t.name.value
                                ),
                            );
                            Vec::new()
                        }
                    };
                    then.push(ThenDef {
                        name: t.name.value.clone(),
                        description,
                        until,
                        skill,
                        loc: tl,
                    });
                }
                let skill = match &ch.skill {
                    Some(s) if !s.is_empty() => c.schemas(s, vars, scope),
                    _ => {
                        c.err(
                            cl,
                            format!(
                                "child `{}` needs a `skill` (a list of schemas)",
                                ch.name.value
                            ),
                        );
                        Vec::new()
                    }
                };
                out.push(ChildDef {
                    name: ch.name.value.clone(),
                    guard,
                    description,
                    members: ch.members.as_ref().map(|m| m.value),
                    critical: ch.critical.as_ref().is_some_and(|c| c.value),
                    repeat,
                    until,
                    skill,
                    then,
                    loc: cl,
                });
            }
            Body::Split(out)
        }
        _ => {
            c.err(
                loc,
                format!(
                    "phase `{}` needs either `skill` or `children`",
                    p.name.value
                ),
            );
            return None;
        }
    };
    Some(PhaseDef {
        name: p.name.value.clone(),
        guard,
        description,
        until,
        terminate,
        body,
        loc,
    })
}

fn default_value(
    c: &mut Checker<'_>,
    ty: &ParamType,
    d: &Spanned<serde_json::Value>,
    colours: &[String],
) -> Option<Val> {
    let l = loc_of(d);
    match (ty, &d.value) {
        (t, serde_json::Value::Number(n)) if t.is_numeric() => {
            let x = n.as_f64().filter(|x| x.is_finite())?;
            if matches!(t, ParamType::Distance | ParamType::Duration) && x < 0.0 {
                c.err(l, "the default cannot be negative");
                return None;
            }
            Some(Val::Num(x))
        }
        (ParamType::Colour, serde_json::Value::String(s))
            if colours.contains(&s.to_ascii_lowercase()) =>
        {
            Some(Val::Text(s.to_ascii_lowercase()))
        }
        (ParamType::Choice(v), serde_json::Value::String(s))
            if v.contains(&s.to_ascii_lowercase()) =>
        {
            Some(Val::Text(s.to_ascii_lowercase()))
        }
        _ => {
            c.err(l, format!("the default must be {}", ty.describe()));
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_library_loads() {
        let lib = Library::from_str("commands.yaml", BUILTIN).unwrap_or_else(|e| panic!("{e}"));
        for c in [
            "find",
            "move",
            "goto",
            "scan",
            "wait",
            "formation",
            "follow",
        ] {
            assert!(lib.command(c).is_some(), "{c}");
        }
        assert_eq!(
            lib.command("MOVE").map(CommandDef::usage).as_deref(),
            Some("move:object:x:y")
        );
        assert_eq!(
            lib.command("find").map(CommandDef::usage).as_deref(),
            Some("find:[length]:[width]:[height]:[colour][=>name]")
        );
        assert!(lib.colours.iter().any(|c| c == "yellow"));
    }

    fn lib_err(text: &str) -> Vec<(u32, u32, String)> {
        match Library::from_str("lib.yaml", text) {
            Ok(_) => Vec::new(),
            Err(d) => {
                d.0.iter()
                    .map(|d| (d.loc.line, d.loc.col, d.message.clone()))
                    .collect()
            }
        }
    }

    #[test]
    fn yaml_errors_are_located() {
        let e = lib_err("commands:\n  wait:\n    parms: []\n");
        assert_eq!(e.len(), 1);
        assert_eq!((e[0].0, e[0].1), (3, 5));
        assert!(e[0].2.contains("unknown key `parms`"), "{e:?}");
    }

    #[test]
    fn an_unknown_sharing_policy_is_located_with_the_ones_there_are() {
        let text = "\
commands:
  go:
    sharing: focussed
    phases: [{ name: p, skill: [{ schema: stop, layer: 1 }], until: \"elapsed > 1\" }]
";
        let d = Library::from_str("lib.yaml", text).expect_err("unknown policy");
        let d = &d.0[0];
        assert_eq!((d.loc.line, d.loc.col), (3, 14));
        assert_eq!(d.message, "unknown sharing policy `focussed`");
        assert!(
            d.hint.as_deref().is_some_and(|h| h.contains("`focused`")),
            "{d:?}"
        );
        let lib = Library::from_str("lib.yaml", &text.replace("focussed", "focused+helpful"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            lib.command("go").map(|c| c.sharing),
            Some(Policy::FocusedHelpful)
        );
    }

    #[test]
    fn chains_need_conditions_to_go_on() {
        let text = "\
commands:
  go:
    phases:
      - name: p
        children:
          - name: a
            skill: [{ schema: stop, layer: 1 }]
            then:
              - { name: b, skill: [{ schema: stop, layer: 1 }] }
              - { name: c, skill: [{ schema: stop, layer: 1 }], until: \"elapsed > 1\" }
";
        let e = lib_err(text);
        let msgs: Vec<_> = e.iter().map(|(l, c, m)| format!("{l}:{c}: {m}")).collect();
        assert_eq!(
            msgs,
            vec![
                "6:13: child `a` is followed by `then` steps, so it needs an `until` (when to go on)",
                "9:17: step `b` is followed by another, so it needs an `until`",
            ],
            "{msgs:#?}"
        );
    }

    #[test]
    fn semantic_errors_are_located_and_all_reported() {
        let text = "\
commands:
  wait:
    params:
      - { name: seconds, type: duraton }
    phases:
      - name: hold
        skill:
          - { schema: stp, layer: 1 }
          - { schema: stop }
        until: \"elapsed >= {secnds}\"
";
        let e = lib_err(text);
        let msgs: Vec<_> = e.iter().map(|(l, c, m)| format!("{l}:{c}: {m}")).collect();
        assert_eq!(
            msgs,
            vec![
                "4:32: unknown parameter type `duraton`",
                "8:13: unknown schema `stp`",
                "9:13: schema `stop` needs a `layer` (its priority, 0 to 3)",
                "10:29: unknown variable `{secnds}`",
            ],
            "{msgs:#?}"
        );
    }

    /// A condition of the library that cannot parse is reported at the
    /// library's line, not in the graph a mission compiles to; one that
    /// parses once filled in (a placeholder as part of a name, or as a
    /// number) is not.
    #[test]
    fn a_condition_that_cannot_parse_is_located_in_the_library() {
        let text = "\
commands:
  wait:
    params:
      - { name: seconds, type: duration }
      - { name: what, type: name }
      - { name: op, type: name }
    beliefs:
      close: \"known({what}_pos) &&\"
    phases:
      - name: hold
        skill: [{ schema: stop, layer: 1 }]
        until: \"elapsed >= {seconds} && {what}_ok || runs({what}) > {seconds}\"
      - name: after
        skill: [{ schema: stop, layer: 1 }]
        until: \"elapsed >= {seconds} ! 2\"
      - name: compared
        skill: [{ schema: stop, layer: 1 }]
        until: \"runs({what}) {op} {seconds}\"
";
        let e = lib_err(text);
        let msgs: Vec<_> = e.iter().map(|(l, c, m)| format!("{l}:{c}: {m}")).collect();
        assert_eq!(msgs.len(), 2, "{msgs:#?}");
        assert!(
            msgs[0].starts_with("8:14: condition `known({what}_pos) &&` does not parse"),
            "{msgs:#?}"
        );
        assert!(
            msgs[1].starts_with("15:16: condition `elapsed >= {seconds} ! 2` does not parse"),
            "{msgs:#?}"
        );
    }
}
