//! The robot's side of the physical world: what one robot's mind keeps
//! between control ticks (the skill it runs and its schemas' state, what
//! it remembers of objects and teammates, who holds the roles it refers
//! to) and what it makes of its sensor readings.
//!
//! A [`Pilot`] turns the raw readings of a tick ([`Sensed`], from
//! `bite_sim::physics::World::observe` or from a real robot's drivers) into percepts
//! and, through the scenario's `beliefs:` expressions, into the beliefs its
//! graph reads ([`Pilot::perceive`]); it fuses the schemas of its current
//! skill into a velocity command ([`Pilot::control`]) that the world
//! carries out (`bite_sim::physics::World::actuate`). It never touches the physics:
//! in the simulator each robot's `Agent` keeps one; a
//! robot process talking to a simulator server keeps its own.

use crate::schema::{self, Command, Mate, Sensed, State, View, Weighted};
use crate::spec::{PhysicsSpec, in_rect};
use bite_core::cond::{Env, Expr, Resolver};
use bite_core::diag::{Diagnostic, Diagnostics};
use bite_core::ids::{BehaviorId, BeliefId};
use bite_core::value::Value;
use glam::DVec2;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Seconds a teammate's sighting counts as knowing where it is
/// (`teammates_known`, avoid-teammate).
pub const MATE_MEMORY: f64 = 3.0;

/// The percepts every robot computes, by name.
#[derive(Clone, Debug, Default)]
struct Percepts {
    names: Vec<String>,
    index: BTreeMap<String, BeliefId>,
}

impl Percepts {
    fn add(&mut self, name: String) {
        if !self.index.contains_key(&name) {
            self.index
                .insert(name.clone(), BeliefId(self.names.len() as u32));
            self.names.push(name);
        }
    }
    fn id(&self, name: &str) -> Option<BeliefId> {
        self.index.get(name).copied()
    }
}

struct PerceptResolver<'a> {
    known: &'a Percepts,
    unknown: Vec<String>,
}

impl Resolver for PerceptResolver<'_> {
    fn belief(&mut self, name: &str) -> BeliefId {
        match self.known.id(name) {
            Some(id) => id,
            None => {
                self.unknown.push(name.to_string());
                BeliefId(u32::MAX)
            }
        }
    }
    fn behavior(&self, _: &str) -> Option<BehaviorId> {
        None
    }
}

struct PerceptEnv<'a>(&'a [Option<Value>]);

impl Env for PerceptEnv<'_> {
    fn belief(&self, id: BeliefId) -> Option<&Value> {
        self.0.get(id.index())?.as_ref()
    }
    fn belief_age(&self, _: BeliefId) -> Option<f64> {
        None
    }
    fn elapsed(&self) -> f64 {
        0.0
    }
    fn runs(&self, _: Option<BehaviorId>) -> u32 {
        1
    }
}

/// The percepts every robot has, whatever the scenario; `P_*` are their
/// indices.
const FIXED: [&str; 14] = [
    "x",
    "y",
    "pos",
    "heading",
    "odometer",
    "skill_distance",
    "skill_time",
    "skill_done",
    "range_min",
    "obstacle_near",
    "contact",
    "teammates_seen",
    "teammates_known",
    "reference_pos",
];
const P_X: usize = 0;
const P_Y: usize = 1;
const P_POS: usize = 2;
const P_HEADING: usize = 3;
const P_ODOMETER: usize = 4;
const P_SKILL_DISTANCE: usize = 5;
const P_SKILL_TIME: usize = 6;
const P_SKILL_DONE: usize = 7;
const P_RANGE_MIN: usize = 8;
const P_OBSTACLE_NEAR: usize = 9;
const P_CONTACT: usize = 10;
const P_TEAMMATES_SEEN: usize = 11;
const P_TEAMMATES_KNOWN: usize = 12;
const P_REFERENCE_POS: usize = 13;

/// The names of the percepts a scenario's robots have (fixed ones, and
/// per object, colour and zone).
fn percept_names(spec: &PhysicsSpec) -> Percepts {
    let mut p = Percepts::default();
    // The fixed percepts come first: their ids are their places in `FIXED`.
    for n in FIXED {
        p.add(n.to_string());
    }
    for (key, _) in object_keys(spec) {
        for suffix in KEY_SUFFIXES {
            p.add(format!("{key}_{suffix}"));
        }
    }
    for z in spec.zones.keys() {
        p.add(format!("in_{z}"));
    }
    p
}

/// Objects are seen by name and by colour: each key, and the objects
/// that answer to it.
fn object_keys(spec: &PhysicsSpec) -> Vec<(String, Vec<usize>)> {
    let mut keys: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, o) in spec.objects.iter().enumerate() {
        for k in o.name.iter().chain(o.colour.iter()) {
            match keys.iter_mut().find(|(x, _)| x == k) {
                Some((_, objects)) => objects.push(i),
                None => keys.push((k.clone(), vec![i])),
            }
        }
    }
    // Targets: a name for the objects that fit a description.
    for (name, t) in &spec.targets {
        let fits: Vec<usize> = (spec.objects.iter().enumerate())
            .filter(|(_, o)| t.fits(o))
            .map(|(i, _)| i)
            .collect();
        match keys.iter_mut().find(|(x, _)| x == name) {
            Some((_, objects)) => *objects = fits,
            None => keys.push((name.clone(), fits)),
        }
    }
    keys
}

/// An object key with the ids of its percepts.
#[derive(Debug)]
struct KeyPercepts {
    key: String,
    objects: Vec<usize>,
    /// `<key>_seen`, `_pos`, `_distance`, `_bearing`.
    ids: [BeliefId; 4],
}

const KEY_SUFFIXES: [&str; 4] = ["seen", "pos", "distance", "bearing"];

/// A compiled `beliefs:` entry.
#[derive(Debug)]
struct Mapped {
    belief: BeliefId,
    expr: Expr,
}

/// Check a scenario's `beliefs:` against the percepts its world has.
pub fn check_beliefs(spec: &PhysicsSpec, file: &Arc<str>) -> Vec<Diagnostic> {
    let percepts = percept_names(spec);
    let mut d = Vec::new();
    for (name, text, loc) in &spec.beliefs {
        let mut r = PerceptResolver {
            known: &percepts,
            unknown: Vec::new(),
        };
        match Expr::parse(text, &mut r) {
            Err(e) => d.push(Diagnostic::error(
                file,
                *loc,
                "bad-belief",
                format!("belief `{name}`: {e}"),
            )),
            Ok(_) if !r.unknown.is_empty() => d.push(
                Diagnostic::error(
                    file,
                    *loc,
                    "unknown-percept",
                    format!(
                        "belief `{name}` reads `{}`, which no sensor provides",
                        r.unknown[0]
                    ),
                )
                .with_hint(
                    bite_core::diag::did_you_mean(
                        &r.unknown[0],
                        percepts.names.iter().map(String::as_str),
                    )
                    .unwrap_or_else(|| format!("the percepts are: {}", percepts.names.join(", "))),
                ),
            ),
            Ok(_) => {}
        }
    }
    d
}

/// How a scenario's percepts become a graph's beliefs: the percepts'
/// ids, the object keys and zones they are computed from, and the graph
/// beliefs they set, directly (same name) or through the scenario's
/// `beliefs:` expressions. The same for every robot of a run, and
/// immutable: shared by the robots' pilots.
#[derive(Debug)]
pub struct PerceptTables {
    percepts: Percepts,
    /// Percept ids by object key.
    object_keys: Vec<KeyPercepts>,
    /// The rectangle of each zone and the id of its `in_<zone>`.
    zone_ids: Vec<([f64; 4], BeliefId)>,
    /// Graph beliefs the percepts set directly (same name): percept → graph id.
    direct: Vec<(BeliefId, BeliefId)>,
    mapped: Vec<Mapped>,
}

impl PerceptTables {
    /// The tables of the scenario `spec` (read from `file`) for a graph
    /// whose beliefs are `symbols`; an error for each `beliefs:`
    /// expression that cannot be computed from the percepts.
    pub fn new(
        spec: &PhysicsSpec,
        symbols: &bite_core::belief::Symbols,
        file: &Arc<str>,
    ) -> Result<Arc<PerceptTables>, Diagnostics> {
        let percepts = percept_names(spec);
        let mut errors = Vec::new();
        let mut mapped = Vec::new();
        for (name, text, loc) in &spec.beliefs {
            let Some(belief) = symbols.get(name) else {
                continue; // nobody reads it (the scenario check warns)
            };
            let mut r = PerceptResolver {
                known: &percepts,
                unknown: Vec::new(),
            };
            match Expr::parse(text, &mut r) {
                Ok(expr) if r.unknown.is_empty() => mapped.push(Mapped { belief, expr }),
                _ => errors.push(Diagnostic::error(
                    file,
                    *loc,
                    "bad-belief",
                    format!("belief `{name}` cannot be computed from the percepts"),
                )),
            }
        }
        if !errors.is_empty() {
            return Err(Diagnostics(errors));
        }
        let direct = percepts
            .names
            .iter()
            .enumerate()
            .filter(|(_, n)| !spec.beliefs.iter().any(|(b, _, _)| b == *n))
            .filter_map(|(i, n)| symbols.get(n).map(|g| (BeliefId(i as u32), g)))
            .collect();
        let id = |n: String| percepts.id(&n).unwrap_or(BeliefId(u32::MAX));
        let object_keys = object_keys(spec)
            .into_iter()
            .map(|(key, objects)| KeyPercepts {
                ids: KEY_SUFFIXES.map(|x| id(format!("{key}_{x}"))),
                key,
                objects,
            })
            .collect();
        let zone_ids = (spec.zones.iter())
            .map(|(z, r)| (*r, id(format!("in_{z}"))))
            .collect();
        Ok(Arc::new(PerceptTables {
            percepts,
            object_keys,
            zone_ids,
            direct,
            mapped,
        }))
    }

    /// The graph beliefs that are about the robot itself (its pose, its
    /// skill, its odometry, the zone it is in, what it sees of teammates):
    /// computed from those percepts alone or in part. A world model never
    /// shares them: a teammate's `skill_done` says nothing about mine.
    pub fn private_beliefs(&self) -> Vec<BeliefId> {
        // Measured from this robot: its pose, its zone, its view (whether it
        // sees an object now, how far, at what bearing). Where an object
        // was seen (`<key>_pos`) is a fact about the world.
        let personal = |p: BeliefId| {
            p.index() < FIXED.len()
                || self.zone_ids.iter().any(|(_, z)| *z == p)
                || (self.object_keys.iter())
                    .any(|k| k.ids[0] == p || k.ids[2] == p || k.ids[3] == p)
        };
        let mut out: Vec<BeliefId> = (self.direct.iter())
            .filter(|(p, _)| personal(*p))
            .map(|(_, g)| *g)
            .collect();
        out.extend(
            (self.mapped.iter())
                .filter(|m| m.expr.beliefs().iter().any(|p| personal(*p)))
                .map(|m| m.belief),
        );
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The percepts' names, in id order.
    pub fn names(&self) -> &[String] {
        &self.percepts.names
    }
}

/// One robot's mind in the physical world: its current skill and what it
/// remembers, turning sensor readings into beliefs and its skill's
/// schemas into velocity commands.
#[derive(Debug)]
pub struct Pilot {
    spec: Arc<PhysicsSpec>,
    tables: Arc<PerceptTables>,
    /// Skill of the current leaf.
    skill: Arc<[Weighted]>,
    states: Vec<State>,
    skill_started: f64,
    skill_odometer: f64,
    leaf: Option<BehaviorId>,
    /// Last seen positions of objects, by name and by colour.
    seen_objects: BTreeMap<String, DVec2>,
    /// Last seen teammates.
    mates: BTreeMap<u32, (Mate, f64)>,
    /// Robots holding each sibling role (set by the runner).
    roles: BTreeMap<String, u32>,
    /// The robot this one's schemas refer to, for the pictures.
    link: Option<u32>,
    /// The last robot it kept a slot on or followed (its reference in the
    /// formation, kept while it searches).
    anchor: Option<u32>,
    /// What it sensed last.
    view: View,
    /// The percepts of the last reading, by percept id.
    values: Vec<Option<Value>>,
    /// Teammates presumed lost (their bodies are obstacles).
    lost: std::collections::BTreeSet<u32>,
    /// The arena as this robot knows it, built when first needed.
    map: Option<Arc<crate::plan::Map>>,
    /// The steps the current skill's execution has made ([`State::marks`]),
    /// and the world time of the last new one, of any skill.
    marks: u32,
    progressed_at: Option<f64>,
}

impl Pilot {
    /// A robot's pilot in the scenario `spec`, with the percept tables
    /// every robot of the run shares; idle until its first leaf.
    pub fn new(spec: Arc<PhysicsSpec>, tables: Arc<PerceptTables>) -> Pilot {
        let values = vec![None; tables.percepts.names.len()];
        Pilot {
            spec,
            tables,
            skill: Arc::from(Vec::new()),
            states: Vec::new(),
            skill_started: 0.0,
            skill_odometer: 0.0,
            leaf: None,
            seen_objects: BTreeMap::new(),
            mates: BTreeMap::new(),
            roles: BTreeMap::new(),
            link: None,
            anchor: None,
            view: View::default(),
            values,
            lost: std::collections::BTreeSet::new(),
            map: None,
            marks: 0,
            progressed_at: None,
        }
    }

    /// Take the percept tables of a new version of the mission, keeping
    /// what it has seen (objects, teammates, the map).
    pub fn set_tables(&mut self, tables: Arc<PerceptTables>) {
        self.values = vec![None; tables.percepts.names.len()];
        self.tables = tables;
    }

    /// The pilot of robot `robot` of the team `names`, for a process that
    /// runs that robot alone: from the scenario `spec` (read from `file`)
    /// and the symbol table of the beliefs its graph reads, with the same
    /// tables the simulator's `World::new` builds.
    pub fn for_robot(
        spec: Arc<PhysicsSpec>,
        names: &[String],
        symbols: &bite_core::belief::Symbols,
        file: &Arc<str>,
        robot: usize,
    ) -> Result<Pilot, Diagnostics> {
        if robot >= names.len() {
            let loc = bite_core::diag::Loc::UNKNOWN;
            return Err(Diagnostics(vec![Diagnostic::error(
                file,
                loc,
                "unknown-robot",
                format!("robot {robot} is not in a team of {}", names.len()),
            )]));
        }
        let tables = PerceptTables::new(&spec, symbols, file)?;
        Ok(Pilot::new(spec, tables))
    }

    /// The percept tables it reads readings with.
    pub fn tables(&self) -> &Arc<PerceptTables> {
        &self.tables
    }

    /// The graph beliefs that are about the robot itself (see
    /// [`PerceptTables::private_beliefs`]).
    pub fn private_beliefs(&self) -> Vec<BeliefId> {
        self.tables.private_beliefs()
    }

    /// The leaf behavior it runs the skill of (`None`: idle).
    pub fn leaf(&self) -> Option<BehaviorId> {
        self.leaf
    }

    /// The robot its schemas refer to (the one it keeps a slot on or
    /// follows), as of its last command.
    pub fn link(&self) -> Option<u32> {
        self.link
    }

    /// When (world time) its current skill started.
    pub fn skill_started(&self) -> f64 {
        self.skill_started
    }

    /// The percept `name` as of its last reading (`None`: no such percept,
    /// or unknown).
    pub fn percept(&self, name: &str) -> Option<&Value> {
        let id = self.tables.percepts.id(name)?;
        self.values.get(id.index())?.as_ref()
    }

    /// The teammate its skill keeps a slot on or follows (the holder of
    /// the role the schema names), with the slot's side and distance for
    /// `keep-slot`.
    pub fn reference(&self) -> Option<(u32, Option<(schema::Side, f64)>)> {
        self.skill.iter().find_map(|w| match &w.schema {
            schema::Schema::KeepSlot {
                of, side, distance, ..
            } => self.roles.get(of).map(|l| (*l, Some((*side, *distance)))),
            schema::Schema::Follow { of, .. } => self.roles.get(of).map(|l| (*l, None)),
            _ => None,
        })
    }

    /// The world time at which its skill last made a step toward its end
    /// (see [`State::marks`]: a sweep coming nearer its next waypoint),
    /// if one ever did.
    pub fn progressed_at(&self) -> Option<f64> {
        self.progressed_at
    }

    /// It starts the skill of a new leaf behavior (or none) at world time
    /// `t`, its odometer reading `odometer`.
    pub fn leaf_changed(
        &mut self,
        t: f64,
        odometer: f64,
        leaf: Option<BehaviorId>,
        skill: Arc<[Weighted]>,
    ) {
        self.leaf = leaf;
        self.skill = skill;
        self.states.clear();
        self.marks = 0;
        self.skill_started = t;
        self.skill_odometer = odometer;
    }

    /// The teammates its kernel presumes lost: their bodies (where it last
    /// saw them) become obstacles it routes around.
    pub fn set_lost(&mut self, lost: impl IntoIterator<Item = u32>) {
        self.lost.clear();
        self.lost.extend(lost);
        if !self.lost.is_empty() && self.map.is_none() {
            self.map = Some(Arc::new(crate::plan::Map::new(&self.spec)));
        }
    }

    /// Who holds each sibling role (behavior name → robot), and its rank
    /// among the robots running its behavior (rank, count).
    pub fn set_roles(&mut self, roles: BTreeMap<String, u32>, rank: (u32, u32)) {
        self.roles = roles;
        self.view.rank = rank;
    }

    /// Ask for the state [`Pilot::perceive`] and the schemas read first
    /// to be brought into the cache (see `Agent::prefetch`).
    pub fn prefetch(&self) {
        use bite_core::hint::{prefetch, prefetch_slice};
        prefetch_slice(&self.states, 8);
        prefetch_slice(&self.values, 16);
        prefetch(self.view.rays.as_ptr());
    }

    /// What it makes of a tick's readings: updates what it remembers of
    /// objects and teammates, and writes the graph beliefs its percepts
    /// give into `out`.
    pub fn perceive(&mut self, s: &Sensed, out: &mut Vec<(BeliefId, Value)>) {
        let t = s.t;
        let pose = s.pose;
        // Teammates in sight.
        let mut mates_seen = 0;
        for &(j, est) in &s.mates {
            mates_seen += 1;
            let heading = self.mates.get(&j).and_then(|(m, at)| {
                let moved = est - m.pos;
                if moved.length() > 0.03 && t - at < 2.0 {
                    Some(moved.y.atan2(moved.x))
                } else {
                    m.heading
                }
            });
            // Keep the old sighting as the reference for the heading
            // until the mate has moved enough to tell.
            let keep_old = self
                .mates
                .get(&j)
                .is_some_and(|(m, at)| est.distance(m.pos) <= 0.03 && t - at < 2.0);
            if !keep_old {
                self.mates.insert(j, (Mate { pos: est, heading }, t));
            }
        }
        // Objects in sight, under each key they answer to.
        let mut seen_now: Vec<usize> = Vec::new();
        for &(k, est) in &s.objects {
            for (key, ids) in self.tables.object_keys.iter().enumerate() {
                if ids.objects.contains(&k) {
                    self.seen_objects.insert(ids.key.clone(), est);
                    seen_now.push(key);
                }
            }
        }
        // Forget teammates long out of sight, unless a role refers to them.
        {
            let (anchor, roles) = (self.anchor, &self.roles);
            self.mates.retain(|k, (_, at)| {
                t - *at <= 10.0 * MATE_MEMORY
                    || anchor == Some(*k)
                    || roles.values().any(|v| v == k)
            });
        }
        // Percepts.
        let tables = &*self.tables;
        let skill_done = self.states.iter().any(|s| s.finished);
        let range_min = (s.rays.iter())
            .map(|(_, d)| *d)
            .fold(self.spec.sensors.ray_range, f64::min);
        let known = (self.mates.values())
            .filter(|(_, at)| t - at <= MATE_MEMORY)
            .count();
        let reference = self
            .anchor
            .and_then(|a| self.mates.get(&a))
            .map_or(pose.pos, |(m, _)| m.pos);
        let v = &mut self.values;
        v[P_X] = Some(Value::Num(pose.pos.x));
        v[P_Y] = Some(Value::Num(pose.pos.y));
        v[P_POS] = Some(Value::Vec2([pose.pos.x, pose.pos.y]));
        v[P_HEADING] = Some(Value::Num(pose.heading.to_degrees()));
        v[P_ODOMETER] = Some(Value::Num(s.odometer));
        // A leaf without a skill (a team behavior waiting for its
        // allocation, a barrier) is no skill running: its time and
        // distance stay 0 (a leg counted in `skill_time` must not end
        // while the team is still deciding who walks it).
        let running = !self.skill.is_empty();
        v[P_SKILL_DISTANCE] = Some(Value::Num(if running {
            s.odometer - self.skill_odometer
        } else {
            0.0
        }));
        v[P_SKILL_TIME] = Some(Value::Num(if running {
            t - self.skill_started
        } else {
            0.0
        }));
        v[P_SKILL_DONE] = Some(Value::Bool(skill_done));
        v[P_RANGE_MIN] = Some(Value::Num(range_min));
        v[P_OBSTACLE_NEAR] = Some(Value::Bool(range_min < 0.3));
        v[P_CONTACT] = Some(Value::Bool(s.contact));
        v[P_TEAMMATES_SEEN] = Some(Value::Num(mates_seen as f64));
        v[P_TEAMMATES_KNOWN] = Some(Value::Num(known as f64));
        v[P_REFERENCE_POS] = Some(Value::Vec2([reference.x, reference.y]));
        for (k, key) in tables.object_keys.iter().enumerate() {
            let est = self.seen_objects.get(&key.key).copied();
            let [seen, pos, distance, bearing] = key.ids;
            v[seen.index()] = Some(Value::Bool(seen_now.contains(&k)));
            v[pos.index()] = est.map(|p| Value::Vec2([p.x, p.y]));
            v[distance.index()] = est.map(|p| Value::Num(p.distance(pose.pos)));
            v[bearing.index()] = est.map(|p| {
                let off = p - pose.pos;
                Value::Num(schema::wrap(off.y.atan2(off.x) - pose.heading).to_degrees())
            });
        }
        for (rect, id) in &tables.zone_ids {
            v[id.index()] = Some(Value::Bool(in_rect(pose.pos, rect)));
        }
        for (p, g) in &tables.direct {
            if let Some(v) = &v[p.index()] {
                out.push((*g, v.clone()));
            }
        }
        let env = PerceptEnv(v);
        for m in &tables.mapped {
            if let Some(v) = m.expr.eval_value(&env) {
                out.push((m.belief, v));
            }
        }
        // What the schemas read when the robot is next controlled.
        self.view = View {
            pose,
            rays: s.rays.clone(),
            objects: self.seen_objects.clone(),
            in_view: seen_now
                .iter()
                .map(|k| tables.object_keys[*k].key.clone())
                .collect(),
            // Teammates seen lately, and the ones its roles refer to (a
            // stale sighting repels from where a teammate no longer is).
            mates: (self.mates.iter())
                .filter(|(k, (_, at))| {
                    !self.lost.contains(k)
                        && (t - at <= MATE_MEMORY
                            || self.anchor == Some(**k)
                            || self.roles.values().any(|v| v == *k))
                })
                .map(|(k, (m, _))| (*k, *m))
                .collect(),
            roles: BTreeMap::new(),
            skill_time: 0.0,
            max_speed: self.spec.robot.max_speed,
            rank: self.view.rank,
            radius: self.spec.robot.radius,
            bodies: (self.lost.iter())
                .filter_map(|k| self.mates.get(k).map(|(m, _)| m.pos))
                .collect(),
            map: self.map.clone(),
            last_mate: (self.mates.iter())
                .filter(|(k, _)| !self.lost.contains(k))
                .max_by(|(_, (_, a)), (_, (_, b))| a.total_cmp(b))
                .map(|(_, (m, at))| (m.pos, t - at)),
        };
    }

    /// The behavior-selection module: fuse the schemas of its current
    /// skill over what it sensed last into a velocity command, at world
    /// time `t`; `draw` gives the uniform draws in [0, 1) that `wander`
    /// reads.
    pub fn control(&mut self, t: f64, draw: &mut impl FnMut() -> f64) -> Command {
        self.view.roles = self.roles.clone();
        self.view.skill_time = t - self.skill_started;
        let mut cmd = schema::command(&self.skill, &self.view, &mut self.states, draw);
        let marks = self.states.iter().map(State::marks).sum::<u32>();
        if marks > self.marks {
            self.progressed_at = Some(t);
        }
        self.marks = marks;
        // A trapped robot plans its detour on the arena's map, a long
        // search explores it, and a pusher whose object makes no headway
        // plans the object's way round obstacles on it (made the first
        // time one is needed: its next command follows the detour, heads
        // for a lookout, or steers the object). A robot restarted after
        // its teammates were lost knows of none lost, and had no map for
        // its search.
        if self.map.is_none() && (self.states.iter()).any(|s| s.needs_map(self.view.skill_time)) {
            self.map = Some(Arc::new(crate::plan::Map::new(&self.spec)));
        }
        let reference = self.reference();
        self.link = reference.map(|(l, _)| l);
        cmd.label = schema::Label {
            behavior: self.leaf,
            link: self.link,
            // Still getting into its slot during the skill's first second.
            slot: reference
                .filter(|_| t - self.skill_started >= 1.0)
                .and_then(|(l, s)| s.map(|(side, d)| (l, side, d))),
        };
        // A robot that leads (moves to a goal on its own) is its own
        // reference; one that keeps station keeps its reference while it
        // searches.
        if self.link.is_some() {
            self.anchor = self.link;
        } else if self
            .skill
            .iter()
            .any(|w| matches!(w.schema, schema::Schema::MoveToGoal { .. }))
        {
            self.anchor = None;
        }
        cmd
    }
}
