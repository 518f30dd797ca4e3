//! Loading and validating behavior graphs.
//!
//! Validation collects every problem it can find in one pass (instead of
//! stopping at the first), each with file, line and column, what was
//! expected, and a hint where one helps.

use super::spec::{BehaviorSpec, BindingSpec, GraphSpec, Ordered, RobotsSpec};
use super::{
    Behavior, BehaviorGraph, Binding, MAX_BEHAVIORS, MAX_DEPTH, MAX_ROBOTS, NameIndex, Skill,
};
use crate::belief::Symbols;
use crate::cond::{CondError, Expr, Resolver};
use crate::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use crate::ids::Kind;
use crate::ids::{BehaviorId, BeliefId, name_hash};
use crate::roster::{RobotInfo, Roster};
use crate::time::parse_duration;
use crate::value::Value;
use crate::yaml::json_to_value;
use serde_saphyr::Spanned;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;
use std::sync::Arc;

/// Load and validate a behavior graph file.
pub fn load(path: &Path) -> Result<BehaviorGraph, Diagnostics> {
    let (file, text) = crate::yaml::read_file(path)?;
    load_str(&file, &text)
}

/// Load and validate a behavior graph from text; `file` names it in messages.
pub fn load_str(file: &Arc<str>, text: &str) -> Result<BehaviorGraph, Diagnostics> {
    // Most graphs, and generated ones always, are in the plain subset of
    // YAML the fast reader takes (10-20x faster); anything else, and any
    // mistake, goes through the YAML library and its messages. A test
    // (`fast_tests`) checks both give the same graph or the same errors.
    let fast = crate::yaml::fast::parse(text).and_then(|root| super::spec::fast::graph(&root));
    let spec: GraphSpec = match fast {
        Some(spec) => spec,
        None => crate::yaml::parse(file, text)?,
    };
    build(file, text, &spec)
}

/// Validate a behavior graph built in code rather than read from YAML
/// (the command-language compiler hands its graph over this way): the same
/// checks and the same [`BehaviorGraph`] as [`load_str`] on the equivalent
/// text. Diagnostics carry the locations the spec's `Spanned` values hold
/// (`Location::UNKNOWN` in a spec built in code: no line or column).
pub fn load_spec(file: &Arc<str>, spec: GraphSpec) -> Result<BehaviorGraph, Diagnostics> {
    build(file, "", &spec)
}

/// One behavior as written: its name and its spec.
pub type BehaviorEntry = (Spanned<String>, Spanned<BehaviorSpec>);

/// [`load_spec`] on a graph whose behaviors are kept apart, read in place
/// (`spec.behaviors` is not read): a compiled mission keeps its behaviors
/// (one list per command) and hands them over without a copy.
pub fn load_parts(
    file: &Arc<str>,
    spec: &GraphSpec,
    behaviors: &[&BehaviorEntry],
) -> Result<BehaviorGraph, Diagnostics> {
    builder(file, "").build(spec, Some((behaviors, Loc::UNKNOWN)))
}

fn builder<'a>(file: &Arc<str>, text: &'a str) -> Builder<'a> {
    Builder {
        file: file.clone(),
        text,
        diags: Vec::new(),
        labels: BTreeMap::new(),
        runs_refs: Vec::new(),
    }
}

fn build(file: &Arc<str>, text: &str, spec: &GraphSpec) -> Result<BehaviorGraph, Diagnostics> {
    let entries: Vec<&BehaviorEntry> = spec.behaviors.iter().flat_map(|b| &b.value.0).collect();
    let behaviors = (spec.behaviors.as_ref()).map(|b| (&entries[..], Loc::from(b.referenced)));
    builder(file, text).build(spec, behaviors)
}

struct Builder<'a> {
    file: Arc<str>,
    text: &'a str,
    diags: Vec<Diagnostic>,
    /// Point labels seen so far: label → behavior.
    labels: BTreeMap<String, String>,
    /// `runs(x)` in a condition of a behavior: (owner, x, field, where).
    runs_refs: Vec<(BehaviorId, BehaviorId, &'static str, Loc)>,
}

/// The behaviors' names while a graph is built: hashed (every edge and
/// every `runs(...)` looks one up), and in order for the messages that
/// list them (sorted the first time one is written).
struct Names<'a> {
    index: &'a NameIndex,
    entries: &'a [&'a BehaviorEntry],
    sorted: std::sync::OnceLock<Vec<&'a str>>,
}

impl<'a> Names<'a> {
    fn get(&self, name: &str) -> Option<BehaviorId> {
        self.index.get(name, |i| &self.entries[i].0.value)
    }
    fn all(&self) -> impl Iterator<Item = &'a str> + '_ {
        self.sorted
            .get_or_init(|| {
                let mut v: Vec<&str> = self.entries.iter().map(|(n, _)| n.value.as_str()).collect();
                v.sort_unstable();
                v.dedup();
                v
            })
            .iter()
            .copied()
    }
}

/// Graphs of this many behaviors or more are built side by side on rayon's
/// pool; the graph and the messages are those of a build one behavior after
/// the other, whatever the number of threads.
const PARALLEL_FROM: usize = 4096;

/// Lists up to this long (a behavior's edges, the belief names its
/// conditions read) are searched by a scan, longer ones through a hash set.
const SHORT_LIST: usize = 8;

/// What building one behavior reads: the same for every behavior.
struct Cx<'a> {
    file: &'a Arc<str>,
    text: &'a str,
    names: &'a Names<'a>,
}

/// What a behavior's entry gives besides the behavior itself, put in order
/// with the other behaviors' afterwards.
#[derive(Default)]
struct Made {
    member_loc: Option<Loc>,
    critical_loc: Option<Loc>,
    /// Its messages, in the order they were found.
    diags: Vec<Diagnostic>,
    /// The belief names its conditions read, in order of first appearance:
    /// its conditions' belief ids index this until the graph's table of
    /// names is filled, in the behaviors' order.
    beliefs: Vec<Box<str>>,
    /// Their hashes ([`crate::ids::name_hash`]), made by the thread that made the
    /// behavior: the table of names is filled from them.
    belief_hashes: Vec<u64>,
    /// `runs(x)` in its conditions: (x, field, where).
    runs_refs: Vec<(BehaviorId, &'static str, Loc)>,
    /// Its bindings give point labels: labels are unique graph-wide, so
    /// these are made in order afterwards.
    labelled: bool,
}

/// A behavior's bindings: sync, allocate, terminate.
fn binding_specs(spec: &BehaviorSpec) -> [Option<&Spanned<BindingSpec>>; 3] {
    [
        spec.sync.as_deref(),
        spec.allocate.as_deref(),
        spec.terminate.as_deref(),
    ]
}

/// Belief names of one behavior's conditions, numbered from 0.
struct LocalNames<'a, 'n> {
    beliefs: &'a mut Vec<Box<str>>,
    /// `beliefs` hashed, once there are many.
    index: rustc_hash::FxHashMap<Box<str>, u32>,
    names: &'a Names<'n>,
    /// Behaviors named in `runs(...)` by the condition being parsed.
    looked_up: std::cell::RefCell<Vec<BehaviorId>>,
}

impl Resolver for LocalNames<'_, '_> {
    fn belief(&mut self, name: &str) -> BeliefId {
        // A behavior's conditions read a handful of names: a scan finds
        // them. Past `SHORT_LIST`, a table (a condition may read hundreds).
        if self.beliefs.len() > SHORT_LIST && self.index.is_empty() {
            self.index = (self.beliefs.iter().enumerate())
                .map(|(i, b)| (b.clone(), i as u32))
                .collect();
        }
        let found = if self.index.is_empty() {
            self.beliefs.iter().position(|b| **b == *name)
        } else {
            self.index.get(name).map(|&i| i as usize)
        };
        let at = found.unwrap_or_else(|| {
            self.beliefs.push(name.into());
            if !self.index.is_empty() {
                self.index
                    .insert(name.into(), (self.beliefs.len() - 1) as u32);
            }
            self.beliefs.len() - 1
        });
        BeliefId(at as u32)
    }
    fn behavior(&self, name: &str) -> Option<BehaviorId> {
        let id = self.names.get(name);
        if let Some(id) = id {
            self.looked_up.borrow_mut().push(id);
        }
        id
    }
    fn behavior_names(&self) -> Vec<&str> {
        self.names.all().collect()
    }
}

impl Made {
    fn err(
        &mut self,
        cx: &Cx<'_>,
        loc: Loc,
        code: &'static str,
        msg: impl Into<String>,
    ) -> &mut Diagnostic {
        self.diags.push(Diagnostic::error(cx.file, loc, code, msg));
        let n = self.diags.len() - 1;
        &mut self.diags[n]
    }

    /// Behavior `id` from its entry.
    fn behavior(
        cx: &Cx<'_>,
        id: BehaviorId,
        name: &Spanned<String>,
        spec: &BehaviorSpec,
    ) -> (Behavior, Made) {
        let mut made = Made::default();
        let loc = Loc::from(name.referenced);
        let children = made.edges(cx, &spec.children, &name.value, "child");
        let next = made.edges(cx, &spec.next, &name.value, "successor");
        for c in &spec.children {
            if spec.next.iter().any(|n| n.value == c.value) {
                made.err(
                    cx,
                    Loc::from(c.referenced),
                    "sequential-and-decomposition",
                    format!(
                        "`{}` is both a child and a sequential successor of `{}` (S ∩ V must be empty)",
                        c.value, name.value
                    ),
                )
                .hint = Some("an edge is either `children` (decomposition) or `next` (sequence), not both".into());
            }
        }
        let pre = made.condition(cx, &spec.pre, "pre", Some("bool"));
        let until = made.condition(cx, &spec.until, "until", Some("bool"));
        let urgent = made.condition(cx, &spec.urgent, "urgent", Some("bool"));
        let utility = made.condition(cx, &spec.utility, "utility", Some("number"));
        let mut bindings: [Option<Box<Binding>>; 3] = [None, None, None];
        let specs = binding_specs(spec);
        if specs.iter().flatten().any(|b| b.value.point.is_some()) {
            made.labelled = true;
        } else {
            for (slot, b) in bindings.iter_mut().zip(specs) {
                *slot = b.map(|b| Box::new(make_binding(cx.file, b, &mut made.diags)));
            }
        }
        let members = spec
            .members
            .as_ref()
            .map_or((1, u32::MAX), |m| (m.value.min, m.value.max));
        made.member_loc = spec.members.as_ref().map(|m| Loc::from(m.referenced));
        made.critical_loc = spec.critical.as_ref().map(|c| Loc::from(c.referenced));
        let skill = spec.skill.as_ref().map(|s| Skill {
            name: s.value.name.clone(),
            params: s.value.params.clone(),
        });
        made.belief_hashes = made.beliefs.iter().map(|b| name_hash(b)).collect();
        let behavior = Behavior {
            id,
            name: name.value.clone(),
            description: spec.description.clone(),
            team: spec.team,
            children,
            next,
            pre,
            until,
            urgent,
            utility,
            skill,
            members,
            critical: spec.critical.as_ref().is_some_and(|c| c.value),
            bindings,
            labels: None,
            loc,
        };
        (behavior, made)
    }

    /// The ids of an edge list (where each is written is looked up again
    /// for a message: [`EdgeLocs`]).
    fn edges(
        &mut self,
        cx: &Cx<'_>,
        refs: &[Spanned<String>],
        owner: &str,
        what: &str,
    ) -> Vec<BehaviorId> {
        let mut ids: Vec<BehaviorId> = Vec::with_capacity(refs.len());
        let mut seen: rustc_hash::FxHashSet<BehaviorId> = rustc_hash::FxHashSet::default();
        let long = refs.len() > SHORT_LIST;
        for r in refs {
            let loc = Loc::from(r.referenced);
            match cx.names.get(&r.value) {
                Some(id)
                    if if long {
                        !seen.insert(id)
                    } else {
                        ids.contains(&id)
                    } =>
                {
                    self.err(
                        cx,
                        loc,
                        "duplicate-edge",
                        format!("`{}` is listed twice as a {what} of `{owner}`", r.value),
                    );
                }
                Some(id) => ids.push(id),
                None => {
                    let hint = did_you_mean(&r.value, cx.names.all());
                    let d = self.err(
                        cx,
                        loc,
                        "unknown-reference",
                        format!(
                            "`{owner}` names `{}` as a {what}, but no behavior is called `{}`",
                            r.value, r.value
                        ),
                    );
                    d.hint = hint;
                }
            }
        }
        ids
    }

    fn condition(
        &mut self,
        cx: &Cx<'_>,
        src: &Option<Box<Spanned<String>>>,
        field: &'static str,
        want: Option<&'static str>,
    ) -> Option<Box<Expr>> {
        let s = src.as_ref()?;
        let mut resolver = LocalNames {
            beliefs: &mut self.beliefs,
            index: rustc_hash::FxHashMap::default(),
            names: cx.names,
            looked_up: std::cell::RefCell::new(Vec::new()),
        };
        let parsed = Expr::parse(&s.value, &mut resolver);
        let looked_up = resolver.looked_up.into_inner();
        match parsed {
            Ok(e) => {
                for x in looked_up {
                    self.runs_refs.push((x, field, Loc::from(s.referenced)));
                }
                if let (Some(want), Some(got)) = (want, e.static_type())
                    && want != got
                {
                    self.err(
                        cx,
                        Loc::from(s.referenced),
                        "condition-type",
                        format!(
                            "`{field}` must be a {want} expression, but `{}` is a {got}",
                            s.value
                        ),
                    );
                    return None;
                }
                Some(Box::new(e))
            }
            Err(ce) => {
                let loc = expr_loc(cx.text, Loc::from(s.referenced), &s.value, &ce);
                let d = self.err(
                    cx,
                    loc,
                    "bad-condition",
                    format!("in `{field}`: {}", ce.message),
                );
                d.detail = Some(ce.render(&s.value));
                d.hint = ce.hint.clone();
                None
            }
        }
    }
}

fn valid_name(n: &str) -> bool {
    let mut cs = n.chars();
    matches!(cs.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && cs.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

impl Builder<'_> {
    fn err(&mut self, loc: Loc, code: &'static str, msg: impl Into<String>) -> &mut Diagnostic {
        self.diags
            .push(Diagnostic::error(&self.file, loc, code, msg));
        let n = self.diags.len() - 1;
        &mut self.diags[n]
    }
    fn warn(&mut self, loc: Loc, code: &'static str, msg: impl Into<String>) {
        self.diags
            .push(Diagnostic::warning(&self.file, loc, code, msg));
    }

    fn build(
        mut self,
        spec: &GraphSpec,
        behaviors: Option<(&[&BehaviorEntry], Loc)>,
    ) -> Result<BehaviorGraph, Diagnostics> {
        let roster = self.roster(spec.team.as_ref());
        let Some((entries, section_loc)) = behaviors else {
            self.err(
                Loc::new(1, 1),
                "no-behaviors",
                "the graph has no `behaviors:` section",
            );
            return Err(Diagnostics(self.diags));
        };
        if entries.is_empty() {
            self.err(section_loc, "no-behaviors", "`behaviors:` is empty");
            return Err(Diagnostics(self.diags));
        }
        if entries.len() > MAX_BEHAVIORS {
            self.err(
                section_loc,
                "too-large",
                format!(
                    "the graph has {} behaviors; the limit is {MAX_BEHAVIORS}",
                    entries.len()
                ),
            );
            return Err(Diagnostics(self.diags));
        }

        // Each name's id (a name given twice keeps its last id). The names
        // are hashed and checked side by side for large graphs (each read
        // once, by one thread), then put in the table in order.
        let hashed =
            |&(name, _): &&BehaviorEntry| (name_hash(&name.value), valid_name(&name.value));
        let hashes: Vec<(u64, bool)> = if entries.len() >= PARALLEL_FROM {
            use rayon::prelude::*;
            entries.par_iter().map(hashed).collect()
        } else {
            entries.iter().map(hashed).collect()
        };
        let index = NameIndex::hashed(hashes.len(), |i| hashes[i].0, |i| &entries[i].0.value);
        for (&(name, _), _) in entries.iter().zip(&hashes).filter(|(_, (_, ok))| !ok) {
            self.err(
                Loc::from(name.referenced),
                "bad-name",
                format!(
                    "`{}` is not a valid behavior name: use letters, digits, `_` and `-`, starting with a letter",
                    name.value
                ),
            );
        }

        let names = Names {
            index: &index,
            entries,
            sorted: std::sync::OnceLock::new(),
        };
        let n = entries.len();
        // Each behavior on its own, side by side for large graphs; then, in
        // order, the belief names numbered by first appearance, the
        // messages put in order and the point labels (graph-wide) checked.
        let file = self.file.clone();
        let cx = Cx {
            file: &file,
            text: self.text,
            names: &names,
        };
        let one = |(i, &(name, body)): (usize, &&BehaviorEntry)| {
            Made::behavior(&cx, BehaviorId(i as u32), name, &body.value)
        };
        let (mut out, made): (Vec<Behavior>, Vec<Made>) = if n >= PARALLEL_FROM {
            use rayon::prelude::*;
            entries.par_iter().enumerate().map(one).unzip()
        } else {
            entries.iter().enumerate().map(one).unzip()
        };
        // Belief names read, counted with repeats: the tables are made at
        // their largest size (growing them copies them on this thread).
        let reads: usize = if n >= PARALLEL_FROM {
            use rayon::prelude::*;
            made.par_iter().map(|m| m.beliefs.len()).sum()
        } else {
            made.iter().map(|m| m.beliefs.len()).sum()
        };
        let mut symbols = Symbols::with_capacity(reads);
        let mut member_locs: Vec<[Option<Loc>; 2]> = Vec::with_capacity(n);
        // Behavior i's belief ids in the graph's table, `ids[remap[i]..
        // remap[i + 1]]`, left empty where they are its own numbering.
        let mut ids: Vec<BeliefId> = Vec::with_capacity(reads);
        let mut remap: Vec<u32> = Vec::with_capacity(n + 1);
        remap.push(0);
        for (i, (m, &(_, body))) in made.into_iter().zip(entries).enumerate() {
            let from = ids.len();
            ids.extend(
                (m.beliefs.iter().zip(&m.belief_hashes))
                    .map(|(name, &h)| symbols.intern_hashed(h, name)),
            );
            if ids[from..]
                .iter()
                .enumerate()
                .all(|(k, id)| id.index() == k)
            {
                ids.truncate(from);
            }
            remap.push(ids.len() as u32);
            self.diags.extend(m.diags);
            if m.labelled {
                let b = &mut out[i];
                let (bindings, labels) = self.bindings(&b.name, binding_specs(&body.value));
                b.bindings = bindings;
                b.labels = labels.iter().any(Option::is_some).then(|| Box::new(labels));
            }
            let id = BehaviorId(i as u32);
            self.runs_refs.extend(
                m.runs_refs
                    .into_iter()
                    .map(|(x, field, loc)| (id, x, field, loc)),
            );
            member_locs.push([m.member_loc, m.critical_loc]);
        }
        // The conditions' belief ids renumbered, side by side.
        let renumber = |(i, b): (usize, &mut Behavior)| {
            let map = &ids[remap[i] as usize..remap[i + 1] as usize];
            if !map.is_empty() {
                for e in [&mut b.pre, &mut b.until, &mut b.urgent, &mut b.utility]
                    .into_iter()
                    .flatten()
                {
                    e.remap_beliefs(map);
                }
            }
        };
        if n >= PARALLEL_FROM {
            use rayon::prelude::*;
            out.par_iter_mut().enumerate().for_each(renumber);
        } else {
            out.iter_mut().enumerate().for_each(renumber);
        }
        let edges = Edges::of(&out, n >= PARALLEL_FROM);
        let locs = EdgeLocs {
            entries,
            names: &names,
        };

        let start = match &spec.start {
            None => {
                let roots: Vec<&str> = roots(&edges)
                    .iter()
                    .map(|b| out[b.index()].name.as_str())
                    .collect();
                let d = self.err(
                    Loc::new(1, 1),
                    "missing-start",
                    "the graph has no `start:` behavior (b0, where execution begins)",
                );
                if !roots.is_empty() {
                    d.hint = Some(format!(
                        "add `start: {}` (behaviors nothing leads to: {})",
                        roots[0],
                        roots.join(", ")
                    ));
                }
                None
            }
            Some(s) => match names.get(&s.value) {
                Some(id) => Some(id),
                None => {
                    let hint = did_you_mean(&s.value, names.all());
                    let d = self.err(
                        Loc::from(s.referenced),
                        "unknown-reference",
                        format!("the start behavior `{}` is not defined", s.value),
                    );
                    d.hint = hint;
                    None
                }
            },
        };

        self.check_decomposition(&out, &edges, &locs);
        self.check_loops_and_depth(&out, &edges, &locs);
        self.check_chain_heads(&out, &edges, &locs);
        self.check_bindings_fit(&out);
        self.check_members(&out, &edges, &member_locs);
        if let Some(start) = start {
            self.check_reachable(&out, &edges, start);
            self.check_runs_scope(&out, &edges, start);
        }
        let defaults = self.defaults(&spec.defaults);
        let sharing = match &spec.world_model {
            Some(w) => crate::graph::Sharing::default().with_spec(&self.file, w, &mut self.diags),
            None => crate::graph::Sharing::default(),
        };
        let initial_beliefs = self.beliefs(&spec.beliefs, &symbols);

        if self.diags.iter().any(Diagnostic::is_error) {
            return Err(Diagnostics(self.diags));
        }
        let (Some(start), Some(roster)) = (start, roster) else {
            return Err(Diagnostics(self.diags));
        };
        Ok(BehaviorGraph {
            name: spec.graph.clone().unwrap_or_else(|| stem(&self.file)),
            description: spec.description.clone(),
            file: self.file.clone(),
            behaviors: out,
            names: index,
            start,
            symbols: Arc::new(symbols),
            roster: Arc::new(roster),
            defaults,
            initial_beliefs,
            sharing,
            config: None,
            warnings: self.diags,
            retired: Vec::new(),
        })
    }

    fn roster(&mut self, team: Option<&super::spec::TeamSpec>) -> Option<Roster> {
        let Some(team) = team else {
            return Some(Roster::anonymous(1));
        };
        let loc = Loc::from(team.robots.referenced);
        match &team.robots.value {
            RobotsSpec::Count(0) => {
                self.err(loc, "empty-team", "a team needs at least one robot");
                None
            }
            RobotsSpec::Count(n) if *n as usize > MAX_ROBOTS => {
                self.err(
                    loc,
                    "too-large",
                    format!("{n} robots; the limit is {MAX_ROBOTS}"),
                );
                None
            }
            RobotsSpec::Count(n) => Some(Roster::anonymous(*n as usize)),
            RobotsSpec::List(list) => {
                if list.is_empty() {
                    self.err(loc, "empty-team", "a team needs at least one robot");
                    return None;
                }
                let mut seen = BTreeSet::new();
                let mut robots = Vec::new();
                for r in list {
                    let rloc = Loc::from(r.referenced);
                    // A robot's name is a chunk of its network keys
                    // (`bite/<team>/net/<robot>`) and of its log's file
                    // name: no `/`, `*`, spaces, nor an empty name.
                    if !valid_name(&r.value.name) {
                        self.err(
                            rloc,
                            "bad-name",
                            format!(
                                "`{}` is not a valid robot name: use letters, digits, `_` and `-`, starting with a letter",
                                r.value.name
                            ),
                        );
                    }
                    if !seen.insert(r.value.name.clone()) {
                        self.err(
                            rloc,
                            "duplicate-robot",
                            format!("robot `{}` is listed twice", r.value.name),
                        );
                    }
                    let mut attributes = BTreeMap::new();
                    for (k, v) in &r.value.attributes {
                        match json_to_value(v) {
                            Some(v) => {
                                attributes.insert(k.clone(), v);
                            }
                            None => {
                                self.err(
                                    rloc,
                                    "bad-value",
                                    format!(
                                        "attribute `{k}` of robot `{}` must be a bool, number, text or [x, y]",
                                        r.value.name
                                    ),
                                );
                            }
                        }
                    }
                    robots.push(RobotInfo {
                        name: r.value.name.clone(),
                        attributes,
                    });
                }
                Some(Roster::new(robots))
            }
        }
    }

    fn binding(&mut self, spec: &Spanned<BindingSpec>) -> Binding {
        make_binding(&self.file, spec, &mut self.diags)
    }

    /// A behavior's bindings (sync, allocate, terminate) and the point
    /// labels they give, checked against the labels of the behaviors
    /// before it.
    fn bindings(
        &mut self,
        behavior: &str,
        specs: [Option<&Spanned<BindingSpec>>; 3],
    ) -> ([Option<Box<Binding>>; 3], [Option<String>; 3]) {
        let mut bindings: [Option<Box<Binding>>; 3] = [None, None, None];
        let mut labels: [Option<String>; 3] = [None, None, None];
        for (kind, b) in [Kind::Sync, Kind::Allocate, Kind::Terminate]
            .into_iter()
            .zip(specs)
        {
            let Some(b) = b else { continue };
            if let Some(label) = &b.value.point {
                let at = Loc::from(label.referenced);
                if !valid_name(&label.value) {
                    self.err(
                        at,
                        "bad-name",
                        format!(
                            "point label `{}` must be letters, digits, `_` or `-`",
                            label.value
                        ),
                    );
                }
                match self.labels.get(&label.value) {
                    Some(other) if other == behavior => {
                        self.err(
                            at,
                            "duplicate-point",
                            format!(
                                "point label `{}` is used twice in `{behavior}`",
                                label.value
                            ),
                        );
                    }
                    Some(other) => {
                        let msg = format!(
                            "point label `{}` is used by `{other}` and `{behavior}`",
                            label.value
                        );
                        self.err(at, "duplicate-point", msg);
                    }
                    None => {
                        self.labels
                            .insert(label.value.clone(), behavior.to_string());
                    }
                }
                labels[kind.index()] = Some(label.value.clone());
            }
            bindings[kind.index()] = Some(Box::new(self.binding(b)));
        }
        (bindings, labels)
    }

    fn defaults(&mut self, d: &super::spec::DefaultsSpec) -> [Option<Binding>; 3] {
        let mut out: [Option<Binding>; 3] = [None, None, None];
        for (kind, b) in [
            (Kind::Sync, &d.sync),
            (Kind::Allocate, &d.allocate),
            (Kind::Terminate, &d.terminate),
        ] {
            if let Some(b) = b {
                if let Some(p) = &b.value.point {
                    self.err(
                        Loc::from(p.referenced),
                        "bad-binding",
                        "a default binding cannot carry a `point` label",
                    );
                }
                out[kind.index()] = Some(self.binding(b));
            }
        }
        out
    }

    /// The initial beliefs. One whose name no condition can read (a
    /// condition names a belief with letters, digits and `_`) is a
    /// warning: nothing can ever read it, a protocol's expression no more
    /// than a behavior's condition, so it is most likely a misspelling.
    fn beliefs(
        &mut self,
        spec: &Ordered<serde_json::Value>,
        symbols: &Symbols,
    ) -> Vec<(String, Value)> {
        let mut out = Vec::new();
        for (k, v) in &spec.0 {
            if !crate::cond::readable_name(&k.value) {
                let mut d = Diagnostic::warning(
                    &self.file,
                    Loc::from(k.referenced),
                    "unreadable-belief",
                    format!(
                        "initial belief `{}` has a name no condition can read",
                        k.value
                    ),
                );
                let near: String = (k.value.chars())
                    .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                    .collect();
                d.hint = Some(if symbols.get(&near).is_some() {
                    format!("did you mean `{near}`? A condition reads it")
                } else {
                    "conditions name beliefs with ASCII letters, digits and `_`, starting with a letter or `_` (not `and`, `or`, `not`, `true`, `false`)".into()
                });
                self.diags.push(d);
            }
            match json_to_value(&v.value) {
                Some(val) => out.push((k.value.clone(), val)),
                None => {
                    self.err(
                        Loc::from(v.referenced),
                        "bad-value",
                        format!(
                            "initial belief `{}` must be a bool, number, text or [x, y]",
                            k.value
                        ),
                    );
                }
            }
        }
        out
    }

    /// V must be acyclic (a behavior cannot be its own ancestor).
    fn check_decomposition(&mut self, bs: &[Behavior], g: &Edges, locs: &EdgeLocs<'_>) {
        // Iterative DFS with colours: 0 new, 1 on the path, 2 done.
        let n = bs.len();
        let mut colour = vec![0u8; n];
        let mut reported = BTreeSet::new();
        let mut stack: Vec<(usize, usize)> = Vec::new();
        for root in 0..n {
            if colour[root] != 0 {
                continue;
            }
            stack.push((root, 0));
            colour[root] = 1;
            while let Some(&mut (v, ref mut next)) = stack.last_mut() {
                if let Some(&c) = g.children(v).get(*next) {
                    *next += 1;
                    let c = c.index();
                    match colour[c] {
                        0 => {
                            colour[c] = 1;
                            stack.push((c, 0));
                        }
                        1 => {
                            let from = stack.iter().position(|(x, _)| *x == c).unwrap_or(0);
                            let mut cycle: Vec<usize> =
                                stack[from..].iter().map(|(x, _)| *x).collect();
                            let key: BTreeSet<usize> = cycle.iter().copied().collect();
                            if reported.insert(key.into_iter().collect::<Vec<_>>()) {
                                cycle.push(c);
                                let path: Vec<&str> =
                                    cycle.iter().map(|x| bs[*x].name.as_str()).collect();
                                let loc = locs.child(v, c).unwrap_or(bs[v].loc);
                                let d = self.err(
                                    loc,
                                    "decomposition-cycle",
                                    format!(
                                        "decomposition cycle: {} (a behavior cannot be its own ancestor)",
                                        path.join(" → ")
                                    ),
                                );
                                d.hint = Some(
                                    "to repeat a behavior, use a sequential edge (`next`), which may cycle".into(),
                                );
                            }
                        }
                        _ => {}
                    }
                } else {
                    colour[v] = 2;
                    stack.pop();
                }
            }
        }
    }

    /// A `next` edge must not lead back to an ancestor, and the stack must
    /// not grow deeper than [`MAX_DEPTH`].
    ///
    /// Descending (`children`) pushes a level onto the stack; a sequential
    /// edge (`next`) replaces the top at the same level. A cycle of edges
    /// that descends at least once would therefore grow the stack on every
    /// pass, without bound: `mission: {children: [work]}` with
    /// `work: {next: [mission]}` runs `mission` again *under* `mission`.
    /// Such a cycle is refused (`loop-to-ancestor`) at the `next` entry that
    /// closes it; cycles of `next` edges alone (a patrol `a -> b -> a`) stay
    /// legal. Without them, the deepest stack is the largest number of
    /// descents on any path, which is checked against [`MAX_DEPTH`]
    /// (`too-deep`).
    ///
    /// Linear in the size of the graph: strongly connected components of
    /// the `children` + `next` edges, one search per component that holds
    /// both kinds of edge, and levels over the components' DAG.
    fn check_loops_and_depth(&mut self, bs: &[Behavior], g: &Edges, locs: &EdgeLocs<'_>) {
        let n = bs.len();
        let (comp, ncomp) = components(g);
        // Nodes of each component, in graph order.
        let (start, nodes) = grouped(
            ncomp,
            (comp.iter().enumerate()).map(|(v, &c)| (c as usize, v as u32)),
            0,
        );
        // Layered search state, reused across components (they are
        // disjoint): for (node, descended), the step that reached it.
        let mut prev: Vec<Option<(u32, bool, bool)>> = vec![None; 2 * n];
        let mut level = vec![0usize; ncomp];
        for c in 0..ncomp {
            let members = &nodes[start[c] as usize..start[c + 1] as usize];
            let inside = |v: usize| comp[v] as usize == c;
            let mut descends = false;
            let mut closing: Option<(usize, usize)> = None;
            let mut deepest = 0usize;
            for &v in members {
                let v = v as usize;
                for ch in g.children(v) {
                    if inside(ch.index()) {
                        descends = true;
                    } else {
                        deepest = deepest.max(1 + level[comp[ch.index()] as usize]);
                    }
                }
                for nx in g.next(v) {
                    if inside(nx.index()) {
                        closing = closing.or(Some((v, nx.index())));
                    } else {
                        deepest = deepest.max(level[comp[nx.index()] as usize]);
                    }
                }
            }
            level[c] = deepest;
            let (true, Some((s, t))) = (descends, closing) else {
                continue;
            };
            // A walk t ~> s inside the component that descends at least
            // once; with s -> t it closes a loop. Breadth first over
            // (node, descended yet).
            let slot = |v: usize, d: bool| 2 * v + usize::from(d);
            let mut queue = VecDeque::from([(t, false)]);
            prev[slot(t, false)] = Some((t as u32, false, false));
            let mut found = false;
            while let Some((v, d)) = queue.pop_front() {
                if v == s && d {
                    found = true;
                    break;
                }
                let edges = (g.children(v).iter().map(|x| (x.index(), true)))
                    .chain(g.next(v).iter().map(|x| (x.index(), false)));
                for (w, down) in edges {
                    let dw = d || down;
                    if inside(w) && prev[slot(w, dw)].is_none() {
                        prev[slot(w, dw)] = Some((v as u32, d, down));
                        queue.push_back((w, dw));
                    }
                }
            }
            if !found {
                continue;
            }
            // The loop as edges (from, to, descends), ending with s -> t.
            let mut walk = vec![(s, t, false)];
            let (mut v, mut d) = (s, true);
            while v != t || d {
                let Some((u, du, down)) = prev[slot(v, d)] else {
                    break;
                };
                walk.push((u as usize, v, down));
                (v, d) = (u as usize, du);
            }
            walk.reverse();
            // Start it where a `next` edge leads into a descent: the end
            // of that `next` edge is an ancestor of its start.
            let m = walk.len();
            let Some(i) = (0..m).find(|&i| !walk[i].2 && walk[(i + 1) % m].2) else {
                continue;
            };
            walk.rotate_left((i + 1) % m);
            let &(from, to, _) = walk.last().unwrap_or(&(s, t, false));
            // `a > b -> c`: `>` descends, `->` follows a `next`; a long
            // loop is shown by its ends.
            let mut path = bs[to].name.clone();
            let steps = &walk[..m - 1];
            for (k, &(_, w, down)) in steps.iter().enumerate() {
                if steps.len() > 12 && (6..steps.len() - 6).contains(&k) {
                    if k == 6 {
                        path.push_str(&format!(" … ({} more)", steps.len() - 12));
                    }
                    continue;
                }
                path.push_str(if down { " > " } else { " -> " });
                path.push_str(&bs[w].name);
            }
            let levels = walk.iter().filter(|e| e.2).count();
            let loc = locs.next(from, to).unwrap_or(bs[from].loc);
            let (f, a) = (&bs[from].name, &bs[to].name);
            let d = self.err(
                loc,
                "loop-to-ancestor",
                format!(
                    "`{f}` -> `{a}` loops back to an ancestor: `{a}` is an ancestor of `{f}` ({path}), so every pass would run `{a}` {levels} level{} deeper, without bound",
                    if levels == 1 { "" } else { "s" }
                ),
            );
            d.hint = Some(format!(
                "`next` runs a behavior at the same level of the stack: to run `{a}` again, loop at its own level (`next: [{a}]` on `{a}`, or on a behavior after it), or loop among its children"
            ));
        }
        // The deepest stack below any behavior: descents on the longest path.
        if let Some(deepest) = level.iter().copied().max()
            && deepest > MAX_DEPTH
            && let Some(i) = (0..n).find(|&v| level[comp[v] as usize] == deepest)
        {
            self.err(
                bs[i].loc,
                "too-deep",
                format!(
                    "decomposition below `{}` is {deepest} levels deep; the limit is {MAX_DEPTH}",
                    bs[i].name
                ),
            );
        }
    }

    /// A child must head an execution chain: nothing may enter it by a
    /// sequential edge except from its own chain (a cycle back to the head).
    fn check_chain_heads(&mut self, bs: &[Behavior], g: &Edges, locs: &EdgeLocs<'_>) {
        let incoming = g.incoming_next();
        for p in 0..g.len() {
            for c in g.children(p) {
                if incoming.children(c.index()).is_empty() {
                    continue;
                }
                let chain = seq_reach(g, *c);
                // An edge from the parent itself is the S ∩ V error, reported once.
                for x in (incoming.children(c.index()).iter()).filter(|x| x.index() != p) {
                    if !chain.contains(x) {
                        let (child, parent, from) =
                            (&bs[c.index()].name, &bs[p].name, &bs[x.index()].name);
                        let d = self.err(
                            locs.child(p, c.index()).unwrap_or(bs[p].loc),
                            "child-not-chain-head",
                            format!(
                                "`{child}` is a child of `{parent}`, so it must head an execution chain, but `{from}` leads into it sequentially from outside its chain"
                            ),
                        );
                        d.hint = Some(format!(
                            "remove `{child}` from the `children` of `{parent}` (it already runs after `{from}`), or remove `{child}` from the `next` of `{from}`"
                        ));
                        break;
                    }
                }
            }
        }
    }

    /// A binding on a behavior that is not that kind of point is unused.
    fn check_bindings_fit(&mut self, bs: &[Behavior]) {
        for b in bs {
            for kind in Kind::ALL {
                let Some(bind) = &b.bindings[kind.index()] else {
                    continue;
                };
                let team_next = b.next.iter().filter(|n| bs[n.index()].team).count();
                let why = match kind {
                    Kind::Sync if team_next < 2 => Some(format!(
                        "it has {team_next} team successor(s); a synchronization point needs two or more"
                    )),
                    Kind::Allocate if b.children.len() < 2 => Some(format!(
                        "it has {} child(ren); an allocation point needs two or more",
                        b.children.len()
                    )),
                    Kind::Terminate if !b.team => {
                        Some("it is not a team behavior (add `team: true`)".to_string())
                    }
                    _ => None,
                };
                if let Some(why) = why {
                    self.warn(
                        bind.loc,
                        "binding-unused",
                        format!(
                            "`{}` binds {} protocol but is not {} point: {why}",
                            b.name,
                            kind.a_noun(),
                            kind.a_noun()
                        ),
                    );
                }
            }
        }
    }

    /// `members` and `critical` (`locs[i]`: where behavior `i` sets them)
    /// on a behavior that no allocation point ever deals members to.
    fn check_members(&mut self, bs: &[Behavior], g: &Edges, locs: &[[Option<Loc>; 2]]) {
        let mut allocated = vec![false; bs.len()];
        for p in 0..bs.len() {
            let children = g.children(p);
            if children.len() >= 2 {
                for c in children {
                    allocated[c.index()] = true;
                }
            }
        }
        for (i, pair) in locs.iter().enumerate() {
            if allocated[i] {
                continue;
            }
            for (loc, key) in pair.iter().zip(["members", "critical"]) {
                let Some(loc) = loc else { continue };
                self.warn(
                    *loc,
                    "members-unused",
                    format!(
                        "`{}` sets `{key}` but is never a child of an allocation point",
                        bs[i].name
                    ),
                );
            }
        }
    }

    fn check_reachable(&mut self, bs: &[Behavior], g: &Edges, start: BehaviorId) {
        let mut seen = vec![false; bs.len()];
        let mut q = VecDeque::from([start]);
        seen[start.index()] = true;
        while let Some(b) = q.pop_front() {
            for n in g.children(b.index()).iter().chain(g.next(b.index())) {
                if !seen[n.index()] {
                    seen[n.index()] = true;
                    q.push_back(*n);
                }
            }
        }
        // Only the unreachable ones are read.
        for (v, _) in seen.iter().enumerate().filter(|(_, seen)| !**seen) {
            self.warn(
                bs[v].loc,
                "unreachable",
                format!(
                    "`{}` can never run: no path of `children`/`next` edges leads to it from `{}`",
                    bs[v].name,
                    bs[start.index()].name
                ),
            );
        }
    }

    /// `runs(x)` counts the starts of `x` in the current execution of the
    /// parent of the behavior whose condition it is in; an `x` that never
    /// runs under the same parent is always 0 — a mistake, not a loop count.
    fn check_runs_scope(&mut self, bs: &[Behavior], g: &Edges, start: BehaviorId) {
        if self.runs_refs.is_empty() {
            return;
        }
        // The parents each behavior can run under (None: the top-level chain).
        let mut parents: Vec<BTreeSet<Option<BehaviorId>>> = vec![BTreeSet::new(); bs.len()];
        for b in seq_reach(g, start) {
            parents[b.index()].insert(None);
        }
        for p in 0..bs.len() {
            for c in g.children(p) {
                for b in seq_reach(g, *c) {
                    parents[b.index()].insert(Some(BehaviorId(p as u32)));
                }
            }
        }
        for (owner, x, field, loc) in std::mem::take(&mut self.runs_refs) {
            if parents[owner.index()].is_disjoint(&parents[x.index()]) {
                let d = self.err(
                    loc,
                    "runs-out-of-scope",
                    format!(
                        "`runs({})` in the `{field}` of `{}` is always 0: `{}` never runs under the same parent as `{}`",
                        bs[x.index()].name,
                        bs[owner.index()].name,
                        bs[x.index()].name,
                        bs[owner.index()].name
                    ),
                );
                d.hint = Some(
                    "`runs(x)` counts the starts of `x` during the current execution of the parent; name a behavior of the same execution chains".into(),
                );
            }
        }
    }
}

/// A binding from its spec; bad durations become diagnostics.
pub(crate) fn make_binding(
    file: &Arc<str>,
    spec: &Spanned<BindingSpec>,
    diags: &mut Vec<Diagnostic>,
) -> Binding {
    let loc = Loc::from(spec.referenced);
    let mut dur = |text: &Option<Spanned<crate::yaml::DurationText>>, what: &str| {
        text.as_ref()
            .and_then(|t| match parse_duration(&t.value.0) {
                Ok(d) => Some(d),
                Err(e) => {
                    diags.push(Diagnostic::error(
                        file,
                        Loc::from(t.referenced),
                        "bad-duration",
                        format!("`{what}`: {e}"),
                    ));
                    None
                }
            })
    };
    let deadline = dur(&spec.value.deadline, "deadline");
    let retry = dur(&spec.value.retry, "retry");
    Binding {
        protocol: spec.value.protocol.clone(),
        deadline,
        retry,
        params: spec.value.params.clone(),
        file: file.clone(),
        loc,
    }
}

/// Strongly connected components of the `children` + `next` edges
/// (iterative Tarjan): each behavior's component, and how many there are.
/// Components are numbered in the order they complete, so every edge
/// leaving a component leads to one with a lower number.
fn components(g: &Edges) -> (Vec<u32>, usize) {
    const NEW: u32 = u32::MAX;
    let n = g.len();
    // The i-th edge of v: its children, then its successors.
    let edge = |v: usize, i: usize| -> Option<usize> {
        let children = g.children(v);
        match i.checked_sub(children.len()) {
            None => Some(children[i].index()),
            Some(j) => g.next(v).get(j).map(|x| x.index()),
        }
    };
    let mut index = vec![NEW; n];
    let mut low = vec![0u32; n];
    let mut on_stack = vec![false; n];
    let mut comp = vec![NEW; n];
    let mut stack: Vec<usize> = Vec::new();
    let mut calls: Vec<(usize, usize)> = Vec::new();
    let mut counter = 0u32;
    let mut ncomp = 0usize;
    for root in 0..n {
        if index[root] != NEW {
            continue;
        }
        index[root] = counter;
        low[root] = counter;
        counter += 1;
        stack.push(root);
        on_stack[root] = true;
        calls.push((root, 0));
        while let Some(&mut (v, ref mut i)) = calls.last_mut() {
            if let Some(w) = edge(v, *i) {
                *i += 1;
                if index[w] == NEW {
                    index[w] = counter;
                    low[w] = counter;
                    counter += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    calls.push((w, 0));
                } else if on_stack[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            calls.pop();
            if let Some(&(u, _)) = calls.last() {
                low[u] = low[u].min(low[v]);
            }
            if low[v] == index[v] {
                while let Some(x) = stack.pop() {
                    on_stack[x] = false;
                    comp[x] = ncomp as u32;
                    if x == v {
                        break;
                    }
                }
                ncomp += 1;
            }
        }
    }
    (comp, ncomp)
}

/// Behaviors reachable from `b` along sequential edges, `b` included.
fn seq_reach(g: &Edges, b: BehaviorId) -> BTreeSet<BehaviorId> {
    let mut seen = BTreeSet::from([b]);
    let mut q = VecDeque::from([b]);
    while let Some(x) = q.pop_front() {
        for n in g.next(x.index()) {
            if seen.insert(*n) {
                q.push_back(*n);
            }
        }
    }
    seen
}

/// Behaviors with no incoming edge of either kind (candidates for `start`).
fn roots(g: &Edges) -> Vec<BehaviorId> {
    let mut has_in = vec![false; g.len()];
    for v in 0..g.len() {
        for n in g.children(v).iter().chain(g.next(v)) {
            has_in[n.index()] = true;
        }
    }
    (0..g.len())
        .filter(|&v| !has_in[v])
        .map(|v| BehaviorId(v as u32))
        .collect()
}

/// Every behavior's `children` and `next` edges, packed: the graph-wide
/// checks walk these instead of the behaviors themselves (their walks
/// were cache misses on behaviors of a few hundred bytes each).
struct Edges {
    /// Behavior v's children: `children[child_at[v]..child_at[v + 1]]`.
    children: Vec<BehaviorId>,
    child_at: Vec<u32>,
    /// Its successors: `next[next_at[v]..next_at[v + 1]]`.
    next: Vec<BehaviorId>,
    next_at: Vec<u32>,
}

impl Edges {
    /// The edges of `bs`, read side by side when `parallel`.
    fn of(bs: &[Behavior], parallel: bool) -> Self {
        use rayon::prelude::*;
        let len = |b: &Behavior| (b.children.len() as u32, b.next.len() as u32);
        let lens: Vec<(u32, u32)> = if parallel {
            bs.par_iter().map(len).collect()
        } else {
            bs.iter().map(len).collect()
        };
        let at = |f: fn(&(u32, u32)) -> u32| {
            let mut at = Vec::with_capacity(bs.len() + 1);
            at.push(0u32);
            let mut sum = 0;
            for l in &lens {
                sum += f(l);
                at.push(sum);
            }
            at
        };
        let list = |f: fn(&Behavior) -> &[BehaviorId]| -> Vec<BehaviorId> {
            if parallel {
                bs.par_iter()
                    .flat_map_iter(|b| f(b).iter().copied())
                    .collect()
            } else {
                bs.iter().flat_map(|b| f(b).iter().copied()).collect()
            }
        };
        Edges {
            children: list(|b| &b.children),
            child_at: at(|l| l.0),
            next: list(|b| &b.next),
            next_at: at(|l| l.1),
        }
    }
    fn len(&self) -> usize {
        self.child_at.len() - 1
    }
    fn children(&self, v: usize) -> &[BehaviorId] {
        &self.children[self.child_at[v] as usize..self.child_at[v + 1] as usize]
    }
    fn next(&self, v: usize) -> &[BehaviorId] {
        &self.next[self.next_at[v] as usize..self.next_at[v + 1] as usize]
    }
    /// Who leads into each behavior by a `next` edge, in the behaviors'
    /// order, as the `children` of the result.
    fn incoming_next(&self) -> Edges {
        let n = self.len();
        let edges = (0..n).flat_map(|v| {
            let from = BehaviorId(v as u32);
            self.next(v).iter().map(move |x| (x.index(), from))
        });
        let (at, from) = grouped(n, edges, BehaviorId(0));
        Edges {
            children: from,
            child_at: at,
            next: Vec::new(),
            next_at: vec![0; n + 1],
        }
    }
}

/// `(key, value)` pairs grouped by key, in the order given (a counting
/// sort): group k is `values[at[k]..at[k + 1]]`, for keys below `keys`
/// (`blank` fills the list before the values are put in place).
fn grouped<V: Copy>(
    keys: usize,
    pairs: impl Iterator<Item = (usize, V)> + Clone,
    blank: V,
) -> (Vec<u32>, Vec<V>) {
    let mut at = vec![0u32; keys + 1];
    for (k, _) in pairs.clone() {
        at[k + 1] += 1;
    }
    for k in 0..keys {
        at[k + 1] += at[k];
    }
    let mut fill = at.clone();
    let mut values = vec![blank; at[keys] as usize];
    for (k, v) in pairs {
        values[fill[k] as usize] = v;
        fill[k] += 1;
    }
    (at, values)
}

/// Where each edge is written, looked up for a message (the behaviors
/// keep the ids only).
struct EdgeLocs<'a> {
    entries: &'a [&'a BehaviorEntry],
    names: &'a Names<'a>,
}

impl EdgeLocs<'_> {
    /// Where `from` names `to` among its children.
    fn child(&self, from: usize, to: usize) -> Option<Loc> {
        self.find(&self.entries[from].1.value.children, to)
    }
    /// Where `from` names `to` among its successors.
    fn next(&self, from: usize, to: usize) -> Option<Loc> {
        self.find(&self.entries[from].1.value.next, to)
    }
    fn find(&self, refs: &[Spanned<String>], to: usize) -> Option<Loc> {
        (refs.iter())
            .find(|r| self.names.get(&r.value).is_some_and(|id| id.index() == to))
            .map(|r| Loc::from(r.referenced))
    }
}

fn stem(file: &str) -> String {
    Path::new(file)
        .file_stem()
        .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned())
}

/// The file position of byte `ce.span.start` of an expression whose YAML
/// scalar starts at `at`. Exact for single-line plain and quoted scalars;
/// for block scalars, the line holding the offending token.
fn expr_loc(src: &str, at: Loc, value: &str, ce: &CondError) -> Loc {
    let off = ce.span.start.min(value.len());
    let Some(line) = (at.line as usize)
        .checked_sub(1)
        .and_then(|l| crate::yaml::lines(src).nth(l))
    else {
        return at;
    };
    let rest: String = line
        .chars()
        .skip(at.col.saturating_sub(1) as usize)
        .collect();
    let prefix = value.get(..off).map_or(0, |p| p.chars().count()) as u32;
    if rest.starts_with(value) {
        return Loc::new(at.line, at.col + prefix);
    }
    if (rest.starts_with('"') || rest.starts_with('\'')) && rest[1..].starts_with(value) {
        return Loc::new(at.line, at.col + 1 + prefix);
    }
    // A scalar over several lines (plain, or a `|` / `>` block): the value
    // joins its lines with one character (a newline or a space). The first
    // line starts at `at`; the others after their indentation. Walk the
    // lines in step with the value.
    let mut value_off = 0usize;
    for (i, line) in crate::yaml::lines(src)
        .enumerate()
        .skip(at.line as usize - 1)
    {
        let first = i + 1 == at.line as usize;
        let (content, indent): (String, usize) = if first {
            let skip = at.col.saturating_sub(1) as usize;
            (line.chars().skip(skip).collect(), skip)
        } else {
            let t = line.trim_start();
            (t.to_string(), line.chars().count() - t.chars().count())
        };
        let content = content.trim_end();
        if value
            .get(value_off..)
            .is_none_or(|v| !v.starts_with(content))
        {
            break;
        }
        let end = value_off + content.len();
        if off < end || (off == end && end == value.len()) {
            let col = value
                .get(value_off.min(off)..off)
                .map_or(0, |p| p.chars().count())
                + indent
                + 1;
            return Loc::new(i as u32 + 1, col as u32);
        }
        value_off = end + 1;
    }
    at
}

#[cfg(test)]
mod fast_tests {
    use super::*;
    use std::path::PathBuf;

    /// Both readers on one text: the fast one must take only what the
    /// YAML library takes, and give the same graph, or the same errors,
    /// with the same locations.
    fn same(file: &Arc<str>, text: &str) -> bool {
        let Some(fast) =
            crate::yaml::fast::parse(text).and_then(|r| super::super::spec::fast::graph(&r))
        else {
            return false;
        };
        let slow: Result<GraphSpec, _> = crate::yaml::parse(file, text);
        let slow = slow.unwrap_or_else(|e| {
            panic!("{file}: the fast reader took what the library refuses: {e}")
        });
        let (a, b) = (build(file, text, &fast), build(file, text, &slow));
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "{file}");
        true
    }

    fn files(dir: &str) -> Vec<PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
        let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
            .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
            .unwrap_or_default();
        v.retain(|p| p.extension().is_some_and(|x| x == "yaml"));
        v.sort();
        v
    }

    #[test]
    fn the_fast_reader_reads_as_the_yaml_library_does() {
        let mut taken = 0;
        let mut all = 0;
        for dir in [
            "../../examples",
            "tests/fixtures",
            "../bite-rtcl/tests/golden",
        ] {
            for p in files(dir) {
                let text = std::fs::read_to_string(&p).expect("readable");
                let file: Arc<str> = Arc::from(p.display().to_string());
                all += 1;
                if same(&file, &text) {
                    taken += 1;
                }
            }
        }
        let f: Arc<str> = Arc::from("t.yaml");
        let cases = [
            "graph: g\nstart: a\nbehaviors:\n  a: { skill: s, until: \"x > 1\" }\n",
            "start: a\nteam: { robots: 3 }\nbehaviors:\n  a:\n    team: true\n    children: [b, c]\n  b: { skill: s, members: 2 }\n  c: { skill: s, members: \"1..\" }\n",
            "start: a\nbehaviors:\n  a:\n    children: [b, zz]   # a comment\n    next: [ b ]\n  b: {}\n",
            "start: q\nbehaviors:\n  a: { next: [a, a] }\n  Bé: { description: \"é\\u00e9\\\"q\\\"\" }\n",
            "start: a\nbehaviors:\n  a: { until: \"runs(b) > 1\", next: [b] }\n  b: { until: done and x >= 2, pre: not done }\n",
            "start: a\nbehaviors:\n  a: { children: [a] }\n",
            "start: a\ndefaults: { sync: sync.vote, terminate: term.local }\nbehaviors:\n  a: { team: true, terminate: term.first-wins, sync: sync.vote }\n",
            "start: a\nbehaviors:\n  a: { until: \"bad (\" }\n",
            "start: a\nbehaviors:\n  a: { until: 3 }\n",
            "start: a\nbehaviors:\n  a: { until: true }\n",
            "start: a\nbehaviors:\n  a: { team: yes }\n",
            "start: a\nbehaviors:\n  a: { members: 0 }\n",
            "start: a\nbehaviors:\n  a: { nxt: [a] }\n",
            "start: a\nbehaviors:\n  a: {}\n  a: {}\n",
            "start: a\nbehaviors:\n  a:\n    next: [a]\n     skill: s\n",
            "start: a\nbehaviors:\n  a: { skill: s }\n  b: { skill: s\n",
            "start: a\nbehaviors:\n  a: { skill: s } x\n",
            "start: a\nbehaviors:\n  a:\n    until: a\n      and b\n",
            "start: a\nbehaviors: {}\n",
            "start: a\nbehaviors:\n",
        ];
        for text in cases {
            same(&f, text);
        }
        // What the library reads differently or refuses is left to it.
        for text in [
            "start: a\nbehaviors:\n  a: { description: x\u{86}y }\n",
            "start: a\r\nbehaviors:\r\n  a: {}\r\n",
            "start: a\nbehaviors:\n\ta: {}\n",
            "start: a\nbehaviors:\n  a: { description: 'q' }\n",
            "start: a\nbehaviors:\n  a: &x { }\n",
            "---\nstart: a\nbehaviors:\n  a: {}\n",
            "start: a\nbehaviors:\n  a:\n    next:\n      - a\n",
        ] {
            assert!(!same(&f, text), "{text:?}");
        }
        eprintln!("the fast reader took {taken} of {all} files");
        assert!(taken >= 10, "the fast reader took {taken} of {all} files");
    }
}

#[cfg(test)]
mod side_by_side_tests {
    use super::*;

    /// A graph large enough to be built side by side: a chain of `n`
    /// behaviors whose conditions read beliefs in an order that repeats
    /// only from afar, some with bindings, some giving point labels.
    /// `broken`: every 97th behavior also has mistakes of every kind the
    /// builder finds one behavior at a time.
    fn large(n: usize, broken: bool) -> String {
        let mut y = String::from("start: b0\nbehaviors:\n");
        for i in 0..n {
            let mut fields = vec![format!(
                "until: \"x{} > 1 && y{} || x{}\"",
                (i * 7) % 61,
                (i * 13) % 37,
                (i * 3) % 61
            )];
            if i + 1 < n {
                fields.push(format!("next: [b{}]", i + 1));
            }
            if i % 5 == 0 {
                fields.push(format!("pre: \"known(z{})\"", i % 11));
            }
            if i % 250 == 0 {
                fields.push(format!("sync: {{ protocol: sync.vote, point: P{i} }}"));
            } else if i % 3 == 0 {
                fields.push("terminate: { protocol: term.local, deadline: 2s }".into());
            }
            if broken && i % 97 == 0 {
                fields.push(format!("children: [nowhere{i}, b{}, b{}]", i + 1, i + 1));
                fields.push("utility: \"x1 >\"".into());
                fields.push(format!(
                    "allocate: {{ protocol: alloc.by-id, point: P{}, retry: soon }}",
                    (i / 250) * 250
                ));
            }
            y.push_str(&format!("  b{i}: {{ {} }}\n", fields.join(", ")));
        }
        y
    }

    fn on_threads(threads: usize, text: &str) -> Result<BehaviorGraph, Diagnostics> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool");
        let file: Arc<str> = Arc::from("large.yaml");
        pool.install(|| load_str(&file, text))
    }

    #[test]
    fn a_large_graph_is_the_graph_of_one_behavior_after_the_other() {
        let n = PARALLEL_FROM + 1500;
        let text = large(n, false);
        let g = on_threads(3, &text).expect("loads");
        // Belief names numbered in order of first appearance, behavior
        // after behavior (pre before until), as one after the other does.
        let mut expected: Vec<String> = Vec::new();
        let mut see = |name: String| {
            if !expected.contains(&name) {
                expected.push(name);
            }
        };
        for i in 0..n {
            if i % 5 == 0 {
                see(format!("z{}", i % 11));
            }
            see(format!("x{}", (i * 7) % 61));
            see(format!("y{}", (i * 13) % 37));
            see(format!("x{}", (i * 3) % 61));
        }
        let names: Vec<&str> = g.symbols().iter().map(|(_, n)| n).collect();
        assert_eq!(names, expected);
        // Each condition reads its own names under the graph's ids.
        for b in g.behaviors() {
            let i = b.id.index();
            let until = b.until.as_ref().expect("an until");
            let mut read: Vec<&str> = until
                .beliefs()
                .iter()
                .map(|&id| g.symbols().name(id))
                .collect();
            read.sort_unstable();
            let mut want = vec![
                format!("x{}", (i * 7) % 61),
                format!("y{}", (i * 13) % 37),
                format!("x{}", (i * 3) % 61),
            ];
            want.sort_unstable();
            want.dedup();
            assert_eq!(read, want, "b{i}");
            assert!(until.beliefs().is_sorted(), "b{i}");
        }
        // Labels and bindings where they were written.
        let p = g.find("b500").expect("b500");
        assert_eq!(g.behavior(p).label(Kind::Sync), Some("P500"));
        let t = g.find("b3").expect("b3");
        assert!(g.behavior(t).bindings[2].is_some());
        // The same graph for any number of threads.
        for threads in [1, 2, 8] {
            let other = on_threads(threads, &text).expect("loads");
            assert_eq!(format!("{other:?}"), format!("{g:?}"), "{threads} threads");
        }
    }

    #[test]
    fn a_large_graph_s_mistakes_are_told_in_the_order_of_its_behaviors() {
        let n = PARALLEL_FROM + 1500;
        let text = large(n, true);
        let Err(d) = on_threads(3, &text) else {
            panic!("a broken graph loads");
        };
        // Per broken behavior, in order: the unknown child, the child
        // listed twice, a child that is also its successor, the utility
        // that does not parse, the retry that is no duration and the label
        // another behavior gives (or one used twice in itself).
        let mut i = 0;
        let mut codes = Vec::new();
        for x in
            d.0.iter()
                .filter(|x| x.code != "too-deep" && x.code != "unreachable")
        {
            codes.push((x.code, x.message.clone()));
        }
        for b in (0..n).step_by(97) {
            let owner = format!("`b{b}`");
            let mine: Vec<&str> = codes[i..]
                .iter()
                .take_while(|(_, m)| m.contains(&owner) || !m.contains("`b"))
                .map(|(c, _)| *c)
                .collect();
            assert!(
                mine.starts_with(&[
                    "unknown-reference",
                    "duplicate-edge",
                    "sequential-and-decomposition"
                ]),
                "b{b}: {mine:?}"
            );
            assert!(mine.contains(&"bad-condition"), "b{b}: {mine:?}");
            assert!(mine.contains(&"bad-duration"), "b{b}: {mine:?}");
            i += mine.len();
        }
        for threads in [1, 2, 8] {
            let Err(other) = on_threads(threads, &text) else {
                panic!("a broken graph loads");
            };
            assert_eq!(format!("{other:?}"), format!("{d:?}"), "{threads} threads");
        }
    }

    #[test]
    fn conditions_reading_many_beliefs_number_them_in_order_of_appearance() {
        // `pre` reads v0..v39, `until` v20..v59 and w: past a handful, the
        // names of one behavior are found through a table.
        let pre: Vec<String> = (0..40).map(|i| format!("v{i}")).collect();
        let until: Vec<String> = (20..60).rev().map(|i| format!("v{i}")).collect();
        let text = format!(
            "start: a\nbehaviors:\n  a: {{ next: [b], pre: \"{}\", until: \"{} && w\" }}\n  b: {{ until: \"w && v3\" }}\n",
            pre.join(" && "),
            until.join(" && ")
        );
        let g = load_str(&Arc::from("t.yaml"), &text).expect("loads");
        let mut expected = pre.clone();
        expected.extend(until.iter().filter(|n| !pre.contains(n)).cloned());
        expected.push("w".into());
        let names: Vec<&str> = g.symbols().iter().map(|(_, n)| n).collect();
        assert_eq!(names, expected);
        let b = g.behavior(g.find("b").expect("b"));
        let read: Vec<&str> = (b.until.as_ref().expect("until").beliefs().iter())
            .map(|&id| g.symbols().name(id))
            .collect();
        assert_eq!(read, ["v3", "w"]);
    }

    #[test]
    fn names_are_found_and_a_name_given_twice_keeps_its_last_id() {
        let names = ["a", "b", "a", "c"];
        let index = NameIndex::new(names.len(), |i| names[i]);
        assert_eq!(index.get("a", |i| names[i]), Some(BehaviorId(2)));
        assert_eq!(index.get("b", |i| names[i]), Some(BehaviorId(1)));
        assert_eq!(index.get("c", |i| names[i]), Some(BehaviorId(3)));
        assert_eq!(index.get("d", |i| names[i]), None);
    }
}
