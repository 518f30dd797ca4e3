//! One robot's mind, for runtimes that run each robot on its own: the
//! kernel (Algorithm 1), its timed skills, its world model and, in the
//! physical world, its pilot (percepts from sensor readings, motor schemas
//! fused into a velocity command).
//!
//! Sans-IO like the kernel: the runtime hands in the time with every input
//! (a control tick with the sensor readings, a message, a world-model
//! report, a timer, a teammate lost or back) and drains [`Agent::poll`]
//! for what to send, what happened and what to drive. The Zenoh runtime
//! (`bite-zenoh`) drives one per process; the order of steps inside a
//! control tick is the simulator's (`runner.rs`), so a graph behaves the
//! same in both.

use crate::scenario::{Scenario, TimedFact};
use crate::world::{RobotWorld, SkillBook};
use bite_core::belief::Source;
use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BeliefId, RobotId};
use bite_core::interaction::{Recipients, Rng};
use bite_core::kernel::{Kernel, Output};
use bite_core::mission::Mission;
use bite_core::msg::Envelope;
use bite_core::org::MemberSet;
use bite_core::time::Time;
use bite_core::value::Value;
use bite_core::wm::{Inform, Outgoing, Policy, WorldModel};
use rand::SeedableRng;
use std::collections::VecDeque;
use std::sync::Arc;

use crate::physics::schema::{Command, Weighted};
use crate::physics::{Pilot, Sensed};

/// What an agent asks its runtime to do.
#[derive(Debug)]
pub enum AgentOutput {
    /// Send a kernel message.
    Send {
        /// To whom.
        to: Recipients,
        /// The message.
        envelope: Envelope,
    },
    /// Send a world-model report.
    Inform(Outgoing),
    /// Something happened (for the run log).
    Event(Event),
    /// Drive: the fused velocity command of the current skill.
    Drive(Command),
}

/// One robot's mind.
pub struct Agent {
    kernel: Kernel,
    graph: Arc<BehaviorGraph>,
    book: SkillBook,
    world: RobotWorld,
    wm: Option<WorldModel>,
    pilot: Option<Pilot>,
    motor: Vec<Arc<[Weighted]>>,
    /// The scenario's timed facts for this robot, by time (injected at the
    /// first control tick at or after their time).
    facts: VecDeque<(Time, Vec<(BeliefId, Value)>)>,
    version: u64,
    /// The odometer of the last sensor readings.
    odometer: f64,
    rng: Rng,
    out: VecDeque<AgentOutput>,
    percepts: Vec<(BeliefId, Value)>,
    own: Vec<(BeliefId, Value)>,
    told: Vec<(BeliefId, Value, bite_core::belief::Source)>,
}

impl std::fmt::Debug for Agent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Agent")
            .field("me", &self.kernel.me())
            .field("phase", &self.kernel.phase_name())
            .finish_non_exhaustive()
    }
}

impl Agent {
    /// Robot `me` of `mission` in `scenario`; `seed` is the run's seed
    /// (each purpose draws its own stream from it, as in the simulator).
    pub fn new(
        mission: Arc<Mission>,
        scenario: &Scenario,
        me: RobotId,
        seed: u64,
    ) -> Result<Agent, bite_core::diag::Diagnostics> {
        let graph = mission.graph().clone();
        let resolved = scenario.resolve(&graph)?;
        let n = graph.roster().len();
        let sym = graph.symbols().clone();
        let facts = facts_for(&resolved.events, me, &sym);
        let kernel = Kernel::with_root(
            mission.clone(),
            me,
            crate::runner::derive_seed(seed, "kernel", me.0),
            Arc::new(MemberSet::all(n)),
        );
        let pilot = match &scenario.physics {
            None => None,
            Some(spec) => {
                let names: Vec<String> = (0..n as u32)
                    .map(|r| graph.roster().name(RobotId(r)))
                    .collect();
                Some(Pilot::for_robot(
                    spec.clone(),
                    &names,
                    &sym,
                    &scenario.file,
                    me.index(),
                )?)
            }
        };
        let sharing = graph.sharing();
        let wm = (sharing.policy != Policy::None).then(|| {
            let mut private = vec![false; sym.len()];
            let mut personal = SkillBook::private_beliefs(scenario, &graph);
            if let Some(p) = &pilot {
                personal.extend(p.private_beliefs());
            }
            for id in personal {
                if let Some(p) = private.get_mut(id.index()) {
                    *p = true;
                }
            }
            WorldModel::new(me, sym.len(), sharing, Arc::from(private))
        });
        Ok(Agent {
            kernel,
            book: SkillBook::new(scenario, &graph),
            world: RobotWorld::new(crate::runner::derive_seed(seed, "world", me.0)),
            graph,
            wm,
            pilot,
            motor: resolved.motor,
            facts,
            version: u64::MAX,
            odometer: 0.0,
            rng: Rng::seed_from_u64(crate::runner::derive_seed(seed, "pilot", me.0)),
            out: VecDeque::new(),
            percepts: Vec::new(),
            own: Vec::new(),
            told: Vec::new(),
        })
    }

    /// The kernel (read only).
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// Does this robot drive a body (physical world)?
    pub fn has_body(&self) -> bool {
        self.pilot.is_some()
    }

    /// The world model, if the team shares beliefs.
    pub fn world_model(&self) -> Option<&WorldModel> {
        self.wm.as_ref()
    }

    /// A control tick: the timed skills advance, the sensor readings (in the
    /// physical world) become percepts, the world model fuses and shares,
    /// the kernel runs Algorithm 1, and the pilot fuses the current skill's
    /// schemas into a velocity command.
    pub fn tick(&mut self, now: Time, sensed: Option<&Sensed>) {
        let mut percepts = std::mem::take(&mut self.percepts);
        while self.facts.front().is_some_and(|(t, _)| *t <= now) {
            if let Some((_, set)) = self.facts.pop_front() {
                self.world.inject(set);
            }
        }
        self.world.tick(now, &mut percepts);
        if let (Some(p), Some(s)) = (self.pilot.as_mut(), sensed) {
            self.odometer = s.odometer;
            p.perceive(s, &mut percepts);
        }
        if self.wm.is_none() {
            self.kernel.tick(now, &percepts);
        } else {
            self.through_world_model(now, |wm, own, told| wm.perceive(now, &percepts, own, told));
            self.share(now);
            self.kernel.tick(now, &[]);
        }
        self.percepts = percepts;
        self.drain(now);
        if let Some(p) = self.pilot.as_mut() {
            let k = &self.kernel;
            let roles = crate::runner::roles_of(k, &self.graph);
            let rank = k
                .leaf()
                .and_then(|f| k.org().team(f.team))
                .map_or((0, 1), |t| (t.members.rank(k.me()) as u32, t.size));
            p.set_lost(k.lost().iter().map(|r| r.0));
            p.set_roles(roles, rank);
            let rng = &mut self.rng;
            let mut draw = || {
                use rand::RngExt;
                rng.random_range(0.0..1.0)
            };
            let cmd = p.control(now.as_secs_f64(), &mut draw);
            self.out.push_back(AgentOutput::Drive(cmd));
        }
    }

    /// A kernel message from a teammate.
    pub fn message(&mut self, now: Time, env: Envelope) {
        self.kernel.message(now, env);
        self.drain(now);
    }

    /// A world-model report from a teammate.
    pub fn inform(&mut self, now: Time, from: RobotId, msg: &Inform) {
        if self.wm.is_some() {
            self.through_world_model(now, |wm, own, told| wm.receive(from, msg, own, told));
        }
    }

    /// A kernel timer fired (call at or after [`Agent::poll_timeout`]).
    pub fn timer(&mut self, now: Time) {
        if self.kernel.poll_timeout().is_some_and(|t| t <= now) {
            self.kernel.timer(now);
            self.drain(now);
        }
    }

    /// A teammate's team view, heard with its heartbeat.
    pub fn peer(&mut self, now: Time, from: RobotId, pos: &bite_core::kernel::Position) {
        self.kernel.peer(now, from, pos);
        self.drain(now);
    }

    /// The failure detector presumes `r` lost.
    pub fn member_lost(&mut self, now: Time, r: RobotId) {
        self.kernel.member_lost(now, r);
        self.drain(now);
    }

    /// The failure detector hears `r` again.
    pub fn member_back(&mut self, now: Time, r: RobotId) {
        self.kernel.member_back(now, r);
        self.drain(now);
    }

    /// When the kernel wants [`Agent::timer`].
    pub fn poll_timeout(&self) -> Option<Time> {
        self.kernel.poll_timeout()
    }

    /// The next output.
    pub fn poll(&mut self) -> Option<AgentOutput> {
        self.out.pop_front()
    }

    fn drain(&mut self, now: Time) {
        while let Some(o) = self.kernel.poll_output() {
            self.out.push_back(match o {
                Output::Send(s) => AgentOutput::Send {
                    to: s.to,
                    envelope: s.envelope,
                },
                Output::Event(e) => AgentOutput::Event(e),
            });
        }
        if self.kernel.stack_version() != self.version {
            self.version = self.kernel.stack_version();
            let leaf = self.kernel.leaf().map(|f| (f.behavior, f.team, f.epoch));
            let started: Vec<(BeliefId, Value)> =
                self.world.leaf_changed(&self.book, leaf, now).to_vec();
            if self.wm.is_none() {
                for (id, v) in started {
                    self.kernel.set_belief(id, v, Source::Percept);
                }
            } else {
                self.through_world_model(now, |wm, own, told| {
                    wm.perceive(now, &started, own, told)
                });
            }
            if let Some(p) = self.pilot.as_mut() {
                let leaf = leaf.map(|l| l.0);
                let skill = leaf
                    .and_then(|b| self.motor.get(b.index()).cloned())
                    .unwrap_or_else(|| Arc::from(Vec::new()));
                p.leaf_changed(now.as_secs_f64(), self.odometer, leaf, skill);
            }
        }
    }

    fn through_world_model(
        &mut self,
        now: Time,
        feed: impl FnOnce(
            &mut WorldModel,
            &mut Vec<(BeliefId, Value)>,
            &mut Vec<(BeliefId, Value, Source)>,
        ),
    ) {
        let Some(wm) = self.wm.as_mut() else { return };
        self.own.clear();
        self.told.clear();
        feed(wm, &mut self.own, &mut self.told);
        self.kernel.observe(now, &self.own);
        for (id, v, src) in self.told.drain(..) {
            self.kernel.set_belief(id, v, src);
        }
    }

    fn share(&mut self, now: Time) {
        let Some(wm) = self.wm.as_mut() else { return };
        if wm.due(now) {
            wm.share(now, &self.kernel);
        }
        while let Some(o) = wm.poll(now) {
            self.out.push_back(AgentOutput::Inform(o));
        }
    }
}

/// The scenario's timed facts that reach robot `me`, in time order.
fn facts_for(
    events: &[TimedFact],
    me: RobotId,
    sym: &bite_core::belief::Symbols,
) -> VecDeque<(Time, Vec<(BeliefId, Value)>)> {
    let mut out: Vec<(Time, Vec<(BeliefId, Value)>)> = events
        .iter()
        .filter(|f| f.robots.as_ref().is_none_or(|rs| rs.contains(&me)))
        .map(|f| {
            let set = (f.set.iter())
                .filter_map(|(name, v)| sym.get(name).map(|id| (id, v.clone())))
                .collect();
            (f.at, set)
        })
        .collect();
    out.sort_by_key(|(t, _)| *t);
    out.into()
}
