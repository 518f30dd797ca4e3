//! Invariants checked over a recorded run (record, then check — as etcd's
//! robustness tests do). Every scenario and property test runs these.
//!
//! - **agreement**: all members that decided a synchronization instance
//!   normally (not by timeout) chose the same successor — members that could
//!   talk (neither presumed the other lost), and under a silent rule members
//!   whose instances left out the same teammates;
//! - **allocation**: all members that decided an allocation instance
//!   normally hold the same assignment; no robot is given two children; no
//!   child is left without members while another child has more than its
//!   minimum; no member is left out while a child has room;
//! - **team termination**: once a communicating termination protocol
//!   decided that the team ended a behavior, every member running it ends it
//!   (unless it crashed, or the run stopped within the grace period);
//! - **epochs**: a robot's executions of a behavior by a team are numbered
//!   1, 2, 3… with no repeat;
//! - **stack**: every termination matches an earlier selection;
//! - **organization**: every robot's hierarchy is structurally sound.

use crate::runner::RunReport;
use bite_core::event::{Event, MembersLog, OutcomeLog};
use bite_core::ids::{BehaviorId, RobotId, TeamId};
use bite_core::mission::Mission;
use bite_core::msg::{InstanceKey, Kind};
use bite_core::time::Time;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::time::Duration;

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

/// Check every invariant over a recorded run.
pub fn check(report: &RunReport, mission: &Mission) -> Vec<Violation> {
    let mut v = Vec::new();
    let graph = mission.graph();
    let name = |b: BehaviorId| graph.name_of(b).to_string();
    let mut sync: BTreeMap<InstanceKey, BTreeMap<RobotId, Option<BehaviorId>>> = BTreeMap::new();
    let mut alloc: BTreeMap<InstanceKey, BTreeMap<RobotId, Vec<(BehaviorId, MembersLog)>>> =
        BTreeMap::new();
    let mut ended: BTreeMap<InstanceKey, Time> = BTreeMap::new();
    // Who each robot presumes lost, as the run goes (for "could talk").
    let mut lost_now: BTreeMap<RobotId, BTreeSet<RobotId>> = BTreeMap::new();
    let mut view_at: BTreeMap<(InstanceKey, RobotId), BTreeSet<RobotId>> = BTreeMap::new();
    // Whom each robot's instance left out from its start, and whom it
    // presumed lost while the instance ran.
    let mut left_out_at: BTreeMap<(InstanceKey, RobotId), BTreeSet<RobotId>> = BTreeMap::new();
    let mut lost_during: BTreeMap<(InstanceKey, RobotId), BTreeSet<RobotId>> = BTreeMap::new();
    let mut open: BTreeMap<RobotId, BTreeSet<InstanceKey>> = BTreeMap::new();
    let mut timed_out_at: BTreeSet<InstanceKey> = BTreeSet::new();

    let mut selected: BTreeMap<(TeamId, BehaviorId, u32), BTreeSet<RobotId>> = BTreeMap::new();
    let mut terminated: BTreeMap<(TeamId, BehaviorId, u32, RobotId), Time> = BTreeMap::new();
    let mut started: BTreeMap<(TeamId, BehaviorId, u32, RobotId), Time> = BTreeMap::new();

    let mut last_epoch: BTreeMap<(RobotId, TeamId, BehaviorId), u32> = BTreeMap::new();
    for rec in &report.history {
        if let Event::InteractionDecided { instance, .. }
        | Event::InteractionAborted { instance, .. } = &rec.event
            && let Some(o) = open.get_mut(&rec.robot)
        {
            o.remove(instance);
        }
        match &rec.event {
            Event::MemberLost { member } => {
                lost_now.entry(rec.robot).or_default().insert(*member);
                // Running instances decide without it from now on.
                for key in open.get(&rec.robot).into_iter().flatten() {
                    lost_during
                        .entry((*key, rec.robot))
                        .or_default()
                        .insert(*member);
                }
            }
            Event::MemberBack { member } => {
                lost_now.entry(rec.robot).or_default().remove(member);
            }
            Event::InteractionStarted {
                instance, excluded, ..
            } => {
                left_out_at.insert((*instance, rec.robot), excluded.iter().copied().collect());
                open.entry(rec.robot).or_default().insert(*instance);
            }
            Event::InteractionDecided {
                instance,
                timed_out,
                ..
            } if matches!(instance.kind, Kind::Sync | Kind::Allocate) => {
                if *timed_out {
                    timed_out_at.insert(*instance);
                }
                let mut view = lost_now.get(&rec.robot).cloned().unwrap_or_default();
                for x in [&left_out_at, &lost_during] {
                    if let Some(x) = x.get(&(*instance, rec.robot)) {
                        view.extend(x.iter().copied());
                    }
                }
                view_at.insert((*instance, rec.robot), view);
            }
            _ => {}
        }
        match &rec.event {
            // Decided while leaving (the protocol's last word to its
            // teammates as an ancestor ended or a re-allocation began):
            // this robot never applied it.
            Event::InteractionAborted { instance, .. } => {
                if let Some(m) = sync.get_mut(instance) {
                    m.remove(&rec.robot);
                }
                if let Some(m) = alloc.get_mut(instance) {
                    m.remove(&rec.robot);
                }
            }
            Event::InteractionDecided {
                instance,
                outcome,
                timed_out: false,
                ..
            } => match outcome {
                OutcomeLog::Sync { choice } => {
                    sync.entry(*instance)
                        .or_default()
                        .insert(rec.robot, *choice);
                }
                OutcomeLog::Allocate { assignment } => {
                    alloc
                        .entry(*instance)
                        .or_default()
                        .insert(rec.robot, assignment.clone());
                }
                OutcomeLog::Terminate { .. } => {
                    let communicates = mission
                        .bound(instance.behavior, Kind::Terminate)
                        .is_some_and(|b| b.protocol.communicates());
                    if communicates {
                        ended.entry(*instance).or_insert(rec.t);
                    }
                }
            },
            Event::Selected {
                behavior,
                team,
                epoch,
                ..
            } => {
                selected
                    .entry((*team, *behavior, *epoch))
                    .or_default()
                    .insert(rec.robot);
                started.insert((*team, *behavior, *epoch, rec.robot), rec.t);

                let last = last_epoch.entry((rec.robot, *team, *behavior)).or_insert(0);
                if *epoch != *last + 1 {
                    v.push(Violation {
                        invariant: "epochs",
                        detail: format!(
                            "{} started `{}` for team {team} with epoch {epoch} after epoch {last}",
                            rec.robot,
                            name(*behavior)
                        ),
                    });
                }
                *last = *epoch;
            }
            Event::Terminated {
                behavior,
                team,
                epoch,
                ..
            } => {
                if !selected
                    .get(&(*team, *behavior, *epoch))
                    .is_some_and(|s| s.contains(&rec.robot))
                {
                    v.push(Violation {
                        invariant: "stack",
                        detail: format!(
                            "{} terminated `{}` #{epoch} without selecting it",
                            rec.robot,
                            name(*behavior)
                        ),
                    });
                }
                terminated.insert((*team, *behavior, *epoch, rec.robot), rec.t);
            }
            _ => {}
        }
    }
    // Two robots that could talk (neither presumed the other lost when it
    // decided) must agree; robots on two sides of a partition may not.
    // (Robots whose views of an allocation diverged after a timeout are in
    // different teams: a team id includes its members.)
    // A silent rule computes from what each robot knows alone, so two
    // robots that presumed different teammates lost may differ; so may two
    // robots with different views of who is alive after a teammate timed
    // out (each learnt the outcome from a different side).
    let could_talk = |key: &InstanceKey, a: RobotId, b: RobotId| {
        let va = view_at.get(&(*key, a));
        let vb = view_at.get(&(*key, b));
        let silent = mission
            .bound(key.behavior, key.kind)
            .is_some_and(|x| !x.protocol.communicates());
        !va.is_some_and(|v| v.contains(&b))
            && !vb.is_some_and(|v| v.contains(&a))
            && (!silent || left_out_at.get(&(*key, a)) == left_out_at.get(&(*key, b)))
            && (!timed_out_at.contains(key) || va == vb)
    };
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
    for (key, choices) in &sync {
        if split(choices, &|a, b| could_talk(key, a, b)) {
            v.push(Violation {
                invariant: "agreement",
                detail: format!(
                    "members chose different successors after `{}` ({key}): {}",
                    name(key.behavior),
                    choices
                        .iter()
                        .map(|(r, c)| format!("{r}→{}", c.map_or("end".to_string(), name)))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
    }
    for (key, views) in &alloc {
        if split(views, &|a, b| could_talk(key, a, b)) {
            v.push(Violation {
                invariant: "allocation",
                detail: format!(
                    "members hold different allocations at `{}` ({key})",
                    name(key.behavior)
                ),
            });
            continue;
        }
        // Each distinct assignment (one per view of the team) must be sound,
        // and each robot must hold a child in its own view when one had room.
        let slots = mission.child_slots(key.behavior);
        let distinct: Vec<&Vec<(BehaviorId, MembersLog)>> = {
            let mut d: Vec<&Vec<(BehaviorId, MembersLog)>> = Vec::new();
            for a in views.values() {
                if !d.contains(&a) {
                    d.push(a);
                }
            }
            d
        };
        for asg in distinct {
            // Member lists are logged for subteams up to 64 robots; larger
            // ones are compared by fingerprint above and counted here.
            let mut seen = BTreeSet::new();
            let mut listed = true;
            for (_, members) in asg {
                match members {
                    MembersLog::List(ms) => {
                        for m in ms {
                            if !seen.insert(*m) {
                                v.push(Violation {
                                    invariant: "allocation",
                                    detail: format!(
                                        "{m} got two children at `{}` ({key})",
                                        name(key.behavior)
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
            for (b, members) in asg {
                if members.is_empty() && spare {
                    v.push(Violation {
                        invariant: "allocation",
                        detail: format!(
                            "child `{}` left without members at `{}` ({key}) while another child has more than it needs",
                            name(*b),
                            name(key.behavior)
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
                            name(key.behavior)
                        ),
                    });
                }
                continue;
            }
            // A robot some teammate's instance left out (presumed lost at
            // its start or before it decided) was left out on purpose, even
            // if it came back meanwhile: it rejoins at the next point.
            let left_out = |r: RobotId| {
                view_at
                    .range((*key, RobotId(0))..=(*key, RobotId(u32::MAX)))
                    .any(|(_, v)| v.contains(&r))
            };
            for r in holders.iter().copied() {
                if !seen.contains(&r) && room && !left_out(r) {
                    v.push(Violation {
                        invariant: "allocation",
                        detail: format!(
                            "{r} got no child at `{}` ({key}) although a child had room",
                            name(key.behavior)
                        ),
                    });
                }
            }
        }
    }
    // Robots that crashed for good are not held to anything after their
    // crash; a paused robot is held to it from its resumption on.
    let crashed: BTreeSet<RobotId> = report
        .crashes
        .iter()
        .filter(|(_, t, until)| *t <= report.end && until.is_none_or(|u| u > report.end))
        .map(|(r, _, _)| *r)
        .collect();
    let resumed: BTreeMap<RobotId, Time> = report
        .crashes
        .iter()
        .filter_map(|(r, _, until)| until.filter(|u| *u <= report.end).map(|u| (*r, u)))
        .collect();
    // A member must end a behavior its team ended within a grace period:
    // two deadlines of the termination binding (time to hear it, with
    // retries) and a second.
    for (key, t) in &ended {
        let grace = mission
            .bound(key.behavior, Kind::Terminate)
            .map_or(Duration::from_secs(10), |b| {
                b.deadline * 2 + Duration::from_secs(1)
            });
        let limit = *t + grace;
        for r in selected
            .get(&(key.team, key.behavior, key.epoch))
            .into_iter()
            .flatten()
        {
            if crashed.contains(r) {
                continue;
            }

            // A member that started this epoch after the team ended it gets
            // the same grace from its own start.
            let start = started
                .get(&(key.team, key.behavior, key.epoch, *r))
                .copied();
            let limit = start.map_or(limit, |s| limit.max(s + grace));
            let limit = resumed.get(r).map_or(limit, |u| limit.max(*u + grace));
            let late = match terminated.get(&(key.team, key.behavior, key.epoch, *r)) {
                Some(at) => *at > limit,
                None => report.end > limit,
            };
            if late {
                v.push(Violation {
                    invariant: "team-termination",
                    detail: format!(
                        "{r} ran `{}` #{} more than {:.1} s after its team ended it at {t}",
                        name(key.behavior),
                        key.epoch,
                        grace.as_secs_f64()
                    ),
                });
            }
        }
    }
    for f in &report.finals {
        if let Err(e) = &f.org_check {
            v.push(Violation {
                invariant: "organization",
                detail: format!("{}: {e}", f.robot),
            });
        }
    }
    v
}
