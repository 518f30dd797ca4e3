//! What each teammate runs: the *team view* a kernel keeps from its
//! teammates' heartbeats.
//!
//! Algorithm 1 runs on every robot separately; nothing in it tells a robot
//! where its teammates are. Two things go wrong without that knowledge:
//!
//! - **Waiting across levels.** A robot that ended an ancestor (its
//!   condition held, or it waits in the ancestor's termination protocol)
//!   will never take part in anything below it again, yet a teammate still
//!   below may wait for it there — in a barrier it leads, a vote it
//!   counts — while it waits for that teammate at the ancestor: each waits
//!   for the other until a deadline.
//! - **Silent splits.** A silent rule decides from what each member
//!   perceives; members that perceive differently choose different
//!   successors at the same synchronization point, and each part then
//!   waits for the other at its barrier.
//!
//! The runtime sends each robot's [`Position`] with its heartbeats (the
//! messages robots already send for failure detection) to the teams it is
//! in: to every member of a team it leads, to the leader of the others
//! ([`Kernel::beacon_audience`]). A kernel that hears one
//! ([`Kernel::peer`]):
//!
//! 1. **departures**: marks the teammate *departed* from every frame of its
//!    own stack that the teammate has ended (it shows it ending or ended,
//!    or lists it among the frames it recently left), and every teammate a
//!    team leader reports departed. A departed teammate is left out of
//!    every instance below that frame, exactly like a teammate presumed
//!    lost: no protocol of a descendant ever waits for it. The frame's own
//!    termination still counts it (it waits there);
//! 2. **splits**: compares each of its frames that followed a decision
//!    (the frame has a chain predecessor) with the teammate's frame after
//!    the same predecessor. Another successor is a split: the member
//!    follows the choice of the team's *healing leader* (the lowest-id
//!    member neither presumed lost nor departed from an ancestor), which
//!    every member computes alike, and a `split` event is recorded; a
//!    member that sees a lower-id member on another successor follows it
//!    too (the leader may be on neither side), so choices only move down
//!    the id order and the split closes. The
//!    same successor at another epoch (histories that diverged before)
//!    converges on the higher epoch;
//! 3. **burns**: an execution a member left to converge is *burned*: its
//!    epoch is never used again, by anyone (the burn travels with the
//!    positions), so that no message sent for it can count in a later
//!    execution;
//! 4. **catching up**: a teammate that runs the same execution after a
//!    later execution of its predecessor (cut off, it ran the predecessor
//!    more times) makes the robot burn the executions between, so that
//!    both number the next one alike;
//! 5. **meeting**: a teammate that runs, under the same execution of a
//!    parent, an execution after another predecessor, with neither on the
//!    other's way (the histories diverged while the team was cut apart),
//!    is a split too: the team meets on the side further on (it ran the
//!    common predecessor more times) or else its healing leader's; a robot
//!    that moves burns what it ran since the sides parted;
//! 6. **left behind**: a robot that has waited at a point for a retry and
//!    hears a teammate past it for a retry, with no other teammate still
//!    talking to it from the point, was left out by a team that presumes
//!    it lost (its own messages do not get out): it goes on as they did
//!    (their successor, the end of the behavior, or no part in the
//!    allocation they made) instead of waiting out its deadline.
//!
//! Silent protocols keep their zero-message decisions; healing sends no
//! message of its own (it rides on the heartbeats).

use super::{Frame, Kernel, Phase};
use crate::event::{Event, FrameRef, Via};
use crate::ids::{BehaviorId, RobotId, TeamId};
use crate::ids::{InstanceKey, Kind};
use crate::org::MemberSet;
use crate::time::Time;
use serde::{Deserialize, Serialize};

use crate::mission::slow_wait;

/// How many times one execution of an allocation point is allocated again
/// to converge with teammates that hold another allocation of it (a
/// teammate that keeps a different view of who is alive would otherwise
/// make the team re-allocate forever).
pub const ALLOC_HEALS: u8 = 4;

/// How many recently ended (and burned) executions a position lists.
pub const RECENT: usize = 8;

/// How long a restarted process waits to hear where its team is before it
/// starts the mission from the beginning on its own.
pub const REJOIN_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// How recent a teammate's heartbeat must be for the kernel to count on
/// what it said (that the teammate is still at work on a behavior).
pub const FRESH: std::time::Duration = std::time::Duration::from_secs(3);

/// How long after it left subteams on its own (an individual behavior
/// above them ended, or one that each member ends alone) a robot answers
/// the teammates that still send it heartbeats for one of them (see
/// `Kernel::answer_strangers`).
pub const ANSWER_LEFT: std::time::Duration = std::time::Duration::from_secs(6);

/// How many members, in id order, a robot looks through for the one that
/// relays a team's heartbeats while its leader is away
/// (`Kernel::acting_leader`): a bound on the walk in a large team whose
/// first members are all elsewhere.
const ACTING_WALK: usize = 8;

/// Who leads one of a robot's frames, as its heartbeat needs it
/// ([`Kernel::frame_leaders`]).
#[derive(Clone, Copy, Debug)]
struct FrameLeader {
    /// The member whose choice a split there follows
    /// ([`Kernel::heal_leader`]).
    leader: Option<RobotId>,
    /// The leader is a teammate, and this robot relays the root in its
    /// place ([`Kernel::relays_root`]).
    relays: bool,
}

impl FrameLeader {
    /// True when robot `me` speaks for the frame: it leads it, or relays
    /// the root in its leader's place.
    fn leads(&self, me: RobotId) -> bool {
        self.leader == Some(me) || self.relays
    }
}

/// Identity of one execution of a behavior by a team.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct FrameId {
    /// The team.
    pub team: TeamId,
    /// The behavior.
    pub behavior: BehaviorId,
    /// The team's execution count of it.
    pub epoch: u32,
}

impl FrameId {
    /// The execution whose point instance `key` is.
    pub fn of(key: InstanceKey) -> FrameId {
        FrameId {
            team: key.team,
            behavior: key.behavior,
            epoch: key.epoch,
        }
    }
}

/// What a robot knows of a teammate from its heartbeats.
#[derive(Clone, Debug, Default)]
pub(super) struct Peer {
    /// When it was last heard.
    pub heard: Time,
    /// When its position last changed, or its skill made a step (it makes
    /// progress); none: it was heard only after this robot finished.
    pub moved: MaybeTime,
    /// Its skill's steps, as it last told them ([`Position::progress`]).
    pub progress: u32,
    /// The executions it is engaged in (its position's frames), kept in
    /// the entry up to a stack four deep: a team leader compares every
    /// member's heartbeat with them, and at 100,000 members a vector of
    /// its own was one more cache miss per heartbeat.
    pub frames: smallvec::SmallVec<[(FrameId, FrameState); 4]>,
}

/// What a robot keeps of a teammate it has not heard for longer than
/// [`FRESH`]. Nothing reads such a peer (the audience of a finished
/// robot's heartbeats and the wait for slow teammates read only those
/// heard within [`FRESH`]) until it is heard again, and then only one
/// thing: whether its position changed meanwhile, which says whether it
/// moved. That needs a digest of its frames, not the frames: at 100,000
/// robots each member's leaders of finished subteams, kept whole, were a
/// seventh of a run's memory (docs/performance.md, "2026-11-28, late").
#[derive(Clone, Copy, Debug)]
pub(super) struct Quiet {
    /// [`Peer::moved`].
    moved: MaybeTime,
    /// [`digest`] of [`Peer::frames`] and [`Peer::progress`].
    frames: u64,
}

impl Quiet {
    fn of(p: &Peer) -> Self {
        Quiet {
            moved: p.moved,
            frames: digest(p.frames.iter().copied(), p.progress),
        }
    }
}

/// An optional time in 8 bytes (an `Option<Time>` takes 16): `u64::MAX`,
/// never a time a robot hears a teammate at, is none. A [`Peer`] with it
/// is 128 bytes, and a robot's first four peers fill a 512-byte block
/// instead of a 640-byte one (docs/performance.md, "2026-12-07, tenth
/// session").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct MaybeTime(u64);

impl MaybeTime {
    pub const NONE: MaybeTime = MaybeTime(u64::MAX);
    pub fn get(self) -> Option<Time> {
        (self != Self::NONE).then_some(Time(self.0))
    }
}

impl Default for MaybeTime {
    fn default() -> Self {
        Self::NONE
    }
}

impl From<Time> for MaybeTime {
    fn from(t: Time) -> Self {
        debug_assert_ne!(t, Time::MAX, "not a time a teammate is heard at");
        MaybeTime(t.0)
    }
}

/// A digest of a peer's frames and its skill's steps (SipHash with fixed
/// keys: deterministic, and two different positions share a digest once in
/// 2^64).
fn digest(frames: impl Iterator<Item = (FrameId, FrameState)>, progress: u32) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::hash::DefaultHasher::new();
    for f in frames {
        f.hash(&mut h);
    }
    progress.hash(&mut h);
    h.finish()
}

/// Where a frame of a position is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FrameState {
    /// On the stack: it runs (or runs something below it).
    Running,
    /// Ended here; the robot waits for its termination protocol.
    Ending,
    /// Ended; the robot chooses what follows it.
    Ended,
}

/// What a frame follows: the execution before it in its chain, or, for
/// the first of a chain, the parent execution it runs under. Two members'
/// frames with the same team and anchor are the same step of the mission:
/// they must be the same execution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Anchor {
    /// The behavior before it, or its parent.
    pub behavior: BehaviorId,
    /// That behavior's epoch.
    pub epoch: u32,
    /// True when it is the first of a chain under `behavior`.
    pub first: bool,
}

/// One frame of a position.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PosFrame {
    /// Which execution.
    pub id: FrameId,
    /// What it follows (`None`: the mission's first behavior).
    pub anchor: Option<Anchor>,
    /// Where it is.
    pub state: FrameState,
    /// Its allocation: round and a fingerprint of the subteams it made.
    pub alloc: Option<(u32, u64)>,
    /// Teammates the sender knows to be done with it (sent by the team's
    /// leader, so that every member learns what only the leader hears).
    /// A set over the roster, a bit per robot on the wire: a member reads
    /// what is new to it word by word, so the leader's heartbeat to a team
    /// of n costs each member O(n / 64), not O(n) (a list of 100,000
    /// ids would not even fit in a message).
    pub departed: Option<MemberSet>,
}

/// An execution a robot ended, and the execution it ran under.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ended {
    /// The execution.
    pub id: FrameId,
    /// Its parent (`None`: the mission's first behavior).
    pub parent: Option<FrameId>,
}

/// What a robot runs, as its teammates learn it from its heartbeats.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Position {
    /// The robot whose position it is. A hearer refuses a position that
    /// came as from another robot: one teammate's ended executions
    /// credited to another would mark that one departed from a behavior
    /// it still runs (`Kernel::learn_departures`), and a barrier decide
    /// without it.
    pub robot: RobotId,
    /// Its frames, root first; the last may be one it ended.
    pub frames: Vec<PosFrame>,
    /// Executions it ended recently, oldest first.
    pub ended: Vec<Ended>,
    /// Executions it (or a teammate it heard) burned recently.
    pub burned: Vec<FrameId>,
    /// The version of the mission it runs (0: the one it started with).
    pub version: u32,
    /// The newest version it holds, waiting for a safe point (0: none).
    pub pending: u32,
    /// What it decided or followed at recent safe points while a version
    /// was pending, and what it passes on from teammates (see
    /// `kernel/change.rs`).
    pub fences: Vec<super::change::Fence>,
    /// How many steps its skill has made, wrapping
    /// ([`Kernel::skill_progressed`]): a teammate whose count changes is
    /// getting on with its work though its frames stay the same (a long
    /// sweep), and a barrier waits for it (`Kernel::awaited_at_work`).
    pub progress: u32,
}

impl Default for Position {
    /// An empty position of robot 0.
    fn default() -> Self {
        Position {
            robot: RobotId(0),
            frames: Vec::new(),
            ended: Vec::new(),
            burned: Vec::new(),
            version: 0,
            pending: 0,
            fences: Vec::new(),
            progress: 0,
        }
    }
}

impl Position {
    /// Ask for what a heartbeat's hearer reads of this position beyond its
    /// own fields (its frames, the executions ended and burned) to be
    /// brought into the cache: a large team's leader hears every member's
    /// position, each in allocations of its own (a hint only; see
    /// [`crate::hint`]).
    pub fn prefetch(&self) {
        use crate::hint::prefetch_slice;
        prefetch_slice(&self.frames, 2);
        prefetch_slice(&self.ended, 2);
        prefetch_slice(&self.burned, 1);
    }

    /// True when the sender went through the allocation `key`'s execution:
    /// it ran a child of it (an execution it ended recently ran under that
    /// execution) or runs it with an allocation applied.
    pub fn went_through(&self, key: InstanceKey) -> bool {
        let point = FrameId::of(key);
        self.ended.iter().any(|e| e.parent == Some(point))
            || self
                .frames
                .iter()
                .any(|f| f.id == point && f.alloc.is_some())
    }

    /// True when the sender runs a successor of the sync point `key`: a
    /// behavior of `key`'s team that follows `key`'s execution. It decided
    /// that point.
    pub fn went_past(&self, key: InstanceKey) -> bool {
        self.running_after(FrameId::of(key)).is_some()
    }

    /// The frame the sender runs that follows execution `id` in its chain.
    fn running_after(&self, id: FrameId) -> Option<&PosFrame> {
        self.frames.iter().find(|f| {
            f.id.team == id.team
                && f.anchor
                    .is_some_and(|a| !a.first && a.behavior == id.behavior && a.epoch == id.epoch)
        })
    }

    /// What the sender ran after execution `id` (it decided the sync point
    /// of `id`): the frame it runs that follows `id`, or the execution it
    /// ended next under the same parent (its recent ends are in order, and
    /// the next of a chain ends after its own descendants).
    pub fn successor_of(&self, id: FrameId) -> Option<BehaviorId> {
        if let Some(f) = self.running_after(id) {
            return Some(f.id.behavior);
        }
        let i = self.ended.iter().position(|e| e.id == id)?;
        let parent = self.ended[i].parent;
        // The next of its chain ends after its own descendants.
        let next = self.ended[i + 1..].iter().find(|e| e.parent == parent)?;
        (next.id.team == id.team).then_some(next.id.behavior)
    }

    /// Where the sender is in the execution of `key`'s point: `None` when
    /// it is not engaged in it. `Ended` at a termination point: its
    /// barrier is over; not `Running` at an allocation point: it left the
    /// allocation (a coordinator that leaves decides from what it has).
    pub fn state_at(&self, key: InstanceKey) -> Option<FrameState> {
        let id = FrameId::of(key);
        self.frames.iter().find(|f| f.id == id).map(|f| f.state)
    }

    /// True when the sender is past the termination point `key`: it ended
    /// the execution and chooses what follows, runs what follows, or is
    /// out of the execution and lists it among those it ended (a robot
    /// that finished the mission; one still waiting at the barrier lists
    /// it too, from the moment its own part ended). Its barrier is over,
    /// or it left it.
    pub fn past_barrier(&self, key: InstanceKey) -> bool {
        match self.state_at(key) {
            Some(state) => state == FrameState::Ended || self.went_past(key),
            None => self.went_past(key) || self.ended.iter().any(|e| e.id == FrameId::of(key)),
        }
    }

    /// Its size on the wire, bytes: what [`Position::encode`] writes,
    /// counted field by field in postcard's format (varints, a byte per
    /// `Option` tag, enum variant and `bool`) without serde's walk, which
    /// cost a fifth of a heartbeat sent (a test compares the two on
    /// random positions).
    pub fn encoded_len(&self) -> usize {
        use crate::members::varint_len as v;
        let id = |f: &FrameId| v(f.team.0) + v(f.behavior.0.into()) + v(f.epoch.into());
        let frames: usize = self
            .frames
            .iter()
            .map(|f| {
                id(&f.id)
                    + 1
                    + f.anchor
                        .map_or(0, |a| v(a.behavior.0.into()) + v(a.epoch.into()) + 1)
                    + 1
                    + 1
                    + f.alloc
                        .map_or(0, |(round, print)| v(round.into()) + v(print))
                    + 1
                    + f.departed.as_ref().map_or(0, MemberSet::wire_len)
            })
            .sum();
        let ended: usize = self
            .ended
            .iter()
            .map(|e| id(&e.id) + 1 + e.parent.as_ref().map_or(0, id))
            .sum();
        let burned: usize = self.burned.iter().map(id).sum();
        let fences: usize = self
            .fences
            .iter()
            .map(|f| v(f.version.into()) + id(&f.after) + 1)
            .sum();
        v(self.robot.0.into())
            + v(self.frames.len() as u64)
            + frames
            + v(self.ended.len() as u64)
            + ended
            + v(self.burned.len() as u64)
            + burned
            + v(self.version.into())
            + v(self.pending.into())
            + v(self.fences.len() as u64)
            + fences
            + v(self.progress.into())
    }
    /// Its wire form.
    pub fn encode(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }
    /// Decode a wire form; `None` if malformed or larger than
    /// [`crate::msg::MAX_WIRE_BYTES`]. Never panics.
    pub fn decode(bytes: &[u8]) -> Option<Position> {
        if bytes.len() > crate::msg::MAX_WIRE_BYTES {
            return None;
        }
        postcard::from_bytes(bytes).ok()
    }
    /// True when the position is within the bounds a kernel accepts from
    /// the network (a forged or corrupted one is dropped and counted).
    pub fn is_bounded(&self, roster_len: usize, behaviors: usize) -> bool {
        let ok_id = |id: &FrameId| id.behavior.index() < behaviors && id.epoch > 0;
        self.frames.len() <= crate::graph::MAX_DEPTH + 1
            && self.ended.len() <= RECENT
            && self.burned.len() <= RECENT
            && self
                .ended
                .iter()
                .all(|e| ok_id(&e.id) && e.parent.as_ref().is_none_or(ok_id))
            && self.burned.iter().all(ok_id)
            && self.fences.len() <= 2 * RECENT
            && self.fences.iter().all(|f| ok_id(&f.after))
            && self.frames.iter().all(|f| {
                ok_id(&f.id)
                    && f.anchor
                        .is_none_or(|a| a.behavior.index() < behaviors && a.epoch > 0)
                    && f.departed
                        .as_ref()
                        .is_none_or(|d| d.roster_len() == roster_len)
            })
    }
}

impl Anchor {
    /// True when a frame of team `team` with this anchor is the successor
    /// of execution `id` in its chain: whoever runs it is done with `id`
    /// (ran it, or went past it converging on teammates further on).
    pub fn after(self, team: TeamId, id: FrameId) -> bool {
        !self.first && team == id.team && self.behavior == id.behavior && self.epoch == id.epoch
    }
}

impl PosFrame {
    /// True when this frame is the successor of execution `id` (see
    /// [`Anchor::after`]).
    pub fn follows(&self, id: FrameId) -> bool {
        self.anchor.is_some_and(|a| a.after(self.id.team, id))
    }
}

impl Frame {
    /// The identity of this execution.
    pub fn id(&self) -> FrameId {
        FrameId {
            team: self.team,
            behavior: self.behavior,
            epoch: self.epoch,
        }
    }

    pub(super) fn step_ref(&self) -> FrameRef {
        FrameRef {
            behavior: self.behavior,
            epoch: self.epoch,
        }
    }

    /// Round and fingerprint of the allocation this frame applied.
    pub(super) fn alloc_print(&self) -> Option<(u32, u64)> {
        // FNV-1a over the subteam ids, kept by the (shared) split.
        self.subteams
            .as_ref()
            .filter(|s| !s.is_empty())
            .map(|s| (self.round, s.print()))
    }
}

/// Where one of this robot's frames is: on the stack, or the one it ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Slot {
    Stack(usize),
    Popped,
}

/// The executions a robot ended recently ([`RECENT`] of them, for its
/// heartbeats), with a one-word filter of their ids: a bit per id, set for
/// every one in the list and for a few that left it (a stale bit only
/// sends a lookup to the list). Most ids a heartbeat names are not in it,
/// and the filter answers for those without reading it (a leader asks for
/// every member's heartbeat).
#[derive(Clone, Debug, Default)]
pub(super) struct RecentEnded {
    list: std::collections::VecDeque<Ended>,
    filter: u64,
}

impl RecentEnded {
    pub(super) fn push(&mut self, e: Ended) {
        let bit = filter_bit(&e.id);
        // [`push_recent`], with the filter answering for most ids: one
        // whose bit is clear is not in the list.
        if self.filter & bit != 0 && self.list.contains(&e) {
            return;
        }
        if self.list.len() >= RECENT {
            self.list.pop_front();
        }
        self.list.push_back(e);
        self.filter |= bit;
        if self.filter.count_ones() as usize > 2 * RECENT {
            self.filter = self.list.iter().fold(0, |m, e| m | filter_bit(&e.id));
        }
    }
    /// Whether execution `id` is in the list.
    #[inline]
    pub(super) fn contains(&self, id: &FrameId) -> bool {
        self.filter & filter_bit(id) != 0 && self.list.iter().any(|e| e.id == *id)
    }
    /// Whether execution `e.id`, under parent `e.parent`, is in the list.
    #[inline]
    pub(super) fn contains_ended(&self, e: &Ended) -> bool {
        self.filter & filter_bit(&e.id) != 0 && self.list.iter().any(|x| x == e)
    }
    pub(super) fn is_empty(&self) -> bool {
        self.list.is_empty()
    }
    pub(super) fn iter(&self) -> impl Iterator<Item = &Ended> {
        self.list.iter()
    }
    #[cfg(test)]
    pub(super) fn filter(&self) -> u64 {
        self.filter
    }
}

/// One bit of a 64-bit filter of execution ids.
#[inline]
fn filter_bit(id: &FrameId) -> u64 {
    let h = (id.team.0 ^ (id.team.0 >> 29))
        .wrapping_add(u64::from(id.behavior.0) << 7)
        .wrapping_add(u64::from(id.epoch))
        .wrapping_mul(0x9e37_79b9_7f4a_7c15);
    1 << (h >> 58)
}

pub(super) fn push_recent<T: PartialEq>(ring: &mut std::collections::VecDeque<T>, id: T) {
    if ring.contains(&id) {
        return;
    }
    if ring.len() >= RECENT {
        ring.pop_front();
    }
    ring.push_back(id);
}

impl Kernel {
    /// This robot's position, for its heartbeats.
    pub fn position(&self) -> Position {
        self.position_with(&self.frame_leaders())
    }

    /// Who its next heartbeat goes to ([`Kernel::beacon_audience`]) and
    /// what it says ([`Kernel::position`]), made together: both read who
    /// leads each of its frames, worked out once here for the two (a robot
    /// sends a heartbeat every period, and each leader is the first member
    /// of the team not departed from a frame above). `None`: nobody to
    /// tell, and no position made.
    pub fn beacon(&self) -> Option<(MemberSet, Position)> {
        let leaders = self.frame_leaders();
        let audience = self.audience_with(&leaders);
        (!audience.is_empty()).then(|| (audience, self.position_with(&leaders)))
    }

    /// For each of its frames (the stack's, root first, then the one it
    /// ended), the member whose choice a split there follows
    /// ([`Kernel::heal_leader`]) and, when that is a teammate, whether this
    /// robot relays the root in its place ([`Kernel::relays_root`]).
    fn frame_leaders(&self) -> smallvec::SmallVec<[FrameLeader; 8]> {
        self.frames()
            .map(|(depth, f)| {
                let leader = self.heal_leader(f.team, depth);
                let relays = leader.is_some_and(|l| l != self.me && self.relays_root(f, depth, l));
                FrameLeader { leader, relays }
            })
            .collect()
    }

    /// [`Kernel::position`], with its frames' leaders worked out
    /// ([`Kernel::frame_leaders`]).
    fn position_with(&self, leaders: &[FrameLeader]) -> Position {
        // A robot idle under its top frame (an allocation gave it no part,
        // or it rejoined there after a restart) has ended its part of it:
        // it waits in that frame's termination, and takes no part below.
        let idle = matches!(self.phase, Phase::Idle { .. });
        let top = self.stack.len().saturating_sub(1);
        let leads = |depth: usize| leaders[depth].leads(self.me);
        let mut frames: Vec<PosFrame> = self
            .stack
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let state = if idle && i == top {
                    FrameState::Ending
                } else {
                    FrameState::Running
                };
                self.pos_frame(f, leads(i), state)
            })
            .collect();
        if let Some((f, state)) = self.popped() {
            frames.push(self.pos_frame(f, leads(self.stack.len()), state));
        }
        Position {
            robot: self.me,
            frames,
            ended: self.recent_ended.iter().copied().collect(),
            burned: self.recent_burned.iter().copied().collect(),
            version: self.version,
            pending: self.pending_version().unwrap_or(0),
            fences: self.fences.iter().chain(&self.relayed).copied().collect(),
            progress: self.progress,
        }
    }

    /// The runtime's word that this robot's skill made a step toward its
    /// end (a sweep came nearer its next waypoint, a robot nearer the goal
    /// it drives to: finitely many between two changes of its stack). Its
    /// heartbeats say so, and a teammate waiting for it at a barrier waits
    /// on while it keeps making them, however long it works (see
    /// `Kernel::awaited_at_work`). The timed world's skills make none.
    pub fn skill_progressed(&mut self) {
        self.progress = self.progress.wrapping_add(1);
    }

    /// Frame `f` as its heartbeat tells it; `leads`: this robot leads it
    /// (or relays the root in its leader's place).
    pub(super) fn pos_frame(&self, f: &Frame, leads: bool, state: FrameState) -> PosFrame {
        PosFrame {
            id: f.id(),
            anchor: f.anchor,
            state,
            alloc: f.alloc_print(),
            departed: match (&f.departed, leads) {
                // A frame it ended: its members learn that the leader
                // departed it from the frame's state anyway; listing it
                // too lets them keep this report as it is (one set shared
                // by the team) instead of a roster-sized copy each.
                (d, true) if state != FrameState::Running => {
                    let mut d = d
                        .clone()
                        .unwrap_or_else(|| MemberSet::empty(self.org.roster_len()));
                    d.insert(self.me);
                    Some(d)
                }
                (Some(d), true) if !d.is_empty() => Some(d.clone()),
                _ => None,
            },
        }
    }

    /// Every frame this robot runs, with its depth: the stack's, root
    /// first, then the one it ended ([`Kernel::popped`]), one deeper.
    pub(super) fn frames(&self) -> impl Iterator<Item = (usize, &Frame)> + '_ {
        (self.stack.iter().enumerate()).chain(self.popped().map(|(f, _)| (self.stack.len(), f)))
    }

    /// The frame this robot ended and is terminating or choosing a
    /// successor for, if any.
    pub(super) fn popped(&self) -> Option<(&Frame, FrameState)> {
        match &self.phase {
            Phase::Terminating { frame, .. } => Some((frame, FrameState::Ending)),
            Phase::Selecting { frame, .. } => Some((frame, FrameState::Ended)),
            _ => None,
        }
    }

    /// Who this robot's heartbeats go to: every member of the teams it
    /// leads, and the leader of each other team it is in (and, while that
    /// leader is away from the team, or behind the point this robot waits
    /// at, or departed from the execution of the allocation this robot
    /// waits at, the member that relays for it: `Kernel::acting_leader`).
    pub fn beacon_audience(&self) -> MemberSet {
        self.audience_with(&self.frame_leaders())
    }

    /// [`Kernel::beacon_audience`], with its frames' leaders worked out
    /// ([`Kernel::frame_leaders`]).
    fn audience_with(&self, leaders: &[FrameLeader]) -> MemberSet {
        let mut to = MemberSet::empty(self.org.roster_len());
        let frames = self.frames();
        // The frame this robot waits at, if any (its end, or its
        // allocation).
        let waiting = match self.phase {
            Phase::Terminating { .. } | Phase::Selecting { .. } => Some(self.stack.len()),
            Phase::Allocating(_) => self.stack.len().checked_sub(1),
            _ => None,
        };
        let allocating = matches!(self.phase, Phase::Allocating(_));
        for (depth, f) in frames {
            let t = f.team;
            let Some(team) = self.org.team(t) else {
                continue;
            };
            let FrameLeader { leader, relays } = leaders[depth];
            match leader {
                Some(l) if l == self.me => to.union_with(&team.members),
                Some(_) if relays => to.union_with(&team.members),
                Some(l) => {
                    to.insert(l);
                    // At the allocation it waits at, a leader departed
                    // from the execution (it left it and went on) relays
                    // nothing of it: the members still in it would not
                    // hear each other (docs/reliability.md, "A coordinator
                    // that left undecided, unheard"). At a termination,
                    // members done with their part are departed from it
                    // as a matter of course.
                    let left = |r: RobotId| {
                        allocating && f.departed.as_ref().is_some_and(|d| d.contains(r))
                    };
                    let away = |r: RobotId| {
                        self.absent_from(r, t, f.started)
                            || (waiting == Some(depth) && (self.behind(r, f) || left(r)))
                            || self.passed_by(r, depth, f)
                    };
                    if away(l) {
                        match self.acting_leader(t, depth, away) {
                            Some(a) if a == self.me => to.union_with(&team.members),
                            Some(a) => {
                                to.insert(a);
                            }
                            None => {}
                        }
                    }
                }
                None => {}
            }
        }
        // Teammates counted at a point whose deadline fell unheard (see
        // `Kernel::call_unheard`).
        if let Some((set, until)) = self.calling.as_deref()
            && self.now < *until
        {
            to.union_with(set);
        }
        // Teammates that count it in a team it is not in, while they
        // still send to it (see `Kernel::answer_strangers`).
        if let Some(a) = &self.answering {
            for r in a.iter() {
                if self.fresh_peer(r).is_some() {
                    to.insert(r);
                }
            }
        }
        // A robot that finished the mission tells that it did (its
        // position lists the root behavior ended) to the root team's
        // leader, which relays it to every member with its own heartbeats,
        // and answers whoever still sends it heartbeats: a leader waiting
        // for it, or a member whose leader it is. Nobody waits for it below
        // the root any more, and the cost stays linear in the team (a
        // beacon to the whole team from every finished robot would be
        // quadratic).
        if self.stack.is_empty() && matches!(self.phase, Phase::Finished) {
            for (r, p) in self.peers.iter() {
                if self.now - p.heard <= FRESH {
                    to.insert(r);
                }
            }
            if let Some(l) = self.heal_leader(TeamId::ROOT, 0) {
                to.insert(l);
            }
        }
        to.remove(self.me);
        to
    }

    /// True when teammate `r`, heard within [`FRESH`] and since `since`
    /// (when this robot took up the behavior it runs in team `t`), runs
    /// nothing in team `t`: it is a lap behind on its way there, or
    /// elsewhere. (A heartbeat from before may predate its joining.)
    fn absent_from(&self, r: RobotId, t: TeamId, since: Time) -> bool {
        (self.fresh_peer(r))
            .is_some_and(|p| p.heard >= since && !p.frames.iter().any(|(f, _)| f.team == t))
    }

    /// True when a teammate's execution `g`, at depth `k` under execution
    /// `parent`, is behind on this robot's way: this robot runs `parent`
    /// at depth `k - 1` and, under it, started `g` or a later execution of
    /// the same behavior in the same team (epochs count a team's
    /// executions of a behavior), and neither runs `g` at depth `k` nor
    /// abandoned it. The ends a robot remembers are bounded ([`RECENT`]);
    /// under `term.local` a teammate may be any number of behaviors
    /// behind.
    pub(super) fn passed(&self, k: usize, parent: FrameId, g: FrameId) -> bool {
        let Some(p) = k.checked_sub(1).and_then(|i| self.stack.get(i)) else {
            return false;
        };
        p.id() == parent
            && p.runs.latest_epoch(g.behavior) >= g.epoch
            && self
                .slot_at(k)
                .is_some_and(|(_, f)| f.team == g.team && f.id() != g)
            && !self.recent_burned.contains(&g)
    }

    /// True when a teammate's execution `g` at depth `k`, beside this
    /// robot's execution `m` there in the same team and under the same
    /// parent execution, is one this robot has yet to start: its epoch is
    /// past the latest this robot started of that behavior under the
    /// parent (the mirror of [`Kernel::passed`]).
    fn ahead(&self, k: usize, m: FrameId, g: FrameId) -> bool {
        m.team == g.team
            && k.checked_sub(1)
                .and_then(|i| self.stack.get(i))
                .is_some_and(|p| p.runs.latest_epoch(g.behavior) < g.epoch)
    }

    /// True when a teammate's execution `g`, at depth `k` under execution
    /// `parent`, leads into the execution this robot runs there: this
    /// robot runs `parent` at depth `k - 1` and, under it in `g`'s team,
    /// another execution of a behavior `g`'s behavior is followed by (a
    /// sequential edge). The two took different successors of a point
    /// where each decides alone (`sync.by-rule`, a precondition that held
    /// for one of them), and the teammate is on its way. A teammate that
    /// went through this robot's execution is departed from it and not
    /// waited for.
    ///
    /// From an individual behavior (`team: false`) the way may be longer:
    /// each member numbers its runs of it at its own pace, so a teammate's
    /// epoch there says nothing of where it is beside this robot
    /// ([`Kernel::passed`] cannot tell), and one still in it is on its way
    /// into any behavior its sequential edges lead to (a robot that ran
    /// it sooner went on through `b2` into `b3`, where it waits for a
    /// teammate still in its run of `b1`).
    ///
    /// From an execution of a team behavior this robot never ran under
    /// the parent the way may be longer too: the teammate took another
    /// successor of a point before, and its way leads into this robot's
    /// behavior through others (a loop `b5`, then `alt8` or `b6`, then
    /// `b7`, then `b5` again: a teammate in `b6`#1 beside this robot's
    /// `b5`#2, reached through `alt8`#1 and `b7`#1, is on its way;
    /// property seed 6286, where the leader, slow in `b5`#1's subtree,
    /// then in `b6`#1, was taken for silent at `b5`#2's auction). Its epoch cannot say which lap it is
    /// on (this robot never numbered that behavior), so it is waited for
    /// as one behind is: while it makes progress, for a bounded number of
    /// deadlines ([`Kernel::awaited_at_work`]).
    ///
    /// Not a later execution of the behavior this robot's execution came
    /// after ([`Kernel::round_past`]): that teammate went round past it.
    fn leads_into(&self, k: usize, parent: FrameId, g: FrameId) -> bool {
        let graph = self.graph();
        let Some(p) = k.checked_sub(1).and_then(|i| self.stack.get(i)) else {
            return false;
        };
        p.id() == parent
            && graph.get(g.behavior).is_some_and(|b| {
                self.slot_at(k).is_some_and(|(_, f)| {
                    f.team == g.team
                        && f.id() != g
                        && (b.next.contains(&f.behavior)
                            || ((graph.is_individual(g.behavior)
                                || p.runs.latest_epoch(g.behavior) == 0)
                                && graph.leads_to(g.behavior, f.behavior)))
                })
            })
            && !self.round_past(k, g)
    }

    /// True when a teammate's execution `g` at depth `k` is a later
    /// execution of the behavior this robot's execution there came after
    /// (its anchor: `b3`#2 beside this robot's `b1`#2, which came after
    /// `b3`#1), a behavior whose only successor is this robot's. Every way
    /// from that behavior's executions leads into this robot's behavior,
    /// so the teammate went round past this robot's execution, running it
    /// or converging past it, and is not on its way into it
    /// (docs/reliability.md, "A teammate gone round past the execution").
    /// With another successor it might be: it may have gone round another
    /// way and come to this execution's epoch later.
    ///
    /// Not from an individual behavior (`team: false`): each member
    /// numbers its runs of one at its own pace, so a higher epoch there
    /// says nothing of a lap (docs/reliability.md, "Laps of an individual
    /// behavior taken for laps past").
    pub(super) fn round_past(&self, k: usize, g: FrameId) -> bool {
        self.slot_at(k).is_some_and(|(_, f)| {
            f.team == g.team
                && f.anchor
                    .is_some_and(|a| !a.first && a.behavior == g.behavior && a.epoch < g.epoch)
                && (self.graph().get(g.behavior))
                    .is_some_and(|b| b.team && b.next[..] == [f.behavior])
        })
    }

    /// True when frame `f` (at depth `depth`) came after a point with
    /// several successors, and teammate `r`, heard within [`FRESH`] since
    /// this robot took `f` up, runs under the same parent execution an
    /// execution of `f`'s team this robot went past ([`Kernel::passed`]):
    /// it is behind on this robot's way, however many behaviors back.
    /// Members that went on past such a leader and chose apart there (each
    /// alone: a silent rule, a precondition that held for some of them, an
    /// individual behavior) heard only the leader, not each other, and
    /// the split stayed unseen until the leader came (docs/reliability.md,
    /// "Members ahead of their leader"). After a point with one successor
    /// nobody chooses, and a team in step sends nothing more.
    fn passed_by(&self, r: RobotId, depth: usize, f: &Frame) -> bool {
        let Some(a) = f.anchor.filter(|a| !a.first) else {
            return false;
        };
        if !self.splits_after(a.behavior) {
            return false;
        }
        let Some(parent) = depth.checked_sub(1).and_then(|i| self.stack.get(i)) else {
            return false;
        };
        let parent = parent.id();
        self.fresh_peer(r).is_some_and(|p| {
            p.heard >= f.started
                && p.frames.get(depth - 1).is_some_and(|(g, _)| *g == parent)
                && p.frames
                    .get(depth)
                    .is_some_and(|(g, _)| g.team == f.team && self.passed(depth, parent, *g))
        })
    }

    /// True when behavior `b` has several successors: a point after which
    /// members may choose apart.
    fn splits_after(&self, b: BehaviorId) -> bool {
        self.graph().get(b).is_some_and(|b| b.next.len() >= 2)
    }

    /// Teammate `r`'s entry, if it was heard within [`FRESH`].
    pub(super) fn fresh_peer(&self, r: RobotId) -> Option<&Peer> {
        self.peers.get(&r).filter(|p| self.now - p.heard <= FRESH)
    }

    /// True when teammate `r`, heard within [`FRESH`] since this robot
    /// took up frame `f`, still runs the execution before `f` in its
    /// team's sequence: it has not reached the point this robot waits at
    /// past it.
    fn behind(&self, r: RobotId, f: &Frame) -> bool {
        let Some(a) = f.anchor.filter(|a| !a.first) else {
            return false;
        };
        let before = FrameId {
            team: f.team,
            behavior: a.behavior,
            epoch: a.epoch,
        };
        (self.fresh_peer(r))
            .is_some_and(|p| p.heard >= f.started && p.frames.iter().any(|(g, _)| *g == before))
    }

    /// The member of team `t` (at stack depth `depth`) that relays the
    /// team's heartbeats while its leader is `away`
    /// ([`Kernel::absent_from`], or, at the point this robot waits at,
    /// [`Kernel::behind`]): the lowest-id member neither presumed lost,
    /// departed, nor itself away, looked for among the first
    /// [`ACTING_WALK`] members not left out, the leader first (`None`
    /// beyond). Its members' heartbeats go to the
    /// leader and to it, and it sends its own to every member, as a leader
    /// does: without it the members already there hear only the leader,
    /// which is not, and not each other. Two of them that took the team
    /// from different allocation views (two ids for one subteam) then
    /// learnt of the split only from the leader's arrival, after a
    /// deadline of theirs (docs/reliability.md, "A leader a lap behind").
    fn acting_leader(
        &self,
        t: TeamId,
        depth: usize,
        away: impl Fn(RobotId) -> bool,
    ) -> Option<RobotId> {
        let team = self.org.team(t)?;
        let above = &self.stack[..depth.min(self.stack.len())];
        let gone = |r: RobotId| {
            self.lost.contains(r)
                || above
                    .iter()
                    .any(|f| f.departed.as_ref().is_some_and(|d| d.contains(r)))
        };
        team.members
            .iter()
            .filter(|r| !gone(*r))
            .take(ACTING_WALK)
            .find(|r| *r == self.me || !away(*r))
    }

    /// The member of team `t` whose choice a split at stack depth `depth`
    /// follows: the lowest-id member neither presumed lost nor departed
    /// from a frame above that depth.
    pub(super) fn heal_leader(&self, t: TeamId, depth: usize) -> Option<RobotId> {
        let team = self.org.team(t)?;
        let above = &self.stack[..depth.min(self.stack.len())];
        team.members.first_not_in(self.me, || {
            std::iter::once(&self.lost).chain(above.iter().filter_map(|f| f.departed.as_ref()))
        })
    }

    /// True when this robot relays the root team's departures (frame `f`
    /// at depth `depth`, the root) in place of its leader, which finished
    /// the mission (it left the root and is heard with no frame): the
    /// lowest-id member neither presumed lost nor departed from the root.
    /// A robot that finished runs no frame and relays nothing, so members
    /// learnt of teammates that finished after it only if those sent to
    /// them; members that knew different finished teammates left different
    /// ones out of their silent allocations, round after round
    /// (docs/reliability.md, "A root leader that finished"). Its members
    /// still send to the leader (see [`Kernel::heal_leader`]); a leader
    /// waiting at the root's end still relays itself. `leader`: the
    /// frame's [`Kernel::heal_leader`], already worked out.
    fn relays_root(&self, f: &Frame, depth: usize, leader: RobotId) -> bool {
        if depth != 0 || f.team != TeamId::ROOT {
            return false;
        }
        let Some(departed) = &f.departed else {
            return false;
        };
        let Some(team) = self.org.team(f.team) else {
            return false;
        };
        let finished = |r: RobotId| {
            departed.contains(r) && self.fresh_peer(r).is_some_and(|p| p.frames.is_empty())
        };
        leader != self.me
            && finished(leader)
            && team
                .members
                .first_not_in(self.me, || [&self.lost, departed].into_iter())
                == Some(self.me)
    }

    /// A teammate's position, heard with its heartbeat: learn who departed
    /// what, heal splits, honour burns (see the module documentation).
    pub fn peer(&mut self, now: Time, from: RobotId, pos: &Position) {
        self.set_now(now);
        if from == self.me {
            return;
        }
        // Bounded first (lengths, epochs); behaviors of a version this
        // robot does not run yet are then left out of what it reads.
        if from.index() >= self.org.roster_len()
            || !pos.is_bounded(self.org.roster_len(), u32::MAX as usize)
        {
            return self.drop_msg(from, crate::event::DropReason::Malformed);
        }
        if pos.robot != from {
            return self.drop_msg(from, crate::event::DropReason::Misattributed);
        }
        self.peer_version(from, pos);
        if self.awaiting_rejoin() {
            self.rejoin_version(pos);
        }
        let readable = self.readable(pos);
        let pos = readable.as_ref().unwrap_or(pos);
        if self.awaiting_rejoin() {
            self.adopt(from, pos);
            self.step();
            return;
        }
        if matches!(self.phase, Phase::NotStarted) {
            return;
        }
        if matches!(self.phase, Phase::Finished) {
            // Only who still sends heartbeats matters now: they get an
            // answer (see `beacon_audience`).
            let quiet = &mut self.quiet;
            let roster_len = self.org.roster_len();
            let p = self.peers.get_or_insert_with(from, roster_len, || Peer {
                moved: quiet.remove(&from).map_or(MaybeTime::NONE, |q| q.moved),
                ..Peer::default()
            });
            if let Some(p) = p {
                p.heard = self.now;
                p.frames.clear();
            }
            return;
        }
        self.stats.positions += 1;
        // What it is engaged in, compared and kept in place (no vector
        // made per heartbeat: a team leader hears one from every member).
        let engaged = || pos.frames.iter().map(|f| (f.id, f.state));
        let now = self.now;
        match self.peers.get_mut(&from) {
            Some(p) => {
                p.heard = now;
                if !p.frames.iter().copied().eq(engaged()) {
                    p.frames.clear();
                    p.frames.extend(engaged());
                    p.moved = now.into();
                }
                if p.progress != pos.progress {
                    p.progress = pos.progress;
                    p.moved = now.into();
                }
            }
            None => {
                // Heard again after a while: it moved if its frames changed
                // or its skill made steps.
                let moved = match self.quiet.remove(&from) {
                    Some(q) if q.frames == digest(engaged(), pos.progress) => q.moved,
                    _ => now.into(),
                };
                self.peers.insert(
                    from,
                    Peer {
                        heard: now,
                        moved,
                        progress: pos.progress,
                        frames: engaged().collect(),
                    },
                    self.org.roster_len(),
                );
            }
        }
        self.answer_strangers(from, pos);
        self.apply_burns(pos);
        self.count_past(pos);
        self.count_renamed(pos);
        self.catch_up(pos);
        self.learn_departures(from, pos);
        if !self.reconcile(from, pos, false) && !self.meet(from, pos) {
            self.reconcile(from, pos, true);
        }
        self.reconcile_allocation(from, pos);
        self.ask_past_point(from, pos);
        self.heard_waiting(from, pos);
        self.take_back(from, pos);
        self.follow_past(from, pos);
        self.step();
    }

    /// A teammate sends this robot its heartbeats for a team the robot is
    /// not in: the teammate counts it a member there (it leads the team,
    /// or it is the leader the teammate computes), but the robot left the
    /// team, or has not joined it yet. Its own heartbeats go to the teams
    /// it is in, so the teammate does not hear where it is:
    ///
    /// - **left**: the behavior above the team ended for this robot alone
    ///   (an individual behavior, or one each member ends on its own). Its
    ///   teammates do not learn it left; when it was the team's leader,
    ///   the members keep sending their heartbeats to it, no member hears
    ///   another, and a teammate a lap behind on its way to a point is
    ///   taken for silent: the point's deadline decides;
    /// - **not yet joined**: the teammate went through an allocation this
    ///   robot, a lap behind, has yet to make, and waits for it at the new
    ///   team's first point without hearing it on its way;
    /// - **ended**: the teammate waits at a point below an execution this
    ///   robot has ended (its own condition, under a termination each
    ///   member makes alone), or gone past (it converged onto a
    ///   teammate's execution after it: [`Kernel::passed`]); the team's
    ///   leader, past it too, does not report that this robot left it,
    ///   and the teammate waits for it;
    /// - **behind**: the teammate waits at a point after the execution
    ///   this robot runs (its frame there is that execution's successor:
    ///   this robot is slower in an individual behavior, or was cut off),
    ///   and may wait for it; its heartbeats go to the team's leader, which
    ///   may be elsewhere, and the teammate took it for silent;
    /// - **laps behind**: the same, with the teammate's execution there
    ///   any number of behaviors ahead (an execution of the team this
    ///   robot has yet to start: under `term.local` a robot may go round a
    ///   cycle again while a teammate still runs a long chain of the lap
    ///   before). Once the team's leader has gone by too, the teammate
    ///   leads the point and waits for this robot without hearing it;
    /// - **at work, its leader unheard**: the teammate waits at the point
    ///   of an execution this robot still runs, and sends to it as its
    ///   leader there, while this robot sends to a leader it does not hear
    ///   (the two counted different teammates departed above: an
    ///   individual behavior ended for the lowest ids, each heard by only
    ///   some of the others).
    ///
    /// So it answers such a teammate with its own heartbeats
    /// (`beacon_audience`) while the teammate goes on sending them: the
    /// teammate marks it departed, or waits on for it while it is on its
    /// way (`awaited_at_work`). A team it left is answered for
    /// [`ANSWER_LEFT`] (a leader that learnt of the departure still
    /// sends its heartbeats to every member, and an answer must not go on
    /// for ever), and after that while the teammate waits at a point (a
    /// robot that ended the team behavior above by its own condition,
    /// ahead of its team, left the subteam without telling, and the
    /// subteam's leader may reach a later point of the subteam long
    /// after: property seed 5212); a team it has yet to join, or an
    /// execution it ended, only while the teammate waits at a point. A
    /// team that ends a behavior together learns who ended it from its
    /// termination protocol, and a teammate at work waits for nobody:
    /// neither is answered, so a team in step sends nothing more.
    fn answer_strangers(&mut self, from: RobotId, pos: &Position) {
        // Only a teammate waiting at a point waits for this robot: it
        // ended its last frame, or that frame is an allocation point not
        // allocated yet.
        let waits = || {
            let g = self.graph();
            pos.frames.last().is_some_and(|f| {
                f.state != FrameState::Running
                    || (f.alloc.is_none()
                        && f.id.behavior.index() < g.len()
                        && g.is_alloc_point(f.id.behavior))
            })
        };
        // Read along the sender's frames beside this robot's, root first;
        // most heartbeats run where this robot does, and only compare ids.
        // - The first execution the two do not share: one this robot ended
        //   (the sender waits below it, behind this robot, and may wait
        //   for it there: its team's leader, past it too, does not tell).
        // - The first frame in a team this robot's organization does not
        //   hold (deeper frames run under it): one it left, or has yet to
        //   join. A frame in the team of this robot's frame at the same
        //   depth is not looked up.
        // (Not `Kernel::frames`: its opaque iterator would hold `self` to
        // the end of the function, and `answering` is changed below.)
        let mut mine = self
            .stack
            .iter()
            .chain(self.popped().map(|(f, _)| f))
            .map(Frame::id);
        let mut shared = true;
        let mut stranger = false;
        for (k, f) in pos.frames.iter().enumerate() {
            let m = mine.next();
            if m == Some(f.id) {
                // - Or the execution this robot runs, which the sender ended
                //   and leads the end of, not being the leader this robot
                //   sends to there: the two counted different teammates
                //   departed above it, and the sender waits for it unheard.
                // - Or the execution this robot still runs, whose point the
                //   sender waits at (it ended it by its own condition, or
                //   its chain, while this robot works on below), while
                //   the leader this robot sends to there is not heard: the
                //   two counted different teammates departed above it (an
                //   individual behavior ended for some, each heard by only
                //   some of the others), this robot's heartbeats go to a
                //   teammate gone elsewhere, and the sender, sending to
                //   this robot as its leader, took it for silent.
                let here = f.state != FrameState::Running && k < self.stack.len();
                let leader = || self.heal_leader(f.id.team, k);
                if here
                    && ((f.departed.is_some() && leader() != Some(from))
                        || (k + 1 == pos.frames.len()
                            && leader().is_some_and(|l| {
                                l != self.me && l != from && self.fresh_peer(l).is_none()
                            })))
                {
                    stranger = true;
                    break;
                }
                continue;
            }
            // - Or the successor of the execution this robot runs there, or
            //   a later execution in the same team under the same parent:
            //   the sender went on (this robot is behind, in an individual
            //   behavior, or was cut off), and may wait for it further on.
            let first = std::mem::take(&mut shared);
            if first
                && (self.recent_ended.contains(&f.id)
                    || m.is_some_and(|m| f.follows(m) || self.ahead(k, m, f.id))
                    || (k.checked_sub(1).and_then(|p| pos.frames.get(p)))
                        .is_some_and(|p| self.passed(k, p.id, f.id)))
                && waits()
            {
                stranger = true;
                break;
            }
            // - Or the successor of the execution this robot runs there,
            //   at a point where each member may choose alone, while this
            //   robot does not lead the team: the sender went on past it
            //   (and past the team's leader, or it would not send here),
            //   and took this robot for the member that relays the team
            //   (`Kernel::acting_leader`: unheard, it is not known to be
            //   behind). Answered, the sender learns it is behind and
            //   looks further, until the members past the point find the
            //   lowest of them; without it two members that chose apart
            //   there heard only those behind them, and ran their two
            //   successors side by side until the leader came
            //   (docs/reliability.md, "Members past a split, unheard").
            if first
                && k > 0
                && m.is_some_and(|m| f.follows(m) && self.splits_after(m.behavior))
                && self.heal_leader(f.id.team, k) != Some(self.me)
            {
                stranger = true;
                break;
            }
            if m.is_some_and(|m| m.team == f.id.team) || self.org.team(f.id.team).is_some() {
                continue;
            }
            stranger = (self.org.is_dead(f.id.team)
                && self.left_at.is_some_and(|at| self.now - at <= ANSWER_LEFT))
                || waits();
            break;
        }
        if stranger {
            let n = self.org.roster_len();
            self.answering
                .get_or_insert_with(|| Box::new(MemberSet::empty(n)))
                .insert(from);
        } else if let Some(a) = &mut self.answering
            && a.contains(from)
        {
            a.remove(from);
            if a.is_empty() {
                self.answering = None;
            }
        }
    }

    /// Left behind: a robot that has waited at a point for longer than a
    /// retry hears teammates past that point for a retry, while no other
    /// teammate it waits for there still talks to it from the point (heard
    /// within two retries engaged there). The team decided without it: it
    /// presumes this robot lost, its own messages do not get out (a
    /// one-way link, heavy loss), and no message of its own (a vote, a
    /// report, a query) will reach them before its deadline. A teammate
    /// that no longer sends this robot its heartbeats, though alive, has
    /// another leader: it presumes this robot lost too. So the robot goes
    /// on as the team did instead of waiting the deadline out, and a
    /// `left_behind` event says so:
    ///
    /// - at a synchronization point it takes the successor the teammate
    ///   ran after it;
    /// - at a barrier it ends the behavior;
    /// - at an allocation the teammate went through, the team allocated
    ///   without it, and its part cannot be read from a heartbeat: it
    ///   leaves the allocation and idles under the behavior until the
    ///   behavior ends (by its condition, or at the team's barrier), and
    ///   does not allocate it again to join the team there (its teammates
    ///   would not hear that either). When the teammate is its own
    ///   coordinator, it most likely has a part whose decision was lost,
    ///   and asks for it (`ask_past_point`): it waits six retries, not
    ///   one, before it gives up.
    fn follow_past(&mut self, from: RobotId, pos: &Position) {
        use crate::interaction::Outcome;
        // Only a robot at a point waits there (a robot that runs, the
        // common case of a heartbeat, returns here).
        let allocating = match self.phase {
            Phase::Allocating(k) => Some(k),
            Phase::Terminating { .. } | Phase::Selecting { .. } | Phase::Idle { .. } => None,
            _ => return,
        };
        let now = self.now;
        let mut past = None;
        for (key, inst) in self.instances.iter() {
            if !inst.waited_a_retry(now) || !inst.team.contains(from) || inst.excludes(from) {
                continue;
            }
            let outcome = match (key.kind, &inst.input) {
                (Kind::Sync, super::PointInput::Sync { successors, .. }) => pos
                    .successor_of(FrameId::of(key))
                    .filter(|b| successors.contains(b))
                    .map(|b| Some(Outcome::Sync(Some(b)))),
                (Kind::Terminate, _) => pos
                    .past_barrier(key)
                    .then_some(Some(Outcome::Terminate(None))),
                (Kind::Allocate, _) => {
                    (allocating == Some(key) && pos.went_through(key)).then_some(None)
                }
                _ => None,
            };
            if let Some(o) = outcome {
                // A robot its own coordinator went through an allocation
                // without has a part it missed, most likely (the decision
                // was lost), and asks for it (`ask_past_point`): it gives
                // up only after six retries of asking unanswered.
                let patience = match key.kind {
                    Kind::Allocate if self.coordinator(key, inst) == Some(from) => 6,
                    _ => 1,
                };
                past = Some((key, inst.retry.get(), patience, o));
                break;
            }
        }
        let Some((key, retry, patience, outcome)) = past else {
            return;
        };
        // Teammates past it for a retry: a decision sent to this robot (a
        // release, a reply to its query) has arrived by then, and the
        // heartbeat that overtook it changes nothing. Then the team is
        // looked at, once a retry at most.
        match self.left_behind {
            Some((k, since)) if k == key => {
                if now - since < retry * patience {
                    return;
                }
                self.left_behind = Some((key, now));
            }
            _ => {
                self.left_behind = Some((key, now));
                return;
            }
        }
        let Some(inst) = self.instances.get(&key) else {
            return;
        };
        let id = FrameId::of(key);
        // Still at the point (or on its way there): engaged in the
        // execution, or, at an allocation, not below it yet.
        let at_point = |frames: &[(FrameId, FrameState)]| match key.kind {
            Kind::Allocate => frames.last().is_some_and(|(f, _)| *f == id),
            _ => frames.iter().any(|(f, _)| *f == id),
        };
        let waits_here = |r: RobotId| {
            r != self.me
                && r != from
                && self.counted(inst, r)
                && self
                    .peers
                    .get(&r)
                    .is_some_and(|p| now - p.heard <= retry * 2 && at_point(&p.frames))
        };
        if inst.team.members.iter().any(waits_here) {
            return;
        }
        self.left_behind = None;
        self.emit(Event::LeftBehind {
            instance: key,
            member: from,
        });
        match outcome {
            Some(o) => self.force(key, o),
            None => {
                self.abort_quietly(key);
                if let Some(top) = self.stack.last_mut() {
                    top.left_behind = true;
                }
                self.idle_under_top();
            }
        }
    }

    /// A teammate back from being presumed lost whose heartbeat shows it
    /// engaged in a synchronization or allocation instance this robot
    /// started without it (it was presumed lost then): the instance takes
    /// it back, and its protocol is told that the members changed (a new
    /// leader gets this robot's contribution). Members that started the
    /// same instance with different views named different coordinators,
    /// and waited out the deadline (docs/reliability.md, "Two
    /// coordinators after a heal"). A member that left the behavior above
    /// is not taken back, and a robot that coordinates the instance takes
    /// no one back.
    fn take_back(&mut self, from: RobotId, pos: &Position) {
        if !self.ever_lost.contains(from) || self.lost.contains(from) {
            return;
        }
        let depth = self.stack.len();
        let mut back = Vec::new();
        for (key, inst) in self.instances.iter() {
            // Not where this robot coordinates: a coordinator decides with
            // the members it has (the protocols move a lead only to a
            // member when the one before it is lost, never away from a
            // robot that leads).
            if inst.state != super::State::Active
                || !matches!(key.kind, Kind::Sync | Kind::Allocate)
                || !inst.excludes(from)
                || !inst.team.contains(from)
                || self.coordinator(key, inst) == Some(self.me)
            {
                continue;
            }
            let id = FrameId::of(key);
            let engaged = pos.frames.iter().any(|f| {
                f.id == id
                    && match key.kind {
                        // At the point, not past it.
                        Kind::Sync => f.state == FrameState::Ended,
                        // In the allocation, not through this round.
                        _ => {
                            f.state == FrameState::Running
                                && f.alloc.is_none_or(|(round, _)| round < key.round)
                        }
                    }
            });
            if engaged && !pos.went_past(key) {
                back.push(key);
            }
        }
        for key in back {
            let above = match key.kind {
                Kind::Allocate => depth.saturating_sub(1),
                _ => depth,
            };
            if Frame::any_left_by(&self.stack[..above], from) {
                continue;
            }
            if let Some(x) = self
                .instances
                .get_mut(&key)
                .and_then(|i| i.excluded.as_mut())
            {
                x.remove(from);
            }
            self.call(key, |imp, cx| imp.on_members_changed(cx));
        }
    }

    /// A teammate whose heartbeats have shown it waiting at a termination
    /// point this robot coordinates, for a retry interval at least (its
    /// engagement unchanged that long), has reported its end: its report
    /// was sent when it began to wait, and arrives within a trip unless it
    /// was lost. Tell the protocol ([`Interaction::on_member_waiting`]),
    /// which counts it as arrived if it has not heard it: under heavy loss
    /// a member backs off between resends, and a barrier whose every
    /// member had arrived waited out its deadline (docs/reliability.md,
    /// "A report lost on the way to the barrier"). A run without faults
    /// hears every report long before: nothing changes there.
    ///
    /// [`Interaction::on_member_waiting`]: crate::interaction::Interaction::on_member_waiting
    fn heard_waiting(&mut self, from: RobotId, pos: &Position) {
        // Only the last frame of a position can be one it waits at (the
        // one it ended, or the top it idles under).
        let Some(f) = pos.frames.last().filter(|f| f.state == FrameState::Ending) else {
            return;
        };
        let key = InstanceKey {
            team: f.id.team,
            behavior: f.id.behavior,
            kind: Kind::Terminate,
            epoch: f.id.epoch,
            round: 0,
        };
        let now = self.now;
        let Some(inst) = self.instances.get(&key) else {
            return;
        };
        let waiting_long = (self.peers.get(&from))
            .and_then(|p| p.moved.get())
            .is_some_and(|t| now - t >= inst.retry.get());
        if !waiting_long
            || !matches!(inst.state, super::State::Armed | super::State::Active)
            || !inst.team.contains(from)
            || self.coordinator(key, inst) != Some(self.me)
        {
            return;
        }
        self.call(key, |imp, cx| imp.on_member_waiting(cx, from));
        self.refresh_due();
    }

    /// A coordinator whose heartbeat shows it past a sync point, through
    /// an allocation, or past a barrier ([`Position::past_barrier`]), where this robot has waited longer than a
    /// retry decided it, and its decision did not arrive: ask it now rather
    /// than at the next resend (spaced further apart after every loss, up
    /// to 64 retries: under heavy loss, longer than the team can wait; a
    /// barrier's member, acknowledged, resends every 4, 8, 16… retries,
    /// and under heavy loss waited out the deadline). So is one that left
    /// an allocation it coordinated (its own behavior ended as it decided:
    /// the decision stands, and only asking brings it back), or that runs
    /// the successor of the allocation's execution: it decided and left,
    /// or left undecided (its own reason to end the behavior came first),
    /// and answers `Done` (docs/reliability.md, "A coordinator that left
    /// undecided, unheard").
    ///
    /// The heartbeat that shows a barrier's leader past it, or a leader
    /// out of its allocation or past it, may arrive before the decision
    /// does: then the member asks only once the coordinator has been seen
    /// so for a retry (a run without faults sends nothing more).
    fn ask_past_point(&mut self, from: RobotId, pos: &Position) {
        let now = self.now;
        // No instance has waited a retry yet: nothing to ask, and no
        // instance read (the common case of a heartbeat).
        if self.asks_from.is_none_or(|t| now < t) {
            debug_assert!(
                !self.instances.values().any(|i| i.waited_a_retry(now)),
                "asks_from is later than an instance that has waited a retry"
            );
            return;
        }
        // Walk them all, and learn when the next will have waited a retry.
        self.asks_from = self.instances.values().filter_map(|i| i.retry_due()).min();
        let waiting = self.instances.iter().filter(|(_, i)| i.waited_a_retry(now));
        // Each with whether to wait a retry first.
        let ask: Vec<(InstanceKey, bool)> = waiting
            .filter_map(|(k, _)| match k.kind {
                Kind::Allocate if pos.went_through(k) => Some((k, false)),
                Kind::Allocate => (pos.state_at(k).is_some_and(|s| s != FrameState::Running)
                    || pos.went_past(k))
                .then_some((k, true)),
                Kind::Sync => pos.went_past(k).then_some((k, false)),
                Kind::Terminate => pos.past_barrier(k).then_some((k, true)),
            })
            .collect();
        for (k, after_a_retry) in ask {
            if self.coordinator_of(k) != Some(from) {
                continue;
            }
            if after_a_retry {
                let Some(inst) = self.instances.get_mut(&k) else {
                    continue;
                };
                let seen = *inst.past_seen.get_or_insert(now);
                if now - seen < inst.retry.get() {
                    continue;
                }
            }
            self.reply(k, from, crate::msg::Body::Query);
        }
    }

    /// This robot's process restarted with nothing kept (its previous
    /// incarnation's state is gone): instead of starting the mission from
    /// the beginning, it waits (up to [`REJOIN_WAIT`]) to hear a teammate's
    /// heartbeat and joins the team where the team is.
    pub fn rejoin(&mut self, now: Time) {
        self.set_now(now);
        if matches!(self.phase, Phase::NotStarted) {
            self.rejoin_since = Some(self.now);
        }
    }

    /// True while a restarted process waits to hear where its team is.
    pub(super) fn awaiting_rejoin(&self) -> bool {
        matches!(self.phase, Phase::NotStarted)
            && self
                .rejoin_since
                .is_some_and(|t| self.now - t < REJOIN_WAIT)
    }

    /// Join the team where a teammate's position says it is: the frames it
    /// runs for teams this robot knows (the root team and its executions,
    /// with their epochs), down to the first subteam an allocation made
    /// while this robot was away. It takes no part in what was allocated
    /// without it: it idles under the deepest frame it joined until that
    /// frame ends (by its team, or by its own condition), and goes on with
    /// the team from there.
    pub(super) fn adopt(&mut self, from: RobotId, pos: &Position) {
        let graph = self.mission.graph().clone();
        for (name, v) in graph.initial_beliefs() {
            self.beliefs
                .set_named(name, v.clone(), self.now, crate::belief::Source::Given);
        }
        // Epochs the team has used: never reuse them.
        for id in pos.ended.iter().map(|e| &e.id).chain(&pos.burned) {
            self.org.runs_at_least(id.team, id.behavior, id.epoch);
        }
        for f in &pos.frames {
            self.org
                .runs_at_least(f.id.team, f.id.behavior, f.id.epoch - 1);
        }
        self.rejoin_since = None;
        let mut joined = 0;
        for f in pos.frames.iter().filter(|f| f.state == FrameState::Running) {
            let ok = self
                .org
                .team(f.id.team)
                .is_some_and(|t| t.contains(self.me))
                && match self.stack.last() {
                    None => f.anchor.is_none() && f.id.behavior == graph.start(),
                    Some(p) => graph.runs_under(p.behavior, f.id.behavior),
                };
            if !ok {
                break;
            }
            self.org
                .runs_at_least(f.id.team, f.id.behavior, f.id.epoch - 1);
            self.push_anchored(f.id.behavior, f.id.team, Via::Rejoined, f.anchor);
            joined += 1;
        }
        self.emit(Event::Rejoined {
            member: from,
            depth: joined,
        });
        if joined == 0 {
            // Nothing in common yet (the team has not started, or is done):
            // start from the beginning.
            self.phase = Phase::NotStarted;
            return;
        }
        // The team has allocated the deepest frame joined: take part in it
        // again, as a teammate back from a loss does (the part its previous
        // incarnation was given is gone with it, and the team may be
        // waiting on that part).
        let Some(top) = self.stack.last() else {
            return;
        };
        let allocated = pos
            .frames
            .iter()
            .find(|g| g.id == top.id() && g.state == FrameState::Running)
            .and_then(|g| g.alloc);
        if let Some((round, _)) = allocated
            && self.join_allocation(self.stack.len() - 1, round)
        {
            return;
        }
        // Else idle under it: tell its termination that this robot has no
        // part to wait for.
        self.idle_under_top();
    }

    /// A robot that rejoined under frame `i` (an allocation point it took
    /// no part in: no subteams of its own) and hears that its team
    /// allocated it, in round `round`, allocates it again in the next
    /// round, with itself among the members. The teammates heal to that
    /// round ([`Kernel::reconcile_allocation`]), as for a member back from
    /// a loss. False (nothing done) when frame `i` is not such a point or
    /// none of its children is enabled.
    pub(super) fn join_allocation(&mut self, i: usize, round: u32) -> bool {
        let Some(f) = self.stack.get(i) else {
            return false;
        };
        if f.subteams.is_some()
            || !self.graph().is_alloc_point(f.behavior)
            || i + 1 != self.stack.len()
        {
            return false;
        }
        let enabled = self.enabled_children();
        if enabled.is_empty() {
            return false;
        }
        self.stack[i].allotted = enabled;
        self.reallocate(i, round.saturating_add(1), &[]);
        true
    }

    /// True when instance `key` (a termination or a synchronization) waits
    /// on teammates that are slow, not silent: then the deadline — which
    /// bounds waiting on silent teammates — is re-armed.
    ///
    /// - The instance's leader (its lowest live member) hears every member:
    ///   it waits on if every member it still counts was heard within
    ///   [`FRESH`] and one of them is still *running* the behavior (it has
    ///   not reached the point yet), or the execution before one this
    ///   robot is in (it is behind on the same path), or it is still
    ///   making the allocation of an execution above the point (it runs
    ///   one, with nothing below it yet: it is on its way down).
    /// - A member waits on its leader: it waits on while the leader was
    ///   heard within [`FRESH`] engaged in the execution (running it, or
    ///   waiting at its point), or, making progress, behind on the same
    ///   path or still making the allocation of an execution above the
    ///   point.
    ///
    /// At an allocation only a teammate behind on the path counts (a team
    /// at the point reaches it together, and a protocol may count on its
    /// deadline to recover what a crash took with it: a token).
    ///
    /// A slow teammate is waited for while it makes progress: its position
    /// changed, or its skill made a step ([`Kernel::skill_progressed`]),
    /// within [`crate::mission::SLOW_WAITS`] deadlines (and at least
    /// [`crate::mission::SLOW_WAIT_MIN`]).
    /// One whose condition never holds (it cannot see what it looks for)
    /// is then a timeout and a decision, not a team waiting forever. A
    /// member trusts a leader waiting at the point: the leader's own
    /// deadline decides for the team.
    pub(super) fn awaited_at_work(&self, key: InstanceKey) -> bool {
        // At an allocation the leader counts only teammates behind on the
        // path: a team at the point reaches it together, and a protocol
        // may count on its deadline to recover what a crash took with it
        // (a token). A member trusts a leader engaged at the point.
        let at_point_counts = key.kind != Kind::Allocate;
        let Some(inst) = self.instances.get(&key) else {
            return false;
        };
        let limit = slow_wait(inst.deadline_len.get());
        let progressing = |r: RobotId| {
            self.peers
                .get(&r)
                .and_then(|p| p.moved.get())
                .is_some_and(|t| self.now - t < limit)
        };
        let id = FrameId::of(key);
        let heard = |r: RobotId| self.fresh_peer(r).map(|p| &p.frames);
        let leader = inst
            .team
            .members
            .iter()
            .find(|r| *r == self.me || self.counted(inst, *r));
        // A teammate still running the execution before one this robot is
        // in (in the same team) is behind on the same path: slow, not
        // silent, it is on its way to the point.
        // So is one running an execution this robot has already ended
        // (under a `term.local` behavior a robot may run ahead).
        // Each is kept with the execution it runs under: two executions
        // under different parents may share an id (a behavior both
        // `triangle` and `line` expand to, at the same team count), and a
        // teammate ahead, in the later one, is not behind.
        let behind: Vec<Ended> = self
            .frames()
            .filter_map(|(i, f)| {
                f.anchor.filter(|a| !a.first).map(|a| Ended {
                    id: FrameId {
                        team: f.team,
                        behavior: a.behavior,
                        epoch: a.epoch,
                    },
                    parent: i.checked_sub(1).map(|p| self.stack[p].id()),
                })
            })
            .chain(self.recent_ended.iter().copied())
            .filter(|b| b.id != id)
            .collect();
        // Whether a teammate's frame `k` (its frames are a chain, root
        // first: frame `k` runs under frame `k - 1`) is one of those.
        let is_behind = |frames: &[(FrameId, FrameState)], k: usize| {
            let parent = k.checked_sub(1).map(|p| frames[p].0);
            behind.contains(&Ended {
                id: frames[k].0,
                parent,
            }) || parent.is_some_and(|p| {
                frames[k].0 != id
                    && (self.passed(k, p, frames[k].0) || self.leads_into(k, p, frames[k].0))
            })
        };
        // The executions above the point's, here (root first).
        let ancestors = match self.stack.iter().position(|f| f.id() == id) {
            Some(i) => &self.stack[..i],
            // Its end or its synchronization: the frame is popped.
            None if self.popped().is_some_and(|(f, _)| f.id() == id) => &self.stack[..],
            None => &[],
        };
        let above = ancestors.last().map(Frame::id);
        // A teammate still making the allocation of an execution above the
        // point (a lap behind, or coming down from further up: the
        // grandparent's allocation) runs that execution with nothing below
        // it yet: it is on its way. Not one in another of its subteams:
        // two robots each in a subteam the other did not take waited for
        // each other for ever (docs/reliability.md, "A coordinator still
        // on its way to the allocation above", "A teammate allocating two
        // levels up").
        let allocating_above = |frames: &[(FrameId, FrameState)]| {
            frames.last().is_some_and(|(f, st)| {
                *st == FrameState::Running && ancestors.iter().any(|a| a.id() == *f)
            })
        };
        if leader != Some(self.me) {
            return leader.and_then(heard).is_some_and(|frames| {
                frames.iter().any(|(f, _)| *f == id)
                    || (leader.is_some_and(progressing)
                        && ((0..frames.len()).any(|k| is_behind(frames, k))
                            || allocating_above(frames)))
            });
        }
        // A teammate in the execution above the point's, in another of its
        // subteams (or in none): the two took that allocation from
        // different views (one had heard that a teammate finished, the
        // other not yet), and the split heals within a heartbeat or two
        // (`Kernel::reconcile_allocation`): it is on its way, as one behind
        // is (docs/reliability.md, "A root leader that finished").
        let split_off = |frames: &[(FrameId, FrameState)]| {
            above.is_some_and(|a| {
                (frames.iter().position(|(f, _)| *f == a))
                    .is_some_and(|k| frames.get(k + 1).is_none_or(|(g, _)| g.team != key.team))
            })
        };
        // A teammate on the other side of a split this robot heals (it took
        // another successor after the same execution, and this robot's side
        // is the healing leader's: `Kernel::split_seen`) follows it within a
        // heartbeat: it is on its way (docs/reliability.md, "A teammate
        // seen on the other side of a split").
        let healing = |r: RobotId, frames: &[(FrameId, FrameState)]| {
            (frames.iter()).any(|(f, _)| f.team == key.team && self.splits_seen.contains(&(r, *f)))
        };
        let mut running = false;
        for r in inst
            .team
            .members
            .iter()
            .filter(|r| *r != self.me && self.counted(inst, *r))
        {
            match heard(r) {
                Some(frames) => {
                    running |= (frames.iter().enumerate().any(|(k, (f, st))| {
                        (at_point_counts && *f == id && *st == FrameState::Running)
                            || is_behind(frames, k)
                    }) || split_off(frames)
                        || healing(r, frames)
                        || (at_point_counts && allocating_above(frames)))
                        && progressing(r);
                }
                None => return false,
            }
        }
        running
    }

    /// Teammates not heard for longer than [`FRESH`] keep only what their
    /// next heartbeat is compared with (see [`Quiet`]).
    pub(super) fn quiet_peers(&mut self) {
        let now = self.now;
        let quiet = &mut self.quiet;
        self.peers.retain(|r, p| {
            let fresh = now - p.heard <= FRESH;
            if !fresh {
                quiet.insert(r, Quiet::of(p));
            }
            fresh
        });
        // Nobody is answered who no longer sends (the set is the roster's
        // size: it is dropped once empty).
        if let Some(a) = &self.answering {
            let gone: Vec<RobotId> = a.iter().filter(|r| self.peers.get(r).is_none()).collect();
            if let Some(a) = &mut self.answering {
                for r in gone {
                    a.remove(r);
                }
                if a.is_empty() {
                    self.answering = None;
                }
            }
        }
    }

    /// Record an execution this robot ended (for its heartbeats).
    pub(super) fn note_ended(&mut self, id: FrameId, parent: Option<FrameId>) {
        self.recent_ended.push(Ended { id, parent });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A teammate went through an allocation's execution when it ended a
    /// child of it or runs it with an allocation applied; not when it only
    /// ran the execution, another epoch of it, or something else.
    #[test]
    fn a_position_tells_whether_its_sender_went_through_an_allocation() {
        let point = FrameId {
            team: TeamId::ROOT,
            behavior: BehaviorId(2),
            epoch: 1,
        };
        let key = InstanceKey {
            team: point.team,
            behavior: point.behavior,
            kind: Kind::Allocate,
            epoch: 1,
            round: 0,
        };
        let child = FrameId {
            team: TeamId(77),
            behavior: BehaviorId(3),
            epoch: 1,
        };
        let frame = |id: FrameId, alloc: Option<(u32, u64)>| PosFrame {
            id,
            anchor: None,
            state: FrameState::Running,
            alloc,
            departed: None,
        };
        let ended = |id: FrameId, parent: Option<FrameId>| Ended { id, parent };
        let later = FrameId { epoch: 2, ..point };
        let cases = [
            (Position::default(), false),
            (
                Position {
                    ended: vec![ended(child, Some(point))],
                    ..Position::default()
                },
                true,
            ),
            (
                Position {
                    ended: vec![ended(point, None), ended(child, Some(later))],
                    ..Position::default()
                },
                false,
            ),
            (
                Position {
                    frames: vec![frame(point, Some((0, 9)))],
                    ..Position::default()
                },
                true,
            ),
            (
                Position {
                    frames: vec![frame(point, None), frame(later, Some((0, 9)))],
                    ..Position::default()
                },
                false,
            ),
        ];
        for (pos, through) in cases {
            assert_eq!(pos.went_through(key), through, "{pos:?}");
        }
    }

    /// A random execution id, its numbers spread over every varint length.
    fn any_frame_id() -> impl proptest::strategy::Strategy<Value = FrameId> {
        use proptest::prelude::*;
        (any::<u64>(), any::<u32>(), any::<u32>(), 0u32..4).prop_map(
            |(team, behavior, epoch, shift)| FrameId {
                team: TeamId(team >> (shift * 16)),
                behavior: BehaviorId(behavior >> (shift * 8)),
                epoch: epoch >> (shift * 8),
            },
        )
    }

    /// A random position: every field, sets of each of `MemberSet`'s forms
    /// (a few, a list, a bit set) over rosters of 1 to 100,000.
    fn any_position() -> impl proptest::strategy::Strategy<Value = Position> {
        use proptest::collection::vec;
        use proptest::option::of;
        use proptest::prelude::*;
        let set = (1usize..100_000, vec(any::<u32>(), 0..200)).prop_map(|(roster, ids)| {
            MemberSet::from_iter(roster, ids.into_iter().map(|i| RobotId(i % roster as u32)))
        });
        let anchor =
            (any::<u32>(), any::<u32>(), any::<bool>()).prop_map(|(b, epoch, first)| Anchor {
                behavior: BehaviorId(b >> (b % 32)),
                epoch,
                first,
            });
        let state = prop_oneof![
            Just(FrameState::Running),
            Just(FrameState::Ending),
            Just(FrameState::Ended)
        ];
        let frame = (
            any_frame_id(),
            of(anchor),
            state,
            of((any::<u32>(), any::<u64>())),
            of(set),
        )
            .prop_map(|(id, anchor, state, alloc, departed)| PosFrame {
                id,
                anchor,
                state,
                alloc,
                departed,
            });
        let ended =
            (any_frame_id(), of(any_frame_id())).prop_map(|(id, parent)| Ended { id, parent });
        let fence =
            (any::<u32>(), any_frame_id(), any::<bool>()).prop_map(|(version, after, switched)| {
                super::super::change::Fence {
                    version,
                    after,
                    switched,
                }
            });
        (
            any::<u32>(),
            vec(frame, 0..6),
            vec(ended, 0..10),
            vec(any_frame_id(), 0..10),
            (any::<u32>(), any::<u32>(), any::<u32>()),
            vec(fence, 0..4),
        )
            .prop_map(
                |(robot, frames, ended, burned, (version, pending, progress), fences)| Position {
                    robot: RobotId(robot),
                    frames,
                    ended,
                    burned,
                    version,
                    pending,
                    fences,
                    progress,
                },
            )
    }

    proptest::proptest! {
        /// The size counted by hand is the size of what is sent, and of
        /// what postcard's own counting pass says.
        #[test]
        fn encoded_len_is_the_wire_forms_length(pos in any_position()) {
            let bytes = pos.encode();
            proptest::prop_assert_eq!(pos.encoded_len(), bytes.len());
            proptest::prop_assert_eq!(
                postcard::experimental::serialized_size(&pos).ok(),
                Some(bytes.len())
            );
        }
    }

    proptest::proptest! {
        /// The list of recently ended executions keeps what the plain ring
        /// ([`push_recent`]) keeps, whatever the pushes, repeats included,
        /// and its filter answers for every execution in it.
        #[test]
        fn recent_ended_keeps_what_the_plain_ring_keeps(
            pushes in proptest::collection::vec((0u64..6, 0u32..4, 1u32..4, proptest::option::of(0u32..3)), 0..80),
        ) {
            let mut recent = RecentEnded::default();
            let mut ring = std::collections::VecDeque::new();
            for (team, behavior, epoch, parent) in pushes {
                let id = FrameId { team: TeamId(team), behavior: BehaviorId(behavior), epoch };
                let parent = parent.map(|b| FrameId { team: TeamId::ROOT, behavior: BehaviorId(b), epoch: 1 });
                let e = Ended { id, parent };
                recent.push(e);
                push_recent(&mut ring, e);
                proptest::prop_assert!(recent.iter().eq(ring.iter()));
                for x in &ring {
                    proptest::prop_assert!(recent.contains(&x.id) && recent.contains_ended(x));
                }
            }
        }
    }
}
