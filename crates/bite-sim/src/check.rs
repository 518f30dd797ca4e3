//! Invariants checked over a recorded run (record, then check — as etcd's
//! robustness tests do). Every scenario and property test runs these.
//!
//! - **agreement**: all members that decided a synchronization instance
//!   normally (not by timeout) chose the same successor, among members that
//!   could talk (neither presumed the other lost). A protocol guarantees it
//!   *always* when it communicates; a silent rule only *when perceptions
//!   agree* — among members whose instances saw the same options and left
//!   out the same teammates (`docs/protocols.md`);
//! - **splits healed**: members that could talk never run two successors
//!   of the same point side by side for longer than [`SPLIT_BOUND`] (a
//!   silent rule's split is healed through the heartbeats);
//! - **allocation**: all members that decided an allocation instance
//!   normally hold the same assignment; no robot is given two children; no
//!   child is left without members while another child has more than its
//!   minimum; no member is left out while a child has room;
//! - **team termination**: once a communicating termination protocol
//!   decided that the team ended a behavior, every member running it ends it
//!   (unless it crashed, or the run stopped within the grace period);
//! - **epochs**: a robot's executions of a behavior by a team are numbered
//!   1, 2, 3…, strictly increasing (an execution burned to converge with
//!   the team is skipped, never repeated);
//! - **stack**: every termination matches an earlier selection;
//! - **organization**: every robot's hierarchy is structurally sound.

use crate::runner::{FinalRobot, RunReport};
use bite_core::event::{Event, LogList, MembersLog, OutcomeLog};
use bite_core::ids::{BehaviorId, RobotId, TeamId};
use bite_core::mission::Mission;
use bite_core::msg::{InstanceKey, Kind};
use bite_core::time::Time;
use rustc_hash::{FxHashMap, FxHashSet};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::sync::Arc;
use std::time::Duration;

/// Longest two members that could talk may run different successors of
/// one point side by side before the split counts as unhealed (healing
/// takes a heartbeat or two; a lossy network may need a few).
pub const SPLIT_BOUND: Duration = Duration::from_secs(5);

/// The invariants [`Checker`] checks, by name.
pub const CHECKED: [&str; 8] = [
    "agreement",
    "allocation",
    "splits-healed",
    "team-termination",
    "epochs",
    "stack",
    "organization",
    "mission-change",
];

/// What the checker found, for summaries.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Invariants {
    /// The invariants checked.
    pub checked: Vec<&'static str>,
    /// Violations found.
    pub violations: usize,
    /// The first one, if any.
    pub first: Option<String>,
}

impl Invariants {
    /// The summary of a list of violations.
    pub fn of(v: &[Violation]) -> Self {
        Invariants {
            checked: CHECKED.to_vec(),
            violations: v.len(),
            first: v.first().map(ToString::to_string),
        }
    }
}

/// A broken invariant.
#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    /// Which invariant.
    pub invariant: &'static str,
    /// What happened.
    pub detail: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}] {}", self.invariant, self.detail)
    }
}

/// Check every invariant over a recorded run (`record: true`), from its
/// history: the same checks every run makes as it goes (its
/// [`RunReport::violations`]).
pub fn check(report: &RunReport, mission: &Arc<Mission>) -> Vec<Violation> {
    let mut c = Checker::new(mission.clone());
    for rec in &report.history {
        c.observe(rec.t, rec.robot, &rec.event);
    }
    c.finish(report.end, &report.crashes, &report.finals)
}

/// Check every invariant over the run logs of a team that ran as separate
/// processes (`bite launch`), each as (robot name, records), as a simulated
/// run is checked. Records are merged by their team time. A robot in
/// `stopped` (killed, or exited before the end) counts as crashed at its
/// last record. Returns the violations and the number of records checked.
pub fn check_logs(
    mission: &Arc<Mission>,
    logs: &[(String, Vec<serde_json::Value>)],
    stopped: &[&str],
) -> (Vec<Violation>, usize) {
    let graph = mission.graph();
    let namer = crate::log::Namer::new(graph);
    let mut events = Vec::new();
    let mut crashes = Vec::new();
    let mut end = Time::ZERO;
    for (name, records) in logs {
        let Some(robot) = graph.roster().find(name) else {
            continue;
        };
        let mut last = Time::ZERO;
        for rec in records {
            if let Some(t) = rec.get("t").and_then(serde_json::Value::as_f64) {
                last = last.max(Time::from_secs_f64(t.max(0.0)));
            }
            if let Some((t, r, e)) = namer.unrecord(mission, rec)
                && r == robot
            {
                events.push((t, robot, events.len(), e));
            }
        }
        end = end.max(last);
        if stopped.contains(&name.as_str()) {
            crashes.push((robot, last, None));
        }
    }
    events.sort_by_key(|(t, r, i, _)| (*t, *r, *i));
    let mut c = Checker::new(mission.clone());
    for (t, r, _, e) in &events {
        c.observe(*t, *r, e);
    }
    (c.finish(end, &crashes, &[]), events.len())
}

/// An execution: team, behavior, epoch.
type Exec = (TeamId, BehaviorId, u32);

/// A member's runs of the successors of one point: nearly always one.
type Legs = smallvec::SmallVec<[Leg; 1]>;

/// When a member started and terminated one execution (`Time(u64::MAX)`:
/// not seen; one table of both, not two of one each).
#[derive(Clone, Copy, Debug)]
struct Span {
    started: Time,
    terminated: Time,
}

impl Span {
    const NONE: Span = Span {
        started: Time(u64::MAX),
        terminated: Time(u64::MAX),
    };
    fn started(self) -> Option<Time> {
        (self.started != Span::NONE.started).then_some(self.started)
    }
    fn terminated(self) -> Option<Time> {
        (self.terminated != Span::NONE.terminated).then_some(self.terminated)
    }
}

/// A member's choice after a point: the version it chose in, and whom it
/// presumed lost then (`None`: nobody).
type Chosen = (RobotId, u32, Option<Box<BTreeSet<RobotId>>>);

/// One member's run of a successor of a point.
#[derive(Clone, Copy, Debug)]
struct Leg {
    behavior: BehaviorId,
    from: Time,
    until: Option<Time>,
}

/// A member's leg as the run records it, packed (24 bytes, against 40 for
/// a robot beside a [`Leg`]; a 100,000-robot run records about a million).
#[derive(Clone, Copy, Debug)]
struct LegOf {
    robot: RobotId,
    behavior: BehaviorId,
    from: Time,
    /// [`LegOf::OPEN`] while it runs.
    until: Time,
}

impl LegOf {
    const OPEN: Time = Time(u64::MAX);
    fn leg(self) -> Leg {
        Leg {
            behavior: self.behavior,
            from: self.from,
            until: (self.until != LegOf::OPEN).then_some(self.until),
        }
    }
}

/// What the members of a silent rule's instance saw when they started it:
/// whom it left out and what it could choose. Members nearly always see
/// the same, so each distinct pair is stored once and a member holds its
/// index (at 100,000 robots, a pair per member and instance was a tenth of
/// a run's memory: docs/performance.md, "2026-11-28, late").
#[derive(Default)]
struct SilentViews {
    distinct: Vec<(BTreeSet<RobotId>, LogList<BehaviorId>)>,
    of: FxHashMap<RobotId, u32>,
}

impl SilentViews {
    /// Robot `r`'s instance started (again) with this view.
    fn insert(&mut self, r: RobotId, left_out: BTreeSet<RobotId>, options: &LogList<BehaviorId>) {
        // Only the latest few are compared: a view equal to an older one
        // is stored again, which costs room, never a wrong answer.
        let tail = self.distinct.len().saturating_sub(4);
        let found = (self.distinct[tail..].iter())
            .position(|(l, o)| *l == left_out && o == options)
            .map(|i| tail + i);
        let i = found.unwrap_or_else(|| {
            self.distinct.push((left_out, options.clone()));
            self.distinct.len() - 1
        });
        self.of.insert(r, i as u32);
    }

    /// What robot `r`'s instance saw, if it started.
    fn of(&self, r: RobotId) -> Option<&(BTreeSet<RobotId>, LogList<BehaviorId>)> {
        self.of.get(&r).map(|&i| &self.distinct[i as usize])
    }
}

/// Checks invariants as a run goes: fed every event in order
/// ([`Checker::observe`]), it keeps only what later checks need, then
/// [`Checker::finish`] reports the violations. Every simulated run (`bite
/// run`, `bite sweep`, the tests) runs one.
pub struct Checker {
    mission: Arc<Mission>,
    v: Vec<Violation>,
    sync: BTreeMap<InstanceKey, BTreeMap<RobotId, Option<BehaviorId>>>,
    alloc: BTreeMap<InstanceKey, BTreeMap<RobotId, LogList<(BehaviorId, MembersLog)>>>,
    ended: BTreeMap<InstanceKey, Time>,
    // What is only looked up, never walked in order, is kept in hash
    // tables: at 100,000 robots they hold an entry per robot and
    // execution, and as B-trees of millions of entries they cost a large
    // team's first decisions about 15 % (docs/performance.md,
    // "2026-11-28"). Whatever a violation is reported from is walked in
    // order (B-trees).
    /// Who each robot presumes lost, as the run goes (for "could talk").
    lost_now: FxHashMap<RobotId, BTreeSet<RobotId>>,
    /// Whom each robot ever presumed lost.
    ever_lost: FxHashMap<RobotId, BTreeSet<RobotId>>,
    // A run's records grow with robots × executions, so what a check
    // reads only while an instance runs is dropped when it ends, and an
    // empty set is not stored (absent reads as empty): a 100,000-robot
    // formation run peaked at 3.6 GB, a fifth of it here (docs/performance.md,
    // "2026-11-28, evening").
    /// Whom each robot's instance presumed lost or left out when it
    /// decided, by instance (robots whose view was empty: absent).
    view_at: FxHashMap<InstanceKey, FxHashMap<RobotId, BTreeSet<RobotId>>>,
    /// Synchronizations and allocations run by a silent rule (no
    /// messages), under the mission version they started in, with what
    /// each member's instance saw when it started: only their members'
    /// perceptions say whether they should have agreed. Kept to the end.
    silent: FxHashMap<InstanceKey, SilentViews>,
    /// Whom each robot's instance of a talking rule left out from its
    /// start (only when not empty, until the robot's instance ends), and
    /// whom it presumed lost while the instance ran (until it ends).
    left_out_at: FxHashMap<(InstanceKey, RobotId), BTreeSet<RobotId>>,
    lost_during: FxHashMap<(InstanceKey, RobotId), BTreeSet<RobotId>>,
    open: FxHashMap<RobotId, BTreeSet<InstanceKey>>,
    timed_out_at: FxHashSet<InstanceKey>,
    /// Who decided each instance by its deadline, and whose successor a
    /// robot left behind took at an instance (`Event::LeftBehind`): a
    /// robot that took the successor of a teammate that decided by its
    /// deadline decided by that deadline too.
    timed_out_by: FxHashSet<(InstanceKey, RobotId)>,
    followed: FxHashMap<(InstanceKey, RobotId), RobotId>,
    selected: BTreeMap<Exec, BTreeSet<RobotId>>,
    /// Behaviors whose termination communicates in some version of the
    /// mission seen so far (by index): only their executions' starts and
    /// ends are read (team termination).
    team_ended: Vec<bool>,
    /// When each member started and terminated each execution of those.
    /// (By execution, then member: one table keyed by both repeated the
    /// execution's 16 bytes in every member's entry.)
    spans: FxHashMap<Exec, FxHashMap<RobotId, Span>>,
    /// Each member's last epoch of each team's behavior (by team and
    /// behavior, then member, as `spans`).
    last_epoch: FxHashMap<(TeamId, BehaviorId), FxHashMap<RobotId, u32>>,
    /// After each point (team, behavior, epoch), what its members ran, in
    /// the order they started it (grouped by member at the end: a B-tree
    /// per point, half-full nodes of 40-byte entries, was twice the room).
    legs: BTreeMap<Exec, Vec<LegOf>>,
    /// Where each robot's running legs are, to close them when they end.
    running_leg: FxHashMap<(RobotId, TeamId, BehaviorId, u32), (Exec, usize)>,
    /// The version of the mission each robot runs.
    version: FxHashMap<RobotId, u32>,
    /// After each point, the version each member chose its successor in,
    /// and whom it presumed lost then (nearly always nobody), in the order
    /// they chose (a later choice replaces an earlier one).
    chosen_in: BTreeMap<Exec, Vec<Chosen>>,
}

impl Checker {
    /// A checker for runs of `mission`.
    pub fn new(mission: Arc<Mission>) -> Self {
        let mut c = Checker {
            mission,
            v: Vec::new(),
            sync: BTreeMap::new(),
            alloc: BTreeMap::new(),
            ended: BTreeMap::new(),
            lost_now: FxHashMap::default(),
            ever_lost: FxHashMap::default(),
            view_at: FxHashMap::default(),
            silent: FxHashMap::default(),
            left_out_at: FxHashMap::default(),
            lost_during: FxHashMap::default(),
            open: FxHashMap::default(),
            timed_out_at: FxHashSet::default(),
            timed_out_by: FxHashSet::default(),
            followed: FxHashMap::default(),
            selected: BTreeMap::new(),
            team_ended: Vec::new(),
            spans: FxHashMap::default(),
            last_epoch: FxHashMap::default(),
            legs: BTreeMap::new(),
            running_leg: FxHashMap::default(),
            version: FxHashMap::default(),
            chosen_in: BTreeMap::new(),
        };
        c.note_team_ended();
        c
    }

    /// Mark the behaviors whose termination communicates in the current
    /// mission (marks from earlier versions stay).
    fn note_team_ended(&mut self) {
        let graph = self.mission.graph();
        self.team_ended
            .resize(graph.len().max(self.team_ended.len()), false);
        for i in 0..graph.len() {
            if self
                .mission
                .bound(BehaviorId(i as u32), Kind::Terminate)
                .is_some_and(|x| x.protocol.communicates())
            {
                self.team_ended[i] = true;
            }
        }
    }

    fn team_ends(&self, b: BehaviorId) -> bool {
        self.team_ended.get(b.index()).copied().unwrap_or(false)
    }

    /// A newer version of the mission was handed to the team: name
    /// behaviors after it (versions are numbered alike, so it names every
    /// earlier version's behaviors too).
    pub fn set_mission(&mut self, mission: Arc<Mission>) {
        self.mission = mission;
        self.note_team_ended();
    }

    /// Robot `r`'s process restarted with a fresh mind: it is held to
    /// nothing its previous incarnation started, and its epochs count on
    /// from where it rejoins.
    pub fn restarted(&mut self, r: RobotId) {
        for members in self.selected.values_mut() {
            members.remove(&r);
        }
        for members in self.last_epoch.values_mut() {
            members.remove(&r);
        }
        self.running_leg.retain(|(robot, _, _, _), _| *robot != r);
        self.open.remove(&r);
    }

    /// Violations found so far that can be told before the run ends.
    pub fn early(&self) -> &[Violation] {
        &self.v
    }

    /// Whether `b` is a team behavior (one the checker does not know, of a
    /// version it has not seen, is taken for one).
    fn is_team(&self, b: BehaviorId) -> bool {
        let g = self.mission.graph();
        b.index() >= g.len() || g.behavior(b).team
    }

    fn name(&self, b: BehaviorId) -> String {
        self.mission.graph().name_of(b).to_string()
    }

    /// One event of robot `robot` at `t`.
    pub fn observe(&mut self, t: Time, robot: RobotId, event: &Event) {
        if let Event::InteractionDecided { instance, .. }
        | Event::InteractionAborted { instance, .. } = event
            && let Some(o) = self.open.get_mut(&robot)
        {
            o.remove(instance);
        }
        match event {
            Event::MemberLost { member } => {
                self.lost_now.entry(robot).or_default().insert(*member);
                self.ever_lost.entry(robot).or_default().insert(*member);
                // Running instances decide without it from now on.
                for key in self.open.get(&robot).into_iter().flatten() {
                    self.lost_during
                        .entry((*key, robot))
                        .or_default()
                        .insert(*member);
                }
            }
            Event::MemberBack { member } => {
                self.lost_now.entry(robot).or_default().remove(member);
            }
            Event::LeftBehind { instance, member } => {
                self.followed.insert((*instance, robot), *member);
            }
            Event::LeftOut { instance, members } => {
                self.lost_during
                    .entry((*instance, robot))
                    .or_default()
                    .extend(members.iter().copied());
            }
            Event::InteractionStarted {
                instance,
                excluded,
                options,
                ..
            } => {
                // A termination's start is only tracked as open (its
                // members' losses are not read).
                let key = (*instance, robot);
                let silent = instance.kind != Kind::Terminate
                    && self
                        .mission
                        .bound(instance.behavior, instance.kind)
                        .is_some_and(|x| !x.protocol.communicates());
                if silent {
                    let excluded = excluded.iter().copied().collect();
                    (self.silent.entry(*instance).or_default()).insert(robot, excluded, options);
                } else if instance.kind != Kind::Terminate && !excluded.is_empty() {
                    let excluded = excluded.iter().copied().collect();
                    self.left_out_at.insert(key, excluded);
                } else {
                    self.left_out_at.remove(&key);
                }
                self.open.entry(robot).or_default().insert(*instance);
            }
            Event::InteractionDecided {
                instance,
                timed_out,
                ..
            } if matches!(instance.kind, Kind::Sync | Kind::Allocate) => {
                if *timed_out {
                    self.timed_out_at.insert(*instance);
                    self.timed_out_by.insert((*instance, robot));
                    self.followed.remove(&(*instance, robot));
                }
                let key = (*instance, robot);
                let mut view = self.lost_now.get(&robot).cloned().unwrap_or_default();
                let left_out = (self.silent.get(instance))
                    .and_then(|views| views.of(robot))
                    .map(|(l, _)| l)
                    .or_else(|| self.left_out_at.get(&key));
                view.extend(left_out.into_iter().flatten().copied());
                self.left_out_at.remove(&key);
                if let Some(x) = self.lost_during.remove(&key) {
                    view.extend(x);
                }
                if !view.is_empty() {
                    self.view_at
                        .entry(*instance)
                        .or_default()
                        .insert(robot, view);
                } else if let Some(views) = self.view_at.get_mut(instance) {
                    views.remove(&robot);
                }
            }
            // A termination decided, or an instance abandoned: what it
            // presumed lost is not read again.
            Event::InteractionDecided { instance, .. }
            | Event::InteractionAborted { instance, .. } => {
                let key = (*instance, robot);
                self.lost_during.remove(&key);
                self.left_out_at.remove(&key);
                self.followed.remove(&key);
            }
            _ => {}
        }
        match event {
            // Decided while leaving (the protocol's last word to its
            // teammates as an ancestor ended or a re-allocation began):
            // this robot never applied it.
            Event::InteractionAborted { instance, .. } => {
                if let Some(m) = self.sync.get_mut(instance) {
                    m.remove(&robot);
                }
                if let Some(m) = self.alloc.get_mut(instance) {
                    m.remove(&robot);
                }
            }
            Event::InteractionDecided {
                instance,
                outcome,
                timed_out: false,
                ..
            } => match outcome {
                OutcomeLog::Sync { choice } => {
                    // Left behind, it took the successor a teammate ran
                    // after the point: when that teammate decided by its
                    // deadline, so did this robot.
                    let by_deadline = (self.followed.remove(&(*instance, robot)))
                        .is_some_and(|m| self.timed_out_by.contains(&(*instance, m)));
                    if !by_deadline {
                        self.sync
                            .entry(*instance)
                            .or_default()
                            .insert(robot, *choice);
                    }
                }
                OutcomeLog::Allocate { assignment } => {
                    let views = self.alloc.entry(*instance).or_default();
                    // Members that agree share one copy of the assignment.
                    let a = match views.values().next() {
                        Some(first) if first == assignment => first.clone(),
                        _ => assignment.clone(),
                    };
                    views.insert(robot, a);
                }
                OutcomeLog::Terminate { .. } => {
                    let communicates = self
                        .mission
                        .bound(instance.behavior, Kind::Terminate)
                        .is_some_and(|b| b.protocol.communicates());
                    if communicates {
                        self.ended.entry(*instance).or_insert(t);
                    }
                }
            },
            Event::MissionChanged { version, .. } => {
                self.version.insert(robot, *version);
            }
            Event::Selected {
                behavior,
                team,
                epoch,
                after,
                ..
            } => {
                self.selected
                    .entry((*team, *behavior, *epoch))
                    .or_default()
                    .insert(robot);
                if self.team_ends(*behavior) {
                    let span = self.spans.entry((*team, *behavior, *epoch)).or_default();
                    span.entry(robot).or_insert(Span::NONE).started = t;
                }
                let last = (self.last_epoch.entry((*team, *behavior)).or_default())
                    .entry(robot)
                    .or_insert(0);
                let before = *last;
                *last = before.max(*epoch);
                if *epoch <= before {
                    let last = before;
                    self.v.push(Violation {
                        invariant: "epochs",
                        detail: format!(
                            "{robot} started `{}` for team {team} with epoch {epoch} after epoch {last}",
                            self.name(*behavior)
                        ),
                    });
                }
                if let Some(a) = after {
                    let point = (*team, a.behavior, a.epoch);
                    self.check_version(robot, point);
                    let legs = self.legs.entry(point).or_default();
                    self.running_leg
                        .insert((robot, *team, *behavior, *epoch), (point, legs.len()));
                    legs.push(LegOf {
                        robot,
                        behavior: *behavior,
                        from: t,
                        until: LegOf::OPEN,
                    });
                }
            }
            Event::Terminated {
                behavior,
                team,
                epoch,
                ..
            } => {
                if !self
                    .selected
                    .get(&(*team, *behavior, *epoch))
                    .is_some_and(|s| s.contains(&robot))
                {
                    self.v.push(Violation {
                        invariant: "stack",
                        detail: format!(
                            "{robot} terminated `{}` #{epoch} without selecting it",
                            self.name(*behavior)
                        ),
                    });
                }
                if self.team_ends(*behavior) {
                    let span = self.spans.entry((*team, *behavior, *epoch)).or_default();
                    span.entry(robot).or_insert(Span::NONE).terminated = t;
                }
                if let Some((point, i)) =
                    self.running_leg.remove(&(robot, *team, *behavior, *epoch))
                    && let Some(l) = self.legs.get_mut(&point).and_then(|m| m.get_mut(i))
                {
                    l.until = t;
                }
            }
            _ => {}
        }
    }

    /// Robot `r` (restarted) runs version `version` of the mission.
    pub fn runs_version(&mut self, r: RobotId, version: u32) {
        self.version.insert(r, version);
    }

    /// Record the version `robot` chose the successor of `point` in (a
    /// member that re-chooses there, converging after a split, replaces
    /// its earlier choice).
    fn check_version(&mut self, robot: RobotId, point: Exec) {
        let v = self.version.get(&robot).copied().unwrap_or(0);
        let lost = (self.lost_now.get(&robot))
            .filter(|l| !l.is_empty())
            .map(|l| Box::new(l.clone()));
        self.chosen_in
            .entry(point)
            .or_default()
            .push((robot, v, lost));
    }

    /// Every member of a team chooses what follows a point under the same
    /// version of the mission, once splits have healed: a team switches
    /// versions together, at one safe point (members that presumed each
    /// other lost then, cut off from each other, each decide on their
    /// own side).
    fn check_versions(&mut self) {
        let none = BTreeSet::new();
        for (point, choices) in std::mem::take(&mut self.chosen_in) {
            let members: BTreeMap<RobotId, (u32, &BTreeSet<RobotId>)> = (choices.iter())
                .map(|(r, v, lost)| (*r, (*v, lost.as_deref().unwrap_or(&none))))
                .collect();
            // Usually everyone chose in the same version: one linear pass
            // settles it (the pairwise search below is quadratic).
            let mut versions = members.values().map(|(v, _)| *v);
            let first = versions.next();
            if versions.all(|v| Some(v) == first) {
                continue;
            }
            let mut clash = None;
            for (a, (va, lost_a)) in &members {
                for (b, (vb, lost_b)) in members.range(*a..) {
                    if va != vb && !lost_a.contains(b) && !lost_b.contains(a) {
                        clash = Some((*a, *va, *b, *vb));
                    }
                }
            }
            if let Some((a, va, b, vb)) = clash {
                let detail = format!(
                    "after `{}` #{} (team {}), {a} chose in version {va} and {b} in version {vb}",
                    self.name(point.1),
                    point.2,
                    point.0
                );
                self.v.push(Violation {
                    invariant: "mission-change",
                    detail,
                });
            }
        }
    }

    /// The run ended at `end`: run the checks that need the whole run.
    pub fn finish(
        mut self,
        end: Time,
        crashes: &[(RobotId, Time, Option<Time>)],
        finals: &[FinalRobot],
    ) -> Vec<Violation> {
        self.check_decisions();
        self.check_splits(end, crashes);
        self.check_versions();
        self.check_termination(end, crashes);
        for f in finals {
            if let Err(e) = &f.org_check {
                self.v.push(Violation {
                    invariant: "organization",
                    detail: format!("{}: {e}", f.robot),
                });
            }
        }
        self.v
    }

    /// Two robots that could talk (neither presumed the other lost when it
    /// decided) must agree; robots on two sides of a partition may not.
    /// (Robots whose views of an allocation diverged after a timeout are in
    /// different teams: a team id includes its members.) A silent rule
    /// computes from what each robot perceives and knows alone, so robots
    /// that saw different options, or presumed different teammates lost,
    /// may differ; so may two robots with different views of who is alive
    /// after a teammate timed out (each learnt the outcome from a
    /// different side).
    fn could_talk(&self, key: &InstanceKey, a: RobotId, b: RobotId) -> bool {
        let views = self.view_at.get(key);
        let va = views.and_then(|v| v.get(&a));
        let vb = views.and_then(|v| v.get(&b));
        !va.is_some_and(|v| v.contains(&b))
            && !vb.is_some_and(|v| v.contains(&a))
            && self.silent.get(key).is_none_or(|s| s.of(a) == s.of(b))
            && (!self.timed_out_at.contains(key) || va == vb)
    }

    fn check_decisions(&mut self) {
        fn split<T: PartialEq>(
            m: &BTreeMap<RobotId, T>,
            talk: &dyn Fn(RobotId, RobotId) -> bool,
        ) -> bool {
            // Usually everyone agrees: one linear pass settles it.
            let mut values = m.values();
            let first = values.next();
            if values.all(|x| Some(x) == first) {
                return false;
            }
            m.iter()
                .any(|(a, x)| m.iter().any(|(b, y)| a < b && x != y && talk(*a, *b)))
        }
        let mut v = Vec::new();
        for (key, choices) in &self.sync {
            if split(choices, &|a, b| self.could_talk(key, a, b)) {
                v.push(Violation {
                    invariant: "agreement",
                    detail: format!(
                        "members chose different successors after `{}` ({key}): {}",
                        self.name(key.behavior),
                        choices
                            .iter()
                            .map(|(r, c)| format!(
                                "{r}→{}",
                                c.map_or("end".to_string(), |c| self.name(c))
                            ))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                });
            }
        }
        for (key, views) in &self.alloc {
            if split(views, &|a, b| self.could_talk(key, a, b)) {
                v.push(Violation {
                    invariant: "allocation",
                    detail: format!(
                        "members hold different allocations at `{}` ({key})",
                        self.name(key.behavior)
                    ),
                });
                continue;
            }
            self.check_assignments(key, views, &mut v);
        }
        self.v.extend(v);
    }

    /// Each distinct assignment (one per view of the team) must be sound,
    /// and each robot must hold a child in its own view when one had room.
    fn check_assignments(
        &self,
        key: &InstanceKey,
        views: &BTreeMap<RobotId, LogList<(BehaviorId, MembersLog)>>,
        v: &mut Vec<Violation>,
    ) {
        let slots = self.mission.child_slots(key.behavior);
        let mut distinct: Vec<&LogList<(BehaviorId, MembersLog)>> = Vec::new();
        for a in views.values() {
            if !distinct.contains(&a) {
                distinct.push(a);
            }
        }
        for asg in distinct {
            // Member lists are logged for subteams up to 64 robots; larger
            // ones are compared by fingerprint above and counted here.
            let mut seen = BTreeSet::new();
            let mut listed = true;
            for (_, members) in asg.iter() {
                match members {
                    MembersLog::List(ms) => {
                        for m in ms {
                            if !seen.insert(*m) {
                                v.push(Violation {
                                    invariant: "allocation",
                                    detail: format!(
                                        "{m} got two children at `{}` ({key})",
                                        self.name(key.behavior)
                                    ),
                                });
                            }
                        }
                    }
                    MembersLog::Summary { .. } => listed = false,
                }
            }
            let count = |c: &BehaviorId| {
                asg.iter()
                    .find(|(b, _)| b == c)
                    .map_or(0, |(_, m)| m.len() as u32)
            };
            let spare = asg.iter().any(|(b, m)| {
                slots
                    .iter()
                    .any(|s| s.behavior == *b && m.len() as u32 > s.min)
            });
            for (b, members) in asg.iter() {
                if members.is_empty() && spare {
                    v.push(Violation {
                        invariant: "allocation",
                        detail: format!(
                            "child `{}` left without members at `{}` ({key}) while another child has more than it needs",
                            self.name(*b),
                            self.name(key.behavior)
                        ),
                    });
                }
            }
            let room = asg
                .iter()
                .any(|(b, _)| slots.iter().any(|s| s.behavior == *b && count(b) < s.max));
            let holders: Vec<RobotId> = views
                .iter()
                .filter(|(_, a)| *a == asg)
                .map(|(r, _)| *r)
                .collect();
            if !listed {
                let assigned: usize = asg.iter().map(|(_, m)| m.len()).sum();
                if assigned < holders.len() && room {
                    v.push(Violation {
                        invariant: "allocation",
                        detail: format!(
                            "{} of {} members got no child at `{}` ({key}) although a child had room",
                            holders.len() - assigned,
                            holders.len(),
                            self.name(key.behavior)
                        ),
                    });
                }
                continue;
            }
            // A robot some teammate's instance left out (presumed lost at
            // its start or before it decided) was left out on purpose, even
            // if it came back meanwhile: it rejoins at the next point.
            let left_out = |r: RobotId| {
                self.view_at
                    .get(key)
                    .is_some_and(|views| views.values().any(|v| v.contains(&r)))
            };
            for r in holders.iter().copied() {
                if !seen.contains(&r) && room && !left_out(r) {
                    v.push(Violation {
                        invariant: "allocation",
                        detail: format!(
                            "{r} got no child at `{}` ({key}) although a child had room",
                            self.name(key.behavior)
                        ),
                    });
                }
            }
        }
    }

    /// Members that could talk must not run different successors of one
    /// point side by side for longer than [`SPLIT_BOUND`].
    fn check_splits(&mut self, end: Time, crashes: &[(RobotId, Time, Option<Time>)]) {
        let crashed = |r: RobotId| crashes.iter().any(|(c, _, _)| *c == r);
        let talked = |a: RobotId, b: RobotId| {
            !self.ever_lost.get(&a).is_some_and(|s| s.contains(&b))
                && !self.ever_lost.get(&b).is_some_and(|s| s.contains(&a))
        };
        let mut v = Vec::new();
        for ((team, point, epoch), legs) in &self.legs {
            let mut members: BTreeMap<RobotId, Legs> = BTreeMap::new();
            for l in legs {
                members.entry(l.robot).or_default().push(l.leg());
            }
            if !may_split(&members, end, &crashed) {
                continue;
            }
            let robots: Vec<&RobotId> = members.keys().collect();
            'pairs: for (i, a) in robots.iter().enumerate() {
                for b in &robots[i + 1..] {
                    if crashed(**a) || crashed(**b) || !talked(**a, **b) {
                        continue;
                    }
                    for la in &members[a] {
                        for lb in &members[b] {
                            // A robot in an individual behavior runs it at
                            // its own pace, in no team execution: beside a
                            // teammate's team successor it is no split (a
                            // point with one team successor synchronizes
                            // nobody).
                            if la.behavior == lb.behavior
                                || !self.is_team(la.behavior)
                                || !self.is_team(lb.behavior)
                            {
                                continue;
                            }
                            let from = la.from.max(lb.from);
                            let until = la.until.unwrap_or(end).min(lb.until.unwrap_or(end));
                            if until > from && until - from > SPLIT_BOUND {
                                v.push(Violation {
                                    invariant: "splits-healed",
                                    detail: format!(
                                        "after `{}` #{epoch} (team {team}) {a} ran `{}` and {b} ran `{}` side by side for {:.1} s from {from}",
                                        self.name(*point),
                                        self.name(la.behavior),
                                        self.name(lb.behavior),
                                        (until - from).as_secs_f64()
                                    ),
                                });
                                break 'pairs;
                            }
                        }
                    }
                }
            }
        }
        self.v.extend(v);
    }

    /// A member must end a behavior its team ended within a grace period:
    /// two deadlines of the termination binding (time to hear it, with
    /// retries) and a second.
    fn check_termination(&mut self, end: Time, crashes: &[(RobotId, Time, Option<Time>)]) {
        // Robots that crashed for good are not held to anything after their
        // crash; a paused robot is held to it from its resumption on.
        let crashed: BTreeSet<RobotId> = crashes
            .iter()
            .filter(|(_, t, until)| *t <= end && until.is_none_or(|u| u > end))
            .map(|(r, _, _)| *r)
            .collect();
        let resumed: BTreeMap<RobotId, Time> = crashes
            .iter()
            .filter_map(|(r, _, until)| until.filter(|u| *u <= end).map(|u| (*r, u)))
            .collect();
        let mut v = Vec::new();
        for (key, t) in &self.ended {
            let grace = self
                .mission
                .bound(key.behavior, Kind::Terminate)
                .map_or(Duration::from_secs(10), |b| {
                    b.deadline * 2 + Duration::from_secs(1)
                });
            let limit = *t + grace;
            for r in self
                .selected
                .get(&(key.team, key.behavior, key.epoch))
                .into_iter()
                .flatten()
            {
                if crashed.contains(r) {
                    continue;
                }
                // A member that started this epoch after the team ended it
                // gets the same grace from its own start.
                let span = (self.spans)
                    .get(&(key.team, key.behavior, key.epoch))
                    .and_then(|s| s.get(r))
                    .copied()
                    .unwrap_or(Span::NONE);
                let limit = span.started().map_or(limit, |s| limit.max(s + grace));
                let limit = resumed.get(r).map_or(limit, |u| limit.max(*u + grace));
                let late = match span.terminated() {
                    Some(at) => at > limit,
                    None => end > limit,
                };
                if late {
                    v.push(Violation {
                        invariant: "team-termination",
                        detail: format!(
                            "{r} ran `{}` #{} more than {:.1} s after its team ended it at {t}",
                            self.name(key.behavior),
                            key.epoch,
                            grace.as_secs_f64()
                        ),
                    });
                }
            }
        }
        self.v.extend(v);
    }
}

/// Could two robots' legs after one point be a split (different behaviors
/// side by side for longer than [`SPLIT_BOUND`])? Legs `[f, u)` overlap by
/// more than the bound exactly when `[f + bound, u)` intersect, so one
/// sweep in start order over those finds a pair of different behaviors in
/// O(k log k) for k legs; the exact check over pairs (quadratic in the
/// team) then runs only where this says yes. Conservative: it does not
/// ask whether the two are different robots that could talk.
fn may_split(
    members: &BTreeMap<RobotId, Legs>,
    end: Time,
    crashed: &dyn Fn(RobotId) -> bool,
) -> bool {
    use std::cmp::Reverse;
    let mut spans: Vec<(Time, Time, BehaviorId)> = Vec::new();
    for (r, legs) in members {
        if crashed(*r) {
            continue;
        }
        for l in legs {
            let from = l.from + SPLIT_BOUND;
            let until = l.until.unwrap_or(end);
            if until > from {
                spans.push((from, until, l.behavior));
            }
        }
    }
    let Some(first) = spans.first().map(|s| s.2) else {
        return false;
    };
    if spans.iter().all(|s| s.2 == first) {
        return false; // the usual case: one successor for everyone
    }
    spans.sort_unstable();
    // Active spans: ends (earliest first) and how many per behavior.
    let mut ends: std::collections::BinaryHeap<Reverse<(Time, BehaviorId)>> =
        std::collections::BinaryHeap::new();
    let mut active: BTreeMap<BehaviorId, usize> = BTreeMap::new();
    for (from, until, b) in spans {
        while let Some(Reverse((e, eb))) = ends.peek().copied()
            && e <= from
        {
            ends.pop();
            if let Some(c) = active.get_mut(&eb) {
                *c -= 1;
                if *c == 0 {
                    active.remove(&eb);
                }
            }
        }
        if active.keys().any(|x| *x != b) {
            return true;
        }
        *active.entry(b).or_insert(0) += 1;
        ends.push(Reverse((until, b)));
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The pairs the exact check would look at, without the who-could-talk
    /// part: two legs of different behaviors overlapping by more than the
    /// bound.
    fn brute(members: &BTreeMap<RobotId, Legs>, end: Time) -> bool {
        let legs: Vec<&Leg> = members.values().flatten().collect();
        legs.iter().any(|a| {
            legs.iter().any(|b| {
                let from = a.from.max(b.from);
                let until = a.until.unwrap_or(end).min(b.until.unwrap_or(end));
                a.behavior != b.behavior && until > from && until - from > SPLIT_BOUND
            })
        })
    }

    /// The formation run, recorded, with the bindings of `config` (none:
    /// the graph's own, which communicate), robot r2 crashing for good at
    /// 12 s and 10 % of messages lost: teammates are left out and presumed
    /// lost while instances run.
    fn recorded(config: Option<&str>, crash_at: f64) -> (RunReport, Arc<Mission>) {
        let file = Arc::from("formation.yaml");
        let mut g =
            bite_core::graph::load_str(&file, include_str!("../../../examples/formation.yaml"))
                .unwrap_or_else(|d| panic!("{d}"));
        if let Some(c) = config {
            let cfg = bite_core::graph::Config::load_str(&Arc::from("config.yaml"), c)
                .unwrap_or_else(|d| panic!("{d}"));
            g = g.with_config(&cfg).unwrap_or_else(|d| panic!("{d}"));
        }
        let text = format!(
            "{}crashes:\n  - {{ robot: r2, at: {crash_at}s }}\n",
            include_str!("../../../examples/scenarios/formation.yaml")
                .replace("  latency: 5ms\n", "  latency: 5ms\n  loss: 0.1\n")
        );
        let sc = crate::Scenario::load_str(&Arc::from("formation-scenario.yaml"), &text)
            .unwrap_or_else(|d| panic!("{d}"));
        let mission = crate::prepare(&g, &sc, None, &bite_protocols::registry())
            .unwrap_or_else(|d| panic!("{d}"));
        let options = crate::RunOptions {
            record: true,
            ..crate::RunOptions::default()
        };
        let report = crate::run(mission.clone(), &sc, options).unwrap_or_else(|d| panic!("{d}"));
        (report, mission)
    }

    /// What only a running instance needs (whom it left out or presumed
    /// lost) is dropped when the robot's instance ends, unless a silent
    /// rule ran it (its agreement check compares what each member's
    /// instance saw, at the end); empty views are not stored; starts and
    /// ends are kept only for behaviors a team ends together. A run's
    /// records otherwise grew with robots × executions.
    #[test]
    fn an_ended_instance_leaves_only_what_the_end_checks_read() {
        let configs = [
            include_str!("../../../examples/configs/5.yaml"), // votes at A and B
            include_str!("../../../examples/configs/1.yaml"), // silent everywhere
        ];
        for (i, config) in configs.into_iter().enumerate() {
            // r2 crashes while its teammates wait for it at a point.
            let (report, mission) = recorded(Some(config), 13.0);
            let mut c = Checker::new(mission.clone());
            // The most presumed-lost records of talking instances at once.
            let mut most_lost = 0;
            for rec in &report.history {
                c.observe(rec.t, rec.robot, &rec.event);
                let talking = (c.lost_during.keys()).filter(|k| !c.silent.contains_key(&k.0));
                most_lost = most_lost.max(talking.count());
            }
            assert!(most_lost > 0, "r2 is presumed lost while instances wait");
            assert!(
                !c.silent.is_empty(),
                "both configurations have silent points"
            );
            if i == 1 {
                // Members that saw the same share one copy of it.
                let members: usize = c.silent.values().map(|s| s.of.len()).sum();
                let distinct: usize = c.silent.values().map(|s| s.distinct.len()).sum();
                assert!(distinct < members, "{distinct} views for {members} members");
            }
            let open: FxHashSet<(InstanceKey, RobotId)> = (c.open.iter())
                .flat_map(|(r, ks)| ks.iter().map(move |k| (*k, *r)))
                .collect();
            assert!(c.lost_during.keys().all(|k| open.contains(k)));
            assert!(c.followed.keys().all(|k| open.contains(k)));
            assert!(
                (c.left_out_at.keys()).all(|k| open.contains(k) && !c.silent.contains_key(&k.0))
            );
            assert!((c.view_at.values()).all(|m| m.values().all(|v| !v.is_empty())));
            assert!(c.spans.keys().all(|(_, b, _)| c.team_ends(*b)));
        }
    }

    /// A robot left behind at a synchronization takes the successor a
    /// teammate ran after it. When that teammate decided by its deadline,
    /// the robot's choice is that deadline's, not the team's agreement
    /// (`bite sweep --robots 8`, Table II row 7, heavy loss, seed 1: r1
    /// timed out on the fallback, r3 followed it, the others had agreed on
    /// the other successor; the split then healed).
    #[test]
    fn a_choice_taken_from_a_teammate_that_timed_out_is_that_timeout() {
        let (_, mission) = recorded(None, 1e6);
        let g = mission.graph();
        let (walk, search) = (g.find("linewalk"), g.find("search"));
        let (Some(walk), Some(search)) = (walk, search) else {
            panic!("the formation has `linewalk` and `search`");
        };
        let key = InstanceKey {
            team: bite_core::ids::TeamId::ROOT,
            behavior: walk,
            kind: Kind::Sync,
            epoch: 2,
            round: 0,
        };
        let decided = |choice, timed_out| Event::InteractionDecided {
            instance: key,
            protocol: "sync.elected-leader",
            outcome: OutcomeLog::Sync {
                choice: Some(choice),
            },
            waited_us: 0,
            sent: 0,
            bytes: 0,
            received: 0,
            timed_out,
        };
        for followed_a_timeout in [true, false] {
            let mut c = Checker::new(mission.clone());
            let t = Time::from_millis(1000);
            c.observe(t, RobotId(0), &decided(search, false));
            c.observe(t, RobotId(1), &decided(walk, followed_a_timeout));
            let behind = Event::LeftBehind {
                instance: key,
                member: RobotId(1),
            };
            c.observe(t, RobotId(2), &behind);
            c.observe(t, RobotId(2), &decided(walk, false));
            c.check_decisions();
            let broken = c.v.iter().any(|v| v.invariant == "agreement");
            assert_eq!(broken, !followed_a_timeout);
        }
    }

    proptest! {
        #[test]
        fn the_sweep_finds_exactly_the_overlapping_pairs(
            legs in proptest::collection::vec((0u32..6, 0u32..3, 0u32..40, 0u32..20, any::<bool>()), 0..14),
        ) {
            let end = Time::from_secs_f64(50.0);
            let mut members: BTreeMap<RobotId, Legs> = BTreeMap::new();
            for (r, b, from, len, open) in legs {
                let from = Time::from_secs_f64(f64::from(from));
                members.entry(RobotId(r)).or_default().push(Leg {
                    behavior: BehaviorId(b),
                    from,
                    until: (!open).then(|| from + Duration::from_secs(u64::from(len))),
                });
            }
            prop_assert_eq!(may_split(&members, end, &|_| false), brute(&members, end));
        }
    }
}
