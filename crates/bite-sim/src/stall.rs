//! Stall detection: a run that makes no progress, or goes round in circles,
//! ends as **STALLED** with what was repeating, instead of running to its
//! time limit.
//!
//! Fed the same event stream as the invariant checker. Two signs of a
//! stall, both configurable in the scenario (`stall:`):
//!
//! - **no progress**: no robot selected, ended or decided anything for
//!   `after` (default 120 s) while the mission is not over — every live
//!   robot is stuck in a skill that never ends, or waits;
//! - **repetition**: a robot started the same behavior more than `repeats`
//!   times (default 100) within one execution of its parent — a livelock
//!   such as `search → linewalk → search …` that never reaches the
//!   parent's end;
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
        }
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

    /// The run is at `now` and not over: has it gone without progress for
    /// too long?
    pub fn idle_check(&mut self, now: Time) {
        if let Some(after) = self.limits.after
            && self.stalled.is_none()
            && now - self.last_progress > after
        {
            self.stalled = Some((
                now,
                format!(
                    "no robot selected, ended or decided anything for {:.0} s (since {})",
                    after.as_secs_f64(),
                    self.last_progress
                ),
            ));
        }
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

    /// When and why the run stalled, if it did.
    pub fn stalled(&self) -> Option<&(Time, String)> {
        self.stalled.as_ref()
    }
}
