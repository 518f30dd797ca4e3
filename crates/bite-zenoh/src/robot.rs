//! One robot's runtime (`bite robot`): its [`Agent`] (kernel, world model,
//! skills, pilot) driven by the team clock and by what arrives over Zenoh.
//!
//! The agent stays a plain state machine, as in the simulator, driven by
//! one holder at a time of the robot's lock. What Zenoh delivers (frames
//! from teammates, sensor readings, membership queries) is handled at once
//! in Zenoh's callback when the robot is free and nothing is queued before
//! it; otherwise it goes through one bounded queue to the robot's thread,
//! which handles the queue in order. Mission submissions (which compile)
//! always go to the thread. The thread sleeps until the next of: a queued
//! input, the next control tick, the kernel's timer, the next heartbeat,
//! the next status report (a callback that brings a timer nearer wakes it).
//!
//! Failure detection: every robot sends a signed heartbeat every
//! `failure_detector.heartbeat` (team time); a teammate silent for
//! `lost_after` is presumed lost (the kernel re-allocates), and is back
//! when it is heard again. A teammate whose last heartbeat said it had
//! completed the mission is not presumed lost when it goes quiet.

use crate::Keys;
use crate::auth::{AuthStats, FrameKind, Opener, Reject, Scope, Sealer, TeamKey};
use crate::net::{Clock, NetOptions, unix_micros};
use crate::wire::{self, Heartbeat, Membership, MissionBody, Status};
use bite_agent::agent::{Agent, AgentOutput};
use bite_agent::detector::{Detector, Verdict};
use bite_agent::log::Namer;
use bite_agent::scenario::{FailureDetector, Scenario};
use bite_agent::schema::Sensed;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::RobotId;
use bite_core::interaction::Recipients;
use bite_core::mission::Mission;
use bite_core::msg::WireError;
use bite_core::time::Time;
use serde_json::json;
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender};
use std::time::Duration;
use zenoh::Wait;

/// A mission ready to run: the mission (graph with protocols), the
/// scenario (the robot's body and world), and the seed.
pub struct Prepared {
    /// The mission.
    pub mission: Arc<Mission>,
    /// The scenario.
    pub scenario: Scenario,
    /// The seed of the robots' random streams.
    pub seed: u64,
    /// What the mission was made from (recorded with `record`, so that a
    /// replay can make it again; `null`: unknown).
    pub origin: serde_json::Value,
}

/// Turns a submitted mission into a [`Prepared`] one (the CLI compiles
/// graphs and command-language missions against the robot's scenario).
/// With the running mission (a replacement, `MissionBody::replace`), it
/// builds the new version numbered like it.
pub type Loader =
    Box<dyn Fn(&MissionBody, Option<&Arc<Mission>>) -> Result<Prepared, String> + Send>;

/// How a robot runs.
pub struct RobotOptions {
    /// The team (the `bite/<team>/` key prefix).
    pub team: String,
    /// This robot's name in the mission's roster.
    pub name: String,
    /// The team key.
    pub key: TeamKey,
    /// How to join the Zenoh network.
    pub net: NetOptions,
    /// Team seconds per wall second (1 for real robots).
    pub speed: f64,
    /// The team clock's origin for the first mission, microseconds since the
    /// Unix epoch (default: when every teammate has been heard).
    pub start_at_us: Option<u64>,
    /// The run log (JSON lines).
    pub log: Option<PathBuf>,
    /// Exit once the mission is completed (after a short grace period).
    pub exit_when_done: bool,
    /// Give up after this much team time.
    pub time_limit: Option<Duration>,
    /// How long to wait for every teammate to be heard before starting
    /// anyway (wall time).
    pub gather_timeout: Duration,
    /// Wall time between status reports.
    pub status_period: Duration,
    /// Record the mind's every input here (see `bite_agent::record`).
    pub record: Option<PathBuf>,
    /// The body speaks ROS 2 (rmw_zenoh): odometry and range rays from
    /// `/<name>/odom` and `/<name>/scan`, velocity commands to
    /// `/<name>/cmd_vel`, the status on `/<name>/bite/status`
    /// (docs/ros2.md). The camera's sightings, which ROS has no standard
    /// message for, still come on BITE's sensor key when a body sends them.
    pub ros2: Option<crate::ros2::Ros2Options>,
    /// How its authenticated frames are published.
    pub publish: Publish,
}

/// How a robot publishes its authenticated frames (kernel messages,
/// informs, heartbeats) on its `net` key. See docs/performance.md for what
/// each costs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Publish {
    /// `Session::put` per frame.
    Put,
    /// A publisher declared once (Zenoh resolves its routes once); Zenoh
    /// may hold a frame back to batch it with the next ones when the link
    /// is busy (the default).
    #[default]
    Declared,
    /// A publisher declared once, express: every frame leaves at once,
    /// never held back for batching.
    Express,
}

impl Publish {
    /// Its name on the command line (`put`, `declared`, `express`).
    pub fn name(self) -> &'static str {
        match self {
            Publish::Put => "put",
            Publish::Declared => "declared",
            Publish::Express => "express",
        }
    }
}

/// The robot's JSON publications: run-log records, status, velocity
/// commands.
struct Outlets {
    log: zenoh::pubsub::Publisher<'static>,
    status: zenoh::pubsub::Publisher<'static>,
    cmd: zenoh::pubsub::Publisher<'static>,
}

/// Where a robot's frames go.
struct Frames {
    key: String,
    publisher: Option<zenoh::pubsub::Publisher<'static>>,
    /// The team's keys and this robot's name, for frames to one teammate.
    keys: Keys,
    me: String,
    /// How frames are published (a publisher per addressee is declared
    /// the first time it is written to, unless frames are `put`).
    publish: Publish,
    /// Publishers of frames to one teammate, by its name.
    to_one: BTreeMap<String, zenoh::pubsub::Publisher<'static>>,
    /// Frames published.
    sent: u64,
    /// Bursts: calls of `flush_agent` that published at least one frame,
    /// and heartbeats (`sent / bursts` is what batching the frames of one
    /// burst in one publication would save).
    bursts: u64,
}

/// The one teammate a kernel message goes to, if it goes to one (a team
/// multicast goes to the team's key).
fn one_of(to: &Recipients) -> Option<RobotId> {
    match to {
        Recipients::One(r) => Some(*r),
        Recipients::Team(_) => None,
    }
}

/// Publishers kept for frames to one teammate at most (a robot that met
/// more names over its missions starts the table again).
const TO_ONE_KEPT: usize = 1024;

impl Frames {
    /// Publish `frame` to the team.
    fn send(&mut self, session: &zenoh::Session, frame: Vec<u8>) {
        self.sent += 1;
        // A frame that cannot be sent is lost, as on a lossy network: the
        // protocols' timeouts and retries cover it.
        let _ = match &self.publisher {
            Some(p) => p.put(frame).wait(),
            None => session.put(&self.key, frame).wait(),
        };
    }

    /// Publish `frame`: on the addressee's own key when it is for one
    /// teammate on the roster `names` (the other robots' processes then
    /// neither receive it nor wake for it), else on the team's.
    fn send_to(
        &mut self,
        session: &zenoh::Session,
        names: &[String],
        one: Option<RobotId>,
        frame: Vec<u8>,
    ) {
        let Some(to) = one.and_then(|r| names.get(r.index())) else {
            return self.send(session, frame);
        };
        self.sent += 1;
        if let Some(p) = self.to_one.get(to) {
            let _ = p.put(frame).wait();
            return;
        }
        let key = self.keys.net_to(&self.me, to);
        let declared = (self.publish != Publish::Put)
            .then(|| {
                session
                    .declare_publisher(key.clone())
                    .express(self.publish == Publish::Express)
                    .wait()
                    .ok()
            })
            .flatten();
        let _ = match declared {
            Some(p) => {
                let sent = p.put(frame).wait();
                if self.to_one.len() >= TO_ONE_KEPT {
                    self.to_one.clear();
                }
                self.to_one.insert(to.clone(), p);
                sent
            }
            None => session.put(&key, frame).wait(),
        };
    }
}

/// How a robot's run ended.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// It completed its last mission.
    pub completed: bool,
    /// Frames accepted and dropped.
    pub auth: AuthStats,
    /// Inputs dropped because the queue was full.
    pub overflow: u64,
}

/// Why a robot could not run.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// Bad options.
    #[error("{0}")]
    Options(String),
    /// Zenoh.
    #[error(transparent)]
    Net(#[from] crate::net::ConfigError),
    /// Zenoh refused a declaration.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// The run log.
    #[error("run log {0}: {1}")]
    Log(PathBuf, std::io::Error),
}

enum Input {
    /// A frame, and when it arrived (wall µs).
    Frame {
        from: String,
        bytes: Vec<u8>,
        at_us: u64,
    },
    Sensors(Vec<u8>),
    /// A ROS 2 sample on `odom` or `scan` (`ok`: it carried rmw_zenoh's
    /// attachment).
    Ros2 {
        odom: bool,
        bytes: Vec<u8>,
        ok: bool,
    },
    Mission(Vec<u8>),
    /// An input larger than its kind may be, dropped uncopied: only
    /// counted (and logged, the first ones).
    Oversize {
        what: Big,
        len: usize,
    },
    Query(zenoh::query::Query),
    /// Nothing: the robot's thread is to look at its timers again.
    Wake,
}

/// What an oversized input was.
enum Big {
    /// A frame, on the key of this sender.
    Frame(String),
    Sensors,
    Mission,
    Ros2,
}

/// Queue size between Zenoh's callbacks and the robot's thread.
const QUEUE: usize = 4096;
/// Rejected frames logged one by one, per reason (all are counted).
const LOG_REJECTS: u64 = 100;
/// Largest sensor reading or mission submission taken (bytes).
const MAX_JSON: usize = wire::MAX_SUBMISSION_BYTES;
/// Largest magnitude of a length or coordinate taken in a sensor reading
/// (m): no robot measures a billion metres, and past it the squares of
/// distances the fusion computes lose the precision it needs. A reading
/// with a larger one, or with a number that is not finite (NaN, ±inf), is
/// dropped and counted (`sensors-malformed`).
const MAX_READING_M: f64 = 1e9;
/// Inputs handled before the timers get a turn.
const BATCH: usize = 256;
/// Range readings and object sightings taken per reading.
const MAX_READINGS: usize = 1024;
/// How far a submission's `issued_at` may be from the robot's clock.
const SUBMISSION_FRESH_MS: u64 = 5 * 60 * 1000;

/// One running mission.
struct Running {
    agent: Agent,
    graph: Arc<BehaviorGraph>,
    me: RobotId,
    names: Vec<String>,
    index: BTreeMap<String, u32>,
    sealer: Sealer,
    opener: Opener,
    clock: Clock,
    /// The clock's origin was given (shared by the team).
    shared_origin: bool,
    /// Waiting for teammates until this wall time (`None`: started).
    gather_until: Option<u64>,
    /// Who is alive: wall time of arrival each teammate was last heard,
    /// who said it completed, who is presumed lost.
    alive: Detector,
    detector: FailureDetector,
    period: Duration,
    next_control: Time,
    next_heartbeat: u64,
    last_sensed: Option<Sensed>,
    mission_id: Option<String>,
    finished_at: Option<u64>,
    payload_rejects: BTreeMap<&'static str, u64>,
    /// Teammates whose last authenticated frame had another payload
    /// version, by name (a teammate whose frames read again leaves it).
    other_versions: BTreeMap<String, u8>,
    /// Teammates and versions said in the log and on standard error (each
    /// once a run).
    versions_told: BTreeSet<(String, u8)>,
    /// Said that the kernel's timer spins (see `Node::timer_spinning`).
    spin_said: bool,
    /// Kernel messages that arrived before the first control tick.
    early: Vec<bite_core::msg::Envelope>,
    /// Presume silent teammates lost (the scenario's failure detector).
    detects: bool,
    /// The first control tick has run.
    ticked: bool,
    /// The scenario it runs in (new versions of the mission run in it too).
    scenario: Scenario,
}

/// Run a robot until it is stopped (`stop`), its time limit passes, or
/// (with `exit_when_done`) it completes its mission, on a Zenoh session of
/// its own (`opts.net`).
pub fn run(
    opts: RobotOptions,
    first: Option<Prepared>,
    loader: Loader,
    stop: Arc<AtomicBool>,
) -> Result<Outcome, RobotError> {
    crate::check_team(&opts.team, &[&opts.name], opts.speed).map_err(RobotError::Options)?;
    let session = opts.net.open()?;
    let out = run_on(&session, opts, first, loader, stop);
    let _ = session.close().wait();
    out
}

/// [`run`] on a session the caller opened and closes, which several robots
/// of one process may share (`bite robot --name r0 --name r1`): each robot
/// keeps its own keys, subscriptions, status and log, and hears its
/// housemates' frames through the session, as it hears the others' over the
/// network. `opts.net` is not used.
pub fn run_on(
    session: &zenoh::Session,
    opts: RobotOptions,
    first: Option<Prepared>,
    loader: Loader,
    stop: Arc<AtomicBool>,
) -> Result<Outcome, RobotError> {
    crate::check_team(&opts.team, &[&opts.name], opts.speed).map_err(RobotError::Options)?;
    let opts = Arc::new(opts);
    let keys = Keys::new(&opts.team);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Input>(QUEUE);
    let z = |e: zenoh::Error| RobotError::Zenoh(e.to_string());
    // The body in ROS 2 terms: its odometry and scans are subscribed to
    // below; the command and status publishers are announced here.
    let mut ros = None;
    let mut ros_keys = Vec::new();
    if let Some(r) = &opts.ros2 {
        use crate::ros2;
        let ns = format!("/{}", opts.name);
        let mut node =
            ros2::RosNode::declare(session, r.domain, &ns, &format!("{}_bite", opts.name))
                .map_err(z)?;
        for (odom, name, ty) in [
            (true, "odom", &ros2::ODOMETRY),
            (false, "scan", &ros2::LASER_SCAN),
        ] {
            let key = node
                .subscription(session, &ros2::topic(&ns, name), ty)
                .map_err(z)?;
            ros_keys.push((odom, key));
        }
        let cmd = node
            .publisher(session, &ros2::topic(&ns, "cmd_vel"), &ros2::TWIST)
            .map_err(z)?;
        let status = node
            .publisher(session, &ros2::topic(&ns, "bite/status"), &ros2::STRING)
            .map_err(z)?;
        ros = Some(RosBody {
            _node: node,
            cmd,
            status,
            scan: Vec::new(),
            camera: None,
            last_pos: None,
            odometer: 0.0,
        });
    }
    let net_key = keys.net(&opts.name);
    let publisher = match opts.publish {
        Publish::Put => None,
        Publish::Declared | Publish::Express => Some(
            session
                .declare_publisher(net_key.clone())
                .express(opts.publish == Publish::Express)
                .wait()
                .map_err(z)?,
        ),
    };
    let frames = Frames {
        key: net_key,
        publisher,
        keys: keys.clone(),
        me: opts.name.clone(),
        publish: opts.publish,
        to_one: BTreeMap::new(),
        sent: 0,
        bursts: 0,
    };
    // Declared once: Zenoh resolves their routes once, not at every put.
    let declare = |key: String| session.declare_publisher(key).wait().map_err(z);
    let outlets = Outlets {
        log: declare(keys.log(&opts.name))?,
        status: declare(keys.status(&opts.name))?,
        cmd: declare(keys.cmd(&opts.name))?,
    };
    let log = (opts.log.as_deref().map(crate::create_log))
        .transpose()
        .map_err(|e| RobotError::Log(opts.log.clone().unwrap_or_default(), e))?
        .map(|w| Box::new(w) as Box<dyn Write + Send>);
    let shared = Arc::new(Shared {
        node: Mutex::new(Node {
            keys: keys.clone(),
            frames,
            outlets,
            session: session.clone(),
            opts: opts.clone(),
            run: None,
            seen_missions: BTreeSet::new(),
            missions_rejected: 0,
            last_rejection: None,
            log,
            log_error: None,
            next_status: 0,
            last_auth: AuthStats::default(),
            ros,
            handled: Handled::default(),
        }),
        pending: AtomicUsize::new(0),
        sleeps_until: AtomicU64::new(0),
        closed: AtomicBool::new(false),
        overflow: AtomicU64::new(0),
    });
    let mut subscribers = Vec::new();
    // Frames to the whole team, and frames to this robot alone.
    for key in [keys.all("net"), keys.net_for(&opts.name)] {
        let (shared, tx) = (shared.clone(), tx.clone());
        let me = opts.name.clone();
        let frames = session
            .declare_subscriber(key)
            .callback(move |s| {
                // The robot's own frames (Zenoh hands a session its own
                // publications) are dropped before anything else is done;
                // oversized ones are counted, not copied.
                let from = Keys::sender_of(s.key_expr().as_str());
                if from == me {
                    return;
                }
                let len = s.payload().len();
                if len > crate::auth::HEADER + crate::auth::MAX_PAYLOAD + crate::auth::MAC {
                    let what = Big::Frame(from.to_string());
                    return shared.deliver(&tx, Input::Oversize { what, len });
                }
                shared.deliver(
                    &tx,
                    Input::Frame {
                        from: from.to_string(),
                        bytes: s.payload().to_bytes().into_owned(),
                        at_us: unix_micros(),
                    },
                )
            })
            .wait()
            .map_err(z)?;
        subscribers.push(frames);
    }
    // Sensor readings and mission submissions: JSON, bounded.
    let json_input = |key: String, input: fn(Vec<u8>) -> Input, big: fn() -> Big| {
        let (shared, tx) = (shared.clone(), tx.clone());
        session
            .declare_subscriber(key)
            .callback(move |s| {
                let len = s.payload().len();
                if len <= MAX_JSON {
                    shared.deliver(&tx, input(s.payload().to_bytes().into_owned()))
                } else {
                    shared.deliver(&tx, Input::Oversize { what: big(), len })
                }
            })
            .wait()
            .map_err(z)
    };
    subscribers.push(json_input(
        keys.sensors(&opts.name),
        Input::Sensors,
        || Big::Sensors,
    )?);
    subscribers.push(json_input(keys.mission(), Input::Mission, || Big::Mission)?);
    for (odom, key) in ros_keys {
        let (shared, tx) = (shared.clone(), tx.clone());
        let sub = session
            .declare_subscriber(key)
            .callback(move |s| {
                let len = s.payload().len();
                if len > MAX_JSON {
                    let what = Big::Ros2;
                    shared.deliver(&tx, Input::Oversize { what, len })
                } else {
                    let ok = s
                        .attachment()
                        .is_some_and(|a| crate::ros2::parse_attachment(&a.to_bytes()).is_ok());
                    shared.deliver(
                        &tx,
                        Input::Ros2 {
                            odom,
                            bytes: s.payload().to_bytes().into_owned(),
                            ok,
                        },
                    )
                }
            })
            .wait()
            .map_err(z)?;
        subscribers.push(sub);
    }
    let members = {
        let (shared, tx) = (shared.clone(), tx.clone());
        session
            .declare_queryable(keys.members(&opts.name))
            .callback(move |q| shared.deliver(&tx, Input::Query(q)))
            .wait()
            .map_err(z)?
    };
    drop(tx);
    if let Some(p) = first {
        shared.lock().start(p, None, opts.start_at_us)?;
    }
    let completed = shared.main_loop(&rx, &loader, &stop);
    // No callback touches the robot from here on.
    shared.closed.store(true, Ordering::Release);
    for s in subscribers {
        let _ = s.undeclare().wait();
    }
    let _ = members.undeclare().wait();
    let overflow = shared.overflow.load(Ordering::Relaxed);
    let mut node = shared.lock();
    node.finish(overflow);
    let auth = node
        .run
        .as_ref()
        .map_or_else(|| node.last_auth.clone(), |r| r.opener.stats().clone());
    if let Some(e) = node.log_error.take() {
        return Err(RobotError::Log(opts.log.clone().unwrap_or_default(), e));
    }
    // The agent (and its recorder) ends here, as before, and the log is
    // flushed whatever a late callback still holds.
    node.run = None;
    if let Some(w) = node.log.as_mut()
        && let Err(e) = w.flush()
    {
        return Err(RobotError::Log(opts.log.clone().unwrap_or_default(), e));
    }
    Ok(Outcome {
        completed,
        auth,
        overflow,
    })
}

/// What Zenoh's callbacks and the robot's thread share: the robot, behind a
/// lock, and the count of inputs queued for the thread.
///
/// An input is handled at once in the callback that brought it when the
/// robot is free and nothing is queued before it (no wake-up of the
/// robot's thread, which was most of a hop's time with ten processes on
/// two cores: docs/performance.md); otherwise it is queued, and the
/// thread handles the queue in order. So inputs are handled one at a
/// time, in the order they arrived, and the agent stays a plain state
/// machine driven by whoever holds the lock.
struct Shared {
    node: Mutex<Node>,
    /// Inputs queued and not yet handled.
    pending: AtomicUsize,
    /// The wall time (µs) the robot's thread sleeps until.
    sleeps_until: AtomicU64,
    /// The robot stopped: inputs are dropped.
    closed: AtomicBool,
    /// Inputs dropped because the queue was full.
    overflow: AtomicU64,
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, Node> {
        // A panic while handling an input (a bug) ends the robot, as it
        // did when one thread owned it.
        self.node
            .lock()
            .unwrap_or_else(|_| panic!("the robot panicked while handling an input"))
    }

    /// An input from a callback: handled now if the robot is free and
    /// nothing waits before it, else queued. A robot whose handling
    /// publishes a frame that a housemate's callback answers at once finds
    /// itself busy there (the same thread holds its lock), and queues.
    fn deliver(&self, tx: &SyncSender<Input>, i: Input) {
        if self.closed.load(Ordering::Acquire) {
            return;
        }
        if matches!(i, Input::Mission(_)) {
            // A submission may take a while to compile: always the robot's
            // thread's work, never a Zenoh callback's.
            return self.enqueue(tx, i);
        }
        let guard = match self.pending.load(Ordering::Acquire) {
            0 => self.node.try_lock().ok(),
            _ => None,
        };
        let Some(mut node) = guard.filter(|_| self.pending.load(Ordering::Acquire) == 0) else {
            return self.enqueue(tx, i);
        };
        node.handled.inline += 1;
        node.handle(i);
        let wake = node.periodic();
        // The thread sleeps on: wake it if a timer now comes sooner, or
        // if the robot has completed and may leave.
        let leaving = node.opts.exit_when_done && node.finished();
        drop(node);
        if wake < self.sleeps_until.load(Ordering::Acquire) || leaving {
            self.enqueue(tx, Input::Wake);
        }
    }

    /// Queue an input for the robot's thread (dropped and counted if the
    /// queue is full).
    fn enqueue(&self, tx: &SyncSender<Input>, i: Input) {
        if self.closed.load(Ordering::Acquire) {
            return;
        }
        self.pending.fetch_add(1, Ordering::AcqRel);
        if tx.try_send(i).is_err() {
            self.pending.fetch_sub(1, Ordering::AcqRel);
            self.overflow.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The robot's thread: timers, and the inputs that were queued.
    fn main_loop(&self, rx: &Receiver<Input>, loader: &Loader, stop: &AtomicBool) -> bool {
        loop {
            let mut node = self.lock();
            if stop.load(Ordering::Relaxed) {
                node.log_record(json!({"event": "stopped", "reason": "signal"}));
                return node.completed();
            }
            let wake = node.periodic();
            if let Some(done) = node.should_end() {
                return done;
            }
            let wait = Duration::from_micros(wake.saturating_sub(unix_micros()))
                .min(Duration::from_millis(100));
            self.sleeps_until
                .store(unix_micros() + wait.as_micros() as u64, Ordering::Release);
            drop(node);
            match rx.recv_timeout(wait) {
                Ok(i) => {
                    let mut node = self.lock();
                    node.input(i, loader);
                    self.pending.fetch_sub(1, Ordering::AcqRel);
                    // Take what else is queued (bounded) before the timers.
                    for _ in 0..BATCH {
                        match rx.try_recv() {
                            Ok(i) => {
                                node.input(i, loader);
                                self.pending.fetch_sub(1, Ordering::AcqRel);
                            }
                            Err(_) => break,
                        }
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return self.lock().completed(),
            }
        }
    }
}

/// Inputs handled in Zenoh's callbacks and by the robot's thread (in the
/// run log's `run_finished`).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
struct Handled {
    inline: u64,
    queued: u64,
}

/// The robot: its running mission and everything it publishes.
struct Node {
    keys: Keys,
    frames: Frames,
    outlets: Outlets,
    session: zenoh::Session,
    opts: Arc<RobotOptions>,
    run: Option<Running>,
    seen_missions: BTreeSet<String>,
    missions_rejected: u64,
    last_rejection: Option<wire::Rejection>,
    log: Option<Box<dyn Write + Send>>,
    log_error: Option<std::io::Error>,
    next_status: u64,
    last_auth: AuthStats,
    /// The body over ROS 2, if it speaks it.
    ros: Option<RosBody>,
    handled: Handled,
}

/// A body that speaks ROS 2: the latest scan and camera sightings, the
/// distance travelled (from odometry), the publishers.
struct RosBody {
    _node: crate::ros2::RosNode,
    cmd: crate::ros2::RosPublisher,
    status: crate::ros2::RosPublisher,
    scan: Vec<(f64, f64)>,
    camera: Option<Sensed>,
    last_pos: Option<(f64, f64)>,
    odometer: f64,
}

impl Node {
    /// Whether the robot's run is over (`Some(completed)`): its time limit
    /// passed, or it completed and no teammate may still need its answers
    /// (every teammate completed or is presumed lost, after a grace
    /// period; at most twice `lost_after`).
    fn should_end(&mut self) -> Option<bool> {
        let r = self.run.as_ref()?;
        let now = r.clock.now();
        if let Some(limit) = self.opts.time_limit
            && r.gather_until.is_none()
            && now >= Time::ZERO + limit
            && r.finished_at.is_none()
        {
            self.log_record(json!({"event": "stopped", "reason": "time limit"}));
            return Some(false);
        }
        if self.opts.exit_when_done
            && let Some(at) = r.finished_at
        {
            let others_done = (0..r.names.len() as u32)
                .all(|i| i == r.me.0 || r.alive.is_finished(i) || r.alive.is_suspected(i));
            let now_us = unix_micros();
            if (others_done && now_us >= at.saturating_add(grace_us(r)))
                || now_us >= at.saturating_add(linger_us(r))
            {
                return Some(true);
            }
        }
        None
    }

    /// It completed its mission (and waits to leave).
    fn finished(&self) -> bool {
        self.run.as_ref().is_some_and(|r| r.finished_at.is_some())
    }

    fn completed(&self) -> bool {
        self.run
            .as_ref()
            .is_some_and(|r| r.agent.kernel().is_finished())
    }

    /// Start a mission.
    fn start(
        &mut self,
        p: Prepared,
        id: Option<String>,
        start_at: Option<u64>,
    ) -> Result<(), RobotError> {
        let graph = p.mission.graph().clone();
        let Some(me) = graph.roster().find(&self.opts.name) else {
            return Err(RobotError::Options(format!(
                "robot `{}` is not on the roster of mission `{}` ({})",
                self.opts.name,
                graph.name(),
                (graph.roster().iter().map(|(_, r)| r.name.clone()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        };
        let mut agent = Agent::new(p.mission.clone(), &p.scenario, me, p.seed).map_err(|d| {
            RobotError::Options(
                d.0.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join("\n"),
            )
        })?;
        if let Some(path) = &self.opts.record {
            let f = std::fs::File::create(path).map_err(|e| RobotError::Log(path.clone(), e))?;
            agent.record(bite_agent::record::Recorder::new(
                Box::new(std::io::BufWriter::new(f)),
                &json!({"robot": self.opts.name, "seed": p.seed, "origin": p.origin}),
            ));
        }
        let names: Vec<String> = (0..graph.roster().len() as u32)
            .map(|r| graph.roster().name(RobotId(r)))
            .collect();
        let index = names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.clone(), i as u32))
            .collect();
        let n = names.len() as u32;
        let now_us = unix_micros();
        // Without a failure detector (`enabled: false`) heartbeats still
        // serve gathering, but nobody is ever presumed lost.
        let detects = p.scenario.failure_detector.is_some();
        let detector = p.scenario.failure_detector.unwrap_or_default();
        let tag = mission_tag(id.as_deref(), &graph, start_at);
        let scope = Scope::new(&self.opts.team, tag);
        let origin = start_at.unwrap_or(now_us);
        let clock = Clock {
            origin_us: origin,
            speed: self.opts.speed,
        };
        let gather = now_us.max(origin) + self.opts.gather_timeout.as_micros() as u64;
        // The first mission's counts start with the frames dropped while
        // the robot waited for it (`before-mission`, `oversize`).
        let opener = Opener::new(self.opts.key.clone(), scope.clone(), me.0, n);
        let opener = match &self.run {
            Some(old) => {
                self.last_auth = old.opener.stats().clone();
                opener
            }
            None => opener.with_stats(self.last_auth.clone()),
        };
        self.log_record(json!({
            "t": 0.0,
            "event": "run_started",
            "graph": graph.name(),
            "config": graph.config_name(),
            "scenario": p.scenario.name,
            "seed": p.seed,
            "robots": n,
            "robot": self.opts.name,
            "engine": concat!("bite ", env!("CARGO_PKG_VERSION")),
            "transport": "zenoh",
            "team": self.opts.team,
            "mission_id": id,
            "speed": self.opts.speed,
        }));
        self.run = Some(Running {
            agent,
            graph,
            me,
            index,
            sealer: Sealer::new(self.opts.key.clone(), scope.clone(), me.0),
            opener,
            detects,
            ticked: false,
            clock,
            shared_origin: start_at.is_some(),
            gather_until: Some(gather),
            alive: Detector::new(
                n as usize,
                me.0,
                clock.wall(detector.lost_after).as_micros() as u64,
            ),
            detector,
            period: Duration::from_secs_f64(1.0 / p.scenario.control_hz),
            next_control: Time::ZERO,
            next_heartbeat: 0,
            last_sensed: None,
            mission_id: id,
            finished_at: None,
            payload_rejects: BTreeMap::new(),
            other_versions: BTreeMap::new(),
            versions_told: BTreeSet::new(),
            spin_said: false,
            early: Vec::new(),
            names,
            scenario: p.scenario,
        });
        Ok(())
    }

    /// Timers: heartbeats, gathering, failure detection, control ticks,
    /// kernel timers, status. Returns the wall time to wake up next.
    fn periodic(&mut self) -> u64 {
        let now_us = unix_micros();
        let mut wake = now_us + 100_000;
        if now_us >= self.next_status {
            self.next_status = now_us + self.opts.status_period.as_micros() as u64;
            self.publish_status();
            // A killed process loses at most one status period of its log.
            if let Some(w) = self.log.as_mut()
                && let Err(e) = w.flush()
                && self.log_error.is_none()
            {
                self.log_error = Some(e);
            }
        }
        wake = wake.min(self.next_status);
        let Some(r) = self.run.as_mut() else {
            return wake;
        };
        let hb_us = r.clock.wall(r.detector.heartbeat).as_micros() as u64;
        if now_us >= r.next_heartbeat {
            r.next_heartbeat = now_us + hb_us.max(1000);
            let kernel = r.agent.kernel();
            let hb = Heartbeat {
                finished: kernel.is_finished(),
                // Only the team view is new per heartbeat; it is what lets
                // teammates find and heal a split (`Kernel::peer`).
                position: if r.ticked {
                    kernel.beacon().map(|(_, pos)| pos)
                } else {
                    None
                },
            };
            let frame = r
                .sealer
                .seal(FrameKind::Heartbeat, &wire::encode_heartbeat(&hb), now_us);
            self.frames.send(&self.session, frame);
            self.frames.bursts += 1;
        }
        wake = wake.min(r.next_heartbeat);
        if let Some(until) = r.gather_until {
            let everyone = r.alive.everyone_heard();
            if !((everyone && now_us >= r.clock.origin_us) || now_us >= until) {
                return wake.min(until).min(now_us + 10_000);
            }
            r.gather_until = None;
            // A shared origin (given by whoever launched the team) is kept
            // when everyone is here; otherwise the clock starts now.
            if !r.shared_origin {
                r.clock.origin_us = now_us;
            }
            let missing: Vec<String> = (r.alive.never_heard())
                .map(|i| r.names[i as usize].clone())
                .collect();
            // Silence is counted from the start.
            r.alive.start(r.clock.origin_us);
            let rec = json!({"t": 0.0, "event": "gathered", "missing": missing});
            self.log_record(rec);
        }
        let Some(r) = self.run.as_mut() else {
            return wake;
        };
        let now = r.clock.now();
        // Failure detector.
        let mut lost = Vec::new();
        if r.detects
            && let Some(next) = r.alive.poll(now_us, &mut lost)
        {
            wake = wake.min(next);
        }
        for v in lost {
            let Verdict::Lost(i) = v else { continue };
            if let Some(r) = self.run.as_mut() {
                // The kernel logs it (`member_lost`).
                r.agent.member_lost(now, RobotId(i));
            }
            self.flush_agent();
        }
        let Some(r) = self.run.as_mut() else {
            return wake;
        };
        // Control ticks: in the physical world at each sensor reading
        // (see `input`); in the timed world on the team clock.
        if !r.agent.has_body() && now >= r.next_control {
            r.next_control = now + r.period;
            r.agent.tick(now, None);
            Self::after_first_tick(r, now);
            self.flush_agent();
        }
        let Some(r) = self.run.as_mut() else {
            return wake;
        };
        if !r.agent.has_body() {
            wake = wake.min(r.clock.wall_at(r.next_control));
        }
        if let Some(t) = r.agent.poll_timeout() {
            if t > now {
                wake = wake.min(r.clock.wall_at(t));
            } else {
                r.agent.timer(now);
                let (spinning, period) = (r.agent.timer_spinning(), r.period);
                self.flush_agent();
                if !spinning {
                    return now_us;
                }
                // A kernel whose timer stays due however often it is
                // woken would have this loop spin a core: said once, and
                // woken once a control period while it lasts (messages
                // and heartbeats still wake it).
                self.timer_spinning(now);
                wake = wake.min(now_us + period.as_micros() as u64);
            }
        }
        self.check_finished();
        wake
    }

    /// Messages kept until the kernel had its first tick (as in the
    /// simulator, every robot ticks before it hears anything).
    fn after_first_tick(r: &mut Running, now: Time) {
        if !r.ticked {
            r.ticked = true;
            for env in std::mem::take(&mut r.early) {
                r.agent.message(now, env);
            }
        }
    }

    fn check_finished(&mut self) {
        let Some(r) = self.run.as_mut() else { return };
        if r.finished_at.is_none() && r.agent.kernel().is_finished() {
            r.finished_at = Some(unix_micros());
            let rec = json!({
                "t": r.clock.now().as_secs_f64(),
                "robot": self.opts.name,
                "event": "run_finished",
                "completed": true,
                "auth": r.opener.stats(),
                "payload_rejects": r.payload_rejects,
                "messages": r.agent.kernel().stats().sent,
                "frames": {"sent": self.frames.sent, "bursts": self.frames.bursts},
                "inputs": self.handled,
            });
            self.log_record(rec);
            self.publish_status();
        }
    }

    /// A queued input (the robot's thread).
    fn input(&mut self, i: Input, loader: &Loader) {
        match i {
            Input::Wake => {}
            Input::Mission(bytes) => {
                self.handled.queued += 1;
                self.submission(&bytes, loader)
            }
            i => {
                self.handled.queued += 1;
                self.handle(i)
            }
        }
    }

    /// Any input but a submission (which needs the loader: the robot's
    /// thread only).
    fn handle(&mut self, i: Input) {
        match i {
            Input::Wake => {}
            Input::Mission(_) => debug_assert!(false, "submissions are the robot's thread's"),
            Input::Frame { from, bytes, at_us } => self.frame(&from, &bytes, at_us),
            Input::Oversize { what, len } => self.oversize(what, len),
            Input::Sensors(bytes) => {
                let Some(r) = self.run.as_mut() else { return };
                match serde_json::from_slice::<Sensed>(&bytes) {
                    Ok(mut s) => {
                        // Only sightings that can be: teammates on the roster
                        // other than itself; bounded lists.
                        let (n, me) = (r.names.len() as u32, r.me.0);
                        s.mates.retain(|(j, _)| *j < n && *j != me);
                        s.rays.truncate(MAX_READINGS);
                        s.objects.truncate(MAX_READINGS);
                        if !readings_hold(&s) {
                            *r.payload_rejects.entry("sensors-malformed").or_insert(0) += 1;
                            return;
                        }
                        // A ROS 2 body: these are the camera's sightings;
                        // odometry drives the control ticks.
                        if let Some(ros) = self.ros.as_mut() {
                            ros.camera = Some(s);
                            return;
                        }
                        r.last_sensed = Some(s)
                    }
                    Err(_) => {
                        *r.payload_rejects.entry("sensors-malformed").or_insert(0) += 1;
                        return;
                    }
                }
                self.control_tick();
            }
            Input::Ros2 { odom, bytes, ok } => self.ros2_sample(odom, &bytes, ok),
            Input::Query(q) => {
                let m = self.membership();
                let body = serde_json::to_vec(&m).unwrap_or_default();
                let _ = q.reply(self.keys.members(&self.opts.name), body).wait();
            }
        }
    }

    /// A ROS 2 odometry or scan sample: a scan is kept for the next tick;
    /// odometry is the body's pose estimate, and makes the readings of a
    /// control tick with the latest scan and camera sightings.
    fn ros2_sample(&mut self, odom: bool, bytes: &[u8], ok: bool) {
        use crate::ros2;
        let (Some(r), Some(ros)) = (self.run.as_mut(), self.ros.as_mut()) else {
            return;
        };
        if !ok {
            *r.payload_rejects.entry("ros2-no-attachment").or_insert(0) += 1;
            return;
        }
        if !odom {
            match ros2::decode::<ros2::LaserScan>(&ros2::LASER_SCAN, bytes) {
                Ok(scan) => {
                    // A dense lidar: every n-th hit, round the whole circle.
                    let hits = ros2::hits_of(&scan);
                    let every = hits.len().div_ceil(MAX_READINGS).max(1);
                    ros.scan = hits.into_iter().step_by(every).collect();
                }
                Err(_) => *r.payload_rejects.entry("ros2-scan-malformed").or_insert(0) += 1,
            }
            return;
        }
        let o = match ros2::decode::<ros2::Odometry>(&ros2::ODOMETRY, bytes) {
            Ok(o) => o,
            Err(_) => {
                *r.payload_rejects.entry("ros2-odom-malformed").or_insert(0) += 1;
                return;
            }
        };
        let p = o.pose.pose.position;
        let heading = o.pose.pose.orientation.to_yaw();
        if !(p.x.is_finite() && p.y.is_finite() && heading.is_finite()) {
            *r.payload_rejects.entry("ros2-odom-malformed").or_insert(0) += 1;
            return;
        }
        let odometer = match ros.last_pos {
            Some((x, y)) => ros.odometer + ((p.x - x).powi(2) + (p.y - y).powi(2)).sqrt(),
            None => ros.odometer,
        };
        let camera = ros.camera.clone();
        let sensed = Sensed {
            t: o.header.stamp.as_secs(),
            pose: bite_agent::schema::Pose {
                pos: glam::DVec2::new(p.x, p.y),
                heading,
            },
            rays: ros.scan.clone(),
            mates: camera.as_ref().map(|c| c.mates.clone()).unwrap_or_default(),
            objects: camera
                .as_ref()
                .map(|c| c.objects.clone())
                .unwrap_or_default(),
            odometer,
            contact: camera.is_some_and(|c| c.contact),
        };
        // The same bounds as the simulator's readings (`readings_hold`):
        // the ROS 2 topics are no more authenticated than `sim/**`.
        if !readings_hold(&sensed) {
            *r.payload_rejects.entry("ros2-odom-malformed").or_insert(0) += 1;
            return;
        }
        ros.odometer = odometer;
        ros.last_pos = Some((p.x, p.y));
        ros.camera = None;
        r.last_sensed = Some(sensed);
        self.control_tick();
    }

    /// The readings in `last_sensed` are in: run a control tick if one is
    /// due.
    fn control_tick(&mut self) {
        {
            {
                let Some(r) = self.run.as_mut() else { return };
                if r.gather_until.is_some() || !r.agent.has_body() {
                    return;
                }
                let now = r.clock.now();
                // One tick per control period, whatever the server's rate.
                if now + r.period / 2 < r.next_control {
                    return;
                }
                r.next_control = now + r.period;
                let mut s = r.last_sensed.take();
                if let Some(s) = s.as_mut() {
                    // Readings are dated on arrival, on the team clock.
                    s.t = now.as_secs_f64();
                }
                r.agent.tick(now, s.as_ref());
                Self::after_first_tick(r, now);
                r.last_sensed = s;
                self.flush_agent();
                self.check_finished();
            }
        }
    }

    fn frame(&mut self, from: &str, bytes: &[u8], at_us: u64) {
        // Zenoh hands a session its own publications too.
        if from == self.opts.name {
            return;
        }
        let Some(r) = self.run.as_mut() else {
            // No mission yet: no tag to check the frame's MAC against.
            return self.count_reject(from, Reject::BeforeMission);
        };
        // A key no member publishes on matches no sender.
        let claimed = r.index.get(from).copied().unwrap_or(u32::MAX);
        let result = r
            .opener
            .open(bytes, Some(claimed), at_us)
            .map(|f| (f.kind, f.sender, f.payload.to_vec()));
        let (kind, sender, payload) = match result {
            Ok(x) => x,
            Err(Reject::Own) => return,
            Err(reason) => {
                let count = r.opener.stats().rejected.get(&reason).copied().unwrap_or(0);
                return self.log_reject(from, reason, count);
            }
        };
        let now = r.clock.now();
        // Heard when it arrived, not when this thread got to it.
        if let Some(Verdict::Back(_)) = r.alive.heard(sender, at_us) {
            r.agent.member_back(now, RobotId(sender));
            self.flush_agent();
        }
        let Some(r) = self.run.as_mut() else { return };
        match kind {
            FrameKind::Heartbeat => match wire::decode_heartbeat(&payload) {
                Ok(h) => {
                    Self::version_ok(r, sender);
                    r.alive.finished(sender, h.finished);
                    if let Some(pos) = h.position
                        && r.ticked
                        && r.gather_until.is_none()
                    {
                        r.agent.peer(now, RobotId(sender), &pos);
                        self.flush_agent();
                    }
                }
                Err(e) => self.payload_rejected(sender, "heartbeat-malformed", &e),
            },
            FrameKind::Kernel => match wire::decode_kernel(&payload) {
                Ok((to, env)) => {
                    Self::version_ok(r, sender);
                    if env.sender.0 != sender {
                        *r.payload_rejects.entry("sender-mismatch").or_insert(0) += 1;
                    } else if to.includes(r.me) {
                        if !r.ticked {
                            // A teammate that started first: kept for the
                            // start (bounded, as the input queue is).
                            if r.early.len() < QUEUE {
                                r.early.push(env);
                            }
                        } else {
                            r.agent.message(now, env);
                            self.flush_agent();
                        }
                    }
                }
                Err(e) => self.payload_rejected(sender, "kernel-malformed", &e),
            },
            FrameKind::Inform => match wire::decode_inform(&payload) {
                Ok((to, msg)) => {
                    Self::version_ok(r, sender);
                    if to.contains(&r.me.0) && r.gather_until.is_none() {
                        r.agent.inform(now, RobotId(sender), &msg);
                    }
                }
                Err(e) => self.payload_rejected(sender, "inform-malformed", &e),
            },
        }
    }

    /// An input too large for its kind, dropped uncopied: counted where
    /// the rejects of its kind are (frames in `auth.rejected` as
    /// `oversize`; sensor readings and ROS 2 samples in `payload_rejects`;
    /// submissions in `missions_rejected`).
    fn oversize(&mut self, what: Big, len: usize) {
        let reason = match what {
            Big::Frame(from) => return self.count_reject(&from, Reject::Oversize),
            Big::Mission => {
                let why = format!("{len} bytes, larger than the {MAX_JSON} bytes a robot takes");
                return self.reject_mission("mission_rejected", None, why);
            }
            Big::Sensors => "sensors-oversize",
            Big::Ros2 => "ros2-oversize",
        };
        if let Some(r) = self.run.as_mut() {
            *r.payload_rejects.entry(reason).or_insert(0) += 1;
        }
    }

    /// Count a frame dropped before it was opened (`oversize`, or
    /// `before-mission`): in the running mission's counts, or, before the
    /// first mission, in those the status shows (the first mission's
    /// counts start from them).
    fn count_reject(&mut self, from: &str, reason: Reject) {
        let stats = match self.run.as_mut() {
            Some(r) => {
                r.opener.count(reason);
                r.opener.stats()
            }
            None => {
                *self.last_auth.rejected.entry(reason).or_insert(0) += 1;
                &self.last_auth
            }
        };
        let count = stats.rejected.get(&reason).copied().unwrap_or(0);
        self.log_reject(from, reason, count);
    }

    /// Log a rejected frame: the first [`LOG_REJECTS`] of each reason.
    fn log_reject(&mut self, from: &str, reason: Reject, count: u64) {
        if count <= LOG_REJECTS {
            let rec = json!({
                "robot": self.opts.name,
                "event": "frame_rejected",
                "key": from,
                "reason": reason,
            });
            self.log_record(rec);
        }
    }

    /// The kernel's timer stays due however often it is woken (see
    /// [`Agent::timer_spinning`]): a defect, said once per run.
    fn timer_spinning(&mut self, now: Time) {
        let Some(r) = self.run.as_mut() else { return };
        if std::mem::replace(&mut r.spin_said, true) {
            return;
        }
        eprintln!(
            "robot {}: its kernel's timer stays due at {now} however often it is woken \
             (a defect in bite: please report it with this robot's log); \
             woken once a control period from now on",
            self.opts.name
        );
        self.log_record(json!({
            "t": now.as_secs_f64(),
            "event": "timer_spin",
            "calls": bite_agent::TIMER_SPIN_LIMIT,
        }));
    }

    /// A teammate's frame that authenticated (`Opener::open` passed it)
    /// and whose payload read: the teammate speaks this robot's payload
    /// version, whatever an earlier frame (a corrupt one) said.
    fn version_ok(r: &mut Running, sender: u32) {
        if !r.other_versions.is_empty()
            && let Some(name) = r.names.get(sender as usize)
        {
            r.other_versions.remove(name);
        }
    }

    /// A teammate's authenticated frame whose payload this robot cannot
    /// read: counted under `malformed`, or, when the payload's own first
    /// byte is another payload version (a team not upgraded together),
    /// under `payload-version`, shown in the status until a frame of that
    /// teammate reads again, and said once per teammate and version in the
    /// log and on standard error: its frames are all dropped until it is
    /// upgraded. (Only an authenticated frame reaches here: a forged one
    /// never blames a teammate.)
    fn payload_rejected(&mut self, sender: u32, malformed: &'static str, e: &WireError) {
        let Some(r) = self.run.as_mut() else { return };
        let WireError::Version(theirs) = *e else {
            *r.payload_rejects.entry(malformed).or_insert(0) += 1;
            return;
        };
        *r.payload_rejects.entry("payload-version").or_insert(0) += 1;
        // On the roster: the frame authenticated.
        let teammate =
            (r.names.get(sender as usize).cloned()).unwrap_or_else(|| format!("#{sender}"));
        let new = r.other_versions.insert(teammate.clone(), theirs) != Some(theirs);
        if !r.versions_told.insert((teammate.clone(), theirs)) {
            if new {
                self.publish_status();
            }
            return;
        }
        // Shown at once: the next good frame of the teammate clears it.
        self.publish_status();
        eprintln!(
            "robot {}: teammate {teammate} speaks payload version {theirs}, this robot version {}: \
             its frames are dropped; run the same version of bite on every robot of the team",
            self.opts.name,
            wire::PAYLOAD_VERSION
        );
        self.log_record(json!({
            "event": "peer_version",
            "teammate": teammate,
            "theirs": theirs,
            "ours": wire::PAYLOAD_VERSION,
        }));
    }

    fn submission(&mut self, bytes: &[u8], loader: &Loader) {
        let body = match wire::open_submission(&self.opts.key, &self.opts.team, bytes) {
            Ok(b) => b,
            Err(e) => return self.reject_mission("mission_rejected", None, e.to_string()),
        };
        let id = Some(body.id.clone());
        let now_ms = unix_micros() / 1000;
        if body.issued_at.abs_diff(now_ms) > SUBMISSION_FRESH_MS {
            let why = "stale: issued_at is more than 5 minutes from now";
            return self.reject_mission("mission_rejected", id, why.into());
        }
        if self.seen_missions.contains(&body.id) {
            return self.reject_mission("mission_rejected", id, "replayed id".into());
        }
        if let Some(r) = &self.run
            && !r.agent.kernel().is_finished()
        {
            if body.replace {
                return self.replace_mission(&body, loader);
            }
            let why = "busy: the current mission has not completed (send a new version of it \
                       with `bite submit --replace`)";
            return self.reject_mission("mission_refused", id, why.into());
        }
        match loader(&body, None).and_then(|p| {
            self.start(p, Some(body.id.clone()), None)
                .map_err(|e| e.to_string())
        }) {
            Ok(()) => {
                self.seen_missions.insert(body.id.clone());
            }
            Err(e) => self.reject_mission("mission_refused", id, e),
        }
    }

    /// A new version of the running mission: offered to the mind, which
    /// switches at its team's next safe point (see `bite_core::kernel`'s
    /// `change.rs`), or refused with the reason.
    fn replace_mission(&mut self, body: &MissionBody, loader: &Loader) {
        let id = Some(body.id.clone());
        let version = body.version();
        let Some(r) = self.run.as_mut() else { return };
        // Numbered like the newest version it runs or holds; run in the
        // world it runs in (a scenario sent with it is not used).
        let prepared = loader(body, Some(r.agent.kernel().newest_mission())).and_then(|p| {
            bite_agent::agent::Shared::new(p.mission, &r.scenario).map_err(|d| d.to_string())
        });
        let shared = match prepared {
            Ok(s) => s,
            Err(e) => return self.reject_mission("mission_refused", id, e),
        };
        let graph = shared.mission().graph().clone();
        let now = r.clock.now();
        match r.agent.offer_change(now, version, shared) {
            Ok(()) => {
                // Names every version's behaviors (aligned).
                r.graph = graph;
                self.seen_missions.insert(body.id.clone());
                self.log_record(json!({
                    "event": "mission_change_submitted",
                    "id": body.id,
                    "version": version,
                }));
                self.flush_agent();
            }
            Err(e) => {
                self.flush_agent();
                self.reject_mission("mission_refused", id, e.to_string());
            }
        }
    }

    /// Count, log and report a submission not run (`event`:
    /// `mission_rejected` or `mission_refused`).
    fn reject_mission(&mut self, event: &str, id: Option<String>, reason: String) {
        self.missions_rejected += 1;
        self.log_record(json!({"event": event, "id": id, "reason": reason}));
        eprintln!(
            "robot {}: {} {}: {reason}",
            self.opts.name,
            event.replace('_', " "),
            id.as_deref().unwrap_or("(unreadable)")
        );
        self.last_rejection = Some(wire::Rejection {
            id,
            event: event.trim_start_matches("mission_").to_string(),
            reason,
        });
    }

    /// Send and log what the agent produced.
    fn flush_agent(&mut self) {
        let Some(r) = self.run.as_mut() else { return };
        let now = r.clock.now();
        let mut records = Vec::new();
        let sent = self.frames.sent;
        while let Some(o) = r.agent.poll() {
            match o {
                AgentOutput::Send { to, envelope, .. } => {
                    let frame = r.sealer.seal(
                        FrameKind::Kernel,
                        &wire::encode_kernel(&to, &envelope),
                        unix_micros(),
                    );
                    self.frames
                        .send_to(&self.session, &r.names, one_of(&to), frame);
                }
                AgentOutput::Inform(o) => {
                    records.push(json!({
                        "t": now.as_secs_f64(),
                        "robot": self.opts.name,
                        "event": "inform",
                        "reason": o.msg.reason,
                        "about": o.msg.about.map(|b| r.graph.name_of(b).to_string()),
                        "to": o.to.iter().map(|x| r.names[x.index()].clone()).collect::<Vec<_>>(),
                        "beliefs": bite_core::wm::belief_names(&r.graph, &o.msg),
                    }));
                    let frame = r.sealer.seal(
                        FrameKind::Inform,
                        &wire::encode_inform(&o.to, &o.msg),
                        unix_micros(),
                    );
                    let one = match o.to.as_slice() {
                        [one] => Some(*one),
                        _ => None,
                    };
                    self.frames.send_to(&self.session, &r.names, one, frame);
                }
                AgentOutput::Event(e) => {
                    records.push(Namer::new(&r.graph).record(now, r.me, &e));
                }
                AgentOutput::Drive(cmd) => {
                    // A ROS 2 body takes a body velocity: what the robot's
                    // drive makes of the command at its estimated heading.
                    if let Some(ros) = self.ros.as_mut()
                        && let Some(body) = &r.scenario.physics
                    {
                        let heading = r.last_sensed.as_ref().map_or(0.0, |s| s.pose.heading);
                        let m = body.robot;
                        let twist = match m.drive {
                            bite_agent::spec::Drive::Differential => {
                                let (f, turn) = bite_agent::schema::differential(
                                    &cmd,
                                    heading,
                                    m.max_speed,
                                    m.max_turn,
                                );
                                (f, 0.0, turn)
                            }
                            bite_agent::spec::Drive::Holonomic => {
                                let v = glam::DVec2::from_angle(-heading).rotate(cmd.v);
                                let turn = cmd.face.map_or(0.0, |h| {
                                    (bite_agent::schema::wrap(h - heading) * 3.0)
                                        .clamp(-m.max_turn, m.max_turn)
                                });
                                (v.x, v.y, turn)
                            }
                        };
                        let t = crate::ros2::Twist {
                            linear: crate::ros2::Vector3 {
                                x: twist.0,
                                y: twist.1,
                                z: 0.0,
                            },
                            angular: crate::ros2::Vector3 {
                                x: 0.0,
                                y: 0.0,
                                z: twist.2,
                            },
                        };
                        ros.cmd.put(&self.session, &t);
                    }
                    // BITE's own command too: a simulated body colours its
                    // trail with the label (a ROS body ignores it).
                    let body = serde_json::to_vec(&cmd).unwrap_or_default();
                    let _ = self.outlets.cmd.put(body).wait();
                }
            }
        }
        if self.frames.sent > sent {
            self.frames.bursts += 1;
        }
        for rec in records {
            self.log_record(rec);
        }
    }

    /// Write a record to the run log and publish it.
    fn log_record(&mut self, mut rec: serde_json::Value) {
        if let Some(o) = rec.as_object_mut() {
            if !o.contains_key("t") {
                let t = self
                    .run
                    .as_ref()
                    .map_or(0.0, |r| r.clock.now().as_secs_f64());
                o.insert("t".into(), json!(t));
            }
            if !o.contains_key("robot") {
                o.insert("robot".into(), json!(self.opts.name));
            }
        }
        let mut line = rec.to_string();
        line.push('\n');
        if let Some(w) = self.log.as_mut()
            && self.log_error.is_none()
            && let Err(e) = w.write_all(line.as_bytes())
        {
            self.log_error = Some(e);
        }
        line.pop();
        let _ = self.outlets.log.put(line).wait();
    }

    fn status(&self) -> Status {
        let mut s = Status {
            robot: self.opts.name.clone(),
            team: self.opts.team.clone(),
            mission: None,
            mission_id: None,
            t: 0.0,
            state: "waiting".into(),
            phase: None,
            stack: Vec::new(),
            subteam: None,
            beliefs: BTreeMap::new(),
            lost: Vec::new(),
            auth: self.last_auth.clone(),
            missions_rejected: self.missions_rejected,
            last_rejection: self.last_rejection.clone(),
            version: 0,
            pending_version: None,
            peer_versions: BTreeMap::new(),
        };
        if let Some(r) = &self.run {
            let k = r.agent.kernel();
            s.version = k.version();
            s.pending_version = k.pending_version();
            s.mission = Some(r.graph.name().to_string());
            s.mission_id = r.mission_id.clone();
            s.t = r.clock.now().as_secs_f64();
            s.state = if r.gather_until.is_some() {
                "gathering"
            } else if k.is_finished() {
                "completed"
            } else {
                "running"
            }
            .into();
            s.phase = Some(k.phase_name().to_string());
            (s.stack, s.subteam) = Status::of_kernel(k, &r.graph);
            s.beliefs = (k.beliefs().iter())
                .filter_map(|(n, b)| {
                    serde_json::to_value(&b.value)
                        .ok()
                        .map(|v| (n.to_string(), v))
                })
                .collect();
            s.lost = (r.alive.suspected())
                .map(|i| r.names[i as usize].clone())
                .collect();
            s.auth = r.opener.stats().clone();
            s.peer_versions = r.other_versions.clone();
        }
        s
    }

    fn publish_status(&mut self) {
        let s = self.status();
        let body = serde_json::to_vec(&s).unwrap_or_default();
        if let Some(ros) = self.ros.as_mut() {
            let data = String::from_utf8_lossy(&body).into_owned();
            ros.status
                .put(&self.session, &crate::ros2::RosString { data });
        }
        let _ = self.outlets.status.put(body).wait();
    }

    fn membership(&self) -> Membership {
        let mut m = Membership {
            robot: self.opts.name.clone(),
            roster: Vec::new(),
            alive: Vec::new(),
            lost: Vec::new(),
            subteams: Vec::new(),
        };
        if let Some(r) = &self.run {
            m.roster = r.names.clone();
            m.lost = (r.alive.suspected())
                .map(|i| r.names[i as usize].clone())
                .collect();
            m.alive = (0..r.names.len() as u32)
                .filter(|i| *i != r.me.0 && r.alive.has_heard(*i) && !r.alive.is_suspected(*i))
                .map(|i| r.names[i as usize].clone())
                .collect();
            m.subteams = Status::of_kernel(r.agent.kernel(), &r.graph).0;
        }
        m
    }

    fn finish(&mut self, overflow: u64) {
        self.publish_status();
        if let Some(r) = &self.run
            && r.finished_at.is_none()
        {
            let rec = json!({
                "robot": self.opts.name,
                "event": "run_finished",
                "completed": false,
                "auth": r.opener.stats(),
                "payload_rejects": r.payload_rejects,
                "overflow": overflow,
                "inputs": self.handled,
            });
            self.log_record(rec);
        }
    }
}

/// Whether a sensor reading's numbers can be a body's: every one finite,
/// lengths and coordinates within [`MAX_READING_M`], the odometer not
/// negative (`sim/**` keys are not authenticated: anyone on the network
/// may publish a reading).
fn readings_hold(s: &Sensed) -> bool {
    let m = |x: f64| x.is_finite() && x.abs() <= MAX_READING_M;
    let at = |p: &glam::DVec2| m(p.x) && m(p.y);
    s.t.is_finite()
        && at(&s.pose.pos)
        && m(s.pose.heading)
        && m(s.odometer)
        && s.odometer >= 0.0
        && s.rays.iter().all(|(a, d)| m(*a) && m(*d))
        && s.mates.iter().all(|(_, p)| at(p))
        && s.objects.iter().all(|(_, p)| at(p))
}

/// The tag that binds frames to a mission: a hash of its submission id, or
/// of what the robots were started with (graph name, configuration name,
/// clock origin in µs), so frames of another mission do not verify.
pub fn mission_tag(id: Option<&str>, graph: &BehaviorGraph, start_at_us: Option<u64>) -> u64 {
    let mut h = bite_core::ids::Fnv1a::new();
    match id {
        Some(id) => {
            h.write(b"id\0");
            h.write(id.as_bytes());
        }
        None => {
            h.write(b"cli\0");
            h.write(graph.name().as_bytes());
            h.write(b"\0");
            h.write(graph.config_name().unwrap_or("").as_bytes());
            h.write(&start_at_us.unwrap_or(0).to_le_bytes());
        }
    }
    h.finish()
}

/// How long a robot that completed stays at least (its last heartbeats
/// say so), wall µs.
fn grace_us(r: &Running) -> u64 {
    r.clock
        .wall(r.detector.heartbeat.saturating_mul(2))
        .as_micros() as u64
}

/// How long a robot that completed stays at most, wall µs.
fn linger_us(r: &Running) -> u64 {
    r.clock
        .wall(r.detector.lost_after.saturating_mul(2))
        .as_micros() as u64
}

/// Shared flag set by a signal handler.
pub type StopFlag = Arc<AtomicBool>;

#[cfg(test)]
mod tests {
    use super::*;
    use bite_core::members::MemberSet;

    #[test]
    fn readings_that_no_body_makes_are_refused() {
        let good: Sensed = serde_json::from_str(
            r#"{"t": 1.0, "pose": {"x": 1.5, "y": 1.0, "heading": 0.1},
                "rays": [[0.0, 0.8]], "mates": [{"robot": 1, "x": 1.1, "y": 1.4}],
                "objects": [{"index": 0, "x": 3.0, "y": 2.0}], "odometer": 4.7}"#,
        )
        .expect("a reading");
        assert!(readings_hold(&good));
        let bad: [fn(&mut Sensed); 10] = [
            |s| s.odometer = 1e308,
            |s| s.odometer = f64::INFINITY,
            |s| s.odometer = -1.0,
            |s| s.pose.pos.x = f64::NAN,
            |s| s.pose.pos.y = -1e300,
            |s| s.pose.heading = f64::NEG_INFINITY,
            |s| s.rays[0].1 = f64::NAN,
            |s| s.mates[0].1.x = f64::INFINITY,
            |s| s.objects[0].1.y = 1e10,
            |s| s.t = f64::NAN,
        ];
        for (i, spoil) in bad.iter().enumerate() {
            let mut s = good.clone();
            spoil(&mut s);
            assert!(!readings_hold(&s), "case {i}: {s:?}");
        }
        // The forged reading of the audit: a finite odometer of 1e308.
        let forged: Sensed = serde_json::from_str(
            r#"{"t": 1.0, "pose": {"x": 0, "y": 0, "heading": 0}, "odometer": 1e308}"#,
        )
        .expect("it parses");
        assert!(!readings_hold(&forged));
    }

    #[test]
    fn a_message_to_one_teammate_goes_to_its_own_key_and_a_multicast_to_the_team() {
        assert_eq!(one_of(&Recipients::One(RobotId(2))), Some(RobotId(2)));
        let team = Arc::new(MemberSet::all(3));
        assert_eq!(one_of(&Recipients::Team(team)), None);
    }
}
