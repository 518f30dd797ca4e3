//! The discrete-event team runner: N kernels, the timed-skill world and the
//! seeded network in one process, on a simulated clock.
//!
//! Events are processed in time order, ties in the order they were
//! scheduled, so a run is a pure function of (mission, scenario, seed).
//! Control ticks reach every robot at the scenario's rate; messages and
//! kernel timers are delivered at their own times in between.

use crate::log::{Namer, RunLog};
use crate::net::SimNet;
use crate::summary::{Aggregator, Summary};
use bite_agent::agent::{Agent, AgentOutput, Ahead, Input, Shared};
use bite_agent::scenario::{Resolved, Scenario};
use bite_agent::schema::Sensed;
use bite_core::diag::{Diagnostic, Diagnostics};
use bite_core::event::{DropReason, Event};
use bite_core::graph::BehaviorGraph;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{Recipients, Registry};
use bite_core::kernel::{Frame, Position, Stats};
use bite_core::mission::Mission;
use bite_core::msg::Envelope;
use bite_core::org::MemberSet;
use bite_core::time::Time;
use rand::SeedableRng;
use serde_json::json;
use std::collections::BTreeMap;
use std::io::Write;
use std::sync::Arc;

/// From how many robots their control ticks run on several threads and
/// their world steps ahead on a second one (below, the threads would cost
/// more than they save; the run is the same).
const PARALLEL_FROM: usize = 64;

/// Should a team of `n` tick on several threads (and its world step ahead,
/// [`Sim::step_ahead`])? Only from
/// [`PARALLEL_FROM`] robots, and never from inside a rayon pool's worker
/// (`bite sweep`, `bite experiment` already run whole runs side by side:
/// a worker waiting for its robots could steal another run's job and
/// block it under locks that run holds). The run is the same either way.
pub(crate) fn parallel(n: usize) -> bool {
    n >= PARALLEL_FROM && rayon::current_thread_index().is_none()
}

/// How long a pool thread kept awake waits for the run's next turn at
/// most, in pauses of the processor (a few milliseconds to a few tens:
/// longer than the run's own thread takes between turns in a large team,
/// short enough not to hold a core long after the last).
const AWAKE_SPINS: u32 = 1 << 20;

/// One of the pool's threads kept awake until the pool's next turn: from
/// late in the run's own thread's carrying out of a window of events the
/// pool handled ([`Sim::batch`]); in a physical world, from the minds'
/// end to the world leaving to step ahead ([`Sim::step_ahead`]) and from
/// the run's thread waiting for the world to the robots' sensing (the
/// world's job started 1.5 ms late at every tick otherwise, of a 22 ms
/// tick at 10,000 robots on two threads, and sensing took 0.3 ms longer;
/// docs/performance.md, "2026-12-01"). A thread that fell asleep was
/// woken at the next turn only once the other had started and handed it
/// work, and on a virtual machine whose idle processor the host had put
/// to sleep, that took 1.4 ms a turn at 100,000 robots (a fifth of the
/// turn; docs/performance.md, "2026-11-29, night: the second thread woken
/// late"). What OpenMP calls an active wait policy, bounded. It changes
/// nothing of the run.
#[derive(Default)]
struct Awake {
    /// The waiting thread's signal to stop, if one waits.
    stop: Option<Arc<std::sync::atomic::AtomicBool>>,
}

impl Awake {
    /// Keep one of `pool`'s threads (or the global pool's) awake from now
    /// until [`Awake::release`] or [`AWAKE_SPINS`].
    fn keep(&mut self, pool: Option<&rayon::ThreadPool>) {
        use std::sync::atomic::{AtomicBool, Ordering};
        self.release();
        let stop = Arc::new(AtomicBool::new(false));
        self.stop = Some(stop.clone());
        let wait = move || {
            for k in 0..AWAKE_SPINS {
                if stop.load(Ordering::Relaxed) {
                    return;
                }
                // Now and then the core is offered to whatever else waits
                // for it (nothing, on a machine the run has to itself).
                if k % 256 == 255 {
                    std::thread::yield_now();
                } else {
                    std::hint::spin_loop();
                }
            }
        };
        spawn_on(pool, wait);
    }

    /// The pool's turn: the thread kept awake goes back to the pool.
    fn release(&mut self) {
        if let Some(stop) = self.stop.take() {
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

/// Run `job` on `pool`'s threads (or the global pool's), not waiting for it.
fn spawn_on(pool: Option<&rayon::ThreadPool>, job: impl FnOnce() + Send + 'static) {
    match pool {
        Some(p) => p.spawn(job),
        None => rayon::spawn(job),
    }
}

impl Drop for Awake {
    fn drop(&mut self) {
        self.release();
    }
}

use std::time::Duration;

pub use bite_agent::agent::derive_seed;

/// Build the mission for a run: the graph resized to the team size the
/// caller or the scenario asks for, with protocols resolved.
pub fn prepare(
    graph: &BehaviorGraph,
    scenario: &Scenario,
    robots: Option<usize>,
    registry: &Registry,
) -> Result<Arc<Mission>, Diagnostics> {
    let graph = match robots.or(scenario.robots) {
        Some(n) if n != graph.roster().len() => graph.with_team_size(n),
        _ => graph.clone(),
    };
    Ok(Arc::new(Mission::new(graph, registry)?))
}

/// Progress of a running simulation.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Simulated time.
    pub now: Time,
    /// Robots that completed the mission.
    pub finished: usize,
    /// Team size.
    pub robots: usize,
}

/// How to run.
#[derive(Default)]
pub struct RunOptions<'a> {
    /// Seed (default: the scenario's).
    pub seed: Option<u64>,
    /// Time limit (default: the scenario's).
    pub time_limit: Option<Duration>,
    /// Where to write the JSON-lines run log.
    pub log: Option<&'a mut dyn Write>,
    /// Keep every event in memory for checking (tests).
    pub record: bool,
    /// Called about once per simulated second.
    pub progress: Option<&'a mut dyn FnMut(Progress)>,
    /// New versions of the mission handed to the running team, in order
    /// (see [`prepare_change`]).
    pub changes: Vec<Change>,
    /// Someone watching the run as it goes (a live view, an MCAP file).
    pub watch: Option<Watch<'a>>,
    /// The threads a large team's control tick runs on, and its world steps
    /// ahead on (default: rayon's global pool; `bite bench --threads`
    /// compares one with two). The run's events stay on the caller's
    /// thread. Results are the same for any.
    pub pool: Option<Arc<rayon::ThreadPool>>,
    /// The team size from which, in a timed world on two threads or more,
    /// robots' events are handled side by side (`Sim::batch`; default
    /// [`BATCH_FROM`]). Results are the same either way.
    pub batch_from: Option<usize>,
    /// The most events one window of robots' events holds (default
    /// [`BATCH_MOST`]); the rest begin the next. Results are the same for
    /// any.
    pub batch_most: Option<usize>,
    /// Write a `message` record to the log for every message a robot
    /// sends (`bite run --log-messages`).
    pub log_messages: bool,
}

/// The team size from which robots' events are handled side by side by
/// default: below it, handing them to the pool costs more than it saves
/// (measured on 2 cores: 3,000 robots 10 % slower, 6,000 20 % faster;
/// docs/performance.md).
pub const BATCH_FROM: usize = 5_000;

/// The most robots' events one window handles side by side by default
/// ([`Sim::batch`]). Each event's result holds what its robot asked until
/// the window is carried out, and a window is otherwise as long as the
/// network's least delay: a burst (every member of a large team answering
/// at once) made one of 420,000 events at 30,000 robots, 200 MB of results
/// held at once on two threads, the run's peak. An average window at
/// 100,000 robots holds about 9,000 events.
pub const BATCH_MOST: usize = 1 << 15;

/// A watcher of a run: sees every run-log record when it is made (whether
/// or not a log is written), and in a physical world a `poses` record every
/// `poses_every` of simulated time instead of the log's one a second.
pub struct Watch<'a> {
    /// Called with each record, in log order.
    pub on_record: &'a mut dyn FnMut(&serde_json::Value),
    /// How often the watcher sees where everything is (physical world).
    pub poses_every: Duration,
}

/// A new version of the mission handed to the team at a time.
#[derive(Clone, Debug)]
pub struct Change {
    /// When the team is given it (every robot not crashed; a crashed one
    /// when it resumes).
    pub at: Time,
    /// Its version (1 for the first change, and so on).
    pub version: u32,
    /// The mission, aligned to the version before it.
    pub mission: Arc<Mission>,
    /// Where it came from (for the log).
    pub source: String,
}

/// Build version `version` of a running mission from its new graph: sized
/// like `base`, numbered like it (see `BehaviorGraph::aligned_to`), with
/// protocols resolved. A version that cannot replace `base` is refused
/// with the reason.
pub fn prepare_change(
    base: &Mission,
    graph: &BehaviorGraph,
    registry: &Registry,
) -> Result<Arc<Mission>, String> {
    let n = base.graph().roster().len();
    let graph = if graph.roster().len() != n {
        graph.with_team_size(n)
    } else {
        graph.clone()
    };
    let aligned = graph.aligned_to(base.graph()).map_err(|e| e.to_string())?;
    Mission::new(aligned, registry)
        .map(Arc::new)
        .map_err(|d| d.to_string())
}

/// One recorded event.
#[derive(Clone, Debug)]
pub struct Record {
    /// When.
    pub t: Time,
    /// Which robot.
    pub robot: RobotId,
    /// What.
    pub event: Event,
}

/// The state of one robot at the end of a run.
#[derive(Clone, Debug)]
pub struct FinalRobot {
    /// Which robot.
    pub robot: RobotId,
    /// It crashed (by the scenario).
    pub crashed: bool,
    /// It completed the mission.
    pub finished: bool,
    /// Its behavior stack at the end.
    pub stack: Vec<Frame>,
    /// Result of its organization's structural check.
    pub org_check: Result<(), String>,
    /// Its kernel's counters.
    pub stats: Stats,
    /// The version of the mission it ran at the end.
    pub version: u32,
}

/// What a run produced.
#[derive(Debug)]
pub struct RunReport {
    /// The summary.
    pub summary: Summary,
    /// Every event, when recording was asked for.
    pub history: Vec<Record>,
    /// Robots at the end.
    pub finals: Vec<FinalRobot>,
    /// Scenario warnings.
    pub warnings: Vec<Diagnostic>,
    /// When each robot crashed, and when it resumed (`None`: never).
    pub crashes: Vec<(RobotId, Time, Option<Time>)>,
    /// When the run stopped.
    pub end: Time,
    /// The physical world at the end (`world: physics`), for pictures.
    pub world: Option<crate::physics::World>,
    /// Invariants the run broke (checked on every run).
    pub violations: Vec<crate::check::Violation>,
    /// How many robots' events were handled side by side (`Sim::batch`).
    pub batched: Batched,
}

/// Robots' events handled side by side in a run (`Sim::batch`): what a
/// test of that path checks it took, and `bite bench team --json` reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Batched {
    /// Windows of robots' events (`Sim::batch`).
    pub windows: u64,
    /// Of which were handed to the pool (the others had few robots).
    pub pooled: u64,
    /// Events in them.
    pub events: u64,
    /// Events of a robot whose timer could fall due first, handled in order
    /// afterwards.
    pub later: u64,
    /// Timers that fell due inside a window, handled in their place.
    pub between: u64,
    /// Windows cut short at the most events one holds
    /// (`RunOptions::batch_most`).
    pub cut: u64,
}

enum What {
    Control,
    Deliver {
        to: RobotId,
        env: Arc<Envelope>,
    },
    /// A world-model message.
    Inform {
        from: RobotId,
        to: RobotId,
        msg: Arc<bite_core::wm::Inform>,
    },
    Timer(RobotId),
    Crash(RobotId),
    Resume(RobotId),
    /// `observer` has not heard from `subject` for `lost_after`.
    Lost {
        observer: RobotId,
        subject: RobotId,
    },
    /// `observer` hears from `subject` again.
    Back {
        observer: RobotId,
        subject: RobotId,
    },
    /// Robot's heartbeat: its position goes to its audience.
    Beacon(RobotId),
    /// A heartbeat arrives.
    Peer {
        to: RobotId,
        from: RobotId,
        pos: Arc<bite_core::kernel::Position>,
    },
    /// A forged, replayed or malformed message is injected.
    Inject,
    /// The `k`th new version of the mission is handed to the team.
    Change(usize),
    /// A message or heartbeat robot `to` has heard, its content dropped
    /// where it was handled (see [`spend`]); never scheduled.
    Spent(RobotId),
}

/// An event as the queue gives it: its time, its place among the events
/// at that time, the event.
type Queued = (Time, u64, What);

/// A robot's events of a window ([`Sim::handle_batch`]): its mind, each
/// event's (robot, place in the window), the events.
type Task<'a, 'b> = (&'a mut Agent, &'a [(u32, u32)], &'a mut [&'b mut Queued]);

/// The most robots that may hold what a message carries for it to be let
/// go where it was heard ([`spend`]).
const SPEND_MAX: usize = 4;

/// What a handled message or heartbeat carries, let go on the thread that
/// handled it (which has just read it) instead of the run's (which would
/// fetch it again from that thread's cache only to count it down): a
/// member's heartbeat to its leaders, a protocol message to one robot. One
/// held by many robots (a leader's heartbeat to its team) is left to the
/// run's thread, which holds it already, rather than counted down from
/// both threads at once. Nothing the run does depends on where this
/// happens.
fn spend(what: &mut What) {
    let held = match what {
        What::Peer { pos, .. } => Arc::strong_count(pos),
        What::Deliver { env, .. } => Arc::strong_count(env),
        What::Inform { msg, .. } => Arc::strong_count(msg),
        _ => return,
    };
    if held <= SPEND_MAX
        && let Some(to) = robot_event(what)
    {
        *what = What::Spent(to);
    }
}

struct Sim<'a, 'w> {
    /// Each robot's mind (the same `Agent` a robot process runs).
    agents: Vec<Agent>,
    /// What the agents share (to give a restarted robot a fresh mind).
    shared: Arc<Shared>,
    crashed: Vec<bool>,
    timers: Vec<Option<Time>>,
    net: SimNet,
    queue: crate::queue::EventQueue<What>,
    now: Time,
    agg: Aggregator,
    log: RunLog<'w>,
    /// Log every message sent (`RunOptions::log_messages`).
    log_messages: bool,
    record: bool,
    history: Vec<Record>,
    resolved: Resolved,
    times: Vec<Time>,
    graph: Arc<BehaviorGraph>,
    progress: Option<&'a mut dyn FnMut(Progress)>,
    detector: Option<bite_agent::scenario::FailureDetector>,
    /// (observer, subject) pairs where the observer presumes the subject lost.
    suspected: std::collections::BTreeSet<(RobotId, RobotId)>,
    seed: u64,
    /// The physical world (the robots' bodies), if the scenario has one.
    /// `None` in a physical run while it steps ahead ([`Sim::step_ahead`]).
    physics: Option<crate::physics::World>,
    /// The physical world stepping to the next control tick on another
    /// thread, while the events until then are handled on this one.
    stepping: Option<Stepping>,
    /// Where the live robots were at the last control tick, for the
    /// stall detector (kept from tick to tick).
    positions: Vec<Option<glam::DVec2>>,
    /// When robots crash or come back, in order: the world does not step
    /// ahead across one (a stopped robot stands still from the tick before).
    crash_times: Vec<Time>,
    /// The threads of a large team's control tick (see `RunOptions::pool`).
    pool: Option<Arc<rayon::ThreadPool>>,
    /// One of the pool's threads kept awake for its next turn (see [`Awake`]:
    /// only a timed world's windows keep one, released by whatever uses
    /// the pool next).
    awake: Awake,
    /// See `RunOptions::batch_from`.
    batch_from: usize,
    /// See `RunOptions::batch_most`.
    batch_most: usize,
    /// See `RunReport::batched`.
    batched: Batched,
    next_poses: Time,
    /// How often, and when next, the watcher sees the poses.
    watch_poses: Option<(Duration, Time)>,
    /// Heartbeat period (positions travel with heartbeats).
    beacon_period: Duration,
    /// Heartbeat copies sent, and their bytes.
    beacons: (u64, u64),
    /// The invariant checker, fed every event.
    checker: crate::check::Checker,
    /// The stall watch, fed every event.
    stall: crate::stall::StallWatch,
    /// What each robot sent, window by window (see `chatter`).
    chatter: crate::chatter::ChatterWatch,
    /// Each robot's process incarnation (restarts).
    incarnation: Vec<u32>,
    /// Recent genuine messages and heartbeats, for replay injection.
    captured: std::collections::VecDeque<Arc<Envelope>>,
    captured_pos: std::collections::VecDeque<Arc<bite_core::kernel::Position>>,
    /// The injector's own generator.
    inject_rng: bite_core::interaction::Rng,
    /// Messages injected, and by kind.
    injected: BTreeMap<&'static str, u64>,
    /// How often a message is injected (`None`: never).
    inject: Option<Duration>,
    /// New versions of the mission, with what their robots share.
    changes: Vec<(Change, Arc<Shared>)>,
    /// How many of them have been handed out.
    handed: usize,
    /// What a robot's mind asked, being carried out (kept to reuse).
    outs: Vec<AgentOutput>,
    /// A window's events and what their minds asked ([`Sim::batch`]),
    /// their room kept from window to window: made anew, each window's
    /// lists (hundreds of kilobytes at 100,000 robots) were pages the
    /// system zeroed again.
    window: (Vec<Queued>, Vec<Done>),
    /// Each robot's drive command from the last control tick and its
    /// steering, taken out of what its mind asked and worked out while the
    /// minds ran side by side (kept to reuse; see [`Sim::control_tick`]).
    drives: Vec<Drive>,
    /// Whether what each robot's mind asked at the last control tick
    /// has an event (for the stall watch, which sees them first).
    eventful: Vec<bool>,
}

/// Robots a thread's control tick takes at a time (see `Sim::control_tick`).
const RUN: usize = 64;

/// What a differential drive steers toward (`schema::steering`).
type Steering = (Option<f64>, f64);

/// A robot's drive command from a control tick, with its steering.
type Drive = Option<(bite_agent::schema::Command, Steering)>;

/// The physical world away, stepping to the next control tick.
struct Stepping {
    /// The world once stepped (or the panic that stopped it).
    world: std::sync::mpsc::Receiver<std::thread::Result<crate::physics::World>>,
    /// Who hears whom meanwhile: as the robots stood when it left.
    radio: crate::physics::Radio,
    /// The control tick it steps to.
    until: Time,
}

impl Sim<'_, '_> {
    /// The threads of the run's pool (or the global pool's).
    fn threads(&self) -> usize {
        (self.pool.as_ref()).map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
    }

    fn schedule(&mut self, at: Time, what: What) {
        self.queue.push(at, what);
    }

    /// Step the physical world to the next control tick, `next`, on
    /// another thread while the events until then (deliveries, heartbeats,
    /// timers) are handled on this one. They never touch the world but
    /// to ask who is in radio range, answered from the robots' positions
    /// now, which is what the world says until it steps; and the world
    /// steps on the commands of this tick (only a control tick drives) with
    /// the robots stopped that are stopped now. So the run is the same as
    /// stepping at the next tick, which the world does instead when it
    /// cannot step ahead: a small team (the thread would cost more than
    /// the steps), one thread, a run inside a pool's worker (`bite sweep`,
    /// `bite experiment`: see [`parallel`]), a watcher that will see the
    /// world before the next tick, a crash or a restart before the next
    /// tick, or the run's time limit before it.
    fn step_ahead(&mut self, next: Time, limit: Time) {
        let threads = self.threads();
        let crash = self.crash_times.partition_point(|t| *t < self.now);
        if self.physics.is_none()
            || self
                .watch_poses
                .is_some_and(|(every, at)| !every.is_zero() && at < next)
            || next > limit
            || threads < 2
            || !parallel(self.agents.len())
            || self.crash_times.get(crash).is_some_and(|t| *t <= next)
        {
            return;
        }
        let Some(mut w) = self.physics.take() else {
            return;
        };
        let radio = w.radio();
        let stopped = self.crashed.clone();
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.awake.release();
        let job = move || {
            let stepped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
                w.advance(next, &stopped);
                w
            }));
            // The run waits for it at the next tick (or has panicked).
            let _ = tx.send(stepped);
        };
        spawn_on(self.pool.as_deref(), job);
        self.stepping = Some(Stepping {
            world: rx,
            radio,
            until: next,
        });
    }

    /// The world back from stepping ahead, if it was away; true if it was
    /// (it has then stepped to the control tick it left for).
    fn home(&mut self) -> bool {
        let Some(s) = self.stepping.take() else {
            return false;
        };
        assert_eq!(s.until, self.now, "the world stepped to the next tick");
        match s.world.recv() {
            Ok(Ok(w)) => self.physics = Some(w),
            Ok(Err(panic)) => std::panic::resume_unwind(panic),
            // The job always answers (its panic included).
            Err(std::sync::mpsc::RecvError) => unreachable!("the world stepping ahead was lost"),
        }
        true
    }

    /// Robot `i`'s clock at simulated time `t` (its rate and offset; a
    /// robot's mind sees only its own clock).
    fn local(&self, i: usize, t: Time) -> Time {
        local_clock(&self.resolved.clocks, i, t)
    }

    /// The simulated time at which robot `i`'s clock reads `t` (rounded up,
    /// so that a timer set for `t` finds the clock at or past it).
    fn global(&self, i: usize, t: Time) -> Time {
        global_clock(&self.resolved.clocks, i, t)
    }

    /// Robot `i`'s clock now.
    fn clock(&self, i: usize) -> Time {
        self.local(i, self.now)
    }

    /// Every live robot's control tick: each senses the world and its
    /// mind ticks, side by side on the threads of the current rayon pool
    /// for a large team (a robot's mind reads nothing of the others', and
    /// the world does not change while they think); then each robot's
    /// drive command goes to its body and the stall watch sees the events,
    /// in robot order. The rest of what the minds asked is carried out by
    /// [`Sim::carry_out_tick`], in robot order too, once the world has
    /// left to step to the next tick: nothing else a mind asks reaches the
    /// world, and who hears a message is answered from where the robots
    /// stand now either way. The run is the same whatever the number of
    /// threads, and the same as handing the robots their ticks one by one
    /// (nothing a mind asks reaches another mind or the world before the
    /// tick ends).
    fn control_tick(&mut self) {
        use rayon::prelude::*;
        let n = self.agents.len();
        let par = parallel(n);
        let pool = self.pool.clone();
        // On the run's own pool when it has one (the decision to go
        // parallel is taken here, on the run's thread).
        let on_pool = |f: &mut (dyn FnMut() + Send)| match &pool {
            Some(p) if par => p.install(f),
            _ => f(),
        };
        if par {
            self.awake.release();
        }
        let mut sensed: Vec<Option<Sensed>> = Vec::new();
        if let Some(w) = self.physics.as_mut() {
            let crashed = &self.crashed;
            on_pool(&mut || sensed = w.observe_all(crashed, par));
        }
        let clocks: Vec<Time> = (0..n).map(|i| self.clock(i)).collect();
        let (world, crashed) = (self.now, &self.crashed);
        self.drives.resize(n, None);
        self.eventful.resize(n, false);
        type Asked<'a> = (&'a mut Drive, &'a mut bool);
        let tick = |((i, a), (drive, eventful)): ((usize, &mut Agent), Asked<'_>)| {
            *drive = None;
            *eventful = false;
            if !crashed[i] {
                let sensed = sensed.get(i).and_then(Option::as_ref);
                a.handle(clocks[i], Input::Tick { world, sensed });
                *drive = (a.take_drive()).map(|cmd| (cmd, bite_agent::schema::steering(&cmd)));
                *eventful = a.pending().any(|o| matches!(o, AgentOutput::Event(_)));
            }
        };
        // In runs of robots, each thread with the next robots' minds on
        // their way into the cache (`look_ahead`).
        type Run<'a> = (usize, ((&'a mut [Agent], &'a mut [Drive]), &'a mut [bool]));
        let run = |(k, ((agents, drives), eventful)): Run<'_>| {
            let first = k * RUN;
            look_ahead(
                agents,
                |a| a,
                |j, a| tick(((first + j, a), (&mut drives[j], &mut eventful[j]))),
            );
        };
        let (agents, drives, eventful) = (&mut self.agents, &mut self.drives, &mut self.eventful);
        if par {
            on_pool(&mut || {
                (agents.par_chunks_mut(RUN))
                    .zip(drives.par_chunks_mut(RUN))
                    .zip(eventful.par_chunks_mut(RUN))
                    .enumerate()
                    .for_each(run)
            });
        } else {
            (agents.chunks_mut(RUN))
                .zip(drives.chunks_mut(RUN))
                .zip(eventful.chunks_mut(RUN))
                .enumerate()
                .for_each(run);
        }
        // The world leaves soon to step ahead, on one of the pool's
        // threads, kept awake for it meanwhile (see `Awake`).
        if par && self.physics.is_some() && self.threads() > 1 {
            self.awake.keep(self.pool.as_deref());
        }
        for i in 0..n {
            if let Some((cmd, steering)) = self.drives[i].take()
                && let Some(w) = self.physics.as_mut()
            {
                w.actuate_steered(i, cmd, steering);
            }
            if self.eventful[i] {
                let r = RobotId(i as u32);
                for o in self.agents[i].pending() {
                    if let AgentOutput::Event(e) = o {
                        self.stall.observe(self.now, r, e, &self.graph);
                    }
                }
            }
        }
    }

    /// Carry out the rest of what the minds asked at the control tick
    /// ([`Sim::control_tick`]), in robot order.
    fn carry_out_tick(&mut self) {
        for i in 0..self.agents.len() {
            if !self.crashed[i] {
                self.drain_observed(RobotId(i as u32), true);
            }
        }
    }

    /// A robot's event, handled here and now: a message, a heartbeat
    /// heard or sent, a timer.
    fn agent_event(&mut self, what: What) {
        let r = robot_of(&what);
        let i = r.index();
        let clock = self.clock(i);
        let done = handle_one(&mut self.agents[i], clock, self.crashed[i], &what);
        self.finish(r, &what, done);
    }

    /// Carry out robot `r`'s part of an event its mind has handled
    /// (`handle_one`), here and now.
    fn finish(&mut self, r: RobotId, what: &What, done: Done) {
        match done {
            Done::Later => unreachable!("an event handled later is handled by `agent_event`"),
            Done::Nothing => {}
            Done::Beacon(b) => self.send_beacon(r, b),
            Done::Handled(mut outs, mut timeout) => {
                if matches!(what, What::Timer(_)) {
                    self.timers[r.index()] = None;
                    // A kernel whose timer stays due would be woken at
                    // this instant for ever, and the clock would never
                    // move: the run ends as stalled at the next tick.
                    if self.agents[r.index()].timer_spinning() {
                        self.stall.spinning(self.now, r);
                        timeout = None;
                    }
                }
                self.carry_out(r, &mut outs, timeout);
            }
        }
    }

    /// Send robot `r`'s heartbeat (its audience and position, if it has
    /// one) and schedule the next.
    fn send_beacon(&mut self, r: RobotId, beacon: Option<Beacon>) {
        if let Some(Beacon {
            audience,
            pos,
            bytes,
        }) = beacon
        {
            if self.inject.is_some() {
                if self.captured_pos.len() >= 16 {
                    self.captured_pos.pop_front();
                }
                self.captured_pos.push_back(pos.clone());
            }
            for to in audience.iter() {
                self.beacons.0 += 1;
                self.beacons.1 += bytes;
                self.send(r, to, || What::Peer {
                    to,
                    from: r,
                    pos: pos.clone(),
                });
            }
        }
        let next = self.now + self.beacon_period;
        self.schedule(next, What::Beacon(r));
    }

    /// How far ahead robots' events may be handled side by side (see
    /// [`Sim::batch`]): nothing one robot does reaches another sooner than
    /// the network's least delay, and its next heartbeat is a period
    /// away. `None`: one event at a time (one thread, a physical world,
    /// which steps ahead on the second core instead, a team smaller than
    /// `batch_from`, or a network without delay).
    /// Decided once, when the run starts (nothing it depends on changes).
    fn batching(&self) -> Option<Duration> {
        let n = self.agents.len();
        if self.physics.is_some() || n < self.batch_from || !parallel(n) {
            return None;
        }
        let threads = self.threads();
        let window = self.net.model().latency.min(self.beacon_period);
        (threads > 1 && !window.is_zero()).then_some(window)
    }

    /// Robots' events from `at` on, handled side by side: the events at the
    /// head of the queue until one that is not a robot's, or one `window`
    /// after the first (each robot's own events in order, on one thread).
    /// Nothing a robot does reaches another robot within the window, so
    /// the robots' minds end where they would one event at a time. What
    /// each mind asked is then carried out one event after the other in
    /// the queue's order (messages drawn from the network's generator,
    /// events logged and checked, timers scheduled), with the events that
    /// fall due in between (a robot's own timer) handled in their place.
    /// A robot whose timer could fall due before its next event in the
    /// window has its remaining events handled in that second pass, one at
    /// a time. So the run is the same, byte for byte, as one event at a
    /// time, whatever the number of threads.
    fn batch(&mut self, at: Time, seq: u64, what: What, window: Duration, limit: Time) {
        let end = at + window;
        let (mut batch, mut done) = std::mem::take(&mut self.window);
        batch.push((at, seq, what));
        while let Some((t, _, w)) = self.queue.peek() {
            if robot_event(w).is_none() || t >= end || t > limit {
                break;
            }
            if batch.len() >= self.batch_most {
                // The rest begin the next window, from their own time: a
                // shorter window is as safe as the full one.
                self.batched.cut += 1;
                break;
            }
            batch.extend(self.queue.pop_keyed());
        }
        let pooled = self.handle_batch(&mut batch, &mut done);
        // The pool's next turn comes once this window is carried out: one
        // of its threads is woken for it while the last two fifths are
        // (`Awake`; woken at the start, it spun on a core the run's thread
        // then shared, no faster at 100,000 robots).
        let wake_at = pooled.then(|| batch.len() * 3 / 5);
        self.batched.windows += 1;
        self.batched.events += batch.len() as u64;
        self.batched.later += done.iter().filter(|d| matches!(d, Done::Later)).count() as u64;
        for (k, ((at, seq, what), done)) in batch.drain(..).zip(done.drain(..)).enumerate() {
            if wake_at == Some(k) {
                self.awake.keep(self.pool.as_deref());
            }
            // What fell due since the last event and before this one (a
            // robot's timer: anything else is at least a window away).
            while let Some((t, s, w)) = self.queue.peek()
                && (t, s) < (at, seq)
            {
                debug_assert!(
                    matches!(w, What::Timer(_)),
                    "only timers fall due in a window"
                );
                let Some((t, _, w)) = self.queue.pop_keyed() else {
                    break;
                };
                self.now = t;
                self.batched.between += 1;
                self.agent_event(w);
            }
            self.now = at;
            match done {
                Done::Later => self.agent_event(what),
                done => self.finish(robot_of(&what), &what, done),
            }
        }
        self.window = (batch, done);
    }

    /// The minds' part of a batch of robots' events ([`Sim::batch`]),
    /// side by side by robot, each robot's events in order: `done` gets
    /// one result per event, in the batch's order. True if they were
    /// handed to the pool (not a few robots handled here).
    fn handle_batch(&mut self, batch: &mut [(Time, u64, What)], done: &mut Vec<Done>) -> bool {
        use rayon::prelude::*;
        // (robot, place in the batch): by robot, each robot's in order.
        let mut order: Vec<(u32, u32)> = (batch.iter().enumerate())
            .map(|(j, (_, _, what))| (robot_of(what).0, j as u32))
            .collect();
        // A stable radix sort by robot (the places are in order already):
        // a window holds thousands of events, and comparison sorting them
        // took 1.5 % of a 100,000-robot run on two threads (perf), this 0.6 %.
        radsort::sort_by_key(&mut order, |&(robot, _)| robot);
        // The events themselves in the same order, each task's its own
        // (the handling thread spends what they carry, below).
        let mut places: Vec<Option<&mut Queued>> = batch.iter_mut().map(Some).collect();
        let mut events: Vec<&mut Queued> = (order.iter())
            .filter_map(|&(_, j)| places[j as usize].take())
            .collect();
        debug_assert_eq!(events.len(), order.len());
        let groups: Vec<&[(u32, u32)]> = order.chunk_by(|a, b| a.0 == b.0).collect();
        let robots: Vec<usize> = groups.iter().map(|g| g[0].0 as usize).collect();
        // Each robot's events: as many as its group, in the same order.
        let mut rest: &mut [&mut Queued] = &mut events;
        let mut tasks: Vec<Task<'_, '_>> = pick_mut(&mut self.agents, &robots)
            .into_iter()
            .zip(groups)
            .map(|(a, mine)| {
                let (evs, tail) = std::mem::take(&mut rest).split_at_mut(mine.len());
                rest = tail;
                (a, mine, evs)
            })
            .collect();
        // The robot with the most events first: one robot's events stay on
        // one thread, and a large team's leader hears a heartbeat from
        // every member it has; handled last, the other thread would wait
        // for it with nothing left to take. (The order of the tasks changes
        // nothing else: each result goes back to its event's place.)
        if let Some(heavy) = (tasks.iter().enumerate())
            .max_by_key(|(k, (_, mine, _))| (mine.len(), std::cmp::Reverse(*k)))
            .map(|(k, _)| k)
        {
            tasks.swap(0, heavy);
        }
        let (clocks, crashed) = (&self.resolved.clocks, &self.crashed);
        // Each robot's results go on its run's list (one list per run of
        // robots, not one per robot: a window holds thousands, and each
        // list made on a pool thread was freed on the run's).
        let work = |(a, mine, evs): &mut Task<'_, '_>, out: &mut Vec<(u32, Done)>| {
            // The earliest timer its events so far may have scheduled.
            let mut due: Option<Time> = None;
            // What its events carry, on their way into the cache: a
            // leader hears a window's heartbeats of many members in a
            // row, each position in allocations of its own.
            for w in evs.iter().take(2) {
                prefetch_heard(a, &w.2);
            }
            for k in 0..evs.len() {
                if let Some(w) = evs.get(k + 2) {
                    prefetch_heard(a, &w.2);
                }
                if let Some((_, _, What::Peer { pos, .. })) = evs.get(k + 1).map(|w| &**w) {
                    pos.prefetch();
                }
                let (at, _, what) = &mut *evs[k];
                let at = *at;
                let i = robot_of(what).index();
                out.push((
                    mine[k].1,
                    handle_one(a, local_clock(clocks, i, at), crashed[i], what),
                ));
                spend(what);
                // A timer may fall due before its next event here (this
                // event's, or an earlier one's that is still scheduled and
                // would find the robot as it was then): that event and the
                // rest are handled in order later.
                if let Some(next) = evs.get(k + 1) {
                    let now_due = a.poll_timeout().map(|t| global_clock(clocks, i, t).max(at));
                    due = due.into_iter().chain(now_due).min();
                    if due.is_some_and(|t| t < next.0) {
                        break;
                    }
                }
            }
        };
        // A few robots are handled here (handing work to the pool and
        // waiting for it costs more).
        let few = tasks.len() < 2 * 32;
        self.batched.pooled += u64::from(!few);
        // In runs of robots, with the next robots' minds on their way into
        // the cache (`look_ahead`).
        let run = |tasks: &mut [Task<'_, '_>]| -> Vec<(u32, Done)> {
            let mut out = Vec::with_capacity(tasks.iter().map(|(_, mine, _)| mine.len()).sum());
            look_ahead(tasks, |(a, _, _)| &**a, |_, task| work(task, &mut out));
            out
        };
        let mut side_by_side = || (tasks.par_chunks_mut(RUN)).map(run).collect();
        if !few {
            self.awake.release();
        }
        let results: Vec<Vec<(u32, Done)>> = match &self.pool {
            _ if few => vec![run(&mut tasks)],
            Some(pool) => pool.install(side_by_side),
            None => side_by_side(),
        };
        done.clear();
        done.resize_with(batch.len(), || Done::Later);
        for (j, d) in results.into_iter().flatten() {
            done[j as usize] = d;
        }
        !few
    }

    /// Hand robot `r` one input at its own clock, then carry out what
    /// its mind asks.
    fn input(&mut self, r: RobotId, input: Input<'_>) {
        let now = self.clock(r.index());
        self.agents[r.index()].handle(now, input);
        self.drain(r);
    }

    /// Carry out what robot `r`'s mind asks: messages onto the simulated
    /// network, events into the aggregator, checker, stall watch and log,
    /// commands to its body; and keep its timer scheduled.
    fn drain(&mut self, r: RobotId) {
        self.drain_observed(r, false);
    }

    /// [`Sim::drain`]; `observed`: the stall watch has seen its events.
    fn drain_observed(&mut self, r: RobotId, observed: bool) {
        let i = r.index();
        let mut outs = std::mem::take(&mut self.outs);
        outs.extend(std::iter::from_fn(|| self.agents[i].poll()));
        let timeout = self.agents[i].poll_timeout();
        self.carry_out_observed(r, &mut outs, timeout, observed);
        self.outs = outs;
    }

    /// Carry out what robot `r`'s mind asked (`outs`, emptied), and keep
    /// its timer scheduled for `timeout` (its clock), as [`Sim::drain`].
    fn carry_out(&mut self, r: RobotId, outs: &mut Vec<AgentOutput>, timeout: Option<Time>) {
        self.carry_out_observed(r, outs, timeout, false);
    }

    /// [`Sim::carry_out`]; `observed`: the stall watch has seen its events.
    fn carry_out_observed(
        &mut self,
        r: RobotId,
        outs: &mut Vec<AgentOutput>,
        timeout: Option<Time>,
        observed: bool,
    ) {
        let i = r.index();
        for o in outs.drain(..) {
            match o {
                AgentOutput::Send {
                    to,
                    envelope,
                    bytes,
                } => {
                    let key = envelope.instance;
                    if self.log_messages && self.log.is_writing() {
                        let rec =
                            Namer::new(&self.graph).message(self.now, r, &to, &envelope, bytes);
                        self.log.write(&rec);
                    }
                    self.agg.sent(key.behavior, key.kind, bytes);
                    self.chatter.sent(self.now, r);
                    let env = Arc::new(envelope);
                    if self.inject.is_some() {
                        if self.captured.len() >= 64 {
                            self.captured.pop_front();
                        }
                        self.captured.push_back(env.clone());
                    }
                    match &to {
                        Recipients::One(x) => self.transmit(r, *x, &env),
                        Recipients::Team(set) => {
                            for x in set.iter() {
                                if x != r {
                                    self.transmit(r, x, &env);
                                }
                            }
                        }
                    }
                }
                AgentOutput::Event(e) => {
                    self.agg.event(self.now, r, &e);
                    self.checker.observe(self.now, r, &e);
                    if !observed {
                        self.stall.observe(self.now, r, &e, &self.graph);
                    }
                    if self.log.is_writing() {
                        let rec = Namer::new(&self.graph).record(self.now, r, &e);
                        self.log.write(&rec);
                    }
                    if self.record {
                        self.history.push(Record {
                            t: self.now,
                            robot: r,
                            event: e,
                        });
                    }
                }
                AgentOutput::Inform(o) => {
                    if self.log.is_writing() {
                        let rec = json!({
                            "t": self.now.as_secs_f64(),
                            "robot": self.graph.roster().name(r),
                            "event": "inform",
                            "reason": o.msg.reason,
                            "about": o.msg.about.map(|b| self.graph.name_of(b).to_string()),
                            "to": o.to.iter().map(|x| self.graph.roster().name(*x)).collect::<Vec<_>>(),
                            "beliefs": bite_core::wm::belief_names(&self.graph, &o.msg),
                        });
                        self.log.write(&rec);
                    }
                    let msg = Arc::new(o.msg);
                    for to in o.to {
                        let msg = msg.clone();
                        self.send(r, to, move || What::Inform {
                            from: r,
                            to,
                            msg: msg.clone(),
                        });
                    }
                }
                AgentOutput::Drive(cmd) => {
                    // Only a control tick drives, and the world is home
                    // then (it steps ahead after the tick): driving it
                    // while away would change the run without a trace.
                    assert!(self.stepping.is_none(), "a robot drove between ticks");
                    if let Some(w) = self.physics.as_mut() {
                        w.actuate(i, cmd);
                    }
                }
            }
        }
        if let Some(t) = timeout {
            let t = self.global(i, t);
            if self.timers[i].is_none_or(|s| t < s || s < self.now) {
                self.timers[i] = Some(t);
                let at = t.max(self.now);
                self.schedule(at, What::Timer(r));
            }
        }
    }

    fn transmit(&mut self, from: RobotId, to: RobotId, env: &Arc<Envelope>) {
        self.send(from, to, || What::Deliver {
            to,
            env: env.clone(),
        });
    }

    /// Put a message on the simulated network: radio range, loss,
    /// duplication, latency; `what` makes each copy's delivery.
    fn send(&mut self, from: RobotId, to: RobotId, what: impl Fn() -> What) {
        let (a, b) = (from.index(), to.index());
        let heard = match (&self.physics, &self.stepping) {
            (Some(w), _) => w.in_radio_range(a, b),
            (None, Some(away)) => away.radio.in_range(a, b),
            (None, None) => true,
        };
        if !heard {
            self.net.out_of_range();
            return;
        }
        let mut times = std::mem::take(&mut self.times);
        self.net.transmit(self.now, from, to, &mut times);
        for t in &times {
            self.schedule(*t, what());
        }
        self.times = times;
    }

    /// Robot `r`'s process restarts: a fresh mind (kernel, world model,
    /// skills, pilot) with nothing of its previous incarnation, which
    /// rejoins the team where the team is (see `Kernel::rejoin`). Its
    /// sequence numbers start from the clock, so that no teammate drops its
    /// messages as duplicates of the old incarnation's.
    fn restart(&mut self, r: RobotId) {
        let i = r.index();
        // What its skill got done before it went down still counts.
        self.stall
            .skill_progressed(self.agents[i].skill_progressed_at());
        self.incarnation[i] += 1;
        let now = self.clock(i);
        self.agents[i] = Agent::restart(
            self.shared.clone(),
            r,
            self.seed,
            self.incarnation[i],
            now,
            self.now,
        );
        self.timers[i] = None;
        self.checker.restarted(r);
        self.checker.runs_version(r, 0);
        // A fresh mind starts on the first version and holds the newest
        // one handed out: it takes it as it rejoins a team that runs it,
        // or with its team at the next safe point.
        self.hand_changes(r);
        if self.log.is_writing() {
            let rec = json!({"t": self.now.as_secs_f64(), "robot": self.graph.roster().name(r), "event": "restarted", "incarnation": self.incarnation[i]});
            self.log.write(&rec);
        }
        self.drain(r);
    }

    /// Deliver one forged, replayed or malformed message to a random live
    /// robot: what gets past authentication (replays of genuine messages
    /// and heartbeats, which dedup and epochs must neutralise) and what a
    /// broken or hostile peer sends (unknown senders, malformed instance
    /// keys, garbage positions). Every one must be dropped and counted, or
    /// be harmless.
    fn inject_one(&mut self) {
        use rand::RngExt;
        let n = self.agents.len();
        let live: Vec<usize> = (0..n).filter(|i| !self.crashed[*i]).collect();
        if live.is_empty() {
            return;
        }
        let i = live[self.inject_rng.random_range(0..live.len())];
        let to = RobotId(i as u32);
        let now = self.clock(i);
        let kind = self.inject_rng.random_range(0..5u32);
        let graph = self.graph.clone();
        let nb = graph.behaviors().len() as u32;
        let what = match kind {
            // A replay of a genuine message (same sender, same sequence
            // number), possibly to another robot.
            0 if !self.captured.is_empty() => {
                let k = self.inject_rng.random_range(0..self.captured.len());
                let env = self.captured[k].clone();
                self.agents[i].handle(now, Input::Message(&env));
                "replayed message"
            }
            // A replay of a genuine heartbeat, as from another robot.
            1 if !self.captured_pos.is_empty() => {
                let k = self.inject_rng.random_range(0..self.captured_pos.len());
                let pos = self.captured_pos[k].clone();
                let from = RobotId(self.inject_rng.random_range(0..n as u32));
                self.agents[i].handle(now, Input::Peer { from, pos: &pos });
                "replayed heartbeat"
            }
            // A garbage position.
            2 => {
                let mut pos = bite_core::kernel::Position::default();
                for _ in 0..self.inject_rng.random_range(0..200u32) {
                    pos.ended.push(bite_core::kernel::Ended {
                        id: bite_core::kernel::FrameId {
                            team: bite_core::ids::TeamId(self.inject_rng.random()),
                            behavior: bite_core::ids::BehaviorId(
                                self.inject_rng.random_range(0..nb * 2 + 1),
                            ),
                            epoch: self.inject_rng.random(),
                        },
                        parent: None,
                    });
                }
                let from = RobotId(self.inject_rng.random_range(0..n as u32 + 2));
                self.agents[i].handle(now, Input::Peer { from, pos: &pos });
                "garbage heartbeat"
            }
            // A message from a robot that is not on the roster.
            3 => {
                let sender = n as u32 + self.inject_rng.random_range(0..100u32);
                let env = self.forged(sender, nb);
                self.agents[i].handle(now, Input::Message(&env));
                "unknown sender"
            }
            // A malformed instance key from a teammate: a behavior or kind
            // that is no point, epoch 0.
            _ => {
                let sender = RobotId(self.inject_rng.random_range(0..n as u32));
                let mut env = self.forged(sender.0, nb);
                match self.inject_rng.random_range(0..3u32) {
                    0 => env.instance.epoch = 0,
                    1 => env.instance.behavior = bite_core::ids::BehaviorId(nb + 7),
                    _ => env.seq = 0,
                }
                self.agents[i].handle(now, Input::Message(&env));
                "malformed key"
            }
        };
        *self.injected.entry(what).or_insert(0) += 1;
        self.drain(to);
    }

    /// A message with a random instance key and body, from `sender`.
    fn forged(&mut self, sender: u32, nb: u32) -> Envelope {
        use rand::RngExt;
        let kinds = bite_core::msg::Kind::ALL;
        Envelope {
            instance: bite_core::msg::InstanceKey {
                team: bite_core::ids::TeamId::ROOT,
                behavior: bite_core::ids::BehaviorId(self.inject_rng.random_range(0..nb.max(1))),
                kind: kinds[self.inject_rng.random_range(0..kinds.len())],
                epoch: self.inject_rng.random_range(1..50u32),
                round: 0,
            },
            sender: RobotId(sender),
            seq: self.inject_rng.random_range(1..u64::MAX),
            body: match self.inject_rng.random_range(0..4u32) {
                0 => bite_core::msg::Body::Done,
                1 => bite_core::msg::Body::Release { next: None },
                2 => bite_core::msg::Body::Vote { choice: None },
                _ => bite_core::msg::Body::Ack,
            },
        }
    }

    /// When `observer` notices a change about `subject`: detection happens
    /// at a heartbeat, so it is spread over one heartbeat period.
    fn detection_jitter(&self, observer: RobotId, subject: RobotId) -> Duration {
        let period = self
            .detector
            .map_or(0, |d| d.heartbeat.as_micros() as u64)
            .max(1);
        let h = derive_seed(
            self.seed,
            "detector",
            observer.0.wrapping_mul(1_000_003) ^ subject.0,
        );
        Duration::from_micros(h % period)
    }

    /// Can `observer` hear `subject` now (not crashed, no partition)?
    fn hears(&self, observer: RobotId, subject: RobotId) -> bool {
        !self.crashed[subject.index()] && !self.net.cut(self.now, subject, observer)
    }

    /// Hand robot `r` the newest version handed out so far, if it does not
    /// run or hold it already.
    fn hand_changes(&mut self, r: RobotId) {
        let Some((c, shared)) = self.handed.checked_sub(1).map(|k| &self.changes[k]) else {
            return;
        };
        let (version, shared) = (c.version, shared.clone());
        let k = self.agents[r.index()].kernel();
        if k.pending_version().unwrap_or(k.version()) >= version {
            return;
        }
        let now = self.clock(r.index());
        // A refusal is an event in the log; the robot runs on.
        let _ = self.agents[r.index()].offer_change(now, version, shared);
        self.drain(r);
    }

    fn live_all_finished(&self) -> bool {
        self.agents
            .iter()
            .zip(&self.crashed)
            .all(|(a, c)| *c || a.kernel().is_finished())
    }

    fn run(&mut self, limit: Time, period: Duration) -> Time {
        self.schedule(Time::ZERO, What::Control);
        for k in 0..self.changes.len() {
            let at = self.changes[k].0.at;
            self.schedule(at, What::Change(k));
        }
        for i in 0..self.resolved.crashes.len() {
            let (r, at, until) = self.resolved.crashes[i];
            self.schedule(at, What::Crash(r));
            if let Some(u) = until {
                self.schedule(u, What::Resume(r));
            }
        }
        // Partitions that outlast the detector's bound make each side
        // presume the other lost, and heal with it.
        if let Some(det) = self.detector {
            let n = self.agents.len() as u32;
            let parts = self.net.model().partitions.clone();
            for p in parts {
                if p.until - p.from <= det.lost_after {
                    continue;
                }
                for x in 0..n {
                    for r in 0..n {
                        let (x, r) = (RobotId(x), RobotId(r));
                        if x != r && p.cut.blocks(r, x) {
                            let j = self.detection_jitter(x, r);
                            self.schedule(
                                p.from + det.lost_after + j,
                                What::Lost {
                                    observer: x,
                                    subject: r,
                                },
                            );
                            self.schedule(
                                p.until + j,
                                What::Back {
                                    observer: x,
                                    subject: r,
                                },
                            );
                        }
                    }
                }
            }
        }
        let n = self.agents.len();
        let period_us = self.beacon_period.as_micros().max(1) as u64;
        for r in 0..n as u32 {
            let phase = derive_seed(self.seed, "beacon", r) % period_us;
            self.schedule(
                Time::ZERO + Duration::from_micros(phase),
                What::Beacon(RobotId(r)),
            );
        }
        if let Some(every) = self.inject {
            self.schedule(Time::ZERO + every, What::Inject);
        }
        let mut next_progress = Time::ZERO;
        let batching = self.batching();
        while let Some((at, seq, what)) = self.queue.pop_keyed() {
            if at > limit {
                return limit;
            }
            self.now = at;
            match what {
                What::Control => {
                    // Waiting for the world, one of the pool's threads
                    // is kept awake for the robots' sensing, which comes
                    // next (see `Awake`).
                    if self.stepping.is_some() {
                        self.awake.keep(self.pool.as_deref());
                    }
                    let stepped = self.home();
                    if let Some(w) = self.physics.as_mut() {
                        // A watcher that asked to see the world more often
                        // than the control rate sees it between ticks too
                        // (the physics steps the same either way).
                        if let Some((every, next)) = self.watch_poses.as_mut() {
                            let g = &self.graph;
                            let name = |b: BehaviorId| g.name_of(b).to_string();
                            while *next < self.now && !every.is_zero() {
                                w.step_until(*next, &self.crashed);
                                // Stamped with the step it shows (whole
                                // physics steps only).
                                self.log.show(&w.poses_record(w.time(), &name));
                                *next += *every;
                            }
                        }
                        if !stepped {
                            w.advance(self.now, &self.crashed);
                        }
                        w.record();
                    }
                    self.control_tick();
                    // The poses the log and a watcher get at this tick,
                    // taken while the world is home and written after
                    // the minds' events (see `carry_out_tick`).
                    let mut poses = (None, None);
                    if let Some(w) = &self.physics {
                        let g = &self.graph;
                        let name = |b: BehaviorId| g.name_of(b).to_string();
                        let t = self.now.as_secs_f64();
                        if self.now >= self.next_poses {
                            self.next_poses = self.now + Duration::from_secs(1);
                            if self.log.is_writing() {
                                poses.0 = Some(w.poses_record(t, &name));
                            }
                        }
                        if let Some((every, next)) = self.watch_poses.as_mut()
                            && self.now >= *next
                        {
                            *next = self.now + *every;
                            poses.1 = Some(w.poses_record(t, &name));
                        }
                    }
                    let over = self.live_all_finished() || {
                        if let Some(w) = &self.physics {
                            self.stall.goal(self.now, w.goal_distance());
                        }
                        // Crashed robots too: what they got done while
                        // they ran was progress then.
                        let agents = &self.agents;
                        self.stall.idle_check(self.now, || {
                            agents.iter().filter_map(Agent::skill_progressed_at).max()
                        });
                        if let Some(w) = &self.physics {
                            let mut at = std::mem::take(&mut self.positions);
                            at.clear();
                            at.extend((0..n).map(|i| (!self.crashed[i]).then(|| w.position(i))));
                            self.stall.motion(self.now, &at);
                            self.positions = at;
                        }
                        self.stall.stalled().is_some()
                    };
                    let next = self.now + period;
                    if !over {
                        if self.now >= next_progress {
                            next_progress = self.now + Duration::from_secs(1);
                            let finished = (self.agents.iter())
                                .filter(|a| a.kernel().is_finished())
                                .count();
                            if let Some(p) = self.progress.as_mut() {
                                p(Progress {
                                    now: self.now,
                                    finished,
                                    robots: n,
                                });
                            }
                        }
                        // The world leaves first: what is left of the tick
                        // is carried out while it steps.
                        self.step_ahead(next, limit);
                    }
                    // The thread kept awake for the world goes back to
                    // the pool if the world did not leave.
                    self.awake.release();
                    self.carry_out_tick();
                    if let Some(rec) = poses.0 {
                        // A watcher with its own pace sees its own.
                        match self.watch_poses {
                            Some(_) => self.log.write_only(&rec),
                            None => self.log.write(&rec),
                        }
                    }
                    if let Some(rec) = poses.1 {
                        self.log.show(&rec);
                    }
                    if over {
                        return self.now;
                    }
                    self.schedule(next, What::Control);
                }
                What::Deliver { .. }
                | What::Inform { .. }
                | What::Timer(_)
                | What::Beacon(_)
                | What::Peer { .. } => match batching {
                    Some(window) => self.batch(at, seq, what, window, limit),
                    None => {
                        // The next robots' minds on their way into the
                        // cache while this one's event is handled (hints:
                        // the next events may change meanwhile): the
                        // agent three events ahead, what it points to and
                        // the heartbeat it hears two ahead, the next one's
                        // agent in case it was not seen coming.
                        if let Some(r) = self.queue.ahead(1).and_then(robot_event) {
                            self.agents[r.index()].prefetch(Ahead::Agent);
                        }
                        if let Some(w) = self.queue.ahead(0) {
                            if let Some(r) = robot_event(w) {
                                self.agents[r.index()].prefetch(Ahead::Buffers);
                            }
                            prefetch_carried(&self.agents, w);
                        }
                        let next = (self.queue.peek()).and_then(|(_, _, w)| {
                            // What its position points to (asked for two
                            // events ahead, so read from the cache now).
                            if let What::Peer { pos, .. } = w {
                                pos.prefetch();
                            }
                            robot_event(w)
                        });
                        if let Some(r) = next {
                            self.agents[r.index()].prefetch(Ahead::Agent);
                        }
                        self.agent_event(what);
                        if let Some(r) = next {
                            self.agents[r.index()].prefetch(Ahead::Buffers);
                        }
                    }
                },
                What::Lost { observer, subject } => {
                    let o = observer.index();
                    if !self.crashed[o]
                        && !self.hears(observer, subject)
                        && self.suspected.insert((observer, subject))
                    {
                        self.input(observer, Input::Lost(subject));
                    }
                }
                What::Back { observer, subject } => {
                    let o = observer.index();
                    if !self.crashed[o]
                        && self.hears(observer, subject)
                        && self.suspected.remove(&(observer, subject))
                    {
                        self.input(observer, Input::Back(subject));
                    }
                }
                What::Inject => {
                    self.inject_one();
                    if let Some(every) = self.inject {
                        let next = self.now + every;
                        self.schedule(next, What::Inject);
                    }
                }
                // Made of a handled event only, never scheduled.
                What::Spent(_) => {}
                What::Change(k) => {
                    self.handed = self.handed.max(k + 1);
                    let (c, _) = &self.changes[k];
                    let mission = c.mission.clone();
                    if self.log.is_writing() {
                        let rec = json!({
                            "t": self.now.as_secs_f64(),
                            "event": "mission_change_submitted",
                            "version": c.version,
                            "source": c.source,
                            "changed": mission.graph().changed_since(self.graph.as_ref()),
                        });
                        self.log.write(&rec);
                    }
                    // Names of every version's behaviors (aligned: a
                    // superset of the earlier ones).
                    self.graph = mission.graph().clone();
                    self.checker.set_mission(mission);
                    for x in 0..n as u32 {
                        if !self.crashed[x as usize] {
                            self.hand_changes(RobotId(x));
                        }
                    }
                }
                What::Resume(r) => {
                    self.crashed[r.index()] = false;
                    if self.resolved.restarts.contains(&(r, self.now)) {
                        self.restart(r);
                    } else {
                        self.hand_changes(r);
                    }
                    if self.log.is_writing() {
                        let rec = json!({"t": self.now.as_secs_f64(), "robot": self.graph.roster().name(r), "event": "resumed"});
                        self.log.write(&rec);
                    }
                    for x in 0..n as u32 {
                        let x = RobotId(x);
                        if x != r {
                            let j = self.detection_jitter(x, r);
                            self.schedule(
                                self.now + j,
                                What::Back {
                                    observer: x,
                                    subject: r,
                                },
                            );
                        }
                    }
                }
                What::Crash(r) => {
                    self.crashed[r.index()] = true;
                    if let Some(det) = self.detector {
                        for x in 0..n as u32 {
                            let x = RobotId(x);
                            if x != r {
                                let j = self.detection_jitter(x, r);
                                self.schedule(
                                    self.now + det.lost_after + j,
                                    What::Lost {
                                        observer: x,
                                        subject: r,
                                    },
                                );
                            }
                        }
                    }
                    if self.log.is_writing() {
                        let rec = json!({"t": self.now.as_secs_f64(), "robot": self.graph.roster().name(r), "event": "crashed"});
                        self.log.write(&rec);
                    }
                    if self.live_all_finished() {
                        return self.now;
                    }
                }
            }
        }
        self.now
    }
}

/// Robot `i`'s clock at simulated time `t` (its rate and offset; a robot's
/// mind sees only its own clock).
fn local_clock(clocks: &[(f64, f64)], i: usize, t: Time) -> Time {
    let (rate, off) = clocks.get(i).copied().unwrap_or((1.0, 0.0));
    if rate == 1.0 && off == 0.0 {
        return t;
    }
    Time::from_secs_f64(t.as_secs_f64() * rate + off)
}

/// The simulated time at which robot `i`'s clock reads `t` (rounded up, so
/// that a timer set for `t` finds the clock at or past it).
fn global_clock(clocks: &[(f64, f64)], i: usize, t: Time) -> Time {
    let (rate, off) = clocks.get(i).copied().unwrap_or((1.0, 0.0));
    if rate == 1.0 && off == 0.0 {
        return t;
    }
    let g = (t.as_secs_f64() - off) / rate;
    Time((g * 1e6).ceil().max(0.0) as u64 + 1)
}

/// A robot's heartbeat.
struct Beacon {
    /// To whom.
    audience: MemberSet,
    /// Its position.
    pos: Arc<Position>,
    /// Its size encoded.
    bytes: u64,
}

/// Robot `a`'s heartbeat (`None`: nobody to tell).
fn beacon_of(a: &Agent) -> Option<Beacon> {
    a.kernel().beacon().map(|(audience, pos)| Beacon {
        audience,
        bytes: pos.encoded_len() as u64,
        pos: Arc::new(pos),
    })
}

/// Call `f` on each of `items` in order, with the next items' minds on
/// their way into the cache (`Agent::prefetch`): the agent of the item four
/// ahead, what it points to two ahead, its pilot's state one ahead (each
/// stage reads only what the one before brought in). A large team's minds
/// are handled one after the other, each on state of its own scattered in
/// memory.
fn look_ahead<T>(items: &mut [T], agent: impl Fn(&T) -> &Agent, mut f: impl FnMut(usize, &mut T)) {
    let ask = |items: &[T], j: usize, stage: Ahead| {
        if let Some(x) = items.get(j) {
            agent(x).prefetch(stage);
        }
    };
    for j in 0..4 {
        ask(items, j, Ahead::Agent);
    }
    for j in 0..2 {
        ask(items, j, Ahead::Buffers);
    }
    ask(items, 0, Ahead::Pilot);
    for j in 0..items.len() {
        ask(items, j + 4, Ahead::Agent);
        ask(items, j + 2, Ahead::Buffers);
        ask(items, j + 1, Ahead::Pilot);
        f(j, &mut items[j]);
    }
}

/// The robot whose event it is, if it is one robot's (a message, a
/// heartbeat heard or sent, a timer).
fn robot_event(what: &What) -> Option<RobotId> {
    match what {
        What::Deliver { to, .. }
        | What::Inform { to, .. }
        | What::Peer { to, .. }
        | What::Spent(to) => Some(*to),
        What::Timer(r) | What::Beacon(r) => Some(*r),
        _ => None,
    }
}

/// Ask for what an event carries to be brought into the cache: a
/// heartbeat's position (shared by its whole audience, but heard between
/// other robots' events, so cold by then), and what its hearer keeps of
/// its sender (see `Kernel::prefetch_peer`); for a heartbeat to send,
/// where its sender keeps its leaders (`Kernel::prefetch_audience`).
fn prefetch_carried(agents: &[Agent], what: &What) {
    if let Some(a) = robot_event(what).and_then(|r| agents.get(r.index())) {
        prefetch_heard(a, what);
    }
}

/// [`prefetch_carried`], for an event of robot `a`'s.
fn prefetch_heard(a: &Agent, what: &What) {
    match what {
        What::Peer { pos, from, .. } => {
            bite_core::hint::prefetch_lines(Arc::as_ptr(pos), 2);
            a.kernel().prefetch_peer(*from);
        }
        // A heartbeat to send: its audience is read from the peer table.
        What::Beacon(_) => a.kernel().prefetch_audience(),
        _ => {}
    }
}

/// The robot whose event it is.
fn robot_of(what: &What) -> RobotId {
    robot_event(what).expect("a robot's event")
}

/// A mind's part of one event of a batch ([`Sim::batch`]).
enum Done {
    /// Handled: what the mind asked, and its timeout after.
    Handled(Vec<AgentOutput>, Option<Time>),
    /// Nothing to do (a stopped robot, a timer not due).
    Nothing,
    /// A heartbeat to send.
    Beacon(Option<Beacon>),
    /// To handle in order, after the others.
    Later,
}

/// Robot `a`'s mind's part of one of its events, at its clock `clock`
/// (what it asked is carried out by [`Sim::finish`]).
fn handle_one(a: &mut Agent, clock: Time, crashed: bool, what: &What) -> Done {
    if crashed {
        return match what {
            What::Beacon(_) => Done::Beacon(None),
            _ => Done::Nothing,
        };
    }
    match what {
        What::Deliver { env, .. } => a.handle(clock, Input::Message(env)),
        What::Inform { from, msg, .. } => a.handle(clock, Input::Inform { from: *from, msg }),
        What::Peer { from, pos, .. } => a.handle(clock, Input::Peer { from: *from, pos }),
        What::Timer(_) => {
            if a.poll_timeout().is_none_or(|t| t > clock) {
                return Done::Nothing;
            }
            a.handle(clock, Input::Timer);
        }
        What::Beacon(_) => return Done::Beacon(beacon_of(a)),
        _ => unreachable!("not a robot's event"),
    }
    let outs = std::iter::from_fn(|| a.poll()).collect();
    Done::Handled(outs, a.poll_timeout())
}

/// The elements at `sorted` (increasing, without repeats), each borrowed
/// mutably on its own.
fn pick_mut<'a, T>(mut rest: &'a mut [T], sorted: &[usize]) -> Vec<&'a mut T> {
    let mut out = Vec::with_capacity(sorted.len());
    let mut base = 0;
    for &i in sorted {
        let tail = std::mem::take(&mut rest).split_at_mut(i - base).1;
        let Some((x, tail)) = tail.split_first_mut() else {
            break;
        };
        out.push(x);
        rest = tail;
        base = i + 1;
    }
    out
}

/// Run a mission: in the timed-skill world, or in the physical world when
/// the scenario has one.
pub fn run(
    mission: Arc<Mission>,
    scenario: &Scenario,
    opts: RunOptions<'_>,
) -> Result<RunReport, Diagnostics> {
    let graph = mission.graph().clone();
    let resolved = scenario.resolve(&graph)?;
    let warnings = resolved.warnings.clone();
    let seed = opts.seed.unwrap_or(scenario.seed);
    let n = graph.roster().len();
    let shared = Shared::new(mission.clone(), scenario)?;
    let agents = (0..n as u32)
        .map(|r| Agent::start(shared.clone(), RobotId(r), seed, 0))
        .collect();
    let watch_poses = opts.watch.as_ref().map(|w| (w.poses_every, Time::ZERO));
    let mut log = RunLog::new(opts.log).with_watch(opts.watch.map(|w| w.on_record));
    log.write(&json!({
        "t": 0.0,
        "event": "run_started",
        "graph": graph.name(),
        "config": graph.config_name(),
        "scenario": scenario.name,
        "seed": seed,
        "robots": n,
        "engine": concat!("bite ", env!("CARGO_PKG_VERSION")),
    }));
    let physics = match &scenario.physics {
        None => None,
        Some(spec) => {
            let names: Vec<String> = (0..n as u32)
                .map(|r| graph.roster().name(RobotId(r)).to_string())
                .collect();
            Some(crate::physics::World::new(
                spec.clone(),
                &names,
                graph.symbols(),
                &scenario.file,
                seed,
            )?)
        }
    };
    let behavior_names: Vec<String> = (0..graph.len())
        .map(|b| graph.name_of(BehaviorId(b as u32)).to_string())
        .collect();
    if let Some(w) = &physics
        && log.is_writing()
    {
        let robots: Vec<String> = (0..n as u32)
            .map(|r| graph.roster().name(RobotId(r)).to_string())
            .collect();
        log.write(&w.layout_record(&robots, &behavior_names));
    }
    let mut sim = Sim {
        agents,
        shared,
        crashed: vec![false; n],
        timers: vec![None; n],
        net: SimNet::new(resolved.network.clone(), derive_seed(seed, "net", 0)),
        queue: Default::default(),
        now: Time::ZERO,
        agg: Aggregator::new(n),
        log,
        log_messages: opts.log_messages,
        record: opts.record,
        history: Vec::new(),
        resolved,
        times: Vec::new(),
        graph: graph.clone(),
        progress: opts.progress,
        detector: scenario.failure_detector,
        suspected: std::collections::BTreeSet::new(),
        seed,
        physics,
        next_poses: Time::ZERO,
        watch_poses,
        beacon_period: scenario.failure_detector.map_or(
            bite_agent::scenario::FailureDetector::default().heartbeat,
            |d| d.heartbeat,
        ),
        beacons: (0, 0),
        checker: crate::check::Checker::new(mission.clone()),
        stall: crate::stall::StallWatch::new(scenario.stall),
        chatter: crate::chatter::ChatterWatch::new(n),
        incarnation: vec![0; n],
        captured: std::collections::VecDeque::new(),
        captured_pos: std::collections::VecDeque::new(),
        inject_rng: bite_core::interaction::Rng::seed_from_u64(derive_seed(seed, "inject", 0)),
        injected: BTreeMap::new(),
        inject: scenario.inject,
        changes: Vec::new(),
        handed: 0,
        outs: Vec::new(),
        window: (Vec::new(), Vec::new()),
        drives: Vec::new(),
        eventful: Vec::new(),
        pool: opts.pool.clone(),
        awake: Awake::default(),
        batch_from: opts.batch_from.unwrap_or(BATCH_FROM),
        batch_most: opts.batch_most.unwrap_or(BATCH_MOST).max(1),
        batched: Batched::default(),
        stepping: None,
        positions: Vec::new(),
        crash_times: Vec::new(),
    };
    sim.crash_times = (sim.resolved.crashes.iter())
        .flat_map(|(_, at, until)| std::iter::once(*at).chain(*until))
        .collect();
    sim.crash_times.sort_unstable();
    sim.stall.waits_at_least(mission.longest_wait());
    for c in opts.changes {
        sim.stall.waits_at_least(c.mission.longest_wait());
        let shared = Shared::new(c.mission.clone(), scenario)?;
        sim.changes.push((c, shared));
    }
    let limit = Time::ZERO + opts.time_limit.unwrap_or(scenario.time_limit);
    let period = Duration::from_secs_f64(1.0 / scenario.control_hz);
    let end = sim.run(limit, period);
    // (Never away here: it steps ahead only to a tick the run reaches.)
    sim.home();

    let mut dropped: BTreeMap<DropReason, u64> = BTreeMap::new();
    for a in &sim.agents {
        for (r, c) in &a.kernel().stats().dropped {
            *dropped.entry(*r).or_insert(0) += c;
        }
    }
    let finals: Vec<FinalRobot> = (sim.agents.iter().map(Agent::kernel))
        .enumerate()
        .map(|(i, k)| FinalRobot {
            robot: RobotId(i as u32),
            crashed: sim.crashed[i],
            finished: k.is_finished(),
            stack: k.stack().to_vec(),
            org_check: k.org().check_invariants(),
            stats: k.stats().clone(),
            version: k.version(),
        })
        .collect();
    // The newest version handed out names every behavior of every version.
    let mission = sim
        .handed
        .checked_sub(1)
        .map_or(mission, |k| sim.changes[k].0.mission.clone());
    let versions: BTreeMap<u32, usize> = (sim.agents.iter().enumerate())
        .filter(|(i, _)| !sim.crashed[*i])
        .fold(BTreeMap::new(), |mut m, (_, a)| {
            *m.entry(a.kernel().version()).or_insert(0) += 1;
            m
        });
    let crashes = sim.resolved.crashes.clone();
    let stalled = sim.stall.stalled().cloned();
    let checker = std::mem::replace(
        &mut sim.checker,
        crate::check::Checker::new(mission.clone()),
    );
    let violations = checker.finish(end, &crashes, &finals);
    let fingerprint = sim.log.fingerprint();
    let mut summary = std::mem::take(&mut sim.agg).finish(
        &mission,
        &scenario.name,
        seed,
        end,
        &sim.crashed,
        sim.net.stats().clone(),
        dropped,
        fingerprint,
    );
    summary.invariants = crate::check::Invariants::of(&violations);
    if !sim.changes.is_empty() {
        summary.versions = Some(crate::summary::Versions {
            handed: sim.handed as u32,
            robots: versions,
        });
    }
    if let Some((_, why)) = stalled
        && !summary.completed
    {
        summary.outcome = crate::summary::Outcome::Stalled;
        summary.stall = Some(why);
    }
    summary.chatter = sim.chatter.found().map(ToString::to_string);
    summary.world = sim.physics.as_ref().map(crate::summary::of_world);
    summary.heartbeats = crate::summary::Heartbeats {
        messages: sim.beacons.0,
        bytes: sim.beacons.1,
    };
    summary.injected = std::mem::take(&mut sim.injected)
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
    summary.sharing = (graph.sharing().policy != bite_core::wm::Policy::None).then(|| {
        bite_core::wm::SharingTotals::of(
            graph.sharing().policy,
            sim.agents
                .iter()
                .filter_map(|a| a.world_model().map(|w| w.stats())),
        )
    });
    sim.log.write(&json!({
        "t": end.as_secs_f64(),
        "event": "run_finished",
        "summary": summary,
    }));
    if let Err(e) = sim.log.finish() {
        return Err(Diagnostics(vec![Diagnostic::error(
            &Arc::from("run log"),
            bite_core::diag::Loc::UNKNOWN,
            "io",
            format!("cannot write the run log: {e}"),
        )]));
    }
    Ok(RunReport {
        summary,
        history: std::mem::take(&mut sim.history),
        finals,
        warnings,
        crashes,
        end,
        world: sim.physics.take(),
        violations,
        batched: sim.batched,
    })
}

#[cfg(test)]
mod tests {
    use super::Awake;
    use std::sync::atomic::Ordering;

    #[test]
    fn a_thread_kept_awake_goes_back_to_the_pool_when_released_or_dropped() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("a thread pool");
        let mut awake = Awake::default();
        awake.keep(Some(&pool));
        let stop = awake.stop.clone().expect("a thread is kept awake");
        assert!(!stop.load(Ordering::Relaxed));
        awake.release();
        assert!(awake.stop.is_none() && stop.load(Ordering::Relaxed));
        // The pool's only thread takes the next job once it has stopped
        // waiting.
        assert_eq!(pool.install(|| 6 * 7), 42);
        // Kept again: keeping anew stops the previous wait first, and a
        // dropped `Awake` stops its own.
        awake.keep(Some(&pool));
        let first = awake.stop.clone().expect("kept");
        awake.keep(Some(&pool));
        assert!(first.load(Ordering::Relaxed), "the earlier wait is stopped");
        let second = awake.stop.clone().expect("kept");
        drop(awake);
        assert!(second.load(Ordering::Relaxed));
        assert_eq!(pool.install(|| 1), 1);
    }
}
