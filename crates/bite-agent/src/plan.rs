//! Routing around what motor schemas alone cannot: a robot's own small
//! path planner (A* on an occupancy grid of the arena it knows), used only
//! when the body of a teammate presumed lost — crashed, out of power —
//! blocks the straight way to where a schema steers, or when a robot
//! driving to a goal has been trapped (it made no headway for a while: a
//! pocket between two obstacles where attraction and repulsion cancel), or
//! a wandering one pinned in a corner heads for open floor. It also plans
//! the way of an object a robot pushes, when a wall or obstacle stands in
//! its straight way to the goal ([`Map::object_route`]).
//!
//! Motor schemas are reactive: attraction to the goal plus repulsion from
//! what the rays see. A body parked in a doorway makes a local minimum (the
//! two cancel, the robot pushes against it for ever). The pilot knows the
//! arena's walls and static obstacles (from the scenario, as a robot knows
//! its map), where it last saw each lost teammate and each object it has
//! seen (objects can be pushed, so they are not on the map: the route keeps
//! clear of them where it last saw them, but of the one its schema drives
//! to or pushes); it plans over that map, inflated by its own radius, and
//! steers to the next point of the path. Healthy teammates are not
//! obstacles here: they move, and `avoid-teammate` handles them. A body that leaves no way round it (a
//! corridor too narrow beside it) is pushed out of the way instead
//! (`schema::command`).

use crate::spec::{PhysicsSpec, Shape};
use glam::DVec2;
use std::collections::BinaryHeap;

/// Clearance kept beyond the robot's radius, m.
pub(crate) const MARGIN: f64 = 0.02;
/// How near a lost body keeps a robot on its planned detour, m.
const NEAR: f64 = 1.0;
/// Most cells a grid may have (the cell grows for large arenas).
const MAX_CELLS: f64 = 60_000.0;
/// A trapped robot's detour keeps its centre this far from walls and
/// obstacles where it can (beyond the reach of obstacle avoidance, whose
/// ranges are 0.15-0.55 m from the body's edge): a cell closer costs more
/// to cross, up to [`CLOSE_COST`] times more at the edge of the inflated
/// obstacle.
const WIDE: f64 = 0.45;
const CLOSE_COST: f64 = 4.0;
/// How much farther than its body needs a trapped robot's detour keeps from
/// bodies and objects, where it can, m: a gap its body fits through with
/// less than this on either side is one its obstacle avoidance (0.15-0.55
/// m) holds it out of. Not from the points its rays hit: those lie on the
/// surface of something, often a wall the map already holds, and the spare
/// room round each would narrow every corridor (a formation's lead, trapped
/// at the mouth of its 0.8 m corridor, was routed round and round in front
/// of it).
const WIDE_GAP: f64 = 0.1;
/// How much room beyond its reach a pushed object's planned way keeps
/// from walls and obstacles, m (see [`Map::object_route`]).
const OBJECT_GAP: f64 = 0.05;
/// The spacing of the points a searching robot chooses where to look
/// round from (see [`Map::lookout`]), m.
const LOOKOUT_STEP: f64 = 0.25;
/// How far ahead along its planned way a pusher steers its object, m.
pub(crate) const OBJECT_LOOKAHEAD: f64 = 0.4;

/// The static map a pilot plans on: the arena's cells, with those its
/// centre cannot enter (walls and obstacles, inflated by its radius).
#[derive(Debug)]
pub struct Map {
    cell: f64,
    w: usize,
    h: usize,
    blocked: Vec<bool>,
    /// Each cell centre's distance to the nearest wall or obstacle, m
    /// (what a trapped robot's detour keeps clear of; see [`WIDE`]).
    clearance: Vec<f32>,
    /// Robot radius plus margin: how close the centre may get to things.
    inflate: f64,
    /// Radius of a robot body.
    body: f64,
    /// The scenario's named objects, the radius of the disc round each and
    /// of the disc inside it (what can be pushed, so not in `blocked`: a
    /// robot routes round those it has seen where it last saw them; see
    /// [`Map::objects_seen`]).
    objects: Vec<(String, f64, f64)>,
}

impl Map {
    /// The map of a scenario's arena for its robots.
    pub fn new(spec: &PhysicsSpec) -> Map {
        let area = (spec.arena.x * spec.arena.y).max(1e-6);
        let cell = (area / MAX_CELLS).sqrt().max(0.02);
        let w = ((spec.arena.x / cell).ceil() as usize).max(1);
        let h = ((spec.arena.y / cell).ceil() as usize).max(1);
        let inflate = spec.robot.radius + MARGIN;
        let mut blocked = vec![false; w * h];
        let mut clearance = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let p = DVec2::new((x as f64 + 0.5) * cell, (y as f64 + 0.5) * cell);
                let wall = p.x < inflate
                    || p.y < inflate
                    || p.x > spec.arena.x - inflate
                    || p.y > spec.arena.y - inflate;
                let mut near = p.x.min(p.y).min(spec.arena.x - p.x).min(spec.arena.y - p.y);
                let mut hit = false;
                for o in &spec.obstacles {
                    let local = DVec2::from_angle(-o.angle).rotate(p - o.at);
                    let d = match o.shape {
                        Shape::Disc(r) => {
                            hit |= local.length() < r + inflate;
                            local.length() - r
                        }
                        Shape::Box(size) => {
                            let d = (local.abs() - size / 2.0).max(DVec2::ZERO);
                            hit |= d.length() < inflate;
                            d.length()
                        }
                    };
                    near = near.min(d);
                }
                blocked[y * w + x] = wall || hit;
                clearance[y * w + x] = near.max(0.0) as f32;
            }
        }
        Map {
            cell,
            w,
            h,
            blocked,
            clearance,
            inflate,
            body: spec.robot.radius,
            objects: (spec.objects.iter())
                .filter_map(|o| Some((o.name.clone()?, o.shape.reach(), o.shape.inner())))
                .collect(),
        }
    }

    fn cell_of(&self, p: DVec2) -> (usize, usize) {
        let x = (p.x / self.cell).floor().clamp(0.0, (self.w - 1) as f64) as usize;
        let y = (p.y / self.cell).floor().clamp(0.0, (self.h - 1) as f64) as usize;
        (x, y)
    }

    fn centre(&self, (x, y): (usize, usize)) -> DVec2 {
        DVec2::new((x as f64 + 0.5) * self.cell, (y as f64 + 0.5) * self.cell)
    }

    fn is_blocked(&self, p: DVec2) -> bool {
        let (x, y) = self.cell_of(p);
        self.blocked[y * self.w + x]
    }

    /// True when `p` is inside the arena and a robot's centre there is at
    /// least `clear` m from every wall and obstacle (open floor to head
    /// for).
    pub fn open(&self, p: DVec2, clear: f64) -> bool {
        let inside = p.x >= 0.0
            && p.y >= 0.0
            && p.x < self.w as f64 * self.cell
            && p.y < self.h as f64 * self.cell;
        let (x, y) = self.cell_of(p);
        inside
            && !self.blocked[y * self.w + x]
            && f64::from(self.clearance[y * self.w + x]) >= clear
    }

    /// Where a robot searching for an object it has not found looks round
    /// next (see `schema::command`): of the open floor (points on a grid of
    /// [`LOOKOUT_STEP`] m, at least `clear` m from walls and obstacles),
    /// the point farthest from every place in `looked` (where it has looked
    /// round already), any `apart` m or more from all of them counting as
    /// far enough, and of those the nearest to `from`. With the point, how
    /// far it is from the nearest place looked from (at most `apart`).
    /// `None` if no point is open. A pure function of its inputs: the grid
    /// is walked in one order and the first best point is kept.
    pub fn lookout(
        &self,
        looked: &[DVec2],
        from: DVec2,
        apart: f64,
        clear: f64,
    ) -> Option<(DVec2, f64)> {
        let (w, h) = (self.w as f64 * self.cell, self.h as f64 * self.cell);
        let (nx, ny) = ((w / LOOKOUT_STEP) as usize, (h / LOOKOUT_STEP) as usize);
        let mut best: Option<(DVec2, f64, f64)> = None;
        for j in 0..ny {
            for i in 0..nx {
                let p = DVec2::new(
                    (i as f64 + 0.5) * LOOKOUT_STEP,
                    (j as f64 + 0.5) * LOOKOUT_STEP,
                );
                if !self.open(p, clear) {
                    continue;
                }
                let far = (looked.iter()).map(|l| l.distance(p)).fold(apart, f64::min);
                let near = p.distance(from);
                let better = best.is_none_or(|(_, f, n)| far > f || (far == f && near < n));
                if better {
                    best = Some((p, far, near));
                }
            }
        }
        best.map(|(p, far, _)| (p, far))
    }

    /// The objects of the scenario a robot has seen (`seen`: last seen
    /// positions by name), as discs its route keeps clear of, but the one
    /// at `own` (the object its skill drives to or pushes, within 5 cm of
    /// it): a crate beside a lost teammate's body narrows the way round the
    /// body as a wall would, and its rays alone (12 of them) show the planner
    /// little of it.
    pub fn objects_seen(
        &self,
        seen: &std::collections::BTreeMap<String, DVec2>,
        own: Option<DVec2>,
    ) -> Vec<(DVec2, f64)> {
        (self.objects.iter())
            .filter_map(|(name, reach, _)| Some((*seen.get(name)?, *reach)))
            .filter(|(at, _)| own.is_none_or(|o| o.distance(*at) > 0.05))
            .collect()
    }

    /// The size of the scenario's object last seen at `at` (`seen`: last
    /// seen positions by name; within 5 cm), if one was: the radii of the
    /// discs round it and inside it ([`Shape::reach`], [`Shape::inner`]).
    pub fn size_at(
        &self,
        seen: &std::collections::BTreeMap<String, DVec2>,
        at: DVec2,
    ) -> Option<(f64, f64)> {
        (self.objects.iter())
            .find(|(name, ..)| seen.get(name).is_some_and(|p| p.distance(at) <= 0.05))
            .map(|(_, reach, inner)| (*reach, *inner))
    }

    /// The distance from `p` to the nearest wall or obstacle, as the map's
    /// cells know it (0 outside the arena).
    fn clearance_at(&self, p: DVec2) -> f64 {
        let inside = p.x >= 0.0
            && p.y >= 0.0
            && p.x < self.w as f64 * self.cell
            && p.y < self.h as f64 * self.cell;
        let (x, y) = self.cell_of(p);
        if inside {
            f64::from(self.clearance[y * self.w + x])
        } else {
            0.0
        }
    }

    /// True when a wall or an obstacle stands between a camera at `eye` and
    /// a point `at` (the straight line between them passes inside one, as
    /// the map's cells know it: within half a cell of its surface). What
    /// it hides may well be there.
    pub fn hides(&self, eye: DVec2, at: DVec2) -> bool {
        let steps = (eye.distance(at) / (self.cell / 2.0)).ceil().min(10_000.0) as usize;
        (1..steps)
            .any(|k| self.clearance_at(eye.lerp(at, k as f64 / steps as f64)) < self.cell / 2.0)
    }

    /// True when an object of `size` (the radii of the discs round it and
    /// inside it) pushed straight from `from` to `to` does not run into a
    /// wall or obstacle on the way, however it is turned (its centre at
    /// least the inner radius from every one, all the way), nor stands
    /// against one at the start (its centre nearer one than its reach: it
    /// may be caught on it, as a box's corner on a chair); or when `to`
    /// itself has no such room (the goal is tight against something: the
    /// object goes straight for it, as before there was a way to plan).
    /// Between the two radii, on the way, an object grazes at worst and
    /// slides by.
    pub fn object_way_clear(&self, from: DVec2, to: DVec2, (reach, inner): (f64, f64)) -> bool {
        self.clearance_at(to) < inner
            || (self.clearance_at(from) >= reach && self.keeps_clear(from, to, inner))
    }

    /// True when every point of the segment from `a` to `b` (sampled every
    /// half cell) is at least `clear` from every wall and obstacle.
    fn keeps_clear(&self, a: DVec2, b: DVec2, clear: f64) -> bool {
        let steps = (a.distance(b) / (self.cell / 2.0)).ceil().min(10_000.0) as usize;
        (0..=steps).all(|k| self.clearance_at(a.lerp(b, k as f64 / steps.max(1) as f64)) >= clear)
    }

    /// Where to steer an object of `reach` at `at` on its planned way
    /// `path` ([`Map::object_route`]): the farthest point up to `ahead` m on
    /// from the point nearest it ([`pursue`]) that it reaches in a straight
    /// line without coming nearer a wall or obstacle than the way keeps
    /// (nor nearer than it is); the next point of the way if none is.
    pub(crate) fn object_aim(
        &self,
        path: &[DVec2],
        at: DVec2,
        reach: f64,
        ahead: f64,
    ) -> Option<DVec2> {
        let floor = (reach + OBJECT_GAP).min(self.clearance_at(at));
        let (nearest, far) = pursue(path, at, ahead)?;
        (nearest..=far)
            .rev()
            .map(|k| path[k])
            .find(|p| self.keeps_clear(at, *p, floor - 1e-6))
            .or_else(|| path.get(nearest + 1).or(path.last()).copied())
    }

    /// The way to push an object of `reach` from `from` to `to` round the
    /// walls and obstacles (points, `to` last): its centre keeps
    /// [`OBJECT_GAP`] beyond its reach from them, or, where it is already
    /// nearer (pushed against one), no nearer than it is; a way closer
    /// than that gap costs more, the more the closer. `None` if there is
    /// none.
    pub fn object_route(&self, from: DVec2, to: DVec2, reach: f64) -> Option<Vec<DVec2>> {
        let need = reach + OBJECT_GAP;
        let floor = need.min(self.clearance_at(from)) as f32;
        let blocked: Vec<bool> = self.clearance.iter().map(|c| *c < floor).collect();
        let step = |j: usize| {
            let c = f64::from(self.clearance[j]);
            1.0 + CLOSE_COST * ((need - c) / need).max(0.0)
        };
        self.search(&blocked, from, to, step)
    }

    /// True when the straight way from `a` to `b` is not clear: a robot's
    /// centre on it would come closer to one of `bodies` than two radii and
    /// the margin, or into a wall or obstacle (the robot may have been
    /// pushed against one by a body in its way).
    pub fn body_in_the_way(&self, a: DVec2, b: DVec2, bodies: &[DVec2]) -> bool {
        let clear = self.body + self.inflate;
        if bodies.iter().any(|c| segment_distance(a, b, *c) < clear) {
            return true;
        }
        // Near a body, a blocked straight way is a trap for reactive
        // schemas: plan. Far from any, leave static obstacles to them.
        let near = bodies.iter().any(|c| c.distance(a) < NEAR);
        let steps = (a.distance(b) / (self.cell / 2.0)).ceil().min(10_000.0) as usize;
        near && (1..=steps).any(|k| self.is_blocked(a.lerp(b, k as f64 / steps as f64)))
    }

    /// A path from `from` to `to` around the map's obstacles and `bodies`
    /// (points to drive through, `to` last), or `None` if there is none.
    /// `wide`: keep clear of walls and obstacles where it can (cells within
    /// [`WIDE`] of one cost more to cross), for a robot trapped near them;
    /// `sensed`: what the map does not hold, as discs (centre, radius):
    /// points where its range sensor hit something (radius 0: an object, a
    /// teammate) and the objects it has seen; kept clear of as obstacles
    /// are.
    /// A trapped robot's way keeps [`WIDE_GAP`] more from bodies and objects
    /// (discs of a radius above 0) where there is such a way, and only its
    /// body's room where there is not.
    pub fn route(
        &self,
        from: DVec2,
        to: DVec2,
        bodies: &[DVec2],
        (sensed, wide): (&[(DVec2, f64)], bool),
    ) -> Option<Vec<DVec2>> {
        let roomy = wide && (!bodies.is_empty() || sensed.iter().any(|(_, r)| *r > 0.0));
        (roomy.then(|| self.route_clear_by(from, to, bodies, (sensed, wide), WIDE_GAP)))
            .flatten()
            .or_else(|| self.route_clear_by(from, to, bodies, (sensed, wide), 0.0))
    }

    /// [`Map::route`], keeping `extra` m more from bodies and from the
    /// discs of `sensed` that have a radius (objects; not ray hits).
    fn route_clear_by(
        &self,
        from: DVec2,
        to: DVec2,
        bodies: &[DVec2],
        (sensed, wide): (&[(DVec2, f64)], bool),
        extra: f64,
    ) -> Option<Vec<DVec2>> {
        let clear = self.body + self.inflate + extra;
        let mut blocked = self.blocked.clone();
        // Bodies keep a robot's centre two radii and the margin away; what
        // the rays hit, one radius and the margin; an object, its own
        // radius more.
        let discs = (bodies.iter().map(|b| (*b, clear))).chain(sensed.iter().map(|(p, r)| {
            let spare = if *r > 0.0 { extra } else { 0.0 };
            (*p, self.inflate + r + spare)
        }));
        for (at, within) in discs {
            let (cx, cy) = self.cell_of(at);
            let r = (within / self.cell).ceil() as isize + 1;
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (cx as isize + dx, cy as isize + dy);
                    if x < 0 || y < 0 || x >= self.w as isize || y >= self.h as isize {
                        continue;
                    }
                    let c = (x as usize, y as usize);
                    if self.centre(c).distance(at) < within {
                        blocked[c.1 * self.w + c.0] = true;
                    }
                }
            }
        }
        let step = |j: usize| {
            if !wide {
                return 1.0;
            }
            // Clearance from the edge of what is near: walls and
            // obstacles, what the rays hit, objects and bodies.
            let at = self.centre((j % self.w, j / self.w));
            let c = (sensed.iter())
                .map(|(p, r)| p.distance(at) - r)
                .chain(bodies.iter().map(|b| b.distance(at) - self.body))
                .fold(f64::from(self.clearance[j]), f64::min);
            1.0 + CLOSE_COST * ((WIDE - c) / WIDE).max(0.0)
        };
        self.search(&blocked, from, to, step)
    }

    /// A* over the cells from `from` to `to`, not entering `blocked` ones
    /// (but the goal's; a goal in a blocked cell is swapped for the nearest
    /// open one) nor cutting corners between two; crossing cell `j` costs
    /// its length times `step(j)`. The path's points to drive through,
    /// `to` last.
    fn search(
        &self,
        blocked: &[bool],
        from: DVec2,
        to: DVec2,
        step: impl Fn(usize) -> f64,
    ) -> Option<Vec<DVec2>> {
        let n = self.w * self.h;
        let start = self.cell_of(from);
        // A goal inside an inflated obstacle: aim at the nearest free cell.
        let goal = {
            let g = self.cell_of(to);
            if blocked[g.1 * self.w + g.0] {
                (0..n)
                    .filter(|i| !blocked[*i])
                    .map(|i| (i % self.w, i / self.w))
                    .min_by(|a, b| {
                        self.centre(*a)
                            .distance_squared(to)
                            .total_cmp(&self.centre(*b).distance_squared(to))
                    })?
            } else {
                g
            }
        };
        let idx = |(x, y): (usize, usize)| y * self.w + x;
        let h = |(x, y): (usize, usize)| {
            let dx = x.abs_diff(goal.0) as f64;
            let dy = y.abs_diff(goal.1) as f64;
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        };
        let mut g = vec![f64::INFINITY; n];
        let mut came = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        g[idx(start)] = 0.0;
        heap.push(Open(h(start), 0.0, idx(start)));
        while let Some(Open(_, cost, i)) = heap.pop() {
            if cost > g[i] {
                continue;
            }
            let here = (i % self.w, i / self.w);
            if here == goal {
                let mut path = vec![to];
                let mut c = came[i];
                while c != usize::MAX && c != idx(start) {
                    path.push(self.centre((c % self.w, c / self.w)));
                    c = came[c];
                }
                path.reverse();
                return Some(path);
            }
            for (dx, dy) in [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ] {
                let (x, y) = (here.0 as isize + dx, here.1 as isize + dy);
                if x < 0 || y < 0 || x >= self.w as isize || y >= self.h as isize {
                    continue;
                }
                let next = (x as usize, y as usize);
                let j = idx(next);
                // The start cell may be inside an inflated zone (the robot
                // is pressed against something): it may always leave it.
                if blocked[j] && next != goal {
                    continue;
                }
                // No cutting corners between two blocked cells.
                if dx != 0
                    && dy != 0
                    && (blocked[idx((next.0, here.1))] || blocked[idx((here.0, next.1))])
                {
                    continue;
                }
                let length = if dx != 0 && dy != 0 {
                    std::f64::consts::SQRT_2
                } else {
                    1.0
                };
                let c = cost + length * step(j);
                if c < g[j] {
                    g[j] = c;
                    came[j] = i;
                    heap.push(Open(c + h(next), c, j));
                }
            }
        }
        None
    }
}

/// An A* frontier entry: estimate, cost so far, cell (a min-heap by
/// estimate, ties by cell for determinism).
struct Open(f64, f64, usize);

impl PartialEq for Open {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == std::cmp::Ordering::Equal
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        o.0.total_cmp(&self.0).then(o.2.cmp(&self.2))
    }
}

/// The points of `path` from the one nearest `at` to the one `ahead` m on
/// (the distance counted from `at`; the path's last if it ends sooner), as
/// their indices; `None` for an empty path.
pub(crate) fn pursue(path: &[DVec2], at: DVec2, ahead: f64) -> Option<(usize, usize)> {
    let nearest = (0..path.len())
        .min_by(|a, b| (path[*a].distance_squared(at)).total_cmp(&path[*b].distance_squared(at)))?;
    let mut k = nearest;
    let mut travel = at.distance(path[k]);
    while travel < ahead && k + 1 < path.len() {
        travel += path[k].distance(path[k + 1]);
        k += 1;
    }
    Some((nearest, k))
}

pub(crate) fn segment_distance(a: DVec2, b: DVec2, p: DVec2) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 < 1e-12 {
        return p.distance(a);
    }
    let t = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
    p.distance(a + ab * t)
}

impl Route {
    /// True while it leads somewhere (a trapped robot that found no way
    /// round keeps an empty one until it plans again).
    pub fn leads(&self) -> bool {
        !self.path.is_empty()
    }
}

/// A planned detour a schema is following.
#[derive(Clone, Debug, Default)]
pub struct Route {
    /// Where it leads.
    goal: DVec2,
    /// The bodies it avoids.
    bodies: Vec<DVec2>,
    /// Planned for a trapped robot (clear of walls and obstacles).
    wide: bool,
    /// When it was planned (skill time).
    at: f64,
    /// Points still ahead.
    pub(crate) path: Vec<DVec2>,
}

/// Where to steer, from `from`, to get to `to`: `to` itself, unless a lost
/// teammate's body is in the way, or the robot is `trapped` — then the
/// next point of a path around them and what `sensed` gives when it plans
/// (discs, centre and radius: the objects it has seen and, trapped, what
/// its range sensor hits now; re-planned when the goal or the bodies move,
/// and every 2 s; a trapped robot's path keeps clear of walls, obstacles,
/// objects and bodies where it can). Once on a detour, the robot keeps to it
/// while a body is within a metre, or while it is trapped: the straight
/// way may look clear from inside a tight gap, where reactive avoidance
/// would push it back out.
pub fn aim(
    map: Option<&Map>,
    bodies: &[DVec2],
    route: &mut Option<Route>,
    now: f64,
    (from, to): (DVec2, DVec2),
    (trapped, sensed): (bool, impl FnOnce(&Map) -> Vec<(DVec2, f64)>),
) -> DVec2 {
    let Some(map) = map.filter(|_| trapped || !bodies.is_empty()) else {
        *route = None;
        return to;
    };
    let near = bodies.iter().any(|b| b.distance(from) < NEAR);
    let keep = route.is_some() && (near || trapped);
    if !keep && !trapped && !map.body_in_the_way(from, to, bodies) {
        *route = None;
        return to;
    }
    let stale = route.as_ref().is_none_or(|r| {
        r.goal.distance(to) > 0.3
            || r.bodies != bodies
            || r.wide != trapped
            || now - r.at > 2.0
            || now < r.at
    });
    if stale {
        // No way round: a trapped robot keeps that answer (an empty path,
        // straight on) until the next re-plan rather than searching the
        // whole map again at every tick.
        let path = map.route(from, to, bodies, (&sensed(map), trapped));
        *route = path.or_else(|| trapped.then(Vec::new)).map(|path| Route {
            goal: to,
            bodies: bodies.to_vec(),
            wide: trapped,
            at: now,
            path,
        });
    }
    let Some(r) = route.as_mut() else {
        return to;
    };
    // Drop the points reached; aim at the next.
    while r.path.len() > 1 && r.path[0].distance(from) < map.cell.max(0.15) {
        r.path.remove(0);
    }
    r.path.first().copied().unwrap_or(to)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The physical world of a scenario with `arena` and `obstacles` (YAML
    /// lines), robots of radius 0.12 m.
    fn physics(arena: &str, obstacles: &str) -> PhysicsSpec {
        let text = format!(
            "scenario: t\nworld: physics\nphysics:\n  arena: {arena}\n  robot: {{ radius: 0.12 }}\n  obstacles:\n{obstacles}"
        );
        let sc = crate::Scenario::load_str(&std::sync::Arc::from("t.yaml"), &text)
            .unwrap_or_else(|d| panic!("{d}"));
        (*sc.physics.expect("physics")).clone()
    }

    /// The hall of `search-rescue-hidden-physics.yaml`: its three chairs
    /// (obstacles) and the red crate (an object, so not on the map).
    pub(crate) fn hidden_hall() -> PhysicsSpec {
        physics(
            "[7, 4]",
            "    - { disc: 0.2, at: [0.8, 1.35] }\n    - { disc: 0.2, at: [0.8, 2.65] }\n    - { disc: 0.2, at: [3.2, 1.2] }\n  objects:\n    - { name: red_crate, box: [0.3, 0.3], at: [3.8, 0.8], colour: red }\n    - { name: yellow_box, box: [0.3, 0.3], at: [6.32, 3.04], colour: yellow }\n",
        )
    }

    pub(crate) fn corridor() -> PhysicsSpec {
        // The formation scenario: a hall narrowing into a 0.8 m corridor.
        physics(
            "[8, 3]",
            "    - { box: [3, 1.1], at: [6.5, 0.55] }\n    - { box: [3, 1.1], at: [6.5, 2.45] }\n",
        )
    }

    /// The chair between a robot and the red crate hides the crate (a
    /// random mission, `move:crate:0.46:0.12` with three robots, seed 56:
    /// the pusher, against the chair on its way round, looked for the
    /// crate for good); past the chair, or with nothing between, nothing
    /// does; the crate itself is not on the map.
    #[test]
    fn a_chair_hides_what_is_behind_it() {
        let map = Map::new(&hidden_hall());
        let crate_at = DVec2::new(3.561, 0.893);
        assert!(map.hides(DVec2::new(2.888, 1.131), crate_at));
        assert!(!map.hides(DVec2::new(2.9, 0.6), crate_at));
        assert!(!map.hides(DVec2::new(4.3, 0.8), crate_at));
        assert!(!map.hides(DVec2::new(3.2, 0.6), DVec2::new(3.8, 0.8)));
        // A wall between: the camera's point of view outside the arena.
        assert!(map.hides(DVec2::new(1.0, 1.0), DVec2::new(-1.0, 1.0)));
    }

    #[test]
    fn a_body_in_the_doorway_is_routed_around_through_the_gap() {
        let map = Map::new(&corridor());
        // The crashed leader of the formation example, in the corridor
        // entrance; the gap below it is 0.34 m wide.
        let body = [DVec2::new(4.87, 1.56)];
        let (from, to) = (DVec2::new(4.76, 1.93), DVec2::new(7.8, 1.5));
        assert!(map.body_in_the_way(from, to, &body));
        let path = map
            .route(from, to, &body, (&[], false))
            .expect("a way round");
        assert_eq!(path.last(), Some(&to));
        for p in &path {
            assert!(p.distance(body[0]) >= 0.2, "{p} too close to the body");
        }
        // It enters the corridor below the body.
        assert!(
            path.iter().any(|p| (4.8..5.0).contains(&p.x) && p.y < 1.4),
            "{path:?}"
        );
    }

    /// Search and rescue with the box hidden, crash seed 6: the pusher's
    /// teammate crashed 0.35 m east of the red crate, and the robot, south
    /// of both, heads for the box in the north-east. The way between body
    /// and crate is wide enough for its body, not for its obstacle
    /// avoidance (it stood there for 100 s). Knowing the crate, it goes
    /// round.
    #[test]
    fn a_crate_beside_a_body_closes_the_gap_between_them() {
        let map = Map::new(&hidden_hall());
        let body = [DVec2::new(4.419, 0.692)];
        let (from, to) = (DVec2::new(4.13, 0.49), DVec2::new(6.34, 3.08));
        let seen: std::collections::BTreeMap<String, DVec2> = [
            ("red_crate", DVec2::new(3.8, 0.8)),
            ("red", DVec2::new(3.8, 0.8)),
            ("yellow_box", DVec2::new(6.32, 3.04)),
            ("box", DVec2::new(6.32, 3.04)),
        ]
        .into_iter()
        .map(|(k, p)| (k.to_string(), p))
        .collect();
        // The box the robot drives to is not in its way; the crate is, once.
        let objects = map.objects_seen(&seen, Some(DVec2::new(6.32, 3.04)));
        assert_eq!(objects.len(), 1, "{objects:?}");
        assert!((objects[0].1 - 0.3f64.hypot(0.3) / 2.0).abs() < 1e-9);
        let through_gap = |path: &[DVec2]| {
            path.iter()
                .any(|p| (3.95..4.3).contains(&p.x) && (0.7..0.95).contains(&p.y))
        };
        // Blind to the crate: through the gap.
        let blind = map.route(from, to, &body, (&[], false)).expect("a way");
        assert!(through_gap(&blind), "{blind:?}");
        // Seeing it, a robot merely detouring round the body keeps only its
        // body clear of the crate; a trapped one keeps clear of the gap.
        let seeing = map
            .route(from, to, &body, (&objects, false))
            .expect("a way");
        let crate_at = DVec2::new(3.8, 0.8);
        assert!(
            seeing.iter().all(|p| p.distance(crate_at) > 0.35),
            "{seeing:?}"
        );
        let trapped = map.route(from, to, &body, (&objects, true)).expect("a way");
        assert!(!through_gap(&trapped), "{trapped:?}");
        assert_eq!(trapped.last(), Some(&to));
        assert!(
            trapped.iter().all(|p| p.distance(crate_at) > 0.45),
            "{trapped:?}"
        );
        // It goes under the body instead (a 0.57 m way to the wall). With
        // that way and the one under the crate closed by two more bodies,
        // the gap is all that is left: room for its body is enough then.
        assert!(
            trapped
                .iter()
                .any(|p| p.y < 0.35 && (4.3..4.55).contains(&p.x)),
            "{trapped:?}"
        );
        let hemmed = [DVec2::new(4.42, 0.2), DVec2::new(3.75, 0.35)];
        let bodies = [body[0], hemmed[0], hemmed[1]];
        let tight = map
            .route(from, to, &bodies, (&objects, true))
            .expect("a way");
        assert!(through_gap(&tight), "{tight:?}");
    }

    /// Hidden box, crash seed 168: the box pushed against the north chair
    /// beside the goal. Its straight way is not clear; its planned way
    /// leaves the chair (no point nearer it than the box is) and ends at
    /// the goal; the point pursued lies away from the chair. Between the
    /// chairs, the straight way is clear; a goal against a chair is gone
    /// for straight.
    #[test]
    fn an_object_pushed_against_a_chair_is_routed_off_it() {
        let map = Map::new(&hidden_hall());
        let chair = DVec2::new(0.8, 2.65);
        let seen: std::collections::BTreeMap<String, DVec2> = [
            ("yellow_box", DVec2::new(1.17, 2.6)),
            ("box", DVec2::new(1.17, 2.6)),
        ]
        .into_iter()
        .map(|(k, p)| (k.to_string(), p))
        .collect();
        let (o, goal) = (DVec2::new(1.17, 2.6), DVec2::new(0.8, 2.0));
        let size = map.size_at(&seen, o).expect("the box's size");
        let (reach, inner) = size;
        assert!((reach - 0.3f64.hypot(0.3) / 2.0).abs() < 1e-9);
        assert!((inner - 0.15).abs() < 1e-9);
        assert_eq!(map.size_at(&seen, DVec2::new(2.0, 2.0)), None);
        assert!(!map.object_way_clear(o, goal, size));
        let path = map.object_route(o, goal, reach).expect("a way");
        assert_eq!(path.last(), Some(&goal));
        let start = o.distance(chair);
        for p in &path {
            assert!(
                p.distance(chair) >= start - map.cell,
                "{p} nearer the chair: {path:?}"
            );
        }
        let ahead = (map.object_aim(&path, o, reach, OBJECT_LOOKAHEAD)).expect("a point");
        assert!(ahead.distance(chair) > start + 0.05, "{ahead} {path:?}");
        // Straight there, the box comes no nearer the chair.
        assert!((ahead - o).dot(o - chair) > 0.0, "{ahead}");
        // Between the chairs, from the east: straight on.
        assert!(map.object_way_clear(DVec2::new(3.0, 2.0), goal, size));
        // Grazing the chair (its centre 0.17 m from it, between the box's
        // inner radius and its reach): straight on; starting there, caught
        // on it, not.
        let graze = DVec2::new(1.5, 3.0);
        assert!(crate::plan::segment_distance(graze, goal, chair) - 0.2 > inner);
        assert!(crate::plan::segment_distance(graze, goal, chair) - 0.2 < reach);
        assert!(map.object_way_clear(graze, goal, size));
        assert!(!map.object_way_clear(DVec2::new(1.13, 2.5), goal, size));
        // A goal with no room for the box: straight on.
        assert!(map.object_way_clear(o, DVec2::new(0.8, 2.36), size));
    }

    #[test]
    fn pursuit_walks_the_path_ahead_of_the_nearest_point() {
        let path = [0.0, 0.2, 0.4, 0.6, 1.0].map(|x| DVec2::new(x, 0.0));
        let at = DVec2::new(0.21, 0.05);
        assert_eq!(pursue(&path, at, 0.3), Some((1, 3)));
        assert_eq!(pursue(&path, at, 5.0), Some((1, 4)));
        assert_eq!(pursue(&path, at, 0.0), Some((1, 1)));
        assert_eq!(pursue(&[], at, 0.3), None);
    }

    #[test]
    fn nothing_in_the_way_means_straight_on() {
        let map = Map::new(&corridor());
        let mut route = None;
        let to = DVec2::new(7.0, 1.5);
        let aim_at = aim(
            Some(&map),
            &[DVec2::new(2.0, 2.5)],
            &mut route,
            0.0,
            (DVec2::new(1.0, 1.5), to),
            (false, |_: &Map| Vec::new()),
        );
        assert_eq!(aim_at, to);
        assert!(route.is_none());
    }

    #[test]
    fn a_blocked_corridor_has_no_route() {
        let map = Map::new(&corridor());
        let bodies = [DVec2::new(5.5, 1.3), DVec2::new(5.5, 1.7)];
        assert!(
            map.route(
                DVec2::new(2.0, 1.5),
                DVec2::new(7.5, 1.5),
                &bodies,
                (&[], false)
            )
            .is_none()
        );
    }

    /// The pocket of the search-and-rescue hall: a robot south of the
    /// middle chair and west of the red crate, driving to a box in the
    /// north-east (the gap between chair and crate is 0.32 m wide: its
    /// body passes, its obstacle avoidance does not let it).
    pub(crate) fn hall() -> PhysicsSpec {
        physics(
            "[7, 4]",
            "    - { disc: 0.2, at: [3.2, 1.2] }\n    - { box: [0.3, 0.3], at: [3.8, 0.8] }\n",
        )
    }

    /// A searching robot's next lookout is open floor the farthest from
    /// where it has looked (any `apart` off being far enough), the nearest
    /// of those to it; off the chair; and when every point is near a place
    /// looked from, the farthest of all.
    #[test]
    fn the_next_lookout_is_the_nearest_open_floor_far_from_where_it_looked() {
        let map = Map::new(&hall());
        let from = DVec2::new(0.5, 0.7);
        let (p, far) = map.lookout(&[from], from, 2.5, 0.24).expect("open floor");
        assert_eq!(far, 2.5);
        assert!((p.distance(from) - 2.5).abs() < 0.2, "{p}");
        // A second place looked from, 2.5 m east: the next is beyond it,
        // at least 2.5 m from both.
        let second = p;
        let (q, far) = map
            .lookout(&[from, second], second, 2.5, 0.24)
            .expect("open floor");
        assert_eq!(far, 2.5);
        assert!(q.distance(from) >= 2.5 && q.distance(second) >= 2.5, "{q}");
        assert!(q.x > second.x, "{q}");
        // Open floor only: never on the chair or within `clear` of a wall.
        let chair = DVec2::new(3.2, 1.2);
        let (r, _) = map
            .lookout(&[DVec2::new(3.2, 3.7)], chair, 2.5, 0.24)
            .expect("open floor");
        assert!(r.distance(chair) >= 0.2 + 0.24 && map.open(r, 0.24), "{r}");
        // Looked from everywhere 1.5 m apart: the farthest point left.
        let grid: Vec<DVec2> = (0..5)
            .flat_map(|i| {
                (0..3).map(move |j| DVec2::new(0.5 + 1.5 * i as f64, 0.5 + 1.5 * j as f64))
            })
            .collect();
        let (_, far) = map.lookout(&grid, from, 2.5, 0.24).expect("open floor");
        assert!(far > 0.5 && far < 1.5, "{far}");
        // Determined by its inputs.
        assert_eq!(
            map.lookout(&grid, from, 2.5, 0.24),
            map.lookout(&grid, from, 2.5, 0.24)
        );
    }

    #[test]
    fn a_trapped_robot_is_routed_round_the_pocket_not_through_the_gap() {
        let map = Map::new(&hall());
        let (from, to) = (DVec2::new(3.27, 0.6), DVec2::new(6.3, 3.0));
        // Through the gap when only the body must fit.
        let tight = map.route(from, to, &[], (&[], false)).expect("a way");
        let clear = |path: &[DVec2]| {
            path.iter()
                .map(|p| {
                    let i = map.cell_of(*p);
                    map.clearance[i.1 * map.w + i.0]
                })
                .fold(f32::INFINITY, f32::min)
        };
        assert!(clear(&tight) < 0.17, "{}", clear(&tight));
        // Round the chair or the crate, clear of both, when trapped.
        let wide = map.route(from, to, &[], (&[], true)).expect("a way");
        assert_eq!(wide.last(), Some(&to));
        assert!(clear(&wide) > 0.25, "{}", clear(&wide));
        let gap = DVec2::new(3.51, 1.03);
        assert!(wide.iter().all(|p| p.distance(gap) > 0.2), "{wide:?}");
        // No detour without a body or a trap; one when trapped, which it
        // keeps while it is.
        let mut route = None;
        let nothing = |_: &Map| Vec::new();
        assert_eq!(
            aim(
                Some(&map),
                &[],
                &mut route,
                0.0,
                (from, to),
                (false, nothing)
            ),
            to
        );
        assert!(route.is_none());
        let next = aim(
            Some(&map),
            &[],
            &mut route,
            0.0,
            (from, to),
            (true, nothing),
        );
        assert_ne!(next, to);
        assert!(next.distance(from) < 0.3);
        assert!(route.is_some());
        assert_eq!(
            aim(
                Some(&map),
                &[],
                &mut route,
                1.0,
                (from, to),
                (false, nothing)
            ),
            to
        );
        assert!(route.is_none());
        // Walled in by what its rays hit: no way round, straight on, and
        // no new search until the next re-plan.
        let ring: Vec<(DVec2, f64)> = (0..36)
            .map(|k| from + DVec2::from_angle(f64::from(k) * 10f64.to_radians()) * 0.2)
            .map(|p| (p, 0.0))
            .collect();
        assert!(map.route(from, to, &[], (&ring, true)).is_none());
        let walls = |_: &Map| ring.clone();
        assert_eq!(
            aim(Some(&map), &[], &mut route, 2.0, (from, to), (true, walls)),
            to
        );
        assert!(route.as_ref().is_some_and(|r| !r.leads()));
    }
}
