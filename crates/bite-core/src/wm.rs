//! Collaborative world modelling (section III-B of Kaminka & Frenkel): the
//! world model as its own process per robot, beside the kernel.
//!
//! It turns the robot's percepts and its teammates' reports into beliefs,
//! and decides what to tell whom:
//!
//! - [`Policy::Broadcast`]: every change of every belief to every teammate
//!   (the baseline the paper ruled out for bandwidth);
//! - [`Policy::Focused`] (Algorithm 2, FUSEINFORMATIONWITHTEAMMATES,
//!   obligatory): for every behavior on the robot's own stack, when its
//!   termination condition, or the precondition of one of its sequential
//!   successors, becomes true, the subteam responsible for it is told the
//!   beliefs the condition reads;
//! - [`Policy::Helpful`] (Algorithm 3, PROVIDEHELPFULINFORMATION): for
//!   every subteam of the hierarchy and the behaviors it is linked to that
//!   are not on this robot's stack, the same test with this robot's
//!   beliefs, and the subteam is told;
//! - [`Policy::FocusedHelpful`]: both, obligatory messages first when the
//!   per-robot budget (messages per second) binds; helpful ones wait at most
//!   [`HELPFUL_TTL`] and are then dropped (counted).
//!
//! **Fusion.** A belief's time is when its value last *changed*, not when it
//! was last read: a teammate's report wins over the robot's own value when
//! it is newer than the robot's last change of that belief (latest wins),
//! so the robot that saw the goal first makes its teammates believe it
//! until their own perception changes. Positions reported by teammates
//! within [`FUSE_WINDOW`] of the robot's own change are fused, weighted by
//! confidence.
//!
//! Sans-IO like the kernel: the runtime calls [`WorldModel::perceive`],
//! [`WorldModel::receive`] and [`WorldModel::share`], and drains
//! [`WorldModel::poll`]; it reads no clock.

use crate::belief::{BeliefEnv, BeliefStore, Source};
use crate::graph::BehaviorGraph;
pub use crate::graph::sharing::{Policy, Sharing};
use crate::ids::{BehaviorId, BeliefId, RobotId, TeamId};
use crate::kernel::Kernel;
use crate::members::MemberSet;
use crate::time::Time;
use crate::value::Value;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::fmt;
use std::time::Duration;

/// How long a helpful message may wait for budget before it is dropped.
pub const HELPFUL_TTL: Duration = Duration::from_secs(1);

/// Reports of a position closer in time than this to the robot's own are
/// fused with it rather than replacing it.
pub const FUSE_WINDOW: Duration = Duration::from_secs(1);

/// Messages a world model holds back for want of budget, at most.
pub const MAX_QUEUED: usize = 1024;

/// How often a robot waiting at a behavior's termination point tells its
/// subteam again what its termination condition read (focused policies).
pub const RESEND: Duration = Duration::from_secs(1);

/// Confidence a robot gives its own percepts.
pub const OWN_CONFIDENCE: f32 = 1.0;

/// Why a report is sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reason {
    /// Algorithm 2: a condition of the robot's own behaviors.
    Obligatory,
    /// Algorithm 3: a condition of another subteam's behavior.
    Helpful,
    /// The broadcast baseline.
    Broadcast,
}

impl Reason {
    /// Index for per-reason tables.
    pub fn index(self) -> usize {
        self as usize
    }
    /// All reasons.
    pub const ALL: [Reason; 3] = [Reason::Obligatory, Reason::Helpful, Reason::Broadcast];
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Reason::Obligatory => "obligatory",
            Reason::Helpful => "helpful",
            Reason::Broadcast => "broadcast",
        })
    }
}

/// One belief as reported.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Which belief.
    pub belief: BeliefId,
    /// Its value.
    pub value: Value,
    /// How long before the message left the sender its value last
    /// changed, microseconds. An age rather than a time, so that robots
    /// whose clocks disagree still agree which report is newer: the
    /// receiver reads it against its own clock on arrival
    /// ([`Report::changed_at`]).
    pub age_us: u64,
    /// The sender's confidence in it, 0-1.
    pub confidence: f32,
}

impl Report {
    /// A report at `now` of a value that last changed at `changed` (both on
    /// the sender's clock).
    pub fn new(belief: BeliefId, value: Value, changed: Time, now: Time, confidence: f32) -> Self {
        Report {
            belief,
            value,
            age_us: now.as_micros().saturating_sub(changed.as_micros()),
            confidence,
        }
    }

    /// When the value changed, on the clock of a receiver that reads the
    /// report at `now` (the time the message spent on its way counts as
    /// age it did not have: a report looks that much newer).
    pub fn changed_at(&self, now: Time) -> Time {
        Time(now.as_micros().saturating_sub(self.age_us))
    }

    /// The report as it is when it leaves `waited` later than it was made.
    fn aged(&mut self, waited: Duration) {
        let us = u64::try_from(waited.as_micros()).unwrap_or(u64::MAX);
        self.age_us = self.age_us.saturating_add(us);
    }
}

/// A world-model message: some beliefs, and why they are sent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Inform {
    /// Why.
    pub reason: Reason,
    /// The behavior whose condition made it worth sending (`None`:
    /// broadcast).
    pub about: Option<BehaviorId>,
    /// The beliefs.
    pub beliefs: Vec<Report>,
}

impl Inform {
    /// Size on the wire (postcard), bytes.
    pub fn bytes(&self) -> usize {
        postcard::to_allocvec(self).map_or(0, |v| v.len())
    }
}

/// A message to send.
#[derive(Clone, Debug, PartialEq)]
pub struct Outgoing {
    /// Recipients.
    pub to: Vec<RobotId>,
    /// The message.
    pub msg: Inform,
}

/// Counters of one robot's world model.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct WmStats {
    /// Messages sent by reason (one per recipient).
    pub messages: [u64; 3],
    /// Bytes sent by reason (per recipient).
    pub bytes: [u64; 3],
    /// Helpful or broadcast messages dropped for want of budget.
    pub dropped: u64,
    /// Reports received.
    pub received: u64,
    /// Reports that changed a belief.
    pub adopted: u64,
    /// Reports ignored (a belief the graph does not have, or stale).
    pub ignored: u64,
}

/// What the robot itself last perceived of a belief, and when it changed.
#[derive(Clone, Debug)]
struct Own {
    value: Value,
    changed: Time,
}

/// The latest teammate report of a belief.
#[derive(Clone, Debug)]
struct Told {
    value: Value,
    time: Time,
    from: RobotId,
    confidence: f32,
}

/// Which condition an inform was about: (team, behavior, epoch, the
/// successor whose precondition it is, or `None` for the termination
/// condition).
type Edge = (TeamId, BehaviorId, u32, Option<BehaviorId>);

/// One robot's world model.
#[derive(Clone, Debug)]
pub struct WorldModel {
    me: RobotId,
    sharing: Sharing,
    /// Beliefs about the robot itself: never reported, reports ignored.
    private: std::sync::Arc<[bool]>,
    own: Vec<Option<Own>>,
    told: Vec<Option<Told>>,
    /// What the kernel was last given for each belief (to pass on changes only).
    given: Vec<Option<(Value, Source)>>,
    /// Conditions already reported while they hold (cleared when they stop).
    informed: BTreeSet<(Reason, Edge)>,
    /// Termination conditions this robot waits at the point of, and when
    /// they were last reported ([`RESEND`]).
    waiting: BTreeMap<Edge, Time>,
    /// Broadcast: beliefs changed since the last share.
    changed: BTreeSet<BeliefId>,
    queue: VecDeque<(Time, Outgoing)>,
    tokens: f64,
    refilled: Time,
    next_share: Time,
    stats: WmStats,
}

impl WorldModel {
    /// Take a new version of the mission with `beliefs` beliefs (at least
    /// as many as before, numbered alike) and, if it says, its privacy
    /// marks (else the beliefs it adds are shared like any other).
    pub fn grow(&mut self, beliefs: usize, private: Option<std::sync::Arc<[bool]>>) {
        let n = beliefs.max(self.own.len());
        self.own.resize(n, None);
        self.told.resize(n, None);
        self.given.resize(n, None);
        if let Some(p) = private {
            self.private = p;
        }
    }

    /// The world model of robot `me` for a graph with `beliefs` beliefs;
    /// `private[b]` marks the beliefs about the robot itself (its own
    /// progress, its pose), which are neither reported nor adopted.
    pub fn new(
        me: RobotId,
        beliefs: usize,
        sharing: Sharing,
        private: std::sync::Arc<[bool]>,
    ) -> Self {
        WorldModel {
            me,
            sharing,
            private,
            own: vec![None; beliefs],
            told: vec![None; beliefs],
            given: vec![None; beliefs],
            informed: BTreeSet::new(),
            waiting: BTreeMap::new(),
            changed: BTreeSet::new(),
            queue: VecDeque::new(),
            tokens: sharing.budget.unwrap_or(0.0),
            refilled: Time::ZERO,
            next_share: Time::ZERO,
            stats: WmStats::default(),
        }
    }

    /// Its settings.
    pub fn sharing(&self) -> Sharing {
        self.sharing
    }

    /// Its counters.
    pub fn stats(&self) -> &WmStats {
        &self.stats
    }

    /// The robot's own percepts at `now`. Writes into `own_out` the
    /// percepts the kernel should take as its own and into `told_out` the
    /// beliefs a teammate's newer report decides, each only when what the
    /// kernel holds changes.
    pub fn perceive(
        &mut self,
        now: Time,
        percepts: &[(BeliefId, Value)],
        own_out: &mut Vec<(BeliefId, Value)>,
        told_out: &mut Vec<(BeliefId, Value, Source)>,
    ) {
        for (id, v) in percepts {
            let Some(slot) = self.own.get_mut(id.index()) else {
                continue;
            };
            let changed = slot.as_ref().is_none_or(|o| o.value != *v);
            if changed {
                *slot = Some(Own {
                    value: v.clone(),
                    changed: now,
                });
                self.changed.insert(*id);
            }
            // The robot's own percept reaches the kernel at every tick, as
            // without a world model (`age(b)` counts from the last
            // reading); a teammate's value only when it changes.
            if let Some((value, Source::Percept)) = self.fused(*id) {
                self.given[id.index()] = Some((value.clone(), Source::Percept));
                own_out.push((*id, value));
            } else {
                self.settle(*id, own_out, told_out);
            }
        }
    }

    /// A teammate's message, arrived at `now` (this robot's clock: the
    /// reports' ages are read against it). Writes into `own_out` and
    /// `told_out` the beliefs it changes.
    pub fn receive(
        &mut self,
        now: Time,
        from: RobotId,
        msg: &Inform,
        own_out: &mut Vec<(BeliefId, Value)>,
        told_out: &mut Vec<(BeliefId, Value, Source)>,
    ) {
        for r in &msg.beliefs {
            self.stats.received += 1;
            if self.is_private(r.belief) {
                self.stats.ignored += 1;
                continue;
            }
            let Some(slot) = self.told.get_mut(r.belief.index()) else {
                self.stats.ignored += 1;
                continue;
            };
            let time = r.changed_at(now);
            if slot.as_ref().is_some_and(|t| t.time > time) {
                self.stats.ignored += 1; // an older report than one we have
                continue;
            }
            *slot = Some(Told {
                value: r.value.clone(),
                time,
                from,
                confidence: r.confidence.clamp(0.0, 1.0),
            });
            let before = told_out.len();
            self.settle(r.belief, own_out, told_out);
            if told_out.len() > before {
                self.stats.adopted += 1;
            }
        }
    }

    fn is_private(&self, id: BeliefId) -> bool {
        self.private.get(id.index()).copied().unwrap_or(false)
    }

    /// The fused value of a belief and where it comes from.
    fn fused(&self, id: BeliefId) -> Option<(Value, Source)> {
        let own = self.own.get(id.index())?.as_ref();
        let told = self.told.get(id.index())?.as_ref();
        match (own, told) {
            (None, None) => None,
            (Some(o), None) => Some((o.value.clone(), Source::Percept)),
            (None, Some(t)) => Some((t.value.clone(), Source::Teammate(t.from))),
            // A teammate that tells the robot what it perceives itself
            // adds nothing: the robot's own reading stands (and keeps its
            // every-tick age), however the two changes are ordered.
            (Some(o), Some(t)) if o.value == t.value => Some((o.value.clone(), Source::Percept)),
            (Some(o), Some(t)) => {
                let apart = if o.changed > t.time {
                    o.changed.saturating_since(t.time)
                } else {
                    t.time.saturating_since(o.changed)
                };
                if let (Value::Vec2(a), Value::Vec2(b)) = (&o.value, &t.value)
                    && apart <= FUSE_WINDOW
                {
                    // Confidence-weighted position.
                    let (wa, wb) = (OWN_CONFIDENCE as f64, t.confidence as f64);
                    let w = (wa + wb).max(1e-9);
                    let p = [(a[0] * wa + b[0] * wb) / w, (a[1] * wa + b[1] * wb) / w];
                    return Some((Value::Vec2(p), Source::Percept));
                }
                // At or after: a tie is a report dated where the robot's
                // own clock cannot tell the two apart (a clock held at the
                // mission's start dates every change 0), and the teammate
                // tells of a change the robot did not see.
                if t.time >= o.changed {
                    Some((t.value.clone(), Source::Teammate(t.from)))
                } else {
                    Some((o.value.clone(), Source::Percept))
                }
            }
        }
    }

    /// Pass a belief's fused value on if it changed.
    fn settle(
        &mut self,
        id: BeliefId,
        own_out: &mut Vec<(BeliefId, Value)>,
        told_out: &mut Vec<(BeliefId, Value, Source)>,
    ) {
        let Some(f) = self.fused(id) else {
            return;
        };
        let slot = &mut self.given[id.index()];
        if slot.as_ref() == Some(&f) {
            return;
        }
        *slot = Some(f.clone());
        match f.1 {
            Source::Percept => own_out.push((id, f.0)),
            s => told_out.push((id, f.0, s)),
        }
    }

    /// True when it is time to decide what to share again.
    pub fn due(&self, now: Time) -> bool {
        self.sharing.policy != Policy::None && now >= self.next_share
    }

    /// Decide what to tell whom, from the kernel's state (its stack, its
    /// copy of the hierarchy, its beliefs). Queues messages for [`poll`].
    ///
    /// [`poll`]: WorldModel::poll
    pub fn share(&mut self, now: Time, kernel: &Kernel) {
        if self.sharing.policy == Policy::None {
            return;
        }
        let period = Duration::from_secs_f64(1.0 / self.sharing.hz.max(1e-3));
        self.next_share = now + period;
        let graph = kernel.mission().graph();
        let beliefs = kernel.beliefs();
        let org = kernel.org();
        let mut keep: BTreeSet<(Reason, Edge)> = BTreeSet::new();
        let mut out: Vec<Outgoing> = Vec::new();
        if self.sharing.policy == Policy::Broadcast {
            let changed = std::mem::take(&mut self.changed);
            // Every change of every belief, the robot's private ones too
            // (teammates ignore those): the baseline's cost.
            let reports: Vec<Report> = changed
                .into_iter()
                .filter_map(|id| {
                    let b = beliefs.get(id).filter(|b| b.source == Source::Percept)?;
                    let changed = self
                        .own
                        .get(id.index())?
                        .as_ref()
                        .map_or(b.time, |o| o.changed);
                    Some(Report::new(
                        id,
                        b.value.clone(),
                        changed,
                        now,
                        OWN_CONFIDENCE,
                    ))
                })
                .collect();
            let to: Vec<RobotId> = (0..graph.roster().len() as u32)
                .map(RobotId)
                .filter(|r| *r != self.me && !kernel.lost().contains(*r))
                .collect();
            if !reports.is_empty() && !to.is_empty() {
                out.push(Outgoing {
                    to,
                    msg: Inform {
                        reason: Reason::Broadcast,
                        about: None,
                        beliefs: reports,
                    },
                });
            }
        } else {
            self.changed.clear();
        }
        let (me, lost) = (self.me, kernel.lost());
        let inform = |t, reason, about, beliefs| inform(me, lost, t, reason, about, beliefs);
        // (reason, the subteam, the behavior, the edge, the reports).
        let mut found = Vec::new();
        if self.sharing.policy.focused() {
            let held = |f: &crate::kernel::Frame| {
                let at = (now, f.started);
                self.conditions(graph, beliefs, at, f.behavior, f.team, f.epoch)
            };
            // Algorithm 2: behaviors on the stack, their own subteams.
            for f in kernel.stack() {
                let Some(t) = org.team(f.team) else { continue };
                for (edge, reports) in held(f) {
                    found.push((Reason::Obligatory, t, f.behavior, edge, reports));
                }
            }
            // Waiting at the termination point of a behavior whose
            // condition holds here: the report that condition made may
            // have been lost (a teammate that never believes it never
            // reaches the point, and the team waits for ever). Told again
            // every `RESEND` while waiting; a teammate that heard it
            // already holds a report as new, and ignores it.
            let mut still = BTreeMap::new();
            if let Some(f) = kernel.ending()
                && let Some(t) = org.team(f.team)
            {
                for (edge, reports) in held(f).into_iter().filter(|(e, _)| e.3.is_none()) {
                    let last = self.waiting.get(&edge).copied().unwrap_or(now);
                    if now - last >= RESEND {
                        still.insert(edge, now);
                        out.extend(inform(t, Reason::Obligatory, f.behavior, reports));
                    } else {
                        still.insert(edge, last);
                    }
                }
            }
            self.waiting = still;
        }
        if self.sharing.policy.helpful() {
            // Algorithm 3: every subteam, its behaviors not on this stack.
            let on_stack: BTreeSet<BehaviorId> =
                kernel.stack().iter().map(|f| f.behavior).collect();
            for t in org.teams() {
                for b in org.behaviors_of(t.id).filter(|b| !on_stack.contains(b)) {
                    let epoch = org.runs(t.id, b);
                    for (edge, reports) in
                        self.conditions(graph, beliefs, (now, now), b, t.id, epoch)
                    {
                        found.push((Reason::Helpful, t, b, edge, reports));
                    }
                }
            }
        }
        // Once per condition while it holds.
        for (reason, t, about, edge, reports) in found {
            keep.insert((reason, edge));
            if self.informed.insert((reason, edge)) {
                out.extend(inform(t, reason, about, reports));
            }
        }
        // A condition that stopped holding may be reported again when it
        // next becomes true.
        self.informed.retain(|k| keep.contains(k));
        self.queue.extend(out.into_iter().map(|o| (now, o)));
        // Bounded: under a budget too tight for a condition that keeps
        // flipping, the oldest messages go first (counted).
        while self.queue.len() > MAX_QUEUED {
            if let Some((_, o)) = self.queue.pop_front() {
                self.stats.dropped += o.to.len() as u64;
            }
        }
        // Obligatory messages first.
        let (mut first, rest): (VecDeque<_>, VecDeque<_>) = std::mem::take(&mut self.queue)
            .into_iter()
            .partition(|(_, o)| o.msg.reason == Reason::Obligatory);
        first.extend(rest);
        self.queue = first;
    }

    /// The kernel has just ended a behavior by its own condition and waits
    /// at its termination point, on beliefs this world model has not
    /// reported: it was not due at this tick. A robot whose clock runs slow
    /// decides what to share less often than its kernel ticks, and a
    /// condition that held for one tick (a noisy sighting) would never
    /// reach the teammates, who then never reach the point, and the team
    /// waits for ever; one that holds on would reach them only at the
    /// first [`RESEND`]. What the condition read is reported at once
    /// (obligatory), and again every [`RESEND`] while it holds (see
    /// [`WorldModel::share`]). Call after every tick of the kernel.
    pub fn share_ending(&mut self, now: Time, kernel: &Kernel) {
        if !self.sharing.policy.focused() {
            return;
        }
        let Some(f) = kernel.ending() else {
            return;
        };
        let Some(t) = kernel.org().team(f.team) else {
            return;
        };
        let graph = kernel.mission().graph();
        let held = self.conditions(
            graph,
            kernel.beliefs(),
            (now, f.started),
            f.behavior,
            f.team,
            f.epoch,
        );
        for (edge, reports) in held.into_iter().filter(|(e, _)| e.3.is_none()) {
            if self.informed.contains(&(Reason::Obligatory, edge))
                || self.waiting.contains_key(&edge)
            {
                continue;
            }
            self.informed.insert((Reason::Obligatory, edge));
            self.waiting.insert(edge, now);
            // Obligatory: ahead of any helpful message waiting.
            if let Some(o) = inform(
                self.me,
                kernel.lost(),
                t,
                Reason::Obligatory,
                f.behavior,
                reports,
            ) {
                self.queue.push_front((now, o));
            }
        }
    }

    /// The conditions of behavior `b` (run by team `t`, execution `epoch`)
    /// that hold on this robot's beliefs and rest on at least one belief of
    /// its own: its termination condition and its sequential successors'
    /// preconditions, each with the reports that make it hold.
    #[allow(clippy::too_many_arguments)]
    fn conditions(
        &self,
        graph: &BehaviorGraph,
        beliefs: &BeliefStore,
        (now, started): (Time, Time),
        b: BehaviorId,
        t: TeamId,
        epoch: u32,
    ) -> Vec<(Edge, Vec<Report>)> {
        let Some(beh) = graph.get(b) else {
            return Vec::new();
        };
        let env = BeliefEnv {
            beliefs,
            runs: &crate::belief::RunCounts::new(),
            now,
            started,
            own: b,
        };
        let mut found = Vec::new();
        let until = beh.until.as_ref().map(|e| (None, e));
        let pres = beh.next.iter().filter_map(|f| {
            graph
                .get(*f)
                .and_then(|x| x.pre.as_ref())
                .map(|e| (Some(*f), e))
        });
        for (succ, e) in until.into_iter().chain(pres) {
            if e.beliefs().is_empty() || !e.eval(&env) {
                continue;
            }
            // Only what this robot perceived itself: a belief a teammate
            // told it, that teammate has told whom it had to.
            let own = e.beliefs().iter().any(|id| {
                !self.is_private(*id)
                    && beliefs
                        .get(*id)
                        .is_some_and(|x| x.source == Source::Percept)
            });
            if !own {
                continue;
            }
            let reports: Vec<Report> = e
                .beliefs()
                .iter()
                .filter_map(|id| self.report(now, beliefs, *id))
                .collect();
            if !reports.is_empty() {
                found.push(((t, b, epoch, succ), reports));
            }
        }
        found
    }

    /// A report of belief `id` as the kernel holds it (none for a private
    /// belief).
    fn report(&self, now: Time, beliefs: &BeliefStore, id: BeliefId) -> Option<Report> {
        if self.is_private(id) {
            return None;
        }
        let b = beliefs.get(id)?;
        // When the value changed where it was observed: ours, or the
        // time the teammate reported (not when we stored it).
        let time = match b.source {
            Source::Percept => self
                .own
                .get(id.index())?
                .as_ref()
                .map_or(b.time, |o| o.changed),
            _ => self
                .told
                .get(id.index())?
                .as_ref()
                .map_or(b.time, |t| t.time),
        };
        Some(Report::new(id, b.value.clone(), time, now, OWN_CONFIDENCE))
    }

    /// The next message to send now, within the budget.
    pub fn poll(&mut self, now: Time) -> Option<Outgoing> {
        if let Some(budget) = self.sharing.budget {
            let dt = now.saturating_since(self.refilled).as_secs_f64();
            self.tokens = (self.tokens + dt * budget).min(budget.max(1.0));
            self.refilled = now;
        }
        loop {
            let (at, front) = self.queue.front()?;
            if front.msg.reason != Reason::Obligatory && now.saturating_since(*at) > HELPFUL_TTL {
                self.stats.dropped += front.to.len() as u64;
                self.queue.pop_front();
                continue;
            }
            let cost = front.to.len() as f64;
            if self.sharing.budget.is_some() && self.tokens < cost.min(self.tokens.max(1.0)) {
                return None; // wait for budget
            }
            let (at, mut o) = self.queue.pop_front()?;
            // Ages count to the moment the message leaves.
            let waited = now.saturating_since(at);
            if !waited.is_zero() {
                o.msg.beliefs.iter_mut().for_each(|r| r.aged(waited));
            }
            if self.sharing.budget.is_some() {
                self.tokens -= cost;
            }
            let k = o.msg.reason.index();
            let n = o.to.len() as u64;
            self.stats.messages[k] += n;
            self.stats.bytes[k] += n * o.msg.bytes() as u64;
            return Some(o);
        }
    }

    /// Messages waiting for budget.
    pub fn queued(&self) -> usize {
        self.queue.len()
    }
}

/// Inform(b, t): `beliefs` about behavior `about` for the live members of
/// team `t` other than robot `me`; none if there are none.
fn inform(
    me: RobotId,
    lost: &MemberSet,
    t: &crate::org::Team,
    reason: Reason,
    about: BehaviorId,
    beliefs: Vec<Report>,
) -> Option<Outgoing> {
    let to: Vec<RobotId> = (t.members.iter())
        .filter(|r| *r != me && !lost.contains(*r))
        .collect();
    (!to.is_empty()).then_some(Outgoing {
        to,
        msg: Inform {
            reason,
            about: Some(about),
            beliefs,
        },
    })
}

/// A name for each belief of a message, for logs.
pub fn belief_names(graph: &BehaviorGraph, msg: &Inform) -> Vec<String> {
    msg.beliefs
        .iter()
        .map(|r| graph.symbols().name(r.belief).to_string())
        .collect()
}

/// Per-reason totals over a team, for summaries.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SharingTotals {
    /// The policy.
    pub policy: String,
    /// Messages by reason (one per recipient).
    pub messages: BTreeMap<String, u64>,
    /// Bytes by reason.
    pub bytes: BTreeMap<String, u64>,
    /// Dropped for want of budget.
    pub dropped: u64,
    /// Reports that changed a teammate's belief.
    pub adopted: u64,
}

impl SharingTotals {
    /// Sum the robots' counters.
    pub fn of<'a>(policy: Policy, stats: impl IntoIterator<Item = &'a WmStats>) -> Self {
        let mut t = SharingTotals {
            policy: policy.to_string(),
            ..SharingTotals::default()
        };
        for s in stats {
            for r in Reason::ALL {
                *t.messages.entry(r.to_string()).or_insert(0) += s.messages[r.index()];
                *t.bytes.entry(r.to_string()).or_insert(0) += s.bytes[r.index()];
            }
            t.dropped += s.dropped;
            t.adopted += s.adopted;
        }
        t
    }
    /// All messages.
    pub fn total(&self) -> u64 {
        self.messages.values().sum()
    }
}
