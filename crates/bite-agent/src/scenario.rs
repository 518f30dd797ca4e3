//! Scenario files for the timed-skill world (see `docs/scenario-format.md`).
//!
//! A scenario says how long skills take and what they make robots believe,
//! what the network does, which facts change when, which robots crash, the
//! seed and the time limit. The same behavior graph runs against any
//! scenario.

use crate::netmodel::{Cut, NetModel, Partition};
use bite_core::diag::{Diagnostic, Diagnostics, Loc};
use bite_core::graph::BehaviorGraph;
use bite_core::ids::RobotId;
use bite_core::time::{Time, parse_duration};
use bite_core::value::Value;
use bite_core::yaml::{DurationText, Ordered, json_to_value};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_saphyr::Spanned;
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// A random quantity drawn per robot and per skill execution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dist {
    /// Always this value.
    Const(f64),
    /// Uniform in `[lo, hi]`.
    Uniform(f64, f64),
    /// Normal with mean and standard deviation, truncated at zero.
    Normal(f64, f64),
    /// Exponential with this mean.
    Exponential(f64),
}

impl<'de> Deserialize<'de> for Dist {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Dist;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a number, `[lo, hi]` (uniform), `{uniform: [lo, hi]}`, `{normal: [mean, sd]}` or `{exponential: mean}`",
                )
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Dist, E> {
                Ok(Dist::Const(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Dist, E> {
                Ok(Dist::Const(v as f64))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Dist, E> {
                Ok(Dist::Const(v as f64))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Dist, A::Error> {
                let lo: f64 = s
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(0, &self))?;
                let hi: f64 = s
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(1, &self))?;
                if s.next_element::<f64>()?.is_some() {
                    return Err(de::Error::custom("a uniform range has exactly two bounds"));
                }
                Ok(Dist::Uniform(lo, hi))
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Dist, A::Error> {
                let Some(key) = m.next_key::<String>()? else {
                    return Err(de::Error::custom("empty distribution"));
                };
                let d = match key.as_str() {
                    "uniform" => {
                        let [lo, hi]: [f64; 2] = m.next_value()?;
                        Dist::Uniform(lo, hi)
                    }
                    "normal" => {
                        let [mean, sd]: [f64; 2] = m.next_value()?;
                        Dist::Normal(mean, sd)
                    }
                    "exponential" => Dist::Exponential(m.next_value()?),
                    other => {
                        return Err(de::Error::unknown_field(
                            other,
                            &["uniform", "normal", "exponential"],
                        ));
                    }
                };
                if m.next_key::<String>()?.is_some() {
                    return Err(de::Error::custom("a distribution has exactly one kind"));
                }
                Ok(d)
            }
        }
        d.deserialize_any(V)
    }
}

impl Dist {
    fn check(&self) -> Result<(), String> {
        let ok = match *self {
            Dist::Const(v) => v.is_finite(),
            Dist::Uniform(a, b) => a.is_finite() && b.is_finite() && a <= b,
            Dist::Normal(m, s) => m.is_finite() && s.is_finite() && s >= 0.0,
            Dist::Exponential(m) => m.is_finite() && m > 0.0,
        };
        if ok {
            Ok(())
        } else {
            Err(format!(
                "invalid distribution {self:?} (bounds must be finite and ordered, spreads non-negative)"
            ))
        }
    }
    /// Draw a value.
    pub fn sample(&self, rng: &mut bite_core::interaction::Rng) -> f64 {
        use rand::RngExt;
        use rand_distr::Distribution;
        match *self {
            Dist::Const(v) => v,
            Dist::Uniform(a, b) if a < b => rng.random_range(a..=b),
            Dist::Uniform(a, _) => a,
            Dist::Normal(m, s) => match rand_distr::Normal::new(m, s) {
                Ok(n) => n.sample(rng).max(0.0),
                Err(_) => m,
            },
            Dist::Exponential(mean) => match rand_distr::Exp::new(1.0 / mean) {
                Ok(e) => e.sample(rng),
                Err(_) => mean,
            },
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioSpec {
    scenario: Option<String>,
    description: Option<String>,
    world: Option<Spanned<String>>,
    seed: Option<u64>,
    robots: Option<Spanned<u64>>,
    control_hz: Option<Spanned<f64>>,
    time_limit: Option<Spanned<DurationText>>,
    #[serde(default)]
    network: Option<Spanned<NetSpec>>,
    #[serde(default)]
    skills: Ordered<SkillSpec>,
    #[serde(default)]
    events: Vec<Spanned<EventSpec>>,
    #[serde(default)]
    crashes: Vec<Spanned<CrashSpec>>,
    #[serde(default)]
    mission_changes: Vec<Spanned<ChangeSpec>>,
    failure_detector: Option<Spanned<DetectorSpec>>,
    stall: Option<Spanned<StallSpec>>,
    #[serde(default)]
    clocks: Ordered<ClockSpec>,
    inject: Option<Spanned<InjectSpec>>,
    #[serde(default)]
    sensed: Vec<String>,
    physics: Option<Spanned<crate::spec::PhysicsRaw>>,
}

/// How teammates find out that a robot is gone: heartbeats, and a robot
/// silent for longer than `lost_after` is presumed lost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FailureDetector {
    /// Silence after which a teammate is presumed lost.
    pub lost_after: Duration,
    /// Heartbeat period: detection times spread over one period.
    pub heartbeat: Duration,
}

/// The shortest heartbeat period a scenario may ask for.
pub const MIN_HEARTBEAT: Duration = Duration::from_millis(10);

impl Default for FailureDetector {
    fn default() -> Self {
        FailureDetector {
            lost_after: Duration::from_secs(2),
            heartbeat: Duration::from_millis(250),
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct NetSpec {
    latency: Option<DurationText>,
    jitter: Option<DurationText>,
    #[serde(default)]
    loss: f64,
    #[serde(default)]
    duplicate: f64,
    #[serde(default)]
    partitions: Vec<Spanned<PartitionSpec>>,
    #[serde(default)]
    holds: Vec<Spanned<HoldSpec>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HoldSpec {
    from: DurationText,
    until: DurationText,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PartitionSpec {
    from: DurationText,
    until: DurationText,
    groups: Option<Vec<Vec<RobotRef>>>,
    one_way: Option<OneWaySpec>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OneWaySpec {
    from: Vec<RobotRef>,
    to: Vec<RobotRef>,
}

/// A robot named in a scenario: roster name or index.
#[derive(Clone, Debug, PartialEq)]
pub enum RobotRef {
    /// By roster index.
    Index(u64),
    /// By name.
    Name(String),
}

impl<'de> Deserialize<'de> for RobotRef {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = RobotRef;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a robot name or index")
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<RobotRef, E> {
                Ok(RobotRef::Index(v))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<RobotRef, E> {
                Ok(RobotRef::Name(v.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct SkillSpec {
    duration: Option<Dist>,
    #[serde(default)]
    rate: Ordered<Dist>,
    speed: Option<Dist>,
    #[serde(default)]
    drives: Vec<String>,
    #[serde(default)]
    start: Ordered<serde_json::Value>,
    #[serde(default)]
    done: Ordered<serde_json::Value>,
    #[serde(default)]
    schemas: Vec<Spanned<serde_json::Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EventSpec {
    at: DurationText,
    robots: Option<Vec<RobotRef>>,
    set: Ordered<serde_json::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ChangeSpec {
    at: DurationText,
    graph: String,
    config: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CrashSpec {
    robot: RobotRef,
    at: DurationText,
    until: Option<DurationText>,
    #[serde(default)]
    restart: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClockSpec {
    #[serde(default = "one")]
    rate: f64,
    offset: Option<DurationText>,
}

fn one() -> f64 {
    1.0
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InjectSpec {
    every: DurationText,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DetectorSpec {
    #[serde(default = "yes")]
    enabled: bool,
    lost_after: Option<DurationText>,
    heartbeat: Option<DurationText>,
}

fn yes() -> bool {
    true
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StallSpec {
    /// No progress for this long ends the run as stalled (`never`: off).
    after: Option<DurationText>,
    /// A behavior started more than this many times within one execution
    /// of its parent ends the run as stalled (`0`: off).
    repeats: Option<u32>,
}

/// What a skill does in the timed world.
#[derive(Clone, Debug, PartialEq)]
pub struct SkillModel {
    /// Time until the skill completes (`None`: never by itself).
    pub duration: Option<Dist>,
    /// Numeric beliefs that grow at a rate (per second) while it runs,
    /// each rate drawn independently.
    pub rates: Vec<(String, Dist)>,
    /// One rate drawn per execution that drives every belief of `drives`
    /// (a robot's leg and total distance grow at the same pace).
    pub speed: Option<Dist>,
    /// Beliefs driven by `speed`.
    pub drives: Vec<String>,
    /// Beliefs set when it starts.
    pub on_start: Vec<(String, Value)>,
    /// Beliefs set when it completes.
    pub on_done: Vec<(String, Value)>,
    /// Motor schemas that drive the robot in the physical world.
    pub schemas: Vec<crate::spec::SchemaSpec>,
}

/// Facts that change at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldEvent {
    /// When.
    pub at: Time,
    /// For whom (`None`: everyone).
    pub robots: Option<Vec<RobotRef>>,
    /// What becomes true.
    pub set: Vec<(String, Value)>,
    /// Where it is written.
    pub loc: Loc,
}

/// A new version of the mission handed to the running team at a time
/// (`mission_changes:`).
#[derive(Clone, Debug, PartialEq)]
pub struct MissionChange {
    /// When.
    pub at: Time,
    /// The new graph file, as written (relative to the scenario file).
    pub graph: String,
    /// Its configuration file, if any (relative to the scenario file).
    pub config: Option<String>,
    /// Where it is written.
    pub loc: Loc,
}

impl MissionChange {
    /// A path of this entry, relative to the scenario file `scenario`.
    pub fn path(scenario: &Path, written: &str) -> std::path::PathBuf {
        let p = Path::new(written);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        scenario
            .parent()
            .map_or_else(|| p.to_path_buf(), |d| d.join(p))
    }
}

/// A robot that stops at a time (no more ticks, messages or timers).
#[derive(Clone, Debug, PartialEq)]
pub struct Crash {
    /// Which robot.
    pub robot: RobotRef,
    /// When.
    pub at: Time,
    /// When it resumes, with its state intact (`None`: never).
    pub until: Option<Time>,
    /// It resumes as a restarted process: a fresh mind (no state kept)
    /// that rejoins the team where the team is.
    pub restart: bool,
    /// Where it is written.
    pub loc: Loc,
}

/// A partition as written, robots not yet resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct PartitionRef {
    /// Start.
    pub from: Time,
    /// End.
    pub until: Time,
    /// Symmetric groups, or `None` for a one-way cut.
    pub groups: Option<Vec<Vec<RobotRef>>>,
    /// One-way cut: senders and receivers.
    pub one_way: Option<(Vec<RobotRef>, Vec<RobotRef>)>,
    /// Where it is written.
    pub loc: Loc,
}

/// Facts that become true for some robots at a time, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct TimedFact {
    /// When.
    pub at: Time,
    /// For whom (`None`: everyone).
    pub robots: Option<Vec<RobotId>>,
    /// What.
    pub set: Vec<(String, Value)>,
}

/// A scenario resolved against a graph: robot ids instead of names.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The network, partitions included.
    pub network: NetModel,
    /// Timed facts.
    pub events: Vec<TimedFact>,
    /// Crashes: who, when, and when it resumes (`None`: never).
    pub crashes: Vec<(RobotId, Time, Option<Time>)>,
    /// Robots whose resumption is a restart with a fresh mind.
    pub restarts: Vec<(RobotId, Time)>,
    /// Each robot's clock: rate and offset (seconds). Empty when every
    /// clock keeps true time, so that a runtime reads no table per event;
    /// a robot without an entry keeps true time.
    pub clocks: Vec<(f64, f64)>,
    /// Warnings (beliefs nobody reads, skills the scenario does not describe).
    pub warnings: Vec<Diagnostic>,
    /// In the physical world: each behavior's motor schemas, with its skill
    /// parameters laid over the scenario's (empty: none; no world: empty).
    pub motor: Vec<Arc<[crate::schema::Weighted]>>,
}

/// A scenario of the timed-skill world.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Name.
    pub name: String,
    /// Free text.
    pub description: Option<String>,
    /// File it came from.
    pub file: Arc<str>,
    /// Default seed of runs.
    pub seed: u64,
    /// Team size override.
    pub robots: Option<usize>,
    /// Control rate (ticks per second).
    pub control_hz: f64,
    /// Runs stop here if the mission has not completed.
    pub time_limit: Duration,
    /// The network (without partitions; see `partitions`).
    pub network: NetModel,
    /// Partitions, robots unresolved.
    pub partitions: Vec<PartitionRef>,
    /// Skills by name.
    pub skills: BTreeMap<String, SkillModel>,
    /// Timed facts.
    pub events: Vec<WorldEvent>,
    /// Robot crashes.
    pub crashes: Vec<Crash>,
    /// New versions of the mission handed to the team while it runs.
    pub mission_changes: Vec<MissionChange>,
    /// Robots whose clocks run fast, slow or ahead: robot, rate, offset (s).
    pub clocks: Vec<(RobotRef, f64, f64, Loc)>,
    /// Forged, replayed or malformed messages injected this often.
    pub inject: Option<Duration>,
    /// Lost-teammate detection (`None`: off).
    pub failure_detector: Option<FailureDetector>,
    /// When a run counts as stalled.
    pub stall: StallLimits,
    /// Beliefs the world provides whether or not the graph reads them
    /// (protocol parameters of some configurations may): not warned about.
    pub sensed: Vec<String>,
    /// The physical world (`world: physics`), if any.
    pub physics: Option<Arc<crate::spec::PhysicsSpec>>,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: "default".into(),
            description: None,
            file: Arc::from("<built-in>"),
            seed: 1,
            robots: None,
            control_hz: 10.0,
            time_limit: Duration::from_secs(3600),
            network: NetModel::default(),
            partitions: Vec::new(),
            skills: BTreeMap::new(),
            events: Vec::new(),
            crashes: Vec::new(),
            mission_changes: Vec::new(),
            clocks: Vec::new(),
            inject: None,
            failure_detector: Some(FailureDetector::default()),
            stall: StallLimits::default(),
            sensed: Vec::new(),
            physics: None,
        }
    }
}

fn dur(file: &Arc<str>, loc: Loc, t: &DurationText, diags: &mut Vec<Diagnostic>) -> Duration {
    match parse_duration(&t.0) {
        Ok(d) => d,
        Err(e) => {
            diags.push(Diagnostic::error(file, loc, "bad-duration", e));
            Duration::ZERO
        }
    }
}

fn values(
    file: &Arc<str>,
    o: &Ordered<serde_json::Value>,
    diags: &mut Vec<Diagnostic>,
) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    for (k, v) in &o.0 {
        match json_to_value(&v.value) {
            Some(x) => out.push((k.value.clone(), x)),
            None => diags.push(Diagnostic::error(
                file,
                Loc::from(v.referenced),
                "bad-value",
                format!("`{}` must be a bool, number, text or [x, y]", k.value),
            )),
        }
    }
    out
}

/// The parts of a compiled mission (the robot team command language) that
/// belong to the world rather than the graph: each skill's motor schemas,
/// graph beliefs computed from percepts, and named object descriptions.
#[derive(Clone, Debug, Default)]
pub struct MissionParts {
    /// The mission file, for errors.
    pub file: Arc<str>,
    /// Skill name → its schemas, as a scenario's `schemas:` entries.
    pub skills: BTreeMap<String, Vec<serde_json::Value>>,
    /// Belief name → condition over percepts.
    pub beliefs: BTreeMap<String, String>,
    /// Target name → the objects it designates.
    pub targets: BTreeMap<String, crate::spec::TargetSpec>,
}

impl Scenario {
    /// This scenario with a compiled mission's skills, beliefs and targets
    /// added. The scenario's own skills and beliefs of the same names take
    /// precedence (a platform tunes a command's default schemas in its
    /// scenario); targets are the mission's.
    pub fn with_mission(&self, parts: &MissionParts) -> Result<Scenario, Diagnostics> {
        let file = &parts.file;
        let Some(ps) = &self.physics else {
            return Err(Diagnostics(vec![
                Diagnostic::error(
                    &self.file,
                    Loc::UNKNOWN,
                    "missing-physics",
                    format!(
                        "a compiled mission runs in the physical world, and scenario `{}` is a timed world",
                        self.name
                    ),
                )
                .with_hint("use a scenario with `world: physics`"),
            ]));
        };
        let mut d = Vec::new();
        let mut out = self.clone();
        for (name, schemas) in &parts.skills {
            if out.skills.contains_key(name) {
                continue;
            }
            let mut list = Vec::new();
            for v in schemas {
                match crate::spec::SchemaSpec::from_json(v, Loc::UNKNOWN) {
                    Ok(sc) => list.push(sc),
                    Err((e, hint)) => {
                        let mut diag = Diagnostic::error(
                            file,
                            Loc::UNKNOWN,
                            "bad-schema",
                            format!("skill `{name}`: {e}"),
                        );
                        if let Some(h) = hint {
                            diag = diag.with_hint(h);
                        }
                        d.push(diag);
                    }
                }
            }
            out.skills.insert(
                name.clone(),
                SkillModel {
                    duration: None,
                    rates: Vec::new(),
                    speed: None,
                    drives: Vec::new(),
                    on_start: Vec::new(),
                    on_done: Vec::new(),
                    schemas: list,
                },
            );
        }
        let mut spec = (**ps).clone();
        for (name, expr) in &parts.beliefs {
            if !spec.beliefs.iter().any(|(b, _, _)| b == name) {
                spec.beliefs
                    .push((name.clone(), expr.clone(), Loc::UNKNOWN));
            }
        }
        spec.targets.extend(parts.targets.clone());
        // A compiled belief that reads a percept the world lacks is the
        // mission's error, not the scenario's.
        for mut diag in crate::pilot::check_beliefs(&spec, file) {
            if diag.loc == Loc::UNKNOWN {
                diag.file = file.clone();
            }
            d.push(diag);
        }
        if d.iter().any(Diagnostic::is_error) {
            return Err(Diagnostics(d));
        }
        out.physics = Some(Arc::new(spec));
        Ok(out)
    }
}

impl Scenario {
    /// Load a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, Diagnostics> {
        let (file, text) = bite_core::yaml::read_file(path)?;
        Self::load_str(&file, &text)
    }

    /// Parse a scenario from text; `file` names it in messages.
    pub fn load_str(file: &Arc<str>, text: &str) -> Result<Scenario, Diagnostics> {
        let spec: ScenarioSpec = bite_core::yaml::parse(file, text)?;
        let mut d = Vec::new();
        let physical = spec.world.as_ref().is_some_and(|w| w.value == "physics");
        if let Some(w) = &spec.world
            && w.value != "timed"
            && w.value != "physics"
        {
            d.push(
                Diagnostic::error(
                    file,
                    Loc::from(w.referenced),
                    "unknown-world",
                    format!("unknown world `{}`", w.value),
                )
                .with_hint("`timed` (skills take a drawn time) or `physics` (rapier2d arena)"),
            );
        }
        let physics = match spec.physics {
            Some(p) if physical => {
                let loc = Loc::from(p.referenced);
                let ps = crate::spec::PhysicsSpec::from_raw(file, loc, p.value, &mut d);
                d.extend(crate::pilot::check_beliefs(&ps, file));
                Some(Arc::new(ps))
            }
            Some(p) => {
                d.push(
                    Diagnostic::error(
                        file,
                        Loc::from(p.referenced),
                        "unknown-world",
                        "a `physics:` section needs `world: physics`",
                    )
                    .with_hint("add `world: physics` at the top of the scenario"),
                );
                None
            }
            None if physical => {
                d.push(Diagnostic::error(
                    file,
                    spec.world.as_ref().map_or(Loc::UNKNOWN, |w| Loc::from(w.referenced)),
                    "missing-physics",
                    "`world: physics` needs a `physics:` section (at least `arena: [width, height]`)",
                ));
                None
            }
            None => None,
        };
        let control_hz = match &spec.control_hz {
            Some(h) if !(h.value.is_finite() && h.value > 0.0 && h.value <= 1000.0) => {
                d.push(Diagnostic::error(
                    file,
                    Loc::from(h.referenced),
                    "bad-value",
                    format!(
                        "`control_hz` must be more than 0 and at most 1000 (ticks per second), found {}",
                        h.value
                    ),
                ));
                10.0
            }
            Some(h) => h.value,
            None => 10.0,
        };
        let robots = match &spec.robots {
            Some(r) if r.value == 0 || r.value > bite_core::graph::MAX_ROBOTS as u64 => {
                d.push(Diagnostic::error(
                    file,
                    Loc::from(r.referenced),
                    "bad-value",
                    format!(
                        "`robots` must be between 1 and {}",
                        bite_core::graph::MAX_ROBOTS
                    ),
                ));
                None
            }
            Some(r) => Some(r.value as usize),
            None => None,
        };
        let time_limit = spec
            .time_limit
            .as_ref()
            .map_or(Duration::from_secs(3600), |t| {
                dur(file, Loc::from(t.referenced), &t.value, &mut d)
            });
        let mut partitions = Vec::new();
        let network = match &spec.network {
            None => NetModel::default(),
            Some(n) => {
                let loc = Loc::from(n.referenced);
                let n = &n.value;
                for (what, p) in [("loss", n.loss), ("duplicate", n.duplicate)] {
                    if !(0.0..=1.0).contains(&p) {
                        d.push(Diagnostic::error(
                            file,
                            loc,
                            "bad-value",
                            format!("`{what}` is a probability: between 0 and 1, found {p}"),
                        ));
                    }
                }
                for p in &n.partitions {
                    let ploc = Loc::from(p.referenced);
                    if p.value.groups.is_some() == p.value.one_way.is_some() {
                        d.push(Diagnostic::error(
                            file,
                            ploc,
                            "bad-partition",
                            "a partition has either `groups` or `one_way`",
                        ));
                        continue;
                    }
                    partitions.push(PartitionRef {
                        from: Time::ZERO + dur(file, ploc, &p.value.from, &mut d),
                        until: Time::ZERO + dur(file, ploc, &p.value.until, &mut d),
                        groups: p.value.groups.clone(),
                        one_way: p
                            .value
                            .one_way
                            .as_ref()
                            .map(|o| (o.from.clone(), o.to.clone())),
                        loc: ploc,
                    });
                }
                NetModel {
                    latency: n
                        .latency
                        .as_ref()
                        .map_or(NetModel::default().latency, |t| dur(file, loc, t, &mut d)),
                    jitter: n
                        .jitter
                        .as_ref()
                        .map_or(NetModel::default().jitter, |t| dur(file, loc, t, &mut d)),
                    loss: n.loss,
                    duplicate: n.duplicate,
                    partitions: Vec::new(),
                    holds: n
                        .holds
                        .iter()
                        .map(|h| {
                            let hloc = Loc::from(h.referenced);
                            let from = Time::ZERO + dur(file, hloc, &h.value.from, &mut d);
                            let until = Time::ZERO + dur(file, hloc, &h.value.until, &mut d);
                            if until <= from {
                                d.push(Diagnostic::error(
                                    file,
                                    hloc,
                                    "bad-value",
                                    "a hold must end (`until`) after it starts (`from`)",
                                ));
                            }
                            (from, until)
                        })
                        .collect(),
                }
            }
        };
        let mut skills = BTreeMap::new();
        for (name, s) in &spec.skills.0 {
            let sloc = Loc::from(s.referenced);
            let s = &s.value;
            let check = |dist: &Dist, d: &mut Vec<Diagnostic>| {
                if let Err(e) = dist.check() {
                    d.push(Diagnostic::error(file, sloc, "bad-value", e));
                }
            };
            if let Some(x) = &s.duration {
                check(x, &mut d);
            }
            if let Some(x) = &s.speed {
                check(x, &mut d);
            }
            if s.speed.is_some() == s.drives.is_empty() {
                d.push(Diagnostic::error(
                    file,
                    sloc,
                    "bad-skill",
                    format!(
                        "skill `{}`: `speed` and `drives` go together (a speed drives a list of beliefs)",
                        name.value
                    ),
                ));
            }
            for (_, r) in &s.rate.0 {
                check(&r.value, &mut d);
            }
            skills.insert(
                name.value.clone(),
                SkillModel {
                    duration: s.duration,
                    rates: s
                        .rate
                        .0
                        .iter()
                        .map(|(k, v)| (k.value.clone(), v.value))
                        .collect(),
                    speed: s.speed,
                    drives: s.drives.clone(),
                    on_start: values(file, &s.start, &mut d),
                    on_done: values(file, &s.done, &mut d),
                    schemas: s
                        .schemas
                        .iter()
                        .filter_map(|x| {
                            let loc = Loc::from(x.referenced);
                            match crate::spec::SchemaSpec::from_json(&x.value, loc) {
                                Ok(sc) => Some(sc),
                                Err((e, hint)) => {
                                    let mut diag = Diagnostic::error(file, loc, "bad-schema", e);
                                    if let Some(h) = hint {
                                        diag = diag.with_hint(h);
                                    }
                                    d.push(diag);
                                    None
                                }
                            }
                        })
                        .collect(),
                },
            );
        }
        let mut events = Vec::new();
        for e in &spec.events {
            let loc = Loc::from(e.referenced);
            events.push(WorldEvent {
                at: Time::ZERO + dur(file, loc, &e.value.at, &mut d),
                robots: e.value.robots.clone(),
                set: values(file, &e.value.set, &mut d),
                loc,
            });
        }
        events.sort_by_key(|e| e.at);
        let mut crashes = Vec::new();
        for c in &spec.crashes {
            let loc = Loc::from(c.referenced);
            let at = Time::ZERO + dur(file, loc, &c.value.at, &mut d);
            let until = c
                .value
                .until
                .as_ref()
                .map(|u| Time::ZERO + dur(file, loc, u, &mut d));
            if until.is_some_and(|u| u <= at) {
                d.push(Diagnostic::error(
                    file,
                    loc,
                    "bad-value",
                    "a crash must end (`until`) after it starts (`at`)",
                ));
            }
            if c.value.restart && until.is_none() {
                d.push(
                    Diagnostic::error(
                        file,
                        loc,
                        "bad-value",
                        "a restart needs `until`: when the process comes back",
                    )
                    .with_hint("`{ robot: r1, at: 10s, until: 12s, restart: true }`"),
                );
            }
            crashes.push(Crash {
                robot: c.value.robot.clone(),
                at,
                until,
                restart: c.value.restart,
                loc,
            });
        }
        let mut mission_changes = Vec::new();
        let mut last = Time::ZERO;
        for c in &spec.mission_changes {
            let loc = Loc::from(c.referenced);
            let at = Time::ZERO + dur(file, loc, &c.value.at, &mut d);
            if at < last {
                d.push(Diagnostic::error(
                    file,
                    loc,
                    "bad-value",
                    "mission changes are listed in time order (each is the next version)",
                ));
            }
            last = at;
            mission_changes.push(MissionChange {
                at,
                graph: c.value.graph.clone(),
                config: c.value.config.clone(),
                loc,
            });
        }
        let mut clocks = Vec::new();
        for (k, c) in &spec.clocks.0 {
            let loc = Loc::from(k.referenced);
            if !(c.value.rate.is_finite() && c.value.rate > 0.0 && c.value.rate <= 100.0) {
                d.push(Diagnostic::error(
                    file,
                    loc,
                    "bad-value",
                    format!(
                        "clock of `{}`: `rate` is a positive number (1 = true time)",
                        k.value
                    ),
                ));
            }
            let offset = c.value.offset.as_ref().map_or(0.0, |o| {
                let (neg, text) = match o.0.trim().strip_prefix('-') {
                    Some(t) => (true, t.to_string()),
                    None => (false, o.0.clone()),
                };
                let v = dur(file, loc, &DurationText(text), &mut d).as_secs_f64();
                if neg { -v } else { v }
            });
            let robot = match k.value.parse::<u64>() {
                Ok(i) => RobotRef::Index(i),
                Err(_) => RobotRef::Name(k.value.clone()),
            };
            clocks.push((robot, c.value.rate, offset, loc));
        }
        let inject = spec.inject.as_ref().map(|i| {
            dur(file, Loc::from(i.referenced), &i.value.every, &mut d).max(Duration::from_millis(1))
        });
        let failure_detector = match &spec.failure_detector {
            None => Some(FailureDetector::default()),
            Some(f) if !f.value.enabled => None,
            Some(f) => {
                let loc = Loc::from(f.referenced);
                let base = FailureDetector::default();
                let before = d.len();
                let fd = FailureDetector {
                    lost_after: f
                        .value
                        .lost_after
                        .as_ref()
                        .map_or(base.lost_after, |t| dur(file, loc, t, &mut d)),
                    heartbeat: f
                        .value
                        .heartbeat
                        .as_ref()
                        .map_or(base.heartbeat, |t| dur(file, loc, t, &mut d)),
                };
                // A heartbeat of 0 s never lets simulated time pass (the
                // run hung, growing by 450 MB a second); one not shorter
                // than `lost_after` has every robot presumed lost between
                // two of its teammate's heartbeats.
                // (Not again for a duration already reported unreadable.)
                if d.len() > before {
                } else if fd.heartbeat < MIN_HEARTBEAT {
                    d.push(Diagnostic::error(
                        file,
                        loc,
                        "bad-failure-detector",
                        format!(
                            "`heartbeat` must be at least {} ms",
                            MIN_HEARTBEAT.as_millis()
                        ),
                    ));
                } else if fd.lost_after <= fd.heartbeat {
                    d.push(Diagnostic::error(
                        file,
                        loc,
                        "bad-failure-detector",
                        "`lost_after` must be longer than `heartbeat` (a robot is presumed lost \
                         when not heard for `lost_after`)",
                    ));
                }
                Some(fd)
            }
        };
        let mut stall = StallLimits::default();
        if let Some(st) = &spec.stall {
            let loc = Loc::from(st.referenced);
            if let Some(a) = &st.value.after {
                stall.after = if a.0.trim() == "never" {
                    None
                } else {
                    Some(dur(file, loc, a, &mut d))
                };
            }
            if let Some(r) = st.value.repeats {
                stall.repeats = r;
            }
        }
        if d.iter().any(Diagnostic::is_error) {
            return Err(Diagnostics(d));
        }
        Ok(Scenario {
            failure_detector,
            stall,
            clocks,
            inject,
            sensed: spec.sensed,
            physics,
            name: spec.scenario.unwrap_or_else(|| {
                Path::new(&**file)
                    .file_stem()
                    .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned())
            }),
            description: spec.description,
            file: file.clone(),
            seed: spec.seed.unwrap_or(1),
            robots,
            control_hz,
            time_limit,
            network,
            partitions,
            skills,
            events,
            crashes,
            mission_changes,
        })
    }

    /// Resolve robot names against the graph's roster and check what can
    /// only be checked against a graph: robots exist (error), beliefs the
    /// scenario sets are read by some condition and skills the graph uses
    /// are described (warnings).
    pub fn resolve(&self, graph: &BehaviorGraph) -> Result<Resolved, Diagnostics> {
        let roster = graph.roster();
        let mut errors = Vec::new();
        let mut one = |r: &RobotRef, loc: Loc| -> Option<RobotId> {
            let id = match r {
                RobotRef::Index(i) => (*i < roster.len() as u64).then_some(RobotId(*i as u32)),
                RobotRef::Name(n) => roster.find(n),
            };
            if id.is_none() {
                let what = match r {
                    RobotRef::Index(i) => format!("robot {i}"),
                    RobotRef::Name(n) => format!("robot `{n}`"),
                };
                errors.push(Diagnostic::error(
                    &self.file,
                    loc,
                    "unknown-robot",
                    format!("no {what} in the team of {} robots", roster.len()),
                ));
            }
            id
        };
        let mut many = |rs: &[RobotRef], loc: Loc| -> Vec<RobotId> {
            rs.iter().filter_map(|r| one(r, loc)).collect()
        };
        let mut network = self.network.clone();
        for p in &self.partitions {
            let cut = match (&p.groups, &p.one_way) {
                (Some(g), _) => Cut::Groups(g.iter().map(|g| many(g, p.loc)).collect()),
                (None, Some((f, t))) => Cut::OneWay {
                    from: many(f, p.loc),
                    to: many(t, p.loc),
                },
                (None, None) => continue,
            };
            network.partitions.push(Partition {
                from: p.from,
                until: p.until,
                cut,
            });
        }
        let events = self
            .events
            .iter()
            .map(|e| TimedFact {
                at: e.at,
                robots: e.robots.as_ref().map(|r| many(r, e.loc)),
                set: e.set.clone(),
            })
            .collect();
        let mut crashes = Vec::new();
        let mut restarts = Vec::new();
        for c in &self.crashes {
            if let Some(r) = one(&c.robot, c.loc) {
                crashes.push((r, c.at, c.until));
                if c.restart
                    && let Some(u) = c.until
                {
                    restarts.push((r, u));
                }
            }
        }
        let mut clocks = Vec::new();
        for (r, rate, offset, loc) in &self.clocks {
            if let Some(r) = one(r, *loc) {
                if clocks.is_empty() {
                    clocks = vec![(1.0, 0.0); roster.len()];
                }
                clocks[r.index()] = (*rate, *offset);
            }
        }
        if !errors.is_empty() {
            return Err(Diagnostics(errors));
        }
        let mut warnings = Vec::new();
        let symbols = graph.symbols();
        let mut warned = std::collections::BTreeSet::new();
        let set_by_skills = self.skills.values().flat_map(|s| {
            s.rates
                .iter()
                .map(|(n, _)| n)
                .chain(&s.drives)
                .chain(s.on_start.iter().chain(&s.on_done).map(|(n, _)| n))
                .map(|n| (n, Loc::UNKNOWN))
        });
        let set_by_events = self
            .events
            .iter()
            .flat_map(|e| e.set.iter().map(move |(n, _)| (n, e.loc)));
        for (n, loc) in set_by_skills.chain(set_by_events) {
            if symbols.get(n).is_none() && !self.sensed.contains(n) && warned.insert(n.clone()) {
                warnings.push(Diagnostic::warning(
                    &self.file,
                    loc,
                    "unused-belief",
                    format!(
                        "the scenario sets `{n}`, but no condition of graph `{}` reads it",
                        graph.name()
                    ),
                ));
            }
        }
        let mut motor = Vec::new();
        if let Some(ps) = &self.physics {
            let mut bad = Vec::new();
            for b in graph.behaviors() {
                let mut schemas = Vec::new();
                if let Some(sk) = b.skill.as_ref().filter(|_| b.is_atomic())
                    && let Some(model) = self.skills.get(&sk.name)
                {
                    for sc in &model.schemas {
                        match sc.build(&sk.params, ps.robot.max_speed, false) {
                            Ok(w) => schemas.push(w),
                            Err(e) => bad.push(Diagnostic::error(
                                &self.file,
                                sc.loc,
                                "bad-schema",
                                format!("behavior `{}`, skill `{}`: {e}", b.name, sk.name),
                            )),
                        }
                    }
                }
                motor.push(Arc::from(schemas));
            }
            if !bad.is_empty() {
                return Err(Diagnostics(bad));
            }
            for (n, _, loc) in &ps.beliefs {
                if symbols.get(n).is_none() && !self.sensed.contains(n) && warned.insert(n.clone())
                {
                    warnings.push(Diagnostic::warning(
                        &self.file,
                        *loc,
                        "unused-belief",
                        format!(
                            "the scenario computes `{n}`, but no condition of graph `{}` reads it",
                            graph.name()
                        ),
                    ));
                }
            }
        }
        let mut missing = std::collections::BTreeSet::new();
        for b in graph.behaviors() {
            if let Some(s) = &b.skill
                && b.is_atomic()
                && !self.skills.contains_key(&s.name)
                && missing.insert(s.name.clone())
            {
                warnings.push(Diagnostic::warning(
                    &self.file,
                    Loc::UNKNOWN,
                    "unknown-skill",
                    format!(
                        "skill `{}` (behavior `{}`) is not described by the scenario: it runs until a condition ends its behavior",
                        s.name, b.name
                    ),
                ));
            }
        }
        Ok(Resolved {
            network,
            events,
            crashes,
            restarts,
            clocks,
            warnings,
            motor,
        })
    }
}

/// When a run counts as stalled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StallLimits {
    /// No progress for this long (`None`: never).
    pub after: Option<Duration>,
    /// A behavior started more than this many times within one execution
    /// of its parent (`0`: never).
    pub repeats: u32,
}

impl Default for StallLimits {
    fn default() -> Self {
        StallLimits {
            after: Some(Duration::from_secs(120)),
            repeats: 100,
        }
    }
}
