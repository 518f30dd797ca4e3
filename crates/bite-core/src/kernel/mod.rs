//! The BITE control kernel: Algorithm 1 (CONTROL) of the paper, as a
//! sans-IO state machine, one per robot.
//!
//! The runtime drives it with [`Kernel::tick`] (time and percepts),
//! [`Kernel::message`] (a teammate's message) and [`Kernel::timer`], then
//! drains [`Kernel::poll_output`] (messages to send, events) and asks
//! [`Kernel::poll_timeout`] when to call again. The behavior stack G is
//! [`Kernel::stack`]. Nothing here reads a clock, a socket or a random
//! source: time is an argument and randomness a seeded generator.
//!
//! How Algorithm 1 maps onto the phases of the state machine:
//!
//! | Algorithm 1 | here |
//! |---|---|
//! | 1–2 push b0 | `begin` |
//! | 3a–3d expand, `Allocate` at allocation points | `Phase::Expand`, `Phase::Allocating` |
//! | 4a–4c run the stack, first termination pops descendants | `ended_frame` + `end_frame`, checked on every input for *every* frame |
//! | 5–7 pop, `Terminate`, optional new child | `Phase::Terminating` |
//! | 8a–8e choose the next behavior (`Decide` at synchronization points), empty chain terminates the parent | `Phase::Selecting`, `chain_end` |
//! | 9 loop | `advance` |
//!
//! Where Algorithm 1 blocks inside `Allocate`, `Terminate` or `Decide`, the
//! kernel starts a protocol instance and returns; termination conditions of
//! the behaviors still on the stack keep being monitored while it waits, and
//! an ancestor that ends aborts the instance.

use crate::belief::{BeliefEnv, BeliefStore, Source};
use crate::cond::Expr;
use crate::event::{DropReason, EndReason, Event, FrameRef, LogList, OutcomeLog, Via};
use crate::graph::BehaviorGraph;
use crate::ids::{BehaviorId, BeliefId, RobotId, TeamId};
use crate::interaction::{
    Assignment, ChildSlot, Closed, Cx, CxParts, Effects, Interaction, LocalEnd, Outcome,
    PointInput, Recipients, Rng,
};
use crate::mission::Mission;
use crate::msg::{Body, Envelope, InstanceKey, Kind, encoded_len};
use crate::org::{MemberSet, Organization, Split};
use crate::rules;
use crate::time::Time;
use crate::value::Value;
use rand::SeedableRng;
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

mod position;
pub use position::{ALLOC_HEALS, Anchor, Ended, FrameId, FrameState, PosFrame, Position};

/// How long accepted `(sender, seq)` pairs are remembered to drop
/// duplicates (far longer than any network delay; a copy older than this
/// belongs to an instance that is over and is dropped as stale anyway).
const DEDUP_MEMORY: Duration = Duration::from_secs(120);
/// Most `(sender, seq)` pairs remembered per sender.
const DEDUP_PER_SENDER: usize = 4096;
/// Finished instances whose outcome is remembered to answer late teammates.
const TOMBSTONES: usize = 1024;
/// How many instances decided without a lost teammate are remembered per
/// teammate, to tell it how they ended when it comes back.
const MISSED_REMEMBERED: usize = 64;

/// What tells a teammate back from being presumed lost how an instance it
/// missed was decided.
fn missed_body(closed: &Closed) -> Option<Body> {
    match closed {
        Closed::Synced(choice) | Closed::Terminated(choice) => Some(Body::Missed {
            choice: *choice,
            children: Vec::new(),
            members: Vec::new(),
        }),
        Closed::Allocated(a) => match Body::assignment(a) {
            Body::Assignment { children, members } => Some(Body::Missed {
                choice: None,
                children,
                members,
            }),
            _ => None,
        },
        Closed::Left => None,
    }
}

/// Bounds on the work and memory of one kernel.
#[derive(Clone, Debug)]
pub struct Limits {
    /// Transitions processed for one input before yielding.
    pub max_transitions: u32,
    /// Messages buffered for protocol instances not started yet.
    pub max_pending: usize,
    /// How long a buffered message is kept.
    pub pending_ttl: Duration,
}

impl Limits {
    /// Defaults scaled to the team size (a leader may hear from everyone
    /// before it reaches the point).
    pub fn for_team(n: usize) -> Self {
        Limits {
            max_transitions: 512,
            max_pending: 4096.max(4 * n),
            pending_ttl: Duration::from_secs(600),
        }
    }
}

/// One entry of the behavior stack G.
#[derive(Clone, Debug, Serialize)]
pub struct Frame {
    /// The behavior.
    pub behavior: BehaviorId,
    /// The subteam executing it.
    pub team: TeamId,
    /// The team's execution count of it.
    pub epoch: u32,
    /// When this robot started it.
    pub started: Time,
    /// The subteams its allocation created (dissolved when it ends),
    /// shared with the teammates that applied the same allocation.
    #[serde(skip)]
    subteams: Option<Arc<Split>>,
    /// Its allocation round: 0, then one more for every re-allocation
    /// after teammates were lost.
    #[serde(skip)]
    round: u32,
    /// The children its allocation split the team among (a re-allocation
    /// splits the survivors among the same ones, whatever each robot's
    /// preconditions say by then).
    #[serde(skip)]
    allotted: Arc<[ChildSlot]>,
    /// Its termination protocol decided while it was still running here.
    #[serde(skip)]
    team_ended: bool,
    /// It ended by its `urgent` condition: the successor is chosen here,
    /// without the team.
    #[serde(skip)]
    urgent: bool,
    /// Belief and stack versions at which `until` was last found false.
    #[serde(skip)]
    until_false_at: Option<(u64, u64)>,
    /// The control tick during whose period it was pushed.
    #[serde(skip)]
    born: u64,
    /// How many times each behavior has been started directly under this
    /// frame, during this execution of it (what `runs` reads in conditions).
    #[serde(skip)]
    runs: BTreeMap<BehaviorId, u32>,
    /// Teammates known to be done with this behavior: left out of every
    /// instance below it.
    #[serde(skip)]
    departed: Option<MemberSet>,
    /// What it follows: the execution before it in its chain, or the
    /// parent it is the first of a chain under (`None`: b0).
    #[serde(skip)]
    anchor: Option<Anchor>,
    /// Times its allocation was redone because a teammate held another
    /// one (bounded: [`position::ALLOC_HEALS`]).
    #[serde(skip)]
    alloc_heals: u8,
}

impl Frame {
    fn term_key(&self) -> InstanceKey {
        InstanceKey {
            team: self.team,
            behavior: self.behavior,
            kind: Kind::Terminate,
            epoch: self.epoch,
            round: 0,
        }
    }
}

/// Sizes of a kernel's internal tables.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Footprint {
    /// Frames on the stack.
    pub stack: usize,
    /// Protocol instances alive (running or lingering).
    pub instances: usize,
    /// Closed-instance records.
    pub closed: usize,
    /// Buffered early messages.
    pub pending: usize,
    /// Remembered `(sender, seq)` pairs.
    pub seen: usize,
    /// Live teams in the organization.
    pub teams: usize,
}

/// A message to send.
#[derive(Clone, Debug)]
pub struct Outgoing {
    /// Recipients.
    pub to: Recipients,
    /// The message.
    pub envelope: Envelope,
    /// Its encoded size.
    pub bytes: u32,
}

/// What the kernel produces.
#[derive(Clone, Debug)]
pub enum Output {
    /// Send a message.
    Send(Outgoing),
    /// Something happened.
    Event(Event),
}

/// An input from the runtime.
#[derive(Clone, Debug)]
pub enum Input<'a> {
    /// Control tick with fresh percepts.
    Tick {
        /// Belief updates from sensors and skills.
        percepts: &'a [(BeliefId, Value)],
    },
    /// A teammate's message.
    Message(Envelope),
    /// A timer fired (see [`Kernel::poll_timeout`]).
    Timer,
    /// A teammate is presumed lost.
    MemberLost(RobotId),
    /// A teammate presumed lost is heard again.
    MemberBack(RobotId),
    /// A teammate's position, heard with its heartbeat.
    Peer(RobotId, &'a Position),
}

/// Counters of one kernel.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Stats {
    /// Messages sent (a team multicast counts once).
    pub sent: u64,
    /// Bytes sent.
    pub bytes_sent: u64,
    /// Messages received and accepted.
    pub received: u64,
    /// Messages dropped, by reason.
    pub dropped: BTreeMap<DropReason, u64>,
    /// Messages buffered for instances not started yet.
    pub buffered: u64,
    /// Behaviors selected.
    pub selections: u64,
    /// Instances that hit their deadline.
    pub timeouts: u64,
    /// Teammates' positions heard.
    pub positions: u64,
    /// Deadlines re-armed because a teammate waited for was heard still
    /// working on the behavior.
    pub deadlines_rearmed: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Termination instance of a running behavior, before local termination.
    Armed,
    /// Waiting for the decision.
    Active,
    /// Decided; lingers to answer retransmissions.
    Decided,
    /// Left before deciding (an ancestor ended); lingers to answer.
    Aborted,
}

struct Instance {
    protocol: &'static str,
    /// Members presumed lost when it started or since (it decides without
    /// them; a member that comes back joins at the next instance).
    excluded: Option<MemberSet>,
    /// The team as it was when the instance started: the instance can
    /// still answer teammates after this robot dissolved the team.
    team: crate::org::Team,
    /// What it ended with, once over (kept after the outcome is applied).
    closed: Option<Closed>,
    /// The subteams an allocation it decided makes (shared).
    split: Option<Arc<Split>>,
    imp: Box<dyn Interaction>,
    input: PointInput,
    retry: Duration,
    deadline_len: Duration,
    state: State,
    waiting_since: Option<Time>,
    deadline: Time,
    wake: Option<Time>,
    outcome: Option<Outcome>,
    timed_out: bool,
    sent: u32,
    bytes: u64,
    received: u32,
}

impl Instance {
    /// The team's members it decides without, in id order.
    fn excluded_members(&self) -> Vec<RobotId> {
        self.excluded
            .as_ref()
            .map(|x| x.iter().filter(|r| self.team.contains(*r)).collect())
            .unwrap_or_default()
    }
}

#[derive(Debug)]
enum Phase {
    NotStarted,
    /// The top frame must be expanded (Algorithm 1, line 3).
    Expand,
    /// The top frame has no enabled child; re-checked when beliefs change.
    WaitChild {
        seen: (u64, u64),
    },
    /// Waiting for the allocation at the top frame.
    Allocating(InstanceKey),
    /// The leaf is atomic and runs.
    Run,
    /// The top frame allocated its children and gave this robot none: it
    /// idles under it until it ends (by its condition or by its team), or,
    /// with a silent termination protocol, until its next tick.
    Idle {
        since: u64,
        silent: bool,
    },
    /// `frame` was popped; waiting for its termination protocol.
    Terminating {
        frame: Frame,
        key: Option<InstanceKey>,
    },
    /// `frame` ended; choosing its successor.
    Selecting {
        frame: Frame,
        key: Option<InstanceKey>,
    },
    /// The stack emptied.
    Finished,
}

/// A buffered message for an instance not started yet.
struct Pending {
    at: Time,
    from: RobotId,
    body: Body,
}

/// The control kernel of one robot.
pub struct Kernel {
    mission: Arc<Mission>,
    me: RobotId,
    beliefs: BeliefStore,
    org: Organization,
    rng: Rng,
    stack: Vec<Frame>,
    phase: Phase,
    instances: BTreeMap<InstanceKey, Instance>,
    /// Highest epoch known to be over, per (team, behavior, kind).
    closed: BTreeMap<(TeamId, BehaviorId, Kind), (u32, u32)>,
    pending: BTreeMap<InstanceKey, Vec<Pending>>,
    /// Teammates presumed lost (reported by the runtime).
    lost: MemberSet,
    /// Instances decided without a teammate presumed lost, per teammate:
    /// when it comes back it is told how they ended (it may be waiting in
    /// one, or running below a behavior its team ended meanwhile).
    missed: BTreeMap<RobotId, VecDeque<InstanceKey>>,
    /// Teammates presumed lost at some point of the mission.
    ever_lost: MemberSet,
    /// Outcomes of forgotten instances, to answer late teammates.
    tombstones: BTreeMap<InstanceKey, Closed>,
    tomb_order: VecDeque<InstanceKey>,
    pending_len: usize,
    /// Recently accepted `(sender, seq)` with when: a message is acted upon
    /// at most once, whatever the order it arrives in.
    seen: BTreeMap<RobotId, BTreeMap<u64, Time>>,
    next_seq: u64,
    out: VecDeque<Output>,
    now: Time,
    stack_version: u64,
    /// Control ticks handled so far.
    ticks: u64,
    /// Whether the input being handled is a control tick.
    in_tick: bool,
    /// Run counts of the top-level execution chain (behaviors with no parent frame).
    root_runs: BTreeMap<BehaviorId, u32>,
    next_due: Option<Time>,
    gc_at: Time,
    limits: Limits,
    stats: Stats,
    /// Executions this robot ended recently (for its heartbeats).
    recent_ended: VecDeque<Ended>,
    /// Executions burned recently, here or by teammates.
    recent_burned: VecDeque<FrameId>,
    /// Splits this robot, as healing leader, has already recorded.
    splits_seen: std::collections::BTreeSet<(RobotId, FrameId)>,
    /// A restarted process: since when it waits to hear where its team is.
    rejoin_since: Option<Time>,
    /// The executions each teammate is engaged in (its position's frames),
    /// from its last heartbeat, and when it was heard.
    peers: BTreeMap<RobotId, (Time, Vec<(FrameId, FrameState)>)>,
    /// When each teammate's position last changed (it makes progress).
    peer_moved: BTreeMap<RobotId, Time>,
}

impl Kernel {
    /// A kernel for robot `me` of the mission's roster, seeded with `seed`.
    pub fn new(mission: Arc<Mission>, me: RobotId, seed: u64) -> Self {
        let n = mission.graph().roster().len();
        Self::with_root(mission, me, seed, Arc::new(MemberSet::all(n)))
    }

    /// Like [`Kernel::new`], sharing the root team's member set (a simulator
    /// running thousands of kernels stores it once).
    pub fn with_root(mission: Arc<Mission>, me: RobotId, seed: u64, root: Arc<MemberSet>) -> Self {
        let graph = mission.graph().clone();
        let n = graph.roster().len();
        Kernel {
            beliefs: BeliefStore::new(graph.symbols().clone()),
            org: Organization::with_root(root),
            rng: Rng::seed_from_u64(seed),
            me,
            mission,
            stack: Vec::new(),
            phase: Phase::NotStarted,
            instances: BTreeMap::new(),
            closed: BTreeMap::new(),
            pending: BTreeMap::new(),
            lost: MemberSet::empty(n),
            missed: BTreeMap::new(),
            ever_lost: MemberSet::empty(n),
            tombstones: BTreeMap::new(),
            tomb_order: VecDeque::new(),
            pending_len: 0,
            seen: BTreeMap::new(),
            next_seq: 1,
            out: VecDeque::new(),
            now: Time::ZERO,
            stack_version: 0,
            ticks: 0,
            in_tick: false,
            root_runs: BTreeMap::new(),
            next_due: None,
            gc_at: Time::ZERO,
            limits: Limits::for_team(n),
            stats: Stats::default(),
            recent_ended: VecDeque::new(),
            recent_burned: VecDeque::new(),
            splits_seen: std::collections::BTreeSet::new(),
            rejoin_since: None,
            peers: BTreeMap::new(),
            peer_moved: BTreeMap::new(),
        }
    }

    /// Replace the limits.
    pub fn set_limits(&mut self, limits: Limits) {
        self.limits = limits;
    }

    /// Number this kernel's messages from `first` on (a restarted process
    /// passes the time in microseconds, so that it never reuses a sequence
    /// number its previous incarnation sent: teammates would drop them as
    /// duplicates).
    pub fn set_first_seq(&mut self, first: u64) {
        self.next_seq = self.next_seq.max(first).max(1);
    }

    // ----- inputs -------------------------------------------------------

    /// Handle one input at time `now`.
    pub fn handle(&mut self, now: Time, input: Input<'_>) {
        match input {
            Input::Tick { percepts } => self.tick(now, percepts),
            Input::Message(env) => self.message(now, env),
            Input::Timer => self.timer(now),
            Input::MemberLost(r) => self.member_lost(now, r),
            Input::MemberBack(r) => self.member_back(now, r),
            Input::Peer(r, pos) => self.peer(now, r, pos),
        }
    }

    /// Record percepts without acting on them yet: the world model looks at
    /// the beliefs they make before the next [`tick`](Kernel::tick) acts.
    pub fn observe(&mut self, now: Time, percepts: &[(BeliefId, Value)]) {
        self.set_now(now);
        for (id, v) in percepts {
            self.beliefs.set(*id, v.clone(), self.now, Source::Percept);
        }
    }

    /// A control tick: record percepts, fire due timers, run Algorithm 1
    /// until it must wait.
    pub fn tick(&mut self, now: Time, percepts: &[(BeliefId, Value)]) {
        self.observe(now, percepts);
        self.ticks += 1;
        self.in_tick = true;
        self.step();
        self.in_tick = false;
    }

    /// A teammate's message.
    pub fn message(&mut self, now: Time, env: Envelope) {
        self.set_now(now);
        if matches!(self.phase, Phase::NotStarted) && !self.awaiting_rejoin() {
            self.begin();
        }
        self.route(env);
        self.step();
    }

    /// A timer fired.
    pub fn timer(&mut self, now: Time) {
        self.set_now(now);
        self.step();
    }

    /// The runtime presumes teammate `r` lost (no heartbeat for longer than
    /// its bound). Running protocol instances decide without it from now on.
    pub fn member_lost(&mut self, now: Time, r: RobotId) {
        self.set_now(now);
        if r == self.me || !self.lost.insert(r) {
            return;
        }
        self.ever_lost.insert(r);
        self.emit(Event::MemberLost { member: r });
        let affected: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| {
                i.team.contains(r)
                    && (matches!(i.state, State::Armed | State::Active) || i.wake.is_some())
            })
            .map(|(k, _)| *k)
            .collect();
        for k in affected {
            self.exclude(k, &[r]);
        }
        // Children left without enough live members are re-allocated.
        if !matches!(self.phase, Phase::NotStarted | Phase::Finished)
            && let Some(i) = self.orphaned_frame()
        {
            let round = self.stack[i].round + 1;
            self.reallocate(i, round, &[]);
        }
        self.refresh_due();
        self.step();
    }

    /// The runtime hears teammate `r` again. It takes part again from the
    /// next protocol instance on (running ones go on without it).
    pub fn member_back(&mut self, now: Time, r: RobotId) {
        self.set_now(now);
        if self.lost.contains(r) {
            self.lost.remove(r);
            self.emit(Event::MemberBack { member: r });
            // Tell it how what it missed was decided: it may be waiting in
            // one of those instances, or running below a behavior its team
            // ended meanwhile, or lead a protocol its team has moved past.
            for key in self.missed.remove(&r).unwrap_or_default() {
                let closed = self
                    .instances
                    .get(&key)
                    .and_then(|i| i.closed.clone())
                    .or_else(|| self.tombstones.get(&key).cloned());
                if let Some(body) = closed.as_ref().and_then(missed_body) {
                    self.reply(key, r, body);
                }
            }
            // Barriers armed but not started take part it again (a member
            // lost once is not left out of its ancestors' terminations for
            // the rest of the mission).
            let departed = self
                .stack
                .iter()
                .any(|f| f.departed.as_ref().is_some_and(|d| d.contains(r)));
            for inst in self.instances.values_mut() {
                if inst.state == State::Armed
                    && !departed
                    && let Some(x) = &mut inst.excluded
                {
                    x.remove(r);
                }
            }
        }
        self.step();
    }

    /// Teammates currently presumed lost.
    pub fn lost(&self) -> &MemberSet {
        &self.lost
    }

    /// Set a belief from outside the tick (e.g. the world model relaying a
    /// teammate's report). Takes effect at the next input.
    pub fn set_belief(&mut self, id: BeliefId, value: Value, source: Source) -> bool {
        self.beliefs.set(id, value, self.now, source)
    }

    fn set_now(&mut self, now: Time) {
        // Time never goes backwards inside the kernel, whatever the runtime does.
        self.now = self.now.max(now);
    }

    fn step(&mut self) {
        if self.next_due.is_some_and(|t| t <= self.now) {
            self.fire_timers();
        }
        self.advance();
        if self.now >= self.gc_at {
            self.gc();
            self.gc_at = self.now + Duration::from_secs(1);
        }
    }

    // ----- outputs ------------------------------------------------------

    /// The next output, if any.
    pub fn poll_output(&mut self) -> Option<Output> {
        self.out.pop_front()
    }
    /// When the kernel next needs a [`Kernel::timer`] call.
    pub fn poll_timeout(&self) -> Option<Time> {
        self.next_due
    }
    /// The behavior stack G, root first.
    pub fn stack(&self) -> &[Frame] {
        &self.stack
    }
    /// The leaf of the stack (the behavior whose skill runs).
    pub fn leaf(&self) -> Option<&Frame> {
        self.stack.last()
    }
    /// Incremented by every push and pop.
    pub fn stack_version(&self) -> u64 {
        self.stack_version
    }
    /// True once the mission is over for this robot.
    pub fn is_finished(&self) -> bool {
        matches!(self.phase, Phase::Finished)
    }
    /// True while the robot waits for a protocol decision.
    pub fn is_interacting(&self) -> bool {
        match &self.phase {
            Phase::Allocating(_) => true,
            Phase::Terminating { key, .. } | Phase::Selecting { key, .. } => key.is_some(),
            _ => false,
        }
    }
    /// A short name of what the kernel is doing.
    pub fn phase_name(&self) -> &'static str {
        match self.phase {
            Phase::NotStarted => "not-started",
            Phase::Expand => "expanding",
            Phase::WaitChild { .. } => "waiting-for-child",
            Phase::Allocating(_) => "allocating",
            Phase::Run => "running",
            Phase::Idle { .. } => "idle",
            Phase::Terminating { .. } => "terminating",
            Phase::Selecting { .. } => "selecting",
            Phase::Finished => "finished",
        }
    }
    /// This robot.
    pub fn me(&self) -> RobotId {
        self.me
    }
    /// Its beliefs.
    pub fn beliefs(&self) -> &BeliefStore {
        &self.beliefs
    }
    /// Its copy of the organization hierarchy.
    pub fn org(&self) -> &Organization {
        &self.org
    }
    /// Its counters.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
    /// Sizes of its internal tables (to check that memory stays bounded
    /// over long missions).
    pub fn footprint(&self) -> Footprint {
        Footprint {
            stack: self.stack.len(),
            instances: self.instances.len(),
            closed: self.closed.len(),
            pending: self.pending_len,
            seen: self.seen.values().map(BTreeMap::len).sum(),
            teams: self.org.teams().count(),
        }
    }
    /// The mission.
    pub fn mission(&self) -> &Arc<Mission> {
        &self.mission
    }
    /// Current kernel time.
    pub fn now(&self) -> Time {
        self.now
    }

    fn emit(&mut self, e: Event) {
        self.out.push_back(Output::Event(e));
    }

    // ----- Algorithm 1 --------------------------------------------------

    fn graph(&self) -> &BehaviorGraph {
        self.mission.graph()
    }

    /// Lines 1–2: push b0 for the whole team.
    fn begin(&mut self) {
        let graph = self.mission.graph().clone();
        for (name, v) in graph.initial_beliefs() {
            self.beliefs
                .set_named(name, v.clone(), self.now, Source::Given);
        }
        self.push(graph.start(), TeamId::ROOT, Via::Start, None);
    }

    fn versions(&self) -> (u64, u64) {
        (self.beliefs.version(), self.stack_version)
    }

    /// Run transitions until the kernel must wait for an input.
    fn advance(&mut self) {
        for _ in 0..self.limits.max_transitions {
            if !matches!(self.phase, Phase::NotStarted | Phase::Finished)
                && let Some((i, reason)) = self.ended_frame()
            {
                self.end_frame(i, reason);
                continue;
            }
            let progressed = match &self.phase {
                Phase::NotStarted if self.awaiting_rejoin() => false,
                Phase::NotStarted => {
                    self.begin();
                    true
                }
                Phase::Finished | Phase::Run => false,
                Phase::Idle { since, silent } => {
                    // With a silent termination protocol nobody will tell
                    // this robot when the others are done: its empty part is
                    // over, and it ends it at its next tick (never within the
                    // same tick, so a cycle back here cannot spin).
                    if *silent && self.in_tick && self.ticks > *since {
                        let i = self.stack.len() - 1;
                        self.phase = Phase::Run;
                        self.end_frame(i, EndReason::ChainEnded);
                        true
                    } else {
                        false
                    }
                }
                Phase::Expand => self.expand(),
                Phase::WaitChild { seen } => {
                    if *seen == self.versions() && !self.children_pre_timed() {
                        false
                    } else if self.enabled_children().is_empty() {
                        self.phase = Phase::WaitChild {
                            seen: self.versions(),
                        };
                        false
                    } else {
                        self.phase = Phase::Expand;
                        true
                    }
                }
                Phase::Allocating(key) => {
                    let key = *key;
                    self.finish_allocation(key)
                }
                Phase::Terminating { .. } => self.finish_termination(),
                Phase::Selecting { .. } => self.select(),
            };
            if !progressed {
                return;
            }
        }
        self.emit(Event::TransitionLimit);
    }

    /// Line 4: the root-most frame that must end — its termination
    /// condition holds, or its team ended it.
    fn ended_frame(&mut self) -> Option<(usize, EndReason)> {
        let vers = self.versions();
        let graph = self.mission.graph();
        for i in 0..self.stack.len() {
            let f = &self.stack[i];
            if f.team_ended {
                return Some((i, EndReason::Team));
            }
            // Termination conditions are about the world: they are
            // monitored on control ticks (Algorithm 1's execution loop), and
            // a behavior's condition is first checked at the tick after it
            // started, once the runtime has started its skill and reported
            // fresh percepts. Team decisions (above) act on any input.
            if !self.in_tick || f.born == self.ticks {
                continue;
            }
            let beh = graph.behavior(f.behavior);
            if beh.until.is_none() && beh.urgent.is_none() {
                continue;
            }
            let timed = beh
                .until
                .iter()
                .chain(&beh.urgent)
                .any(|e| e.depends_on_time());
            if !timed && f.until_false_at == Some(vers) {
                continue;
            }
            let runs = match i {
                0 => &self.root_runs,
                _ => &self.stack[i - 1].runs,
            };
            let env = BeliefEnv {
                beliefs: &self.beliefs,
                runs,
                now: self.now,
                started: f.started,
                own: f.behavior,
            };
            if let Some(urgent) = &beh.urgent
                && urgent.eval(&env)
            {
                let e = self.condition_event(f.behavior, "urgent", urgent);
                self.out.push_back(Output::Event(e));
                return Some((i, EndReason::Urgent));
            }
            if let Some(until) = &beh.until
                && until.eval(&env)
            {
                let e = self.condition_event(f.behavior, "until", until);
                self.out.push_back(Output::Event(e));
                return Some((i, EndReason::Until));
            }
            self.stack[i].until_false_at = Some(vers);
        }
        None
    }

    fn condition_event(&self, behavior: BehaviorId, field: &'static str, e: &Expr) -> Event {
        let sym = self.beliefs.symbols();
        Event::ConditionHeld {
            behavior,
            field,
            beliefs: e
                .beliefs()
                .iter()
                .map(|id| (sym.name(*id).to_string(), self.beliefs.value(*id).cloned()))
                .collect(),
        }
    }

    /// Lines 4b–6: pop the descendants of frame `i` and `i` itself, and
    /// start its synchronized termination.
    fn end_frame(&mut self, i: usize, reason: EndReason) {
        self.abort_phase();
        let ended = self.stack[i].behavior;
        while self.stack.len() > i + 1 {
            if let Some(f) = self.stack.pop() {
                self.abort(f.term_key());
                self.retire(&f, EndReason::Ancestor(ended));
            }
        }
        let Some(frame) = self.stack.pop() else {
            return;
        };
        self.retire(&frame, reason);
        let key = frame.term_key();
        let why = match reason {
            EndReason::Until | EndReason::Urgent => LocalEnd::Condition,
            _ => LocalEnd::ChainEnded,
        };
        let key = if self.instances.contains_key(&key) {
            self.term_local_done(key, why);
            Some(key)
        } else {
            None
        };
        if reason == EndReason::Urgent {
            // Preemption: the termination protocol has been told (it goes on
            // answering teammates), but this robot does not wait for it,
            // nor for its team to choose the successor.
            let mut frame = frame;
            frame.urgent = true;
            self.phase = Phase::Selecting { frame, key: None };
            return;
        }
        self.phase = Phase::Terminating { frame, key };
    }

    /// Bookkeeping for a popped frame: links, subteams, event.
    fn retire(&mut self, f: &Frame, reason: EndReason) {
        self.stack_version += 1;
        if reason != EndReason::Converged {
            let parent = self.stack.last().map(Frame::id);
            self.note_ended(f.id(), parent);
        }
        self.org.unlink(f.behavior, f.team);
        self.dissolve(f.subteams.as_ref());
        self.emit(Event::Terminated {
            behavior: f.behavior,
            team: f.team,
            epoch: f.epoch,
            reason,
        });
    }

    /// Dissolve subteams an allocation created.
    fn dissolve(&mut self, gone: Option<&Arc<Split>>) {
        let Some(gone) = gone else {
            return;
        };
        self.org.dissolve_split(gone);
        // Late messages for dissolved teams are recognised by the
        // organization's memory of dead teams; the per-instance records can
        // go (a repeated allocation would otherwise grow them forever).
        self.closed.retain(|(t, _, _), _| !gone.contains(*t));
    }

    /// A child of the allocation at a frame on the stack that lost
    /// teammates and has fewer live members than it needs: the frame.
    fn orphaned_frame(&self) -> Option<usize> {
        let graph = self.mission.graph();
        // A lost teammate that had already finished the behavior (arrived at
        // its barrier or an ancestor's) leaves nothing to re-allocate.
        let mut done: Option<MemberSet> = None;
        self.stack.iter().position(|f| {
            if let Some(d) = &f.departed {
                done.get_or_insert_with(|| MemberSet::empty(d.roster_len()))
                    .union_with(d);
            }
            let done = done.as_ref();
            let Some(split) = &f.subteams else {
                return false;
            };
            split.subteams().any(|(child, team)| {
                let live = team
                    .members
                    .iter()
                    .filter(|r| !self.lost.contains(*r) || done.is_some_and(|d| d.contains(*r)))
                    .count();
                let min = graph.behavior(child).members.0.max(1) as usize;
                live < team.size as usize && live < min
            })
        })
    }

    /// Re-allocate the children of frame `i` among the teammates still
    /// under it (its allocation protocol decides, in a new round): what
    /// runs below it ends, its subteams dissolve, and it expands again.
    /// `told` are the teammates the robot that started the round left out
    /// (this robot leaves them out too, presumed lost or not).
    fn reallocate(&mut self, i: usize, round: u32, told: &[RobotId]) {
        self.abort_phase();
        let b = self.stack[i].behavior;
        while self.stack.len() > i + 1 {
            if let Some(f) = self.stack.pop() {
                self.abort(f.term_key());
                self.retire(&f, EndReason::Reallocation(b));
            }
        }
        let gone = self.stack[i].subteams.take();
        self.dissolve(gone.as_ref());
        let f = &mut self.stack[i];
        f.round = round;
        let (team, epoch) = (f.team, f.epoch);
        let children = f.allotted.clone();
        self.stack_version += 1;
        self.emit(Event::Reallocating {
            behavior: b,
            team,
            epoch,
            round,
        });
        let key = self.start_allocation((team, b, epoch, round), children, told);
        // Tell the team, so that teammates that have not noticed the loss
        // join, and those that left the point say so at once.
        if let Some(inst) = self.instances.get(&key)
            && inst.team.size > 1
        {
            let lost = inst.excluded_members();
            let to = Recipients::Team(inst.team.members.clone());
            self.send_outside(key, to, Body::Reallocate { lost });
        }
    }

    /// An ancestor ended while an interaction was in flight: abandon it.
    fn abort_phase(&mut self) {
        self.abort_phase_with(true);
    }

    /// Abandon the interaction in flight without telling the team (its
    /// execution is being burned).
    fn abort_phase_quietly(&mut self) {
        self.abort_phase_with(false);
    }

    fn abort_phase_with(&mut self, tell: bool) {
        match std::mem::replace(&mut self.phase, Phase::Run) {
            Phase::Allocating(k) => self.abort_with(k, tell),
            Phase::Terminating { key: Some(k), .. } | Phase::Selecting { key: Some(k), .. } => {
                self.abort_with(k, tell)
            }
            _ => {}
        }
    }

    fn abort(&mut self, key: InstanceKey) {
        self.abort_with(key, true);
    }

    fn abort_quietly(&mut self, key: InstanceKey) {
        self.abort_with(key, false);
    }

    /// Leave instance `key` before it decided; `tell`: let the protocol tell
    /// the teammates what they need to go on without this robot.
    fn abort_with(&mut self, key: InstanceKey, tell: bool) {
        let Some(inst) = self.instances.get_mut(&key) else {
            return;
        };
        match inst.state {
            State::Decided => {
                // Keep it lingering to answer teammates, but let it be collected.
                inst.outcome = None;
                return;
            }
            State::Aborted => return,
            State::Armed | State::Active => {}
        }
        let protocol = inst.protocol;
        let announced = inst.state == State::Active;
        // Let the protocol tell its teammates, then keep it lingering so
        // that it can answer them (a barrier leader that leaves releases
        // whoever arrives later).
        if tell {
            self.call(key, |imp, cx| imp.on_abort(cx));
        }
        if let Some(inst) = self.instances.get_mut(&key) {
            inst.state = State::Aborted;
            inst.wake = None;
            inst.outcome = None;
            inst.closed = Some(Closed::Left);
        }
        self.close(key);
        if announced {
            self.emit(Event::InteractionAborted {
                instance: key,
                protocol,
            });
        }
    }

    fn close(&mut self, key: InstanceKey) {
        self.mark_closed(key);
        self.drop_pending(key);
    }

    /// Remember that `key` and every earlier instance at its point are over.
    fn mark_closed(&mut self, key: InstanceKey) {
        let e = self
            .closed
            .entry((key.team, key.behavior, key.kind))
            .or_insert((0, 0));
        *e = (*e).max(key.stamp());
    }

    /// Push `b` for `team`, arming its termination protocol if it is a team
    /// behavior.
    /// `after`: the execution before it in its chain (`None`: the first
    /// of a chain under the top frame).
    fn push(&mut self, b: BehaviorId, team: TeamId, via: Via, after: Option<(BehaviorId, u32)>) {
        let anchor = match after {
            Some((behavior, epoch)) => Some(Anchor {
                behavior,
                epoch,
                first: false,
            }),
            None => self.stack.last().map(|p| Anchor {
                behavior: p.behavior,
                epoch: p.epoch,
                first: true,
            }),
        };
        self.push_anchored(b, team, via, anchor);
    }

    fn push_anchored(&mut self, b: BehaviorId, team: TeamId, via: Via, anchor: Option<Anchor>) {
        let parent_runs = match self.stack.last_mut() {
            Some(p) => &mut p.runs,
            None => &mut self.root_runs,
        };
        *parent_runs.entry(b).or_insert(0) += 1;
        let epoch = self.org.start_run(team, b);
        self.org.link(b, team);
        let depth = self.stack.len() as u32;
        self.stack.push(Frame {
            behavior: b,
            team,
            epoch,
            started: self.now,
            subteams: None,
            round: 0,
            allotted: Arc::default(),
            team_ended: false,
            urgent: false,
            until_false_at: None,
            born: self.ticks,
            runs: BTreeMap::new(),
            departed: None,
            anchor,
            alloc_heals: 0,
        });
        self.stack_version += 1;
        self.stats.selections += 1;
        let after = anchor.filter(|a| !a.first).map(|a| FrameRef {
            behavior: a.behavior,
            epoch: a.epoch,
        });
        self.emit(Event::Selected {
            behavior: b,
            team,
            epoch,
            depth,
            via,
            after,
        });
        if self.graph().is_term_point(b) {
            let key = InstanceKey {
                team,
                behavior: b,
                kind: Kind::Terminate,
                epoch,
                round: 0,
            };
            self.start_instance(key, PointInput::Terminate, &[]);
        }
        self.phase = Phase::Expand;
    }

    /// True when a precondition of the top frame's children can change
    /// with time alone (`elapsed`, `age`): re-check on every input.
    fn children_pre_timed(&self) -> bool {
        let Some(top) = self.stack.last() else {
            return false;
        };
        let graph = self.mission.graph();
        graph.behavior(top.behavior).children.iter().any(|c| {
            graph
                .behavior(*c)
                .pre
                .as_ref()
                .is_some_and(Expr::depends_on_time)
        })
    }

    /// The children of the top frame whose preconditions hold, in graph
    /// order (shared with the mission when they all do).
    fn enabled_children(&self) -> Arc<[ChildSlot]> {
        let Some(top) = self.stack.last() else {
            return Arc::default();
        };
        let graph = self.mission.graph();
        let Some(all) = self.mission.child_slots_shared(top.behavior) else {
            return Arc::default();
        };
        if self.mission.children_unconditional(top.behavior) {
            return all.clone();
        }
        match all.iter().position(|c| !self.pre_holds(graph, c.behavior)) {
            None => all.clone(),
            Some(first) => all[..first]
                .iter()
                .chain(
                    all[first + 1..]
                        .iter()
                        .filter(|c| self.pre_holds(graph, c.behavior)),
                )
                .copied()
                .collect(),
        }
    }

    /// Precondition of `b`, a candidate to run directly under the current
    /// top of the stack.
    fn pre_holds(&self, graph: &BehaviorGraph, b: BehaviorId) -> bool {
        graph.behavior(b).pre.as_ref().is_none_or(|pre| {
            pre.eval(&BeliefEnv {
                beliefs: &self.beliefs,
                runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
                now: self.now,
                started: self.now,
                own: b,
            })
        })
    }

    /// Line 3: expand the top frame.
    fn expand(&mut self) -> bool {
        let Some(top) = self.stack.last() else {
            self.phase = Phase::Finished;
            return false;
        };
        let (b, team, epoch, round) = (top.behavior, top.team, top.epoch, top.round);
        if self.graph().behavior(b).is_atomic() {
            self.phase = Phase::Run;
            return false;
        }
        let enabled = self.enabled_children();
        if enabled.is_empty() {
            self.emit(Event::WaitingForChild { behavior: b });
            self.phase = Phase::WaitChild {
                seen: self.versions(),
            };
            return false;
        }
        if self.graph().is_alloc_point(b) {
            if let Some(top) = self.stack.last_mut() {
                top.allotted = enabled.clone();
            }
            self.start_allocation((team, b, epoch, round), enabled, &[]);
            return true;
        }
        self.push(enabled[0].behavior, team, Via::Expansion, None);
        true
    }

    /// Line 3c: allocate the children of the top frame (`team`, `b`,
    /// `epoch`), in allocation round `round`, leaving `told` out.
    fn start_allocation(
        &mut self,
        (team, b, epoch, round): (TeamId, BehaviorId, u32, u32),
        children: Arc<[ChildSlot]>,
        told: &[RobotId],
    ) -> InstanceKey {
        let key = InstanceKey {
            team,
            behavior: b,
            kind: Kind::Allocate,
            epoch,
            round,
        };
        self.phase = Phase::Allocating(key);
        self.start_instance(key, PointInput::Allocate { children }, told);
        key
    }

    /// Line 3c continued: apply the allocation once decided.
    fn finish_allocation(&mut self, key: InstanceKey) -> bool {
        let Some(outcome) = self.take_outcome(key) else {
            return false;
        };
        let Outcome::Allocate(asg) = outcome else {
            return false;
        };
        let (b, team, epoch) = (key.behavior, key.team, key.epoch);
        // The subteams, shared with every teammate of this process that
        // applied the same allocation (made when it was decided).
        let split = match self.instances.get(&key).and_then(|i| i.split.clone()) {
            Some(s) => s,
            None => self.mission.split(team, b, key.stamp(), asg),
        };
        self.org.add_split(split.clone());
        let mine = split.subteam_of(self.me).map(|(child, t)| (child, t.id));
        if let Some(top) = self.stack.last_mut() {
            top.subteams = Some(split);
        }
        match mine {
            Some((child, tid)) => self.push(child, tid, Via::Allocation, None),
            None => {
                // No place for this robot: its part of the allocating
                // behavior is empty. It idles under it until the behavior
                // ends — by its own condition, or by its team (a
                // communicating termination protocol is told at once that
                // this robot's part is over, so barriers do not wait for
                // it). With a silent protocol it ends its part at its next
                // tick (see `Phase::Idle`).
                self.emit(Event::Unassigned { behavior: b });
                let key = InstanceKey {
                    team,
                    behavior: b,
                    kind: Kind::Terminate,
                    epoch,
                    round: 0,
                };
                let communicates = self
                    .mission
                    .bound(b, Kind::Terminate)
                    .is_some_and(|x| x.protocol.communicates());
                self.phase = Phase::Idle {
                    since: self.ticks,
                    silent: !communicates,
                };
                if communicates {
                    self.term_local_done(key, LocalEnd::Idle);
                }
            }
        }
        true
    }

    /// Lines 6–7: once the termination protocol decided, run its
    /// replacement behavior or go on to select a successor.
    fn finish_termination(&mut self) -> bool {
        let Phase::Terminating { key, .. } = &self.phase else {
            return false;
        };
        let outcome = match *key {
            None => Outcome::Terminate(None),
            Some(k) => match self.take_outcome(k) {
                Some(o) => o,
                None => return self.preempt_termination(),
            },
        };
        let Phase::Terminating { frame, key } = std::mem::replace(&mut self.phase, Phase::Run)
        else {
            return false;
        };
        // A replacement must be a child of the parent frame: anything else
        // would let a message push an arbitrary behavior (even an ancestor).
        let parent_children = self
            .stack
            .last()
            .map(|p| self.graph().behavior(p.behavior).children.clone())
            .unwrap_or_default();
        match outcome {
            Outcome::Terminate(Some(next)) if parent_children.contains(&next) => {
                let prev = Some((frame.behavior, frame.epoch));
                self.push(next, frame.team, Via::Replacement, prev);
            }
            Outcome::Terminate(Some(next)) => {
                if let Some(k) = key {
                    self.emit(Event::ProtocolViolation {
                        instance: k,
                        what: format!(
                            "replacement `{}` is not a child of the parent behavior; ignored",
                            self.graph().name_of(next)
                        ),
                    });
                }
                self.phase = Phase::Selecting { frame, key: None };
            }
            _ => self.phase = Phase::Selecting { frame, key: None },
        }
        true
    }

    /// Waiting for a termination protocol: if the behavior's `urgent`
    /// condition holds (checked on control ticks), stop waiting. The
    /// protocol, already told that this robot is done, goes on without it.
    fn preempt_termination(&mut self) -> bool {
        let Phase::Terminating { frame, .. } = &self.phase else {
            return false;
        };
        if !self.in_tick {
            return false;
        }
        let graph = self.mission.graph().clone();
        let Some(urgent) = &graph.behavior(frame.behavior).urgent else {
            return false;
        };
        let env = BeliefEnv {
            beliefs: &self.beliefs,
            runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
            now: self.now,
            started: frame.started,
            own: frame.behavior,
        };
        if !urgent.eval(&env) {
            return false;
        }
        let e = self.condition_event(frame.behavior, "urgent", urgent);
        self.out.push_back(Output::Event(e));
        let Phase::Terminating { mut frame, .. } = std::mem::replace(&mut self.phase, Phase::Run)
        else {
            return false;
        };
        frame.urgent = true;
        self.emit(Event::Preempted {
            behavior: frame.behavior,
            team: frame.team,
            epoch: frame.epoch,
        });
        self.phase = Phase::Selecting { frame, key: None };
        true
    }

    /// Line 8: choose the next behavior of the execution chain.
    fn select(&mut self) -> bool {
        let Phase::Selecting { frame, key } = &self.phase else {
            return false;
        };
        let (b, team, epoch) = (frame.behavior, frame.team, frame.epoch);
        let graph = self.mission.graph().clone();
        match *key {
            None => {
                let beh = graph.behavior(b);
                if beh.next.is_empty() {
                    return self.chain_end();
                }
                let enabled: Vec<BehaviorId> = beh
                    .next
                    .iter()
                    .copied()
                    .filter(|s| self.pre_holds(&graph, *s))
                    .collect();
                if graph.is_sync_point(b) && !frame.urgent {
                    // The team decides jointly even when this robot sees
                    // fewer than two enabled successors: its teammates may
                    // see more. Silent rules reduce to lines 8b–8d exactly.
                    let key = InstanceKey {
                        team,
                        behavior: b,
                        kind: Kind::Sync,
                        epoch,
                        round: 0,
                    };
                    if let Phase::Selecting { key: k, .. } = &mut self.phase {
                        *k = Some(key);
                    }
                    self.start_instance(
                        key,
                        PointInput::Sync {
                            candidates: enabled,
                            successors: beh.next.clone(),
                        },
                        &[],
                    );
                    return true;
                }
                match enabled.first() {
                    Some(s) => {
                        let s = *s;
                        if let Some(pre) = &graph.behavior(s).pre {
                            let e = self.condition_event(s, "pre", pre);
                            self.emit(e);
                        }
                        self.phase = Phase::Run;
                        self.push(s, team, Via::Sequence, Some((b, epoch)));
                        true
                    }
                    None => self.chain_end(),
                }
            }
            Some(k) => {
                let Some(outcome) = self.take_outcome(k) else {
                    return false;
                };
                match outcome {
                    Outcome::Sync(Some(s)) => {
                        self.phase = Phase::Run;
                        self.push(s, team, Via::Decision, Some((b, epoch)));
                        true
                    }
                    _ => self.chain_end(),
                }
            }
        }
    }

    /// Line 8b: the execution chain is over, so its parent terminates.
    fn chain_end(&mut self) -> bool {
        self.phase = Phase::Run;
        if self.stack.is_empty() {
            self.phase = Phase::Finished;
            self.emit(Event::MissionCompleted);
            return false;
        }
        let i = self.stack.len() - 1;
        self.end_frame(i, EndReason::ChainEnded);
        true
    }

    // ----- protocol instances -------------------------------------------

    fn start_instance(&mut self, key: InstanceKey, input: PointInput, told: &[RobotId]) {
        let Some(bound) = self.mission.bound(key.behavior, key.kind) else {
            return;
        };
        let armed = key.kind == Kind::Terminate;
        let Some(team) = self.org.team(key.team).cloned() else {
            return;
        };
        // Lost teammates are left out of every instance (every robot learns
        // of them within a heartbeat), and so are teammates that left an
        // ancestor: every member learns that from the same heartbeats (the
        // leaver's, relayed by the team's leader), so silent rules leave
        // them out alike — an allocation does not give a role to a teammate
        // that is done with the behavior.
        let mut gone = self.lost.clone();
        for r in told {
            gone.insert(*r);
        }
        // An allocation at the top frame is not below it: teammates idle
        // under it take part in a re-allocation (those that left it answer
        // `Done`).
        let below = match key.kind {
            Kind::Allocate => self.stack.len().saturating_sub(1),
            _ => self.stack.len(),
        };
        for f in &self.stack[..below] {
            if let Some(d) = &f.departed {
                gone.union_with(d);
            }
        }
        let excluded = (!gone.is_empty() && !team.members.is_disjoint(&gone)).then_some(gone);
        let inst = Instance {
            excluded,
            protocol: bound.protocol.name(),
            team,
            closed: None,
            split: None,
            imp: (bound.factory)(),
            input,
            retry: bound.retry,
            deadline_len: bound.deadline,
            state: if armed { State::Armed } else { State::Active },
            waiting_since: if armed { None } else { Some(self.now) },
            deadline: if armed {
                Time::MAX
            } else {
                self.now + bound.deadline
            },
            wake: None,
            outcome: None,
            timed_out: false,
            sent: 0,
            bytes: 0,
            received: 0,
        };
        let protocol = inst.protocol;
        self.instances.insert(key, inst);
        if !armed {
            let excluded = self.instances[&key].excluded_members();
            let options: LogList<BehaviorId> = match &self.instances[&key].input {
                PointInput::Sync { candidates, .. } => candidates.as_slice().into(),
                PointInput::Allocate { children } => {
                    match (self.mission.child_slots_shared(key.behavior))
                        .zip(self.mission.child_ids(key.behavior))
                    {
                        // Every child: the mission's list, shared.
                        Some((all, ids)) if Arc::ptr_eq(all, children) => ids.clone(),
                        _ => children.iter().map(|c| c.behavior).collect(),
                    }
                }
                PointInput::Terminate => LogList::default(),
            };
            self.emit(Event::InteractionStarted {
                instance: key,
                protocol,
                excluded,
                options,
            });
        }
        self.call(key, |imp, cx| imp.start(cx));
        self.refresh_due();
        if let Some(msgs) = self.pending.remove(&key) {
            self.pending_len -= msgs.len();
            for m in msgs {
                self.deliver(key, m.from, m.body);
            }
        }
    }

    /// This robot's own reason to end the behavior of `key` happened.
    fn term_local_done(&mut self, key: InstanceKey, why: LocalEnd) {
        let now = self.now;
        let Some(inst) = self.instances.get_mut(&key) else {
            return;
        };
        if inst.state != State::Armed {
            return;
        }
        inst.state = State::Active;
        inst.waiting_since = Some(now);
        inst.deadline = now + inst.deadline_len;
        let protocol = inst.protocol;
        let excluded = inst.excluded_members();
        self.emit(Event::InteractionStarted {
            instance: key,
            protocol,
            excluded,
            options: LogList::default(),
        });
        self.call(key, |imp, cx| imp.local_done(cx, why));
        self.refresh_due();
    }

    fn take_outcome(&mut self, key: InstanceKey) -> Option<Outcome> {
        self.instances.get_mut(&key).and_then(|i| i.outcome.take())
    }

    /// Call into an instance with a fresh context, then apply its effects.
    fn call(&mut self, key: InstanceKey, f: impl FnOnce(&mut dyn Interaction, &mut Cx<'_>)) {
        let Some(mut inst) = self.instances.remove(&key) else {
            return;
        };
        let mut fx = Effects::default();
        {
            let mut cx = Cx::new(CxParts {
                now: self.now,
                me: self.me,
                key,
                team: self.org.team(key.team).unwrap_or(&inst.team),
                excluded: inst.excluded.as_ref(),
                lost: Some(&self.lost),
                org: &self.org,
                runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
                graph: self.mission.graph(),
                mission: Some(&self.mission),
                roster: self.mission.graph().roster(),
                beliefs: &self.beliefs,
                rng: &mut self.rng,
                input: &inst.input,
                retry: inst.retry,
                deadline: inst.deadline,
                decided: inst.state == State::Decided,
                aborted: inst.state == State::Aborted,
                fx: &mut fx,
            });
            f(&mut *inst.imp, &mut cx);
        }
        let departed = std::mem::take(&mut fx.departed);
        self.apply_effects(key, &mut inst, fx);
        self.instances.insert(key, inst);
        if !departed.is_empty() {
            self.departures(key, &departed);
        }
    }

    /// Instance `k` decides without `who` from now on.
    fn exclude(&mut self, k: InstanceKey, who: &[RobotId]) {
        let n = self.org.roster_len();
        let mut new = Vec::new();
        if let Some(inst) = self.instances.get_mut(&k) {
            let ex = inst.excluded.get_or_insert_with(|| MemberSet::empty(n));
            for r in who {
                if inst.team.contains(*r) && ex.insert(*r) {
                    new.push(*r);
                }
            }
            if !new.is_empty() && inst.state == State::Active {
                self.out.push_back(Output::Event(Event::LeftOut {
                    instance: k,
                    members: new,
                }));
            }
        }
        self.call(k, |imp, cx| imp.on_members_changed(cx));
    }

    /// Teammates done with the behavior of termination instance `key`:
    /// leave them out of every instance below that behavior.
    fn departures(&mut self, key: InstanceKey, who: &[RobotId]) {
        if let Some(i) = self.stack.iter().position(|f| f.term_key() == key) {
            self.depart(i, who);
        } else {
            self.depart_popped(key, who);
        }
    }

    /// Teammates done with the behavior this robot ended and waits to
    /// terminate: nothing of it runs here any more, but a leader relays
    /// who is done with its heartbeats.
    fn depart_popped(&mut self, key: InstanceKey, who: &[RobotId]) {
        let n = self.org.roster_len();
        if let Phase::Terminating { frame, .. } | Phase::Selecting { frame, .. } = &mut self.phase
            && frame.term_key() == key
        {
            let set = frame.departed.get_or_insert_with(|| MemberSet::empty(n));
            for r in who {
                set.insert(*r);
            }
        }
    }

    /// Teammates done with the behavior of stack frame `i` (they arrived at
    /// its termination, or left it): leave them out of every instance below
    /// it, as if presumed lost.
    fn depart(&mut self, i: usize, who: &[RobotId]) {
        let n = self.org.roster_len();
        let set = self.stack[i]
            .departed
            .get_or_insert_with(|| MemberSet::empty(n));
        for r in who {
            set.insert(*r);
        }
        // The termination instances of the frames down to this one are not
        // below it, nor is a re-allocation at it (teammates idle under it
        // take part); every other running instance is.
        let here = &self.stack[i];
        let (team, behavior, epoch) = (here.team, here.behavior, here.epoch);
        let mut above: Vec<InstanceKey> = self.stack[..=i].iter().map(Frame::term_key).collect();
        above.extend(
            self.instances
                .keys()
                .filter(|k| {
                    k.kind == Kind::Allocate
                        && (k.team, k.behavior, k.epoch) == (team, behavior, epoch)
                })
                .copied(),
        );
        let below: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(k, inst)| {
                !above.contains(k)
                    && matches!(inst.state, State::Armed | State::Active)
                    && who.iter().any(|r| inst.team.contains(*r))
                    && self
                        .mission
                        .bound(k.behavior, k.kind)
                        .is_some_and(|b| b.protocol.communicates())
            })
            .map(|(k, _)| *k)
            .collect();
        for k in below {
            self.exclude(k, who);
        }
        self.refresh_due();
    }

    fn apply_effects(&mut self, key: InstanceKey, inst: &mut Instance, fx: Effects) {
        for (to, body) in fx.sends {
            let envelope = Envelope {
                instance: key,
                sender: self.me,
                seq: self.next_seq,
                body,
            };
            self.next_seq += 1;
            let bytes = encoded_len(&envelope) as u32;
            inst.sent += 1;
            inst.bytes += u64::from(bytes);
            self.stats.sent += 1;
            self.stats.bytes_sent += u64::from(bytes);
            self.out.push_back(Output::Send(Outgoing {
                to,
                envelope,
                bytes,
            }));
        }
        if let Some(w) = fx.wake
            && inst.state != State::Aborted
        {
            inst.wake = Some(inst.wake.map_or(w, |x| x.min(w)));
            self.next_due = Some(self.next_due.map_or(w, |x| x.min(w)));
        }
        if fx.postpone && inst.state == State::Active {
            inst.deadline = self.now + inst.deadline_len;
        }
        for what in fx.violations {
            self.emit(Event::ProtocolViolation {
                instance: key,
                what,
            });
        }
        let mut tell = Vec::new();
        if let Some(outcome) = fx.outcome
            && matches!(inst.state, State::Armed | State::Active)
        {
            // An allocation a teammate of this process already applied
            // (checked then) is shared as it is; any other is checked.
            let (team, point, stamp) = (key.team, key.behavior, key.stamp());
            let shared = match &outcome {
                Outcome::Allocate(a) => self.mission.find_split(team, point, stamp, a),
                _ => None,
            };
            let mut outcome = match shared {
                Some(_) => outcome,
                None => self.validate(key, inst, outcome),
            };
            inst.state = State::Decided;
            if let Outcome::Allocate(a) = &mut outcome {
                // The subteams it makes, shared with the teammates of this
                // process that decided the same (the assignment moves
                // into them; what the kernel applies is `inst.split`).
                let a = std::mem::take(a);
                inst.split = Some(match shared {
                    Some(s) => s,
                    None => self.mission.split(team, point, stamp, a),
                });
            }
            let waited = inst.waiting_since.map_or(Duration::ZERO, |t| self.now - t);
            self.emit(Event::InteractionDecided {
                instance: key,
                protocol: inst.protocol,
                outcome: match (&outcome, &inst.split) {
                    (Outcome::Sync(c), _) => OutcomeLog::Sync { choice: *c },
                    (Outcome::Allocate(_), Some(s)) => OutcomeLog::Allocate {
                        assignment: s.log().clone(),
                    },
                    (Outcome::Allocate(a), None) => OutcomeLog::allocation(a),
                    (Outcome::Terminate(n), _) => OutcomeLog::Terminate { next: *n },
                },
                waited_us: waited.as_micros() as u64,
                sent: inst.sent,
                bytes: inst.bytes,
                received: inst.received,
                timed_out: inst.timed_out,
            });
            inst.closed = Some(match (&outcome, &inst.split) {
                (Outcome::Sync(c), _) => Closed::Synced(*c),
                (Outcome::Allocate(_), Some(s)) => Closed::Allocated(s.assignment().clone()),
                (Outcome::Allocate(a), None) => Closed::Allocated(a.clone()),
                (Outcome::Terminate(n), _) => Closed::Terminated(*n),
            });
            inst.outcome = Some(outcome);
            // Teammates presumed lost that this decision left out: told
            // now if they are back, else when they are.
            if let Some(ex) = &inst.excluded {
                for r in ex
                    .iter()
                    .filter(|r| inst.team.contains(*r) && self.ever_lost.contains(*r))
                {
                    if self.lost.contains(r) {
                        let missed = self.missed.entry(r).or_default();
                        if missed.len() >= MISSED_REMEMBERED {
                            missed.pop_front();
                        }
                        missed.push_back(key);
                    } else if let Some(body) = inst.closed.as_ref().and_then(missed_body) {
                        tell.push((r, body));
                    }
                }
            }
            self.mark_closed(key);
            // A termination decided while its behavior is still on the stack
            // (the team ended it, or this robot idles under it) ends it here.
            if key.kind == Kind::Terminate
                && let Some(f) = self.stack.iter_mut().find(|f| f.term_key() == key)
            {
                f.team_ended = true;
            }
        }
        for (r, body) in tell {
            self.reply(key, r, body);
        }
    }

    /// Check a decision against what the instance was asked; a protocol bug
    /// or a forged message must not corrupt the kernel, so an invalid
    /// decision is replaced by the silent rule of its kind.
    fn validate(&mut self, key: InstanceKey, inst: &Instance, outcome: Outcome) -> Outcome {
        let graph = self.mission.graph().clone();
        let outcome = match outcome {
            Outcome::Allocate(a) if matches!(inst.input, PointInput::Allocate { .. }) => {
                match self.sanitize_allocation(key, a) {
                    Ok(clean) => return Outcome::Allocate(clean),
                    Err(a) => Outcome::Allocate(a),
                }
            }
            o => o,
        };
        let ok = match (&outcome, &inst.input) {
            (Outcome::Sync(None), PointInput::Sync { .. }) => true,
            (Outcome::Sync(Some(s)), PointInput::Sync { successors, .. }) => successors.contains(s),
            (Outcome::Terminate(n), PointInput::Terminate) => {
                n.is_none_or(|n| graph.get(n).is_some())
            }
            _ => false,
        };
        if ok {
            return outcome;
        }
        self.emit(Event::ProtocolViolation {
            instance: key,
            what: format!("{} decided an invalid outcome {outcome:?}", inst.protocol),
        });
        match &inst.input {
            PointInput::Sync { candidates, .. } => Outcome::Sync(candidates.first().copied()),
            PointInput::Allocate { children } => match self.org.team(key.team) {
                Some(t) => Outcome::Allocate(Arc::new(rules::assign_by_id(&t.members, children))),
                None => Outcome::Allocate(Arc::default()),
            },
            PointInput::Terminate => Outcome::Terminate(None),
        }
    }

    /// An allocation as this robot can apply it: its children must be
    /// children of the point; members this robot does not know in the team
    /// are left out (a leader whose view of the team diverged after a
    /// timeout decides for the members it knows; those both know agree), and
    /// a member listed twice keeps its first child. `Err` (the allocation
    /// back) if a child is not a child of the point. Linear in the size of
    /// the allocation; one that needs no change is returned as it is.
    fn sanitize_allocation(
        &self,
        key: InstanceKey,
        a: Arc<Assignment>,
    ) -> Result<Arc<Assignment>, Arc<Assignment>> {
        let Some(team) = self.org.team(key.team) else {
            return Err(a);
        };
        let n = self.org.roster_len();
        if a.0.iter().any(|(c, m)| {
            self.mission.child_index(key.behavior, *c).is_none() || m.roster_len() != n
        }) {
            return Err(a);
        }
        let mut seen = fixedbitset::FixedBitSet::with_capacity(n);
        if a.0.iter().all(|(_, m)| {
            m.iter()
                .all(|r| team.members.contains(r) && !seen.put(r.index()))
        }) {
            return Ok(a);
        }
        let mut seen = MemberSet::empty(n);
        let mut out = Vec::with_capacity(a.0.len());
        for (c, m) in &a.0 {
            let mut mine = MemberSet::empty(n);
            for r in m.iter() {
                if team.members.contains(r) && seen.insert(r) {
                    mine.insert(r);
                }
            }
            out.push((*c, mine));
        }
        Ok(Arc::new(Assignment(out)))
    }

    fn fire_timers(&mut self) {
        let now = self.now;
        let due: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| i.wake.is_some_and(|w| w <= now))
            .map(|(k, _)| *k)
            .collect();
        for k in due {
            if let Some(i) = self.instances.get_mut(&k) {
                i.wake = None;
            }
            self.call(k, |imp, cx| imp.on_timer(cx));
        }
        let expired: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| i.state == State::Active && i.deadline <= now)
            .map(|(k, _)| *k)
            .collect();
        for k in expired {
            if self.awaited_at_work(k) {
                // A teammate this instance waits for is heard working on
                // the behavior: not silent, only slower. Wait on.
                if let Some(i) = self.instances.get_mut(&k) {
                    i.deadline = now + i.deadline_len;
                }
                self.stats.deadlines_rearmed += 1;
                continue;
            }
            if let Some(i) = self.instances.get_mut(&k) {
                i.timed_out = true;
            }
            self.stats.timeouts += 1;
            self.call(k, |imp, cx| imp.on_deadline(cx));
            let protocol_decided = self
                .instances
                .get(&k)
                .is_some_and(|i| i.state == State::Decided);
            if !protocol_decided {
                self.call(k, |_, cx| {
                    let o = rules::fallback(cx);
                    cx.decide(o);
                });
            }
            let protocol = self.instances.get(&k).map_or("?", |i| i.protocol);
            self.emit(Event::InteractionTimedOut {
                instance: k,
                protocol,
                protocol_decided,
            });
        }
        self.refresh_due();
    }

    fn refresh_due(&mut self) {
        self.next_due = self
            .instances
            .values()
            .flat_map(|i| {
                let d = (i.state == State::Active).then_some(i.deadline);
                i.wake.into_iter().chain(d)
            })
            .min();
    }

    // ----- messages ------------------------------------------------------

    fn drop_msg(&mut self, from: RobotId, reason: DropReason) {
        *self.stats.dropped.entry(reason).or_insert(0) += 1;
        // Duplicates, stale messages and our own echoes are normal on a
        // lossy, duplicating network: counted, not logged one by one.
        if !matches!(
            reason,
            DropReason::Duplicate | DropReason::Stale | DropReason::OwnMessage
        ) {
            self.emit(Event::Dropped { from, reason });
        }
    }

    /// Validate a message and hand it to its instance, or buffer it for an
    /// instance this robot has not reached yet.
    fn route(&mut self, env: Envelope) {
        let from = env.sender;
        if from == self.me {
            return self.drop_msg(from, DropReason::OwnMessage);
        }
        if from.index() >= self.org.roster_len() {
            return self.drop_msg(from, DropReason::UnknownSender);
        }
        let key = env.instance;
        let graph = self.mission.graph();
        let well_formed = key.epoch > 0
            && graph.get(key.behavior).is_some()
            && graph.is_point(key.behavior, key.kind);
        if !well_formed {
            return self.drop_msg(from, DropReason::Malformed);
        }
        let seen = self.seen.entry(from).or_default();
        if env.seq == 0 || seen.contains_key(&env.seq) {
            return self.drop_msg(from, DropReason::Duplicate);
        }
        if seen.len() >= DEDUP_PER_SENDER
            && let Some((&oldest, _)) = seen.iter().next()
        {
            seen.remove(&oldest);
        }
        seen.insert(env.seq, self.now);
        if key.kind == Kind::Allocate && key.round > 0 && !self.instances.contains_key(&key) {
            let frame = self
                .stack
                .iter()
                .position(|f| (f.team, f.behavior, f.epoch) == (key.team, key.behavior, key.epoch));
            let told: &[RobotId] = match &env.body {
                Body::Reallocate { lost } => lost,
                _ => &[],
            };
            match frame {
                // A teammate re-allocates what this robot runs under: join
                // it (this robot may not have noticed the loss yet) — unless
                // that teammate left this robot out.
                Some(i) if self.stack[i].round < key.round && !told.contains(&self.me) => {
                    let told = told.to_vec();
                    self.reallocate(i, key.round, &told);
                }
                Some(_) => {}
                // This robot has left that behavior: it takes no part.
                None if self.org.runs(key.team, key.behavior) >= key.epoch
                    && self.org.team(key.team).is_some_and(|t| t.contains(from)) =>
                {
                    self.stats.received += 1;
                    self.reply(key, from, Body::Done);
                    return;
                }
                None => {}
            }
        }
        if matches!(env.body, Body::Reallocate { .. }) {
            // The kernel's own notice, handled above.
            self.stats.received += 1;
            return;
        }
        if let Some(inst) = self.instances.get(&key) {
            let team = self.org.team(key.team).unwrap_or(&inst.team);
            if !team.contains(from) {
                return self.drop_msg(from, DropReason::SenderNotMember);
            }
            self.stats.received += 1;
            return self.deliver(key, from, env.body);
        }
        if let Some(closed) = self.tombstones.get(&key).cloned() {
            self.stats.received += 1;
            if matches!(env.body, Body::Missed { .. }) {
                // Decided here already: nothing to apply, nothing to answer.
                return;
            }
            return self.late_reply(key, closed, from, &env.body);
        }
        match self.org.team(key.team) {
            Some(t) if !t.contains(self.me) => return self.drop_msg(from, DropReason::NotMember),
            Some(t) if !t.contains(from) => {
                return self.drop_msg(from, DropReason::SenderNotMember);
            }
            Some(_) => {}
            None if self.org.is_dead(key.team) => return self.drop_msg(from, DropReason::Stale),
            None => {}
        }
        if self
            .closed
            .get(&(key.team, key.behavior, key.kind))
            .is_some_and(|e| key.stamp() <= *e)
        {
            return self.drop_msg(from, DropReason::Stale);
        }
        if self.pending_len >= self.limits.max_pending {
            return self.drop_msg(from, DropReason::BufferOverflow);
        }
        let queue = self.pending.entry(key).or_default();
        if queue.iter().any(|p| p.from == from && p.body == env.body) {
            // A retransmission of a message already waiting: one is enough.
            return self.drop_msg(from, DropReason::Duplicate);
        }
        queue.push(Pending {
            at: self.now,
            from,
            body: env.body,
        });
        self.stats.received += 1;
        self.stats.buffered += 1;
        self.pending_len += 1;
    }

    /// Answer a teammate's late message for a forgotten instance, as its
    /// protocol says.
    fn late_reply(&mut self, key: InstanceKey, closed: Closed, from: RobotId, body: &Body) {
        if let Some(reply) = self
            .mission
            .bound(key.behavior, key.kind)
            .and_then(|b| b.protocol.late_reply(&closed, body))
        {
            self.reply(key, from, reply);
        }
    }

    /// Send `body` to `to` for instance `key`, outside any live instance.
    fn reply(&mut self, key: InstanceKey, to: RobotId, body: Body) {
        self.send_outside(key, Recipients::One(to), body);
    }

    /// Send a message of the kernel's own (not of a protocol instance).
    fn send_outside(&mut self, key: InstanceKey, to: Recipients, body: Body) {
        let envelope = Envelope {
            instance: key,
            sender: self.me,
            seq: self.next_seq,
            body,
        };
        self.next_seq += 1;
        let bytes = encoded_len(&envelope) as u32;
        self.stats.sent += 1;
        self.stats.bytes_sent += u64::from(bytes);
        self.out.push_back(Output::Send(Outgoing {
            to,
            envelope,
            bytes,
        }));
    }

    fn bury(&mut self, key: InstanceKey, closed: Closed) {
        if self.tombstones.insert(key, closed).is_none() {
            self.tomb_order.push_back(key);
        }
        while self.tomb_order.len() > TOMBSTONES {
            if let Some(old) = self.tomb_order.pop_front() {
                self.tombstones.remove(&old);
            }
        }
    }

    fn deliver(&mut self, key: InstanceKey, from: RobotId, body: Body) {
        if let Some(i) = self.instances.get_mut(&key) {
            i.received += 1;
        }
        if key.kind != Kind::Terminate && body == Body::Done {
            // "I have left this behavior" (a re-allocation reached a
            // teammate that is done with it): decide without it.
            self.exclude(key, &[from]);
            self.refresh_due();
            return;
        }
        if let Body::Missed {
            choice,
            children,
            members,
        } = body
        {
            // The team decided without this robot while it was presumed
            // lost: apply the team's decision, whatever this robot's own
            // protocol instance (it may believe itself the coordinator).
            let outcome = match key.kind {
                Kind::Sync => Some(Outcome::Sync(choice)),
                Kind::Terminate => Some(Outcome::Terminate(choice)),
                Kind::Allocate => Body::Assignment { children, members }
                    .to_assignment(self.org.roster_len())
                    .map(|a| Outcome::Allocate(Arc::new(a))),
            };
            match outcome {
                Some(o) => self.force(key, o),
                None => self.drop_msg(from, DropReason::Malformed),
            }
            return;
        }
        self.call(key, |imp, cx| imp.on_message(cx, from, &body));
        self.refresh_due();
    }

    /// Decide instance `key` with `outcome`, outside its protocol.
    fn force(&mut self, key: InstanceKey, outcome: Outcome) {
        let Some(mut inst) = self.instances.remove(&key) else {
            return;
        };
        let fx = Effects {
            outcome: Some(outcome),
            ..Effects::default()
        };
        self.apply_effects(key, &mut inst, fx);
        self.instances.insert(key, inst);
        self.refresh_due();
    }

    fn drop_pending(&mut self, key: InstanceKey) {
        if let Some(v) = self.pending.remove(&key) {
            self.pending_len -= v.len();
        }
    }

    /// Forget instances that stopped lingering and buffered messages that
    /// can no longer be used.
    fn gc(&mut self) {
        let now = self.now;
        // A finished instance (decided or left) stays while it still has
        // work (a timer: e.g. telling stragglers of a release); then only
        // its outcome is kept, to answer late teammates.
        let done: Vec<(InstanceKey, Closed)> = self
            .instances
            .iter()
            .filter(|(_, i)| {
                matches!(i.state, State::Decided | State::Aborted)
                    && i.outcome.is_none()
                    && i.wake.is_none()
            })
            .filter_map(|(k, i)| i.closed.clone().map(|c| (*k, c)))
            .collect();
        for (k, c) in done {
            self.instances.remove(&k);
            self.bury(k, c);
        }
        for senders in self.seen.values_mut() {
            senders.retain(|_, t| now - *t < DEDUP_MEMORY);
        }
        self.seen.retain(|_, s| !s.is_empty());
        let ttl = self.limits.pending_ttl;
        let closed = &self.closed;
        let org = &self.org;
        let mut expired = 0usize;
        self.pending.retain(|k, v| {
            let stale = closed
                .get(&(k.team, k.behavior, k.kind))
                .is_some_and(|e| k.stamp() <= *e)
                || org.is_dead(k.team);
            let before = v.len();
            if stale {
                v.clear();
            } else {
                v.retain(|m| now - m.at < ttl);
            }
            expired += before - v.len();
            !v.is_empty()
        });
        if expired > 0 {
            self.pending_len -= expired;
            *self
                .stats
                .dropped
                .entry(DropReason::BufferOverflow)
                .or_insert(0) += expired as u64;
        }
        self.refresh_due();
    }
}

#[cfg(test)]
mod tests;
