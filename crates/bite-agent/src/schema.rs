//! Motor schemas and command fusion (the second paper's behavior-selection
//! and command-fusion modules; Arkin's motor schemas).
//!
//! A schema reads what the robot believes about the world (its pose, range
//! readings, where it last saw objects and teammates) and outputs a desired
//! velocity in the world frame, or nothing when it has nothing to say (an
//! obstacle-avoidance schema with no obstacle in range). A skill is a set of
//! schemas, each with a gain and a priority layer 0-3.
//!
//! Fusion: within a layer the outputs are superposed linearly (weighted by
//! the gains); the highest layer in which some schema is active overrides
//! all the layers below it. So obstacle avoidance at layer 3 overrides a
//! search at layer 1 while an obstacle is near, and the search drives the
//! robot again once it is clear. Which layer a schema sits in is part of the
//! skill, not of the schema: `find` puts avoidance at 3, `push` below the
//! push itself (the box is an obstacle the robot must touch).
//!
//! Everything here is a pure function of its inputs (and, for `wander`, of
//! a seeded random stream), so it is unit-testable without physics.

use bite_core::ids::BehaviorId;
use glam::DVec2;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Where a robot is and which way it faces (radians, counter-clockwise
/// from +x). In JSON: `{"x": m, "y": m, "heading": radians}`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(from = "PoseJson", into = "PoseJson")]
pub struct Pose {
    /// Position, metres.
    pub pos: DVec2,
    /// Heading, radians.
    pub heading: f64,
}

impl Pose {
    /// Unit vector along the heading.
    pub fn dir(&self) -> DVec2 {
        DVec2::from_angle(self.heading)
    }
}

/// Something a schema steers relative to.
#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    /// A fixed point of the arena.
    Point(DVec2),
    /// A direction to keep going in.
    Direction(DVec2),
    /// An object by name or colour, where the robot last saw it.
    Object(String),
}

/// Which side of its reference a formation slot is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Behind and to the left.
    Left,
    /// Behind and to the right.
    Right,
    /// Straight behind.
    Behind,
}

/// A motor schema (what it does, with its own parameters).
#[derive(Clone, Debug, PartialEq)]
pub enum Schema {
    /// Go to a point / object, or along a direction; slows down within
    /// `slow` metres of a point.
    MoveToGoal {
        /// Where.
        goal: Target,
        /// Cruise speed, m/s.
        speed: f64,
    },
    /// Repulsion from range readings closer than `range`.
    AvoidObstacle {
        /// Distance at which obstacles start to push, m.
        range: f64,
    },
    /// Repulsion from teammates closer than `range`.
    AvoidTeammate {
        /// Distance at which teammates start to push, m.
        range: f64,
    },
    /// Keep a formation slot relative to the robot that holds role `of`.
    KeepSlot {
        /// The sibling behavior whose member is the reference.
        of: String,
        /// Which slot.
        side: Side,
        /// Distance to the reference, m.
        distance: f64,
        /// Top speed, m/s.
        speed: f64,
    },
    /// Follow the robot that holds role `of` at `distance`.
    Follow {
        /// The sibling behavior whose member is followed.
        of: String,
        /// Distance kept, m.
        distance: f64,
        /// Top speed, m/s.
        speed: f64,
    },
    /// Wander: a new random heading every `period` seconds.
    Wander {
        /// Speed, m/s.
        speed: f64,
        /// Seconds between heading changes.
        period: f64,
    },
    /// Sweep a rectangle in lanes `spacing` apart (boustrophedon).
    Scan {
        /// `[x0, y0, x1, y1]`.
        region: [f64; 4],
        /// Distance between lanes, m.
        spacing: f64,
        /// Speed, m/s.
        speed: f64,
        /// Split the region among the robots running the skill: each
        /// sweeps its own cell of a near-square grid, by rank.
        split: bool,
        /// Per-waypoint budget, seconds: a waypoint the robot has got no
        /// closer to for this long (a pillar, a wall or a parked teammate
        /// in the way) is given up, so that the sweep always ends.
        patience: f64,
    },
    /// Turn to face a target (no translation).
    Face {
        /// What to face.
        target: Target,
    },
    /// Turn in place to look all round with the camera (the AIBO panning
    /// its head to find its peers).
    LookAround,
    /// Push an object toward a goal point: get behind it, then drive
    /// through it.
    Push {
        /// The object (name or colour).
        object: String,
        /// Where it must go.
        goal: DVec2,
        /// Distance from the object's centre to stand behind it, m.
        offset: f64,
        /// Speed, m/s.
        speed: f64,
    },
    /// Stand still.
    Stop,
}

impl Schema {
    /// The schema's name in scenario files.
    pub fn name(&self) -> &'static str {
        match self {
            Schema::MoveToGoal { .. } => "move-to-goal",
            Schema::AvoidObstacle { .. } => "avoid-obstacle",
            Schema::AvoidTeammate { .. } => "avoid-teammate",
            Schema::KeepSlot { .. } => "keep-slot",
            Schema::Follow { .. } => "follow",
            Schema::Wander { .. } => "wander",
            Schema::Scan { .. } => "scan",
            Schema::Face { .. } => "face",
            Schema::LookAround => "look-around",
            Schema::Push { .. } => "push",
            Schema::Stop => "stop",
        }
    }

    /// The object it drives to, faces or pushes, if it names one.
    pub fn object(&self) -> Option<&str> {
        match self {
            Schema::MoveToGoal {
                goal: Target::Object(o),
                ..
            }
            | Schema::Face {
                target: Target::Object(o),
            } => Some(o),
            Schema::Push { object, .. } => Some(object),
            _ => None,
        }
    }

    /// True for the schemas that only keep the robot clear of things.
    pub fn avoids(&self) -> bool {
        matches!(
            self,
            Schema::AvoidObstacle { .. } | Schema::AvoidTeammate { .. }
        )
    }
}

/// A schema in a skill: gain and priority layer.
#[derive(Clone, Debug, PartialEq)]
pub struct Weighted {
    /// The schema.
    pub schema: Schema,
    /// Its weight within its layer.
    pub gain: f64,
    /// Priority layer, 0 (lowest) to 3.
    pub layer: u8,
}

/// A teammate as this robot knows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mate {
    /// Where it was last seen.
    pub pos: DVec2,
    /// Its heading, estimated from how it moved (`None`: unknown).
    pub heading: Option<f64>,
}

/// What the schemas of one robot read at a control step.
#[derive(Clone, Debug, Default)]
pub struct View {
    /// Estimated pose.
    pub pose: Pose,
    /// Range readings: (angle relative to the heading, distance), only
    /// those that hit something within the sensor's range.
    pub rays: Vec<(f64, f64)>,
    /// Objects by name and by colour: last seen position.
    pub objects: BTreeMap<String, DVec2>,
    /// The object keys in view now.
    pub in_view: std::collections::BTreeSet<String>,
    /// Teammates' last seen positions, by robot index.
    pub mates: BTreeMap<u32, Mate>,
    /// The robot holding each sibling role (behavior name → robot index).
    pub roles: BTreeMap<String, u32>,
    /// Seconds since the skill started.
    pub skill_time: f64,
    /// Top speed of this robot, m/s.
    pub max_speed: f64,
    /// This robot's rank among the robots running its behavior (0-based),
    /// and how many they are.
    pub rank: (u32, u32),
    /// Its body's radius, m.
    pub radius: f64,
    /// Where it last saw teammates presumed lost: bodies that do not move
    /// out of the way (obstacles to route around, not teammates to avoid).
    pub bodies: Vec<DVec2>,
    /// The arena as it knows it, to route around those bodies.
    pub map: Option<std::sync::Arc<crate::plan::Map>>,
    /// Where it last saw a live teammate (the latest sighting it still
    /// remembers, however old), and how long ago, s: where to look for
    /// the team when turning in place shows no one (see [`command`]).
    pub last_mate: Option<(DVec2, f64)>,
}

/// A fused command: a desired velocity in the world frame, and a heading
/// to turn to when standing (from `face`). What a robot sends the world
/// at each control tick; in JSON
/// `{"vx": m/s, "vy": m/s, "face": radians | null, "layer": 0-3 | null,
/// "behavior": index | null, "link": robot | null,
/// "slot": [robot, side, distance] | null}` (all but `vx`, `vy` may be left
/// out: null). The last three are the [`Label`]: what the mind runs, for
/// the world's records (trails coloured by behavior, formation links and
/// error); they do not move the body.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CommandJson", into = "CommandJson")]
pub struct Command {
    /// Desired velocity, m/s, world frame.
    pub v: DVec2,
    /// Heading to face (radians) when `v` is (nearly) zero.
    pub face: Option<f64>,
    /// The layer that produced it (`None`: no schema active).
    pub layer: Option<u8>,
    /// What the mind runs as it sends it.
    pub label: Label,
}

/// What a robot's mind runs, sent with its commands so that the world
/// (in process, or a simulator server) records what every robot did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Label {
    /// The leaf behavior whose skill it runs (`None`: idle).
    pub behavior: Option<BehaviorId>,
    /// The teammate its schemas refer to (the one it keeps a slot on or
    /// follows).
    pub link: Option<u32>,
    /// The formation slot it keeps, once settled in its skill: on robot
    /// `of`, side, distance (m).
    pub slot: Option<(u32, Side, f64)>,
}

#[derive(Serialize, Deserialize)]
struct PoseJson {
    x: f64,
    y: f64,
    heading: f64,
}

impl From<PoseJson> for Pose {
    fn from(p: PoseJson) -> Self {
        Pose {
            pos: DVec2::new(p.x, p.y),
            heading: p.heading,
        }
    }
}

impl From<Pose> for PoseJson {
    fn from(p: Pose) -> Self {
        PoseJson {
            x: p.pos.x,
            y: p.pos.y,
            heading: p.heading,
        }
    }
}

#[derive(Serialize, Deserialize)]
struct CommandJson {
    vx: f64,
    vy: f64,
    #[serde(default)]
    face: Option<f64>,
    #[serde(default)]
    layer: Option<u8>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    behavior: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    link: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    slot: Option<(u32, String, f64)>,
}

impl TryFrom<CommandJson> for Command {
    type Error = String;
    fn try_from(c: CommandJson) -> Result<Self, String> {
        if let Some(l) = c.layer
            && l > 3
        {
            return Err(format!("layer {l}: layers are 0 to 3"));
        }
        let slot = match c.slot {
            None => None,
            Some((of, side, d)) => Some((
                of,
                match side.as_str() {
                    "left" => Side::Left,
                    "right" => Side::Right,
                    "behind" => Side::Behind,
                    other => return Err(format!("slot side `{other}`: left, right or behind")),
                },
                d,
            )),
        };
        Ok(Command {
            v: DVec2::new(c.vx, c.vy),
            face: c.face,
            layer: c.layer,
            label: Label {
                behavior: c.behavior.map(BehaviorId),
                link: c.link,
                slot,
            },
        })
    }
}

impl From<Command> for CommandJson {
    fn from(c: Command) -> Self {
        CommandJson {
            vx: c.v.x,
            vy: c.v.y,
            face: c.face,
            layer: c.layer,
            behavior: c.label.behavior.map(|b| b.0),
            link: c.label.link,
            slot: c.label.slot.map(|(of, side, d)| {
                let side = match side {
                    Side::Left => "left",
                    Side::Right => "right",
                    Side::Behind => "behind",
                };
                (of, side.to_string(), d)
            }),
        }
    }
}

/// One robot's raw sensor readings at a control tick: what the world (the
/// simulator, or a real robot's drivers) measures, before the robot's mind
/// makes percepts of it. In JSON:
///
/// ```json
/// { "t": 12.3,
///   "pose": { "x": 1.0, "y": 2.0, "heading": 0.5 },
///   "rays": [[0.0, 0.84], [0.5236, 1.02]],
///   "mates": [{ "robot": 1, "x": 2.1, "y": 0.4 }],
///   "objects": [{ "index": 0, "x": 3.0, "y": 2.5 }],
///   "odometer": 4.2,
///   "contact": false }
/// ```
///
/// Lengths in metres, angles in radians; `t` and `pose` are required, the
/// rest may be left out (no rays, no sightings, 0 m, no contact).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sensed {
    /// World time of the readings, s.
    pub t: f64,
    /// Estimated pose.
    pub pose: Pose,
    /// Range readings: (angle relative to the heading, distance), only
    /// those that hit something within the sensor's range.
    pub rays: Vec<(f64, f64)>,
    /// Teammates the camera sees: robot index and estimated position.
    pub mates: Vec<(u32, DVec2)>,
    /// Objects the camera sees: index in the scenario's `objects` and
    /// estimated position.
    pub objects: Vec<(usize, DVec2)>,
    /// Distance travelled since the start, m.
    pub odometer: f64,
    /// Touching something.
    pub contact: bool,
}

#[derive(Serialize, Deserialize)]
struct MateJson {
    robot: u32,
    x: f64,
    y: f64,
}

#[derive(Serialize, Deserialize)]
struct ObjectJson {
    index: usize,
    x: f64,
    y: f64,
}

#[derive(Serialize)]
struct SensedOut<'a> {
    t: f64,
    pose: Pose,
    rays: &'a [(f64, f64)],
    mates: Vec<MateJson>,
    objects: Vec<ObjectJson>,
    odometer: f64,
    contact: bool,
}

#[derive(Deserialize)]
struct SensedIn {
    t: f64,
    pose: Pose,
    #[serde(default)]
    rays: Vec<(f64, f64)>,
    #[serde(default)]
    mates: Vec<MateJson>,
    #[serde(default)]
    objects: Vec<ObjectJson>,
    #[serde(default)]
    odometer: f64,
    #[serde(default)]
    contact: bool,
}

impl Serialize for Sensed {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        SensedOut {
            t: self.t,
            pose: self.pose,
            rays: &self.rays,
            mates: (self.mates.iter())
                .map(|(robot, p)| MateJson {
                    robot: *robot,
                    x: p.x,
                    y: p.y,
                })
                .collect(),
            objects: (self.objects.iter())
                .map(|(index, p)| ObjectJson {
                    index: *index,
                    x: p.x,
                    y: p.y,
                })
                .collect(),
            odometer: self.odometer,
            contact: self.contact,
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Sensed {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = SensedIn::deserialize(d)?;
        Ok(Sensed {
            t: s.t,
            pose: s.pose,
            rays: s.rays,
            mates: (s.mates.into_iter())
                .map(|m| (m.robot, DVec2::new(m.x, m.y)))
                .collect(),
            objects: (s.objects.into_iter())
                .map(|o| (o.index, DVec2::new(o.x, o.y)))
                .collect(),
            odometer: s.odometer,
            contact: s.contact,
        })
    }
}

/// The waypoint a sweep heads for ([`scan_waypoints`]): what its lanes
/// were made from, its index, the point.
type ScanLanes = (([f64; 4], f64, bool, (u32, u32)), usize, Option<DVec2>);

/// State a schema keeps across steps during one execution of its skill.
#[derive(Clone, Debug, Default)]
pub struct State {
    /// Wander: current heading and when it was drawn.
    wander: Option<(f64, f64)>,
    /// Scan: index of the next waypoint.
    waypoint: usize,
    /// Scan: all waypoints visited.
    pub finished: bool,
    /// Scan: the closest the robot has come to the current waypoint, and
    /// when it last came closer.
    approach: Option<(f64, f64)>,
    /// Scan: waypoints given up (out of reach).
    pub skipped: u32,
    /// Scan: what its lanes were made from (region, spacing, split, the
    /// robot's rank among how many), the index of the waypoint it heads
    /// for, and that waypoint (none: the sweep is done).
    lanes: Option<ScanLanes>,
    /// How many times the robot came 5 cm nearer its goal (scan: its next
    /// waypoint; move-to-goal and push: the point it drives to) than it
    /// had been, or (scan) reached a waypoint or gave one up: the skill's
    /// progress, finitely many: see [`State::marks`].
    marks: u32,
    /// Push: when it started looking round for an object that was not
    /// where it was last seen.
    search: Option<f64>,
    /// Push: that turn ended without seeing it (lost until seen again).
    gone: bool,
    /// A detour around a lost teammate's body it is following.
    route: Option<crate::plan::Route>,
    /// The skill's object was never seen: when this robot started
    /// searching for it (see [`command`]).
    lost: Option<f64>,
    /// That search round a lost teammate's body near where the object
    /// was last seen.
    circle: Option<Circle>,
    /// That search's own moves: its detour round a lost teammate's body,
    /// and whether it is pinned (see [`State::watch_search`]); kept apart
    /// from the skill's schema's, which they replace while it evaluates.
    search_moves: Moves,
    /// That search, exploring (after [`EXPLORE_AFTER`]): the places it has
    /// looked round from in vain, and the lookout it heads for or looks
    /// round from.
    looked: Vec<DVec2>,
    lookout: Option<Lookout>,
    /// That search: how many of its turns it has looked round with a
    /// teammate within [`MATE_NEAR`], and the last such turn.
    looks_near_mate: (u32, Option<u32>),
    /// That search's look past a live teammate near it (see [`Beyond`]).
    beyond: Beyond,
    /// Move-to-goal, push getting behind its object: the point it drives
    /// to at this tick.
    bound_for: Option<DVec2>,
    /// The nearest it has come to that point while driving there, and
    /// when it last came nearer.
    headway: Option<(f64, f64)>,
    /// The nearest it has come to that point at all during this execution
    /// of the skill (whatever drove it, the point moving or not): each
    /// 5 cm nearer is a step of the skill ([`State::marks`]).
    nearest: Option<f64>,
    /// When it found itself trapped on the way there (no headway for
    /// [`TRAPPED_AFTER`]) and took a planned detour.
    pub trapped: Option<f64>,
    /// Wander: where it was, and when, last time it had moved
    /// [`PIN_RADIUS`] away from where it was before.
    roam: Option<(DVec2, f64)>,
    /// Wander, pinned: the open floor it heads for.
    escape: Option<DVec2>,
    /// Push: the turn (radians) from the goal's direction it pushes the
    /// object in while a lost teammate's body stands where it would push
    /// from (see [`push_direction`]).
    push_turn: Option<f64>,
    /// Push: the planned way of its object round walls and obstacles that
    /// stand in its straight way to the goal (see [`push_way`]): when it
    /// was planned (skill time), for which goal, its points.
    object_way: Option<(f64, DVec2, Vec<DVec2>)>,
    /// Look-around: since when it has looked round without seeing a live
    /// teammate (see [`command`]).
    in_vain: Option<f64>,
    /// Move-to-goal: it pushes a lost teammate's body that blocks its only
    /// way (see [`command`]).
    shoving: bool,
    /// Push, in position behind its object: the nearest the object has
    /// come to the goal, and when it last came nearer.
    object_headway: Option<(f64, f64)>,
    /// Push: it needs the arena's map, to plan its object's way round
    /// walls and obstacles (see [`push_way`]), since the object made no
    /// headway for [`TRAPPED_AFTER`].
    pushing: bool,
    /// Push: it needs the arena's map, to tell whether a wall or an
    /// obstacle hides its object from it (the object is not in view where
    /// it was last seen, close by).
    sighting: bool,
}

/// What a search's moves keep of the way they go (see [`command`]): a
/// planned detour, and the watch for a pin (see [`State::watch_search`]),
/// apart from the skill's schema's.
#[derive(Clone, Debug, Default)]
struct Moves {
    route: Option<crate::plan::Route>,
    trapped: Option<f64>,
    roam: Option<(DVec2, f64)>,
    escape: Option<DVec2>,
}

impl State {
    /// True when this schema needs the arena's map at skill time `now`:
    /// pushing an object that makes no headway (its way round obstacles
    /// is planned on it) or that is out of sight close by (whether a wall
    /// or an obstacle hides it is read on it), trapped (its detour is
    /// planned on it), its
    /// search pinned, or
    /// searching for its object for [`EXPLORE_AFTER`] s (it explores the
    /// open floor on it).
    pub fn needs_map(&self, now: f64) -> bool {
        self.pushing
            || self.sighting
            || self.trapped.is_some()
            || self.search_moves.trapped.is_some()
            || self.lost.is_some_and(|since| now - since >= EXPLORE_AFTER)
    }

    /// Swap the search's moves ([`Moves`]) with the schema's: the search
    /// evaluates its moves between two swaps.
    fn swap_moves(&mut self) {
        let m = &mut self.search_moves;
        std::mem::swap(&mut self.route, &mut m.route);
        std::mem::swap(&mut self.trapped, &mut m.trapped);
        std::mem::swap(&mut self.roam, &mut m.roam);
        std::mem::swap(&mut self.escape, &mut m.escape);
    }

    /// Keep track of a search's moves (its moves swapped in), at `pos` at
    /// skill time `now`: pinned when it has stayed within [`PIN_RADIUS`]
    /// of one spot for [`SEARCH_PINNED_AFTER`], looking round and moving
    /// by turns (held between a wall and an obstacle by its move toward a
    /// teammate, say, where attraction and avoidance cancel). A pinned
    /// search is trapped for [`DETOUR`]: its moves follow a planned
    /// detour, and it does not stop to look round meanwhile; one with no
    /// teammate to head for explores (see [`command`]).
    fn watch_search(&mut self, pos: DVec2, now: f64) {
        match self.trapped {
            Some(t) if now - t >= DETOUR || now < t => {
                self.trapped = None;
                self.roam = None;
            }
            Some(_) => return,
            None => {}
        }
        self.watch_roaming(pos, now, SEARCH_PINNED_AFTER);
    }

    /// How many steps the skill has made since its state was last reset
    /// (the pilot resets it whenever the robot's stack changes): a sweep
    /// (`scan`) coming 5 cm nearer its next waypoint than it had been,
    /// reaching it, or giving it up (no nearer for its `patience`); a
    /// `move-to-goal`, or a `push` getting behind its object, coming 5 cm
    /// nearer the point it drives to than it has been in this execution
    /// (a pusher working its way to the box through a crowd). Each makes
    /// finitely many (a sweep's waypoints are few, and the nearest a robot
    /// has been to a point only shrinks, by 5 cm a step, down to nothing),
    /// so a robot that keeps making them is getting on with its skill, not
    /// going round in circles: the simulator's stall watch counts them as
    /// progress (`bite_sim::stall`). Other schemas make none.
    pub fn marks(&self) -> u32 {
        self.marks
    }

    /// Keep track of a schema's headway (move-to-goal, push getting behind
    /// its object) while it `drives` the robot,
    /// now `to` m from its goal at skill time `now`: trapped after
    /// `patience` s without getting [`HEADWAY`] m nearer than it has
    /// been, for [`DETOUR`].
    fn watch_headway(&mut self, drives: bool, to: f64, now: f64, patience: f64) {
        if !drives {
            self.headway = None;
            self.trapped = None;
            return;
        }
        match self.trapped {
            Some(t) if now - t >= DETOUR || now < t => {
                self.trapped = None;
                self.headway = Some((to, now));
            }
            Some(_) => return,
            None => {}
        }
        match self.headway {
            Some((best, since)) if to > best - HEADWAY && now >= since => {
                if now - since >= patience {
                    self.trapped = Some(now);
                }
            }
            _ => self.headway = Some((to, now)),
        }
    }

    /// Keep track of a wandering robot's roaming, at `pos` at skill time
    /// `now`: pinned when it has stayed within [`PIN_RADIUS`] of one spot
    /// for [`PINNED_AFTER`] (between walls, obstacles and teammates where
    /// avoidance overrides the wander whichever way it turns). A pinned
    /// robot is trapped: it heads for open floor on a planned detour, as a
    /// trapped robot driving to a goal does (see [`evaluate`]).
    fn watch_roaming(&mut self, pos: DVec2, now: f64, patience: f64) {
        match self.roam {
            _ if self.trapped.is_some() => self.roam = Some((pos, now)),
            Some((at, since)) if at.distance(pos) <= PIN_RADIUS && now >= since => {
                if now - since >= patience {
                    self.roam = Some((pos, now));
                    self.trapped = Some(now);
                    self.escape = None;
                }
            }
            _ => self.roam = Some((pos, now)),
        }
    }
}

/// One leg of a search: heading for a point, then a look all round there
/// ([`State::explore`]'s lookouts, [`State::circle_round`]'s vantage
/// points).
#[derive(Clone, Copy, Debug)]
struct Visit {
    /// When it started heading there, or looking round.
    since: f64,
    /// It is looking round.
    looking: bool,
}

impl Visit {
    /// A leg that starts heading for its point at skill time `now`.
    fn new(now: f64) -> Visit {
        Visit {
            since: now,
            looking: false,
        }
    }

    /// Looking round, and not yet round once ([`SEARCH_TURN`]) at `now`.
    fn still_looking(&self, now: f64) -> bool {
        self.looking && now - self.since < SEARCH_TURN
    }

    /// The step toward `to` from `pos` at `now`: on the way until within
    /// [`ARRIVED`] of it or `limit` s after it set out, then a look round.
    fn head(&mut self, to: DVec2, pos: DVec2, now: f64, limit: f64) -> Schema {
        if to.distance(pos) > ARRIVED && now - self.since < limit {
            return Schema::MoveToGoal {
                goal: Target::Point(to),
                speed: SEARCH_SPEED,
            };
        }
        self.looking = true;
        self.since = now;
        Schema::LookAround
    }
}

/// A search for an object round a lost teammate's body near where it was
/// last seen (see [`vantage`]).
#[derive(Clone, Copy, Debug)]
struct Circle {
    /// The bearing (radians, from the body) the robot searched from when
    /// the search began.
    from: f64,
    /// The vantage point it heads for or looks from: the `k`-th.
    k: usize,
    /// The leg to it.
    visit: Visit,
}

/// A search's look past a live teammate near it, round it, once a search,
/// after its first look round (see [`command`]).
#[derive(Clone, Copy, Debug, Default)]
enum Beyond {
    /// Not yet.
    #[default]
    NotYet,
    /// Heading for the point past the teammate, or looking round there.
    Going(Lookout),
    /// Done (or found no open floor there).
    Done,
}

/// A search for an object exploring the open floor (see [`State::explore`]).
#[derive(Clone, Copy, Debug)]
struct Lookout {
    /// The point it heads for, or looks round from.
    at: DVec2,
    /// The leg to it.
    visit: Visit,
}

impl State {
    /// The next step of a search for an object that has gone on for
    /// [`EXPLORE_AFTER`] without finding it (neither where teammates are
    /// nor near where it wandered): first, a teammate within
    /// [`MATE_NEAR`] that may have hidden the object all along, to its far
    /// side; then to the open floor farthest from every
    /// place it has looked round from, any [`LOOK_APART`] m off being far
    /// enough and the nearest of those first (`Map::lookout`); there (within
    /// [`ARRIVED`], or after [`LOOKOUT_TIME`] on the way) a look all round,
    /// and on to the next. Once every point of the floor is within
    /// [`LOOKED_NEAR`] of a place looked from, it starts over.
    fn explore(&mut self, view: &View, map: &crate::plan::Map, mate: Option<DVec2>) -> Schema {
        let (pos, now) = (view.pose.pos, view.skill_time);
        let clear = 2.0 * view.radius;
        if self.looked.is_empty() {
            // Where it searched until now.
            self.looked.push(pos);
            // A teammate near may have hidden the object from it all
            // along (one standing aside in front of the box): first the
            // far side of it, [`VANTAGE`] m beyond.
            let beyond = mate
                .filter(|m| m.distance(pos) < MATE_NEAR && m.distance(pos) > 1e-6)
                .map(|m| past(m, pos, 0.0))
                .filter(|p| map.open(*p, clear));
            if let Some(at) = beyond {
                self.lookout = Some(Lookout {
                    at,
                    visit: Visit::new(now),
                });
            }
        }
        match &mut self.lookout {
            Some(l) if l.visit.looking => {
                if l.visit.still_looking(now) {
                    return Schema::LookAround;
                }
                self.looked.push(pos);
                self.lookout = None;
            }
            Some(l) => return l.visit.head(l.at, pos, now, LOOKOUT_TIME),
            None => {}
        }
        let mut next = map.lookout(&self.looked, pos, LOOK_APART, clear);
        if next.is_some_and(|(_, far)| far < LOOKED_NEAR) {
            self.looked = vec![pos];
            next = map.lookout(&self.looked, pos, LOOK_APART, clear);
        }
        match next {
            Some((at, _)) => {
                self.lookout = Some(Lookout {
                    at,
                    visit: Visit::new(now),
                });
                Schema::MoveToGoal {
                    goal: Target::Point(at),
                    speed: SEARCH_SPEED,
                }
            }
            None => Schema::Wander {
                speed: SEARCH_SPEED,
                period: 2.0,
            },
        }
    }

    /// The next step of a search heading past a live teammate (see
    /// [`command`]), at `pos` at skill time `now`: `None` once it has
    /// looked round there.
    fn go_beyond(&mut self, pos: DVec2, now: f64) -> Option<Schema> {
        let Beyond::Going(l) = &mut self.beyond else {
            return None;
        };
        if !l.visit.looking {
            return Some(l.visit.head(l.at, pos, now, VANTAGE_TIME));
        }
        if l.visit.still_looking(now) {
            return Some(Schema::LookAround);
        }
        self.beyond = Beyond::Done;
        None
    }

    /// The next step of a search round `centre` (see [`vantage`]): to the
    /// next vantage point (until within [`ARRIVED`] of it, or after
    /// [`VANTAGE_TIME`] on the way), a look all round there, and on.
    fn circle_round(&mut self, view: &View, centre: DVec2) -> Schema {
        let (pos, now) = (view.pose.pos, view.skill_time);
        let c = self.circle.get_or_insert_with(|| {
            let d = pos - centre;
            Circle {
                from: d.y.atan2(d.x),
                k: 0,
                visit: Visit::new(now),
            }
        });
        if c.visit.looking {
            if c.visit.still_looking(now) {
                return Schema::LookAround;
            }
            c.k += 1;
            c.visit = Visit::new(now);
        }
        match vantage(view, centre, c.from, c.k) {
            Some(p) => c.visit.head(p, pos, now, VANTAGE_TIME),
            None => Schema::Wander {
                speed: SEARCH_SPEED,
                period: 2.0,
            },
        }
    }
}

/// One schema's output, before fusion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Output {
    /// Desired velocity.
    pub v: DVec2,
    /// Heading to face.
    pub face: Option<f64>,
}

fn clamp_len(v: DVec2, max: f64) -> DVec2 {
    let l = v.length();
    if l > max && l > 0.0 { v * (max / l) } else { v }
}

fn target_point(view: &View, t: &Target) -> Option<DVec2> {
    match t {
        Target::Point(p) => Some(*p),
        Target::Direction(d) => Some(view.pose.pos + d.normalize_or_zero()),
        Target::Object(name) => view.objects.get(name).copied(),
    }
}

/// `avoid-obstacle`: away from every range reading closer than `range`,
/// but a ray that ends on a teammate in sight (avoid-teammate answers for
/// it) and, when `shoving`, one that ends on a lost teammate's body (the
/// robot pushes it out of its way: see [`command`]).
fn avoid_obstacle(view: &View, range: f64, shoving: bool) -> Option<Output> {
    let pose = view.pose;
    let on = |hit: DVec2, p: DVec2| p.distance(hit) < view.radius + 0.06;
    let mut v = DVec2::ZERO;
    for (angle, d) in &view.rays {
        if *d < range {
            let dir = DVec2::from_angle(pose.heading + angle);
            let hit = pose.pos + dir * (d + view.radius);
            if view.mates.values().any(|m| on(hit, m.pos))
                || (shoving && view.bodies.iter().any(|b| on(hit, *b)))
            {
                continue;
            }
            let away = -dir;
            v += away * ((range - d) / range) * view.max_speed;
        }
    }
    (v != DVec2::ZERO).then_some(Output { v, face: None })
}

/// Where to steer to reach `to`: `to`, or the next point of a detour round
/// a lost teammate's body in the way (see [`crate::plan`]), and round the
/// objects it has seen but `own` (where the object its schema drives to or
/// pushes is).
fn aim(view: &View, state: &mut State, to: DVec2, own: Option<DVec2>) -> DVec2 {
    let trapped = state.trapped.is_some();
    // Gathered only when it plans: the objects it has seen and, trapped,
    // what its rays hit (an object or a teammate the map does not hold).
    let sensed = |map: &crate::plan::Map| {
        let mut discs = map.objects_seen(&view.objects, own);
        if trapped {
            discs.extend(view.rays.iter().map(|(a, d)| {
                let dir = DVec2::from_angle(view.pose.heading + a);
                (view.pose.pos + dir * (d + view.radius), 0.0)
            }));
        }
        discs
    };
    crate::plan::aim(
        view.map.as_deref(),
        &view.bodies,
        &mut state.route,
        view.skill_time,
        (view.pose.pos, to),
        (trapped, sensed),
    )
}

/// Seconds a robot driving to a goal more than [`TRAP_FAR`] m away may
/// make no headway (come no more than [`HEADWAY`] m nearer to it than it
/// has been) before it counts as trapped (see [`command`]).
pub const TRAPPED_AFTER: f64 = 5.0;
/// Seconds a trapped robot follows its planned detour before it drives
/// straight to its goal again.
pub const DETOUR: f64 = 8.0;
const TRAP_FAR: f64 = 0.5;
/// A pusher getting behind its object is not done until it stands there (a
/// move-to-goal's `reached` ends it near its goal): one held off the place
/// behind the object nearer than [`TRAP_FAR`] (between the object and a
/// wall, say, its way round the object into the wall) is trapped too, once
/// it has made no headway for this many times [`TRAPPED_AFTER`] (a pusher
/// lining up behind its object, or shoving it about, is slow there, not
/// trapped).
const PUSH_NEAR_PATIENCE: f64 = 3.0;
/// How near the place behind its object that holds, m.
const PUSH_TRAP_FAR: f64 = 0.2;
const HEADWAY: f64 = 0.15;
/// A step of a skill (`State::marks`): this much nearer its goal than it
/// has been.
const MARK_NEARER: f64 = 0.05;
/// A trapped robot pushes a lost teammate's body that blocks its only way
/// when the body is ahead of it and this near its own (m between them).
const SHOVE_NEAR: f64 = 0.2;
/// Seconds a wandering robot may stay within [`PIN_RADIUS`] m of one spot
/// before it counts as pinned there (see `State::watch_roaming`).
pub const PINNED_AFTER: f64 = 10.0;
/// Seconds a robot searching for its object may stay within
/// [`PIN_RADIUS`] m of one spot before its search counts as pinned there
/// (see `State::watch_search`): two of its looks round and moves (a move
/// on open floor takes it 0.75 m; a look round from a lookout or vantage
/// point stays put for one look).
pub const SEARCH_PINNED_AFTER: f64 = 2.0 * (SEARCH_TURN + SEARCH_MOVE);
const PIN_RADIUS: f64 = 0.5;
/// How far off the open floor a pinned robot heads for is, m, and how
/// many random points it tries.
const ESCAPE: f64 = 2.0;
const ESCAPE_DRAWS: usize = 16;

/// Where a formation slot is, behind a reference at `pos` heading `heading`.
pub fn slot_position(pos: DVec2, heading: f64, side: Side, distance: f64) -> DVec2 {
    let (back, lateral) = match side {
        Side::Left => (-0.707, 0.707),
        Side::Right => (-0.707, -0.707),
        Side::Behind => (-1.0, 0.0),
    };
    let fwd = DVec2::from_angle(heading);
    pos + (fwd * back + fwd.perp() * lateral) * distance
}

/// Waypoints of a boustrophedon sweep of `region`, lanes along x.
pub fn scan_waypoints(region: [f64; 4], spacing: f64) -> Vec<DVec2> {
    let [x0, y0, x1, y1] = region;
    let (xa, xb) = (x0.min(x1), x0.max(x1));
    let (ya, yb) = (y0.min(y1), y0.max(y1));
    let spacing = spacing.max(0.05);
    // Lanes end half a lane inside the region, so a waypoint by a wall can
    // be reached.
    let inset = (spacing / 2.0).min((xb - xa) / 2.0);
    let (xa, xb) = (xa + inset, xb - inset);
    let mut pts = Vec::new();
    let mut y = ya + spacing / 2.0;
    let mut forward = true;
    while y <= yb + 1e-9 {
        let (a, b) = if forward { (xa, xb) } else { (xb, xa) };
        pts.push(DVec2::new(a, y.min(yb)));
        pts.push(DVec2::new(b, y.min(yb)));
        forward = !forward;
        y += spacing;
    }
    // A region thinner than half a lane (a strip of a large team's
    // split) still has its lane, along its middle: without it the sweep
    // would be over before it began.
    if pts.is_empty() {
        let mid = (ya + yb) / 2.0;
        pts.push(DVec2::new(xa, mid));
        pts.push(DVec2::new(xb, mid));
    }
    pts
}

/// Seconds a pushing robot turns in place looking for an object that was
/// not where it was last seen (about a full turn).
pub const SEARCH_TURN: f64 = 6.0;

/// Seconds a robot searching for an object it does not know where to find
/// moves between two turns in place (see [`command`]), and how fast.
pub const SEARCH_MOVE: f64 = 5.0;
const SEARCH_SPEED: f64 = 0.15;

/// Seconds a robot turns in place (`look-around`) seeing no live teammate
/// before it goes to look for them (several whole turns at the top turn
/// rate of any robot in the shipped scenarios, 2.5 to 3 rad/s).
pub const LOOK_IN_VAIN: f64 = 10.0;

/// A robot going back to where it last saw a teammate is there this near
/// it, m.
const BACK_WHERE_SEEN: f64 = 0.5;

/// Cell `rank` of `n` when `region` is split into `n` cells of equal area,
/// about square: `rows ≈ √(n·h/w)` rows holding `n / rows` or one more
/// cells each, each row as tall as its share of the cells.
pub fn split_cell(region: [f64; 4], rank: u32, n: u32) -> [f64; 4] {
    let [x0, y0, x1, y1] = region;
    let (xa, xb) = (x0.min(x1), x0.max(x1));
    let (ya, yb) = (y0.min(y1), y0.max(y1));
    let n = n.max(1);
    let rank = rank.min(n - 1);
    let (w, h) = ((xb - xa).max(1e-9), (yb - ya).max(1e-9));
    let rows = ((n as f64 * h / w).sqrt().round() as u32).clamp(1, n);
    // The first `extra` rows hold one more cell.
    let (base, extra) = (n / rows, n % rows);
    let count = |r: u32| base + u32::from(r < extra);
    let (mut row, mut first) = (0, 0);
    while rank >= first + count(row) {
        first += count(row);
        row += 1;
    }
    let in_row = count(row);
    let col = rank - first;
    let bottom = ya + h * first as f64 / n as f64;
    let top = ya + h * (first + in_row) as f64 / n as f64;
    let cw = w / in_row as f64;
    [
        xa + cw * col as f64,
        bottom,
        xa + cw * (col + 1) as f64,
        top,
    ]
}

/// The output of one schema, or `None` when it is not active.
pub fn evaluate(
    schema: &Schema,
    view: &View,
    state: &mut State,
    rng: &mut impl FnMut() -> f64,
) -> Option<Output> {
    let pose = view.pose;
    let out = |v: DVec2| Some(Output { v, face: None });
    match schema {
        Schema::MoveToGoal { goal, speed } => match goal {
            Target::Direction(d) => out(d.normalize_or_zero() * *speed),
            _ => {
                let p = target_point(view, goal)?;
                state.bound_for = Some(p);
                // Arrive: slow down over the last 0.3 m.
                let s = speed * ((p - pose.pos).length() / 0.3).min(1.0);
                let own = matches!(goal, Target::Object(_)).then_some(p);
                let to = aim(view, state, p, own) - pose.pos;
                out(to.normalize_or_zero() * s)
            }
        },
        Schema::AvoidObstacle { range } => avoid_obstacle(view, *range, false),
        Schema::AvoidTeammate { range } => {
            let mut v = DVec2::ZERO;
            for m in view.mates.values() {
                let off = pose.pos - m.pos;
                let d = off.length();
                if d < *range && d > 1e-6 {
                    v += off / d * ((range - d) / range) * view.max_speed;
                }
            }
            (v != DVec2::ZERO).then_some(Output { v, face: None })
        }
        Schema::KeepSlot {
            of,
            side,
            distance,
            speed,
        } => {
            let r = view.roles.get(of)?;
            let m = view.mates.get(r)?;
            let h = m.heading.unwrap_or(pose.heading);
            let fwd = DVec2::from_angle(h);
            let slot = slot_position(m.pos, h, *side, *distance);
            let slot = aim(view, state, slot, None);
            // Proportional to the slot error, plus the reference's pace.
            let v = (slot - pose.pos) * 1.5 + fwd * speed * 0.8;
            out(clamp_len(v, speed * 1.5))
        }
        Schema::Follow {
            of,
            distance,
            speed,
        } => {
            let r = view.roles.get(of)?;
            let m = view.mates.get(r)?;
            let gap = (m.pos - pose.pos).length() - distance;
            let to = aim(view, state, m.pos, None) - pose.pos;
            let v = to.normalize_or_zero() * (gap * 1.5).clamp(-*speed, *speed * 1.5);
            out(v)
        }
        Schema::Wander { speed, period } => {
            // Pinned (see `State::watch_roaming`): head for open floor a
            // few metres off, drawn at random among the open points, on a
            // planned detour.
            match (state.trapped, view.map.as_deref()) {
                (Some(_), Some(map)) => {
                    if state.escape.is_none() {
                        state.escape = (0..ESCAPE_DRAWS)
                            .map(|_| {
                                let a = rng() * std::f64::consts::TAU;
                                pose.pos + DVec2::from_angle(a) * ESCAPE
                            })
                            .find(|p| map.open(*p, 2.0 * view.radius));
                    }
                    if let Some(p) = state.escape {
                        let goal = Target::Point(p);
                        let speed = *speed;
                        return evaluate(&Schema::MoveToGoal { goal, speed }, view, state, rng);
                    }
                }
                (None, _) => state.escape = None,
                (Some(_), None) => {}
            }
            let fresh = state
                .wander
                .is_none_or(|(_, at)| view.skill_time - at >= *period || view.skill_time < at);
            if fresh {
                let turn = (rng() - 0.5) * std::f64::consts::PI;
                state.wander = Some((pose.heading + turn, view.skill_time));
            }
            let h = state.wander.map_or(pose.heading, |(h, _)| h);
            out(DVec2::from_angle(h) * *speed)
        }
        Schema::Scan {
            region,
            spacing,
            speed,
            split,
            patience,
        } => {
            // The waypoint it heads for is kept: the lanes are made again
            // only when it moves on to the next (or the robot's rank or its
            // team's size changed), not at every tick.
            let key = (*region, *spacing, *split, view.rank);
            let waypoint = |i: usize| {
                let cell = match *split {
                    true => split_cell(*region, view.rank.0, view.rank.1),
                    false => *region,
                };
                scan_waypoints(cell, *spacing).get(i).copied()
            };
            let mut next = match state.lanes {
                Some((k, i, p)) if k == key && i == state.waypoint => p,
                _ => waypoint(state.waypoint),
            };
            while let Some(p) = next {
                let d = p.distance(pose.pos);
                let stuck = match state.approach {
                    // Closer by 5 cm: progress.
                    Some((best, _)) if d < best - MARK_NEARER => {
                        state.approach = Some((d, view.skill_time));
                        state.marks = state.marks.saturating_add(1);
                        false
                    }
                    Some((_, since)) => view.skill_time - since > *patience,
                    None => {
                        state.approach = Some((d, view.skill_time));
                        false
                    }
                };
                if d < 0.2 || stuck {
                    state.skipped += u32::from(stuck && d >= 0.2);
                    state.marks = state.marks.saturating_add(1);
                    state.waypoint += 1;
                    state.approach = None;
                    next = waypoint(state.waypoint);
                } else {
                    break;
                }
            }
            state.lanes = Some((key, state.waypoint, next));
            match next {
                Some(p) => out((p - pose.pos).normalize_or_zero() * *speed),
                None => {
                    state.finished = true;
                    Some(Output {
                        v: DVec2::ZERO,
                        face: None,
                    })
                }
            }
        }
        Schema::Face { target } => {
            let p = target_point(view, target)?;
            let to = p - pose.pos;
            (to.length() > 1e-6).then(|| Output {
                v: DVec2::ZERO,
                face: Some(to.y.atan2(to.x)),
            })
        }
        Schema::Push {
            object,
            goal,
            offset,
            speed,
        } => {
            let o = *view.objects.get(object)?;
            // Looking at the place it was last seen, close by, and it is not
            // there: it has been moved (by a teammate, out of this robot's
            // sight). Look round for it rather than circle an empty spot.
            let to = o - pose.pos;
            let facing = wrap(to.y.atan2(to.x) - pose.heading).abs() < 0.6;
            if view.in_view.contains(object) {
                state.search = None;
                state.gone = false;
            } else {
                // Not where it was last seen, nor anywhere in a full turn
                // from there: as good as never seen, until it is seen
                // again (`command` has it search).
                if state.gone {
                    return None;
                }
                // Unless a lost teammate's body stands between, or a wall
                // or an obstacle of the map: it hides the object, which may
                // well be there (a pusher going round a chair to get behind
                // its object lost it behind the chair, looked round, saw it
                // again from the same spot and headed back into the chair,
                // for good: docs/reliability.md, "An object behind a
                // chair").
                let behind_body = view.bodies.iter().any(|b| {
                    b.distance(pose.pos) < to.length()
                        && crate::plan::segment_distance(pose.pos, o, *b) < view.radius * 1.5
                });
                let behind_wall = view.map.as_deref().is_some_and(|m| m.hides(pose.pos, o));
                if behind_wall {
                    // A look round begun before the map was made to tell.
                    state.search = None;
                } else if state.search.is_none()
                    && facing
                    && to.length() < offset * 2.0
                    && !behind_body
                {
                    state.search = Some(view.skill_time);
                    // Made for the next tick, to tell whether a wall or an
                    // obstacle hides it.
                    state.sighting |= view.map.is_none();
                }
            }
            // A full turn at most; then it is lost.
            match state.search {
                Some(t0) if view.skill_time - t0 < SEARCH_TURN => {
                    return evaluate(&Schema::LookAround, view, state, rng);
                }
                Some(_) => {
                    state.search = None;
                    state.gone = true;
                    return None;
                }
                None => {}
            }
            let dir = (*goal - o).normalize_or_zero();
            if dir == DVec2::ZERO || goal.distance(o) < 0.05 {
                return Some(Output {
                    v: DVec2::ZERO,
                    face: None,
                });
            }
            let dir = push_way(view, state, (o, *goal), *offset).unwrap_or(dir);
            let dir = push_direction(view, state, o, dir, *offset);
            let behind = o - dir * *offset;
            let rel = pose.pos - o;
            let along = rel.dot(dir); // < 0: behind the object
            let lateral = rel.dot(dir.perp());
            if along < -offset * 0.6 && lateral.abs() < offset * 0.35 {
                // An object pushed that has made no headway toward the
                // goal for a while may be stuck on a wall or an obstacle
                // in its straight way: its way round is planned on the map
                // (without a map, a robot pushes straight; made for every
                // push, the map's ways made other runs slower:
                // docs/reliability.md, "A box pushed against a chair with
                // no one lost").
                let (d, now) = (goal.distance(o), view.skill_time);
                match state.object_headway {
                    Some((best, at)) if d >= best - HEADWAY && now >= at => {
                        state.pushing |= now - at >= TRAPPED_AFTER;
                    }
                    _ => state.object_headway = Some((d, now)),
                }
                // In position: drive through the object toward the goal,
                // steering back onto the line through it.
                let v = dir * *speed - dir.perp() * lateral * 2.0;
                return out(clamp_len(v, *speed));
            }
            // Get behind it, going round it rather than into it (or, when
            // trapped on the way, by a planned detour clear of it).
            state.object_headway = None;
            state.bound_for = Some(behind);
            let mut v = (behind - pose.pos).normalize_or_zero() * *speed;
            if state.trapped.is_some() {
                v = (aim(view, state, behind, Some(o)) - pose.pos).normalize_or_zero() * *speed;
            } else if along > -offset * 0.6 && rel.length() < offset * 1.6 {
                let around = if lateral >= 0.0 {
                    dir.perp()
                } else {
                    -dir.perp()
                };
                v = (around - dir * 0.5).normalize_or_zero() * *speed;
            }
            out(v)
        }
        Schema::LookAround => Some(Output {
            v: DVec2::ZERO,
            face: Some(pose.heading + std::f64::consts::FRAC_PI_2),
        }),
        Schema::Stop => out(DVec2::ZERO),
    }
}

/// A lost teammate's body this near the place an object was last seen was
/// most likely at work on it (m): a robot searching for the object looks
/// round the body (see [`vantage`]).
const BODY_NEAR_OBJECT: f64 = 2.5;
/// A lost teammate's body this near the way from the place a pushed object
/// was last seen to its goal was pushing it (m): the object is most likely
/// beside it, hidden by it, however far along (see [`command`]).
const BODY_ON_THE_WAY: f64 = 0.5;

/// A robot searching round a body is at a vantage point this near it, m.
const ARRIVED: f64 = 0.25;
/// Seconds a robot searching round a body heads for one vantage point at
/// most (it may not get there: the body, the object itself in the way).
const VANTAGE_TIME: f64 = 15.0;

/// Seconds a robot searches for an object it has not found by heading for
/// teammates (at work on it, most likely near it) and wandering, before it
/// explores the open floor instead (see [`State::explore`]; once it does,
/// it keeps exploring until it finds the object): a teammate that follows
/// it (a watcher trailing its pusher) keeps it where it is, and wandering
/// covers a hall slowly ...
const EXPLORE_AFTER: f64 = 40.0;
/// ... and once it has looked round this many times with a teammate within
/// [`MATE_NEAR`] m (or knows of none): the team is not near the object,
/// or a teammate follows it. A teammate near the object may hide it from
/// one side and not from the next, which moving round it shows.
const LOOKS_NEAR_MATE: u32 = 3;
const MATE_NEAR: f64 = 1.5;
/// An exploring robot looks round from places this far apart where it can,
/// m (half a camera's usual range: the hall between two of them is seen
/// from one or the other).
const LOOK_APART: f64 = 2.5;
/// Once every point of the open floor is this near a place an exploring
/// robot has looked round from, m, it starts over.
const LOOKED_NEAR: f64 = 1.0;
/// Seconds an exploring robot heads for one lookout at most.
const LOOKOUT_TIME: f64 = 30.0;

/// How far a search past a live teammate goes round it from its far side
/// (radians; see [`command`]).
const BEYOND_TURN: f64 = std::f64::consts::FRAC_PI_3;

/// A point [`VANTAGE`] m past a teammate at `mate`, seen from `pos`: on
/// its far side, turned `turn` radians round it (0: straight beyond it, as
/// exploring's first lookout; [`BEYOND_TURN`]: round it, as a search's
/// first leg, see [`command`]).
fn past(mate: DVec2, pos: DVec2, turn: f64) -> DVec2 {
    mate + DVec2::from_angle(turn).rotate((mate - pos).normalize()) * VANTAGE
}

/// How far from the body it searches round a robot looks for its object
/// from, m (see [`vantage`]).
const VANTAGE: f64 = 1.0;

/// The `k`-th vantage point of a robot searching round `centre`, a lost
/// teammate's body, for an object that is not where it was last seen, near
/// the body (each point followed by a look all round): [`VANTAGE`] m off,
/// a sixth of a turn further each time, from the bearing `from` (where it
/// stood when the search began). Seen from one side, a teammate's body,
/// crashed where it pushed, can hide the object; from the next, it does
/// not. Points off the open floor are passed over; `None` if the whole
/// round is.
fn vantage(view: &View, centre: DVec2, from: f64, k: usize) -> Option<DVec2> {
    let step = std::f64::consts::FRAC_PI_3;
    (0..6)
        .map(|j| centre + DVec2::from_angle(from + step * ((k + j) % 6 + 1) as f64) * VANTAGE)
        .find(|p| view.map.as_ref().is_none_or(|m| m.open(*p, view.radius)))
}

/// How often a pusher plans its object's way again while the straight way
/// to the goal is not clear, s.
const OBJECT_REPLAN: f64 = 1.0;

/// The direction a pusher drives its object `o` in on the way to `goal`
/// when a wall or obstacle stands in the straight way (the object would
/// run into it, however it is turned, or stands against it): toward a
/// point up to [`OBJECT_LOOKAHEAD`](crate::plan::OBJECT_LOOKAHEAD) m ahead on
/// the object's planned way round it, one it gets to in a straight line
/// without coming nearer the obstacle (`Map::object_aim`; the way planned
/// again every [`OBJECT_REPLAN`] s). `None` (straight for the goal) where
/// the way is clear, the map or the object's size unknown, there is no way
/// round, or the place to push from, `offset` behind the object, is not
/// open floor.
fn push_way(
    view: &View,
    state: &mut State,
    (o, goal): (DVec2, DVec2),
    offset: f64,
) -> Option<DVec2> {
    let map = view.map.as_deref()?;
    let Some(size) = map.size_at(&view.objects, o) else {
        state.object_way = None;
        return None;
    };
    let reach = size.0;
    if map.object_way_clear(o, goal, size) {
        state.object_way = None;
        return None;
    }
    let now = view.skill_time;
    let stale = state.object_way.as_ref().is_none_or(|(at, to, _)| {
        now - at >= OBJECT_REPLAN || now < *at || to.distance(goal) > 0.05
    });
    if stale {
        let path = map.object_route(o, goal, reach).unwrap_or_default();
        state.object_way = Some((now, goal, path));
    }
    let (_, _, path) = state.object_way.as_ref()?;
    let ahead = map.object_aim(path, o, reach, crate::plan::OBJECT_LOOKAHEAD)?;
    // Only where the robot can stand to push that way (not in the obstacle
    // the object is pushed off).
    Some((ahead - o).normalize_or_zero())
        .filter(|d| *d != DVec2::ZERO && map.open(o - *d * offset, 0.0))
}

/// Turns from the goal's direction, in order of preference, a pusher may
/// push its object in when a body blocks the place behind it (radians: 45°
/// to 90°, either way).
const PUSH_TURNS: [f64; 4] = [
    std::f64::consts::FRAC_PI_4,
    std::f64::consts::FRAC_PI_3,
    5.0 * std::f64::consts::PI / 12.0,
    std::f64::consts::FRAC_PI_2,
];

/// The direction a pusher pushes its object `o` in, `dir` being the
/// goal's. Where a lost teammate's body (it crashed while pushing, say)
/// stands behind the object, the robot cannot get there: it pushes the
/// object aside, at the smallest of [`PUSH_TURNS`] whose place to push
/// from and whose way in to the object are clear of every body (and the
/// object's way ahead of the map's walls and obstacles), the turn that
/// leaves it the shorter walk first. It keeps that turn until the place
/// behind the object, for the goal's direction, is clear again with room
/// to spare; then it pushes straight for the goal. With no body in view
/// (no teammate presumed lost), the goal's direction.
fn push_direction(view: &View, state: &mut State, o: DVec2, dir: DVec2, offset: f64) -> DVec2 {
    if view.bodies.is_empty() {
        state.push_turn = None;
        return dir;
    }
    // A robot's centre this near a body's would overlap it (two radii and
    // a margin), at the place to push from or on the way in to the object.
    let clear = view.radius * 2.0 + crate::plan::MARGIN;
    let room = |d: DVec2, spare: f64| {
        let (from, contact) = (o - d * offset, o - d * (offset * 0.6));
        view.bodies
            .iter()
            .all(|b| b.distance(from) >= clear + spare && b.distance(contact) >= clear + spare)
    };
    if room(dir, if state.push_turn.is_some() { 0.1 } else { 0.0 }) {
        state.push_turn = None;
        return dir;
    }
    if let Some(turn) = state.push_turn {
        return DVec2::from_angle(turn).rotate(dir);
    }
    // The side of the object the robot is on: a turn toward it puts the
    // place to push from on the robot's side.
    let side = if (view.pose.pos - o).dot(dir.perp()) < 0.0 {
        1.0
    } else {
        -1.0
    };
    let ahead_open = |d: DVec2| {
        view.map
            .as_ref()
            .is_none_or(|m| m.open(o + d * offset, 0.0) && m.open(o - d * offset, 0.0))
    };
    for turn in PUSH_TURNS {
        for t in [turn * side, -turn * side] {
            let d = DVec2::from_angle(t).rotate(dir);
            if room(d, 0.0) && ahead_open(d) {
                state.push_turn = Some(t);
                return d;
            }
        }
    }
    dir
}

/// Command fusion: superpose the active schemas of the highest active
/// layer, weighted by their gains; a `face` request comes from the active
/// face schema of that layer with the largest gain.
pub fn fuse(outputs: &[(u8, f64, Option<Output>)]) -> Command {
    let Some(top) = outputs
        .iter()
        .filter(|(_, _, o)| o.is_some())
        .map(|(l, _, _)| *l)
        .max()
    else {
        return Command::default();
    };
    let mut v = DVec2::ZERO;
    let mut face: Option<(f64, f64)> = None;
    for (layer, gain, o) in outputs {
        if *layer != top {
            continue;
        }
        if let Some(o) = o {
            v += o.v * *gain;
            if let Some(h) = o.face
                && face.is_none_or(|(g, _)| *gain > g)
            {
                face = Some((*gain, h));
            }
        }
    }
    Command {
        v,
        face: face.map(|(_, h)| h),
        layer: Some(top),
        label: Label::default(),
    }
}

/// Run a skill's schemas and fuse them.
pub fn command(
    skill: &[Weighted],
    view: &View,
    states: &mut Vec<State>,
    rng: &mut impl FnMut() -> f64,
) -> Command {
    states.resize_with(skill.len(), State::default);
    let mut outputs: Vec<(u8, f64, Option<Output>)> = skill
        .iter()
        .zip(states.iter_mut())
        .map(|(w, s)| {
            s.bound_for = None;
            (w.layer, w.gain, evaluate(&w.schema, view, s, rng))
        })
        .collect();
    // A robot that drives to a goal (its move-to-goal wants to move, or its
    // push to get behind the object, and only avoidance overrides it) but
    // makes no headway for a while is
    // trapped: in a pocket between obstacles where attraction and
    // repulsion cancel, or dithering between two ways out. It follows a
    // planned detour clear of the obstacles for a while (`aim`), then
    // drives straight again.
    for (i, w) in skill.iter().enumerate() {
        let st = &mut states[i];
        let to = st.bound_for.map_or(0.0, |p| p.distance(view.pose.pos));
        let push = matches!(w.schema, Schema::Push { .. });
        let (far, patience) = match push {
            true if to <= TRAP_FAR => (PUSH_TRAP_FAR, TRAPPED_AFTER * PUSH_NEAR_PATIENCE),
            _ => (TRAP_FAR, TRAPPED_AFTER),
        };
        let drives = st.bound_for.is_some()
            && to > far
            && outputs[i].2.is_some_and(|o| o.v.length() > 0.02)
            && skill
                .iter()
                .zip(&outputs)
                .all(|(v, (_, _, o))| o.is_none() || v.layer <= w.layer || v.schema.avoids());
        st.watch_headway(drives, to, view.skill_time, patience);
        if st.bound_for.is_some() {
            match st.nearest {
                Some(best) if to >= best - MARK_NEARER => {}
                Some(_) => {
                    st.nearest = Some(to);
                    st.marks = st.marks.saturating_add(1);
                }
                None => st.nearest = Some(to),
            }
        }
        if matches!(w.schema, Schema::Wander { .. }) {
            st.watch_roaming(view.pose.pos, view.skill_time, PINNED_AFTER);
        }
    }
    // A lost teammate's body blocking the only way to a goal (a robot
    // crashed in a corridor, with no way round it: the trapped robot's
    // planner found none) is pushed out of the way, as an object is: the
    // robot drives on to its goal and its obstacle avoidance no longer
    // answers for what its rays see of the body. It keeps pushing while
    // the body is ahead of it, near, and short of the goal.
    let mut shove = false;
    for (w, st) in skill.iter().zip(states.iter_mut()) {
        if !matches!(w.schema, Schema::MoveToGoal { .. }) {
            continue;
        }
        let pos = view.pose.pos;
        let blocks = st.bound_for.is_some_and(|goal| {
            (view.bodies.iter()).any(|b| {
                b.distance(pos) < 2.0 * view.radius + SHOVE_NEAR
                    && (*b - pos).dot(goal - pos) > 0.0
                    && b.distance(pos) < goal.distance(pos)
            })
        });
        let no_way = st.trapped.is_some() && st.route.as_ref().is_some_and(|r| !r.leads());
        st.shoving = blocks && (st.shoving || no_way);
        shove |= st.shoving;
    }
    if shove {
        for (w, o) in skill.iter().zip(outputs.iter_mut()) {
            if let Schema::AvoidObstacle { range } = w.schema {
                o.2 = avoid_obstacle(view, range, true);
            }
        }
    }
    // Nothing to do but keep clear, because the object the skill works on
    // was never seen (a restarted robot has forgotten it; a teammate found
    // it), or was not found where it was last seen: search for it rather
    // than stand still or turn on the spot for ever. A turn in place to look
    // all round, as `look-around` does; then, if it is still unseen (out of
    // range, or hidden behind a teammate), move a while and look again.
    let idle = skill
        .iter()
        .zip(&outputs)
        .all(|(w, (_, _, o))| o.is_none() || w.schema.avoids());
    let unseen = skill.iter().zip(states.iter()).position(|(w, st)| {
        st.gone
            || w.schema
                .object()
                .is_some_and(|o| !view.objects.contains_key(o))
    });
    match unseen {
        Some(i) if idle => {
            let st = &mut states[i];
            let since = *st.lost.get_or_insert(view.skill_time);
            let phase = (view.skill_time - since).max(0.0) % (SEARCH_TURN + SEARCH_MOVE);
            // Between turns, toward the nearest teammate farther than a
            // metre (the team is at work on the object, most likely near
            // it), else anywhere.
            let pos = view.pose.pos;
            let nearest = (view.mates.values())
                .map(|m| m.pos)
                .filter(|p| !view.bodies.iter().any(|b| b.distance(*p) < 0.05))
                .min_by(|a, b| a.distance(pos).total_cmp(&b.distance(pos)));
            // The object seen before, where it is not now, and a lost
            // teammate's body near that place: the teammate was at work on
            // it when lost (pushing it, most likely, further than this robot
            // saw), and its body may hide it. Round the body.
            // A pushed object goes from there toward its goal: a body on
            // that way, however far along, was pushing it too.
            let pushed_to = match &skill[i].schema {
                Schema::Push { goal, .. } => Some(*goal),
                _ => None,
            };
            let last_seen = (skill[i].schema.object()).and_then(|o| view.objects.get(o).copied());
            let centre = last_seen.and_then(|last| {
                (view.bodies.iter().copied())
                    .filter(|b| {
                        b.distance(last) < BODY_NEAR_OBJECT
                            || pushed_to.is_some_and(|g| {
                                crate::plan::segment_distance(last, g, *b) < BODY_ON_THE_WAY
                            })
                    })
                    .min_by(|a, b| a.distance(last).total_cmp(&b.distance(last)))
            });
            let to_mate = nearest.filter(|p| p.distance(pos) > 1.0);
            // Looks round with a teammate near, counted once a turn: the
            // team is not where the object is (or a follower keeps near).
            let turn = ((view.skill_time - since).max(0.0) / (SEARCH_TURN + SEARCH_MOVE)) as u32;
            if phase < SEARCH_TURN
                && nearest.is_some_and(|p| p.distance(pos) < MATE_NEAR)
                && st.looks_near_mate.1 != Some(turn)
            {
                st.looks_near_mate = (st.looks_near_mate.0 + 1, Some(turn));
            }
            let explore = (view.map.as_deref()).filter(|_| {
                let long = view.skill_time - since >= EXPLORE_AFTER;
                let in_vain = st.looks_near_mate.0 >= LOOKS_NEAR_MATE || nearest.is_none();
                // Pinned with no teammate to head for (wandering beside
                // one): explore rather than wander off at random.
                let pinned = st.search_moves.trapped.is_some() && to_mate.is_none();
                st.lookout.is_some() || (long && in_vain) || pinned
            });
            // After a look round in vain for an object seen before, a live
            // teammate near may stand between this robot and the object
            // (pushed on out of its sight, the teammate now in front of
            // it): past the teammate, [`VANTAGE`] m from it, and a look
            // round there, once a search. Not when a body is searched round
            // instead.
            if matches!(st.beyond, Beyond::NotYet)
                && let Some(last) = last_seen
                && centre.is_none()
                && st.lookout.is_none()
                && view.skill_time - since >= SEARCH_TURN
                && let Some(m) =
                    nearest.filter(|m| m.distance(pos) < MATE_NEAR && m.distance(pos) > 1e-6)
            {
                // Round the teammate, not through it (driving straight at
                // it can drive it on ahead): a sixth of a turn off its far
                // side, toward where the object was last seen first.
                let (a, b) = (past(m, pos, BEYOND_TURN), past(m, pos, -BEYOND_TURN));
                let (a, b) = if a.distance(last) <= b.distance(last) {
                    (a, b)
                } else {
                    (b, a)
                };
                let open = |p: &DVec2| {
                    (view.map.as_deref()).is_none_or(|map| map.open(*p, 2.0 * view.radius))
                };
                st.beyond = match [a, b].into_iter().find(open) {
                    Some(at) => Beyond::Going(Lookout {
                        at,
                        visit: Visit::new(view.skill_time),
                    }),
                    None => Beyond::Done,
                };
            }
            let beyond = st.go_beyond(pos, view.skill_time);
            let schema = beyond.unwrap_or_else(|| match (centre, explore) {
                // After the first look round, with no teammate at work to
                // head for: from one vantage point round it to the next.
                (Some(c), _) if to_mate.is_none() && view.skill_time - since >= SEARCH_TURN => {
                    st.circle_round(view, c)
                }
                // Long in vain: explore.
                (_, Some(map)) => st.explore(view, map, nearest),
                _ if phase < SEARCH_TURN && st.search_moves.trapped.is_none() => Schema::LookAround,
                _ => match to_mate {
                    Some(p) => Schema::MoveToGoal {
                        goal: Target::Point(p),
                        speed: SEARCH_SPEED,
                    },
                    None => Schema::Wander {
                        speed: SEARCH_SPEED,
                        period: 2.0,
                    },
                },
            });
            if matches!(schema, Schema::LookAround) {
                st.wander = None;
            }
            // The search's own moves (its detour round a lost teammate's
            // body, its watch for a trap) are kept apart from the schema's
            // (see the detours below).
            st.swap_moves();
            let search = evaluate(&schema, view, st, rng);
            st.watch_search(view.pose.pos, view.skill_time);
            st.swap_moves();
            outputs.push((skill[i].layer, 1.0, search));
        }
        _ => {
            for st in states.iter_mut() {
                st.lost = None;
                st.circle = None;
                st.lookout = None;
                st.looked.clear();
                st.looks_near_mate = (0, None);
                st.beyond = Beyond::NotYet;
                st.search_moves = Moves::default();
            }
        }
    }
    // Looking round for teammates in vain: a robot that has nothing to do
    // but turn in place (`look-around`) and has seen no live teammate for
    // [`LOOK_IN_VAIN`] is out of their sight (round a corner, behind a
    // wall or a teammate's body), and turning on the spot will never show
    // them. It goes back to where it last saw one; there, or if it
    // remembers none, it moves a while and looks round again, by turns.
    // As soon as it sees a teammate it turns in place again.
    if let Some(i) = (skill.iter()).position(|w| matches!(w.schema, Schema::LookAround)) {
        let only_looks = unseen.is_none()
            && (skill.iter().zip(&outputs)).all(|(w, (_, _, o))| {
                o.is_none() || w.schema.avoids() || matches!(w.schema, Schema::LookAround)
            });
        let no_one = view
            .last_mate
            .is_none_or(|(_, age)| age > crate::pilot::MATE_MEMORY);
        let st = &mut states[i];
        if only_looks && no_one {
            let since = *st.in_vain.get_or_insert(view.skill_time);
            let looked = view.skill_time - since;
            if looked >= LOOK_IN_VAIN {
                let back = (view.last_mate)
                    .map(|(p, _)| p)
                    .filter(|p| p.distance(view.pose.pos) > BACK_WHERE_SEEN);
                let phase = (looked - LOOK_IN_VAIN) % (SEARCH_MOVE + SEARCH_TURN);
                let schema = match back {
                    Some(p) => Schema::MoveToGoal {
                        goal: Target::Point(p),
                        speed: SEARCH_SPEED,
                    },
                    None if phase < SEARCH_MOVE => Schema::Wander {
                        speed: SEARCH_SPEED,
                        period: 2.0,
                    },
                    None => Schema::LookAround,
                };
                if matches!(schema, Schema::LookAround) {
                    st.wander = None;
                }
                outputs[i].2 = evaluate(&schema, view, st, rng);
            }
        } else {
            st.in_vain = None;
        }
    }
    // A schema following a planned detour round a lost teammate's body
    // keeps its clearance by the plan: obstacle avoidance is superposed on
    // it in its layer instead of overriding it (a reading at the edge of
    // the avoidance range would otherwise stop the robot in the gap). A
    // trapped robot's detour, planned clear of what its rays hit,
    // teammates included, superposes teammate avoidance too (a sighting
    // at the edge of its range, or a stale one, would otherwise hold the
    // robot in the trap). So does a pinned search's detour.
    let leads = |r: &Option<crate::plan::Route>| r.as_ref().is_some_and(crate::plan::Route::leads);
    if let Some((layer, trapped)) = (skill.iter().zip(states.iter()))
        .find(|(_, s)| leads(&s.route))
        .map(|(w, s)| (w.layer, s.trapped.is_some()))
        .or_else(|| {
            (skill.iter().zip(states.iter()))
                .find(|(_, s)| s.search_moves.trapped.is_some() && leads(&s.search_moves.route))
                .map(|(w, _)| (w.layer, true))
        })
    {
        for (w, o) in skill.iter().zip(outputs.iter_mut()) {
            let demote = match w.schema {
                Schema::AvoidObstacle { .. } => true,
                Schema::AvoidTeammate { .. } => trapped,
                _ => false,
            };
            if demote {
                o.0 = o.0.min(layer);
            }
        }
    }
    // Obstacle avoidance overrides the layers below it by *constraining*
    // what they want: the robot keeps the part of their motion that does
    // not drive into the obstacle (it slides along it) and is pushed away.
    // A plain override makes a robot at a corner dither for ever between
    // avoiding and seeking.
    for i in 0..skill.len() {
        let (layer, _, Some(o)) = outputs[i] else {
            continue;
        };
        if !matches!(skill[i].schema, Schema::AvoidObstacle { .. }) {
            continue;
        }
        let below: Vec<(u8, f64, Option<Output>)> = outputs
            .iter()
            .filter(|(l, _, _)| *l < layer)
            .cloned()
            .collect();
        let want = fuse(&below).v;
        let n = o.v.normalize_or_zero();
        let into = want.dot(n).min(0.0);
        outputs[i].2 = Some(Output {
            v: o.v + (want - n * into),
            face: o.face,
        });
    }
    fuse(&outputs)
}

/// Wheel commands for a differential-drive robot: forward speed and turn
/// rate that steer the heading onto the command.
pub fn differential(cmd: &Command, heading: f64, max_speed: f64, max_turn: f64) -> (f64, f64) {
    differential_toward(steering(cmd), heading, max_speed, max_turn)
}

/// What a differential drive steers toward for `cmd`: the heading it
/// wants (its velocity's direction, else the way it says to face; `None`:
/// anywhere) and its speed. It depends on the command only, so a drive
/// that follows one command over several physics steps works it out once
/// ([`differential_toward`] does the rest).
pub fn steering(cmd: &Command) -> (Option<f64>, f64) {
    let speed = cmd.v.length();
    let want = if speed > 1e-3 {
        Some(cmd.v.y.atan2(cmd.v.x))
    } else {
        cmd.face
    };
    (want, speed)
}

/// [`differential`] for a command's [`steering`].
pub fn differential_toward(
    (want, speed): (Option<f64>, f64),
    heading: f64,
    max_speed: f64,
    max_turn: f64,
) -> (f64, f64) {
    let Some(want) = want else {
        return (0.0, 0.0);
    };
    let err = wrap(want - heading);
    let turn = (err * 3.0).clamp(-max_turn, max_turn);
    // Drive forward only when roughly facing the way to go.
    let forward = (speed * err.cos()).clamp(0.0, max_speed);
    (forward, turn)
}

/// An angle brought into (-π, π].
pub fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let mut a = a % t;
    if a > std::f64::consts::PI {
        a -= t;
    } else if a <= -std::f64::consts::PI {
        a += t;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A schema of a test skill, gain 1, in `layer`.
    /// [`command`] at skill time `t`, every random draw 0.5.
    fn command_at(skill: &[Weighted], view: &mut View, states: &mut Vec<State>, t: f64) -> Command {
        view.skill_time = t;
        command(skill, view, states, &mut || 0.5)
    }

    fn weighted(schema: Schema, layer: u8) -> Weighted {
        Weighted {
            schema,
            gain: 1.0,
            layer,
        }
    }

    fn o(x: f64, y: f64) -> Option<Output> {
        Some(Output {
            v: DVec2::new(x, y),
            face: None,
        })
    }

    #[test]
    fn readings_round_trip_through_json() {
        let s = Sensed {
            t: 12.3,
            pose: Pose {
                pos: DVec2::new(1.0, 2.5),
                heading: -0.75,
            },
            rays: vec![(0.0, 0.84), (std::f64::consts::FRAC_PI_6, 1.02)],
            mates: vec![(1, DVec2::new(2.1, 0.4))],
            objects: vec![(0, DVec2::new(3.0, 2.5)), (2, DVec2::new(0.5, 0.25))],
            odometer: 4.2,
            contact: true,
        };
        let json = serde_json::to_value(&s).expect("json");
        assert_eq!(
            json,
            serde_json::json!({
                "t": 12.3,
                "pose": { "x": 1.0, "y": 2.5, "heading": -0.75 },
                "rays": [[0.0, 0.84], [std::f64::consts::FRAC_PI_6, 1.02]],
                "mates": [{ "robot": 1, "x": 2.1, "y": 0.4 }],
                "objects": [{ "index": 0, "x": 3.0, "y": 2.5 }, { "index": 2, "x": 0.5, "y": 0.25 }],
                "odometer": 4.2,
                "contact": true
            })
        );
        let back: Sensed = serde_json::from_str(&json.to_string()).expect("sensed");
        assert_eq!(back, s);
        // A robot without rays or a camera says only where it is.
        let bare: Sensed =
            serde_json::from_str(r#"{"t": 1, "pose": {"x": 0.5, "y": 0, "heading": 0}}"#)
                .expect("sensed");
        assert_eq!(
            bare,
            Sensed {
                t: 1.0,
                pose: Pose {
                    pos: DVec2::new(0.5, 0.0),
                    heading: 0.0
                },
                ..Sensed::default()
            }
        );
        assert!(serde_json::from_str::<Sensed>(r#"{"t": 1}"#).is_err());
    }

    #[test]
    fn commands_round_trip_through_json() {
        for c in [
            Command {
                v: DVec2::new(0.25, -0.1),
                face: None,
                layer: Some(1),
                label: Label::default(),
            },
            Command {
                v: DVec2::ZERO,
                face: Some(std::f64::consts::FRAC_PI_2),
                layer: Some(3),
                label: Label {
                    behavior: Some(BehaviorId(4)),
                    link: Some(1),
                    slot: Some((1, Side::Left, 0.6)),
                },
            },
            Command::default(),
        ] {
            let json = serde_json::to_string(&c).expect("json");
            assert_eq!(serde_json::from_str::<Command>(&json).expect("command"), c);
        }
        let c = Command {
            v: DVec2::new(0.25, -0.1),
            face: Some(1.5),
            layer: Some(2),
            label: Label::default(),
        };
        assert_eq!(
            serde_json::to_value(c).expect("json"),
            serde_json::json!({ "vx": 0.25, "vy": -0.1, "face": 1.5, "layer": 2 })
        );
        // `face` and `layer` may be left out; there are four layers.
        assert_eq!(
            serde_json::from_str::<Command>(r#"{"vx": 0.5, "vy": 0}"#).expect("command"),
            Command {
                v: DVec2::new(0.5, 0.0),
                face: None,
                layer: None,
                label: Label::default(),
            }
        );
        assert!(serde_json::from_str::<Command>(r#"{"vx": 0, "vy": 0, "layer": 4}"#).is_err());
    }

    #[test]
    fn schemas_in_a_layer_superpose_linearly() {
        let c = fuse(&[(1, 1.0, o(1.0, 0.0)), (1, 0.5, o(0.0, 2.0))]);
        assert_eq!(c.v, DVec2::new(1.0, 1.0));
        assert_eq!(c.layer, Some(1));
    }

    #[test]
    fn an_active_higher_layer_overrides_the_lower_ones() {
        let c = fuse(&[(1, 1.0, o(1.0, 0.0)), (3, 1.0, o(0.0, -1.0))]);
        assert_eq!(c.v, DVec2::new(0.0, -1.0));
        assert_eq!(c.layer, Some(3));
        // An inactive higher layer does not.
        let c = fuse(&[(1, 1.0, o(1.0, 0.0)), (3, 1.0, None)]);
        assert_eq!(c.v, DVec2::new(1.0, 0.0));
        assert_eq!(c.layer, Some(1));
        // Stop is active: it holds the robot whatever lies below.
        let c = fuse(&[(1, 1.0, o(1.0, 0.0)), (2, 1.0, o(0.0, 0.0))]);
        assert_eq!(c.v, DVec2::ZERO);
        assert_eq!(fuse(&[]), Command::default());
    }

    fn view_with_wall_ahead() -> View {
        View {
            pose: Pose::default(),
            rays: vec![(0.0, 0.2)],
            max_speed: 0.3,
            ..View::default()
        }
    }

    /// The second paper: obstacle avoidance has priority 3 while finding,
    /// and a lower one than the push while moving the box.
    #[test]
    fn the_priority_of_avoidance_changes_between_commands() {
        let view = view_with_wall_ahead();
        let mut rng = || 0.5;
        let find = [
            weighted(
                Schema::MoveToGoal {
                    goal: Target::Direction(DVec2::X),
                    speed: 0.3,
                },
                1,
            ),
            weighted(Schema::AvoidObstacle { range: 0.4 }, 3),
        ];
        let c = command(&find, &view, &mut Vec::new(), &mut rng);
        assert!(c.v.x < 0.0, "finding: the wall pushes back, {c:?}");
        assert_eq!(c.layer, Some(3));
        let mut push = find.clone();
        push[0].layer = 2;
        push[1].layer = 0;
        let c = command(&push, &view, &mut Vec::new(), &mut rng);
        assert!(c.v.x > 0.0, "pushing: the robot keeps going, {c:?}");
        assert_eq!(c.layer, Some(2));
    }

    #[test]
    fn keep_slot_heads_for_the_slot_behind_the_reference() {
        let mut view = View {
            max_speed: 0.3,
            ..View::default()
        };
        view.roles.insert("lead".into(), 0);
        view.mates.insert(
            0,
            Mate {
                pos: DVec2::new(2.0, 0.0),
                heading: Some(0.0),
            },
        );
        let s = Schema::KeepSlot {
            of: "lead".into(),
            side: Side::Left,
            distance: 1.0,
            speed: 0.2,
        };
        let mut rng = || 0.5;
        let out = evaluate(&s, &view, &mut State::default(), &mut rng).unwrap();
        // Slot at (1.29, 0.71): forward and to the left.
        assert!(out.v.x > 0.0 && out.v.y > 0.0, "{out:?}");
        // Without knowing who leads, the schema is silent.
        view.roles.clear();
        assert!(evaluate(&s, &view, &mut State::default(), &mut rng).is_none());
    }

    #[test]
    fn push_goes_behind_the_object_then_through_it() {
        let mut view = View {
            max_speed: 0.3,
            ..View::default()
        };
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        view.in_view.insert("box".into());
        let s = push_box(DVec2::new(3.0, 0.0));
        let mut rng = || 0.5;
        // Behind it, on the line: straight at the goal.
        view.pose.pos = DVec2::new(0.5, 0.0);
        let out = evaluate(&s, &view, &mut State::default(), &mut rng).unwrap();
        assert!(out.v.x > 0.19 && out.v.y.abs() < 1e-9, "{out:?}");
        // In front of it: around it, not through it.
        view.pose.pos = DVec2::new(1.4, 0.1);
        let out = evaluate(&s, &view, &mut State::default(), &mut rng).unwrap();
        assert!(out.v.y > 0.0 && out.v.x < 0.0, "{out:?}");
    }

    /// A robot driving to a goal makes a step of its skill each time it
    /// comes 5 cm nearer than it has been, whatever drives it, and none
    /// going back and forth short of its best (finitely many).
    #[test]
    fn a_robot_driving_to_its_goal_marks_each_5_cm_nearer() {
        let skill = [
            weighted(
                Schema::MoveToGoal {
                    goal: Target::Point(DVec2::new(3.0, 0.0)),
                    speed: 0.3,
                },
                1,
            ),
            weighted(Schema::AvoidTeammate { range: 0.4 }, 2),
        ];
        let mut view = View {
            max_speed: 0.3,
            ..View::default()
        };
        let mut states = Vec::new();
        let marks = |states: &Vec<State>| states.iter().map(State::marks).sum::<u32>();
        let mut at = |x: f64, t: f64, states: &mut Vec<State>| {
            view.pose.pos = DVec2::new(x, 0.0);
            command_at(&skill, &mut view, states, t);
        };
        at(0.0, 0.0, &mut states);
        assert_eq!(marks(&states), 0);
        at(0.04, 0.1, &mut states);
        assert_eq!(marks(&states), 0, "4 cm is no step");
        at(0.06, 0.2, &mut states);
        assert_eq!(marks(&states), 1);
        // Pushed back and coming again, short of its best: nothing new.
        for k in 0..50 {
            at(
                if k % 2 == 0 { -0.5 } else { 0.1 },
                0.3 + f64::from(k),
                &mut states,
            );
        }
        assert_eq!(marks(&states), 1);
        at(1.06, 60.0, &mut states);
        assert_eq!(marks(&states), 2, "one step however far it came");
        at(1.12, 60.1, &mut states);
        assert_eq!(marks(&states), 3);
    }

    #[test]
    fn a_strip_thinner_than_half_a_lane_has_its_lane_along_its_middle() {
        // The 60th of a 5 m tall hall (`scan:0:0:10:5:0.6` for 60 robots).
        let (ya, yb) = (0.5, 0.5 + 5.0 / 60.0);
        let pts = scan_waypoints([0.0, ya, 10.0, yb], 0.6);
        let mid = (ya + yb) / 2.0;
        assert_eq!(pts, vec![DVec2::new(0.3, mid), DVec2::new(9.7, mid)]);
        // One just thick enough keeps its lane half a spacing in.
        let pts = scan_waypoints([0.0, 0.0, 10.0, 0.3], 0.6);
        assert_eq!(pts, vec![DVec2::new(0.3, 0.3), DVec2::new(9.7, 0.3)]);
    }

    #[test]
    fn scan_visits_its_lanes_and_finishes() {
        let pts = scan_waypoints([0.0, 0.0, 2.0, 1.0], 0.5);
        assert_eq!(
            pts,
            vec![
                DVec2::new(0.25, 0.25),
                DVec2::new(1.75, 0.25),
                DVec2::new(1.75, 0.75),
                DVec2::new(0.25, 0.75)
            ]
        );
        let s = Schema::Scan {
            region: [0.0, 0.0, 2.0, 1.0],
            spacing: 0.5,
            speed: 0.3,
            split: false,
            patience: 10.0,
        };
        let mut st = State::default();
        let mut rng = || 0.5;
        let mut view = View::default();
        for p in &pts {
            view.pose.pos = *p;
            evaluate(&s, &view, &mut st, &mut rng);
        }
        assert!(st.finished);
    }

    #[test]
    fn differential_turns_before_driving() {
        let c = Command {
            v: DVec2::new(0.0, 0.3),
            face: None,
            layer: Some(1),
            label: Label::default(),
        };
        let (f, t) = differential(&c, 0.0, 0.3, 2.0);
        assert!(f.abs() < 1e-9 && t > 0.0);
        let (f, t) = differential(&c, std::f64::consts::FRAC_PI_2, 0.3, 2.0);
        assert!((f - 0.3).abs() < 1e-9 && t.abs() < 1e-9);
        assert_eq!(wrap(3.0 * std::f64::consts::PI), std::f64::consts::PI);
    }

    #[test]
    fn split_cells_tile_the_region_in_equal_near_square_cells() {
        for (w, h) in [(40.0, 20.0), (20.0, 40.0), (10.0, 10.0), (100.0, 3.0)] {
            for n in [1u32, 2, 3, 5, 7, 10, 99, 100, 1000] {
                let region = [0.0, 0.0, w, h];
                let cells: Vec<[f64; 4]> = (0..n).map(|r| split_cell(region, r, n)).collect();
                let mut area = 0.0;
                for (i, c) in cells.iter().enumerate() {
                    assert!(c[0] >= -1e-9 && c[2] <= w + 1e-9 && c[1] >= -1e-9 && c[3] <= h + 1e-9);
                    let a = (c[2] - c[0]) * (c[3] - c[1]);
                    assert!(
                        (a - w * h / n as f64).abs() < 1e-6,
                        "{w}x{h}, n={n}: cell {i} area {a}"
                    );
                    area += a;
                    for d in &cells[i + 1..] {
                        let overlap = (c[2].min(d[2]) - c[0].max(d[0])).max(0.0)
                            * (c[3].min(d[3]) - c[1].max(d[1])).max(0.0);
                        assert!(overlap < 1e-9, "n={n}: {c:?} overlaps {d:?}");
                    }
                    // About square once there are enough cells to shape.
                    let aspect = (c[2] - c[0]) / (c[3] - c[1]);
                    if n >= 10 && w / h < 20.0 && h / w < 20.0 {
                        assert!((0.5..=2.0).contains(&aspect), "{w}x{h}, n={n}: {c:?}");
                    }
                }
                assert!((area - w * h).abs() < 1e-6, "n={n}: cells cover {area}");
            }
        }
    }

    #[test]
    fn a_split_scan_sweeps_only_its_own_cell() {
        let s = Schema::Scan {
            region: [0.0, 0.0, 4.0, 2.0],
            spacing: 0.5,
            speed: 0.3,
            split: true,
            patience: 10.0,
        };
        let view = View {
            rank: (1, 2),
            ..View::default()
        };
        let mut st = State::default();
        let out = evaluate(&s, &view, &mut st, &mut || 0.5).expect("active");
        // Rank 1 of 2 sweeps the right half: from (0, 0) it heads for its
        // first waypoint (2.25, 0.25), nearly along x (unsplit, it would
        // head for (0.25, 0.25), at 45°).
        assert!(out.v.x > 0.0 && out.v.y.abs() < 0.2 * out.v.x, "{out:?}");
        assert_eq!(split_cell([0.0, 0.0, 4.0, 2.0], 1, 2), [2.0, 0.0, 4.0, 2.0]);
    }

    #[test]
    fn a_pusher_looks_round_for_an_object_that_is_not_where_it_was_seen() {
        let push = push_box_west();
        let mut view = View::default();
        view.pose.pos = DVec2::new(0.6, 0.0);
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        let mut st = State::default();
        // Facing the spot, close, and the box is not in view: turn in place.
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert_eq!(out.v, DVec2::ZERO);
        assert!(out.face.is_some());
        // Still turning a moment later, though no longer facing the spot.
        view.pose.heading = 2.0;
        view.skill_time = 3.0;
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert_eq!(out.v, DVec2::ZERO);
        // In view again: back to pushing (it moves).
        view.in_view.insert("box".into());
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert!(out.v.length() > 0.0, "{out:?}");
        // Not in view but far from the spot: go there as before.
        let mut st = State::default();
        view.in_view.clear();
        view.pose.pos = DVec2::new(4.0, 0.0);
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert!(out.v.length() > 0.0, "{out:?}");
    }

    /// A robot driving to a goal beyond a lost teammate's body that blocks
    /// the corridor (no way round it) is trapped in front of it, then
    /// pushes it: its obstacle avoidance stops answering for the body.
    #[test]
    fn a_robot_pushes_a_body_that_blocks_its_only_way() {
        let skill = vec![
            weighted(
                Schema::MoveToGoal {
                    goal: Target::Point(DVec2::new(6.8, 1.5)),
                    speed: 0.12,
                },
                1,
            ),
            weighted(Schema::AvoidObstacle { range: 0.12 }, 3),
        ];
        let map = std::sync::Arc::new(crate::plan::Map::new(&crate::plan::tests::corridor()));
        // In the corridor, a body 0.3 m ahead: the ray straight ahead ends
        // on it, 6 cm from the robot's edge.
        let mut view = View {
            max_speed: 0.25,
            radius: 0.12,
            rays: vec![(0.0, 0.06)],
            bodies: vec![DVec2::new(5.6, 1.5)],
            map: Some(map),
            ..View::default()
        };
        view.pose.pos = DVec2::new(5.3, 1.5);
        let mut states = Vec::new();
        let at =
            |view: &mut View, t: f64, states: &mut Vec<State>| command_at(&skill, view, states, t);
        // Held back by its avoidance while it is not trapped ...
        let c = at(&mut view, 0.0, &mut states);
        assert!(c.v.x < 0.0, "{c:?}");
        let mut t = 0.0;
        while states[0].trapped.is_none() {
            t += 0.1;
            assert!(t < TRAPPED_AFTER + 1.0, "never trapped");
            at(&mut view, t, &mut states);
        }
        // ... trapped, with no way round: it drives on into the body.
        let c = at(&mut view, t + 0.1, &mut states);
        assert!(c.v.x > 0.1 && c.v.y.abs() < 1e-9, "{c:?}");
        // A body behind it is not pushed: trapped all the same, its
        // avoidance still answers for it (and adds to the drive ahead).
        view.bodies = vec![DVec2::new(5.0, 1.5)];
        view.rays = vec![(std::f64::consts::PI, 0.06)];
        let mut states = Vec::new();
        let mut t = 0.0;
        while states.first().is_none_or(|s: &State| s.trapped.is_none()) {
            at(&mut view, t, &mut states);
            t += 0.1;
            assert!(t < TRAPPED_AFTER + 1.0, "never trapped");
        }
        let c = at(&mut view, t, &mut states);
        assert!(c.v.x > 0.2, "{c:?}");
    }

    /// A robot looking round for its teammates (`look-around`) that sees
    /// none for [`LOOK_IN_VAIN`] goes back to where it last saw one, then,
    /// there, moves and looks round by turns; it turns in place again as
    /// soon as it sees one.
    #[test]
    fn a_robot_that_looks_round_in_vain_goes_back_for_its_teammates() {
        let skill = vec![
            weighted(Schema::LookAround, 0),
            weighted(Schema::AvoidObstacle { range: 0.12 }, 3),
        ];
        let mut view = View {
            max_speed: 0.25,
            ..View::default()
        };
        view.pose.pos = DVec2::new(5.5, 1.6);
        let seen_at = DVec2::new(3.5, 2.2);
        let mut states = Vec::new();
        let at = |view: &mut View, t: f64, age: f64, states: &mut Vec<State>| {
            view.last_mate = Some((seen_at, age));
            command_at(&skill, view, states, t)
        };
        // Seen lately: a turn in place, however long it has looked.
        let c = at(&mut view, 30.0, 1.0, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        assert!(c.face.is_some());
        // Unseen: it keeps turning for LOOK_IN_VAIN ...
        let c = at(&mut view, 31.0, 4.0, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        let c = at(&mut view, 31.0 + LOOK_IN_VAIN - 0.1, 5.0, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        // ... then heads back to where it last saw a teammate.
        let c = at(&mut view, 31.0 + LOOK_IN_VAIN + 0.1, 5.0, &mut states);
        let back = (seen_at - view.pose.pos).normalize();
        assert!((c.v.length() - SEARCH_SPEED).abs() < 1e-9, "{c:?}");
        assert!(c.v.normalize().dot(back) > 0.999, "{c:?}");
        // There, with no one in sight: it moves, then looks round again.
        view.pose.pos = seen_at + DVec2::new(0.2, 0.0);
        let t = 31.0 + LOOK_IN_VAIN + 20.0;
        let phase = (t - 31.0 - LOOK_IN_VAIN) % (SEARCH_MOVE + SEARCH_TURN);
        let c = at(&mut view, t, 25.0, &mut states);
        assert_eq!(c.v == DVec2::ZERO, phase >= SEARCH_MOVE, "{c:?}");
        // A teammate seen again: a turn in place, and the wait starts anew.
        let c = at(&mut view, t + 1.0, 0.5, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        let c = at(&mut view, t + 5.0, 4.0, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        // Never having seen one, it moves and looks round by turns.
        view.last_mate = None;
        let mut states = Vec::new();
        let mut at = |t: f64, states: &mut Vec<State>| command_at(&skill, &mut view, states, t);
        assert_eq!(at(0.0, &mut states).v, DVec2::ZERO);
        let c = at(LOOK_IN_VAIN + 0.1, &mut states);
        assert!((c.v.length() - SEARCH_SPEED).abs() < 1e-9, "{c:?}");
        let c = at(LOOK_IN_VAIN + SEARCH_MOVE + 0.1, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
    }

    /// A pusher that does not find the object where it last saw it, nor
    /// in a full turn from there, searches for it as for one never seen:
    /// it looks round, wanders a while, looks again, and pushes once it
    /// sees it. (It turned on the spot for ever: found by sweeping the
    /// compiled box push, the box hidden behind the teammate that stepped
    /// aside.)
    #[test]
    fn a_pusher_that_loses_the_object_searches_for_it() {
        let skill = vec![
            weighted(push_box_west(), 2),
            weighted(Schema::AvoidObstacle { range: 0.15 }, 1),
        ];
        let mut view = View::default();
        view.pose.pos = DVec2::new(0.6, 0.0);
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        let mut states = Vec::new();
        let at =
            |view: &mut View, t: f64, states: &mut Vec<State>| command_at(&skill, view, states, t);
        // Facing the spot, the box not there: a turn in place.
        let c = at(&mut view, 0.0, &mut states);
        assert_eq!(c.v, DVec2::ZERO);
        assert!(c.face.is_some());
        // The turn ends without it: lost. It looks round ...
        let c = at(&mut view, SEARCH_TURN + 0.1, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        assert!(c.face.is_some());
        // ... then wanders, ...
        let c = at(&mut view, 2.0 * SEARCH_TURN + 0.2, &mut states);
        assert!((c.v.length() - SEARCH_SPEED).abs() < 1e-9, "{c:?}");
        // ... and looks round again.
        let c = at(
            &mut view,
            2.0 * SEARCH_TURN + SEARCH_MOVE + 0.3,
            &mut states,
        );
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        // Seen again (somewhere else): it goes to push it.
        view.objects.insert("box".into(), DVec2::new(3.0, 2.0));
        view.in_view.insert("box".into());
        let c = at(
            &mut view,
            2.0 * SEARCH_TURN + SEARCH_MOVE + 0.4,
            &mut states,
        );
        assert!(c.v.length() > 0.0, "{c:?}");
        assert!(states.iter().all(|s| !s.gone && s.lost.is_none()));
    }

    /// The same, but a chair of the map stands between the robot and where
    /// it saw the crate: the crate may well be there, hidden. No look
    /// round (one begun before the map was made is given up): it heads on
    /// for the place behind the crate. With nothing between, it looks.
    #[test]
    fn an_object_behind_a_chair_is_hidden_not_gone() {
        let crate_at = DVec2::new(3.561, 0.893);
        let skill = vec![
            weighted(push_box(DVec2::new(1.76, 1.62)), 2),
            weighted(Schema::AvoidObstacle { range: 0.15 }, 1),
        ];
        let mut view = View::default();
        view.pose.pos = DVec2::new(2.888, 1.131);
        let to = crate_at - view.pose.pos;
        view.pose.heading = to.y.atan2(to.x);
        view.objects.insert("box".into(), crate_at);
        let mut states = Vec::new();
        // No map yet: a look round begins, and the map is asked for.
        let c = command_at(&skill, &mut view, &mut states, 0.0);
        assert!(c.face.is_some() && states[0].search.is_some(), "{c:?}");
        assert!(states[0].needs_map(0.0));
        // With the map: the chair hides the crate; the look round is given
        // up and the robot drives on.
        view.map = Some(std::sync::Arc::new(crate::plan::Map::new(
            &crate::plan::tests::hidden_hall(),
        )));
        let c = command_at(&skill, &mut view, &mut states, 0.1);
        assert!(states[0].search.is_none() && !states[0].gone, "{c:?}");
        assert!(c.v.length() > 0.0, "{c:?}");
        // From a place with nothing between, the same: it looks round.
        let mut states = Vec::new();
        view.pose.pos = DVec2::new(2.9, 0.6);
        let to = crate_at - view.pose.pos;
        view.pose.heading = to.y.atan2(to.x);
        let c = command_at(&skill, &mut view, &mut states, 0.0);
        assert!(c.face.is_some() && states[0].search.is_some(), "{c:?}");
    }

    /// A push of the object `box` to (-3, 0), standing 0.4 m behind it, at
    /// 0.2 m/s: the skill the pushing tests run.
    fn push_box_west() -> Schema {
        push_box(DVec2::new(-3.0, 0.0))
    }

    /// Push the box to `goal` from 0.4 m behind it, at 0.2 m/s.
    fn push_box(goal: DVec2) -> Schema {
        Schema::Push {
            object: "box".into(),
            goal,
            offset: 0.4,
            speed: 0.2,
        }
    }

    /// What a pusher of the tests knows of itself: a 0.12 m robot at up
    /// to 0.3 m/s, in an arena it has no map of.
    fn pusher_view() -> View {
        View {
            radius: 0.12,
            max_speed: 0.3,
            ..View::default()
        }
    }

    /// A teammate crashed while pushing: its body stands right behind the
    /// object, where the pusher that takes over would push from. That one
    /// pushes the object aside (at a turn from the goal's direction whose
    /// place to push from is clear of the body) until the place behind it
    /// is clear, then straight for the goal again. (Found in the sweeps:
    /// 42 of 1,080 crash runs of the box-pushing missions stalled so.)
    #[test]
    fn a_pusher_pushes_aside_an_object_a_lost_body_stands_behind() {
        let push = push_box_west();
        let o = DVec2::new(1.0, 0.0);
        let mut view = pusher_view();
        view.pose.pos = DVec2::new(1.0, 1.0);
        view.objects.insert("box".into(), o);
        view.in_view.insert("box".into());
        let mut st = State::default();
        // No body: straight for the goal (get behind it, at +x).
        evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert_eq!(st.push_turn, None);
        assert_eq!(st.bound_for, Some(DVec2::new(1.4, 0.0)));
        // The body against the object's back.
        view.bodies.push(DVec2::new(1.26, 0.0));
        evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        let turn = st.push_turn.expect("pushes aside");
        assert!(
            turn.abs() >= std::f64::consts::FRAC_PI_4 - 1e-9
                && turn.abs() <= std::f64::consts::FRAC_PI_2 + 1e-9
        );
        // On the robot's side of the object (north), clear of the body,
        // and still toward the goal (west).
        let from = st.bound_for.expect("gets behind");
        assert!(from.y > 0.0, "{from:?}");
        assert!(from.distance(view.bodies[0]) >= 0.26, "{from:?}");
        assert!(((o - from).normalize().x) < 0.0, "{from:?}");
        // The same turn while the object is still against the body.
        view.pose.pos = DVec2::new(1.3, 0.5);
        evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert_eq!(st.push_turn, Some(turn));
        // Pushed clear of it (0.4 m south-west): straight for the goal.
        let o = DVec2::new(0.8, -0.35);
        view.objects.insert("box".into(), o);
        evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert_eq!(st.push_turn, None);
        let dir = (DVec2::new(-3.0, 0.0) - o).normalize();
        assert!(st.bound_for.expect("gets behind").distance(o - dir * 0.4) < 1e-9);
    }

    /// A pusher that does not see its object where it last saw it, with a
    /// lost teammate's body standing between, takes the object as hidden:
    /// it goes on, and does not turn round to look for it.
    #[test]
    fn an_object_behind_a_lost_body_is_hidden_not_gone() {
        let push = push_box_west();
        let mut view = View {
            radius: 0.12,
            ..View::default()
        };
        view.pose.pos = DVec2::new(0.4, 0.0);
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        let mut st = State::default();
        // No body: not there, so it looks round.
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert!(st.search.is_some() && out.face.is_some());
        // A body between: hidden; it heads on round the object.
        let mut st = State::default();
        view.bodies.push(DVec2::new(0.7, 0.02));
        let out = evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
        assert!(
            st.search.is_none() && out.face.is_none() && out.v.length() > 0.0,
            "{out:?}"
        );
    }

    /// A pusher that lost its object near a lost teammate's body (which can
    /// hide it from one side) searches round the body: to a vantage point a
    /// metre off, a look all round there, the next point a sixth of a turn
    /// further, and so on; without a body near, it wanders between looks
    /// as before.
    #[test]
    fn a_pusher_searches_round_a_lost_body_near_where_it_lost_the_object() {
        let skill = vec![weighted(push_box_west(), 2)];
        let body = DVec2::new(1.5, 0.0);
        let mut view = View {
            bodies: vec![body],
            ..pusher_view()
        };
        view.pose.pos = DVec2::new(0.6, 0.0);
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        let mut states = Vec::new();
        let at =
            |view: &mut View, t: f64, states: &mut Vec<State>| command_at(&skill, view, states, t);
        // Facing the spot, the box not there: a turn in place; lost.
        at(&mut view, 0.0, &mut states);
        let c = at(&mut view, SEARCH_TURN + 0.1, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        // Then round the body: to the first vantage point, a metre off it,
        // a sixth of a turn on from where the robot stood (west of it).
        let c = at(&mut view, 2.0 * SEARCH_TURN + 0.2, &mut states);
        let first = body + DVec2::from_angle(std::f64::consts::PI + std::f64::consts::FRAC_PI_3);
        assert!(c.v.length() > 0.0, "{c:?}");
        assert!(
            c.v.normalize().dot((first - view.pose.pos).normalize()) > 0.99,
            "{c:?}"
        );
        // There: a look all round, ...
        view.pose.pos = first;
        let t = 2.0 * SEARCH_TURN + 10.0;
        let c = at(&mut view, t, &mut states);
        assert_eq!(c.v, DVec2::ZERO, "{c:?}");
        assert!(c.face.is_some());
        // ... then on to the next point.
        let c = at(&mut view, t + SEARCH_TURN + 0.1, &mut states);
        let next =
            body + DVec2::from_angle(std::f64::consts::PI + 2.0 * std::f64::consts::FRAC_PI_3);
        assert!(
            c.v.normalize().dot((next - first).normalize()) > 0.99,
            "{c:?}"
        );
        // Seen again: back to pushing, the search over.
        view.in_view.insert("box".into());
        at(&mut view, t + SEARCH_TURN + 0.2, &mut states);
        assert!(
            states
                .iter()
                .all(|s| s.circle.is_none() && s.lost.is_none())
        );
    }

    /// A pusher whose box lies against a chair beside the goal (hidden box,
    /// crash seed 168) pushes it off the chair, along its planned way, not
    /// straight at the goal into the chair; with a clear way, straight.
    #[test]
    fn a_pusher_steers_its_object_round_a_chair() {
        let map = crate::plan::Map::new(&crate::plan::tests::hidden_hall());
        let (chair, goal) = (DVec2::new(0.8, 2.65), DVec2::new(0.8, 2.0));
        let push = push_box(goal);
        let mut view = View {
            map: Some(std::sync::Arc::new(map)),
            ..pusher_view()
        };
        view.pose.pos = DVec2::new(2.0, 3.2);
        for (o, planned) in [(DVec2::new(1.17, 2.6), true), (DVec2::new(3.0, 2.0), false)] {
            for key in ["box", "yellow_box"] {
                view.objects.insert(key.into(), o);
                view.in_view.insert(key.into());
            }
            let mut st = State::default();
            evaluate(&push, &view, &mut st, &mut || 0.5).expect("active");
            assert_eq!(st.object_way.is_some(), planned, "{o}");
            let behind = st.bound_for.expect("getting behind it");
            let dir = (o - behind).normalize();
            let straight = (goal - o).normalize();
            if planned {
                // Away from the chair, where straight on heads toward it.
                assert!(dir.dot((o - chair).normalize()) > 0.0, "{dir}");
                assert!(straight.dot((o - chair).normalize()) < 0.0);
            } else {
                assert!(dir.distance(straight) < 1e-9, "{dir} {straight}");
            }
        }
    }

    /// A robot without the arena's map (no teammate lost, never trapped)
    /// pushes straight; once the object it pushes, in position behind it,
    /// has made no headway toward the goal for [`TRAPPED_AFTER`] (held
    /// against a chair, say), it needs the map to plan the object's way
    /// round. Getting behind the object does not count, nor does an object
    /// that moves on.
    #[test]
    fn a_pusher_whose_object_makes_no_headway_asks_for_the_map() {
        let goal = DVec2::new(3.0, 0.0);
        let push = push_box(goal);
        let mut view = pusher_view();
        view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
        view.in_view.insert("box".into());
        let run = |view: &mut View, robot: DVec2, moves: bool| {
            let mut st = State::default();
            for k in 0..=60 {
                view.skill_time = f64::from(k) * 0.1;
                let x = if moves {
                    1.0 + view.skill_time * 0.1
                } else {
                    1.0
                };
                view.objects.insert("box".into(), DVec2::new(x, 0.0));
                view.pose.pos = robot + DVec2::new(x - 1.0, 0.0);
                evaluate(&push, view, &mut st, &mut || 0.5).expect("active");
                if st.needs_map(view.skill_time) {
                    return Some(view.skill_time);
                }
            }
            None
        };
        // In position behind the box, the box stuck: after 5 s.
        let at = run(&mut view, DVec2::new(0.6, 0.0), false).expect("asks for the map");
        assert!((TRAPPED_AFTER..TRAPPED_AFTER + 0.2).contains(&at), "{at}");
        // The box moving on: never.
        assert_eq!(run(&mut view, DVec2::new(0.6, 0.0), true), None);
        // Not in position (beside the box, getting behind it): never.
        assert_eq!(run(&mut view, DVec2::new(1.0, 0.5), false), None);
    }

    /// A body far from where the object was last seen, but on its way from
    /// there to the push's goal, was pushing it (its teammate watched from
    /// behind and lost sight of it there, hidden by the pusher): the search
    /// goes round that body. A body as far off the way is not searched round.
    #[test]
    fn a_pusher_searches_round_a_lost_body_far_along_the_way_to_the_goal() {
        let skill = vec![weighted(push_box_west(), 2)];
        for (body, round) in [
            (DVec2::new(-1.8, 0.1), true),
            (DVec2::new(-1.8, 1.5), false),
        ] {
            assert!(body.distance(DVec2::new(1.0, 0.0)) > BODY_NEAR_OBJECT);
            let mut view = View {
                bodies: vec![body],
                ..pusher_view()
            };
            view.pose.pos = DVec2::new(0.6, 0.0);
            view.objects.insert("box".into(), DVec2::new(1.0, 0.0));
            let mut states = Vec::new();
            command_at(&skill, &mut view, &mut states, 0.0);
            command_at(&skill, &mut view, &mut states, SEARCH_TURN + 0.1);
            let c = command_at(&skill, &mut view, &mut states, 2.0 * SEARCH_TURN + 0.2);
            assert_eq!(states[0].circle.is_some(), round, "{body}: {c:?}");
            if round {
                let to = c.v.normalize();
                let first = (states[0].circle)
                    .and_then(|k| vantage(&view, body, k.from, k.k))
                    .expect("a vantage point");
                assert!((first.distance(body) - VANTAGE).abs() < 1e-9);
                assert!(to.dot((first - view.pose.pos).normalize()) > 0.99, "{c:?}");
            }
        }
    }

    /// A robot driving to a goal that gets no nearer to it for
    /// [`TRAPPED_AFTER`] (held in a pocket between a chair and a crate) is
    /// trapped: it steers along a planned detour instead of straight at the
    /// goal, for [`DETOUR`], then straight again. One that gets nearer is
    /// not trapped.
    #[test]
    fn a_robot_that_makes_no_headway_takes_a_detour() {
        let map = crate::plan::Map::new(&crate::plan::tests::hall());
        let goal = DVec2::new(6.3, 3.0);
        let skill = vec![
            weighted(
                Schema::MoveToGoal {
                    goal: Target::Point(goal),
                    speed: 0.25,
                },
                1,
            ),
            weighted(Schema::AvoidObstacle { range: 0.3 }, 3),
        ];
        let mut view = View {
            map: Some(std::sync::Arc::new(map)),
            ..View::default()
        };
        let start = DVec2::new(3.27, 0.6);
        view.pose.pos = start;
        let straight = (goal - start).normalize();
        let mut states = Vec::new();
        let at =
            |view: &mut View, states: &mut Vec<State>, t: f64| command_at(&skill, view, states, t);
        // Standing still: straight at the goal until trapped.
        for k in 0..50 {
            let c = at(&mut view, &mut states, f64::from(k) * 0.1);
            assert!(c.v.normalize().dot(straight) > 0.999, "{k}: {c:?}");
            assert!(states[0].trapped.is_none());
        }
        at(&mut view, &mut states, TRAPPED_AFTER + 0.05);
        assert!(states[0].trapped.is_some());
        // From its next command, the detour leaves the pocket round the
        // chair or the crate, not at the goal through the gap between them.
        for t in [0.15, 0.25, 3.0] {
            let c = at(&mut view, &mut states, TRAPPED_AFTER + t);
            assert!(c.v.normalize().dot(straight) < 0.9, "{t}: {c:?}");
        }
        // Straight again after the detour.
        let t = TRAPPED_AFTER + 0.05 + DETOUR;
        at(&mut view, &mut states, t);
        assert!(states[0].trapped.is_none());
        let c = at(&mut view, &mut states, t + 0.1);
        assert!(c.v.normalize().dot(straight) > 0.999, "{c:?}");
        // Getting nearer, if slowly, is headway.
        let mut states = Vec::new();
        for k in 0..200 {
            view.pose.pos = start + straight * (f64::from(k) * 0.005);
            at(&mut view, &mut states, f64::from(k) * 0.1);
            assert!(states[0].trapped.is_none(), "{k}");
        }
    }

    /// A wandering robot held west of the hall's south chair by the wall,
    /// the chair and its teammate, where avoidance overrides the wander
    /// whichever way it turns (the compiled search and rescue, seed 606):
    /// after 10 s within half a metre of one spot it is pinned, heads for
    /// open floor two metres off for 8 s, then wanders again; a robot that
    /// roams is never pinned.
    #[test]
    fn a_pinned_wandering_robot_heads_for_open_floor() {
        let hall = crate::plan::tests::hall();
        let map = std::sync::Arc::new(crate::plan::Map::new(&hall));
        let skill = vec![
            weighted(
                Schema::Wander {
                    speed: 0.25,
                    period: 3.0,
                },
                1,
            ),
            weighted(Schema::AvoidTeammate { range: 0.4 }, 2),
            weighted(Schema::AvoidObstacle { range: 0.35 }, 3),
        ];
        let start = DVec2::new(0.45, 0.8);
        let mut view = View {
            map: Some(map.clone()),
            radius: 0.12,
            max_speed: 0.3,
            // The wall 0.33 m behind it.
            rays: vec![(std::f64::consts::PI, 0.33)],
            ..View::default()
        };
        view.pose.pos = start;
        view.mates.insert(
            1,
            Mate {
                pos: DVec2::new(0.51, 0.46),
                heading: None,
            },
        );
        let mut seed = 7u64;
        let mut rng = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut states = Vec::new();
        let mut at = |view: &mut View, states: &mut Vec<State>, t: f64| {
            view.skill_time = t;
            command(&skill, view, states, &mut rng)
        };
        // Shuffling round one spot: not pinned for 10 s.
        for k in 0..100 {
            view.pose.pos = start + DVec2::new(0.0, 0.1 * f64::from(k % 3));
            at(&mut view, &mut states, f64::from(k) * 0.1);
            assert!(states[0].trapped.is_none(), "{k}");
        }
        view.pose.pos = start;
        at(&mut view, &mut states, PINNED_AFTER + 0.05);
        assert!(states[0].trapped.is_some());
        // It heads for open floor two metres off, on a planned detour.
        let c = at(&mut view, &mut states, PINNED_AFTER + 0.15);
        let escape = states[0].escape.expect("open floor to head for");
        assert!((escape.distance(start) - ESCAPE).abs() < 1e-9, "{escape}");
        assert!(map.open(escape, 0.24), "{escape}");
        assert!(
            states[0]
                .route
                .as_ref()
                .is_some_and(crate::plan::Route::leads)
        );
        let route = (states[0].route.as_ref()).map_or(escape, |r| r.path[0]);
        assert!(c.v.length() > 0.1, "{c:?}");
        assert!(
            c.v.normalize().dot((route - start).normalize()) > 0.5,
            "{c:?}"
        );
        // Then it wanders again, and is not pinned while it roams.
        let t = PINNED_AFTER + 0.05 + DETOUR;
        at(&mut view, &mut states, t);
        assert!(states[0].trapped.is_none());
        for k in 1..300 {
            view.pose.pos = start + DVec2::new(0.1 * f64::from(k % 60), 0.0);
            at(&mut view, &mut states, t + f64::from(k) * 0.1);
            assert!(
                states[0].trapped.is_none() && states[0].escape.is_none(),
                "{k}"
            );
        }
    }

    /// A push of a box the robot never saw, obstacle avoidance on top
    /// (layer 3) and `more` schemas with their layers.
    fn pushing_a_box_never_seen(more: &[(Schema, u8)]) -> Vec<Weighted> {
        let push = Schema::Push {
            object: "box".into(),
            goal: DVec2::new(6.0, 0.5),
            offset: 0.25,
            speed: 0.2,
        };
        let mut skill = vec![weighted(push, 1)];
        skill.extend(more.iter().map(|(s, l)| weighted(s.clone(), *l)));
        skill.push(weighted(Schema::AvoidObstacle { range: 0.35 }, 3));
        skill
    }

    /// What a robot at `start` in `world` (its map) sees: one teammate, at
    /// `mate`.
    fn searching(world: crate::spec::PhysicsSpec, start: DVec2, mate: DVec2) -> View {
        let mut view = View {
            map: Some(std::sync::Arc::new(crate::plan::Map::new(&world))),
            radius: 0.12,
            max_speed: 0.3,
            ..View::default()
        };
        view.pose.pos = start;
        view.mates.insert(
            1,
            Mate {
                pos: mate,
                heading: None,
            },
        );
        view
    }

    /// A pusher that never saw its box, held between the hall's west wall
    /// and its south chair by its search's move toward a teammate beyond
    /// the chair (the hidden box, `search-rescue.rtcl`, partition seed
    /// 1616: attraction and avoidance cancelled there for 120 s): after
    /// two looks round and moves within half a metre of one spot its
    /// search is pinned, and it follows a planned detour toward the
    /// teammate for 8 s without stopping to look round, avoidance
    /// superposed on the detour; then it searches as before. A search
    /// that moves on is never pinned.
    #[test]
    fn a_pinned_search_takes_a_detour_to_its_teammate() {
        let skill = pushing_a_box_never_seen(&[(Schema::AvoidTeammate { range: 0.4 }, 2)]);
        let start = DVec2::new(0.41, 0.89);
        let mate = DVec2::new(1.5, 2.3);
        let mut view = searching(crate::plan::tests::hidden_hall(), start, mate);
        let straight = (mate - start).normalize();
        let mut states = Vec::new();
        let at =
            |view: &mut View, states: &mut Vec<State>, t: f64| command_at(&skill, view, states, t);
        // Looking round and heading straight for the teammate by turns,
        // held on the spot: not pinned before two of them.
        let mut k = 0;
        while f64::from(k) * 0.1 < SEARCH_PINNED_AFTER - 0.05 {
            let t = f64::from(k) * 0.1;
            let c = at(&mut view, &mut states, t);
            assert!(states[0].search_moves.trapped.is_none(), "{t}");
            if t % (SEARCH_TURN + SEARCH_MOVE) > SEARCH_TURN + 0.05 {
                assert!(c.v.normalize().dot(straight) > 0.999, "{t}: {c:?}");
            }
            k += 1;
        }
        let pinned = SEARCH_PINNED_AFTER + 0.05;
        at(&mut view, &mut states, pinned);
        assert!(states[0].search_moves.trapped.is_some());
        assert!(
            states[0].trapped.is_none(),
            "the schema's own watch is apart"
        );
        // A look round is due (the third turn), but it moves, on a planned
        // detour round the chair, not straight through it.
        for t in [0.1, 0.2, 3.0, 7.5] {
            let c = at(&mut view, &mut states, pinned + t);
            let r = states[0].search_moves.route.as_ref().expect("a detour");
            assert!(r.leads(), "{t}");
            assert!(c.v.length() > 0.1, "{t}: {c:?}");
            assert!(c.v.normalize().dot(straight) < 0.9, "{t}: {c:?}");
            assert!(
                c.v.normalize().dot((r.path[0] - start).normalize()) > 0.9,
                "{t}: {c:?} toward {:?}",
                r.path[0]
            );
        }
        // The detour over, it heads straight for the teammate again.
        let t = pinned + DETOUR + 0.05;
        at(&mut view, &mut states, t);
        assert!(states[0].search_moves.trapped.is_none());
        let c = at(&mut view, &mut states, t + 0.1);
        assert!(c.v.normalize().dot(straight) > 0.999, "{t}: {c:?}");
        // A search that moves a metre at every move is never pinned.
        let mut states = Vec::new();
        for k in 0..600 {
            let t = f64::from(k) * 0.1;
            let moves = (t / (SEARCH_TURN + SEARCH_MOVE)).floor();
            view.pose.pos = start + DVec2::X * moves;
            at(&mut view, &mut states, t);
            assert!(states[0].search_moves.trapped.is_none(), "{t}");
        }
    }

    /// A search pinned while it wanders beside its teammate (within a
    /// metre, so there is no teammate to head for: a restarted pusher that
    /// never saw the box, its teammate standing between it and the box)
    /// explores instead of wandering off at random: first the far side of
    /// the teammate, on a planned detour, and on from lookout to lookout
    /// after the pin.
    #[test]
    fn a_search_pinned_beside_its_teammate_explores() {
        let skill = pushing_a_box_never_seen(&[]);
        let start = DVec2::new(4.4, 2.3);
        let mate = DVec2::new(3.6, 2.3);
        let mut view = searching(crate::plan::tests::hall(), start, mate);
        let mut states = Vec::new();
        let at =
            |view: &mut View, states: &mut Vec<State>, t: f64| command_at(&skill, view, states, t);
        for k in 0..220 {
            at(&mut view, &mut states, f64::from(k) * 0.1);
            assert!(states[0].lookout.is_none(), "{k}: not exploring yet");
        }
        at(&mut view, &mut states, SEARCH_PINNED_AFTER + 0.05);
        assert!(states[0].search_moves.trapped.is_some());
        // Exploring: first the far side of the teammate, a metre beyond.
        let c = at(&mut view, &mut states, SEARCH_PINNED_AFTER + 0.15);
        let lookout = states[0].lookout.expect("a lookout").at;
        assert!(lookout.distance(past(mate, start, 0.0)) < 1e-9, "{lookout}");
        assert!(c.v.length() > 0.1, "{c:?}");
        // Still exploring once the pin is over.
        view.pose.pos = start.lerp(lookout, 0.5);
        at(&mut view, &mut states, SEARCH_PINNED_AFTER + DETOUR + 1.0);
        assert!(states[0].search_moves.trapped.is_none());
        assert_eq!(states[0].lookout.map(|l| l.at), Some(lookout));
    }

    /// Between its turns, a robot searching for an object heads for the
    /// nearest teammate it knows of (the team works on the object, most
    /// likely near it) while farther than a metre from it; a lost
    /// teammate's body does not count.
    #[test]
    fn a_search_heads_for_the_nearest_teammate() {
        let skill = vec![weighted(
            Schema::Face {
                target: Target::Object("box".into()),
            },
            1,
        )];
        let mut view = View::default();
        // Its first turn, then the search's next leg.
        let search = |view: &mut View| {
            let mut states = Vec::new();
            view.skill_time = 0.0;
            command(&skill, view, &mut states, &mut || 0.5);
            view.skill_time = SEARCH_TURN + 1.0;
            command(&skill, view, &mut states, &mut || 0.5)
        };
        let mate = |x: f64, y: f64| Mate {
            pos: DVec2::new(x, y),
            heading: None,
        };
        view.mates.insert(1, mate(0.0, 3.0));
        view.mates.insert(2, mate(-2.0, 0.0));
        // Robot 2, the nearer, is a lost teammate's body.
        view.bodies.push(DVec2::new(-2.0, 0.0));
        let c = search(&mut view);
        assert!(c.v.y > 0.0 && c.v.x.abs() < 1e-9, "{c:?}");
        // Within a metre of it: it wanders instead.
        view.pose.pos = DVec2::new(0.0, 2.5);
        let c = search(&mut view);
        assert!((c.v.length() - SEARCH_SPEED).abs() < 1e-9, "{c:?}");
    }

    /// A pusher that lost its box (one-way seed 217 of the hidden box: its
    /// teammate pushed the box on out of its sight, then stood between the
    /// two) looks round once, then heads past the live teammate near it,
    /// round it, and looks round there, once a search; a search for an
    /// object never seen does not (the teammate beside it at the start
    /// hides nothing).
    #[test]
    fn a_search_for_a_box_seen_before_looks_beyond_the_teammate_near_it() {
        let skill = vec![weighted(
            Schema::Push {
                object: "box".into(),
                goal: DVec2::new(0.8, 2.0),
                offset: 0.3,
                speed: 0.2,
            },
            1,
        )];
        let start = DVec2::new(4.6, 2.3);
        let mate = DVec2::new(3.8, 2.3);
        // A metre from the teammate, a sixth of a turn off its far side
        // (west), toward where the box was last seen (north-east).
        let beyond = mate + DVec2::from_angle(2.0 * std::f64::consts::FRAC_PI_3) * VANTAGE;
        let mut view = searching(crate::plan::tests::hall(), start, mate);
        let run = |view: &mut View, states: &mut Vec<State>, t: f64| {
            view.skill_time = t;
            command(&skill, view, states, &mut || 0.5)
        };
        for seen in [true, false] {
            view.pose.pos = start;
            view.objects.clear();
            if seen {
                // Last seen north-east, and not there (a full turn showed it
                // gone).
                view.objects.insert("box".into(), DVec2::new(5.2, 2.8));
            }
            let mut states = vec![State {
                gone: seen,
                ..State::default()
            }];
            // A look round first ...
            let c = run(&mut view, &mut states, 1.0);
            assert!(c.face.is_some() && c.v == DVec2::ZERO, "{c:?}");
            let c = run(&mut view, &mut states, 1.0 + SEARCH_TURN + 0.1);
            if !seen {
                // ... then, never seen, not beyond the teammate.
                assert!(matches!(states[0].beyond, Beyond::NotYet));
                continue;
            }
            // ... then past the teammate, round it.
            let Beyond::Going(Lookout { at, .. }) = states[0].beyond else {
                panic!("past the teammate: {:?}", states[0].beyond);
            };
            assert!(at.distance(beyond) < 1e-9, "{at}");
            let way = (beyond - start).normalize();
            assert!(c.v.normalize().dot(way) > 0.99, "{c:?}");
            // There: a look round ...
            view.pose.pos = beyond;
            let c = run(&mut view, &mut states, 10.0);
            assert!(c.face.is_some() && c.v == DVec2::ZERO, "{c:?}");
            // ... and then the search goes on as before, not beyond again.
            run(&mut view, &mut states, 10.0 + SEARCH_TURN + 0.1);
            assert!(matches!(states[0].beyond, Beyond::Done));
            view.pose.pos = start;
            run(&mut view, &mut states, 20.0 + SEARCH_TURN + 0.1);
            assert!(matches!(states[0].beyond, Beyond::Done), "once a search");
        }
    }

    /// A search that has not found its object for [`EXPLORE_AFTER`] s,
    /// having looked round near its teammate [`LOOKS_NEAR_MATE`] times,
    /// explores: the far side of the teammate first (it may hide the
    /// object), then open floor [`LOOK_APART`] m from where it has looked,
    /// looking round at each; the teammate (a watcher trailing its pusher,
    /// so heading for it kept both where they were) no longer leads it.
    /// Seeing the object ends the search, and the next one starts where
    /// teammates are again. A teammate never near is headed for as before.
    #[test]
    fn a_long_search_explores_the_hall_instead_of_following_its_follower() {
        let skill = vec![weighted(
            Schema::Face {
                target: Target::Object("box".into()),
            },
            1,
        )];
        let start = DVec2::new(0.5, 0.7);
        // The teammate 1.2 m east: the search heads for it ...
        let mate = DVec2::new(1.7, 0.7);
        let mut view = searching(crate::plan::tests::hall(), start, mate);
        let mut states = Vec::new();
        let mut rng = || 0.5;
        let mut at = |view: &mut View, states: &mut Vec<State>, t: f64| {
            view.skill_time = t;
            command(&skill, view, states, &mut rng)
        };
        let cycle = SEARCH_TURN + SEARCH_MOVE;
        for k in 0..LOOKS_NEAR_MATE {
            // Looks round, the teammate near ...
            let c = at(&mut view, &mut states, cycle * f64::from(k) + 1.0);
            assert!(c.face.is_some() && c.v == DVec2::ZERO, "{c:?}");
            // ... and heads for it between turns.
            let c = at(
                &mut view,
                &mut states,
                cycle * f64::from(k) + SEARCH_TURN + 1.0,
            );
            assert!(c.v.x > 0.0 && c.v.y.abs() < 1e-9, "{c:?}");
            // (It moves, and comes back: a search held on one spot for
            // two turns would be pinned.)
            view.pose.pos = start + DVec2::Y * 0.6;
            at(
                &mut view,
                &mut states,
                cycle * f64::from(k) + SEARCH_TURN + 2.0,
            );
            view.pose.pos = start;
        }
        assert_eq!(states[0].looks_near_mate.0, LOOKS_NEAR_MATE);
        // Its pilot makes the arena's map for it once it has searched that
        // long (the search began at 1 s).
        assert!(!states[0].needs_map(EXPLORE_AFTER) && states[0].needs_map(EXPLORE_AFTER + 1.0));
        // After EXPLORE_AFTER, with LOOKS_NEAR_MATE looks round near the
        // teammate in vain, it explores: first the far side of the
        // teammate (which may have hidden the object all along) ...
        let c = at(&mut view, &mut states, EXPLORE_AFTER + 1.1);
        let lookout = states[0].lookout.expect("a lookout").at;
        assert!(
            lookout.distance(DVec2::new(1.7 + VANTAGE, 0.7)) < 1e-9,
            "{lookout}"
        );
        assert!(c.v.normalize().dot(DVec2::X) > 0.99, "{c:?} for {lookout}");
        // Still on its way after 20 s: it keeps going.
        view.pose.pos = start.lerp(lookout, 0.5);
        at(&mut view, &mut states, EXPLORE_AFTER + 20.0);
        assert_eq!(states[0].lookout.map(|l| l.at), Some(lookout));
        // There: it looks round ...
        view.pose.pos = lookout;
        let c = at(&mut view, &mut states, EXPLORE_AFTER + 30.0);
        assert!(c.face.is_some() && c.v == DVec2::ZERO, "{c:?}");
        let c = at(
            &mut view,
            &mut states,
            EXPLORE_AFTER + 30.0 + SEARCH_TURN - 0.5,
        );
        assert!(c.face.is_some(), "{c:?}");
        // ... then heads for the next: the nearest open floor LOOK_APART
        // from both places it looked from, whatever its teammate does.
        let c = at(&mut view, &mut states, EXPLORE_AFTER + 31.0 + SEARCH_TURN);
        let next = states[0].lookout.expect("the next lookout").at;
        assert_eq!(states[0].looked, vec![start, lookout]);
        assert!(
            next.distance(start) >= LOOK_APART && next.distance(lookout) >= LOOK_APART,
            "{next}"
        );
        assert!(next.distance(lookout) < LOOK_APART + 0.2, "{next}");
        let way = (next - lookout).normalize();
        assert!(c.v.normalize().dot(way) > 0.99, "{c:?} for {next}");
        // The object seen: the search is over, and forgotten.
        view.objects.insert("box".into(), DVec2::new(6.0, 3.0));
        at(&mut view, &mut states, EXPLORE_AFTER + 40.0);
        assert!(states[0].lookout.is_none() && states[0].looked.is_empty());
        assert!(states[0].lost.is_none());
        assert_eq!(states[0].looks_near_mate, (0, None));
        // A teammate never near: after EXPLORE_AFTER the search still heads
        // for it (the team is at work on the object, most likely near it).
        let mut view = view.clone();
        view.objects.clear();
        view.pose.pos = start;
        view.mates.insert(
            1,
            Mate {
                pos: DVec2::new(3.5, 0.7),
                heading: None,
            },
        );
        let mut states = Vec::new();
        for k in 0..5 {
            view.pose.pos = start;
            at(&mut view, &mut states, cycle * f64::from(k) + 1.0);
            view.pose.pos = start + DVec2::Y * 0.6;
            at(
                &mut view,
                &mut states,
                cycle * f64::from(k) + SEARCH_TURN + 2.0,
            );
        }
        view.pose.pos = start;
        let c = at(&mut view, &mut states, cycle * 5.0 + SEARCH_TURN + 1.0);
        assert!(c.v.x > 0.0 && c.v.y.abs() < 1e-9, "{c:?}");
        assert!(states[0].lookout.is_none());
    }

    /// A skill whose object was never seen looks round for it, then
    /// wanders and looks again, its avoidance still on (a restarted robot
    /// with its teammate standing between it and the box never saw it
    /// turning on the spot).
    #[test]
    fn a_robot_that_never_saw_the_object_looks_round_then_wanders() {
        let skill = vec![
            weighted(
                Schema::Face {
                    target: Target::Object("box".into()),
                },
                1,
            ),
            weighted(Schema::AvoidTeammate { range: 0.7 }, 2),
        ];
        let view = |t: f64| View {
            skill_time: t,
            ..View::default()
        };
        let mut states = Vec::new();
        let mut rng = || 0.5;
        let c = command(&skill, &view(10.0), &mut states, &mut rng);
        assert_eq!(c.v, DVec2::ZERO);
        assert!(c.face.is_some(), "{c:?}");
        let c = command(
            &skill,
            &view(10.0 + SEARCH_TURN + 1.0),
            &mut states,
            &mut rng,
        );
        assert!((c.v.length() - SEARCH_SPEED).abs() < 1e-9, "{c:?}");
    }
}
