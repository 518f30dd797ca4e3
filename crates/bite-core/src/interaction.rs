//! Social interaction behaviors: the pluggable coordination protocols.
//!
//! BITE's kernel never coordinates by itself. At every synchronization,
//! allocation and termination point it starts an *instance* of the protocol
//! bound to that point and waits for the instance's [`Outcome`]. Protocols
//! are registered by name in a [`Registry`]; the graph and configuration
//! files bind them to points by name, so swapping a protocol is a one-line
//! configuration change.
//!
//! A protocol is a [`Protocol`] (a named, configurable factory) that creates
//! [`Interaction`]s (one per instance). An interaction is a sans-IO state
//! machine: the kernel calls it with a [`Cx`] giving read access to what the
//! robot knows and collecting its effects — messages to send, a timer, the
//! decision. It must be bounded: when its deadline passes the kernel calls
//! [`Interaction::on_deadline`], which must decide from what is known; if it
//! still does not, the kernel applies the silent rule of its kind
//! (first candidate / allocation by id / local termination) and reports a
//! timeout.

use crate::belief::{BeliefStore, Symbols};
use crate::cond::{Expr, Resolver};
use crate::graph::BehaviorGraph;
use crate::ids::{BehaviorId, BeliefId, RobotId};
use crate::ids::{InstanceKey, Kind};
pub use crate::members::{Assignment, ByIdMemo, ChildSlot};
use crate::msg::Body;
use crate::org::{MemberSet, Organization, Team};
use crate::roster::Roster;
use crate::time::Time;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

/// The seeded random generator handed to kernels and protocols.
pub type Rng = rand_chacha::ChaCha8Rng;

/// A kernel's seeded generator, made on its first draw: a ChaCha
/// generator is about 300 bytes, and most robots' protocols never draw (a
/// simulator of 100,000 robots would hold 30 MB of them). The stream is the
/// generator's made at once from the same seed.
#[derive(Clone, Debug)]
pub struct LazyRng {
    seed: u64,
    rng: Option<Box<Rng>>,
}

impl LazyRng {
    /// The generator of `seed`, not made yet.
    pub fn new(seed: u64) -> Self {
        LazyRng { seed, rng: None }
    }

    /// The generator, made now if it was not.
    pub fn get(&mut self) -> &mut Rng {
        use rand::SeedableRng;
        let seed = self.seed;
        self.rng
            .get_or_insert_with(|| Box::new(Rng::seed_from_u64(seed)))
    }
}

/// Protocol parameters as written in a graph or configuration file.
pub use crate::graph::Params;

/// Why a protocol could not be bound with the parameters given
/// ([`Protocol::configure`]). The loader reports it at the binding's
/// file:line:column.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// The parameters do not decode into what the protocol takes.
    #[error("`{protocol}`: {detail}")]
    BadParams {
        /// The protocol.
        protocol: String,
        /// What was wrong, as the decoder says it.
        detail: String,
    },
    /// A parameter the protocol cannot do without is missing.
    #[error("`{protocol}` needs `{param}`: {what}")]
    Missing {
        /// The protocol.
        protocol: String,
        /// The parameter.
        param: String,
        /// What it is, with an example.
        what: String,
    },
    /// Parameters given to a protocol that takes none.
    #[error("`{protocol}` takes no parameters")]
    NoParams {
        /// The protocol.
        protocol: String,
    },
    /// A parameter names a behavior that is not a child of the point.
    #[error("`{name}` is not a child of `{point}` (its children: {children})")]
    NotAChild {
        /// The name given.
        name: String,
        /// The point behavior.
        point: String,
        /// Its children, comma-separated.
        children: String,
    },
    /// An expression in a parameter does not parse.
    #[error("in `{src}`: {detail}")]
    BadExpr {
        /// The expression.
        src: String,
        /// The parser's message.
        detail: String,
    },
    /// An expression in a parameter has the wrong type.
    #[error("`{src}` is a {got}, a {want} is expected")]
    ExprType {
        /// The expression.
        src: String,
        /// Its type.
        got: String,
        /// The type wanted.
        want: String,
    },
    /// Any other reason a protocol refuses its parameters.
    #[error("{0}")]
    Invalid(String),
}

/// `Ok` when `params` is empty (`null` or `{}`): for protocols that take
/// no parameters.
pub fn no_params(name: &str, params: &Params) -> Result<(), ConfigError> {
    match params {
        Params::Null => Ok(()),
        Params::Object(m) if m.is_empty() => Ok(()),
        _ => Err(ConfigError::NoParams {
            protocol: name.to_string(),
        }),
    }
}

/// Creates a fresh instance of a configured protocol.
pub type Factory = Arc<dyn Fn() -> Box<dyn Interaction> + Send + Sync>;

/// A coordination protocol, registered by name.
pub trait Protocol: Send + Sync {
    /// The name used in files (`sync.vote`).
    fn name(&self) -> &'static str;
    /// Other accepted names (the paper's `SF8`).
    fn aliases(&self) -> &'static [&'static str] {
        &[]
    }
    /// Which points it can be bound to.
    fn kind(&self) -> Kind;
    /// Whether it sends messages.
    fn communicates(&self) -> bool;
    /// One line for `bite protocols`.
    fn summary(&self) -> &'static str;
    /// Deadline used when a binding does not give one.
    fn default_deadline(&self) -> Duration {
        Duration::from_secs(5)
    }
    /// Validate `params` (JSON `null` when none are given) and return a
    /// factory of instances configured with them. `setup` knows the point
    /// being bound and compiles expressions written in parameters.
    fn configure(&self, params: &Params, setup: &mut Setup<'_>) -> Result<Factory, ConfigError>;
    /// The file a graph-defined protocol was read from (`None`: written
    /// in Rust).
    fn source(&self) -> Option<&str> {
        None
    }
    /// How many protocols deep an instance runs (1: it uses none; a graph
    /// protocol that uses another is one more than it).
    fn nesting(&self) -> u32 {
        1
    }
    /// The answer to a teammate's late message for an instance this robot
    /// has finished and forgotten (only its outcome is remembered): a
    /// barrier answers a late arrival with its release, a vote answers a
    /// late vote with its result. `None`: no answer.
    fn late_reply(&self, _closed: &Closed, _body: &Body) -> Option<Body> {
        None
    }
}

/// What [`Protocol::configure`] may consult: the graph, the point being
/// bound, and a compiler for expressions written in parameters (their
/// belief names join the graph's symbol table).
pub struct Setup<'a> {
    graph: &'a BehaviorGraph,
    symbols: &'a mut Symbols,
    point: BehaviorId,
    kind: Kind,
}

impl<'a> Setup<'a> {
    /// A setup for binding a protocol at point (`point`, `kind`) of `graph`;
    /// new belief names are interned into `symbols` (a copy of the graph's
    /// table that the caller stores back).
    pub fn new(
        graph: &'a BehaviorGraph,
        symbols: &'a mut Symbols,
        point: BehaviorId,
        kind: Kind,
    ) -> Self {
        Setup {
            graph,
            symbols,
            point,
            kind,
        }
    }
    /// The graph.
    pub fn graph(&self) -> &'a BehaviorGraph {
        self.graph
    }
    /// The point behavior.
    pub fn point(&self) -> BehaviorId {
        self.point
    }
    /// The point's kind.
    pub fn kind(&self) -> Kind {
        self.kind
    }
    /// The behavior called `name` if it is a child of the point (for
    /// parameters that talk about children, e.g. roles).
    pub fn child(&self, name: &str) -> Result<BehaviorId, ConfigError> {
        let children = &self.graph.behavior(self.point).children;
        match self.graph.find(name) {
            Some(b) if children.contains(&b) => Ok(b),
            _ => {
                let names: Vec<&str> = children.iter().map(|c| self.graph.name_of(*c)).collect();
                Err(ConfigError::NotAChild {
                    name: name.to_string(),
                    point: self.graph.name_of(self.point).to_string(),
                    children: names.join(", "),
                })
            }
        }
    }
    /// Compile an expression written in a parameter; `want` is the type it
    /// must have (`"number"` or `"bool"`), if any.
    pub fn expr(&mut self, src: &str, want: Option<&str>) -> Result<Expr, ConfigError> {
        struct R<'s> {
            symbols: &'s mut Symbols,
            graph: &'s BehaviorGraph,
        }
        impl Resolver for R<'_> {
            fn belief(&mut self, name: &str) -> BeliefId {
                self.symbols.intern(name)
            }
            fn behavior(&self, name: &str) -> Option<BehaviorId> {
                self.graph.find(name)
            }
            fn behavior_names(&self) -> Vec<&str> {
                self.graph
                    .behaviors()
                    .iter()
                    .map(|b| b.name.as_str())
                    .collect()
            }
        }
        let mut r = R {
            symbols: self.symbols,
            graph: self.graph,
        };
        let e = Expr::parse(src, &mut r).map_err(|e| ConfigError::BadExpr {
            src: src.to_string(),
            detail: e.to_string(),
        })?;
        if let (Some(want), Some(ty)) = (want, e.static_type())
            && want != ty
        {
            return Err(ConfigError::ExprType {
                src: src.to_string(),
                got: ty.to_string(),
                want: want.to_string(),
            });
        }
        Ok(e)
    }
}

/// Decode typed parameters: `null` gives the defaults; unknown fields and
/// wrong types are errors that say what was expected.
pub fn parse_params<T: serde::de::DeserializeOwned + Default>(
    name: &str,
    params: &Params,
) -> Result<T, ConfigError> {
    if params.is_null() {
        return Ok(T::default());
    }
    serde_json::from_value(params.clone()).map_err(|e| ConfigError::BadParams {
        protocol: name.to_string(),
        detail: e.to_string(),
    })
}

/// How an instance this robot has forgotten ended (what
/// [`Protocol::late_reply`] can rely on).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Closed {
    /// A synchronization that chose this successor (`None`: chain ended).
    Synced(Option<BehaviorId>),
    /// An allocation, with the assignment it applied.
    Allocated(Arc<Assignment>),
    /// A termination, with its replacement behavior if any.
    Terminated(Option<BehaviorId>),
    /// This robot left before the instance decided.
    Left,
}

impl Closed {
    /// The decision applied (`None`: this robot left before it decided).
    pub fn outcome(&self) -> Option<Outcome> {
        match self {
            Closed::Synced(c) => Some(Outcome::Sync(*c)),
            Closed::Allocated(a) => Some(Outcome::Allocate(a.clone())),
            Closed::Terminated(n) => Some(Outcome::Terminate(*n)),
            Closed::Left => None,
        }
    }
}

/// One running protocol instance (see the module documentation).
pub trait Interaction: Send {
    /// The instance begins. For synchronization and allocation this is when
    /// the robot reaches the point; for termination it is when the behavior
    /// starts (the instance is *armed* for the behavior's whole run, so that
    /// teammates can end it, e.g. the first robot to see the goal).
    fn start(&mut self, cx: &mut Cx<'_>);
    /// Termination only: this robot's own reason to end the behavior
    /// happened (`why`). The robot now waits for the decision.
    fn local_done(&mut self, _cx: &mut Cx<'_>, _why: LocalEnd) {}
    /// A message for this instance from teammate `from` (a member of the
    /// team, never this robot, never a duplicate). Also called after the
    /// decision while the instance lingers, so that it can answer
    /// retransmissions idempotently.
    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body);
    /// The timer set with [`Cx::wake_at`] fired.
    fn on_timer(&mut self, _cx: &mut Cx<'_>) {}
    /// The deadline passed without a decision: decide now from what is
    /// known. The kernel reports a timeout either way.
    fn on_deadline(&mut self, cx: &mut Cx<'_>);
    /// A member of the team was presumed lost (or, for protocols that
    /// count on it, left): [`Cx::members`], [`Cx::team_size`] and
    /// [`Cx::leader`] no longer include it. Decide without it: re-check
    /// whether everyone still needed has answered; if the leader changed,
    /// send what the new leader needs (a member re-sends its vote or
    /// arrival; a member that already knows the decision tells it).
    fn on_members_changed(&mut self, _cx: &mut Cx<'_>) {}
    /// Termination only: teammate `from`'s heartbeats have shown it waiting
    /// at this termination point (its own part over) for at least a retry
    /// interval, and no report of its own may have reached this robot (lost
    /// on the way). A protocol whose members report their end to a
    /// coordinator may count it as arrived, as if its report had come; one
    /// that already heard it does nothing. Called on every such heartbeat
    /// while the instance runs, armed or waiting.
    fn on_member_waiting(&mut self, _cx: &mut Cx<'_>, _from: RobotId) {}
    /// The kernel applied the team's decision, `outcome`, to this instance
    /// (a teammate presumed lost told this robot how the team decided
    /// without it: `Body::Missed`). The instance is decided now, as
    /// applied: a protocol that answers teammates or tells a new leader
    /// what it decided answers with this one, and never decides another.
    fn on_team_decision(&mut self, _cx: &mut Cx<'_>, _outcome: &Outcome) {}
    /// This robot leaves the instance before it decided (an ancestor
    /// behavior ended). Tell the teammates what they need to go on without
    /// it (a barrier member reports itself done, a coordinator releases who
    /// waits for it). The instance then lingers: [`Cx::is_aborted`] is true
    /// and [`Interaction::on_message`] may still answer teammates.
    fn on_abort(&mut self, _cx: &mut Cx<'_>) {}
}

/// Why this robot is done with a behavior (what a termination protocol is
/// told in [`Interaction::local_done`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LocalEnd {
    /// Its termination condition held: this robot believes the joint goal
    /// reached (or to be abandoned).
    Condition,
    /// Its part is over: its execution chain under the behavior ended.
    ChainEnded,
    /// It has no part: the behavior's allocation gave it no child.
    Idle,
}

/// What the kernel gives an instance to decide about.
#[derive(Clone, Debug, PartialEq)]
pub enum PointInput {
    /// Choose the next behavior after the point behavior.
    Sync {
        /// Successors whose preconditions hold for this robot, graph order
        /// (the same list as `successors` when they all do).
        candidates: Arc<[BehaviorId]>,
        /// All successors, graph order (shared with the mission).
        successors: Arc<[BehaviorId]>,
    },
    /// Split the team among the point behavior's children.
    Allocate {
        /// Children whose preconditions hold for this robot, graph order
        /// (shared with the mission when they all do).
        children: Arc<[ChildSlot]>,
    },
    /// End the point behavior together.
    Terminate,
}

/// The decision of an instance.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The selected successor (`None`: end of the execution chain).
    Sync(Option<BehaviorId>),
    /// The allocation (shared: the silent rule's is computed once for a
    /// process's robots that see the same team and children).
    Allocate(Arc<Assignment>),
    /// The behavior is over; optionally a new behavior to run under the
    /// same parent.
    Terminate(Option<BehaviorId>),
}

/// Who a message goes to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Recipients {
    /// One teammate.
    One(RobotId),
    /// Every member of the set except the sender (a team multicast: one
    /// message on the air, counted once).
    Team(Arc<MemberSet>),
}

/// Effects an instance produced during one call.
#[derive(Debug, Default)]
pub struct Effects {
    /// Messages to send.
    pub sends: Vec<(Recipients, Body)>,
    /// Earliest requested wake-up.
    pub wake: Option<Time>,
    /// The decision, once taken.
    pub outcome: Option<Outcome>,
    /// Protocol violations noticed in incoming messages (logged, ignored).
    pub violations: Vec<String>,
    /// Push the deadline back by a whole deadline from now (the coordinator
    /// was heard from, so waiting on is not waiting on a dead teammate).
    pub postpone: bool,
    /// Teammates known to be done with the behavior (termination only).
    pub departed: Vec<RobotId>,
}

/// The context of one call into an [`Interaction`].
pub struct Cx<'a> {
    now: Time,
    me: RobotId,
    key: InstanceKey,
    team: &'a Team,
    excluded: Option<&'a MemberSet>,
    lost: Option<&'a MemberSet>,
    given_up: Option<&'a MemberSet>,
    left_ran: &'a [LeftRan],
    live: u32,
    org: &'a Organization,
    runs: &'a crate::belief::RunCounts,
    graph: &'a BehaviorGraph,
    memo: Option<&'a ByIdMemo>,
    roster: &'a Roster,
    beliefs: &'a BeliefStore,
    rng: &'a mut LazyRng,
    input: &'a PointInput,
    retry: Duration,
    deadline: Time,
    decided: bool,
    aborted: bool,
    fx: &'a mut Effects,
}

/// An execution of a point (its team, behavior and epoch) that teammate
/// `.0` had ended when this robot learnt it left a behavior of its own
/// (see [`Cx::left_after_running`]).
pub type LeftRan = (RobotId, crate::ids::TeamId, BehaviorId, u32);

/// Everything needed to build a [`Cx`] (for runtimes and protocol tests).
pub struct CxParts<'a> {
    /// Current time.
    pub now: Time,
    /// This robot.
    pub me: RobotId,
    /// The instance.
    pub key: InstanceKey,
    /// The team running it.
    pub team: &'a Team,
    /// Members left out (presumed lost, or known to have ended an
    /// ancestor of the point): left out of [`Cx::members`].
    pub excluded: Option<&'a MemberSet>,
    /// Of those, the teammates this robot presumes lost now (the others
    /// left on their own: they are done with the behavior).
    pub lost: Option<&'a MemberSet>,
    /// Of those, the ones a deadline of this robot has already decided
    /// without since it presumed them lost (see [`Cx::is_given_up`]).
    pub given_up: Option<&'a MemberSet>,
    /// Executions teammates had ended when this robot learnt they left
    /// the behavior above (see [`Cx::left_after_running`]; empty: none
    /// known).
    pub left_ran: &'a [LeftRan],
    /// This robot's organization hierarchy.
    pub org: &'a Organization,
    /// Run counts of the candidates' parent execution (what `runs` reads).
    pub runs: &'a crate::belief::RunCounts,
    /// The behavior graph.
    pub graph: &'a BehaviorGraph,
    /// The allocations by id the robots of this process share, when the
    /// runtime keeps them (the mission's: see [`Cx::assign_by_id`]).
    pub memo: Option<&'a ByIdMemo>,
    /// The roster.
    pub roster: &'a Roster,
    /// This robot's beliefs.
    pub beliefs: &'a BeliefStore,
    /// This robot's random generator.
    pub rng: &'a mut LazyRng,
    /// What to decide about.
    pub input: &'a PointInput,
    /// Retransmission interval of the binding.
    pub retry: Duration,
    /// When the instance must have decided.
    pub deadline: Time,
    /// Whether the instance already decided (it lingers to answer).
    pub decided: bool,
    /// Whether this robot left the instance before it decided.
    pub aborted: bool,
    /// Where effects go.
    pub fx: &'a mut Effects,
}

impl<'a> Cx<'a> {
    /// Assemble a context.
    pub fn new(p: CxParts<'a>) -> Self {
        Cx {
            now: p.now,
            me: p.me,
            key: p.key,
            team: p.team,
            excluded: p.excluded,
            lost: p.lost,
            given_up: p.given_up,
            left_ran: p.left_ran,
            live: match p.excluded {
                // Word by word: a context is made for every message.
                Some(x) => (p.team.members.len() - p.team.members.count_common(x)) as u32,
                None => p.team.size,
            },
            org: p.org,
            runs: p.runs,
            graph: p.graph,
            memo: p.memo,
            roster: p.roster,
            beliefs: p.beliefs,
            rng: p.rng,
            input: p.input,
            retry: p.retry,
            deadline: p.deadline,
            decided: p.decided,
            aborted: p.aborted,
            fx: p.fx,
        }
    }
    /// Current time.
    pub fn now(&self) -> Time {
        self.now
    }
    /// A context for an instance run *inside* this one (a protocol whose
    /// behavior uses another protocol, e.g. a graph-defined protocol that
    /// falls back to `sync.leader`): the same robot, team, point, beliefs
    /// and deadline, with its own effects (`fx`, which the outer instance
    /// translates: it wraps the inner messages, adopts the inner decision)
    /// and its own `decided` flag.
    pub fn nested<'b>(&'b mut self, fx: &'b mut Effects, decided: bool) -> Cx<'b> {
        Cx {
            now: self.now,
            me: self.me,
            key: self.key,
            team: self.team,
            excluded: self.excluded,
            lost: self.lost,
            given_up: self.given_up,
            left_ran: self.left_ran,
            live: self.live,
            org: self.org,
            runs: self.runs,
            graph: self.graph,
            memo: self.memo,
            roster: self.roster,
            beliefs: self.beliefs,
            rng: &mut *self.rng,
            input: self.input,
            retry: self.retry,
            deadline: self.deadline,
            decided,
            aborted: self.aborted,
            fx,
        }
    }
    /// This robot.
    pub fn me(&self) -> RobotId {
        self.me
    }
    /// The instance.
    pub fn key(&self) -> InstanceKey {
        self.key
    }
    /// The team running the instance.
    pub fn team(&self) -> &Team {
        self.team
    }
    /// Number of members not presumed lost.
    pub fn team_size(&self) -> usize {
        self.live as usize
    }
    /// Members not presumed lost, in id order.
    pub fn members(&self) -> impl Iterator<Item = RobotId> + '_ {
        let excluded = self.excluded;
        self.team
            .members
            .iter()
            .filter(move |r| excluded.is_none_or(|x| !x.contains(*r)))
    }
    /// The allocation by id ([`crate::members::assign_by_id`]) of the
    /// members not presumed lost to `children`. With no member left out,
    /// robots of one process that see the same team and children share one
    /// (10,000 robots splitting among 10,000 children compute it once).
    pub fn assign_by_id(&self, children: &Arc<[ChildSlot]>) -> Arc<Assignment> {
        match (self.excluded, self.memo) {
            (None, Some(m)) => m.assign_by_id(&self.team.members, children),
            _ => Arc::new(crate::members::assign_by_id(&self.live_set(), children)),
        }
    }
    /// The members not presumed lost, as a set.
    pub fn live_set(&self) -> MemberSet {
        match self.excluded {
            None => (*self.team.members).clone(),
            Some(_) => MemberSet::from_iter(self.team.members.roster_len(), self.members()),
        }
    }
    /// True when member `r` is left out because it is presumed lost (not
    /// because it left the behavior: it ended an ancestor, and will never
    /// take part below it again — it is done with the behavior).
    pub fn is_presumed_lost(&self, r: RobotId) -> bool {
        self.team.contains(r)
            && self.excluded.is_some_and(|x| x.contains(r))
            && self.lost.is_none_or(|l| l.contains(r))
    }
    /// True when member `r` is presumed lost and a deadline of this robot
    /// (in a team `r` is in) has already decided without it since: the
    /// team went on without it once, as it will at every deadline while
    /// `r` stays silent. `term.majority` counts the majority of the
    /// members not given up, so that a robot that lost half its subteam
    /// (a crash, or a partition that lasts) pays one deadline, not one at
    /// every barrier. Heard again, `r` counts again.
    pub fn is_given_up(&self, r: RobotId) -> bool {
        // The set first: nearly always empty, and this is asked of every
        // member at every arrival.
        self.given_up.is_some_and(|g| g.contains(r)) && self.is_presumed_lost(r)
    }
    /// True when member `r` is left out because it left the behavior (it
    /// ended an ancestor, or went on past the point), not because it is
    /// presumed lost.
    pub fn has_left(&self, r: RobotId) -> bool {
        self.team.contains(r) && !self.is_live(r) && !self.is_presumed_lost(r)
    }
    /// True when member `r` left the behavior after it ran this instance's
    /// execution (its heartbeat listed the execution as ended when this
    /// robot learnt it left): coordinating it, `r` may have decided, and
    /// its decision may still be on its way here.
    pub fn left_after_running(&self, r: RobotId) -> bool {
        let k = self.key;
        self.has_left(r)
            && (self.left_ran.iter())
                .any(|&(x, t, b, e)| x == r && (t, b, e) == (k.team, k.behavior, k.epoch))
    }
    /// True when `r` is a member not presumed lost.
    pub fn is_live(&self, r: RobotId) -> bool {
        self.team.contains(r) && self.excluded.is_none_or(|x| !x.contains(r))
    }
    /// The coordinator of the instance: the lowest-id member not presumed
    /// lost (this robot if it is the only one left).
    pub fn leader(&self) -> RobotId {
        self.members().next().unwrap_or(self.me)
    }
    /// True when this robot coordinates.
    pub fn is_leader(&self) -> bool {
        self.leader() == self.me
    }
    /// This robot's organization hierarchy.
    pub fn org(&self) -> &Organization {
        self.org
    }
    /// The behavior graph.
    pub fn graph(&self) -> &BehaviorGraph {
        self.graph
    }
    /// The `utility` of behavior `b` for this robot, if it declares one and
    /// it evaluates to a number.
    pub fn utility(&self, b: BehaviorId) -> Option<f64> {
        let u = self.graph.get(b)?.utility.as_ref()?;
        let env = crate::belief::BeliefEnv {
            beliefs: self.beliefs,
            runs: self.runs,
            now: self.now,
            started: self.now,
            own: b,
        };
        u.eval_value(&env)?.as_num().filter(|x| x.is_finite())
    }
    /// Evaluate an expression (e.g. a protocol parameter) over this robot's
    /// beliefs; `None` when a belief it needs is unknown.
    pub fn eval(&self, e: &Expr) -> Option<crate::value::Value> {
        let env = crate::belief::BeliefEnv {
            beliefs: self.beliefs,
            runs: self.runs,
            now: self.now,
            started: self.now,
            own: self.key.behavior,
        };
        e.eval_value(&env)
    }
    /// This robot's preference among `options`, restricted to the
    /// candidates enabled for it: highest utility, ties and behaviors
    /// without utility broken by graph order. `None` if none is enabled.
    pub fn preferred(&self, options: &[BehaviorId]) -> Option<BehaviorId> {
        self.ranking(options).into_iter().next()
    }
    /// This robot's full ranking of the enabled candidates among
    /// `options`, best first (same order as [`Cx::preferred`]).
    pub fn ranking(&self, options: &[BehaviorId]) -> Vec<BehaviorId> {
        let mut ranked: Vec<(usize, Option<f64>, BehaviorId)> = options
            .iter()
            .enumerate()
            .filter(|(_, b)| self.candidates().contains(b))
            .map(|(i, b)| (i, self.utility(*b), *b))
            .collect();
        ranked.sort_by(|a, b| match (a.1, b.1) {
            (Some(x), Some(y)) => y.total_cmp(&x).then(a.0.cmp(&b.0)),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => a.0.cmp(&b.0),
        });
        ranked.into_iter().map(|(_, _, b)| b).collect()
    }
    /// The roster (robot attributes).
    pub fn roster(&self) -> &Roster {
        self.roster
    }
    /// This robot's beliefs.
    pub fn beliefs(&self) -> &BeliefStore {
        self.beliefs
    }
    /// This robot's seeded random generator.
    pub fn rng(&mut self) -> &mut Rng {
        self.rng.get()
    }
    /// What to decide about.
    pub fn input(&self) -> &PointInput {
        self.input
    }
    /// Candidates of a synchronization instance (empty otherwise).
    pub fn candidates(&self) -> &[BehaviorId] {
        match self.input {
            PointInput::Sync { candidates, .. } => candidates,
            _ => &[],
        }
    }
    /// Children of an allocation instance (empty otherwise).
    pub fn children(&self) -> &[ChildSlot] {
        match self.input {
            PointInput::Allocate { children } => children,
            _ => &[],
        }
    }
    /// Retransmission interval.
    pub fn retry(&self) -> Duration {
        self.retry
    }
    /// Deadline of the instance.
    pub fn deadline(&self) -> Time {
        self.deadline
    }
    /// Send `body` to one teammate.
    pub fn send(&mut self, to: RobotId, body: Body) {
        if to != self.me {
            self.fx.sends.push((Recipients::One(to), body));
        }
    }
    /// Send `body` to every other member of the team that the instance
    /// has not left out (teammates presumed lost or known to have left the
    /// behavior above are not told: they take no part, and a lost one that
    /// comes back is told how the instance ended).
    pub fn broadcast(&mut self, body: Body) {
        if self.team.size > 1 {
            let to = match self.excluded {
                Some(x) if !self.team.members.is_disjoint(x) => Arc::new(self.live_set()),
                _ => self.team.members.clone(),
            };
            self.fx.sends.push((Recipients::Team(to), body));
        }
    }
    /// Ask to be called back (`on_timer`) at `t`.
    pub fn wake_at(&mut self, t: Time) {
        self.fx.wake = Some(self.fx.wake.map_or(t, |w| w.min(t)));
    }
    /// Ask to be called back after the retry interval.
    pub fn wake_after_retry(&mut self) {
        let t = self.now + self.retry;
        self.wake_at(t);
    }
    /// Take the decision (the first decision counts; later ones, and any
    /// after the robot left the instance, are ignored).
    pub fn decide(&mut self, outcome: Outcome) {
        if !self.decided && !self.aborted && self.fx.outcome.is_none() {
            self.fx.outcome = Some(outcome);
        }
    }
    /// True when this robot left the instance before it decided (it
    /// lingers only to answer teammates).
    pub fn is_aborted(&self) -> bool {
        self.aborted
    }
    /// Push the deadline back a whole deadline from now: the coordinator is
    /// alive, so waiting on is not waiting on a dead teammate.
    pub fn postpone_deadline(&mut self) {
        self.fx.postpone = true;
    }
    /// Termination only: teammate `r` is done with the behavior (it
    /// arrived at the barrier, or left it). It will take no part in what
    /// this robot still runs below the behavior, so the kernel leaves it out
    /// of those instances, as it does a lost teammate.
    pub fn member_done(&mut self, r: RobotId) {
        if r != self.me && !self.fx.departed.contains(&r) {
            self.fx.departed.push(r);
        }
    }
    /// True once the instance has decided.
    pub fn is_decided(&self) -> bool {
        self.decided || self.fx.outcome.is_some()
    }
    /// Record a protocol violation by a teammate (the message is ignored).
    pub fn violation(&mut self, what: impl Into<String>) {
        self.fx.violations.push(what.into());
    }
}

/// The protocols available to a mission, by name.
#[derive(Clone, Default)]
pub struct Registry {
    protocols: BTreeMap<&'static str, Arc<dyn Protocol>>,
    aliases: BTreeMap<&'static str, &'static str>,
}

impl fmt::Debug for Registry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.protocols.keys()).finish()
    }
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }
    /// Add a protocol (replacing one of the same name).
    pub fn register(&mut self, p: Arc<dyn Protocol>) {
        for a in p.aliases() {
            self.aliases.insert(a, p.name());
        }
        self.protocols.insert(p.name(), p);
    }
    /// Look a protocol up by name or alias.
    pub fn get(&self, name: &str) -> Option<&Arc<dyn Protocol>> {
        self.protocols
            .get(name)
            .or_else(|| self.aliases.get(name).and_then(|n| self.protocols.get(n)))
    }
    /// All protocols in name order.
    pub fn iter(&self) -> impl Iterator<Item = &Arc<dyn Protocol>> {
        self.protocols.values()
    }
    /// All names and aliases (for "did you mean").
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.protocols
            .keys()
            .copied()
            .chain(self.aliases.keys().copied())
    }
    /// The protocol used at a point of kind `kind` when nothing is bound.
    pub fn default_for(kind: Kind) -> &'static str {
        match kind {
            Kind::Sync => "sync.by-rule",
            Kind::Allocate => "alloc.by-id",
            Kind::Terminate => "term.wait-all",
        }
    }
}
