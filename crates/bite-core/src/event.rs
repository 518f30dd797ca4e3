//! What a kernel reports: the raw material of run logs, summaries and
//! invariant checks.

use crate::ids::InstanceKey;
use crate::ids::{BehaviorId, RobotId, TeamId};
use crate::members::Assignment;
use crate::value::Value;
use serde::{Deserialize, Serialize};
use smallvec::SmallVec;
use std::sync::{Arc, OnceLock};

/// How a behavior came to be selected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Via {
    /// The start behavior b0.
    Start,
    /// The only enabled child of its parent (no allocation needed).
    Expansion,
    /// Assigned by an allocation.
    Allocation,
    /// The only way on along the execution chain (not a synchronization point).
    Sequence,
    /// Chosen by a synchronization protocol.
    Decision,
    /// Returned by a termination protocol as the next behavior under the parent.
    Replacement,
    /// Joined the successor its team converged on after a split (the
    /// healing leader's choice, or the same successor at a higher epoch).
    Converged,
    /// Joined where the team was, after this robot's process restarted.
    Rejoined,
}

/// Why a behavior ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "behavior")]
pub enum EndReason {
    /// Its termination condition held on this robot.
    Until,
    /// Its `urgent` condition held on this robot: it left at once, without
    /// waiting for its team's termination protocol.
    Urgent,
    /// Its execution chain ran out of successors.
    ChainEnded,
    /// The team ended it (a termination protocol decided it).
    Team,
    /// An ancestor ended; descendants are popped with it.
    Ancestor(BehaviorId),
    /// The allocation of this ancestor is redone (teammates were lost).
    Reallocation(BehaviorId),
    /// Left for the successor the team converged on after a split: the
    /// execution is burned (its epoch is never used again).
    Converged,
}

/// Why an incoming message was dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DropReason {
    /// Sent by this robot.
    OwnMessage,
    /// Sender is not in the roster.
    UnknownSender,
    /// Same `(sender, seq)` seen before, or older than the replay window.
    Duplicate,
    /// Names a behavior, kind or epoch that cannot exist.
    Malformed,
    /// For a team this robot is not in.
    NotMember,
    /// From a robot that is not in the team it names.
    SenderNotMember,
    /// For an instance that is already over (stale epoch, dissolved team).
    Stale,
    /// The buffer of messages for instances not started yet is full, or a
    /// buffered message expired.
    BufferOverflow,
    /// A heartbeat whose position names another robot than the one it
    /// came from (a teammate's position replayed as from another).
    Misattributed,
}

/// Subteams up to this size are logged member by member.
pub const LOG_MEMBERS_LIMIT: usize = 64;

/// The members of a child in a logged allocation: the list for small
/// subteams, a count and fingerprint for large ones (10,000 robots each
/// logging 10,000 ids would be 10⁸ entries per allocation).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MembersLog {
    /// Every member (inline up to four: a list is made at every allocation).
    List(SmallVec<[RobotId; 4]>),
    /// A large subteam.
    Summary {
        /// Number of members.
        count: u32,
        /// [`MemberSet::fingerprint`](crate::org::MemberSet::fingerprint), hex.
        fingerprint: String,
    },
}

impl MembersLog {
    /// Number of members.
    pub fn len(&self) -> usize {
        match self {
            MembersLog::List(v) => v.len(),
            MembersLog::Summary { count, .. } => *count as usize,
        }
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The decision of an instance, for the log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum OutcomeLog {
    /// Selected successor (`None`: chain ended).
    Sync {
        /// The choice.
        choice: Option<BehaviorId>,
    },
    /// Allocation: each child with its members.
    Allocate {
        /// `(child, members)`, shared by the robots that applied the same
        /// allocation. Logged in full up to [`LOG_CHILDREN_LIMIT`]
        /// children; a larger allocation is logged as a summary
        /// (`{"children": 10000, "assigned": 10000, "fingerprint": ...}`).
        assignment: LogList<(BehaviorId, MembersLog)>,
    },
    /// Termination, with an optional replacement.
    Terminate {
        /// Replacement behavior.
        next: Option<BehaviorId>,
    },
}

impl OutcomeLog {
    /// The log form of an allocation.
    pub fn allocation(a: &Assignment) -> Self {
        OutcomeLog::Allocate {
            assignment: Self::members_log(a),
        }
    }
    /// Each child of an allocation with its members as the log shows them.
    pub fn members_log(a: &Assignment) -> LogList<(BehaviorId, MembersLog)> {
        a.0.iter()
            .map(|(b, m)| {
                let n = m.len();
                let log = if n <= LOG_MEMBERS_LIMIT {
                    MembersLog::List(m.iter().collect())
                } else {
                    MembersLog::Summary {
                        count: n as u32,
                        fingerprint: format!("{:016x}", m.fingerprint()),
                    }
                };
                (*b, log)
            })
            .collect()
    }
}

/// Allocations of more children than this are logged as a summary, and so
/// are options lists longer than this: 10,000 robots each logging 10,000
/// children would be 10⁸ entries.
pub const LOG_CHILDREN_LIMIT: usize = 64;

/// A stable 64-bit mix of words (for log fingerprints of long lists).
fn mix(h: u64, x: u64) -> u64 {
    (h ^ x).wrapping_mul(0x9e37_79b9_7f4a_7c15).rotate_left(31)
}

/// A list in events that many robots report alike (the children of an
/// allocation point, an allocation): shared rather than copied, compared
/// by address first, and logged in full up to [`LOG_CHILDREN_LIMIT`]
/// entries, as a count and a fingerprint (computed once) beyond. An
/// empty list holds nothing (a termination's options, every time).
pub struct LogList<T>(Option<Arc<ListInner<T>>>);

struct ListInner<T> {
    items: Vec<T>,
    /// (total weight, fingerprint), for the summary.
    summary: OnceLock<(u64, u64)>,
}

/// An entry of a [`LogList`]: how it feeds the list's fingerprint, and
/// how much it counts (members, for an allocation).
pub trait LogItem {
    /// Mix the entry into a fingerprint.
    fn mix(&self, h: u64) -> u64;
    /// Its weight in the summary's total.
    fn weight(&self) -> u64 {
        1
    }
}

impl LogItem for BehaviorId {
    fn mix(&self, h: u64) -> u64 {
        mix(h, u64::from(self.0))
    }
}

impl LogItem for (BehaviorId, MembersLog) {
    fn mix(&self, h: u64) -> u64 {
        let mut h = mix(h, u64::from(self.0.0));
        match &self.1 {
            MembersLog::List(v) => {
                h = mix(h, v.len() as u64);
                for r in v {
                    h = mix(h, u64::from(r.0));
                }
            }
            MembersLog::Summary { count, fingerprint } => {
                h = mix(h, u64::from(*count));
                h = mix(h, u64::from_str_radix(fingerprint, 16).unwrap_or(0));
            }
        }
        h
    }
    fn weight(&self) -> u64 {
        self.1.len() as u64
    }
}

impl<T> LogList<T> {
    /// True when both are the same list (not just equal ones).
    pub fn ptr_eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            (a, b) => a.is_none() && b.is_none(),
        }
    }
}

impl<T: LogItem> LogList<T> {
    /// Total weight and fingerprint of the entries.
    fn summary(&self) -> (u64, u64) {
        let Some(inner) = &self.0 else {
            return (0, 0);
        };
        *inner.summary.get_or_init(|| {
            let items = &inner.items;
            (
                items.iter().map(LogItem::weight).sum(),
                items.iter().fold(0, |h, x| x.mix(h)),
            )
        })
    }
}

impl<T> From<Vec<T>> for LogList<T> {
    fn from(items: Vec<T>) -> Self {
        if items.is_empty() {
            return LogList(None);
        }
        LogList(Some(Arc::new(ListInner {
            items,
            summary: OnceLock::new(),
        })))
    }
}

impl<T: Clone> From<&[T]> for LogList<T> {
    fn from(items: &[T]) -> Self {
        items.to_vec().into()
    }
}

impl<T> FromIterator<T> for LogList<T> {
    fn from_iter<I: IntoIterator<Item = T>>(it: I) -> Self {
        it.into_iter().collect::<Vec<T>>().into()
    }
}

impl<T> Default for LogList<T> {
    fn default() -> Self {
        LogList(None)
    }
}

impl<T> Clone for LogList<T> {
    fn clone(&self) -> Self {
        LogList(self.0.clone())
    }
}

impl<T> std::ops::Deref for LogList<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        self.0.as_ref().map_or(&[], |i| &i.items)
    }
}

impl<T: PartialEq> PartialEq for LogList<T> {
    fn eq(&self, other: &Self) -> bool {
        self.ptr_eq(other) || **self == **other
    }
}

impl<T: Eq> Eq for LogList<T> {}

impl<T: std::fmt::Debug> std::fmt::Debug for LogList<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

impl Serialize for LogList<BehaviorId> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.len() <= LOG_CHILDREN_LIMIT {
            return (**self).serialize(s);
        }
        #[derive(Serialize)]
        struct Summary {
            count: usize,
            fingerprint: String,
        }
        Summary {
            count: self.len(),
            fingerprint: format!("{:016x}", self.summary().1),
        }
        .serialize(s)
    }
}

impl Serialize for LogList<(BehaviorId, MembersLog)> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.len() <= LOG_CHILDREN_LIMIT {
            return (**self).serialize(s);
        }
        #[derive(Serialize)]
        struct Summary {
            children: usize,
            assigned: u64,
            fingerprint: String,
        }
        let (assigned, fingerprint) = self.summary();
        Summary {
            children: self.len(),
            assigned,
            fingerprint: format!("{fingerprint:016x}"),
        }
        .serialize(s)
    }
}

/// The full form only (a summary cannot be read back into a list).
impl<'de, T: Deserialize<'de>> Deserialize<'de> for LogList<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Vec::<T>::deserialize(d).map(Into::into)
    }
}

fn no_options(o: &LogList<BehaviorId>) -> bool {
    o.is_empty()
}

/// A behavior and one of its epochs, in events.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameRef {
    /// The behavior.
    pub behavior: BehaviorId,
    /// The team's execution count of it.
    pub epoch: u32,
}

/// Something that happened in a kernel.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "event")]
pub enum Event {
    /// A behavior was pushed onto the stack.
    Selected {
        /// The behavior.
        behavior: BehaviorId,
        /// The subteam executing it.
        team: TeamId,
        /// Team's execution count of it (the epoch of its instances).
        epoch: u32,
        /// Stack depth (0 = root).
        depth: u32,
        /// How it was selected.
        via: Via,
        /// The execution before it in its chain (`None`: the first of a
        /// chain).
        #[serde(skip_serializing_if = "Option::is_none")]
        after: Option<FrameRef>,
    },
    /// A behavior was popped.
    Terminated {
        /// The behavior.
        behavior: BehaviorId,
        /// Its subteam.
        team: TeamId,
        /// Its epoch.
        epoch: u32,
        /// Why.
        reason: EndReason,
    },
    /// A condition held and changed what the robot does.
    ConditionHeld {
        /// The behavior whose condition it is.
        behavior: BehaviorId,
        /// `until` or `pre`.
        field: &'static str,
        /// The beliefs the condition reads, with their values (names shared
        /// with the symbol table).
        beliefs: Vec<(std::sync::Arc<str>, Option<Value>)>,
    },
    /// A protocol instance started (the robot reached the point).
    InteractionStarted {
        /// The instance.
        instance: InstanceKey,
        /// Protocol name.
        protocol: &'static str,
        /// Teammates left out from the start (presumed lost, or left out by
        /// the teammate that started a re-allocation).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        excluded: Vec<RobotId>,
        /// What this robot saw it could choose: the enabled successors of a
        /// synchronization, the enabled children of an allocation (what a
        /// silent rule decides from). Shared with the mission when it is
        /// every child; logged as a count and fingerprint when longer than
        /// [`LOG_CHILDREN_LIMIT`].
        #[serde(default, skip_serializing_if = "no_options")]
        options: LogList<BehaviorId>,
    },
    /// A running instance decides without these teammates from now on:
    /// presumed lost, or known to have left the behavior above it (or this
    /// one, for a barrier that counted them arrived).
    LeftOut {
        /// The instance.
        instance: InstanceKey,
        /// Who.
        members: Vec<RobotId>,
    },
    /// This robot stopped waiting for the termination protocol of a
    /// behavior it had finished, because the behavior's `urgent` condition
    /// held (the protocol goes on without it).
    Preempted {
        /// The behavior.
        behavior: BehaviorId,
        /// Its team.
        team: TeamId,
        /// Its execution count.
        epoch: u32,
    },
    /// A protocol instance decided.
    InteractionDecided {
        /// The instance.
        instance: InstanceKey,
        /// Protocol name.
        protocol: &'static str,
        /// The decision.
        outcome: OutcomeLog,
        /// How long this robot waited for it, in microseconds.
        waited_us: u64,
        /// Messages this robot sent for it so far.
        sent: u32,
        /// Bytes this robot sent for it so far.
        bytes: u64,
        /// Messages this robot received for it so far.
        received: u32,
        /// True when the deadline passed and the fallback decided.
        timed_out: bool,
    },
    /// An instance was abandoned (an ancestor ended first).
    InteractionAborted {
        /// The instance.
        instance: InstanceKey,
        /// Protocol name.
        protocol: &'static str,
    },
    /// The deadline of an instance passed.
    InteractionTimedOut {
        /// The instance.
        instance: InstanceKey,
        /// Protocol name.
        protocol: &'static str,
        /// Whether the protocol decided by itself at the deadline (else the
        /// kernel applied the silent rule of its kind).
        protocol_decided: bool,
    },
    /// A non-atomic behavior has no enabled child yet; the robot waits.
    WaitingForChild {
        /// The behavior.
        behavior: BehaviorId,
    },
    /// An allocation gave this robot no child (more members than places).
    Unassigned {
        /// The allocation point.
        behavior: BehaviorId,
    },
    /// An incoming message was dropped.
    Dropped {
        /// Its sender (as claimed).
        from: RobotId,
        /// Why.
        reason: DropReason,
    },
    /// A teammate broke a protocol's rules; its message was ignored.
    ProtocolViolation {
        /// The instance.
        instance: InstanceKey,
        /// What happened.
        what: String,
    },
    /// A teammate is presumed lost (reported by the runtime).
    MemberLost {
        /// Who.
        member: RobotId,
    },
    /// A teammate presumed lost is heard again.
    MemberBack {
        /// Who.
        member: RobotId,
    },
    /// A teammate presumed lost that a deadline of this robot has just
    /// decided without is given up: `term.majority` leaves it out of the
    /// whole until it is heard again (`member_back`).
    MemberGivenUp {
        /// Who.
        member: RobotId,
    },
    /// Teammates lost left a child of this allocation without enough live
    /// members: the team allocates again, in a new round.
    Reallocating {
        /// The allocation point.
        behavior: BehaviorId,
        /// Its team.
        team: TeamId,
        /// Its epoch.
        epoch: u32,
        /// The new allocation round.
        round: u32,
    },
    /// The team split at a synchronization point: after `after`, this robot
    /// runs `mine` while teammate `member` runs `theirs` (heard with its
    /// heartbeat). With `follows`, this robot leaves `mine` for `theirs`
    /// (the healing leader's choice, or the same behavior at a higher
    /// epoch); without, this robot is the healing leader and the teammate
    /// will converge on its choice.
    Split {
        /// The team.
        team: TeamId,
        /// The point whose successors diverged.
        after: FrameRef,
        /// What this robot ran.
        mine: FrameRef,
        /// What the teammate runs.
        theirs: FrameRef,
        /// The teammate.
        member: RobotId,
        /// This robot converges on `theirs`.
        follows: bool,
    },
    /// This robot waited at `instance`'s point (a synchronization, a
    /// barrier or an allocation) for longer than a retry and heard
    /// teammate `member` past it, with no other teammate still waiting
    /// there with it: the team decided without it (it presumes this robot
    /// lost: its messages do not get out). It goes on as they did, with
    /// the teammate's successor, the end of the behavior, or no part in
    /// the allocation (it idles under the behavior), instead of waiting
    /// out the deadline.
    LeftBehind {
        /// The instance it waited in.
        instance: InstanceKey,
        /// The teammate heard past the point.
        member: RobotId,
    },
    /// A teammate under the same execution of an allocation point holds
    /// another allocation of it (views diverged: a partition healed, or a
    /// deadline decided on each side): this robot allocates again, in
    /// round `round`, with everyone it hears.
    AllocationSplit {
        /// The allocation point.
        behavior: BehaviorId,
        /// The team allocating.
        team: TeamId,
        /// The execution.
        epoch: u32,
        /// The round this robot held.
        mine: u32,
        /// The round the teammate holds.
        theirs: u32,
        /// The teammate.
        member: RobotId,
        /// The round it allocates in now.
        round: u32,
    },
    /// This robot's process restarted with a fresh mind and joined its team
    /// where teammate `member`'s position said the team was, `depth` frames
    /// deep (0: nothing in common: it starts from the beginning).
    Rejoined {
        /// Whose position it followed.
        member: RobotId,
        /// How many frames it joined.
        depth: u32,
    },
    /// A new version of the mission reached this robot; it is held until
    /// its team's next safe point.
    MissionChangeOffered {
        /// The version.
        version: u32,
    },
    /// A new version of the mission was refused here (the mission goes on
    /// unchanged).
    MissionChangeRefused {
        /// The version.
        version: u32,
        /// Why.
        reason: String,
    },
    /// The robot switched to a new version of the mission at a safe point,
    /// with the other members of its team there.
    MissionChanged {
        /// The version it runs from now on.
        version: u32,
        /// The team that switched.
        team: TeamId,
        /// The execution whose successor is the first chosen in `version`
        /// (`None`: a restarted robot took its team's version as it
        /// rejoined).
        after: Option<FrameRef>,
        /// Behaviors the version adds, removes or edits.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        changed: Vec<String>,
    },
    /// At a safe point with a version pending, the team went on in the
    /// running version (not every member held it yet, or, `timed_out`,
    /// this member heard no decision from its leader in time).
    MissionChangeDeferred {
        /// The pending version.
        version: u32,
        /// The team.
        team: TeamId,
        /// The execution whose successor was chosen in the running version.
        after: FrameRef,
        /// True when the member stopped waiting for its leader.
        timed_out: bool,
    },
    /// The stack emptied: the mission is over for this robot.
    MissionCompleted,
    /// Too many transitions in one step (conditions that are immediately
    /// true around a sequential cycle); the kernel yields until the next input.
    TransitionLimit,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_list_is_logged_and_compared_like_any_other() {
        let empty: LogList<BehaviorId> = LogList::default();
        let made: LogList<BehaviorId> = Vec::new().into();
        assert!(empty.ptr_eq(&made) && empty == made && empty.is_empty());
        assert_eq!(serde_json::to_string(&empty).expect("json"), "[]");
        let one: LogList<BehaviorId> = vec![BehaviorId(3)].into();
        assert!(!one.ptr_eq(&empty) && one != empty);
        assert!(one.ptr_eq(&one.clone()));
        assert_eq!(serde_json::to_string(&one).expect("json"), "[3]");
    }

    #[test]
    fn a_short_member_list_reads_back_as_it_was_written() {
        let log = MembersLog::List([RobotId(0), RobotId(2)].into_iter().collect());
        let json = serde_json::to_string(&log).expect("json");
        assert_eq!(json, "[0,2]");
        let back: MembersLog = serde_json::from_str(&json).expect("parse");
        assert_eq!(back, log);
        let many: MembersLog = serde_json::from_str("[1,2,3,4,5,6]").expect("parse");
        assert_eq!(many.len(), 6);
    }
}
