//! The physical world: the robots' bodies. A 2-D top-down arena on
//! rapier2d, robots with differential or holonomic drives, sensors with
//! noise.
//!
//! Two sides, as in Player/Stage. This is the world's side ([`World`]): it
//! owns the physics: bodies, drives, odometry, contacts, trajectories and
//! coverage, and the raw sensing: [`World::observe`] reads robot `i`'s
//! sensors (its noisy pose estimate, range rays, camera sightings of
//! teammates and objects, odometer, contact) into a [`Sensed`], and
//! [`World::actuate`] sets the velocity [`Command`] its drive follows. The
//! robot's side, its mind, is in `bite-agent`: each robot's `Agent` has a
//! [`Pilot`] that turns a [`Sensed`] into percepts and beliefs and fuses
//! the leaf behavior's motor schemas into a [`Command`]. Both ends speak
//! JSON ([`Sensed`] and [`Command`] are serde types), so a robot process
//! drives a body in a simulator server the same way, or a real robot.
//!
//! The runner owns the clock: [`World::advance`] steps the physics at its
//! fixed rate up to a control tick, then each robot's readings go to its
//! `Agent` and its command comes back to [`World::actuate`]. Everything is
//! seeded: a run is a pure function of its inputs.

mod grid;
mod place;
pub mod svg;

use bite_agent::{pilot, schema, spec};

use bite_agent::agent::derive_seed;
use bite_agent::spec::in_rect;
use bite_core::diag::{Diagnostic, Diagnostics};
use bite_core::ids::{BehaviorId, BeliefId};
use bite_core::interaction::Rng;
use bite_core::time::Time;
use glam::DVec2;
pub use pilot::{PerceptTables, Pilot, check_beliefs};
use rand::SeedableRng;
use rapier2d::prelude as rp;
use schema::Pose;
pub use schema::{Command, Sensed};
pub use spec::{Drive, PhysicsSpec, SchemaSpec, Shape};
use std::collections::BTreeMap;
use std::sync::Arc;

/// What a collider is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Wall,
    Obstacle,
    Object(usize),
    Robot(usize),
}

/// One robot's sample of the trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// When.
    pub t: f64,
    /// True position.
    pub pos: DVec2,
    /// True heading, radians.
    pub heading: f64,
    /// The leaf behavior it was running (`None`: idle).
    pub behavior: Option<BehaviorId>,
    /// The robot whose slot it keeps or whom it follows, if any.
    pub link: Option<u32>,
}

/// Robot `i`'s body in the world: what drives it and what its sensors
/// measure (its mind is its [`Pilot`]).
#[derive(Debug)]
struct Robot {
    body: rp::RigidBodyHandle,
    collider: rp::ColliderHandle,
    /// Current forward speed and turn rate (differential) or velocity.
    vel: DVec2,
    turn: f64,
    /// Commanded.
    cmd: Command,
    /// What a differential drive steers toward for `cmd`
    /// ([`schema::steering`], worked out when the command arrives rather than
    /// at each physics step it drives).
    steering: (Option<f64>, f64),
    odometer: f64,
    last_pos: DVec2,
    trail: Vec<Sample>,
    contact: bool,
    /// A body velocity to drive by instead of `cmd`'s (forward, left,
    /// turn): a ROS 2 `cmd_vel` (see [`World::actuate_twist`]).
    twist: Option<(f64, f64, f64)>,
}

/// The physical world of a run.
pub struct World {
    spec: Arc<PhysicsSpec>,
    rw: rp::PhysicsWorld,
    /// What each collider is, by collider index (none is ever removed).
    kinds: Vec<Option<Kind>>,
    /// Each robot's sensor noise (apart from the bodies, so that robots
    /// can be sensed side by side on several threads).
    rngs: Vec<Rng>,
    /// Where everything is for sensing, as of the physics step it was
    /// built at (rebuilt on the first sensing after a step).
    grid: grid::Grid,
    /// Physics steps taken.
    steps: u64,
    coverage: Coverage,
    /// When the next trajectory sample is due (`spec.trail`).
    next_trail: f64,
    robots: Vec<Robot>,
    objects: Vec<rp::RigidBodyHandle>,
    object_trails: Vec<Vec<(f64, DVec2)>>,
    /// When some robot's camera first saw each object.
    first_seen: Vec<Option<f64>>,
    dt: f64,
    t: f64,
    /// How percepts become graph beliefs (shared by the pilots).
    tables: Arc<PerceptTables>,
    goal_met: Option<f64>,
    /// Formation error samples: distance from a slot keeper's true position
    /// to its true slot (sum, count, max).
    slot_error: (f64, u64, f64),
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("t", &self.t)
            .field("robots", &self.robots.len())
            .finish()
    }
}

/// Robots' positions at one moment, for radio range ([`World::radio`]).
#[derive(Clone, Debug)]
pub struct Radio {
    range: Option<f64>,
    at: Vec<DVec2>,
}

impl Radio {
    /// Can robot `a` hear robot `b`?
    pub fn in_range(&self, a: usize, b: usize) -> bool {
        within(self.range, || (self.at[a], self.at[b]))
    }
}

/// Are two robots within radio `range` (no range: always)?
fn within(range: Option<f64>, at: impl FnOnce() -> (DVec2, DVec2)) -> bool {
    range.is_none_or(|r| {
        let (a, b) = at();
        a.distance(b) <= r
    })
}

fn v32(v: DVec2) -> rp::Vector {
    rp::Vector::new(v.x as f32, v.y as f32)
}

fn v64(v: rp::Vector) -> DVec2 {
    DVec2::new(v.x as f64, v.y as f64)
}

/// A standard normal draw.
fn gauss(rng: &mut Rng) -> f64 {
    use rand_distr::Distribution;
    rand_distr::StandardNormal.sample(rng)
}

/// Half the thinnest extent of a shape, m.
fn half_thickness(shape: &Shape) -> f64 {
    match shape {
        Shape::Box(s) => s.x.min(s.y) / 2.0,
        Shape::Disc(r) => *r,
    }
}

/// Whether robots need continuous collision detection: a robot at full
/// speed moves more in one physics step than half the thinnest thing it
/// could pass through (itself, a wall, an obstacle, an object), so that a
/// step could carry it across. Otherwise rapier's contacts stop it in
/// time, and CCD's per-step sweep of every robot is pure cost (about 4 %
/// of a one-thread run at 10,000 robots; docs/performance.md,
/// "2026-11-28"). The shipped scenarios move at most 7 mm a step (0.35
/// m/s at 50 Hz) against walls 20 cm thick and robots 24 cm across.
fn needs_ccd(spec: &PhysicsSpec) -> bool {
    let thinnest = (spec.obstacles.iter().map(|o| half_thickness(&o.shape)))
        .chain(spec.objects.iter().map(|o| half_thickness(&o.shape)))
        .fold(spec.robot.radius.min(f64::from(place::WALL_HALF)), f64::min);
    spec.robot.max_speed / spec.hz > thinnest / 2.0
}

fn collider_of(shape: &Shape) -> rp::ColliderBuilder {
    match shape {
        Shape::Box(s) => rp::ColliderBuilder::cuboid(s.x as f32 / 2.0, s.y as f32 / 2.0),
        Shape::Disc(r) => rp::ColliderBuilder::ball(*r as f32),
    }
}

/// Distance from `p` to the edge of body `b` (negative inside).
fn distance_to(b: &spec::Body, p: DVec2) -> f64 {
    let d = p - b.at;
    match b.shape {
        Shape::Disc(r) => d.length() - r,
        Shape::Box(size) => {
            // In the box's own frame.
            let local = DVec2::from_angle(-b.angle).rotate(d);
            let q = local.abs() - size / 2.0;
            q.max(DVec2::ZERO).length() + q.x.max(q.y).min(0.0)
        }
    }
}

/// Where each robot of the team starts: its `start` entry, or, for a
/// robot the scenario does not place, the next free spot of columns at the
/// left of the arena (spots three radii apart, facing +x), skipping spots
/// that a placed robot, an obstacle or an object takes or that lie beyond
/// the arena. `None`: no free spot is left.
fn start_poses(spec: &PhysicsSpec, names: &[String]) -> Vec<Option<(DVec2, f64)>> {
    let r = spec.robot.radius;
    let gap = r * 3.0;
    let rows = ((spec.arena.y - gap) / gap).floor().max(1.0) as usize;
    // Spots keep a radius of clearance from the right wall too.
    let spots = rows.saturating_mul(((spec.arena.x - 2.0 * r) / gap).floor().max(0.0) as usize);
    let placed: Vec<DVec2> = spec.start.values().map(|s| s.0).collect();
    // A spot keeps a radius of clearance, as the spots keep from each
    // other.
    let free = |p: DVec2| {
        placed.iter().all(|q| p.distance(*q) >= gap)
            && spec
                .obstacles
                .iter()
                .chain(&spec.objects)
                .all(|b| distance_to(b, p) >= 2.0 * r)
    };
    let mut next = 0usize;
    names
        .iter()
        .map(|name| {
            if let Some((p, h, _)) = spec.start.get(name) {
                return Some((*p, *h));
            }
            while next < spots {
                let k = next;
                next += 1;
                let p = DVec2::new(
                    gap * (1.0 + (k / rows) as f64),
                    gap * (1.0 + (k % rows) as f64),
                );
                if free(p) {
                    return Some((p, 0.0));
                }
            }
            None
        })
        .collect()
}

impl World {
    /// Build the world for a team of `n` robots named `names`; `graph` is
    /// the symbol table of the beliefs the graph reads.
    pub fn new(
        spec: Arc<PhysicsSpec>,
        names: &[String],
        symbols: &bite_core::belief::Symbols,
        file: &Arc<str>,
        seed: u64,
    ) -> Result<World, Diagnostics> {
        // Objects the seed places, placed (the same for the same seed in
        // every simulator that builds the world).
        let spec = place::place(&spec, names, seed, file).map_err(|e| Diagnostics(vec![e]))?;
        let mut rw = rp::PhysicsWorld::new();
        rw.gravity = rp::Vector::ZERO;
        rw.integration_parameters.dt = (1.0 / spec.hz) as f32;
        let mut kinds: Vec<Option<Kind>> = Vec::new();
        let mut set_kind = |c: rp::ColliderHandle, k: Kind| {
            let at = c.into_raw_parts().0 as usize;
            if kinds.len() <= at {
                kinds.resize(at + 1, None);
            }
            kinds[at] = Some(k);
        };
        // Walls: four thin boxes round the arena.
        for (at, half) in place::walls(spec.arena) {
            let (_, c) = rw.insert(
                rp::RigidBodyBuilder::fixed().translation(at),
                rp::ColliderBuilder::cuboid(half.x, half.y),
            );
            set_kind(c, Kind::Wall);
        }
        for o in &spec.obstacles {
            let (_, c) = rw.insert(
                rp::RigidBodyBuilder::fixed()
                    .translation(v32(o.at))
                    .rotation(o.angle as f32),
                collider_of(&o.shape),
            );
            set_kind(c, Kind::Obstacle);
        }
        let mut objects = Vec::new();
        for (i, o) in spec.objects.iter().enumerate() {
            let (b, c) = rw.insert(
                rp::RigidBodyBuilder::dynamic()
                    .translation(v32(o.at))
                    .rotation(o.angle as f32)
                    .linear_damping(o.damping as f32)
                    .angular_damping(o.damping as f32 * 2.0),
                collider_of(&o.shape).mass(o.mass as f32).friction(0.3),
            );
            set_kind(c, Kind::Object(i));
            objects.push(b);
        }
        let mut robots = Vec::new();
        let mut errors = Vec::new();
        let team: std::collections::BTreeSet<&str> = names.iter().map(String::as_str).collect();
        for (name, (_, _, loc)) in &spec.start {
            if !team.contains(name.as_str()) {
                errors.push(Diagnostic::error(
                    file,
                    *loc,
                    "unknown-robot",
                    format!("`start` places robot `{name}`, which is not in the team"),
                ));
            }
        }
        let poses = start_poses(&spec, names);
        let ccd = needs_ccd(&spec);
        for (i, name) in names.iter().enumerate() {
            let Some((at, heading)) = poses[i] else {
                errors.push(
                    Diagnostic::error(
                        file,
                        spec.loc,
                        "bad-start",
                        format!(
                            "no room for robot `{name}`: the scenario does not place it under \
                             `start`, and no free spot is left in the columns at the left of \
                             the arena"
                        ),
                    )
                    .with_hint("place it under `physics.start`, or use a larger arena"),
                );
                continue;
            };
            let (b, c) = rw.insert(
                rp::RigidBodyBuilder::dynamic()
                    .translation(v32(at))
                    .rotation(heading as f32)
                    .ccd_enabled(ccd),
                rp::ColliderBuilder::ball(spec.robot.radius as f32)
                    .mass(spec.robot.mass as f32)
                    .friction(0.2),
            );
            set_kind(c, Kind::Robot(i));
            robots.push(Robot {
                body: b,
                collider: c,
                vel: DVec2::ZERO,
                turn: 0.0,
                cmd: Command::default(),
                steering: schema::steering(&Command::default()),
                odometer: 0.0,
                last_pos: at,
                trail: Vec::new(),
                contact: false,
                twist: None,
            });
        }
        let tables = match PerceptTables::new(&spec, symbols, file) {
            Ok(tables) => Some(tables),
            Err(d) => {
                errors.extend(d.0);
                None
            }
        };
        let Some(tables) = tables.filter(|_| errors.is_empty()) else {
            return Err(Diagnostics(errors));
        };
        let n_objects = objects.len();
        // One step at rest before the clock starts: it fills the broad
        // phase and the contacts the start check below reads; nothing
        // moves unless it was placed overlapping something.
        rw.step();
        // A robot placed inside a wall, an obstacle, an object or another
        // robot is the scenario's mistake, not a physics puzzle.
        for (i, r) in robots.iter().enumerate() {
            let inside = rw.contact_pairs_with(r.collider).find_map(|p| {
                let other = if p.collider1 == r.collider {
                    p.collider2
                } else {
                    p.collider1
                };
                let (_, c) = p.find_deepest_contact()?;
                (c.dist < -0.01).then_some(other)
            });
            if let Some(other) = inside {
                let what = match kinds
                    .get(other.into_raw_parts().0 as usize)
                    .copied()
                    .flatten()
                {
                    Some(Kind::Wall) => "a wall".to_string(),
                    Some(Kind::Obstacle) => "an obstacle".to_string(),
                    Some(Kind::Object(k)) => format!("object {}", k + 1),
                    Some(Kind::Robot(j)) => format!("robot `{}`", names[j]),
                    None => "something".to_string(),
                };
                // The position of the offending `start` entry: the
                // robot's own, else (a robot the scenario does not place)
                // the teammate's it overlaps, else the `physics:` section.
                let entry = |j: usize| spec.start.get(&names[j]).map(|s| s.2);
                let placed = entry(i);
                let loc = placed
                    .or_else(|| match kinds.get(other.into_raw_parts().0 as usize) {
                        Some(Some(Kind::Robot(j))) => entry(*j),
                        _ => None,
                    })
                    .unwrap_or(spec.loc);
                let mut e = Diagnostic::error(
                    file,
                    loc,
                    "bad-start",
                    format!("robot `{}` starts inside {what}", names[i]),
                );
                if placed.is_none() {
                    let at = poses[i].map_or(DVec2::ZERO, |p| p.0);
                    e = e.with_hint(format!(
                        "`{}` is not placed under `start`, so it stands in a column at the \
                         left, at ({:.2}, {:.2}); place it under `physics.start`",
                        names[i], at.x, at.y
                    ));
                }
                errors.push(e);
            }
        }
        if !errors.is_empty() {
            return Err(Diagnostics(errors));
        }
        let coverage = Coverage::new(spec.arena, robots.len());
        Ok(World {
            dt: 1.0 / spec.hz,
            spec,
            rw,
            kinds,
            rngs: (0..robots.len())
                .map(|i| Rng::seed_from_u64(derive_seed(seed, "sensors", i as u32)))
                .collect(),
            grid: grid::Grid::default(),
            steps: 0,
            coverage,
            next_trail: 0.0,
            robots,
            objects,
            object_trails: vec![Vec::new(); n_objects],
            first_seen: vec![None; n_objects],
            t: 0.0,
            tables,
            goal_met: None,
            slot_error: (0.0, 0, 0.0),
        })
    }

    /// The scenario's world.
    pub fn spec(&self) -> &PhysicsSpec {
        &self.spec
    }

    /// True pose of robot `i`.
    pub fn pose(&self, i: usize) -> Pose {
        let b = &self.rw.bodies[self.robots[i].body];
        Pose {
            pos: v64(b.translation()),
            heading: b.rotation().angle() as f64,
        }
    }

    /// True position of robot `i` (its [`World::pose`] without the
    /// heading, which costs an arctangent).
    pub fn position(&self, i: usize) -> DVec2 {
        v64(self.rw.bodies[self.robots[i].body].translation())
    }

    /// True position of object `i`.
    pub fn object_pos(&self, i: usize) -> DVec2 {
        v64(self.rw.bodies[self.objects[i]].translation())
    }

    /// When some robot's camera first saw object `i` (seconds; `None`:
    /// never so far).
    pub fn first_seen(&self, i: usize) -> Option<f64> {
        self.first_seen.get(i).copied().flatten()
    }

    /// When the scenario's goal (object in zone) was first met.
    pub fn goal_met(&self) -> Option<f64> {
        self.goal_met
    }

    /// How far the scenario's goal object is from its zone now, m (0 in
    /// it; `None`: the scenario has no goal).
    pub fn goal_distance(&self) -> Option<f64> {
        let (obj, zone) = self.spec.goal.as_ref()?;
        let i = (self.spec.objects.iter()).position(|o| o.name.as_ref() == Some(obj))?;
        let z = self.spec.zones.get(zone)?;
        let p = self.object_pos(i);
        let dx = (z[0] - p.x).max(p.x - z[2]).max(0.0);
        let dy = (z[1] - p.y).max(p.y - z[3]).max(0.0);
        Some(dx.hypot(dy))
    }

    /// Distance each robot travelled.
    pub fn odometers(&self) -> Vec<f64> {
        self.robots.iter().map(|r| r.odometer).collect()
    }

    /// Trajectories, for the pictures.
    pub fn trails(&self) -> impl Iterator<Item = &[Sample]> {
        self.robots.iter().map(|r| r.trail.as_slice())
    }

    /// Object trajectories (time, position).
    pub fn object_trails(&self) -> &[Vec<(f64, DVec2)>] {
        &self.object_trails
    }

    /// Step the physics up to `now`, driving each robot by its command
    /// (robots in `stopped` stand still).
    pub fn advance(&mut self, now: Time, stopped: &[bool]) {
        // The floor the robots covered at the last tick is marked while
        // the bodies move (on a second thread of the pool the world steps
        // on, when it has one; it reads only the positions recorded). The
        // bodies move on this thread at once and the marking waits to be
        // taken by the other: the other way round, the world waited for
        // the marking whenever the other thread was asleep (on a virtual
        // machine, woken 1.5 ms late; docs/performance.md, "2026-12-01").
        let mut coverage = std::mem::take(&mut self.coverage);
        if rayon::current_thread_index().is_some() {
            rayon::join(|| self.step_until(now, stopped), || coverage.flush());
        } else {
            coverage.flush();
            self.step_until(now, stopped);
        }
        self.coverage = coverage;
        self.settle();
    }

    /// Step the physics up to `until` only: the bodies move, nothing is
    /// judged (contacts, the goal). [`World::advance`] in several calls of
    /// this then one of `advance` steps exactly as one `advance` does, so a
    /// watcher can see the world between two control ticks without
    /// changing the run.
    pub fn step_until(&mut self, until: Time, stopped: &[bool]) {
        let until = until.as_secs_f64();
        // A robot's odometer counts a step at the next step's drive (one
        // pass over the bodies per step, not two), and after the last.
        let mut stepped = false;
        while self.t + self.dt <= until + 1e-9 {
            for i in 0..self.robots.len() {
                if stepped {
                    self.count_odometer(i);
                }
                self.drive(i, stopped.get(i).copied().unwrap_or(false));
            }
            self.rw.step();
            self.steps += 1;
            self.t += self.dt;
            stepped = true;
        }
        if stepped {
            for i in 0..self.robots.len() {
                self.count_odometer(i);
            }
        }
    }

    /// Robot `i`'s odometer counts how far it went since it last counted.
    fn count_odometer(&mut self, i: usize) {
        let p = self.position(i);
        let r = &mut self.robots[i];
        r.odometer += p.distance(r.last_pos);
        r.last_pos = p;
    }

    /// The physics' own time: the last whole step taken, s.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Contacts and the goal, as of the physics' time.
    fn settle(&mut self) {
        for i in 0..self.robots.len() {
            let c = self.robots[i].collider;
            let touching = self
                .rw
                .contact_pairs_with(c)
                .any(|p| p.has_any_active_contact());
            self.robots[i].contact = touching;
        }
        if self.goal_met.is_none()
            && let Some((obj, zone)) = &self.spec.goal
            && let Some(i) = self
                .spec
                .objects
                .iter()
                .position(|o| o.name.as_ref() == Some(obj))
            && let Some(z) = self.spec.zones.get(zone)
            && in_rect(self.object_pos(i), z)
        {
            self.goal_met = Some(self.t);
        }
    }

    /// Apply robot `i`'s command for one physics step, within its limits.
    fn drive(&mut self, i: usize, stopped: bool) {
        let m = self.spec.robot;
        let dt = self.dt;
        let heading = self.pose(i).heading;
        let r = &mut self.robots[i];
        let cmd = if stopped { Command::default() } else { r.cmd };
        let twist = if stopped {
            r.twist.map(|_| (0.0, 0.0, 0.0))
        } else {
            r.twist
        };
        let step = m.max_accel * dt;
        let (linvel, angvel) = match (m.drive, twist) {
            (Drive::Differential, Some((f, _, turn))) => {
                let f = f.clamp(-m.max_speed, m.max_speed);
                let turn = turn.clamp(-m.max_turn, m.max_turn);
                let cur = r.vel.x;
                let f = cur + (f - cur).clamp(-step, step);
                r.vel = DVec2::new(f, 0.0);
                r.turn = turn;
                (DVec2::from_angle(heading) * f, turn)
            }
            (Drive::Holonomic, Some((f, l, turn))) => {
                let want = DVec2::from_angle(heading).rotate(DVec2::new(f, l));
                let want = if want.length() > m.max_speed {
                    want * (m.max_speed / want.length())
                } else {
                    want
                };
                let dv = want - r.vel;
                let dv = if dv.length() > step {
                    dv * (step / dv.length())
                } else {
                    dv
                };
                r.vel += dv;
                r.turn = turn.clamp(-m.max_turn, m.max_turn);
                (r.vel, r.turn)
            }
            (Drive::Differential, None) => {
                let steering = if stopped {
                    schema::steering(&cmd)
                } else {
                    r.steering
                };
                let (f, turn) =
                    schema::differential_toward(steering, heading, m.max_speed, m.max_turn);
                let cur = r.vel.x;
                let f = cur + (f - cur).clamp(-step, step);
                r.vel = DVec2::new(f, 0.0);
                r.turn = turn;
                (DVec2::from_angle(heading) * f, turn)
            }
            (Drive::Holonomic, None) => {
                let want = {
                    let l = cmd.v.length();
                    if l > m.max_speed {
                        cmd.v * (m.max_speed / l)
                    } else {
                        cmd.v
                    }
                };
                let dv = want - r.vel;
                let dv = if dv.length() > step {
                    dv * (step / dv.length())
                } else {
                    dv
                };
                r.vel += dv;
                let turn = cmd.face.map_or(0.0, |h| {
                    (schema::wrap(h - heading) * 3.0).clamp(-m.max_turn, m.max_turn)
                });
                r.turn = turn;
                (r.vel, turn)
            }
        };
        let b = &mut self.rw.bodies[r.body];
        b.set_linvel(v32(linvel), true);
        b.set_angvel(angvel as f32, true);
    }

    /// Mean and largest formation error seen (m): how far robots keeping a
    /// slot were from it, measured on true poses at every control tick
    /// after their first second in the slot.
    pub fn formation_error(&self) -> Option<(f64, f64)> {
        let (sum, n, max) = self.slot_error;
        (n > 0).then(|| (sum / n as f64, max))
    }

    /// Record one sample of every trajectory (called at control ticks).
    pub fn record(&mut self) {
        for i in 0..self.robots.len() {
            if let Some((l, side, d)) = self.robots[i].cmd.label.slot
                && (l as usize) < self.robots.len()
                && l as usize != i
            {
                let lead = self.pose(l as usize);
                let at = schema::slot_position(lead.pos, lead.heading, side, d);
                let e = at.distance(self.position(i));
                self.slot_error.0 += e;
                self.slot_error.1 += 1;
                self.slot_error.2 = self.slot_error.2.max(e);
            }
        }
        let keep = match self.spec.trail {
            None => true,
            Some(every) => every > 0.0 && self.t + 1e-9 >= self.next_trail,
        };
        if keep && let Some(every) = self.spec.trail {
            self.next_trail = self.t + every;
        }
        for i in 0..self.robots.len() {
            if !keep {
                let p = self.position(i);
                self.coverage.note(i, p);
                continue;
            }
            let p = self.pose(i);
            self.coverage.note(i, p.pos);
            let label = self.robots[i].cmd.label;
            self.robots[i].trail.push(Sample {
                t: self.t,
                pos: p.pos,
                heading: p.heading,
                behavior: label.behavior,
                link: label.link,
            });
        }
        if keep {
            for i in 0..self.objects.len() {
                let p = self.object_pos(i);
                self.object_trails[i].push((self.t, p));
            }
        }
    }

    /// Where everything is, for logs (mm precision): each robot's
    /// `[x, y, heading in degrees]`, and each named object's `[x, y]`.
    pub fn poses(&self) -> (Vec<[f64; 3]>, BTreeMap<String, [f64; 2]>) {
        let mm = |x: f64| (x * 1000.0).round() / 1000.0;
        let robots = (0..self.robots.len())
            .map(|i| {
                let p = self.pose(i);
                [mm(p.pos.x), mm(p.pos.y), mm(p.heading.to_degrees())]
            })
            .collect();
        let objects = (self.spec.objects.iter())
            .enumerate()
            .filter_map(|(k, o)| {
                let p = self.object_pos(k);
                o.name.clone().map(|n| (n, [mm(p.x), mm(p.y)]))
            })
            .collect();
        (robots, objects)
    }

    /// The run-log record of where everything is at `t` (what
    /// [`World::poses`] gives), with what each robot is doing as the
    /// pictures colour it: its leaf behavior (named by `behavior`, `null`
    /// when idle) and the robot whose slot it keeps or whom it follows.
    ///
    /// ```text
    /// {"t":1.0,"event":"poses","robots":[[0.97,1.52,4.845]],"objects":{},"behaviors":["walk"],"links":[null]}
    /// ```
    pub fn poses_record(
        &self,
        t: f64,
        behavior: &dyn Fn(bite_core::ids::BehaviorId) -> String,
    ) -> serde_json::Value {
        let (robots, objects) = self.poses();
        let behaviors: Vec<Option<String>> = (self.robots.iter())
            .map(|r| r.cmd.label.behavior.map(behavior))
            .collect();
        let links: Vec<Option<u32>> = self.robots.iter().map(|r| r.cmd.label.link).collect();
        serde_json::json!({"t": t, "event": "poses", "robots": robots, "objects": objects,
                           "behaviors": behaviors, "links": links})
    }

    /// The run-log record that describes the world once, at the start:
    /// arena size, robot radius, obstacles, objects (start, shape, colour),
    /// zones, the robots' names in roster order (the order of `poses`) and
    /// the graph's behaviors in id order (`palette` gives each its colour
    /// in the pictures: `palette[id % palette.len()]`). What a viewer of
    /// the log (MCAP, the studio) draws the arena from.
    pub fn layout_record(&self, robots: &[String], behaviors: &[String]) -> serde_json::Value {
        let body = |k: usize, b: &spec::Body, pos: DVec2| {
            let (shape, size) = match b.shape {
                Shape::Box(s) => ("box", vec![s.x, s.y]),
                Shape::Disc(r) => ("disc", vec![r]),
            };
            serde_json::json!({"index": k, "name": b.name, "shape": shape, "size": size,
                               "at": [pos.x, pos.y], "angle": b.angle, "colour": b.colour})
        };
        let obstacles: Vec<serde_json::Value> = (self.spec.obstacles.iter())
            .enumerate()
            .map(|(k, b)| body(k, b, b.at))
            .collect();
        let objects: Vec<serde_json::Value> = (self.spec.objects.iter())
            .enumerate()
            .map(|(k, b)| body(k, b, self.object_pos(k)))
            .collect();
        serde_json::json!({
            "t": self.t,
            "event": "world",
            "arena": [self.spec.arena.x, self.spec.arena.y],
            "robots": robots,
            "robot_radius": self.spec.robot.radius,
            "obstacles": obstacles,
            "objects": objects,
            "zones": self.spec.zones,
            "behaviors": behaviors,
            "palette": svg::PALETTE,
        })
    }

    /// Can `a` reach `b` by radio?
    pub fn in_radio_range(&self, a: usize, b: usize) -> bool {
        within(self.spec.sensors.radio_range, || {
            (self.pose(a).pos, self.pose(b).pos)
        })
    }

    /// Who can hear whom as the robots stand now, to ask while the world
    /// itself is stepping on another thread (the same answers as
    /// [`World::in_radio_range`] until it moves).
    pub fn radio(&self) -> Radio {
        let range = self.spec.sensors.radio_range;
        Radio {
            range,
            at: match range {
                Some(_) => (0..self.robots.len()).map(|i| self.pose(i).pos).collect(),
                None => Vec::new(),
            },
        }
    }

    /// What collider `c` is.
    fn kind(&self, c: rp::ColliderHandle) -> Option<Kind> {
        self.kinds
            .get(c.into_raw_parts().0 as usize)
            .copied()
            .flatten()
    }

    /// How far a robot's sensors reach: its camera, or its rays from its
    /// rim (with a margin for rounding: what is within reach is tested
    /// exactly afterwards).
    fn reach(&self) -> f64 {
        let s = self.spec.sensors;
        s.camera_range.max(s.ray_range + self.spec.robot.radius) + 0.25
    }

    /// Bring the sensing grid to the present physics step (once per step
    /// at most, before robots sense).
    fn fresh_grid(&mut self) {
        if self.grid.is_at(self.steps) {
            return;
        }
        let mut grid = std::mem::take(&mut self.grid);
        let colliders = (self.rw.colliders.iter())
            .filter_map(|(h, co)| Some((co.compute_aabb(), self.kind(h)?, h)));
        grid.rebuild(self.steps, 2.0 * self.reach() as f32, colliders);
        self.grid = grid;
    }

    /// Every collider near `at` (its box within `range` on each axis) but
    /// robot `i`'s own, from the sensing grid rather than a scan of the
    /// whole team; sorted, so that rays and noise are drawn in the same
    /// order every run. Rays and the camera test what they are given
    /// exactly, so what they read is the same for any superset of what
    /// is within their reach.
    fn near(&self, i: usize, at: DVec2, range: f64, out: &mut Vec<(Kind, rp::ColliderHandle)>) {
        debug_assert!(self.grid.is_at(self.steps), "the sensing grid is fresh");
        out.clear();
        self.grid.query(at, range, Kind::Robot(i), out);
        out.sort_unstable_by_key(|(k, c)| {
            let (a, b) = match k {
                Kind::Robot(j) => (0, *j),
                Kind::Object(j) => (1, *j),
                Kind::Obstacle => (2, 0),
                Kind::Wall => (3, 0),
            };
            (a, b, c.into_raw_parts().0)
        });
    }

    /// The first of the colliders `near` that a ray hits within `max`:
    /// what it is and how far. Exact as long as `near` holds everything
    /// the ray can reach.
    fn cast(
        &self,
        near: &[(Kind, rp::ColliderHandle)],
        from: DVec2,
        dir: DVec2,
        max: f64,
    ) -> Option<(Kind, f64)> {
        let ray = rp::Ray::new(v32(from), v32(dir));
        let mut best: Option<(Kind, f64)> = None;
        for (k, c) in near {
            let Some(co) = self.rw.colliders.get(*c) else {
                continue;
            };
            if let Some(toi) = co.shape().cast_ray(co.position(), &ray, max as f32, true)
                && best.is_none_or(|(_, b)| (toi as f64) < b)
            {
                best = Some((*k, toi as f64));
            }
        }
        best
    }

    /// Robot `i`'s camera on a target at `at`: its noisy estimate of the
    /// target's position if it is in range, in the field of view and in
    /// sight (the first thing a ray toward it hits is the target itself).
    fn sighting(
        &self,
        rng: &mut Rng,
        near: &[(Kind, rp::ColliderHandle)],
        from: Pose,
        at: DVec2,
        target: Kind,
    ) -> Option<DVec2> {
        let s = self.spec.sensors;
        let off = at - from.pos;
        let len = off.length();
        let bearing = schema::wrap(off.y.atan2(off.x) - from.heading);
        if len > s.camera_range || bearing.abs() > s.fov / 2.0 {
            return None;
        }
        if len > 1e-9
            && let Some((k, _)) = self.cast(near, from.pos, off / len, len)
            && k != target
        {
            return None;
        }
        Some(at + DVec2::new(gauss(rng), gauss(rng)) * s.camera_noise * len)
    }

    /// Robot `i`'s sensors now, raw: its noisy pose estimate, the range
    /// rays, what its camera sees of teammates and objects, its odometer
    /// and whether it touches something (the world's side of sensing; the
    /// noise comes from the robot's own seeded stream).
    pub fn observe(&mut self, i: usize) -> Sensed {
        self.fresh_grid();
        let mut rng = std::mem::replace(&mut self.rngs[i], Rng::seed_from_u64(0));
        let (sensed, seen) = self.sense(i, &mut rng, &mut Vec::new());
        self.rngs[i] = rng;
        self.mark_seen(&seen);
        sensed
    }

    /// Every robot's sensors now ([`World::observe`] for each robot not
    /// `skip`ped), on the threads of the current rayon pool when the team
    /// is large: each robot draws its own noise and the world does not
    /// change while they sense, so the readings are the same for any
    /// number of threads.
    pub fn observe_all(&mut self, skip: &[bool], parallel: bool) -> Vec<Option<Sensed>> {
        use rayon::prelude::*;
        self.fresh_grid();
        let mut rngs = std::mem::take(&mut self.rngs);
        let this = &*self;
        let sense = |near: &mut Vec<(Kind, rp::ColliderHandle)>, (i, rng): (usize, &mut Rng)| {
            if skip.get(i).copied().unwrap_or(false) {
                (None, Vec::new())
            } else {
                let (sensed, seen) = this.sense(i, rng, near);
                (Some(sensed), seen)
            }
        };
        // What each robot sensed and what its camera saw, side by side in
        // two vectors (pairs collected and then moved into a vector of
        // their own were 10,000 readings copied on the run's thread at
        // every tick).
        let (out, seen): (Vec<Option<Sensed>>, Vec<Vec<usize>>) = if parallel {
            (rngs.par_iter_mut().enumerate())
                .with_min_len(16)
                .map_init(Vec::new, sense)
                .unzip()
        } else {
            let mut near = Vec::new();
            (rngs.iter_mut().enumerate())
                .map(|x| sense(&mut near, x))
                .unzip()
        };
        self.rngs = rngs;
        for seen in &seen {
            self.mark_seen(seen);
        }
        out
    }

    /// Objects some camera saw now.
    fn mark_seen(&mut self, seen: &[usize]) {
        for &k in seen {
            self.first_seen[k].get_or_insert(self.t);
        }
    }

    /// Robot `i`'s sensors with its noise `rng` (`near`: scratch), and
    /// the objects its camera saw.
    fn sense(
        &self,
        i: usize,
        rng: &mut Rng,
        near: &mut Vec<(Kind, rp::ColliderHandle)>,
    ) -> (Sensed, Vec<usize>) {
        let s = self.spec.sensors;
        let truth = self.pose(i);
        // Pose estimate.
        let (nx, ny, nh) = (gauss(rng), gauss(rng), gauss(rng));
        let pose = Pose {
            pos: truth.pos + DVec2::new(nx, ny) * s.pose_noise,
            heading: truth.heading + nh * s.pose_noise,
        };
        // Everything a ray or the camera can reach.
        let radius = self.spec.robot.radius;
        self.near(i, truth.pos, self.reach(), near);
        // Range rays, all round.
        let mut rays = Vec::new();
        for k in 0..s.rays {
            let a = std::f64::consts::TAU * k as f64 / s.rays.max(1) as f64;
            let dir = DVec2::from_angle(truth.heading + a);
            if let Some((_, toi)) = self.cast(near, truth.pos, dir, s.ray_range + radius) {
                let noise = gauss(rng) * s.ray_noise;
                rays.push((a, (toi - radius + noise).max(0.0)));
            }
        }
        // Camera: teammates, then objects, in the field of view, in sight.
        let mut mates = Vec::new();
        for &(k, _) in near.iter() {
            let Kind::Robot(j) = k else { continue };
            let p = self.pose(j).pos;
            if let Some(est) = self.sighting(rng, near, truth, p, Kind::Robot(j)) {
                mates.push((j as u32, est));
            }
        }
        let mut objects = Vec::new();
        let mut seen = Vec::new();
        for &(o, _) in near.iter() {
            let Kind::Object(k) = o else { continue };
            let p = self.object_pos(k);
            if let Some(est) = self.sighting(rng, near, truth, p, Kind::Object(k)) {
                objects.push((k, est));
                seen.push(k);
            }
        }
        let r = &self.robots[i];
        let sensed = Sensed {
            t: self.t,
            pose,
            rays,
            mates,
            objects,
            odometer: r.odometer,
            contact: r.contact,
        };
        (sensed, seen)
    }

    /// Robot `i`'s velocity command, which its drive follows from the
    /// next physics step on (what a simulator server does with a command
    /// a robot process sends).
    pub fn actuate(&mut self, i: usize, cmd: Command) {
        self.actuate_steered(i, cmd, schema::steering(&cmd));
    }

    /// [`World::actuate`] with the command's [`schema::steering`] worked
    /// out already (by the robots' threads, side by side).
    pub fn actuate_steered(&mut self, i: usize, cmd: Command, steering: (Option<f64>, f64)) {
        self.robots[i].steering = steering;
        self.robots[i].cmd = cmd;
    }

    /// Drive robot `i` by a body velocity from now on (a ROS 2 `cmd_vel`:
    /// forward and leftward speed, m/s, turn rate, rad/s), within its
    /// limits, instead of by its commands' velocity (their labels still
    /// colour its trail).
    pub fn actuate_twist(&mut self, i: usize, forward: f64, left: f64, turn: f64) {
        let ok = |x: f64| if x.is_finite() { x } else { 0.0 };
        self.robots[i].twist = Some((ok(forward), ok(left), ok(turn)));
    }

    /// Stop driving robot `i` by a body velocity: its commands drive it
    /// again (a `cmd_vel` that went silent).
    pub fn clear_twist(&mut self, i: usize) {
        self.robots[i].twist = None;
    }

    /// Robot `i`'s body velocity: forward speed (m/s, along its heading)
    /// and turn rate (rad/s).
    pub fn body_velocity(&self, i: usize) -> (f64, f64) {
        let r = &self.robots[i];
        let heading = self.pose(i).heading;
        let forward = match self.spec.robot.drive {
            Drive::Differential => r.vel.x,
            Drive::Holonomic => r.vel.dot(DVec2::from_angle(heading)),
        };
        (forward, r.turn)
    }

    /// The graph beliefs that are about the robot itself (its pose, its
    /// skill, its odometry, the zone it is in, what it sees of teammates):
    /// computed from those percepts alone or in part. A world model never
    /// shares them: a teammate's `skill_done` says nothing about mine.
    pub fn private_beliefs(&self) -> Vec<BeliefId> {
        self.tables.private_beliefs()
    }
}

/// Radius around a robot's path counted as covered, m.
pub const COVER_RADIUS: f64 = 0.5;

/// The floor covered so far: cells of `CELL` m within `COVER_RADIUS` of
/// some robot's path, marked as the robots move (kept incrementally, so
/// large teams need no trajectories to measure it).
#[derive(Clone, Debug, Default)]
struct Coverage {
    nx: usize,
    ny: usize,
    covered: fixedbitset::FixedBitSet,
    /// Where each robot last marked the floor.
    last: Vec<Option<DVec2>>,
    /// Where robots were at control ticks, in order, not marked yet
    /// ([`Coverage::flush`]).
    noted: Vec<(u32, DVec2)>,
}

impl Coverage {
    const CELL: f64 = 0.1;
    /// Cells per side at most (the spec limits arenas to this many tenths
    /// of a metre: 2 km, a 50 MB bitset at most).
    const MAX_SIDE: f64 = 20_000.0;

    fn new(arena: DVec2, robots: usize) -> Self {
        let (nx, ny) = (
            (arena.x / Self::CELL).ceil().clamp(0.0, Self::MAX_SIDE) as usize,
            (arena.y / Self::CELL).ceil().clamp(0.0, Self::MAX_SIDE) as usize,
        );
        Coverage {
            nx,
            ny,
            covered: fixedbitset::FixedBitSet::with_capacity(nx * ny),
            last: vec![None; robots],
            noted: Vec::new(),
        }
    }

    /// Robot `i` is at `p`: marked at the next [`Coverage::flush`] (the
    /// world marks while it steps).
    fn note(&mut self, i: usize, p: DVec2) {
        self.noted.push((i as u32, p));
    }

    /// Mark what was noted, in the order it was.
    fn flush(&mut self) {
        let mut noted = std::mem::take(&mut self.noted);
        for &(i, p) in &noted {
            self.mark(i as usize, p);
        }
        noted.clear();
        self.noted = noted;
    }

    /// Robot `i` is at `p`.
    fn mark(&mut self, i: usize, p: DVec2) {
        let cell = Self::CELL;
        // Closer than a cell to where it last marked: nothing new.
        if self.last[i].is_some_and(|l| l.distance(p) < cell) || self.nx == 0 || self.ny == 0 {
            return;
        }
        self.last[i] = Some(p);
        let reach = (COVER_RADIUS / cell).ceil() as i64;
        let (cx, cy) = ((p.x / cell) as i64, (p.y / cell) as i64);
        for gx in (cx - reach).max(0)..=(cx + reach).min(self.nx as i64 - 1) {
            for gy in (cy - reach).max(0)..=(cy + reach).min(self.ny as i64 - 1) {
                let c = DVec2::new((gx as f64 + 0.5) * cell, (gy as f64 + 0.5) * cell);
                if c.distance(p) <= COVER_RADIUS {
                    self.covered.insert(gy as usize * self.nx + gx as usize);
                }
            }
        }
    }

    /// Share of the floor covered, counting what is noted but not marked
    /// yet.
    fn share(&self) -> f64 {
        if !self.noted.is_empty() {
            let mut all = self.clone();
            all.flush();
            return all.share();
        }
        if self.covered.is_empty() {
            return 0.0;
        }
        self.covered.count_ones(..) as f64 / self.covered.len() as f64
    }
}

/// Share of the arena (cells of 0.1 m) within `COVER_RADIUS` of some
/// robot's path, sampled at control ticks.
pub fn coverage(world: &World) -> f64 {
    world.coverage.share()
}

#[cfg(test)]
mod tests {
    use super::*;
    use bite_agent::swarm;
    use bite_core::value::Value;
    use schema::Weighted;

    /// A world of the generated coverage mission for `n` robots.
    fn world(n: usize) -> World {
        let (g, s) = swarm::coverage_mission(n, 10.0);
        let g = bite_core::graph::load_str(&Arc::from("g"), &g).expect("graph");
        let sc = crate::Scenario::load_str(&Arc::from("s"), &s).expect("scenario");
        let names: Vec<String> = (0..n).map(|i| format!("r{i}")).collect();
        let spec = sc.physics.clone().expect("physical");
        World::new(spec, &names, g.symbols(), &Arc::from("s"), 1).expect("world")
    }

    /// Continuous collision detection is on exactly where a step at full
    /// speed could carry a robot across something: off in every shipped
    /// physical scenario and the coverage mission at scale, on for a fast
    /// robot or a thin obstacle.
    #[test]
    fn continuous_collision_detection_where_a_step_could_tunnel() {
        let shipped = [
            include_str!("../../../../examples/scenarios/box-push-hidden-physics.yaml"),
            include_str!("../../../../examples/scenarios/box-push-physics.yaml"),
            include_str!("../../../../examples/scenarios/coverage-physics.yaml"),
            include_str!("../../../../examples/scenarios/coverage-sweep-physics.yaml"),
            include_str!("../../../../examples/scenarios/formation-physics.yaml"),
            include_str!("../../../../examples/scenarios/formation-walk-physics.yaml"),
            include_str!("../../../../examples/scenarios/red-cube-physics.yaml"),
            include_str!("../../../../examples/scenarios/search-rescue-hidden-physics.yaml"),
            include_str!("../../../../examples/scenarios/search-rescue-physics.yaml"),
        ];
        let mut spec = None;
        for text in shipped {
            let sc = crate::Scenario::load_str(&Arc::from("s"), text).expect("scenario");
            let s = sc.physics.clone().expect("physical");
            assert!(!needs_ccd(&s), "{}", sc.name);
            spec = Some(s);
        }
        let (_, s) = swarm::coverage_mission(1000, 10.0);
        let sc = crate::Scenario::load_str(&Arc::from("s"), &s).expect("scenario");
        assert!(!needs_ccd(sc.physics.as_ref().expect("physical")));
        let mut s = (*spec.expect("a shipped scenario")).clone();
        let slow = s.robot.max_speed;
        s.robot.max_speed = s.hz * s.robot.radius; // a radius per step
        assert!(needs_ccd(&s), "fast robot");
        s.robot.max_speed = slow;
        s.obstacles.push(spec::Body {
            name: None,
            at: DVec2::ONE,
            place: None,
            angle: 0.0,
            shape: Shape::Box(DVec2::new(2.0, slow / s.hz)), // a step thick
            colour: None,
            mass: 1.0,
            damping: 0.0,
        });
        assert!(needs_ccd(&s), "thin obstacle");
    }

    /// Everything within `range` of `at`, by scanning every collider.
    fn scan(w: &World, i: usize, at: DVec2, range: f64) -> Vec<Kind> {
        let mut out: Vec<Kind> = (w.rw.colliders.iter())
            .filter_map(|(c, co)| {
                let k = w.kind(c)?;
                if k == Kind::Robot(i) {
                    return None;
                }
                let aabb = co.compute_aabb();
                let near =
                    |lo: f32, hi: f32, p: f64| (p - range) <= hi as f64 && lo as f64 <= p + range;
                (near(aabb.mins.x, aabb.maxs.x, at.x) && near(aabb.mins.y, aabb.maxs.y, at.y))
                    .then_some(k)
            })
            .collect();
        out.sort_by_key(|k| format!("{k:?}"));
        out
    }

    #[test]
    fn the_floor_covered_at_a_tick_counts_before_the_world_steps() {
        let mut w = world(4);
        let stopped = vec![false; 4];
        let mut shares = Vec::new();
        for step in 0..20 {
            w.record();
            // Noted, not marked yet: the share counts it all the same.
            let noted = coverage(&w);
            w.advance(Time::from_secs_f64((step + 1) as f64 * 0.1), &stopped);
            assert!(w.coverage.noted.is_empty(), "marked as the world stepped");
            w.coverage.last.iter().for_each(|l| assert!(l.is_some()));
            shares.push((noted, coverage(&w)));
        }
        for (noted, marked) in &shares {
            assert_eq!(noted, marked);
        }
        assert!(shares[0].0 > 0.0 && shares.windows(2).all(|s| s[0].1 <= s[1].0));
    }

    #[test]
    fn the_sensing_grid_finds_everything_a_full_scan_does() {
        let mut w = world(40);
        let stopped = vec![false; 40];
        let mut near = Vec::new();
        for step in 0..30 {
            // Invariant 10: at every control tick, from the first on.
            w.fresh_grid();
            for i in 0..40 {
                let at = w.pose(i).pos;
                w.near(i, at, 3.5, &mut near);
                let mut got: Vec<Kind> = near.iter().map(|(k, _)| *k).collect();
                got.sort_by_key(|k| format!("{k:?}"));
                got.dedup();
                let mut want = scan(&w, i, at, 3.0);
                want.dedup();
                for k in &want {
                    assert!(got.contains(k), "step {step}, r{i}: {k:?} missed");
                }
            }
            for i in 0..40 {
                let _ = w.observe(i);
            }
            w.advance(Time::from_secs_f64((step + 1) as f64 * 0.1), &stopped);
        }
    }

    #[test]
    fn robots_see_each_other_at_the_first_tick() {
        // The formation: two followers behind the leader, all facing +x.
        let g = bite_core::graph::load_str(
            &Arc::from("formation.yaml"),
            include_str!("../../../../examples/formation.yaml"),
        )
        .expect("graph");
        let sc = crate::Scenario::load_str(
            &Arc::from("formation-physics.yaml"),
            include_str!("../../../../examples/scenarios/formation-physics.yaml"),
        )
        .expect("scenario");
        let names: Vec<String> = (0..3).map(|i| format!("r{i}")).collect();
        let spec = sc.physics.clone().expect("physical");
        let file: Arc<str> = Arc::from("s");
        let mut w = World::new(spec.clone(), &names, g.symbols(), &file, 1).expect("world");
        let mut out = Vec::new();
        let seen: f64 = (0..3)
            .map(|i| {
                let mut p =
                    Pilot::for_robot(spec.clone(), &names, g.symbols(), &file, i).expect("pilot");
                p.perceive(&w.observe(i), &mut out);
                match p.percept("teammates_seen") {
                    Some(Value::Num(x)) => *x,
                    _ => 0.0,
                }
            })
            .sum();
        assert!(seen >= 2.0, "{seen} sightings at t = 0");
    }

    /// The box-push arena with its graph's symbols, two robots.
    fn box_push() -> (bite_core::graph::BehaviorGraph, Arc<PhysicsSpec>) {
        let g = bite_core::graph::load_str(
            &Arc::from("box-push.yaml"),
            include_str!("../../../../examples/box-push.yaml"),
        )
        .expect("graph");
        let sc = crate::Scenario::load_str(
            &Arc::from("box-push-physics.yaml"),
            include_str!("../../../../examples/scenarios/box-push-physics.yaml"),
        )
        .expect("scenario");
        (g, sc.physics.clone().expect("physical"))
    }

    /// Go to `goal`, clear of obstacles.
    fn go_to(goal: DVec2) -> Arc<[Weighted]> {
        use schema::{Schema, Target};
        Arc::from(vec![
            Weighted {
                schema: Schema::MoveToGoal {
                    goal: Target::Point(goal),
                    speed: 0.25,
                },
                gain: 1.0,
                layer: 1,
            },
            Weighted {
                schema: Schema::AvoidObstacle { range: 0.25 },
                gain: 1.0,
                layer: 3,
            },
        ])
    }

    /// The same run twice: in process (`observe`, the pilot, `actuate`),
    /// and split as between a simulator server and robot processes
    /// (`observe`, JSON, the pilot, JSON, `actuate`).
    #[test]
    fn a_split_robot_perceives_and_drives_as_an_in_process_one() {
        use rand::RngExt;
        let (g, spec) = box_push();
        let file: Arc<str> = Arc::from("box-push-physics.yaml");
        let names: Vec<String> = vec!["r0".into(), "r1".into()];
        let world = || World::new(spec.clone(), &names, g.symbols(), &file, 1).expect("world");
        let (mut inproc, mut server) = (world(), world());
        let pilot = |i: usize| {
            Pilot::for_robot(spec.clone(), &names, g.symbols(), &file, i).expect("pilot")
        };
        let mut pilots: Vec<Pilot> = (0..2).map(pilot).collect();
        let mut local: Vec<Pilot> = (0..2).map(pilot).collect();
        let mut draws: Vec<Rng> = (0..2).map(|i| Rng::seed_from_u64(100 + i)).collect();
        let mut local_draws: Vec<Rng> = (0..2).map(|i| Rng::seed_from_u64(100 + i)).collect();
        let goals = [DVec2::new(2.0, 0.5), DVec2::new(2.0, 2.0)];
        for i in 0..2 {
            local[i].leaf_changed(0.0, 0.0, None, go_to(goals[i]));
            pilots[i].leaf_changed(0.0, 0.0, None, go_to(goals[i]));
        }
        let before: Vec<f64> = (0..2)
            .map(|i| server.pose(i).pos.distance(goals[i]))
            .collect();
        let stopped = [false; 2];
        let mut sightings = 0;
        for tick in 0..80 {
            for i in 0..2 {
                let mut want = Vec::new();
                let seen = inproc.observe(i);
                local[i].perceive(&seen, &mut want);
                let rng = &mut local_draws[i];
                let cmd = local[i].control(seen.t, &mut || rng.random_range(0.0..1.0));
                inproc.actuate(i, cmd);
                // The server's side.
                let sensed = serde_json::to_string(&server.observe(i)).expect("json");
                // The robot's side.
                let sensed: Sensed = serde_json::from_str(&sensed).expect("sensed");
                let mut got = Vec::new();
                pilots[i].perceive(&sensed, &mut got);
                if tick == 0 {
                    sightings += sensed.mates.len() + sensed.objects.len();
                    assert_eq!(got, want, "r{i}'s percepts at the first tick");
                }
                let rng = &mut draws[i];
                let cmd = pilots[i].control(sensed.t, &mut || rng.random_range(0.0..1.0));
                let cmd = serde_json::to_string(&cmd).expect("json");
                // The server's side again.
                server.actuate(i, serde_json::from_str(&cmd).expect("command"));
            }
            let now = Time::from_secs_f64((tick + 1) as f64 * 0.1);
            for w in [&mut inproc, &mut server] {
                w.advance(now, &stopped);
                w.record();
            }
        }
        assert!(sightings >= 2, "{sightings} sightings at the first tick");
        for i in 0..2 {
            // Nothing here draws: the two runs go the same way.
            let (a, b) = (inproc.pose(i).pos, server.pose(i).pos);
            assert!(a.distance(b) < 1e-3, "r{i}: {a} in process, {b} split");
            let after = server.pose(i).pos.distance(goals[i]);
            assert!(
                after < before[i] - 1.0,
                "r{i}: {:.2} m from its goal, was {:.2}",
                after,
                before[i]
            );
        }
    }

    #[test]
    fn a_robot_placed_inside_an_obstacle_is_a_located_error() {
        let (g, s) = swarm::coverage_mission(4, 10.0);
        let s = s.replace("r0: { at: [0.50, 0.50] }", "r0: { at: [4.00, 4.00] }");
        let s = s.replace(
            "obstacles:\n",
            "obstacles:\n    - { disc: 0.3, at: [4.0, 4.0] }\n",
        );
        let g = bite_core::graph::load_str(&Arc::from("g"), &g).expect("graph");
        let sc = crate::Scenario::load_str(&Arc::from("s.yaml"), &s).expect("scenario");
        let names: Vec<String> = (0..4).map(|i| format!("r{i}")).collect();
        let spec = sc.physics.clone().expect("physical");
        let err =
            World::new(spec, &names, g.symbols(), &Arc::from("s.yaml"), 1).expect_err("rejected");
        assert!(err.has("bad-start"), "{err}");
        assert!(
            err.to_string().contains("`r0` starts inside an obstacle"),
            "{err}"
        );
    }

    /// A scenario in an 8 × 3 m hall with `start` entries and obstacles.
    fn hall(start: &str, obstacles: &str) -> (bite_core::graph::BehaviorGraph, Arc<PhysicsSpec>) {
        let g = "graph: g\nteam: { robots: 3 }\nstart: a\nbehaviors:\n  a: { team: true }\n";
        let g = bite_core::graph::load_str(&Arc::from("g.yaml"), g).expect("graph");
        let s = format!(
            "scenario: s\nworld: physics\nphysics:\n  arena: [8, 3]\n  robot: {{ radius: 0.12 }}\n  \
             start:\n{start}  obstacles:\n{obstacles}"
        );
        let sc =
            crate::Scenario::load_str(&Arc::from("s.yaml"), &s).unwrap_or_else(|d| panic!("{d}"));
        (g, sc.physics.clone().expect("physical"))
    }

    #[test]
    fn robots_the_scenario_does_not_place_start_clear_of_those_it_does() {
        // The formation scenario's triangle, and obstacles across the
        // left column: five and twenty robots all find a free spot.
        let (g, spec) = hall(
            "    r0: { at: [0.9, 1.5], heading: 0 }\n    r1: { at: [0.5, 1.9], heading: 0 }\n    \
             r2: { at: [0.5, 1.1], heading: 0 }\n",
            "    - { disc: 0.2, at: [0.36, 0.5] }\n    - { box: [0.3, 0.3], at: [0.72, 2.5], angle: 30 }\n",
        );
        for n in [5, 20] {
            let names: Vec<String> = (0..n).map(|i| format!("r{i}")).collect();
            let w = World::new(spec.clone(), &names, g.symbols(), &Arc::from("s.yaml"), 1)
                .unwrap_or_else(|d| panic!("{n} robots: {d}"));
            for i in 0..n {
                let p = w.pose(i).pos;
                for j in 0..i {
                    let d = p.distance(w.pose(j).pos);
                    assert!(d >= 0.36 - 1e-6, "{n} robots: r{i} {p} is {d} m from r{j}");
                }
                for b in &spec.obstacles {
                    assert!(distance_to(b, p) >= 0.24 - 1e-6, "r{i} {p} too near {b:?}");
                }
                assert!(p.x + 0.12 < 8.0 && p.y + 0.12 < 3.0, "r{i} {p} outside");
            }
        }
    }

    #[test]
    fn start_overlaps_are_located_at_the_start_entry() {
        // Two placed robots inside each other: both errors at their
        // entries (line 7 and 8).
        let (g, spec) = hall(
            "    r0: { at: [1.0, 1.5] }\n    r1: { at: [1.1, 1.5] }\n",
            "    - { disc: 0.2, at: [5, 1] }\n",
        );
        let names: Vec<String> = (0..3).map(|i| format!("r{i}")).collect();
        let err = World::new(spec, &names, g.symbols(), &Arc::from("s.yaml"), 1)
            .expect_err("rejected")
            .to_string();
        assert!(err.contains("s.yaml:7:"), "{err}");
        assert!(err.contains("s.yaml:8:"), "{err}");
        assert!(err.contains("`r0` starts inside robot `r1`"), "{err}");
        // No room left: the error is at the `physics:` section.
        let (g, spec) = hall(
            "    r0: { at: [1.0, 1.5] }\n",
            "    - { box: [8, 3], at: [4, 1.5] }\n",
        );
        let err = World::new(spec, &names, g.symbols(), &Arc::from("s.yaml"), 1)
            .expect_err("rejected")
            .to_string();
        assert!(err.contains("s.yaml:4:"), "{err}");
        assert!(err.contains("no room for robot `r1`"), "{err}");
    }
}
