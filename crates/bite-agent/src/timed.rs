//! The timed-skill world: coordination without physics.
//!
//! When a robot's leaf behavior starts a skill, the world draws, for that
//! robot and that execution, how long the skill takes and how fast the
//! numeric beliefs it drives grow; it sets the skill's `start` beliefs at
//! once and its `done` beliefs when the duration has passed. When the skill
//! stops, the numbers it drove from a start value go back to that value (a
//! leg counted from 0 is 0 again until the next leg's skill starts, as the
//! physical world's `skill_time` is 0 between skills). This is enough
//! to make robots finish at different times, which is what coordination is
//! about, and it is cheap enough for teams of thousands.

use crate::scenario::{Scenario, SkillModel};
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BehaviorId, BeliefId};
use bite_core::interaction::Rng;
use bite_core::time::Time;
use bite_core::value::Value;
use rand::SeedableRng;
use std::collections::BTreeMap;
use std::sync::Arc;

/// A skill model with its belief names resolved.
#[derive(Clone, Debug)]
struct Compiled {
    model: SkillModel,
    /// Beliefs driven while the skill runs.
    rates: Vec<BeliefId>,
    /// Their rate distributions (`None`: the skill's shared `speed`).
    dists: Vec<Option<crate::scenario::Dist>>,
    on_start: Vec<(BeliefId, Value)>,
    on_done: Vec<(BeliefId, Value)>,
}

impl Compiled {
    /// The numbers this skill drives from a start value: each with it.
    fn counted_from(&self) -> impl Iterator<Item = (BeliefId, f64)> + '_ {
        self.on_start.iter().filter_map(|(id, v)| match v {
            Value::Num(x) if self.rates.contains(id) => Some((*id, *x)),
            _ => None,
        })
    }
}

/// The skills of a scenario, resolved against a graph, shared by all robots.
#[derive(Clone, Debug, Default)]
pub struct SkillBook {
    /// For each behavior id: its compiled skill, if it has one the scenario describes.
    by_behavior: Vec<Option<Arc<Compiled>>>,
}

impl SkillBook {
    /// The beliefs skills drive (rates, `drives`, start and done effects):
    /// about the robot's own progress, never shared by a world model.
    pub fn private_beliefs(scenario: &Scenario, graph: &BehaviorGraph) -> Vec<BeliefId> {
        let sym = graph.symbols();
        let mut out: Vec<BeliefId> = Vec::new();
        for m in scenario.skills.values() {
            let names = (m.rates.iter().map(|(n, _)| n))
                .chain(m.drives.iter())
                .chain(m.on_start.iter().map(|(n, _)| n))
                .chain(m.on_done.iter().map(|(n, _)| n));
            out.extend(names.filter_map(|n| sym.get(n)));
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Resolve the scenario's skills for the graph's behaviors. Beliefs no
    /// condition reads are dropped (the scenario check warns about them).
    pub fn new(scenario: &Scenario, graph: &BehaviorGraph) -> Self {
        let sym = graph.symbols();
        let ids = |v: &[(String, Value)]| -> Vec<(BeliefId, Value)> {
            v.iter()
                .filter_map(|(n, x)| sym.get(n).map(|id| (id, x.clone())))
                .collect()
        };
        let mut compiled: BTreeMap<&str, Arc<Compiled>> = BTreeMap::new();
        for (name, m) in &scenario.skills {
            // Independent rates first, then the beliefs driven by `speed`
            // (one draw shared by all of them); beliefs nobody reads are dropped.
            let mut rates = Vec::new();
            let mut dists = Vec::new();
            for (n, d) in &m.rates {
                if let Some(id) = sym.get(n) {
                    rates.push(id);
                    dists.push(Some(*d));
                }
            }
            for n in &m.drives {
                if let Some(id) = sym.get(n) {
                    rates.push(id);
                    dists.push(None);
                }
            }
            compiled.insert(
                name,
                Arc::new(Compiled {
                    model: m.clone(),
                    dists,
                    rates,
                    on_start: ids(&m.on_start),
                    on_done: ids(&m.on_done),
                }),
            );
        }
        SkillBook {
            by_behavior: graph
                .behaviors()
                .iter()
                .map(|b| {
                    b.skill
                        .as_ref()
                        .filter(|_| b.is_atomic())
                        .and_then(|s| compiled.get(s.name.as_str()).cloned())
                })
                .collect(),
        }
    }
}

/// Which execution of a behavior a skill belongs to: behavior, subteam and
/// epoch (a behavior popped and pushed again is a new execution, whose
/// skill starts afresh).
pub type LeafId = (BehaviorId, bite_core::ids::TeamId, u32);

#[derive(Debug)]
struct Active {
    leaf: LeafId,
    skill: Arc<Compiled>,
    done_at: Option<Time>,
    rates: Vec<f64>,
}

/// One robot's side of the timed world.
#[derive(Debug)]
pub struct RobotWorld {
    rng: Rng,
    active: Option<Active>,
    /// Current values of rate-driven beliefs, by belief id.
    levels: Vec<f64>,
    /// Belief changes to hand to the kernel at the next tick.
    pending: Vec<(BeliefId, Value)>,
    /// What the last change of leaf set (see [`RobotWorld::leaf_changed`]).
    changed: Vec<(BeliefId, Value)>,
    last_tick: Option<Time>,
}

impl RobotWorld {
    /// The world of one robot, with its own random stream.
    pub fn new(seed: u64) -> Self {
        RobotWorld {
            rng: Rng::seed_from_u64(seed),
            active: None,
            levels: Vec::new(),
            pending: Vec::new(),
            changed: Vec::new(),
            last_tick: None,
        }
    }

    /// The leaf behavior changed: stop the old skill, start the new one.
    /// Returns the beliefs that changed: the numbers the old skill drove
    /// from a start value, back at it (a new execution of the behavior that
    /// counted them, its skill not started yet, reads its own progress as
    /// none, not the last execution's), then the new skill's start beliefs.
    /// The runtime gives them to the kernel at once (before any other input
    /// can make it evaluate a condition on stale values).
    pub fn leaf_changed(
        &mut self,
        book: &SkillBook,
        leaf: Option<LeafId>,
        now: Time,
    ) -> &[(BeliefId, Value)] {
        self.changed.clear();
        if self.active.as_ref().map(|a| a.leaf) == leaf {
            return &[];
        }
        if let Some(old) = self.active.take() {
            for (id, v) in old.skill.counted_from() {
                *self.level(id) = v;
                self.changed.push((id, Value::Num(v)));
            }
        }
        let Some(leaf) = leaf else {
            return &self.changed;
        };
        let b = leaf.0;
        let Some(skill) = book.by_behavior.get(b.index()).cloned().flatten() else {
            return &self.changed;
        };
        for (id, v) in skill.counted_from() {
            *self.level(id) = v;
        }
        let done_at = skill
            .model
            .duration
            .map(|d| now + std::time::Duration::from_secs_f64(d.sample(&mut self.rng).max(0.0)));
        let speed = skill.model.speed.map(|d| d.sample(&mut self.rng));
        let rates = skill
            .dists
            .iter()
            .map(|d| match d {
                Some(d) => d.sample(&mut self.rng),
                None => speed.unwrap_or(0.0),
            })
            .collect();
        // The new skill's start values override the old one's resets.
        self.changed
            .retain(|(id, _)| skill.on_start.iter().all(|(s, _)| s != id));
        self.changed.extend(skill.on_start.iter().cloned());
        self.active = Some(Active {
            leaf,
            skill,
            done_at,
            rates,
        });
        &self.changed
    }

    /// Ask for what a tick reads of this world to be brought into the
    /// cache (see `Agent::prefetch`): the levels and the skill's rates,
    /// each on the heap apart from the robot.
    pub fn prefetch(&self) {
        use bite_core::hint::prefetch_slice;
        prefetch_slice(&self.levels, 1);
        if let Some(a) = &self.active {
            prefetch_slice(&a.rates, 1);
        }
    }

    fn level(&mut self, id: BeliefId) -> &mut f64 {
        if self.levels.len() <= id.index() {
            self.levels.resize(id.index() + 1, 0.0);
        }
        &mut self.levels[id.index()]
    }

    /// Facts set by a scenario event.
    pub fn inject(&mut self, beliefs: impl IntoIterator<Item = (BeliefId, Value)>) {
        self.pending.extend(beliefs);
    }

    /// Advance to `now` and collect the belief changes for the kernel.
    pub fn tick(&mut self, now: Time, out: &mut Vec<(BeliefId, Value)>) {
        out.clear();
        // Start effects first, so that a skill completing at once overrides them.
        out.append(&mut self.pending);
        let dt = self.last_tick.map_or(0.0, |t| (now - t).as_secs_f64());
        self.last_tick = Some(now);
        if let Some(a) = &mut self.active {
            for (id, rate) in a.skill.rates.iter().zip(&a.rates) {
                if self.levels.len() <= id.index() {
                    self.levels.resize(id.index() + 1, 0.0);
                }
                let level = &mut self.levels[id.index()];
                *level += rate * dt;
                out.push((*id, Value::Num(*level)));
            }
            if a.done_at.is_some_and(|t| t <= now) {
                a.done_at = None;
                out.extend(a.skill.on_done.iter().cloned());
            }
        }
    }

    /// When the active skill completes, if it has a duration.
    pub fn next_completion(&self) -> Option<Time> {
        self.active.as_ref().and_then(|a| a.done_at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A leg counted from 0 by the leaf's skill: `leg` reaches 1.5, ends,
    /// and the next `leg` (its subteam's allocation not decided yet, so no
    /// skill runs) reads its own progress as none.
    #[test]
    fn a_skill_that_stops_leaves_the_numbers_it_counted_from_a_start_at_the_start() {
        let file: Arc<str> = Arc::from("t.yaml");
        let graph = bite_core::graph::load_str(
            &file,
            "graph: t\nteam: { robots: 1 }\nstart: leg\nbehaviors:\n  \
             leg:\n    team: true\n    children: [step]\n    until: walked >= 1.5 && total < 100 && busy\n    \
             next: [leg]\n  step:\n    skill: stride\n",
        )
        .expect("graph");
        let scenario = Scenario::load_str(
            &file,
            "scenario: t\nskills:\n  stride:\n    speed: 1\n    drives: [walked, total]\n    \
             start: { walked: 0, busy: true }\n",
        )
        .expect("scenario");
        let book = SkillBook::new(&scenario, &graph);
        let id = |n: &str| graph.symbols().get(n).expect("belief");
        let (leg, step) = (
            graph.find("leg").expect("leg"),
            graph.find("step").expect("step"),
        );
        let team = bite_core::ids::TeamId::ROOT;
        let mut w = RobotWorld::new(1);
        let at = |s: f64| Time::ZERO + std::time::Duration::from_secs_f64(s);
        let num = |out: &[(BeliefId, Value)], b: BeliefId| {
            out.iter()
                .rev()
                .find(|(i, _)| *i == b)
                .map(|(_, v)| v.clone())
        };
        let started = w
            .leaf_changed(&book, Some((step, team, 1)), at(0.0))
            .to_vec();
        assert_eq!(num(&started, id("walked")), Some(Value::Num(0.0)));
        assert_eq!(num(&started, id("busy")), Some(Value::Bool(true)));
        let mut out = Vec::new();
        w.tick(at(0.0), &mut out);
        w.tick(at(2.0), &mut out);
        assert_eq!(num(&out, id("walked")), Some(Value::Num(2.0)));
        // The leg ends; the next one waits for its roles (the leaf is the
        // team behavior itself): `walked` is 0 again, `total` keeps
        // counting from where it was, and `busy` (not a number the skill
        // drives) is left as it is.
        let stopped = w
            .leaf_changed(&book, Some((leg, team, 2)), at(2.0))
            .to_vec();
        assert_eq!(stopped, vec![(id("walked"), Value::Num(0.0))]);
        w.tick(at(3.0), &mut out);
        assert!(out.is_empty(), "{out:?}");
        // Its skill starts: `total` goes on from 2.
        w.leaf_changed(&book, Some((step, team, 2)), at(3.0));
        w.tick(at(4.0), &mut out);
        assert_eq!(num(&out, id("walked")), Some(Value::Num(1.0)));
        assert_eq!(num(&out, id("total")), Some(Value::Num(3.0)));
    }
}
