//! Stall detection: a run that makes no progress, or goes round in circles,
//! ends as **STALLED** with what was repeating, instead of running to its
//! time limit.
//!
//! Fed the same event stream as the invariant checker (and, for a spinning
//! timer, by the simulator). Signs of a stall, their limits configurable
//! in the scenario (`stall:`) but for the spinning timer's:
//!
//! - **no progress**: no robot selected, ended or decided anything for
//!   `after` (default 120 s) while the mission is not over — every live
//!   robot is stuck in a skill that never ends, or waits. In the physical
//!   world, the scenario's goal object brought [`STEP`] nearer its zone
//!   than it has ever been is progress too: a lone robot shoving a box and
//!   a crashed teammate's body together home decides nothing for minutes;
//!   it cannot go round in circles that way (the nearest it has been only
//!   shrinks), and it still ends by the time limit. So is a robot's skill
//!   making a step toward its end (`bite_agent::schema::State::marks`: a
//!   sweep coming 5 cm nearer its next waypoint than it has been, reaching
//!   it or giving it up; a robot driving to a goal coming 5 cm nearer it
//!   than it has been): a team sweeping a large arena decides nothing
//!   until every cell is swept, a pusher working its way to the box
//!   through a crowd of teammates nothing until it gets there, and a skill
//!   makes finitely many such steps (a robot's own, and crashed robots'
//!   before they crashed, count);
//! - **repetition**: a robot started the same behavior more than `repeats`
//!   times (default 100) within one execution of its parent — a livelock
//!   such as `search → linewalk → search …` that never reaches the
//!   parent's end;
//! - **a spinning timer**: a robot's kernel left its timer due at the
//!   instant it was woken, [`bite_agent::TIMER_SPIN_LIMIT`] times in a row
//!   (a defect: the simulated clock would never move on again);
//! - **standstill** (physical world): no robot moved for `after` — the
//!   kernels may go round (legs that end by time) while the team is stuck.

use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::time::Time;
use std::collections::BTreeMap;

/// How far a robot must get from where it was for the team to have moved
/// (dithering in place does not count), m.
pub const STEP: f64 = 0.25;

/// How much longer than the robots' own longest wait the watch waits
/// before it calls a run stalled (see [`StallWatch::waits_at_least`]): the
/// teammate's last change reaches the waiting robot with its heartbeats,
/// a few of which a lossy network may drop.
pub const WAIT_MARGIN: std::time::Duration = std::time::Duration::from_secs(10);

pub use bite_agent::scenario::StallLimits;

/// One frame of a robot's stack as the watch sees it: the behavior and how
/// many times each child was started under it.
struct Seen {
    behavior: BehaviorId,
    starts: rustc_hash::FxHashMap<BehaviorId, u32>,
}

/// Watches a run for stalls.
pub struct StallWatch {
    limits: StallLimits,
    last_progress: Time,
    /// Per robot: its stack as seen from its events, and the start counts of
    /// its top-level chain.
    stacks: BTreeMap<RobotId, (rustc_hash::FxHashMap<BehaviorId, u32>, Vec<Seen>)>,
    stalled: Option<(Time, String)>,
    /// Physical world: where the robots were when one last moved away (by
    /// more than [`STEP`] from there), and when.
    moved: Option<(Vec<glam::DVec2>, Time)>,
    /// Physical world: the nearest the scenario's goal object has been to
    /// its zone, m.
    goal_nearest: Option<f64>,
    /// Physical world: some robot's skill made a step toward its end (see
    /// [`StallWatch::idle_check`]).
    skills_seen: bool,
}

impl StallWatch {
    /// A watch with these limits.
    pub fn new(limits: StallLimits) -> Self {
        StallWatch {
            limits,
            last_progress: Time::ZERO,
            stacks: BTreeMap::new(),
            stalled: None,
            moved: None,
            goal_nearest: None,
            skills_seen: false,
        }
    }

    /// The robots may wait up to `wait` at a point with nothing to show
    /// for it before the point's deadline decides
    /// ([`bite_core::mission::Mission::longest_wait`]): the no-progress and
    /// standstill windows become at least that plus [`WAIT_MARGIN`], so
    /// that a run whose robots still have a timeout and a decision to come
    /// is not called stalled first. A binding with a deadline of 40 s
    /// waits a teammate stuck at work for 160 s, and the default window of
    /// 120 s called such runs stalled.
    pub fn waits_at_least(&mut self, wait: std::time::Duration) {
        if let Some(after) = &mut self.limits.after {
            *after = (*after).max(wait + WAIT_MARGIN);
        }
    }

    /// The no-progress window in force (`None`: never).
    pub fn after(&self) -> Option<std::time::Duration> {
        self.limits.after
    }

    /// One event of `robot` at `t`.
    pub fn observe(&mut self, t: Time, robot: RobotId, e: &Event, graph: &BehaviorGraph) {
        match e {
            Event::Selected {
                behavior, depth, ..
            } => {
                self.last_progress = t;
                let (root, stack) = self.stacks.entry(robot).or_default();
                stack.truncate(*depth as usize);
                let parent = stack.last().map(|p| p.behavior);
                let starts = match stack.last_mut() {
                    Some(p) => &mut p.starts,
                    None => root,
                };
                let n = starts.entry(*behavior).or_insert(0);
                *n += 1;
                let n = *n;
                if self.limits.repeats > 0 && n > self.limits.repeats && self.stalled.is_none() {
                    let within = match parent {
                        Some(p) => format!("one execution of `{}`", graph.name_of(p)),
                        None => "the mission".to_string(),
                    };
                    self.stalled = Some((
                        t,
                        format!(
                            "{robot} started `{}` {n} times within {within}",
                            graph.name_of(*behavior)
                        ),
                    ));
                }
                stack.push(Seen {
                    behavior: *behavior,
                    starts: Default::default(),
                });
            }
            Event::Terminated { .. }
            | Event::InteractionDecided { .. }
            | Event::MissionCompleted => self.last_progress = t,
            _ => {}
        }
    }

    /// A robot's skill last made a step toward its end at `t`, if ever
    /// (told of a robot about to lose what it knows of it: restarted).
    pub fn skill_progressed(&mut self, t: Option<Time>) {
        if let Some(t) = t {
            self.skills_seen = true;
            self.last_progress = self.last_progress.max(t);
        }
    }

    /// The run is at `now` and not over: has it gone without progress for
    /// too long? `skills` says when a robot's skill last made a step toward
    /// its end (`bite_agent::Agent::skill_progressed_at`: a sweep coming
    /// nearer its next waypoint, reaching it or giving it up, a robot
    /// coming nearer the goal it drives to), if one ever
    /// did; it is asked only when nothing else happened for the limit (it
    /// reads every robot).
    pub fn idle_check(&mut self, now: Time, skills: impl FnOnce() -> Option<Time>) {
        let Some(after) = self.limits.after else {
            return;
        };
        if self.stalled.is_some() || now - self.last_progress <= after {
            return;
        }
        self.skill_progressed(skills().map(|t| t.min(now)));
        if now - self.last_progress <= after {
            return;
        }
        self.stalled = Some((
            now,
            format!(
                "no robot selected, ended or decided anything{}{} for {:.0} s (since {})",
                match self.goal_nearest {
                    Some(_) => " nor brought the goal object nearer its zone",
                    None => "",
                },
                match self.skills_seen {
                    true => " nor got nearer the goal or waypoint it drives to",
                    false => "",
                },
                after.as_secs_f64(),
                self.last_progress
            ),
        ));
    }

    /// Physical world: where the live robots are at `now` (`None`: crashed).
    /// A team none of whose robots gets [`STEP`] away from where it was
    /// for `after` is stuck.
    pub fn motion(&mut self, now: Time, at: &[Option<glam::DVec2>]) {
        let moved = match &self.moved {
            None => true,
            Some((marks, _)) => at
                .iter()
                .zip(marks)
                .any(|(p, m)| p.is_some_and(|p| p.distance(*m) > STEP)),
        };
        if moved {
            // The marks' buffer is kept from tick to tick (a large team's
            // would be a fresh allocation at every control tick).
            let mut marks = self.moved.take().map(|(m, _)| m).unwrap_or_default();
            marks.clear();
            marks.extend(at.iter().map(|p| p.unwrap_or_default()));
            self.moved = Some((marks, now));
        }
        if let (Some(after), Some((_, since))) = (self.limits.after, &self.moved)
            && self.stalled.is_none()
            && now - *since > after
        {
            self.stalled = Some((
                now,
                format!(
                    "no robot moved {STEP} m for {:.0} s (since {since})",
                    after.as_secs_f64()
                ),
            ));
        }
    }

    /// Physical world: how far the scenario's goal object is from its zone
    /// at `now` (`None`: no goal). Coming [`STEP`] nearer than it has ever
    /// been is progress.
    pub fn goal(&mut self, now: Time, distance: Option<f64>) {
        let Some(d) = distance else { return };
        match self.goal_nearest {
            Some(best) if d > best - STEP => {}
            Some(_) => {
                self.goal_nearest = Some(d);
                self.last_progress = self.last_progress.max(now);
            }
            None => self.goal_nearest = Some(d),
        }
    }

    /// `robot`'s kernel left its timer due after each of its last
    /// [`bite_agent::TIMER_SPIN_LIMIT`] timer calls at `now`: the simulated
    /// clock would stand still. Its timer is no longer armed, and the run
    /// ends as stalled.
    pub fn spinning(&mut self, now: Time, robot: RobotId) {
        if self.stalled.is_none() {
            self.stalled = Some((
                now,
                format!(
                    "{robot}'s kernel timer was due again after each of {} timer calls at {now}: \
                     the clock could not move on",
                    bite_agent::TIMER_SPIN_LIMIT
                ),
            ));
        }
    }

    /// When and why the run stalled, if it did.
    pub fn stalled(&self) -> Option<&(Time, String)> {
        self.stalled.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(s: u64) -> Time {
        Time::ZERO + Duration::from_secs(s)
    }

    /// A goal object brought a step nearer its zone than ever is progress;
    /// dithering about its nearest, or back and forth, is not.
    #[test]
    fn a_goal_object_brought_nearer_its_zone_is_progress() {
        let limits = StallLimits {
            after: Some(Duration::from_secs(120)),
            ..StallLimits::default()
        };
        let mut w = StallWatch::new(limits);
        w.goal(at(0), Some(3.0));
        // Shoved home slowly: 0.3 m a minute, nothing decided.
        for k in 1..=8 {
            w.goal(at(60 * k), Some(3.0 - 0.3 * k as f64));
            w.idle_check(at(60 * k), || None);
        }
        assert!(w.stalled().is_none(), "{:?}", w.stalled());
        // Back and forth by less than a step, then away and back: no
        // nearer than it has been, so 120 s later the run is stalled.
        for k in 9..=11 {
            let d = if k % 2 == 0 { 0.6 + 0.2 } else { 0.6 - 0.2 };
            w.goal(at(60 * k), Some(d));
            w.idle_check(at(60 * k), || None);
        }
        let (when, why) = w.stalled().expect("stalled");
        assert_eq!(*when, at(60 * 11));
        assert!(
            why.contains("nor brought the goal object nearer its zone"),
            "{why}"
        );
        // Without a goal, the message is as it was.
        let mut w = StallWatch::new(limits);
        w.goal(at(0), None);
        w.idle_check(at(121), || None);
        assert!(w.stalled().is_some_and(|(_, why)| {
            why.starts_with("no robot selected, ended or decided anything for")
        }));
    }

    /// A robot's skill making steps toward its end (a sweep coming nearer
    /// its waypoints) is progress, asked for only when the run looks idle;
    /// once the steps stop, the run is stalled the limit after the last.
    #[test]
    fn a_sweep_getting_on_with_its_waypoints_is_progress() {
        let limits = StallLimits::default();
        let mut w = StallWatch::new(limits);
        let mut asked = 0;
        // A step every second until 400 s, nothing decided.
        for k in 1..=600u64 {
            w.idle_check(at(k), || {
                asked += 1;
                Some(at(k.min(400)))
            });
            if k <= 520 {
                assert!(w.stalled().is_none(), "{k}: {:?}", w.stalled());
            }
        }
        let (when, why) = w.stalled().expect("stalled");
        assert_eq!(*when, at(521));
        assert!(
            why.contains("nor got nearer the goal or waypoint it drives to"),
            "{why}"
        );
        assert!(why.ends_with("(since 400.000s)"), "{why}");
        // Asked once the run had been idle for the limit, not every tick.
        assert!(asked < 10, "asked {asked} times");
        // A sweep that made its last step over the limit ago is no reason
        // to wait longer.
        let mut w = StallWatch::new(limits);
        w.idle_check(at(200), || Some(at(3)));
        assert_eq!(w.stalled().map(|s| s.0), Some(at(200)));
        // What a restarted robot's sweep got done before it went down
        // counts, though the robot no longer knows it.
        let mut w = StallWatch::new(limits);
        w.skill_progressed(Some(at(200)));
        w.idle_check(at(311), || None);
        assert!(w.stalled().is_none());
        w.idle_check(at(321), || None);
        let (when, why) = w.stalled().expect("stalled");
        assert_eq!(*when, at(321));
        assert!(why.ends_with("(since 200.000s)"), "{why}");
    }

    /// A spinning timer stalls the run even with no limit configured, and
    /// the first reason found is the one kept.
    #[test]
    fn a_spinning_timer_stalls_the_run_and_the_first_reason_stays() {
        let mut w = StallWatch::new(StallLimits {
            after: None,
            repeats: 0,
        });
        w.idle_check(at(1000), || None);
        assert!(w.stalled().is_none());
        w.spinning(at(31), RobotId(1));
        w.spinning(at(32), RobotId(2));
        let (when, why) = w.stalled().expect("stalled");
        assert_eq!(*when, at(31));
        assert!(why.starts_with("r1's kernel timer was due again"), "{why}");
    }
}
