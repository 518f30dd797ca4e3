//! The task behavior graph ⟨B, S, V, b0⟩.
//!
//! `B` are the [`Behavior`]s, `S` their sequential edges (`next`: order and
//! choice), `V` their decomposition edges (`children`: each child heads an
//! execution chain), `b0` the start behavior. `V` is acyclic, `S` may cycle
//! (behaviors repeated by choice), and `S ∩ V = ∅`.
//!
//! From this structure BITE derives, without being told, where robots must
//! coordinate ([`BehaviorGraph::points`]):
//! - a **synchronization point** after every behavior with two or more
//!   sequential successors that are team behaviors (the team must choose the
//!   same one);
//! - an **allocation point** at every behavior with two or more children
//!   (the team splits into subteams, one per execution chain);
//! - a **termination point** at every team behavior (the team ends it
//!   together).
//!
//! Graphs are loaded from YAML (see `docs/graph-format.md`) by [`load`].

mod align;
mod config;
pub mod dot;
mod load;
pub mod sharing;
pub mod spec;
pub mod svg;

pub use align::Refused;
pub use config::Config;
pub use load::{BehaviorEntry, load, load_parts, load_spec, load_str};

use crate::belief::Symbols;
use crate::cond::Expr;
use crate::diag::{Diagnostic, Loc};
use crate::ids::BehaviorId;
use crate::ids::Kind;
use crate::roster::Roster;
use crate::value::Value;
pub use sharing::{Policy, Sharing};

/// A protocol's parameters as a binding gives them (`params:` in a graph or
/// configuration file), handed to the protocol to configure itself.
pub type Params = serde_json::Value;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

/// Largest graph accepted (behaviors).
pub const MAX_BEHAVIORS: usize = 100_000;
/// Deepest decomposition accepted (levels below the start behavior).
pub const MAX_DEPTH: usize = 64;
pub use crate::roster::MAX_ROBOTS;

/// A skill: what an atomic behavior makes the robot do.
#[derive(Clone, Debug, PartialEq)]
pub struct Skill {
    /// Skill name, looked up by the runtime (simulator or robot).
    pub name: String,
    /// Parameters.
    pub params: BTreeMap<String, serde_json::Value>,
}

/// A protocol binding at a point, as written in a graph or configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Binding {
    /// Protocol name or alias (`None`: keep the default protocol).
    pub protocol: Option<String>,
    /// Deadline of each instance.
    pub deadline: Option<Duration>,
    /// Retransmission interval.
    pub retry: Option<Duration>,
    /// Protocol parameters (`null` when none).
    pub params: Params,
    /// File the binding was written in.
    pub file: Arc<str>,
    /// Where.
    pub loc: Loc,
}

/// One behavior of the graph.
#[derive(Clone, Debug)]
pub struct Behavior {
    /// Its id (index in the graph).
    pub id: BehaviorId,
    /// Its unique name.
    pub name: String,
    /// Free text.
    pub description: Option<String>,
    /// Team behavior: its selection, allocation and termination are coordinated.
    pub team: bool,
    /// Decomposition edges, to the heads of execution chains (file order).
    pub children: Vec<BehaviorId>,
    /// Sequential edges (file order).
    pub next: Vec<BehaviorId>,
    /// Precondition: the behavior can be selected only when it holds.
    /// (The four conditions are boxed: most behaviors have one or none,
    /// and a condition is 72 bytes; a `Behavior` is 232 bytes, where it
    /// was 552, and a graph of 100,000 behaviors writes them all at once.)
    pub pre: Option<Box<Expr>>,
    /// Termination condition: the behavior ends when it holds.
    pub until: Option<Box<Expr>>,
    /// Emergency termination: when it holds the behavior ends on this robot
    /// at once (its termination protocol is told, not awaited) and the
    /// robot picks the successor alone.
    pub urgent: Option<Box<Expr>>,
    /// Preference among alternatives for deciding protocols (higher wins).
    pub utility: Option<Box<Expr>>,
    /// Skill (atomic behaviors).
    pub skill: Option<Skill>,
    /// Members it takes when allocated: at least `members.0`, at most `members.1`.
    pub members: (u32, u32),
    /// A child of an allocation point whose minimum comes first when the
    /// team is too small for every child's ([`crate::rules::member_counts`]).
    pub critical: bool,
    /// Bindings of its points, indexed by [`Kind::index`].
    pub bindings: [Option<Box<Binding>>; 3],
    /// Labels of its points (`A`), indexed by [`Kind::index`]; `None` when
    /// it has none (most behaviors: boxed, as the bindings are, to keep a
    /// large graph's behaviors small). [`Behavior::label`] reads one.
    pub labels: Option<Box<[Option<String>; 3]>>,
    /// Where it is defined.
    pub loc: Loc,
}

impl Behavior {
    /// True when it has no children (it runs a skill).
    pub fn is_atomic(&self) -> bool {
        self.children.is_empty()
    }

    /// The label of its point of this kind, if it has one.
    pub fn label(&self, kind: Kind) -> Option<&str> {
        self.labels.as_ref()?[kind.index()].as_deref()
    }
}

/// A coordination point found by analysis.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Point {
    /// The point behavior.
    pub behavior: BehaviorId,
    /// Which interaction happens there.
    pub kind: Kind,
    /// Its name: the label if it has one, else `behavior.kind`.
    pub name: String,
}

/// Behaviors' names, hashed: a name's id without a copy of the name (the
/// table holds ids, and a lookup compares with the name the id has).
#[derive(Clone, Debug)]
pub(crate) struct NameIndex {
    table: hashbrown::HashTable<u32>,
}

impl NameIndex {
    /// The ids `0..n` by their names (`name(i)`); a name given twice keeps
    /// its last id.
    pub(crate) fn new<'a>(n: usize, name: impl Fn(usize) -> &'a str) -> NameIndex {
        Self::hashed(n, |i| crate::ids::name_hash(name(i)), &name)
    }

    /// [`NameIndex::new`] with each name's hash given (`hash(i)`, made
    /// by [`crate::ids::name_hash`]): a name is read only to tell it from
    /// another of the same hash.
    pub(crate) fn hashed<'a>(
        n: usize,
        hash: impl Fn(usize) -> u64,
        name: impl Fn(usize) -> &'a str,
    ) -> NameIndex {
        let mut table = hashbrown::HashTable::with_capacity(n);
        for i in 0..n {
            let h = hash(i);
            match table.entry(
                h,
                |&j: &u32| name(j as usize) == name(i),
                |&j| hash(j as usize),
            ) {
                hashbrown::hash_table::Entry::Occupied(mut o) => *o.get_mut() = i as u32,
                hashbrown::hash_table::Entry::Vacant(v) => {
                    v.insert(i as u32);
                }
            }
        }
        NameIndex { table }
    }

    /// The id of `key`, where `name(i)` is the name of id `i` (the names
    /// the index was made with).
    pub(crate) fn get<'a>(&self, key: &str, name: impl Fn(usize) -> &'a str) -> Option<BehaviorId> {
        self.table
            .find(crate::ids::name_hash(key), |&j| name(j as usize) == key)
            .map(|&j| BehaviorId(j))
    }
}

/// A validated behavior graph.
#[derive(Clone, Debug)]
pub struct BehaviorGraph {
    name: String,
    description: Option<String>,
    file: Arc<str>,
    behaviors: Vec<Behavior>,
    /// Each behavior's id by its name.
    names: NameIndex,
    start: BehaviorId,
    symbols: Arc<Symbols>,
    roster: Arc<Roster>,
    defaults: [Option<Binding>; 3],
    initial_beliefs: Vec<(String, Value)>,
    sharing: Sharing,
    config: Option<String>,
    warnings: Vec<Diagnostic>,
    /// Behaviors of older versions kept for robots still inside them
    /// (sorted; see [`BehaviorGraph::aligned_to`]).
    retired: Vec<BehaviorId>,
}

impl BehaviorGraph {
    /// Name of the graph.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Description, if any.
    pub fn description(&self) -> Option<&str> {
        self.description.as_deref()
    }
    /// File it was loaded from.
    pub fn file(&self) -> &Arc<str> {
        &self.file
    }
    /// The team's world-model settings (`world_model:`).
    pub fn sharing(&self) -> Sharing {
        self.sharing
    }
    /// Name of the applied configuration, if any.
    pub fn config_name(&self) -> Option<&str> {
        self.config.as_deref()
    }
    /// All behaviors in id (file) order.
    pub fn behaviors(&self) -> &[Behavior] {
        &self.behaviors
    }
    /// Number of behaviors.
    pub fn len(&self) -> usize {
        self.behaviors.len()
    }
    /// True when the graph has no behavior (never, once validated).
    pub fn is_empty(&self) -> bool {
        self.behaviors.is_empty()
    }
    /// A behavior by id.
    ///
    /// Ids come from this graph; an id from elsewhere is a programming error.
    #[inline]
    pub fn behavior(&self, id: BehaviorId) -> &Behavior {
        &self.behaviors[id.index()]
    }
    /// A behavior by id, if it exists (for ids from the network).
    pub fn get(&self, id: BehaviorId) -> Option<&Behavior> {
        self.behaviors.get(id.index())
    }
    /// A behavior's name (`b<id>` if unknown).
    pub fn name_of(&self, id: BehaviorId) -> &str {
        self.get(id).map_or("?", |b| &b.name)
    }
    /// Look a behavior up by name.
    pub fn find(&self, name: &str) -> Option<BehaviorId> {
        self.names.get(name, |i| &self.behaviors[i].name)
    }
    /// The start behavior b0.
    pub fn start(&self) -> BehaviorId {
        self.start
    }
    /// Interned belief names.
    pub fn symbols(&self) -> &Arc<Symbols> {
        &self.symbols
    }
    /// Replace the symbol table by a superset of it (protocol parameters
    /// add names when a mission is built).
    pub(crate) fn set_symbols(&mut self, symbols: Arc<Symbols>) {
        debug_assert!(symbols.len() >= self.symbols.len());
        self.symbols = symbols;
    }
    /// The team roster.
    pub fn roster(&self) -> &Arc<Roster> {
        &self.roster
    }
    /// Beliefs every robot starts with.
    pub fn initial_beliefs(&self) -> &[(String, Value)] {
        &self.initial_beliefs
    }
    /// Warnings found while loading (unreachable behaviors, unused bindings).
    pub fn warnings(&self) -> &[Diagnostic] {
        &self.warnings
    }

    /// True when `b` is an individual behavior (`team: false`): each
    /// member ends it on its own and numbers its runs of it at its own
    /// pace, so two members' executions of it with the same epoch need not
    /// be the same lap. False for an id not in this graph (from the
    /// network).
    pub fn is_individual(&self, b: BehaviorId) -> bool {
        self.get(b).is_some_and(|x| !x.team)
    }

    /// The same graph for a team of `n` robots (extra robots anonymous).
    pub fn with_team_size(&self, n: usize) -> BehaviorGraph {
        let mut g = self.clone();
        g.roster = Arc::new(self.roster.resized(n));
        g
    }

    /// True when `b` can run directly under `parent`: it heads one of its
    /// execution chains, or follows one along sequential edges.
    pub fn runs_under(&self, parent: BehaviorId, b: BehaviorId) -> bool {
        self.reached(&self.behavior(parent).children, b)
    }

    /// True when a way of one or more sequential edges leads from `from`
    /// to `to` (along a cycle, `from` leads to itself).
    pub fn leads_to(&self, from: BehaviorId, to: BehaviorId) -> bool {
        match (self.get(from), self.get(to)) {
            (Some(a), Some(_)) => self.reached(&a.next, to),
            _ => false,
        }
    }

    /// True when `to` is one of `starts` or follows one of them along
    /// sequential edges.
    fn reached(&self, starts: &[BehaviorId], to: BehaviorId) -> bool {
        let mut seen = vec![false; self.behaviors.len()];
        let mut todo: Vec<BehaviorId> = starts.to_vec();
        while let Some(x) = todo.pop() {
            if x == to {
                return true;
            }
            if std::mem::replace(&mut seen[x.index()], true) {
                continue;
            }
            todo.extend(self.behavior(x).next.iter().copied());
        }
        false
    }

    /// Synchronization point: two or more sequential successors are team
    /// behaviors.
    pub fn is_sync_point(&self, b: BehaviorId) -> bool {
        self.behavior(b)
            .next
            .iter()
            .filter(|n| self.behavior(**n).team)
            .count()
            >= 2
    }
    /// Allocation point: two or more children.
    pub fn is_alloc_point(&self, b: BehaviorId) -> bool {
        self.behavior(b).children.len() >= 2
    }
    /// Termination point: a team behavior.
    pub fn is_term_point(&self, b: BehaviorId) -> bool {
        self.behavior(b).team
    }
    /// True when `b` is a point of kind `kind`.
    pub fn is_point(&self, b: BehaviorId, kind: Kind) -> bool {
        match kind {
            Kind::Sync => self.is_sync_point(b),
            Kind::Allocate => self.is_alloc_point(b),
            Kind::Terminate => self.is_term_point(b),
        }
    }
    /// The name of a point: its label, or `behavior.kind`.
    pub fn point_name(&self, b: BehaviorId, kind: Kind) -> String {
        let beh = self.behavior(b);
        match beh.label(kind) {
            Some(l) => l.to_string(),
            None => format!("{}.{}", beh.name, kind),
        }
    }
    /// Every coordination point, derived from the graph's structure: for
    /// each behavior in file order, its sync, allocation and termination
    /// points.
    pub fn points(&self) -> Vec<Point> {
        let mut out = Vec::new();
        for b in &self.behaviors {
            for kind in Kind::ALL {
                if self.is_point(b.id, kind) {
                    out.push(Point {
                        behavior: b.id,
                        kind,
                        name: self.point_name(b.id, kind),
                    });
                }
            }
        }
        out
    }
    /// Find a point by label or by `behavior.kind`.
    pub fn find_point(&self, name: &str) -> Option<(BehaviorId, Kind)> {
        for b in &self.behaviors {
            for kind in Kind::ALL {
                if b.label(kind) == Some(name) {
                    return Some((b.id, kind));
                }
            }
        }
        let (beh, kind) = name.rsplit_once('.')?;
        Some((self.find(beh)?, Kind::parse(kind)?))
    }
    /// The binding written on the behavior itself, if any (label-only
    /// bindings included). See `Mission` for how it merges with defaults.
    pub fn own_binding(&self, b: BehaviorId, kind: Kind) -> Option<&Binding> {
        self.behavior(b).bindings[kind.index()].as_deref()
    }
    /// Graph-wide default binding of a kind.
    pub fn default_binding(&self, kind: Kind) -> Option<&Binding> {
        self.defaults[kind.index()].as_ref()
    }
    /// The behaviors that have `b` as a child (its possible parents).
    pub fn parents_of(&self, b: BehaviorId) -> impl Iterator<Item = BehaviorId> + '_ {
        self.behaviors
            .iter()
            .filter(move |p| p.children.contains(&b))
            .map(|p| p.id)
    }
    /// Graphviz DOT of the graph (see [`dot`]).
    pub fn to_dot(&self) -> String {
        dot::to_dot(self)
    }
}

impl fmt::Display for BehaviorGraph {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "graph `{}` ({} behaviors, {} robots, start `{}`)",
            self.name,
            self.behaviors.len(),
            self.roster.len(),
            self.name_of(self.start)
        )
    }
}
