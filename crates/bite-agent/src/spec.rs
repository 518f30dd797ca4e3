//! The `physics:` section of a scenario and the `schemas:` of its skills
//! (see `docs/scenario-format.md`).

use crate::schema::{Schema, Side, Target, Weighted};
use bite_core::diag::{Diagnostic, Loc};
use glam::DVec2;
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_saphyr::Spanned;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PhysicsRaw {
    hz: Option<Spanned<f64>>,
    arena: Spanned<[f64; 2]>,
    #[serde(default)]
    robot: RobotRaw,
    #[serde(default)]
    start: BTreeMap<String, Spanned<StartRaw>>,
    #[serde(default)]
    obstacles: Vec<Spanned<ShapeRaw>>,
    #[serde(default)]
    objects: Vec<Spanned<ShapeRaw>>,
    #[serde(default)]
    zones: BTreeMap<String, [f64; 4]>,
    #[serde(default)]
    sensors: SensorsRaw,
    #[serde(default)]
    beliefs: BTreeMap<String, Spanned<String>>,
    goal: Option<GoalRaw>,
    trail: Option<f64>,
    origin: Option<[f64; 2]>,
    #[serde(default)]
    targets: BTreeMap<String, TargetRaw>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TargetRaw {
    colour: Option<String>,
    size: Option<[Option<f64>; 3]>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RobotRaw {
    radius: Option<Spanned<f64>>,
    drive: Option<Spanned<String>>,
    max_speed: Option<Spanned<f64>>,
    max_turn: Option<Spanned<f64>>,
    max_accel: Option<Spanned<f64>>,
    mass: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StartRaw {
    at: [f64; 2],
    #[serde(default)]
    heading: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShapeRaw {
    name: Option<String>,
    at: Spanned<AtRaw>,
    /// Full width and height of a box.
    #[serde(rename = "box")]
    rect: Option<[f64; 2]>,
    /// Radius of a disc.
    disc: Option<f64>,
    colour: Option<String>,
    mass: Option<f64>,
    damping: Option<f64>,
    #[serde(default)]
    angle: f64,
}

/// `at:` of an obstacle or object: a point, or (objects) a position the
/// run's seed draws.
enum AtRaw {
    Point([f64; 2]),
    Drawn(DrawRaw),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DrawRaw {
    one_of: Option<Vec<[f64; 2]>>,
    within: Option<[f64; 4]>,
    #[serde(default)]
    out_of_sight: bool,
}

impl<'de> Deserialize<'de> for AtRaw {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = AtRaw;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a point `[x, y]`, or a drawn position `{ one_of: [[x, y], ...] }` or \
                     `{ within: [x0, y0, x1, y1] }` (with `out_of_sight: true` if it must start \
                     unseen)",
                )
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<AtRaw, A::Error> {
                let x: f64 = s
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(0, &self))?;
                let y: f64 = s
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(1, &self))?;
                if s.next_element::<f64>()?.is_some() {
                    return Err(de::Error::custom("a point is `[x, y]`: two numbers"));
                }
                Ok(AtRaw::Point([x, y]))
            }
            fn visit_map<A: MapAccess<'de>>(self, m: A) -> Result<AtRaw, A::Error> {
                DrawRaw::deserialize(de::value::MapAccessDeserializer::new(m)).map(AtRaw::Drawn)
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct SensorsRaw {
    pose_noise: Option<f64>,
    rays: Option<RaysRaw>,
    camera: Option<CameraRaw>,
    radio_range: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RaysRaw {
    count: Option<u32>,
    range: Option<f64>,
    noise: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraRaw {
    fov: Option<f64>,
    range: Option<f64>,
    noise: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GoalRaw {
    object: String,
    zone: String,
}

/// How robots move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive {
    /// Two wheels: forward speed and turn rate.
    Differential,
    /// Any direction at once.
    Holonomic,
}

/// The robots' body and limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotModel {
    /// Disc radius, m.
    pub radius: f64,
    /// Kinematics.
    pub drive: Drive,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// Top turn rate, rad/s.
    pub max_turn: f64,
    /// Top acceleration, m/s².
    pub max_accel: f64,
    /// Mass, kg.
    pub mass: f64,
}

/// A shape in the arena.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Full width and height.
    Box(DVec2),
    /// Radius.
    Disc(f64),
}

impl Shape {
    /// Radius of the enclosing disc.
    pub fn reach(&self) -> f64 {
        match self {
            Shape::Box(s) => s.length() / 2.0,
            Shape::Disc(r) => *r,
        }
    }

    /// Radius of the largest disc inside it, about its centre (half the
    /// shorter side of a box): nothing nearer its centre than this misses
    /// it, however it is turned.
    pub fn inner(&self) -> f64 {
        match self {
            Shape::Box(s) => s.min_element() / 2.0,
            Shape::Disc(r) => *r,
        }
    }
}

/// Where a drawn position comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Draw {
    /// One of these points, each as likely.
    OneOf(Vec<DVec2>),
    /// Uniformly in the rectangle `[x0, y0, x1, y1]` (`x0 < x1`, `y0 < y1`).
    Within([f64; 4]),
}

/// A movable object whose start the run's seed draws (`at: { one_of: ... }`
/// or `at: { within: ... }`): the simulator draws it when it builds the
/// world, again until the object is clear of everything else and, with
/// `out_of_sight`, no robot's camera sees it from where the robot starts.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Where from.
    pub draw: Draw,
    /// No robot may see the object at its start pose.
    pub out_of_sight: bool,
    /// Where the `at:` is written (errors about the draw).
    pub loc: Loc,
}

impl Draw {
    /// A point the draw can give: the first of `one_of`, the centre of
    /// `within` (where the object stands until a run draws its place).
    pub fn typical(&self) -> DVec2 {
        match self {
            Draw::OneOf(v) => v.first().copied().unwrap_or(DVec2::ZERO),
            Draw::Within([x0, y0, x1, y1]) => DVec2::new(x0 + x1, y0 + y1) / 2.0,
        }
    }
}

/// An obstacle (static) or an object (movable).
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// Name (objects are seen by name and by colour).
    pub name: Option<String>,
    /// Centre (for an object drawn by seed, once the world has drawn it;
    /// before, [`Draw::typical`]).
    pub at: DVec2,
    /// The draw of a movable object's start, if the seed places it.
    pub place: Option<Placement>,
    /// Rotation, radians.
    pub angle: f64,
    /// Shape.
    pub shape: Shape,
    /// Colour, as the camera reports it.
    pub colour: Option<String>,
    /// Mass, kg (objects).
    pub mass: f64,
    /// Linear damping: how fast it stops when no longer pushed (ground friction).
    pub damping: f64,
}

/// Noise and ranges of the sensors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensors {
    /// Standard deviation of the pose estimate, m (heading: this many radians).
    pub pose_noise: f64,
    /// Number of range rays around the robot.
    pub rays: u32,
    /// Their range, m.
    pub ray_range: f64,
    /// Standard deviation of a range reading, m.
    pub ray_noise: f64,
    /// Camera field of view, radians.
    pub fov: f64,
    /// Camera range, m.
    pub camera_range: f64,
    /// Standard deviation of a detection's position, per metre of distance.
    pub camera_noise: f64,
    /// Radio range, m (`None`: unlimited).
    pub radio_range: Option<f64>,
}

/// The physical world of a scenario.
#[derive(Clone, Debug)]
pub struct PhysicsSpec {
    /// Physics steps per second.
    pub hz: f64,
    /// Arena size (walls round `[0, w] × [0, h]`).
    pub arena: DVec2,
    /// Robots' body and limits.
    pub robot: RobotModel,
    /// Start poses by robot name: position, heading (radians), where the
    /// entry is.
    pub start: BTreeMap<String, (DVec2, f64, Loc)>,
    /// Where the `physics:` section is (errors about the world as a whole).
    pub loc: Loc,
    /// Static obstacles.
    pub obstacles: Vec<Body>,
    /// Movable objects.
    pub objects: Vec<Body>,
    /// Named rectangles `[x0, y0, x1, y1]`.
    pub zones: BTreeMap<String, [f64; 4]>,
    /// Sensors.
    pub sensors: Sensors,
    /// Graph beliefs computed from percepts: name → (expression, where).
    pub beliefs: Vec<(String, String, Loc)>,
    /// Success condition: this object inside this zone.
    pub goal: Option<(String, String)>,
    /// Seconds between the trajectory samples kept for pictures (`None`:
    /// every control tick; 0: none, for large teams).
    pub trail: Option<f64>,
    /// Where a mission's (0, 0) is (`None`: where the team starts, the
    /// centroid of the `start` poses).
    pub origin: Option<DVec2>,
    /// Named descriptions of objects (a mission's `find ... => name`):
    /// robots see the objects that fit under that name.
    pub targets: BTreeMap<String, TargetSpec>,
}

/// A description of the objects a name designates: colour and size, each
/// optional.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TargetSpec {
    /// Colour (case-insensitive).
    pub colour: Option<String>,
    /// Length, width, height, m; unknown ones match anything. The world is
    /// flat: length and width are compared with the object's footprint (in
    /// either order; a disc's is its diameter), height is not compared.
    pub size: [Option<f64>; 3],
}

impl TargetSpec {
    /// Relative tolerance of a size match (or 5 cm, whichever is larger).
    pub const SIZE_TOLERANCE: f64 = 0.25;

    /// Does object `o` fit the description?
    pub fn fits(&self, o: &Body) -> bool {
        if let Some(c) = &self.colour
            && !o
                .colour
                .as_ref()
                .is_some_and(|oc| oc.eq_ignore_ascii_case(c))
        {
            return false;
        }
        let (a, b) = match o.shape {
            Shape::Box(s) => (s.x, s.y),
            Shape::Disc(r) => (2.0 * r, 2.0 * r),
        };
        let near =
            |want: f64, have: f64| (want - have).abs() <= (Self::SIZE_TOLERANCE * want).max(0.05);
        match (self.size[0], self.size[1]) {
            (None, None) => true,
            (Some(l), None) => near(l, a) || near(l, b),
            (None, Some(w)) => near(w, a) || near(w, b),
            (Some(l), Some(w)) => (near(l, a) && near(w, b)) || (near(l, b) && near(w, a)),
        }
    }
}

impl PhysicsSpec {
    /// Where a mission's (0, 0) is in the arena: `origin`, or the centroid
    /// of the robots' start poses (the paper's "the point the robots
    /// started from"), or the arena's corner when none is given.
    pub fn mission_origin(&self) -> DVec2 {
        if let Some(o) = self.origin {
            return o;
        }
        if self.start.is_empty() {
            return DVec2::ZERO;
        }
        let sum: DVec2 = self.start.values().map(|(p, _, _)| *p).sum();
        sum / self.start.len() as f64
    }
}

/// Largest arena side, m (the coverage grid is 0.1 m cells).
pub const MAX_ARENA: f64 = 2_000.0;

fn positive(file: &Arc<str>, loc: Loc, what: &str, v: f64, d: &mut Vec<Diagnostic>) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        d.push(Diagnostic::error(
            file,
            loc,
            "bad-value",
            format!("`{what}` must be a positive number, found {v}"),
        ));
    }
    v
}

/// A drawn `at:`, checked: one source of points, all of them finite and in
/// the arena.
fn placement(
    file: &Arc<str>,
    loc: Loc,
    raw: DrawRaw,
    arena: DVec2,
) -> Result<Placement, Diagnostic> {
    let bad = |msg: String| {
        Diagnostic::error(file, loc, "bad-place", msg).with_hint(
            "`at: { one_of: [[x, y], ...] }` or `at: { within: [x0, y0, x1, y1] }`, \
             optionally with `out_of_sight: true`",
        )
    };
    let inside = |p: DVec2| (0.0..=arena.x).contains(&p.x) && (0.0..=arena.y).contains(&p.y);
    let draw = match (raw.one_of, raw.within) {
        (Some(_), Some(_)) => {
            return Err(bad("give `one_of` or `within`, not both".into()));
        }
        (None, None) => {
            return Err(bad(
                "a drawn position needs `one_of: [[x, y], ...]` or `within: [x0, y0, x1, y1]`"
                    .into(),
            ));
        }
        (Some(points), None) => {
            if points.is_empty() {
                return Err(bad("`one_of` lists no point".into()));
            }
            let points: Vec<DVec2> = points.into_iter().map(DVec2::from).collect();
            if let Some(p) = points.iter().find(|p| !p.is_finite() || !inside(**p)) {
                return Err(bad(format!(
                    "`one_of`: point [{}, {}] is not in the arena [0, {}] x [0, {}]",
                    p.x, p.y, arena.x, arena.y
                )));
            }
            Draw::OneOf(points)
        }
        (None, Some(r)) => {
            let [x0, y0, x1, y1] = r;
            if !r.iter().all(|v| v.is_finite()) || x0 >= x1 || y0 >= y1 {
                return Err(bad(format!(
                    "`within` is `[x0, y0, x1, y1]` with x0 < x1 and y0 < y1, found \
                     [{x0}, {y0}, {x1}, {y1}]"
                )));
            }
            if !inside(DVec2::new(x0, y0)) || !inside(DVec2::new(x1, y1)) {
                return Err(bad(format!(
                    "`within` [{x0}, {y0}, {x1}, {y1}] reaches out of the arena [0, {}] x [0, {}]",
                    arena.x, arena.y
                )));
            }
            Draw::Within(r)
        }
    };
    Ok(Placement {
        draw,
        out_of_sight: raw.out_of_sight,
        loc,
    })
}

impl PhysicsSpec {
    pub(crate) fn from_raw(
        file: &Arc<str>,
        loc: Loc,
        raw: PhysicsRaw,
        d: &mut Vec<Diagnostic>,
    ) -> PhysicsSpec {
        // Each value's error at its key, the section's where it is left out.
        let value = |v: &Option<Spanned<f64>>, default: f64| match v {
            Some(s) => (Loc::from(s.referenced), s.value),
            None => (loc, default),
        };
        let (at, v) = value(&raw.hz, 50.0);
        let hz = positive(file, at, "hz", v, d);
        let arena_at = Loc::from(raw.arena.referenced);
        let arena = DVec2::new(
            positive(file, arena_at, "arena width", raw.arena.value[0], d),
            positive(file, arena_at, "arena height", raw.arena.value[1], d),
        );
        if arena.x > MAX_ARENA || arena.y > MAX_ARENA {
            d.push(Diagnostic::error(
                file,
                arena_at,
                "bad-value",
                format!(
                    "the arena is at most {MAX_ARENA} m on a side, found {} x {}",
                    arena.x, arena.y
                ),
            ));
        }
        let r = &raw.robot;
        let drive = match r.drive.as_ref() {
            None => Drive::Differential,
            Some(s) if s.value == "differential" => Drive::Differential,
            Some(s) if s.value == "holonomic" => Drive::Holonomic,
            Some(s) => {
                d.push(
                    Diagnostic::error(
                        file,
                        Loc::from(s.referenced),
                        "bad-value",
                        format!("unknown drive `{}`", s.value),
                    )
                    .with_hint("`differential` or `holonomic`"),
                );
                Drive::Differential
            }
        };
        let robot_value = |name: &str, v: &Option<Spanned<f64>>, default: f64, d: &mut Vec<_>| {
            let (at, v) = value(v, default);
            positive(file, at, name, v, d)
        };
        let robot = RobotModel {
            radius: robot_value("robot.radius", &r.radius, 0.15, d),
            drive,
            max_speed: robot_value("robot.max_speed", &r.max_speed, 0.3, d),
            max_turn: robot_value("robot.max_turn", &r.max_turn, 3.0, d),
            max_accel: robot_value("robot.max_accel", &r.max_accel, 1.0, d),
            mass: robot_value("robot.mass", &r.mass, 10.0, d),
        };
        let start = raw
            .start
            .into_iter()
            .map(|(name, s)| {
                (
                    name,
                    (
                        DVec2::from(s.value.at),
                        s.value.heading.to_radians(),
                        Loc::from(s.referenced),
                    ),
                )
            })
            .collect();
        let mut bodies = |list: Vec<Spanned<ShapeRaw>>, movable: bool| -> Vec<Body> {
            let mut out = Vec::new();
            for s in list {
                let loc = Loc::from(s.referenced);
                let s = s.value;
                let shape = match (s.rect, s.disc) {
                    (Some(b), None) => Shape::Box(DVec2::new(
                        positive(file, loc, "box width", b[0], d),
                        positive(file, loc, "box height", b[1], d),
                    )),
                    (None, Some(r)) => Shape::Disc(positive(file, loc, "disc", r, d)),
                    _ => {
                        d.push(Diagnostic::error(
                            file,
                            loc,
                            "bad-shape",
                            "give exactly one of `box: [width, height]` or `disc: radius`",
                        ));
                        continue;
                    }
                };
                if movable && s.name.is_none() {
                    d.push(Diagnostic::error(
                        file,
                        loc,
                        "bad-shape",
                        "a movable object needs a `name` (robots see it by name)",
                    ));
                }
                let at_loc = Loc::from(s.at.referenced);
                let (at, place) = match s.at.value {
                    AtRaw::Point(p) => (DVec2::from(p), None),
                    AtRaw::Drawn(_) if !movable => {
                        d.push(
                            Diagnostic::error(
                                file,
                                at_loc,
                                "bad-place",
                                "an obstacle stands where it is put: `at: [x, y]`",
                            )
                            .with_hint("only a movable object's start may be drawn by the seed"),
                        );
                        (DVec2::ZERO, None)
                    }
                    AtRaw::Drawn(raw) => match placement(file, at_loc, raw, arena) {
                        Ok(p) => (p.draw.typical(), Some(p)),
                        Err(e) => {
                            d.push(e);
                            (DVec2::ZERO, None)
                        }
                    },
                };
                out.push(Body {
                    name: s.name,
                    at,
                    place,
                    angle: s.angle.to_radians(),
                    shape,
                    colour: s.colour,
                    mass: positive(file, loc, "mass", s.mass.unwrap_or(1.0), d),
                    damping: s.damping.unwrap_or(4.0).max(0.0),
                });
            }
            out
        };
        let obstacles = bodies(raw.obstacles, false);
        let objects = bodies(raw.objects, true);
        let s = &raw.sensors;
        let (rays, camera) = (s.rays.as_ref(), s.camera.as_ref());
        let sensors = Sensors {
            pose_noise: s.pose_noise.unwrap_or(0.0).max(0.0),
            rays: rays.and_then(|r| r.count).unwrap_or(8),
            ray_range: rays.and_then(|r| r.range).unwrap_or(1.5),
            ray_noise: rays.and_then(|r| r.noise).unwrap_or(0.0).max(0.0),
            fov: camera.and_then(|c| c.fov).unwrap_or(120.0).to_radians(),
            camera_range: camera.and_then(|c| c.range).unwrap_or(4.0),
            camera_noise: camera.and_then(|c| c.noise).unwrap_or(0.0).max(0.0),
            radio_range: s.radio_range,
        };
        let goal = raw.goal.map(|g| {
            if !objects.iter().any(|o| o.name.as_deref() == Some(&g.object)) {
                d.push(Diagnostic::error(
                    file,
                    loc,
                    "bad-goal",
                    format!(
                        "the goal names object `{}`, which the scenario does not have",
                        g.object
                    ),
                ));
            }
            if !raw.zones.contains_key(&g.zone) {
                d.push(Diagnostic::error(
                    file,
                    loc,
                    "bad-goal",
                    format!(
                        "the goal names zone `{}`, which the scenario does not have",
                        g.zone
                    ),
                ));
            }
            (g.object, g.zone)
        });
        PhysicsSpec {
            hz,
            arena,
            robot,
            start,
            loc,
            obstacles,
            objects,
            zones: raw.zones,
            sensors,
            beliefs: raw
                .beliefs
                .into_iter()
                .map(|(k, v)| (k, v.value, Loc::from(v.referenced)))
                .collect(),
            goal,
            origin: raw.origin.map(DVec2::from),
            targets: raw
                .targets
                .into_iter()
                .map(|(k, t)| {
                    (
                        k,
                        TargetSpec {
                            colour: t.colour,
                            size: t.size.unwrap_or([None; 3]),
                        },
                    )
                })
                .collect(),
            trail: raw.trail.map(|t| {
                if t.is_finite() && t >= 0.0 {
                    t
                } else {
                    d.push(Diagnostic::error(
                        file,
                        loc,
                        "bad-value",
                        format!("`trail` is seconds between samples (0: none), found {t}"),
                    ));
                    0.0
                }
            }),
        }
    }
}

/// A schema as written in a skill: its name, layer, gain and parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct SchemaSpec {
    /// Schema name.
    pub schema: String,
    /// Priority layer 0-3.
    pub layer: u8,
    /// Gain.
    pub gain: f64,
    /// Parameters (a behavior's skill parameters are laid over them).
    pub params: BTreeMap<String, serde_json::Value>,
    /// Where it is written.
    pub loc: Loc,
}

/// The schema names, for hints.
pub const SCHEMAS: &[&str] = &[
    "move-to-goal",
    "avoid-obstacle",
    "avoid-teammate",
    "keep-slot",
    "follow",
    "wander",
    "scan",
    "face",
    "look-around",
    "push",
    "stop",
];

fn params_of(schema: &str) -> &'static [&'static str] {
    match schema {
        "move-to-goal" => &["goal", "direction", "speed"],
        "avoid-obstacle" | "avoid-teammate" => &["range"],
        "keep-slot" => &["of", "side", "distance", "speed"],
        "follow" => &["of", "distance", "speed"],
        "wander" => &["speed", "period"],
        "scan" => &["region", "spacing", "speed", "split", "patience"],
        "face" => &["target"],
        "push" => &["object", "goal", "offset", "speed"],
        _ => &[],
    }
}

impl SchemaSpec {
    pub(crate) fn from_json(
        v: &serde_json::Value,
        loc: Loc,
    ) -> Result<SchemaSpec, (String, Option<String>)> {
        let serde_json::Value::Object(m) = v else {
            return Err((
                "a schema is a mapping: `{ schema: move-to-goal, layer: 1, gain: 1, ... }`".into(),
                None,
            ));
        };
        let name = m
            .get("schema")
            .and_then(|s| s.as_str())
            .ok_or_else(|| ("a schema needs `schema: <name>`".to_string(), None))?;
        if !SCHEMAS.contains(&name) {
            return Err((
                format!("unknown schema `{name}`"),
                bite_core::diag::did_you_mean(name, SCHEMAS.iter().copied())
                    .or_else(|| Some(format!("the schemas are: {}", SCHEMAS.join(", ")))),
            ));
        }
        let layer = match m.get("layer") {
            None => 1,
            Some(l) => match l.as_u64() {
                Some(l) if l <= 3 => l as u8,
                _ => return Err(("`layer` is a priority from 0 to 3".into(), None)),
            },
        };
        let gain = match m.get("gain") {
            None => 1.0,
            Some(g) => g
                .as_f64()
                .filter(|g| g.is_finite())
                .ok_or_else(|| ("`gain` must be a number".to_string(), None))?,
        };
        let known = params_of(name);
        let mut params = BTreeMap::new();
        for (k, v) in m {
            if matches!(k.as_str(), "schema" | "layer" | "gain") {
                continue;
            }
            if !known.contains(&k.as_str()) {
                return Err((
                    format!("schema `{name}` has no parameter `{k}`"),
                    Some(if known.is_empty() {
                        "it takes none".to_string()
                    } else {
                        format!("its parameters are: {}", known.join(", "))
                    }),
                ));
            }
            params.insert(k.clone(), v.clone());
        }
        let spec = SchemaSpec {
            schema: name.to_string(),
            layer,
            gain,
            params,
            loc,
        };
        // Check what can be checked without a behavior's parameters.
        spec.build(&BTreeMap::new(), 1.0, true)
            .map_err(|e| (e, None))?;
        Ok(spec)
    }

    /// The schema with a behavior's skill parameters laid over the
    /// scenario's. `lenient`: parameters still missing are not errors (a
    /// behavior may give them).
    pub fn build(
        &self,
        over: &BTreeMap<String, serde_json::Value>,
        max_speed: f64,
        lenient: bool,
    ) -> Result<Weighted, String> {
        let known = params_of(&self.schema);
        let get = |k: &str| {
            over.get(k)
                .filter(|_| known.contains(&k))
                .or_else(|| self.params.get(k))
        };
        let name = &self.schema;
        let num = |k: &str, default: Option<f64>| -> Result<f64, String> {
            match get(k) {
                Some(v) => v
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| format!("schema `{name}`: `{k}` must be a number")),
                None => default.ok_or_else(|| format!("schema `{name}` needs `{k}`")),
            }
        };
        let text = |k: &str| -> Result<String, String> {
            match get(k) {
                Some(serde_json::Value::String(s)) => Ok(s.clone()),
                Some(_) => Err(format!("schema `{name}`: `{k}` must be a name")),
                None => Err(format!("schema `{name}` needs `{k}`")),
            }
        };
        let point = |v: &serde_json::Value| -> Option<DVec2> {
            let a = v.as_array()?;
            (a.len() == 2).then_some(DVec2::new(a[0].as_f64()?, a[1].as_f64()?))
        };
        let target = |k: &str| -> Result<Target, String> {
            match get(k) {
                Some(serde_json::Value::String(s)) => Ok(Target::Object(s.clone())),
                Some(v) => point(v)
                    .map(Target::Point)
                    .ok_or_else(|| format!("schema `{name}`: `{k}` is `[x, y]` or an object name")),
                None => Err(format!("schema `{name}` needs `{k}`")),
            }
        };
        let speed = num("speed", Some(max_speed));
        let placeholder = || "?".to_string();
        let or_lenient = |r: Result<String, String>| match r {
            Err(_) if lenient => Ok(placeholder()),
            r => r,
        };
        let schema = match name.as_str() {
            "move-to-goal" => {
                let goal = match (get("goal"), get("direction")) {
                    (Some(_), None) => target("goal")?,
                    (None, Some(v)) => Target::Direction(
                        point(v)
                            .ok_or_else(|| format!("schema `{name}`: `direction` is `[x, y]`"))?,
                    ),
                    (Some(_), Some(_)) => {
                        return Err(format!(
                            "schema `{name}`: give `goal` or `direction`, not both"
                        ));
                    }
                    (None, None) if lenient => Target::Direction(DVec2::X),
                    (None, None) => {
                        return Err(format!("schema `{name}` needs `goal` or `direction`"));
                    }
                };
                Schema::MoveToGoal {
                    goal,
                    speed: speed?,
                }
            }
            "avoid-obstacle" => Schema::AvoidObstacle {
                range: num("range", Some(0.4))?,
            },
            "avoid-teammate" => Schema::AvoidTeammate {
                range: num("range", Some(0.5))?,
            },
            "keep-slot" => Schema::KeepSlot {
                of: or_lenient(text("of"))?,
                side: match get("side").and_then(|s| s.as_str()) {
                    None | Some("behind") => Side::Behind,
                    Some("left") => Side::Left,
                    Some("right") => Side::Right,
                    Some(o) => {
                        return Err(format!(
                            "schema `{name}`: `side` is left, right or behind, not `{o}`"
                        ));
                    }
                },
                distance: num("distance", Some(0.6))?,
                speed: speed?,
            },
            "follow" => Schema::Follow {
                of: or_lenient(text("of"))?,
                distance: num("distance", Some(0.5))?,
                speed: speed?,
            },
            "wander" => Schema::Wander {
                speed: speed?,
                period: num("period", Some(3.0))?,
            },
            "scan" => {
                let region = match get("region") {
                    Some(v) => {
                        let a: Option<Vec<f64>> = v
                            .as_array()
                            .map(|a| a.iter().filter_map(|x| x.as_f64()).collect());
                        match a {
                            Some(a) if a.len() == 4 => [a[0], a[1], a[2], a[3]],
                            _ => {
                                return Err(format!(
                                    "schema `{name}`: `region` is `[x0, y0, x1, y1]`"
                                ));
                            }
                        }
                    }
                    None if lenient => [0.0; 4],
                    None => return Err(format!("schema `{name}` needs `region`")),
                };
                Schema::Scan {
                    region,
                    spacing: num("spacing", Some(1.0))?,
                    speed: speed?,
                    split: match get("split") {
                        None => false,
                        Some(serde_json::Value::Bool(b)) => *b,
                        Some(_) => {
                            return Err(format!("schema `{name}`: `split` is true or false"));
                        }
                    },
                    patience: num("patience", Some(10.0))?,
                }
            }
            "look-around" => Schema::LookAround,
            "face" => Schema::Face {
                target: match target("target") {
                    Err(_) if lenient => Target::Direction(DVec2::X),
                    r => r?,
                },
            },
            "push" => Schema::Push {
                object: or_lenient(text("object"))?,
                goal: match get("goal").and_then(point) {
                    Some(p) => p,
                    None if lenient && get("goal").is_none() => DVec2::ZERO,
                    None => return Err(format!("schema `{name}`: `goal` is `[x, y]`")),
                },
                offset: num("offset", Some(0.45))?,
                speed: speed?,
            },
            _ => Schema::Stop,
        };
        Ok(Weighted {
            schema,
            gain: self.gain,
            layer: self.layer,
        })
    }
}

/// True when `p` lies in the rectangle `[x0, y0, x1, y1]` (corners in any order).
pub fn in_rect(p: DVec2, r: &[f64; 4]) -> bool {
    let [x0, y0, x1, y1] = *r;
    p.x >= x0.min(x1) && p.x <= x0.max(x1) && p.y >= y0.min(y1) && p.y <= y0.max(y1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(shape: Shape, colour: &str) -> Body {
        Body {
            name: None,
            at: DVec2::ZERO,
            place: None,
            angle: 0.0,
            shape,
            colour: Some(colour.into()),
            mass: 1.0,
            damping: 1.0,
        }
    }

    #[test]
    fn a_target_fits_by_colour_and_footprint() {
        let cube = body(Shape::Box(DVec2::new(0.25, 0.25)), "red");
        let crate_ = body(Shape::Box(DVec2::new(0.5, 0.5)), "red");
        let blue = body(Shape::Box(DVec2::new(0.25, 0.25)), "blue");
        let plank = body(Shape::Box(DVec2::new(0.25, 1.0)), "Red");
        let ball = body(Shape::Disc(0.125), "red");
        let red_quarter = TargetSpec {
            colour: Some("RED".into()),
            size: [Some(0.25), Some(0.25), Some(0.25)],
        };
        assert!(red_quarter.fits(&cube));
        assert!(!red_quarter.fits(&crate_), "wrong size");
        assert!(!red_quarter.fits(&blue), "wrong colour");
        assert!(!red_quarter.fits(&plank), "one side wrong");
        assert!(
            red_quarter.fits(&ball),
            "a disc's footprint is its diameter"
        );
        // Unknown parameters match anything; length and width in either order.
        let red = TargetSpec {
            colour: Some("red".into()),
            size: [None; 3],
        };
        assert!(red.fits(&crate_) && red.fits(&plank) && !red.fits(&blue));
        let long = TargetSpec {
            colour: None,
            size: [Some(1.0), Some(0.25), None],
        };
        assert!(long.fits(&plank) && !long.fits(&cube));
        let any = TargetSpec::default();
        assert!(any.fits(&blue));
    }

    /// A one-object physical scenario with `at` as given (line 6).
    fn with_at(at: &str) -> Result<crate::scenario::Scenario, bite_core::diag::Diagnostics> {
        let text = format!(
            "scenario: s\nworld: physics\nphysics:\n  arena: [7, 4]\n  objects:\n    - {{ name: box, box: [0.3, 0.3], at: {at} }}\n"
        );
        crate::scenario::Scenario::load_str(&Arc::from("s.yaml"), &text)
    }

    /// A bad value of the physics section is reported at its key, not at
    /// the section's first line (input audit).
    #[test]
    fn a_bad_physics_value_is_an_error_at_its_key() {
        let err = |body: &str| {
            let text = format!("scenario: s\nworld: physics\nphysics:\n  hz: 50\n{body}");
            match crate::scenario::Scenario::load_str(&Arc::from("s.yaml"), &text) {
                Ok(_) => panic!("`{body}` accepted"),
                Err(d) => d.to_string(),
            }
        };
        let e = err("  arena: [7, -4]\n");
        assert!(
            e.contains("s.yaml:5:10: error[bad-value]: `arena height`"),
            "{e}"
        );
        let e = err("  arena: [7, 4]\n  robot:\n    radius: 0.2\n    mass: 0\n");
        assert!(
            e.contains("s.yaml:8:11: error[bad-value]: `robot.mass`"),
            "{e}"
        );
        let e = err("  arena: [7, 4]\n  robot: { drive: legs }\n");
        assert!(
            e.contains("s.yaml:6:19: error[bad-value]: unknown drive `legs`"),
            "{e}"
        );
        let e = err("  arena: [1e9, 4]\n");
        assert!(
            e.contains("s.yaml:5:10: error[bad-value]: the arena is at most"),
            "{e}"
        );
    }

    #[test]
    fn a_drawn_position_is_read_with_its_source() {
        let sc = with_at("{ within: [4, 0.5, 6.5, 3.5], out_of_sight: true }").expect("loads");
        let o = &sc.physics.as_ref().expect("physics").objects[0];
        let p = o.place.as_ref().expect("drawn");
        assert_eq!(p.draw, Draw::Within([4.0, 0.5, 6.5, 3.5]));
        assert!(p.out_of_sight);
        assert_eq!(p.loc, Loc::new(6, 41));
        // Until a run draws it, it stands at the centre of the region.
        assert_eq!(o.at, DVec2::new(5.25, 2.0));
        let sc = with_at("{ one_of: [[1, 1], [6, 3]] }").expect("loads");
        let o = &sc.physics.as_ref().expect("physics").objects[0];
        let p = o.place.as_ref().expect("drawn");
        assert_eq!(
            p.draw,
            Draw::OneOf(vec![DVec2::new(1.0, 1.0), DVec2::new(6.0, 3.0)])
        );
        assert!(!p.out_of_sight);
        assert_eq!(o.at, DVec2::new(1.0, 1.0));
        // A point is still a point.
        let sc = with_at("[2, 3]").expect("loads");
        let o = &sc.physics.as_ref().expect("physics").objects[0];
        assert_eq!((o.at, o.place.is_none()), (DVec2::new(2.0, 3.0), true));
    }

    #[test]
    fn a_bad_drawn_position_is_an_error_where_it_is_written() {
        let err = |at: &str| match with_at(at) {
            Ok(_) => panic!("`{at}` accepted"),
            Err(d) => d.to_string(),
        };
        let e = err("{ within: [6, 0.5, 4, 3.5] }");
        assert!(e.contains("s.yaml:6:41: error[bad-place]"), "{e}");
        assert!(e.contains("x0 < x1 and y0 < y1"), "{e}");
        let e = err("{ within: [4, 0.5, 8, 3.5] }");
        assert!(e.contains("s.yaml:6:41: error[bad-place]"), "{e}");
        assert!(
            e.contains("reaches out of the arena [0, 7] x [0, 4]"),
            "{e}"
        );
        let e = err("{ within: [4, 0.5, 6] }");
        assert!(e.contains("s.yaml:6:"), "{e}");
        let e = err("{ within: [4, 0.5, 6, 3], one_of: [[1, 1]] }");
        assert!(e.contains("not both"), "{e}");
        let e = err("{ out_of_sight: true }");
        assert!(e.contains("needs `one_of"), "{e}");
        let e = err("{ one_of: [] }");
        assert!(e.contains("lists no point"), "{e}");
        let e = err("{ one_of: [[1, 1], [9, 1]] }");
        assert!(e.contains("point [9, 1] is not in the arena"), "{e}");
        let e = err("{ inside: [4, 0.5, 6, 3] }");
        assert!(e.contains("s.yaml:6:"), "{e}");
        assert!(e.contains("inside"), "{e}");
        let e = err("[1, 2, 3]");
        assert!(e.contains("s.yaml:6:"), "{e}");
        // Obstacles stand where they are put.
        let text = "scenario: s\nworld: physics\nphysics:\n  arena: [7, 4]\n  obstacles:\n    - { disc: 0.2, at: { within: [1, 1, 2, 2] } }\n";
        let e = crate::scenario::Scenario::load_str(&Arc::from("s.yaml"), text)
            .map(|_| ())
            .expect_err("rejected")
            .to_string();
        assert!(e.contains("s.yaml:6:24: error[bad-place]"), "{e}");
    }
}
