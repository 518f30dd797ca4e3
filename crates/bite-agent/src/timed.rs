//! The timed-skill world: coordination without physics.
//!
//! When a robot's leaf behavior starts a skill, the world draws, for that
//! robot and that execution, how long the skill takes and how fast the
//! numeric beliefs it drives grow; it sets the skill's `start` beliefs at
//! once and its `done` beliefs when the duration has passed. This is enough
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
            last_tick: None,
        }
    }

    /// The leaf behavior changed: stop the old skill, start the new one.
    /// Returns the beliefs the new skill sets as it starts; the runtime
    /// gives them to the kernel at once (before any other input can make it
    /// evaluate a condition on stale values).
    pub fn leaf_changed(
        &mut self,
        book: &SkillBook,
        leaf: Option<LeafId>,
        now: Time,
    ) -> &[(BeliefId, Value)] {
        if self.active.as_ref().map(|a| a.leaf) == leaf {
            return &[];
        }
        self.active = None;
        let Some(leaf) = leaf else { return &[] };
        let b = leaf.0;
        let Some(skill) = book.by_behavior.get(b.index()).cloned().flatten() else {
            return &[];
        };
        for (id, v) in &skill.on_start {
            if let Value::Num(x) = v
                && skill.rates.contains(id)
            {
                *self.level(*id) = *x;
            }
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
        self.active = Some(Active {
            leaf,
            skill,
            done_at,
            rates,
        });
        self.active
            .as_ref()
            .map_or(&[], |a| a.skill.on_start.as_slice())
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
