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
use crate::ids::{InstanceKey, Kind};
use crate::interaction::{
    Assignment, ChildSlot, Closed, Cx, CxParts, Effects, Interaction, LocalEnd, Outcome,
    PointInput, Recipients,
};
use crate::mission::Mission;
use crate::msg::{Body, Envelope, encoded_len};
use crate::org::{MemberSet, Organization, Split};
use crate::rules;
use crate::time::Time;
use crate::value::Value;
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

mod change;
mod control;
mod dedup;
mod heal;
mod inbox;
mod instances;
mod membership;
mod peers;
mod position;
mod slots;
mod tombs;
pub use change::{FENCE_WAIT, Fence};
use inbox::Inbox;
pub use position::{ALLOC_HEALS, Anchor, Ended, FrameId, FrameState, PosFrame, Position};

/// How long accepted `(sender, seq)` pairs are remembered to drop
/// duplicates (far longer than any network delay; a copy older than this
/// belongs to an instance that is over and is dropped as stale anyway).
const DEDUP_MEMORY: Duration = Duration::from_secs(120);
/// Most `(sender, seq)` pairs remembered per sender.
const DEDUP_PER_SENDER: usize = 4096;
/// Give back a drained output queue's room. Called once the robot's
/// mission is over, for the kernel's queue and the agent's after it: the
/// mission's end is a burst (every frame ends at once) whose room each of
/// a large team's robots otherwise held for good (docs/performance.md,
/// "2026-11-28, evening"; even room for eight outputs was a fifteenth of
/// a 10,000-robot run's memory, "2026-11-28, late"). A finished robot outputs
/// rarely (an answer to a late teammate), so the room is not kept for it.
/// While the mission runs the kernel keeps its own (a decision's burst
/// would allocate again every cycle): the runtime that drains it after
/// every input gives it back with its own, at most once a second (see
/// `bite_agent::agent::Agent::poll` and [`Kernel::give_back_output_room`]).
pub fn give_back_room<T>(queue: &mut VecDeque<T>) {
    if queue.is_empty() && queue.capacity() > 0 {
        *queue = VecDeque::new();
    }
}
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
    /// Belief and stack versions at which `until` was last found false
    /// (the stack's only for conditions that read `runs`: other ones read
    /// nothing a push or a pop changes; a change of mission changes the
    /// belief version).
    #[serde(skip)]
    until_false_at: Option<(u64, u64)>,
    /// The control tick during whose period it was pushed.
    #[serde(skip)]
    born: u64,
    /// How many times each behavior has been started directly under this
    /// frame, during this execution of it (what `runs` reads in conditions).
    #[serde(skip)]
    runs: crate::belief::RunCounts,
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
    /// The team allocated it without this robot, which idles under it
    /// (see `Kernel::follow_past`): it does not allocate it again to join.
    #[serde(skip)]
    left_behind: bool,
}

impl Frame {
    /// True when robot `r` left one of `frames` (it is done with that
    /// behavior: see `departed`).
    fn any_left_by(frames: &[Frame], r: RobotId) -> bool {
        frames
            .iter()
            .any(|f| f.departed.as_ref().is_some_and(|d| d.contains(r)))
    }

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

/// A binding's duration as an instance keeps it: nanoseconds in 8 bytes
/// instead of a `Duration`'s 16, so that an [`Instance`] fits the
/// allocator's 320-byte size class rather than the 384-byte one (a robot of
/// a large team holds about six instances: docs/performance.md, "2026-12-07,
/// tenth session"). Exact up to 584 years; longer ones are read as 584
/// years, which no run can tell apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PackedDuration(u64);

impl PackedDuration {
    fn get(self) -> Duration {
        Duration::from_nanos(self.0)
    }
}

impl From<Duration> for PackedDuration {
    fn from(d: Duration) -> Self {
        PackedDuration(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
    }
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
    retry: PackedDuration,
    deadline_len: PackedDuration,
    state: State,
    waiting_since: Option<Time>,
    /// When a heartbeat first showed the coordinator past the barrier, or
    /// out of the allocation (see `Kernel::ask_past_point`).
    past_seen: Option<Time>,
    deadline: Time,
    wake: Option<Time>,
    outcome: Option<Outcome>,
    timed_out: bool,
    /// Its deadline fell once with counted teammates never heard, and this
    /// robot called them (`Kernel::call_unheard`).
    called: bool,
    /// The coordinator this robot asked when the deadline fell with it
    /// heard out of the execution (`Kernel::ask_coordinator_out`).
    asked: Option<RobotId>,
    sent: u32,
    bytes: u64,
    received: u32,
}

impl Instance {
    /// True when this instance decides without `r` (it learnt that `r`
    /// left the execution, or the protocol excluded it).
    fn excludes(&self, r: RobotId) -> bool {
        self.excluded.as_ref().is_some_and(|x| x.contains(r))
    }

    /// True when this instance decides without `from` and with at least
    /// one teammate besides `me`: `from` and this side of the team decide
    /// apart.
    fn decides_apart_from(&self, from: RobotId, me: RobotId) -> bool {
        self.excluded.as_ref().is_some_and(|ex| {
            ex.contains(from) && self.team.members.iter().any(|r| r != me && !ex.contains(r))
        })
    }

    /// When it will have waited a retry for its decision (`None`: it does
    /// not wait; see `Kernel::asks_from`).
    fn retry_due(&self) -> Option<Time> {
        match (self.state, self.waiting_since) {
            (State::Active, Some(t)) => Some(t + self.retry.get()),
            _ => None,
        }
    }

    /// True when it has waited a retry for its decision at `now`.
    fn waited_a_retry(&self, now: Time) -> bool {
        self.retry_due().is_some_and(|t| now >= t)
    }

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
    /// `frame` was popped; waiting for its termination protocol. (Boxed,
    /// as in `Selecting`: a phase holding a frame inline was 216 bytes of
    /// every robot's kernel, for the few that are between behaviors.)
    Terminating {
        frame: Box<Frame>,
        key: Option<InstanceKey>,
    },
    /// `frame` ended; choosing its successor.
    Selecting {
        frame: Box<Frame>,
        key: Option<InstanceKey>,
    },
    /// The stack emptied.
    Finished,
}

/// The control kernel of one robot.
pub struct Kernel {
    mission: Arc<Mission>,
    me: RobotId,
    beliefs: BeliefStore,
    org: Organization,
    rng: crate::interaction::LazyRng,
    stack: Vec<Frame>,
    phase: Phase,
    instances: slots::Instances,
    /// Highest epoch known to be over, per (team, behavior, kind) (looked
    /// up and pruned, never walked in order: a hash map).
    closed: rustc_hash::FxHashMap<(TeamId, BehaviorId, Kind), (u32, u32)>,
    /// Messages buffered for instances not started yet.
    inbox: Inbox,
    /// Teammates presumed lost (reported by the runtime).
    lost: MemberSet,
    /// Of those, the ones heard from since (a message, ahead of the
    /// heartbeats that will bring them back): they may have gone on on
    /// their own, so a mission change's safe point waits for them.
    stirring: Vec<RobotId>,
    /// Instances decided without a teammate presumed lost, per teammate:
    /// when it comes back it is told how they ended (it may be waiting in
    /// one, or running below a behavior its team ended meanwhile).
    missed: BTreeMap<RobotId, VecDeque<InstanceKey>>,
    /// Teammates presumed lost at some point of the mission.
    ever_lost: MemberSet,
    /// Of the teammates presumed lost now, those a deadline of this robot
    /// has decided without since (see `Cx::is_given_up`).
    given_up: MemberSet,
    /// Outcomes of forgotten instances, to answer late teammates.
    tombstones: tombs::Tombstones,
    /// Recently accepted `(sender, seq)` with when: a message is acted upon
    /// at most once, whatever the order it arrives in.
    seen: dedup::Accepted,
    next_seq: u64,
    out: VecDeque<Output>,
    now: Time,
    stack_version: u64,
    /// Control ticks handled so far.
    ticks: u64,
    /// Whether the input being handled is a control tick.
    in_tick: bool,
    /// Run counts of the top-level execution chain (behaviors with no parent frame).
    root_runs: crate::belief::RunCounts,
    next_due: Option<Time>,
    gc_at: Time,
    limits: Limits,
    stats: Stats,
    /// Executions this robot ended recently (for its heartbeats).
    recent_ended: position::RecentEnded,
    /// Executions burned recently, here or by teammates.
    recent_burned: VecDeque<FrameId>,
    /// The execution this robot last ended and went on from in sequence:
    /// the depth it ran at, its parent execution, its id and what it
    /// followed. A teammate that runs another execution of its behavior
    /// after the same step renamed it ([`Kernel::count_renamed`]).
    went_on_from: Option<(usize, FrameId, FrameId, Anchor)>,
    /// An instance where this robot waits, and since when teammates are
    /// heard past its point (see `Kernel::follow_past`).
    left_behind: Option<(InstanceKey, Time)>,
    /// No instance has waited a retry before this time (`None`: none
    /// waits): a heartbeat looks for instances to ask about
    /// (`Kernel::ask_past_point`) only from then on, without reading each
    /// instance (a large team's heartbeats found them out of the cache).
    /// Lowered when an instance starts waiting, raised only by a walk of
    /// every instance.
    asks_from: Option<Time>,
    /// Splits this robot, as healing leader, has already recorded.
    splits_seen: std::collections::BTreeSet<(RobotId, FrameId)>,
    /// A restarted process: since when it waits to hear where its team is.
    rejoin_since: Option<Time>,
    /// What each teammate heard from said (see [`position::Peer`]): two
    /// short vectors, a hash map, or a table by roster place for a leader
    /// of a large team (`peers.rs`). A team leader looks one up for every
    /// heartbeat of every member, and a B-tree of 10,000 teammates was a
    /// fifth of a large team's run in cache misses (keys are roster
    /// indices, checked before they are inserted; nothing iterates it in an
    /// order that matters).
    peers: peers::Peers,
    /// Teammates not heard for a while (see [`position::Quiet`]).
    quiet: rustc_hash::FxHashMap<RobotId, position::Quiet>,
    /// The version of the mission it runs (see `change.rs`).
    version: u32,
    /// Steps its skill has made (the runtime's count, wrapping: see
    /// [`Kernel::skill_progressed`]), told with its heartbeats.
    progress: u32,
    /// Newer versions, held until a safe point (the newest few).
    pending: BTreeMap<u32, Arc<Mission>>,
    /// What it did at recent safe points while a version was pending.
    fences: VecDeque<Fence>,
    /// What teammates did at recent safe points of its teams, passed on
    /// with its heartbeats (members hear only their leader).
    relayed: VecDeque<Fence>,
    /// Holding at a safe point for the leader's decision: where, since
    /// when, and until when (the kernel's timer is due then).
    fence_wait: Option<(FrameId, Time, Time)>,
    /// What teammates' heartbeats said about versions.
    peer_versions: BTreeMap<RobotId, change::PeerVersion>,
    /// When it last left subteams on its own (an end it made alone: see
    /// `Kernel::end_frame`).
    left_at: Option<Time>,
    /// Teammates that send it heartbeats for a team it is not in (it left
    /// it, or has yet to join it): its own heartbeats answer them (see
    /// `Kernel::answer_strangers`). Boxed, as `calling`: rarely set, and
    /// every robot's kernel is read from memory at each of its events
    /// (the two inline were 88 of its bytes; docs/performance.md,
    /// "2026-12-06, fifth session").
    answering: Option<Box<MemberSet>>,
    /// Teammates counted at a point whose deadline fell without this robot
    /// ever hearing them, and until when its heartbeats go to them (see
    /// `Kernel::call_unheard`).
    calling: Option<Box<(MemberSet, Time)>>,
    /// Executions of points that teammates before this robot had ended
    /// when it learnt they left a behavior of its own, and that it has not
    /// ended (newest last, at most [`LEFT_RAN`], those it can no longer
    /// come to dropped first): one that coordinated such a point may have
    /// decided it and left with its decision (see `Kernel::note_left_ran`).
    left_ran: Vec<crate::interaction::LeftRan>,
}

/// How many executions [`Kernel`] keeps that teammates ended before it
/// learnt they left.
const LEFT_RAN: usize = 4;

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
            rng: crate::interaction::LazyRng::new(seed),
            me,
            mission,
            stack: Vec::new(),
            phase: Phase::NotStarted,
            instances: slots::Instances::default(),
            closed: Default::default(),
            inbox: Inbox::default(),
            lost: MemberSet::empty(n),
            stirring: Vec::new(),
            missed: BTreeMap::new(),
            ever_lost: MemberSet::empty(n),
            given_up: MemberSet::empty(n),
            tombstones: Default::default(),
            seen: dedup::Accepted::default(),
            next_seq: 1,
            out: VecDeque::new(),
            now: Time::ZERO,
            stack_version: 0,
            ticks: 0,
            in_tick: false,
            root_runs: crate::belief::RunCounts::new(),
            next_due: None,
            gc_at: Time::ZERO,
            limits: Limits::for_team(n),
            stats: Stats::default(),
            recent_ended: position::RecentEnded::default(),
            recent_burned: VecDeque::new(),
            went_on_from: None,
            left_behind: None,
            asks_from: None,
            splits_seen: std::collections::BTreeSet::new(),
            rejoin_since: None,
            peers: Default::default(),
            quiet: Default::default(),
            version: 0,
            progress: 0,
            pending: BTreeMap::new(),
            fences: VecDeque::new(),
            relayed: VecDeque::new(),
            fence_wait: None,
            peer_versions: BTreeMap::new(),
            left_at: None,
            answering: None,
            calling: None,
            left_ran: Vec::new(),
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
        // Asleep (paused, descheduled) between two inputs: the time does
        // not count toward a hold at a safe point, which waits for news
        // this robot could not hear meanwhile.
        if now > self.now + change::ASLEEP {
            self.slept(now - self.now);
        }
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

    /// Ask for the state a control tick or a heartbeat reads first (the
    /// stack, the belief slots, the instances, the execution counts and
    /// the newest dissolved teams) to be brought into the cache, ahead of
    /// the tick: a large team's minds tick one after the other, each on
    /// state of its own scattered in memory.
    pub fn prefetch(&self) {
        // The whole stack of a formation (four frames of 168 bytes): a
        // heartbeat reads every frame's anchor; four lines covered one and
        // a half frames (10,000 robots: 3-12 % faster with twelve).
        crate::hint::prefetch_slice(&self.stack, 12);
        self.beliefs.prefetch();
        self.instances.prefetch();
        self.org.prefetch();
    }

    /// Ask for what this robot keeps of teammate `from` to be brought into
    /// the cache ahead of `from`'s heartbeat (a hint: a robot that heard a
    /// handful, or a large team's leader, knows where without reading
    /// memory; see `peers.rs`).
    pub fn prefetch_peer(&self, from: RobotId) {
        self.peers.prefetch(from);
    }

    /// Ask for what this robot reads to address its next heartbeat to be
    /// brought into the cache (a hint): whether each leader it sends to
    /// is away is read from its entry of that leader
    /// ([`Kernel::beacon_audience`]), and a member keeps a handful.
    pub fn prefetch_audience(&self) {
        self.peers.prefetch_handful();
    }

    /// The next output, if any.
    pub fn poll_output(&mut self) -> Option<Output> {
        if self.out.is_empty() {
            self.drained();
            return None;
        }
        self.out.pop_front()
    }
    /// Room the output queue holds, in outputs.
    pub fn output_room(&self) -> usize {
        self.out.capacity()
    }
    /// Give back the output queue's room if it is drained (see
    /// [`give_back_room`]): for a runtime that drains the kernel after
    /// every input and keeps the room at most for a while. Room for eight
    /// outputs, kept by every robot between its decisions, was 96 MB of a
    /// 100,000-robot run's peak (docs/performance.md, "2026-12-04, late").
    pub fn give_back_output_room(&mut self) {
        give_back_room(&mut self.out);
    }
    /// The outputs are drained: once the mission is over, give back their
    /// room, and the emptied stack's (a large team's robots all finish at
    /// once, and each kept room for a stack of frames it will not run
    /// again). Out of line, so that polling stays small enough to inline.
    #[inline(never)]
    fn drained(&mut self) {
        if self.is_finished() {
            give_back_room(&mut self.out);
            if self.stack.is_empty() && self.stack.capacity() > 0 {
                self.stack = Vec::new();
            }
        }
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
    /// The frame whose termination protocol this robot waits on (it ended
    /// here; the team has not decided yet).
    pub fn ending(&self) -> Option<&Frame> {
        match &self.phase {
            Phase::Terminating {
                frame,
                key: Some(_),
            } => Some(frame),
            _ => None,
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
            pending: self.inbox.len(),
            seen: self.seen.len(),
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
}

#[cfg(test)]
mod tests;
