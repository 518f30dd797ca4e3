//! Social interaction behaviors written as behavior graphs.
//!
//! In the BITE paper the interaction behaviors are themselves behaviors
//! (Fig. 1-c: a vote, a market, a wait). A *protocol file* describes one as
//! a small behavior graph that every member of the team runs for one
//! instance: behaviors with preconditions (`pre`), termination conditions
//! (`until`) and sequential edges (`next`); skills that send and keep
//! protocol messages and take the decision (`do`); and conditions over what
//! has been received (`heard_vote`, `missing_done`, `top_vote`, `live`…).
//! The leader (the lowest-id live member) starts at `start.leader`, the
//! others at `start.member`.
//!
//! What makes a protocol robust is not written in the file: the
//! interpreter ([`run`]) gives every graph protocol the guarantees of the
//! built-in leader-coordinated ones ([`crate::gather`]), with the same code
//! ([`crate::gather::Coord`]): messages to the leader are resent with
//! exponential backoff until the decision is heard; a leader re-sends its
//! last team message to members it has not heard from, and answers queries
//! and late messages with the decision; the decision is announced by the
//! leader and adopted by members wherever they are in the graph; a member
//! that takes over from a lost leader starts again at `start.leader` with
//! what it has received; `on_deadline` and `on_abort` say where each role
//! goes; a forgotten instance answers late teammates with the decision
//! (`late_reply`). The kernel's deadlines, lost-member handling and
//! duplicate filtering apply as to any protocol.
//!
//! A skill may `use` another protocol (built-in or graph-defined, loaded
//! before this one) to decide: it runs as a nested instance whose messages
//! travel inside this protocol's, at most [`MAX_DEPTH`] levels deep.

mod run;
mod spec;

use crate::gather::Announce;
use bite_core::belief::Symbols;
use bite_core::cond::{Expr, Resolver};
use bite_core::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use bite_core::ids::{BehaviorId, BeliefId};
use bite_core::interaction::{
    Closed, ConfigError, Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol, Registry,
    Setup,
};
use bite_core::msg::{Body, Kind};
use serde::{Deserialize, Serialize};
use serde_saphyr::Spanned;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

/// Deepest nesting of protocols used by protocols.
pub const MAX_DEPTH: u32 = 3;
/// Most behaviors in one protocol graph.
pub const MAX_BEHAVIORS: usize = 64;
/// Most messages one protocol declares.
pub const MAX_MESSAGES: usize = 32;
/// Tag bit of a nested protocol's message (the rest is the skill's slot).
const NESTED: u16 = 0x8000;

/// What a message carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Carries {
    Nothing,
    Choice,
    Ranking,
    Number,
    Decision,
}

impl Carries {
    const NAMES: [&'static str; 5] = ["none", "choice", "ranking", "number", "decision"];
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "none" => Carries::Nothing,
            "choice" => Carries::Choice,
            "ranking" => Carries::Ranking,
            "number" => Carries::Number,
            "decision" => Carries::Decision,
            _ => return None,
        })
    }
}

/// A message's content on the wire (inside `Body::Custom`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) enum Payload {
    Nothing,
    Choice(Option<BehaviorId>),
    Ranking(Vec<BehaviorId>),
    Number(f64),
    /// A decision: a successor (sync) or the next behavior (terminate).
    Pick(Option<BehaviorId>),
    /// A decision: an allocation, as in `Body::Assignment`.
    Assignment {
        children: Vec<BehaviorId>,
        members: Vec<(bite_core::ids::RobotId, u32)>,
    },
}

#[derive(Debug)]
pub(crate) struct MessageDef {
    pub name: String,
    pub carries: Carries,
    pub departs: bool,
}

/// Where a sent message goes.
#[derive(Clone, Copy, Debug)]
pub(crate) enum To {
    Leader,
    Team,
    /// The live members this robot has not received this message from.
    Missing(usize),
}

/// What a sent or kept message carries.
#[derive(Clone, Debug)]
pub(crate) enum Source {
    /// No content, or an abstention (`none`).
    Nothing,
    /// This robot's preferred successor.
    Preferred,
    /// The first successor enabled for this robot (the silent rule's).
    First,
    /// This robot's ranking of the successors.
    Ranking,
    /// The decision taken.
    Decision,
    /// A number: expression `i` of the configured program.
    Expr(usize),
}

/// How a `decide` skill decides.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Rule {
    /// The successor with most `choice` votes in message `m`.
    Plurality(usize),
    /// Borda count over the rankings in message `m`.
    Borda(usize),
    /// Members sorted by the numbers in message `m`, dealt to the children.
    Sorted { msg: usize, descending: bool },
    /// This robot's own view: its preference (sync), by id (allocate), the
    /// behavior is over (terminate).
    Own,
    /// The kernel's silent rule (first candidate, by id, local).
    Silent,
}

#[derive(Debug)]
pub(crate) enum Skill {
    Send { msg: usize, to: To, value: Source },
    Keep { msg: usize, value: Source },
    Decide(Rule),
    Use { slot: u16 },
}

#[derive(Debug)]
pub(crate) struct BehaviorDef {
    pub name: String,
    pub description: Option<String>,
    pub pre: Option<Expr>,
    pub skills: Vec<Skill>,
    pub until: Option<Expr>,
    pub next: Vec<usize>,
}

/// A nested protocol used by a skill, as declared.
struct UseDef {
    protocol: Arc<dyn Protocol>,
    params: Params,
}

/// The variables a protocol's conditions read.
pub(crate) struct Vars {
    pub names: Vec<String>,
}

/// Fixed variables, then three per message (`heard_`, `missing_`, `top_`).
pub(crate) const VAR_LIVE: usize = 0;
pub(crate) const VAR_TEAM: usize = 1;
pub(crate) const VAR_LEADER: usize = 2;
pub(crate) const VAR_TOOK_OVER: usize = 3;
pub(crate) const VAR_DONE: usize = 4;
pub(crate) const VAR_GOAL: usize = 5;
pub(crate) const FIXED_VARS: usize = 6;

impl Vars {
    fn new(messages: &[MessageDef]) -> Self {
        let mut names: Vec<String> = ["live", "team", "leader", "took_over", "done", "goal"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        for m in messages {
            names.push(format!("heard_{}", m.name));
            names.push(format!("missing_{}", m.name));
            names.push(format!("top_{}", m.name));
        }
        Vars { names }
    }
}

/// A parsed, checked protocol file.
pub struct GraphProtocol {
    name: &'static str,
    summary: &'static str,
    source: String,
    kind: Kind,
    twin: Option<String>,
    deadline: Duration,
    depth: u32,
    params: Vec<(String, Option<String>, Option<String>)>,
    pub(crate) messages: Vec<MessageDef>,
    pub(crate) announce: Option<usize>,
    pub(crate) start: [usize; 2],
    pub(crate) on_deadline: [Option<usize>; 2],
    pub(crate) on_abort: [Option<usize>; 2],
    pub(crate) behaviors: Vec<BehaviorDef>,
    uses: Vec<UseDef>,
    /// Number expressions by index (`Source::Expr`): their source text,
    /// with parameters written `$name`.
    exprs: Vec<String>,
}

impl std::fmt::Debug for GraphProtocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GraphProtocol")
            .field("name", &self.name)
            .field("source", &self.source)
            .finish()
    }
}

/// A graph protocol configured for one binding: the file plus the compiled
/// expressions and nested factories.
pub(crate) struct Program {
    pub def: Arc<GraphProtocol>,
    /// Announcements in `def`'s own message (shared by the instances).
    pub codec: Arc<Codec>,
    pub exprs: Vec<Expr>,
    pub subs: Vec<Factory>,
}

/// The role index of `start`, `on_deadline` and `on_abort`.
pub(crate) const LEADER: usize = 0;
pub(crate) const MEMBER: usize = 1;

struct Loader<'a> {
    file: Arc<str>,
    diags: Vec<Diagnostic>,
    registry: &'a Registry,
}

impl Loader<'_> {
    fn error(&mut self, loc: Loc, code: &'static str, msg: impl Into<String>) -> Diagnostic {
        Diagnostic::error(&self.file, loc, code, msg)
    }
    fn push(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }
}

fn loc<T>(s: &Spanned<T>) -> Loc {
    Loc::from(s.referenced)
}

impl GraphProtocol {
    /// Load a protocol file; nested protocols are looked up in `registry`.
    pub fn load(path: &Path, registry: &Registry) -> Result<GraphProtocol, Diagnostics> {
        let (file, text) = bite_core::yaml::read_file(path)?;
        Self::load_str(&file, &text, registry)
    }

    /// Parse and check protocol text (`file` names it in diagnostics).
    pub fn load_str(
        file: &Arc<str>,
        text: &str,
        registry: &Registry,
    ) -> Result<GraphProtocol, Diagnostics> {
        let spec: spec::FileSpec = bite_core::yaml::parse(file, text)?;
        let mut l = Loader {
            file: file.clone(),
            diags: Vec::new(),
            registry,
        };
        let p = build(&mut l, spec);
        match p {
            Some(p) if l.diags.is_empty() => Ok(p),
            _ => Err(Diagnostics(l.diags)),
        }
    }

    /// The file it was read from.
    pub fn file(&self) -> &str {
        &self.source
    }

    /// One line: its messages and behaviors, with the roles' starts.
    pub fn outline(&self) -> String {
        let msgs: Vec<String> = self
            .messages
            .iter()
            .map(|m| format!("{} ({})", m.name, Carries::NAMES[m.carries as usize]))
            .collect();
        format!(
            "{} messages: {}; {} behaviors, the leader starts at `{}`, members at `{}`",
            self.messages.len(),
            msgs.join(", "),
            self.behaviors.len(),
            self.behaviors[self.start[LEADER]].name,
            self.behaviors[self.start[MEMBER]].name
        )
    }

    /// The built-in protocol it mirrors, if the file names one.
    pub fn twin(&self) -> Option<&str> {
        self.twin.as_deref()
    }

    /// The protocol graph as Graphviz DOT: behaviors (leader's start
    /// double-circled, member's start bold), sequential edges, skills as
    /// labels.
    pub fn to_dot(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(s, "digraph \"{}\" {{", self.name);
        let _ = writeln!(s, "  rankdir=LR; node [shape=box, fontname=\"Helvetica\"];");
        for (i, b) in self.behaviors.iter().enumerate() {
            let mut label = b.name.clone();
            for sk in &b.skills {
                label.push_str("\\n");
                label.push_str(&self.describe(sk));
            }
            if let Some(u) = &b.until {
                let _ = write!(label, "\\nuntil {}", u.source());
            }
            let mut attrs = String::new();
            if let Some(d) = &b.description {
                let _ = write!(attrs, ", tooltip=\"{}\"", d.replace('"', "\\\""));
            }
            if self.start[LEADER] == i {
                attrs.push_str(", peripheries=2");
            }
            if self.start[MEMBER] == i {
                attrs.push_str(", style=bold");
            }
            let _ = writeln!(
                s,
                "  b{i} [label=\"{}\"{attrs}];",
                label.replace('"', "\\\"")
            );
            for n in &b.next {
                let pre = self.behaviors[*n]
                    .pre
                    .as_ref()
                    .map(|p| format!(" [label=\"{}\"]", p.source().replace('"', "\\\"")))
                    .unwrap_or_default();
                let _ = writeln!(s, "  b{i} -> b{n}{pre};");
            }
        }
        s.push_str("}\n");
        s
    }

    fn describe(&self, sk: &Skill) -> String {
        let m = |i: usize| self.messages[i].name.as_str();
        match sk {
            Skill::Send { msg, to, .. } => {
                let to = match to {
                    To::Leader => "leader".to_string(),
                    To::Team => "team".to_string(),
                    To::Missing(x) => format!("missing {}", m(*x)),
                };
                format!("send {} to {to}", m(*msg))
            }
            Skill::Keep { msg, .. } => format!("keep {}", m(*msg)),
            Skill::Decide(r) => match r {
                Rule::Plurality(x) => format!("decide plurality of {}", m(*x)),
                Rule::Borda(x) => format!("decide borda of {}", m(*x)),
                Rule::Sorted { msg, descending } => format!(
                    "decide sorted {} {}",
                    m(*msg),
                    if *descending {
                        "descending"
                    } else {
                        "ascending"
                    }
                ),
                Rule::Own => "decide own".into(),
                Rule::Silent => "decide rule".into(),
            },
            Skill::Use { slot } => format!("use {}", self.uses[*slot as usize].protocol.name()),
        }
    }

    pub(crate) fn message_body(&self, msg: usize, p: &Payload) -> Body {
        Body::Custom {
            tag: msg as u16,
            data: postcard::to_allocvec(p).unwrap_or_default(),
        }
    }

    /// The payload of `body` if it is message `msg`'s and carries what the
    /// message carries.
    pub(crate) fn decode(&self, body: &Body) -> Option<Result<(usize, Payload), String>> {
        let Body::Custom { tag, data } = body else {
            return None;
        };
        if tag & NESTED != 0 {
            return None;
        }
        let Some(m) = self.messages.get(*tag as usize) else {
            return Some(Err(format!(
                "message tag {tag} is not one of this protocol's"
            )));
        };
        let p: Payload = match postcard::from_bytes(data) {
            Ok(p) => p,
            Err(e) => return Some(Err(format!("`{}` does not decode: {e}", m.name))),
        };
        let fits = matches!(
            (m.carries, &p),
            (Carries::Nothing, Payload::Nothing)
                | (Carries::Choice, Payload::Choice(_))
                | (Carries::Ranking, Payload::Ranking(_))
                | (Carries::Number, Payload::Number(_))
                | (
                    Carries::Decision,
                    Payload::Pick(_) | Payload::Assignment { .. }
                )
        );
        if !fits {
            return Some(Err(format!("`{}` carries the wrong content", m.name)));
        }
        Some(Ok((*tag as usize, p)))
    }
}

/// A nested instance's message, wrapped for the wire.
pub(crate) fn nested_body(slot: u16, inner: &Body) -> Body {
    Body::Custom {
        tag: NESTED | slot,
        data: postcard::to_allocvec(inner).unwrap_or_default(),
    }
}

/// The slot and inner message of a wrapped nested message.
pub(crate) fn unnest(body: &Body) -> Option<Result<(u16, Body), String>> {
    match body {
        Body::Custom { tag, data } if tag & NESTED != 0 => Some(
            postcard::from_bytes(data)
                .map(|b| (tag & !NESTED, b))
                .map_err(|e| format!("a nested message does not decode: {e}")),
        ),
        _ => None,
    }
}

/// Announcements in the protocol's own `announce` message.
pub(crate) struct Codec {
    pub def: Arc<GraphProtocol>,
}

impl Codec {
    fn payload(o: &Outcome) -> Payload {
        match o {
            Outcome::Sync(c) => Payload::Pick(*c),
            Outcome::Terminate(n) => Payload::Pick(*n),
            Outcome::Allocate(a) => match Body::assignment(a) {
                Body::Assignment { children, members } => Payload::Assignment { children, members },
                _ => Payload::Nothing,
            },
        }
    }
}

impl Announce for Codec {
    fn encode(&self, o: &Outcome) -> Body {
        match self.def.announce {
            Some(m) => self.def.message_body(m, &Self::payload(o)),
            None => Body::Custom {
                tag: !NESTED,
                data: Vec::new(),
            },
        }
    }
    fn decode(&self, cx: &Cx<'_>, body: &Body) -> Option<Result<Outcome, ()>> {
        let a = self.def.announce?;
        let Body::Custom { tag, .. } = body else {
            return None;
        };
        if *tag as usize != a {
            return None;
        }
        let Some(Ok((_, p))) = self.def.decode(body) else {
            return Some(Err(()));
        };
        Some(match (cx.input(), p) {
            (PointInput::Sync { successors, .. }, Payload::Pick(c)) => {
                if c.is_none_or(|c| successors.contains(&c)) {
                    Ok(Outcome::Sync(c))
                } else {
                    Err(())
                }
            }
            (PointInput::Terminate, Payload::Pick(n)) => Ok(Outcome::Terminate(n)),
            (PointInput::Allocate { .. }, Payload::Assignment { children, members }) => {
                Body::Assignment { children, members }
                    .to_assignment(cx.team().members.roster_len())
                    .map(|a| Outcome::Allocate(a.into()))
                    .ok_or(())
            }
            _ => Err(()),
        })
    }
}

/// A registered graph protocol (the file, shared by its instances).
#[derive(Clone, Debug)]
pub struct Registered(pub Arc<GraphProtocol>);

impl Registered {
    /// The protocol file.
    pub fn def(&self) -> &GraphProtocol {
        &self.0
    }
}

impl Protocol for Registered {
    fn name(&self) -> &'static str {
        self.0.name
    }
    fn kind(&self) -> Kind {
        self.0.kind
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        self.0.summary
    }
    fn default_deadline(&self) -> Duration {
        self.0.deadline
    }
    fn source(&self) -> Option<&str> {
        Some(&self.0.source)
    }
    fn nesting(&self) -> u32 {
        self.0.depth
    }
    fn configure(&self, params: &Params, setup: &mut Setup<'_>) -> Result<Factory, ConfigError> {
        let def = &self.0;
        let name = def.name;
        // Parameters: expressions by name, checked against the declared ones.
        let mut given: BTreeMap<String, String> = BTreeMap::new();
        match params {
            Params::Null => {}
            Params::Object(m) => {
                for (k, v) in m {
                    if !def.params.iter().any(|(n, _, _)| n == k) {
                        let known: Vec<&str> =
                            def.params.iter().map(|(n, _, _)| n.as_str()).collect();
                        return Err(ConfigError::BadParams {
                            protocol: name.into(),
                            detail: format!(
                                "unknown parameter `{k}` (it takes: {})",
                                if known.is_empty() {
                                    "none".into()
                                } else {
                                    known.join(", ")
                                }
                            ),
                        });
                    }
                    let text = match v {
                        serde_json::Value::String(s) => s.clone(),
                        serde_json::Value::Number(n) => n.to_string(),
                        serde_json::Value::Bool(b) => b.to_string(),
                        _ => {
                            return Err(ConfigError::BadParams {
                                protocol: name.into(),
                                detail: format!("`{k}` must be an expression such as `head_angle`"),
                            });
                        }
                    };
                    given.insert(k.clone(), text);
                }
            }
            _ => {
                return Err(ConfigError::BadParams {
                    protocol: name.into(),
                    detail: "parameters are a mapping of names to expressions".into(),
                });
            }
        }
        let mut values: BTreeMap<&str, String> = BTreeMap::new();
        for (n, default, help) in &def.params {
            match given.get(n).or(default.as_ref()) {
                Some(v) => {
                    values.insert(n, v.clone());
                }
                None => {
                    return Err(ConfigError::Missing {
                        protocol: name.into(),
                        param: n.clone(),
                        what: help.clone().unwrap_or_else(|| "an expression".into()),
                    });
                }
            }
        }
        let mut exprs = Vec::with_capacity(def.exprs.len());
        for src in &def.exprs {
            let text = substitute(src, &values);
            exprs.push(setup.expr(&text, Some("number"))?);
        }
        let mut subs = Vec::with_capacity(def.uses.len());
        for u in &def.uses {
            subs.push(u.protocol.configure(&u.params, setup)?);
        }
        let program = Arc::new(Program {
            def: def.clone(),
            codec: Arc::new(Codec { def: def.clone() }),
            exprs,
            subs,
        });
        Ok(Arc::new(move || {
            Box::new(run::GraphRun::new(program.clone())) as Box<dyn Interaction>
        }))
    }
    fn late_reply(&self, closed: &Closed, body: &Body) -> Option<Body> {
        let a = self.0.announce?;
        let repeatable = match body {
            Body::Query => true,
            Body::Custom { tag, .. } => *tag as usize != a && tag & NESTED == 0,
            _ => false,
        };
        if !repeatable {
            return None;
        }
        let codec = Codec {
            def: self.0.clone(),
        };
        let o = match closed {
            Closed::Synced(c) => Outcome::Sync(*c),
            Closed::Allocated(x) => Outcome::Allocate(x.clone()),
            Closed::Terminated(n) => Outcome::Terminate(*n),
            Closed::Left => return None,
        };
        Some(codec.encode(&o))
    }
}

/// `src` with every `$name` replaced by the parameter's expression (in
/// parentheses, so that it binds as one operand).
fn substitute(src: &str, values: &BTreeMap<&str, String>) -> String {
    let mut out = String::with_capacity(src.len());
    let mut rest = src;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let tail = &rest[i + 1..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(tail.len());
        let name = &tail[..end];
        match values.get(name) {
            Some(v) => {
                out.push('(');
                out.push_str(v);
                out.push(')');
            }
            None => {
                out.push('$');
                out.push_str(name);
            }
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

/// The names `$name` used in `src`.
fn params_in(src: &str) -> Vec<&str> {
    let mut v = Vec::new();
    let mut rest = src;
    while let Some(i) = rest.find('$') {
        let tail = &rest[i + 1..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(tail.len());
        v.push(&tail[..end]);
        rest = &tail[end..];
    }
    v
}

/// Resolves the names of a protocol condition: its variables only.
struct VarResolver<'a> {
    vars: &'a Vars,
    unknown: Vec<String>,
}

impl Resolver for VarResolver<'_> {
    fn belief(&mut self, name: &str) -> BeliefId {
        match self.vars.names.iter().position(|n| n == name) {
            Some(i) => BeliefId(i as u32),
            None => {
                self.unknown.push(name.to_string());
                BeliefId(0)
            }
        }
    }
    fn behavior(&self, _name: &str) -> Option<BehaviorId> {
        None
    }
}

fn condition(l: &mut Loader<'_>, vars: &Vars, s: &Spanned<String>, what: &str) -> Option<Expr> {
    let mut r = VarResolver {
        vars,
        unknown: Vec::new(),
    };
    match Expr::parse(&s.value, &mut r) {
        Ok(e) => {
            if let Some(u) = r.unknown.first() {
                let mut d = l.error(
                    loc(s),
                    "unknown-variable",
                    format!(
                        "{what} `{}` reads `{u}`, which a protocol condition cannot read",
                        s.value
                    ),
                );
                d.hint = did_you_mean(u, vars.names.iter().map(String::as_str)).or_else(|| {
                    Some(format!(
                        "conditions read: {}, elapsed, runs",
                        vars.names.join(", ")
                    ))
                });
                l.push(d);
                return None;
            }
            if e.static_type().is_some_and(|t| t != "bool") {
                let d = l.error(
                    loc(s),
                    "type",
                    format!("{what} `{}` is not a condition (true or false)", s.value),
                );
                l.push(d);
                return None;
            }
            Some(e)
        }
        Err(e) => {
            let d = l
                .error(loc(s), "condition", format!("{what}: {e}"))
                .with_detail(e.render(&s.value));
            l.push(d);
            None
        }
    }
}

fn build(l: &mut Loader<'_>, spec: spec::FileSpec) -> Option<GraphProtocol> {
    // Name and kind.
    let name = spec.protocol.value.trim().to_string();
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'))
    {
        let d = l.error(
            loc(&spec.protocol),
            "bad-name",
            format!("`{name}` is not a protocol name (letters, digits, `.`, `-`, `_`)"),
        );
        l.push(d);
    }
    if let Some(p) = l.registry.get(&name)
        && p.source().is_none()
    {
        let d = l
            .error(
                loc(&spec.protocol),
                "name-taken",
                format!("`{name}` is a built-in protocol"),
            )
            .with_hint("give the graph protocol a name of its own, e.g. `graph.vote`");
        l.push(d);
    }
    let kind = match spec.kind.value.as_str() {
        "sync" => Kind::Sync,
        "allocate" => Kind::Allocate,
        "terminate" => Kind::Terminate,
        other => {
            let mut d = l.error(
                loc(&spec.kind),
                "bad-kind",
                format!(
                    "`{other}` is not a kind of point; expected `sync`, `allocate` or `terminate`"
                ),
            );
            d.hint = did_you_mean(other, ["sync", "allocate", "terminate"]);
            l.push(d);
            Kind::Sync
        }
    };
    let deadline = match &spec.deadline {
        None => Duration::from_secs(5),
        Some(d) => match bite_core::time::parse_duration(&d.value.0) {
            Ok(x) if !x.is_zero() => x,
            Ok(_) => {
                let e = l.error(loc(d), "bad-duration", "the deadline must be more than 0");
                l.push(e);
                Duration::from_secs(5)
            }
            Err(e) => {
                let e = l.error(loc(d), "bad-duration", e);
                l.push(e);
                Duration::from_secs(5)
            }
        },
    };
    let mut depth = 1;
    if let Some(t) = &spec.twin
        && l.registry.get(&t.value).is_none()
    {
        let mut d = l.error(
            loc(t),
            "unknown-protocol",
            format!("no protocol `{}`", t.value),
        );
        d.hint = did_you_mean(&t.value, l.registry.names());
        l.push(d);
    }

    // Messages.
    let mut messages = Vec::new();
    if spec.messages.value.0.len() > MAX_MESSAGES {
        let d = l.error(
            loc(&spec.messages),
            "too-many",
            format!("more than {MAX_MESSAGES} messages"),
        );
        l.push(d);
    }
    for (n, m) in &spec.messages.value.0 {
        if n.value.is_empty()
            || !n
                .value
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            let d = l.error(
                loc(n),
                "bad-name",
                format!("`{}` is not a message name (letters, digits, `_`)", n.value),
            );
            l.push(d);
        }
        let carries = match Carries::parse(&m.value.carries.value) {
            Some(c) => c,
            None => {
                let mut d = l.error(
                    loc(&m.value.carries),
                    "bad-carries",
                    format!(
                        "a message carries one of {}; not `{}`",
                        Carries::NAMES.join(", "),
                        m.value.carries.value
                    ),
                );
                d.hint = did_you_mean(&m.value.carries.value, Carries::NAMES);
                l.push(d);
                Carries::Nothing
            }
        };
        if m.value.departs && kind != Kind::Terminate {
            let d = l.error(
                loc(n),
                "departs",
                "`departs` is for termination protocols (the sender is done with the behavior)",
            );
            l.push(d);
        }
        messages.push(MessageDef {
            name: n.value.clone(),
            carries,
            departs: m.value.departs,
        });
    }
    let msg_names: Vec<&str> = messages.iter().map(|m| m.name.as_str()).collect();
    let find_msg = |l: &mut Loader<'_>, s: &Spanned<String>| -> Option<usize> {
        let i = msg_names.iter().position(|m| *m == s.value);
        if i.is_none() {
            let mut d = l.error(
                loc(s),
                "unknown-message",
                format!("no message `{}` in `messages`", s.value),
            );
            d.hint = did_you_mean(&s.value, msg_names.iter().copied())
                .or_else(|| Some(format!("the messages are: {}", msg_names.join(", "))));
            l.push(d);
        }
        i
    };
    let announce = spec.announce.as_ref().and_then(|a| {
        let i = find_msg(l, a)?;
        if messages[i].carries != Carries::Decision {
            let d = l.error(
                loc(a),
                "announce",
                format!(
                    "`{}` announces the decision, so it must carry `decision`",
                    a.value
                ),
            );
            l.push(d);
        }
        Some(i)
    });
    let vars = Vars::new(&messages);

    // Parameters.
    let params: Vec<(String, Option<String>, Option<String>)> = spec
        .params
        .0
        .iter()
        .map(|(n, p)| {
            (
                n.value.clone(),
                p.value.default.clone(),
                p.value.help.clone(),
            )
        })
        .collect();

    // Behaviors: names first, then bodies.
    let beh_names: Vec<String> = spec
        .behaviors
        .value
        .0
        .iter()
        .map(|(n, _)| n.value.clone())
        .collect();
    if beh_names.is_empty() {
        let d = l.error(
            loc(&spec.behaviors),
            "empty",
            "a protocol has at least one behavior",
        );
        l.push(d);
        return None;
    }
    if beh_names.len() > MAX_BEHAVIORS {
        let d = l.error(
            loc(&spec.behaviors),
            "too-many",
            format!("more than {MAX_BEHAVIORS} behaviors"),
        );
        l.push(d);
        return None;
    }
    let find_beh = |l: &mut Loader<'_>, s: &Spanned<String>| -> Option<usize> {
        let i = beh_names.iter().position(|b| *b == s.value);
        if i.is_none() {
            let mut d = l.error(
                loc(s),
                "unknown-reference",
                format!("no behavior `{}` in `behaviors`", s.value),
            );
            d.hint = did_you_mean(&s.value, beh_names.iter().map(String::as_str));
            l.push(d);
        }
        i
    };
    let mut exprs: Vec<String> = Vec::new();
    let mut uses: Vec<UseDef> = Vec::new();
    let mut behaviors = Vec::new();
    for (i, (n, b)) in spec.behaviors.value.0.iter().enumerate() {
        if beh_names[..i].contains(&n.value) {
            let d = l.error(loc(n), "duplicate", format!("behavior `{}` twice", n.value));
            l.push(d);
        }
        let b = &b.value;
        let pre = b
            .pre
            .as_ref()
            .and_then(|p| condition(l, &vars, p, "precondition"));
        let until = b
            .until
            .as_ref()
            .and_then(|u| condition(l, &vars, u, "termination condition"));
        let next: Vec<usize> = b.next.iter().filter_map(|s| find_beh(l, s)).collect();
        let mut skills = Vec::new();
        for sk in &b.skills {
            if let Some(s) = skill(
                l,
                &SkillCx {
                    kind,
                    messages: &messages,
                    params: &params,
                    find_msg: &find_msg,
                },
                sk,
                &mut exprs,
                &mut uses,
                &mut depth,
            ) {
                skills.push(s);
            }
        }
        behaviors.push(BehaviorDef {
            name: n.value.clone(),
            description: b.description.clone(),
            pre,
            skills,
            until,
            next,
        });
    }

    let roles = |l: &mut Loader<'_>, r: &Spanned<spec::RolesSpec>, need: bool, what: &str| {
        let mut out = [None, None];
        for (i, (role, s)) in [("leader", &r.value.leader), ("member", &r.value.member)]
            .into_iter()
            .enumerate()
        {
            match s {
                Some(s) => out[i] = find_beh(l, s),
                None if need => {
                    let d = l.error(
                        loc(r),
                        "missing",
                        format!("`{what}` names the {role}'s behavior: `{role}: <behavior>`"),
                    );
                    l.push(d);
                }
                None => {}
            }
        }
        out
    };
    let start = roles(l, &spec.start, true, "start");
    let on_deadline = spec
        .on_deadline
        .as_ref()
        .map_or([None, None], |r| roles(l, r, false, "on_deadline"));
    let on_abort = spec
        .on_abort
        .as_ref()
        .map_or([None, None], |r| roles(l, r, false, "on_abort"));

    // Reachability and loops that never wait.
    if let [Some(sl), Some(sm)] = start {
        let mut seen = vec![false; behaviors.len()];
        let mut stack: Vec<usize> = [Some(sl), Some(sm)]
            .into_iter()
            .chain(on_deadline)
            .chain(on_abort)
            .flatten()
            .collect();
        while let Some(b) = stack.pop() {
            if !std::mem::replace(&mut seen[b], true) {
                stack.extend(behaviors[b].next.iter().copied());
            }
        }
        for (i, (n, _)) in spec.behaviors.value.0.iter().enumerate() {
            if !seen[i] {
                let d = l
                    .error(loc(n), "unreachable", format!("no role ever reaches behavior `{}`", n.value))
                    .with_hint("reach it from `start`, `on_deadline`, `on_abort` or another behavior's `next`");
                l.push(d);
            }
        }
        if let Some(b) = busy_loop(&behaviors) {
            let (n, _) = &spec.behaviors.value.0[b];
            let d = l
                .error(
                    loc(n),
                    "busy-loop",
                    format!(
                        "behavior `{}` is on a loop in which no behavior waits",
                        n.value
                    ),
                )
                .with_hint("give a behavior on the loop an `until`, or a successor a `pre`");
            l.push(d);
        }
    }
    // A protocol must be able to decide.
    if !behaviors.iter().any(|b| {
        b.skills
            .iter()
            .any(|s| matches!(s, Skill::Decide(_) | Skill::Use { .. }))
    }) {
        let d = l.error(
            loc(&spec.behaviors),
            "never-decides",
            "no behavior decides: add a skill `decide: <rule>` (or `use: <protocol>`)",
        );
        l.push(d);
    }
    if announce.is_none() {
        let d = l
            .error(
                loc(&spec.protocol),
                "announce",
                "a protocol names the message that carries its decision: `announce: <message>`",
            )
            .with_hint("declare it in `messages` with `carries: decision`");
        l.push(d);
    }
    if !l.diags.is_empty() {
        return None;
    }
    Some(GraphProtocol {
        name: Box::leak(name.into_boxed_str()),
        summary: Box::leak(
            spec.summary
                .unwrap_or_else(|| "A protocol written as a behavior graph.".into())
                .into_boxed_str(),
        ),
        source: l.file.to_string(),
        kind,
        twin: spec.twin.map(|t| t.value),
        deadline,
        depth,
        params,
        messages,
        announce,
        start: [start[0].unwrap_or(0), start[1].unwrap_or(0)],
        on_deadline,
        on_abort,
        behaviors,
        uses,
        exprs,
    })
}

/// A behavior on a cycle of behaviors without `until` joined by edges to
/// successors without `pre` (the interpreter would go round it at once).
fn busy_loop(behaviors: &[BehaviorDef]) -> Option<usize> {
    // A condition that reads nothing (no variable, no time, no count) is
    // a constant: `until: true` waits no more than no `until` (a protocol
    // that looped on it, sending to the team at every step, flooded the
    // network without end), and `pre: true` holds like no `pre`.
    let always = |e: &Option<Expr>| {
        e.as_ref().is_none_or(|e| {
            e.beliefs().is_empty()
                && !e.depends_on_time()
                && !e.depends_on_runs()
                && e.eval(&Nothing)
        })
    };
    let free = |b: usize| always(&behaviors[b].until);
    // An edge into `n` taken without waiting.
    let step = |n: usize| free(n) && always(&behaviors[n].pre);
    // Colour DFS over the free subgraph.
    let mut colour = vec![0u8; behaviors.len()];
    fn visit(
        b: usize,
        behaviors: &[BehaviorDef],
        colour: &mut [u8],
        step: &dyn Fn(usize) -> bool,
    ) -> Option<usize> {
        colour[b] = 1;
        for &n in &behaviors[b].next {
            if !step(n) {
                continue;
            }
            if colour[n] == 1 {
                return Some(n);
            }
            if colour[n] == 0
                && let Some(x) = visit(n, behaviors, colour, step)
            {
                return Some(x);
            }
        }
        colour[b] = 2;
        None
    }
    (0..behaviors.len()).find_map(|b| {
        (free(b) && colour[b] == 0)
            .then(|| visit(b, behaviors, &mut colour, &step))
            .flatten()
    })
}

/// The environment of a constant condition: it reads nothing.
struct Nothing;

impl bite_core::cond::Env for Nothing {
    fn belief(&self, _: bite_core::ids::BeliefId) -> Option<&bite_core::value::Value> {
        None
    }
    fn belief_age(&self, _: bite_core::ids::BeliefId) -> Option<f64> {
        None
    }
    fn elapsed(&self) -> f64 {
        0.0
    }
    fn runs(&self, _: Option<bite_core::ids::BehaviorId>) -> u32 {
        0
    }
}

struct SkillCx<'a, F> {
    kind: Kind,
    messages: &'a [MessageDef],
    params: &'a [(String, Option<String>, Option<String>)],
    find_msg: &'a F,
}

fn skill<F>(
    l: &mut Loader<'_>,
    c: &SkillCx<'_, F>,
    sk: &Spanned<spec::SkillSpec>,
    exprs: &mut Vec<String>,
    uses: &mut Vec<UseDef>,
    depth: &mut u32,
) -> Option<Skill>
where
    F: Fn(&mut Loader<'_>, &Spanned<String>) -> Option<usize>,
{
    let s = &sk.value;
    let at = loc(sk);
    let set = [
        s.send.is_some(),
        s.keep.is_some(),
        s.decide.is_some(),
        s.use_.is_some(),
    ];
    if set.iter().filter(|x| **x).count() != 1 {
        let d = l.error(
            at,
            "skill",
            "a skill is exactly one of `send: <message>`, `keep: <message>`, `decide: <rule>`, `use: <protocol>`",
        );
        l.push(d);
        return None;
    }
    let unexpected = |l: &mut Loader<'_>, field: &str, x: bool| {
        if x {
            let d = l.error(
                at,
                "skill",
                format!("`{field}` does not go with this skill"),
            );
            l.push(d);
        }
    };
    if let Some(m) = s.send.as_ref().or(s.keep.as_ref()) {
        let msg = (c.find_msg)(l, m)?;
        unexpected(l, "from", s.from.is_some());
        unexpected(l, "order", s.order.is_some());
        unexpected(l, "params", s.params.is_some());
        let value = source(l, c, msg, s.value.as_ref(), exprs, at)?;
        if s.keep.is_some() {
            unexpected(l, "to", s.to.is_some());
            return Some(Skill::Keep { msg, value });
        }
        let Some(to) = &s.to else {
            let d = l.error(
                at,
                "skill",
                "`send` needs `to: leader`, `to: team` or `to: missing <message>`",
            );
            l.push(d);
            return None;
        };
        let to = match to.value.split_whitespace().collect::<Vec<_>>().as_slice() {
            ["leader"] => To::Leader,
            ["team"] => To::Team,
            ["missing", m] => {
                let spanned = Spanned {
                    value: m.to_string(),
                    referenced: to.referenced,
                    defined: to.defined,
                };
                To::Missing((c.find_msg)(l, &spanned)?)
            }
            _ => {
                let d = l.error(
                    loc(to),
                    "bad-recipient",
                    format!(
                        "`{}`: expected `leader`, `team` or `missing <message>`",
                        to.value
                    ),
                );
                l.push(d);
                return None;
            }
        };
        return Some(Skill::Send { msg, to, value });
    }
    if let Some(r) = &s.decide {
        unexpected(l, "to", s.to.is_some());
        unexpected(l, "value", s.value.is_some());
        unexpected(l, "params", s.params.is_some());
        let from = |l: &mut Loader<'_>, want: Carries| -> Option<usize> {
            let Some(f) = &s.from else {
                let d = l.error(
                    at,
                    "skill",
                    format!("`decide: {}` needs `from: <message>`", r.value),
                );
                l.push(d);
                return None;
            };
            let m = (c.find_msg)(l, f)?;
            if c.messages[m].carries != want {
                let d = l.error(
                    loc(f),
                    "bad-carries",
                    format!(
                        "`decide: {}` counts messages that carry `{}`; `{}` carries `{}`",
                        r.value,
                        Carries::NAMES[want as usize],
                        f.value,
                        Carries::NAMES[c.messages[m].carries as usize]
                    ),
                );
                l.push(d);
            }
            Some(m)
        };
        let need_kind = |l: &mut Loader<'_>, k: Kind| {
            if c.kind != k {
                let d = l.error(
                    loc(r),
                    "bad-rule",
                    format!(
                        "`decide: {}` decides {} point, not {}",
                        r.value,
                        k.a_noun(),
                        c.kind.a_noun()
                    ),
                );
                l.push(d);
            }
        };
        let rule = match r.value.as_str() {
            "plurality" => {
                need_kind(l, Kind::Sync);
                Rule::Plurality(from(l, Carries::Choice)?)
            }
            "borda" => {
                need_kind(l, Kind::Sync);
                Rule::Borda(from(l, Carries::Ranking)?)
            }
            "sorted" => {
                need_kind(l, Kind::Allocate);
                let descending = match s.order.as_ref().map(|o| o.value.as_str()) {
                    None | Some("ascending") => false,
                    Some("descending") => true,
                    Some(o) => {
                        let d = l.error(
                            at,
                            "bad-order",
                            format!("`{o}`: expected `ascending` or `descending`"),
                        );
                        l.push(d);
                        false
                    }
                };
                Rule::Sorted {
                    msg: from(l, Carries::Number)?,
                    descending,
                }
            }
            "own" => Rule::Own,
            "rule" => Rule::Silent,
            other => {
                const RULES: [&str; 5] = ["plurality", "borda", "sorted", "own", "rule"];
                let mut d = l.error(
                    loc(r),
                    "bad-rule",
                    format!(
                        "`{other}` is not a decision rule; expected one of {}",
                        RULES.join(", ")
                    ),
                );
                d.hint = did_you_mean(other, RULES);
                l.push(d);
                return None;
            }
        };
        if !matches!(
            rule,
            Rule::Plurality(_) | Rule::Borda(_) | Rule::Sorted { .. }
        ) {
            unexpected(l, "from", s.from.is_some());
        }
        return Some(Skill::Decide(rule));
    }
    let u = s.use_.as_ref()?;
    unexpected(l, "to", s.to.is_some());
    unexpected(l, "value", s.value.is_some());
    unexpected(l, "from", s.from.is_some());
    let Some(p) = l.registry.get(&u.value).cloned() else {
        let mut d = l.error(
            loc(u),
            "unknown-protocol",
            format!("no protocol `{}`", u.value),
        );
        d.hint = did_you_mean(&u.value, l.registry.names());
        l.push(d);
        return None;
    };
    if p.kind() != c.kind {
        let d = l.error(
            loc(u),
            "bad-kind",
            format!(
                "`{}` decides {} point; this protocol decides {}",
                u.value,
                p.kind().a_noun(),
                c.kind.a_noun()
            ),
        );
        l.push(d);
        return None;
    }
    let inner = p.nesting();
    if inner + 1 > MAX_DEPTH {
        let d = l.error(
            loc(u),
            "too-deep",
            format!(
                "protocols nest at most {MAX_DEPTH} deep; `{}` is {inner} deep",
                u.value
            ),
        );
        l.push(d);
        return None;
    }
    *depth = (*depth).max(inner + 1);
    let slot = uses.len() as u16;
    uses.push(UseDef {
        protocol: p,
        params: s.params.clone().unwrap_or(Params::Null),
    });
    Some(Skill::Use { slot })
}

fn source<F>(
    l: &mut Loader<'_>,
    c: &SkillCx<'_, F>,
    msg: usize,
    value: Option<&Spanned<String>>,
    exprs: &mut Vec<String>,
    at: Loc,
) -> Option<Source> {
    let carries = c.messages[msg].carries;
    let name = &c.messages[msg].name;
    let text = value.map(|v| v.value.trim());
    let bad = |l: &mut Loader<'_>, want: &str| {
        let d = l.error(
            value.map_or(at, loc),
            "bad-value",
            format!(
                "`{name}` carries `{}`: its value is {want}",
                Carries::NAMES[carries as usize]
            ),
        );
        l.push(d);
        None
    };
    match (carries, text) {
        (Carries::Nothing, None) => Some(Source::Nothing),
        (Carries::Nothing, Some(_)) => bad(l, "not given"),
        (Carries::Choice, Some("preferred")) => Some(Source::Preferred),
        (Carries::Choice, Some("first")) => Some(Source::First),
        (Carries::Choice | Carries::Ranking, Some("none")) => Some(Source::Nothing),
        (Carries::Choice, _) => bad(l, "`preferred`, `first` or `none` (abstain)"),
        (Carries::Ranking, Some("ranking")) => Some(Source::Ranking),
        (Carries::Ranking, _) => bad(l, "`ranking` or `none` (abstain)"),
        (Carries::Decision, Some("decision")) => Some(Source::Decision),
        (Carries::Decision, _) => bad(l, "`decision`"),
        (Carries::Number, None) => bad(l, "an expression (`dist(pos, goal)`, `$value`)"),
        (Carries::Number, Some(t)) => {
            let v = value?;
            for p in params_in(t) {
                if !c.params.iter().any(|(n, _, _)| n == p) {
                    let mut d = l.error(
                        loc(v),
                        "unknown-param",
                        format!("no parameter `${p}` in `params`"),
                    );
                    d.hint = did_you_mean(p, c.params.iter().map(|(n, _, _)| n.as_str()));
                    l.push(d);
                    return None;
                }
            }
            // Check the syntax now, with parameters standing for numbers.
            let probe: BTreeMap<&str, String> = c
                .params
                .iter()
                .map(|(n, _, _)| (n.as_str(), "0".to_string()))
                .collect();
            struct Any(Symbols);
            impl Resolver for Any {
                fn belief(&mut self, name: &str) -> BeliefId {
                    self.0.intern(name)
                }
                fn behavior(&self, _: &str) -> Option<BehaviorId> {
                    None
                }
            }
            if let Err(e) = Expr::parse(&substitute(t, &probe), &mut Any(Symbols::new())) {
                let d = l
                    .error(loc(v), "expression", format!("`{t}`: {e}"))
                    .with_detail(e.render(t));
                l.push(d);
                return None;
            }
            exprs.push(t.to_string());
            Some(Source::Expr(exprs.len() - 1))
        }
    }
}

/// The protocol files shipped in `examples/protocols/`, in load order (a
/// file may use those before it).
pub const SHIPPED: &[(&str, &str)] = &[
    (
        "examples/protocols/vote.yaml",
        include_str!("../../../../examples/protocols/vote.yaml"),
    ),
    (
        "examples/protocols/market.yaml",
        include_str!("../../../../examples/protocols/market.yaml"),
    ),
    (
        "examples/protocols/wait-all.yaml",
        include_str!("../../../../examples/protocols/wait-all.yaml"),
    ),
    (
        "examples/protocols/quorum-vote.yaml",
        include_str!("../../../../examples/protocols/quorum-vote.yaml"),
    ),
];

/// Register `p` in `registry`.
pub fn register(registry: &mut Registry, p: GraphProtocol) {
    registry.register(Arc::new(Registered(Arc::new(p))));
}

/// The shipped graph protocols, loaded once per process on top of the
/// built-in ones.
pub(crate) fn shipped(builtins: &Registry) -> &'static [Arc<Registered>] {
    static S: OnceLock<Vec<Arc<Registered>>> = OnceLock::new();
    S.get_or_init(|| {
        let mut r = builtins.clone();
        let mut out = Vec::new();
        for (file, text) in SHIPPED {
            let f: Arc<str> = Arc::from(*file);
            match GraphProtocol::load_str(&f, text, &r) {
                Ok(p) => {
                    let reg = Arc::new(Registered(Arc::new(p)));
                    r.register(reg.clone());
                    out.push(reg);
                }
                // A shipped file that does not load is a bug caught by the
                // tests (`shipped_protocols_load`); the others still load.
                Err(_) => continue,
            }
        }
        out
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_protocols_load() {
        let mut r = crate::registry();
        // Loading them again on top of themselves works too (same names
        // replace the shipped ones).
        for (file, text) in SHIPPED {
            let f: Arc<str> = Arc::from(*file);
            let p = GraphProtocol::load_str(&f, text, &r).unwrap_or_else(|d| panic!("{d}"));
            assert!(r.get(p.name).is_some(), "{} is registered", p.name);
            assert!(p.to_dot().starts_with("digraph"));
            register(&mut r, p);
        }
        assert_eq!(
            crate::registry()
                .iter()
                .filter(|p| p.source().is_some())
                .count(),
            SHIPPED.len()
        );
    }

    fn errors(text: &str) -> Diagnostics {
        let f: Arc<str> = Arc::from("p.yaml");
        GraphProtocol::load_str(&f, text, &crate::registry()).expect_err("refused")
    }

    const HEAD: &str = "protocol: t.x\nkind: sync\nmessages:\n  vote: { carries: choice }\n  decision: { carries: decision }\nannounce: decision\nstart: { leader: a, member: a }\n";

    #[test]
    fn mistakes_are_located_and_explained() {
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    do:\n      - {{ send: vot, to: leader, value: preferred }}\n"
        ));
        let d = &e.0[0];
        assert_eq!((d.code, d.loc.line), ("unknown-message", 11), "{e}");
        assert_eq!(d.hint.as_deref(), Some("did you mean `vote`?"), "{e}");
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    until: heard_vot > 0\n    do:\n      - {{ decide: plurality, from: vote }}\n"
        ));
        assert!(e.has("unknown-variable"), "{e}");
        assert_eq!(e.0[0].loc.line, 10, "{e}");
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    do:\n      - {{ decide: sorted, from: vote }}\n"
        ));
        assert!(e.has("bad-rule"), "{e}");
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    next: [b]\n  b:\n    next: [a]\n    do:\n      - {{ decide: own }}\n"
        ));
        assert!(e.has("busy-loop"), "{e}");
        // A constant condition waits no more than none (a loop on
        // `until: true` that sent to the team at every step flooded the
        // network); one that reads a variable may wait.
        for (until, pre) in [
            ("true", "true"),
            ("1 < 2", "not false"),
            ("true", "false or true"),
        ] {
            let e = errors(&format!(
                "{HEAD}behaviors:\n  a:\n    until: {until}\n    next: [a]\n    pre: '{pre}'\n    do:\n      - {{ decide: own }}\n"
            ));
            assert!(e.has("busy-loop"), "{until} / {pre}: {e}");
        }
        for (until, pre) in [
            ("heard_vote > 0", "true"),
            ("true", "false"),
            ("elapsed > 1", "true"),
        ] {
            let text = format!(
                "{HEAD}behaviors:\n  a:\n    until: {until}\n    next: [a]\n    pre: '{pre}'\n    do:\n      - {{ decide: own }}\n"
            );
            let f: Arc<str> = Arc::from("p.yaml");
            if let Err(e) = GraphProtocol::load_str(&f, &text, &crate::registry()) {
                assert!(!e.has("busy-loop"), "{until} / {pre}: {e}");
            }
        }
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    do:\n      - {{ use: sync.vot }}\n"
        ));
        assert_eq!(
            e.0[0].hint.as_deref(),
            Some("did you mean `sync.vote`?"),
            "{e}"
        );
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    do:\n      - {{ use: alloc.by-id }}\n"
        ));
        assert!(e.has("bad-kind"), "{e}");
        let e = errors(&format!(
            "{HEAD}behaviors:\n  a:\n    until: heard_vote > 0\n  b:\n    do:\n      - {{ decide: own }}\n"
        ));
        assert!(e.has("unreachable") && !e.has("never-decides"), "{e}");
        let e = errors(&HEAD.replace("t.x", "sync.vote").replace(
            "start:",
            "behaviors:\n  a:\n    do: [{ decide: own }]\nstart:",
        ));
        assert!(e.has("name-taken"), "{e}");
    }

    #[test]
    fn nesting_is_bounded() {
        let mut r = crate::registry();
        let mut prev = "sync.leader".to_string();
        for depth in 2..=MAX_DEPTH + 1 {
            let name = format!("t.nest{depth}");
            let text = format!(
                "protocol: {name}\nkind: sync\nmessages:\n  decision: {{ carries: decision }}\nannounce: decision\nstart: {{ leader: a, member: a }}\nbehaviors:\n  a:\n    do:\n      - {{ use: {prev} }}\n"
            );
            let f: Arc<str> = Arc::from("n.yaml");
            match GraphProtocol::load_str(&f, &text, &r) {
                Ok(p) => {
                    assert!(depth <= MAX_DEPTH, "depth {depth} accepted");
                    assert_eq!(p.depth, depth);
                    register(&mut r, p);
                }
                Err(e) => {
                    assert_eq!(depth, MAX_DEPTH + 1, "{e}");
                    assert!(e.has("too-deep"), "{e}");
                }
            }
            prev = name;
        }
    }
}
