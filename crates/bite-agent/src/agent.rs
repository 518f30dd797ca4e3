//! One robot's mind, for runtimes that run each robot on its own: the
//! kernel (Algorithm 1), its timed skills, its world model and, in the
//! physical world, its pilot (percepts from sensor readings, motor schemas
//! fused into a velocity command).
//!
//! Sans-IO like the kernel: the runtime hands in the time with every
//! [`Input`] (a control tick with the sensor readings, a message, a
//! world-model report, a timer, a teammate's heartbeat, a teammate lost or
//! back) to [`Agent::handle`] and drains [`Agent::poll`] for what to send,
//! what happened and what to drive. Both runtimes drive the same `Agent`:
//! the simulator (`runner.rs`) one per robot in one process, `bite-zenoh`
//! one per robot process. The order of the steps inside a control tick,
//! the duty of feeding a new skill's start beliefs when the leaf changes,
//! the timed facts of the scenario and the random streams (one per
//! purpose, derived from the run's seed) are all here, so a graph makes
//! the same decisions from the same inputs whichever runtime drives it.
//!
//! What every robot of a run shares (the mission, the resolved skills,
//! motor schemas, timed facts, percept tables) is built once
//! ([`Shared`]), so ten thousand agents stay cheap.

use crate::scenario::Scenario;
use crate::timed::{RobotWorld, SkillBook};
use bite_core::belief::Source;
use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BeliefId, Fnv1a, RobotId};
use bite_core::interaction::{Recipients, Rng};
use bite_core::kernel::{Kernel, Output};
use bite_core::mission::Mission;
use bite_core::msg::Envelope;
use bite_core::org::MemberSet;
use bite_core::time::Time;
use bite_core::value::Value;
use bite_core::wm::{Inform, Outgoing, Policy, WorldModel};
use rand::SeedableRng;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use crate::pilot::{PerceptTables, Pilot};
use crate::schema::{Command, Sensed, Weighted};
use crate::spec::PhysicsSpec;

/// A seed for one purpose of one robot, derived from the run's seed.
pub fn derive_seed(seed: u64, purpose: &str, robot: u32) -> u64 {
    let mut h = Fnv1a::new();
    h.write(&seed.to_le_bytes());
    h.write(purpose.as_bytes());
    h.write(&robot.to_le_bytes());
    // One SplitMix64 round to spread FNV's low-entropy high bits.
    let mut z = h.finish().wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Who holds each sibling role of robot `k`'s leaf behavior: the leader of
/// each subteam its parent's allocation made, by the child's name.
pub fn roles_of(k: &Kernel, graph: &BehaviorGraph) -> BTreeMap<String, u32> {
    let mut roles: BTreeMap<String, (u32, u32)> = BTreeMap::new();
    let org = k.org();
    if let Some(leaf) = k.leaf()
        && let Some(team) = org.team(leaf.team)
        && let Some(parent) = team.parent
    {
        for t in org.subteams_of(parent) {
            if let Some((point, epoch, idx)) = t.origin
                && let Some(b) = graph.get(point).and_then(|p| p.children.get(idx as usize))
                && let Some(l) = t.leader()
            {
                let e = roles
                    .entry(graph.name_of(*b).to_string())
                    .or_insert((epoch, l.0));
                if epoch >= e.0 {
                    *e = (epoch, l.0);
                }
            }
        }
    }
    roles.into_iter().map(|(k, (_, r))| (k, r)).collect()
}

/// One input of a robot's mind. Every input goes through
/// [`Agent::handle`], so a robot's whole input stream can be recorded and
/// replayed (see [`crate::record`]).
#[derive(Clone, Copy, Debug)]
pub enum Input<'a> {
    /// A control tick at world time `world` (the time the body, the
    /// timed skills and the scenario's facts go by; the robot's own clock,
    /// which the kernel reads, may differ), with the sensor readings in
    /// the physical world.
    Tick {
        /// The world's time.
        world: Time,
        /// The sensor readings (physical world).
        sensed: Option<&'a Sensed>,
    },
    /// A kernel message from a teammate.
    Message(&'a Envelope),
    /// A world-model report from a teammate.
    Inform {
        /// The teammate.
        from: RobotId,
        /// The report.
        msg: &'a Inform,
    },
    /// The kernel's timer is due (see [`Agent::poll_timeout`]).
    Timer,
    /// A teammate's team view, heard with its heartbeat.
    Peer {
        /// The teammate.
        from: RobotId,
        /// Its position.
        pos: &'a bite_core::kernel::Position,
    },
    /// The failure detector presumes a teammate lost.
    Lost(RobotId),
    /// The failure detector hears a teammate again.
    Back(RobotId),
}

/// A timed fact of the scenario: when, for whom (`None`: everyone), what.
type Fact = (Time, Option<Vec<RobotId>>, Vec<(BeliefId, Value)>);

/// What every robot of a run shares, built once from the mission and the
/// scenario.
#[derive(Debug)]
pub struct Shared {
    mission: Arc<Mission>,
    book: SkillBook,
    motor: Vec<Arc<[Weighted]>>,
    /// Timed facts by time: when, for whom (`None`: everyone), what.
    facts: Vec<Fact>,
    physics: Option<(Arc<PhysicsSpec>, Arc<PerceptTables>)>,
    /// The world model's setup, if the team shares beliefs: belief count,
    /// policy, which beliefs are private.
    wm: Option<(usize, bite_core::wm::Sharing, Arc<[bool]>)>,
    root: Arc<MemberSet>,
}

impl Shared {
    /// The shared parts of `mission` run in `scenario`.
    pub fn new(
        mission: Arc<Mission>,
        scenario: &Scenario,
    ) -> Result<Arc<Shared>, bite_core::diag::Diagnostics> {
        let graph = mission.graph().clone();
        let resolved = scenario.resolve(&graph)?;
        let n = graph.roster().len();
        let sym = graph.symbols().clone();
        let mut facts: Vec<Fact> = resolved
            .events
            .iter()
            .map(|f| {
                let set = (f.set.iter())
                    .filter_map(|(name, v)| sym.get(name).map(|id| (id, v.clone())))
                    .collect();
                (f.at, f.robots.clone(), set)
            })
            .collect();
        facts.sort_by_key(|f| f.0);
        let physics = match &scenario.physics {
            None => None,
            Some(spec) => Some((
                spec.clone(),
                PerceptTables::new(spec, &sym, &scenario.file)?,
            )),
        };
        let sharing = graph.sharing();
        let wm = (sharing.policy != Policy::None).then(|| {
            let mut private = vec![false; sym.len()];
            let mut personal = SkillBook::private_beliefs(scenario, &graph);
            if let Some((_, t)) = &physics {
                personal.extend(t.private_beliefs());
            }
            for id in personal {
                if let Some(p) = private.get_mut(id.index()) {
                    *p = true;
                }
            }
            (sym.len(), sharing, Arc::from(private))
        });
        Ok(Arc::new(Shared {
            book: SkillBook::new(scenario, &graph),
            motor: resolved.motor,
            facts,
            physics,
            wm,
            root: Arc::new(MemberSet::all(n)),
            mission,
        }))
    }

    /// The mission.
    pub fn mission(&self) -> &Arc<Mission> {
        &self.mission
    }
}

/// The stages of [`Agent::prefetch`], in the order a runner asks for
/// them, robots apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ahead {
    /// The agent's own fields.
    Agent,
    /// What they point to: its pilot, its buffers, its kernel's state.
    Buffers,
    /// What its pilot points to.
    Pilot,
}

/// Timer calls in a row that leave the kernel's timer due at the time it
/// was called at, after which a runtime takes the kernel for spinning (see
/// [`Agent::timer_spinning`]). A sound kernel fires everything due when
/// called and leaves its timer in the future, so one such call is already
/// odd; a thousand is a defect, not a burst.
pub const TIMER_SPIN_LIMIT: u32 = 1000;

/// How long a drained output queue keeps its room while the mission runs
/// (see [`Agent::poll`]).
const ROOM_KEPT: std::time::Duration = std::time::Duration::from_secs(1);

/// What an agent asks its runtime to do.
#[derive(Debug)]
pub enum AgentOutput {
    /// Send a kernel message.
    Send {
        /// To whom.
        to: Recipients,
        /// The message.
        envelope: Envelope,
        /// Its size on the wire.
        bytes: u32,
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
    shared: Arc<Shared>,
    kernel: Kernel,
    world: RobotWorld,
    /// Boxed, as is the pilot: a team of 100,000 timed robots has neither,
    /// and the agents are stored side by side.
    wm: Option<Box<WorldModel>>,
    pilot: Option<Box<Piloted>>,
    /// The next of the shared timed facts (injected at the first control
    /// tick at or after their time).
    next_fact: usize,
    version: u64,
    /// The odometer of the last sensor readings.
    odometer: f64,
    /// The world's time at the last control tick.
    body_t: Time,
    /// The latest time an input carried (time never goes back: an input
    /// dated earlier is taken at this time, and counted).
    last: Time,
    backwards: u64,
    /// Timer calls in a row after which the kernel's timer was still due
    /// (see [`Agent::timer_spinning`]).
    spins: u32,
    /// When the drained output queue next gives back its room.
    room_until: Time,
    out: VecDeque<AgentOutput>,
    /// Where every input and what it produced are written, if recording.
    recorder: Option<crate::record::Recorder>,
    percepts: Vec<(BeliefId, Value)>,
    own: Vec<(BeliefId, Value)>,
    told: Vec<(BeliefId, Value, bite_core::belief::Source)>,
    /// New versions of the mission, held by the kernel until a safe point.
    pending: BTreeMap<u32, Arc<Shared>>,
}

/// A robot's pilot, with the generator of its draws (a ChaCha generator is
/// 300 bytes; a timed robot has neither).
struct Piloted {
    pilot: Pilot,
    rng: Rng,
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
        Ok(Agent::start(Shared::new(mission, scenario)?, me, seed, 0))
    }

    /// Robot `me`'s mind in its `incarnation` (0: the first; a restarted
    /// process is a new incarnation with streams of its own).
    pub fn start(shared: Arc<Shared>, me: RobotId, seed: u64, incarnation: u32) -> Agent {
        let who = me.0 ^ (incarnation << 20);
        let kernel = Kernel::with_root(
            shared.mission.clone(),
            me,
            derive_seed(seed, "kernel", who),
            shared.root.clone(),
        );
        let pilot = shared.physics.as_ref().map(|(spec, tables)| {
            Box::new(Piloted {
                pilot: Pilot::new(spec.clone(), tables.clone()),
                rng: Rng::seed_from_u64(derive_seed(seed, "pilot", who)),
            })
        });
        let wm = shared.wm.as_ref().map(|(len, sharing, private)| {
            Box::new(WorldModel::new(me, *len, *sharing, private.clone()))
        });
        Agent {
            kernel,
            world: RobotWorld::new(derive_seed(seed, "world", who)),
            wm,
            pilot,
            next_fact: 0,
            version: u64::MAX,
            odometer: 0.0,
            body_t: Time::ZERO,
            last: Time::ZERO,
            backwards: 0,
            spins: 0,
            room_until: Time::ZERO,
            out: VecDeque::new(),
            recorder: None,
            percepts: Vec::new(),
            own: Vec::new(),
            told: Vec::new(),
            pending: BTreeMap::new(),
            shared,
        }
    }

    /// A robot whose process restarted at `now` (its clock; `world`: the
    /// world's time): a fresh mind with nothing
    /// of its previous incarnation, which rejoins the team where the team
    /// is (see `Kernel::rejoin`). Its sequence numbers start from the
    /// clock, so that no teammate drops its messages as duplicates of the
    /// old incarnation's.
    pub fn restart(
        shared: Arc<Shared>,
        me: RobotId,
        seed: u64,
        incarnation: u32,
        now: Time,
        world: Time,
    ) -> Agent {
        let mut a = Agent::start(shared, me, seed, incarnation);
        a.last = now;
        a.body_t = world;
        a.kernel.set_first_seq(now.as_micros().max(1));
        a.kernel.rejoin(now);
        a.drain(now);
        a
    }

    /// What this agent shares with its teammates' agents.
    pub fn shared(&self) -> &Arc<Shared> {
        &self.shared
    }

    /// Inputs dated before an earlier one (taken at the later time).
    pub fn time_went_back(&self) -> u64 {
        self.backwards
    }

    /// Has the kernel's timer been due again after each of the last
    /// [`TIMER_SPIN_LIMIT`] timer calls, at the time of the call? A runtime
    /// that woke it for each would never let its clock move (the
    /// simulator) or spin a core (a robot process): the simulator ends the
    /// run as stalled, a robot process says so and wakes it less often.
    pub fn timer_spinning(&self) -> bool {
        self.spins >= TIMER_SPIN_LIMIT
    }

    /// The kernel (read only).
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// Does this robot drive a body (physical world)?
    pub fn has_body(&self) -> bool {
        self.pilot.is_some()
    }

    /// When its skill last made a step toward its end (a sweep coming
    /// nearer its next waypoint: [`crate::schema::State::marks`]), in world
    /// time; `None` if it never did or has no body.
    pub fn skill_progressed_at(&self) -> Option<Time> {
        (self.pilot.as_deref())
            .and_then(|p| p.pilot.progressed_at())
            .map(Time::from_secs_f64)
    }

    /// The world model, if the team shares beliefs.
    pub fn world_model(&self) -> Option<&WorldModel> {
        self.wm.as_deref()
    }

    /// Record every input from now on, and what the mind produced for it
    /// (see [`crate::record`]).
    pub fn record(&mut self, recorder: crate::record::Recorder) {
        self.recorder = Some(recorder);
    }

    /// The recorder, if recording.
    pub fn recorder_mut(&mut self) -> Option<&mut crate::record::Recorder> {
        self.recorder.as_mut()
    }

    /// Hand one input to the mind at time `now` (its own clock).
    pub fn handle(&mut self, now: Time, input: Input<'_>) {
        let recorded = self
            .recorder
            .as_ref()
            .map(|_| (now, crate::record::Recorded::of(&input), self.out.len()));
        self.take(now, input);
        if let (Some(r), Some((t, input, before))) = (self.recorder.as_mut(), recorded) {
            let outs: Vec<&AgentOutput> = self.out.range(before..).collect();
            r.write(t, input, &outs);
        }
    }

    fn take(&mut self, now: Time, input: Input<'_>) {
        let now = if now < self.last {
            self.backwards += 1;
            self.last
        } else {
            self.last = now;
            now
        };
        match input {
            Input::Tick { world, sensed } => self.control(now, world, sensed),
            Input::Message(env) => {
                self.kernel.message(now, env.clone());
                self.drain(now);
            }
            Input::Inform { from, msg } => {
                if self.wm.is_some() {
                    self.through_world_model(now, |wm, own, told| {
                        wm.receive(now, from, msg, own, told)
                    });
                }
            }
            Input::Timer => {
                if self.kernel.poll_timeout().is_some_and(|t| t <= now) {
                    self.kernel.timer(now);
                    self.drain(now);
                    self.spins = match self.kernel.poll_timeout() {
                        Some(t) if t <= now => self.spins.saturating_add(1),
                        _ => 0,
                    };
                }
            }
            Input::Peer { from, pos } => {
                self.kernel.peer(now, from, pos);
                self.drain(now);
            }
            Input::Lost(r) => {
                self.kernel.member_lost(now, r);
                self.drain(now);
            }
            Input::Back(r) => {
                self.kernel.member_back(now, r);
                self.drain(now);
            }
        }
    }

    /// A control tick (see [`Input::Tick`]) where the robot's clock is
    /// the world's.
    pub fn tick(&mut self, now: Time, sensed: Option<&Sensed>) {
        self.handle(now, Input::Tick { world: now, sensed });
    }

    /// A kernel message from a teammate.
    pub fn message(&mut self, now: Time, env: Envelope) {
        self.handle(now, Input::Message(&env));
    }

    /// A world-model report from a teammate.
    pub fn inform(&mut self, now: Time, from: RobotId, msg: &Inform) {
        self.handle(now, Input::Inform { from, msg });
    }

    /// A kernel timer fired (call at or after [`Agent::poll_timeout`]).
    pub fn timer(&mut self, now: Time) {
        self.handle(now, Input::Timer);
    }

    /// A teammate's team view, heard with its heartbeat.
    pub fn peer(&mut self, now: Time, from: RobotId, pos: &bite_core::kernel::Position) {
        self.handle(now, Input::Peer { from, pos });
    }

    /// The failure detector presumes `r` lost.
    pub fn member_lost(&mut self, now: Time, r: RobotId) {
        self.handle(now, Input::Lost(r));
    }

    /// The failure detector hears `r` again.
    pub fn member_back(&mut self, now: Time, r: RobotId) {
        self.handle(now, Input::Back(r));
    }

    /// A control tick: the scenario's timed facts due reach the robot, the
    /// timed skills advance, the sensor readings (in the physical world)
    /// become percepts, the world model fuses and shares, the kernel runs
    /// Algorithm 1, and the pilot fuses the current skill's schemas into a
    /// velocity command.
    fn control(&mut self, now: Time, world: Time, sensed: Option<&Sensed>) {
        let mut percepts = std::mem::take(&mut self.percepts);
        let me = self.kernel.me();
        // Borrowed, not cloned: every robot's mind holds the same `Shared`,
        // and a count bumped by every robot at every tick on two threads
        // is one cache line the cores hand back and forth.
        let shared = &self.shared;
        self.body_t = world.max(self.body_t);
        let world = self.body_t;
        while let Some((at, robots, set)) = shared.facts.get(self.next_fact)
            && *at <= world
        {
            self.next_fact += 1;
            if robots.as_ref().is_none_or(|rs| rs.contains(&me)) {
                self.world.inject(set.iter().cloned());
            }
        }
        self.world.tick(world, &mut percepts);
        if let (Some(Piloted { pilot: p, .. }), Some(s)) = (self.pilot.as_deref_mut(), sensed) {
            self.odometer = s.odometer;
            p.perceive(s, &mut percepts);
        }
        if self.wm.is_none() {
            self.kernel.tick(now, &percepts);
        } else {
            // The world model between perception and the kernel: fused
            // with what teammates said. What the new beliefs make true is
            // shared before the kernel acts on it (and, say, dissolves the
            // subteams it would inform).
            self.through_world_model(now, |wm, own, told| wm.perceive(now, &percepts, own, told));
            self.share(now);
            self.kernel.tick(now, &[]);
            // Ended here on what the world model, not due at this tick,
            // has not reported: reported at once.
            if let Some(wm) = self.wm.as_deref_mut() {
                wm.share_ending(now, &self.kernel);
                while let Some(o) = wm.poll(now) {
                    self.out.push_back(AgentOutput::Inform(o));
                }
            }
        }
        self.percepts = percepts;
        self.drain(now);
        if let Some(Piloted { pilot: p, rng }) = self.pilot.as_deref_mut() {
            let k = &self.kernel;
            let roles = roles_of(k, self.shared.mission.graph());
            let rank = k
                .leaf()
                .and_then(|f| k.org().team(f.team))
                .map_or((0, 1), |t| (t.members.rank(k.me()) as u32, t.size));
            p.set_lost(k.lost().iter().map(|r| r.0));
            p.set_roles(roles, rank);
            let mut draw = || {
                use rand::RngExt;
                rng.random_range(0.0..1.0)
            };
            let before = p.progressed_at();
            let cmd = p.control(world.as_secs_f64(), &mut draw);
            if p.progressed_at() != before {
                // Its teammates learn it with its heartbeats: one waiting
                // for it at a barrier waits on while it gets on.
                self.kernel.skill_progressed();
            }
            self.out.push_back(AgentOutput::Drive(cmd));
        }
    }

    /// When the kernel wants [`Agent::timer`].
    pub fn poll_timeout(&self) -> Option<Time> {
        self.kernel.poll_timeout()
    }

    /// The next output.
    pub fn poll(&mut self) -> Option<AgentOutput> {
        if self.out.is_empty() {
            if self.out.capacity() > 0 || self.kernel.output_room() > 0 {
                self.drained();
            }
            return None;
        }
        self.out.pop_front()
    }

    /// Room the output queues hold, this agent's and its kernel's, in
    /// outputs (to check that a robot's memory stays small between
    /// decisions).
    pub fn output_room(&self) -> usize {
        self.out.capacity() + self.kernel.output_room()
    }

    /// The runtimes drain after every input. The drained queue gives back
    /// its room once the mission is over, as the kernel's does, and while
    /// it runs at most once every [`ROOM_KEPT`], with the kernel's (which
    /// [`Agent::take`] drained into it): a decision's burst leaves room for
    /// eight outputs that a robot then mostly does not use (at 100,000
    /// robots, 96 MB each; docs/performance.md, "2026-11-28, late" and
    /// "2026-12-04, late"), and a robot deciding often allocates again at
    /// most once a second.
    #[inline(never)]
    fn drained(&mut self) {
        let now = self.kernel.now();
        if self.kernel.is_finished() || now >= self.room_until {
            bite_core::kernel::give_back_room(&mut self.out);
            self.kernel.give_back_output_room();
            self.room_until = now + ROOM_KEPT;
        }
    }

    /// Ask for what a control tick reads first of this robot's mind to be
    /// brought into the cache, one [`Ahead`] stage at a time: a large
    /// team's minds tick one after the other, each on state of its own
    /// scattered in memory, and the runner asks for the next robots'
    /// while one thinks (each stage reads only what the one before
    /// brought in).
    pub fn prefetch(&self, stage: Ahead) {
        use bite_core::hint::{prefetch_lines, prefetch_slice};
        match stage {
            // The agent itself: stored side by side with the others, but
            // two kilobytes apart.
            Ahead::Agent => prefetch_lines(
                self as *const Agent,
                std::mem::size_of::<Agent>().div_ceil(64),
            ),
            Ahead::Buffers => {
                if let Some(p) = self.pilot.as_deref() {
                    let lines = std::mem::size_of::<Piloted>().div_ceil(64);
                    prefetch_lines(p as *const Piloted, lines);
                }
                prefetch_slice(&self.percepts, 2);
                let (front, back) = self.out.as_slices();
                prefetch_slice(front, 2);
                prefetch_slice(back, 2);
                self.world.prefetch();
                self.kernel.prefetch();
            }
            Ahead::Pilot => {
                if let Some(p) = self.pilot.as_deref() {
                    p.pilot.prefetch();
                }
            }
        }
    }

    /// The outputs not polled yet, in order, left where they are.
    pub fn pending(&self) -> impl Iterator<Item = &AgentOutput> {
        self.out.iter()
    }

    /// Take the drive commands out of the outputs not polled yet (the
    /// others stay, in order) and give the last: what the body follows
    /// once they are all applied in order. For a runtime that drives the
    /// body before it carries out the rest (a drive is the only output
    /// that reaches the body).
    pub fn take_drive(&mut self) -> Option<Command> {
        let mut last = None;
        self.out.retain(|o| match o {
            AgentOutput::Drive(cmd) => {
                last = Some(*cmd);
                false
            }
            _ => true,
        });
        last
    }

    /// Offer version `version` of the mission (`shared`: built for it with
    /// [`Shared::new`] from its aligned graph and the same scenario). The
    /// kernel holds it until its team's next safe point, then the skills,
    /// motor schemas and percepts of the new version take over.
    pub fn offer_change(
        &mut self,
        now: Time,
        version: u32,
        shared: Arc<Shared>,
    ) -> Result<(), bite_core::graph::Refused> {
        let now = now.max(self.last);
        self.last = now;
        let r = self
            .kernel
            .offer_change(now, version, shared.mission.clone());
        if r.is_ok() {
            self.pending.insert(version, shared);
            // What the kernel no longer holds goes (it keeps the newest few).
            let held: Vec<u32> = self.pending.keys().copied().collect();
            let oldest = held.len().saturating_sub(4);
            for v in &held[..oldest] {
                self.pending.remove(v);
            }
        }
        self.drain(now);
        r
    }

    /// The kernel switched to `version`: the rest of the mind follows.
    fn switched(&mut self, version: u32) {
        let Some(shared) = self.pending.remove(&version) else {
            return;
        };
        self.pending.retain(|v, _| *v > version);
        if let (Some(Piloted { pilot: p, .. }), Some((_, tables))) =
            (self.pilot.as_deref_mut(), shared.physics.as_ref())
        {
            p.set_tables(tables.clone());
        }
        // The world model (set up by the first version) takes every belief
        // of the new one: the kernel hears its own readings through it.
        if let Some(wm) = self.wm.as_deref_mut() {
            let len = shared.mission.graph().symbols().len();
            wm.grow(len, shared.wm.as_ref().map(|w| w.2.clone()));
        }
        self.shared = shared;
        // The leaf's skill is looked up again in the new version.
        self.version = u64::MAX;
    }

    fn drain(&mut self, now: Time) {
        while let Some(o) = self.kernel.poll_output() {
            if let Output::Event(Event::MissionChanged { version, .. }) = &o {
                self.switched(*version);
            }
            self.out.push_back(match o {
                Output::Send(s) => AgentOutput::Send {
                    to: s.to,
                    envelope: s.envelope,
                    bytes: s.bytes,
                },
                Output::Event(e) => AgentOutput::Event(e),
            });
        }
        if self.kernel.stack_version() != self.version {
            self.version = self.kernel.stack_version();
            let leaf = self.kernel.leaf().map(|f| (f.behavior, f.team, f.epoch));
            let started: Vec<(BeliefId, Value)> = self
                .world
                .leaf_changed(&self.shared.book, leaf, self.body_t)
                .to_vec();
            if self.wm.is_none() {
                for (id, v) in started {
                    self.kernel.set_belief(id, v, Source::Percept);
                }
            } else {
                self.through_world_model(now, |wm, own, told| {
                    wm.perceive(now, &started, own, told)
                });
            }
            if let Some(Piloted { pilot: p, .. }) = self.pilot.as_deref_mut() {
                let leaf = leaf.map(|l| l.0);
                let skill = leaf
                    .and_then(|b| self.shared.motor.get(b.index()).cloned())
                    .unwrap_or_else(|| Arc::from(Vec::new()));
                p.leaf_changed(self.body_t.as_secs_f64(), self.odometer, leaf, skill);
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
        let Some(wm) = self.wm.as_deref_mut() else {
            return;
        };
        self.own.clear();
        self.told.clear();
        feed(wm, &mut self.own, &mut self.told);
        self.kernel.observe(now, &self.own);
        for (id, v, src) in self.told.drain(..) {
            self.kernel.set_belief(id, v, src);
        }
    }

    fn share(&mut self, now: Time) {
        let Some(wm) = self.wm.as_deref_mut() else {
            return;
        };
        if wm.due(now) {
            wm.share(now, &self.kernel);
        }
        while let Some(o) = wm.poll(now) {
            self.out.push_back(AgentOutput::Inform(o));
        }
    }
}
