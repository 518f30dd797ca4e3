//! The YAML shape of behavior-graph and configuration files, as parsed,
//! before validation. Every name keeps its location so that validation
//! errors can point at it.

pub use crate::yaml::{DurationText, Ordered};
use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_saphyr::Spanned;
use std::collections::BTreeMap;
use std::fmt;

/// A behavior graph file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphSpec {
    /// Name of the graph.
    pub graph: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// The team.
    pub team: Option<TeamSpec>,
    /// The behavior execution begins with (b0).
    pub start: Option<Spanned<String>>,
    /// Graph-wide protocol bindings per kind.
    #[serde(default)]
    pub defaults: DefaultsSpec,
    /// Beliefs every robot starts with.
    #[serde(default)]
    pub beliefs: Ordered<serde_json::Value>,
    /// Collaborative world modelling: what the robots tell each other.
    pub world_model: Option<Spanned<WorldModelSpec>>,
    /// The behaviors, by name.
    pub behaviors: Option<Spanned<Ordered<BehaviorSpec>>>,
}

/// `world_model: { sharing: focused+helpful, hz: 10, budget: 20 }`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldModelSpec {
    /// `none`, `broadcast`, `focused`, `helpful` or `focused+helpful`.
    pub sharing: Option<String>,
    /// Decisions per second.
    pub hz: Option<f64>,
    /// Messages per second per robot (one per recipient).
    pub budget: Option<f64>,
}

/// The `team:` section.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TeamSpec {
    /// A count, or a list of robots.
    pub robots: Spanned<RobotsSpec>,
}

/// `robots: 3` or `robots: [{name, attributes}]`.
#[derive(Debug)]
pub enum RobotsSpec {
    /// Anonymous robots `r0..`.
    Count(u64),
    /// Named robots.
    List(Vec<Spanned<RobotSpec>>),
}

impl<'de> Deserialize<'de> for RobotsSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RobotsSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number of robots, or a list of robots with `name` and `attributes`")
            }
            fn visit_u64<E: de::Error>(self, n: u64) -> Result<RobotsSpec, E> {
                Ok(RobotsSpec::Count(n))
            }
            fn visit_i64<E: de::Error>(self, n: i64) -> Result<RobotsSpec, E> {
                u64::try_from(n)
                    .map(RobotsSpec::Count)
                    .map_err(|_| E::custom("the number of robots cannot be negative"))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<RobotsSpec, A::Error> {
                let mut v = Vec::new();
                while let Some(r) = s.next_element()? {
                    v.push(r);
                }
                Ok(RobotsSpec::List(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// One named robot.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Unique name.
    pub name: String,
    /// Static attributes.
    #[serde(default)]
    pub attributes: BTreeMap<String, serde_json::Value>,
}

/// `defaults:` — one binding per kind.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DefaultsSpec {
    /// Default synchronization protocol.
    pub sync: Option<Spanned<BindingSpec>>,
    /// Default allocation protocol.
    pub allocate: Option<Spanned<BindingSpec>>,
    /// Default termination protocol.
    pub terminate: Option<Spanned<BindingSpec>>,
}

/// One behavior.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BehaviorSpec {
    /// Free text.
    pub description: Option<String>,
    /// Team behavior: selection, allocation and termination coordinated.
    #[serde(default)]
    pub team: bool,
    /// Decomposition edges (heads of execution chains).
    #[serde(default)]
    pub children: Vec<Spanned<String>>,
    /// Sequential edges.
    #[serde(default)]
    pub next: Vec<Spanned<String>>,
    /// Precondition.
    pub pre: Option<Spanned<String>>,
    /// Termination condition.
    pub until: Option<Spanned<String>>,
    /// Emergency termination condition: ends the behavior on this robot at
    /// once, without waiting for its termination protocol.
    pub urgent: Option<Spanned<String>>,
    /// Preference used by deciding protocols (a number; higher is better).
    pub utility: Option<Spanned<String>>,
    /// Skill of an atomic behavior.
    pub skill: Option<Spanned<SkillSpec>>,
    /// How many members it takes when allocated (`1`, `2..4`, `2..`).
    pub members: Option<Spanned<MembersSpec>>,
    /// Binding of its synchronization point.
    pub sync: Option<Spanned<BindingSpec>>,
    /// Binding of its allocation point.
    pub allocate: Option<Spanned<BindingSpec>>,
    /// Binding of its termination point.
    pub terminate: Option<Spanned<BindingSpec>>,
}

/// `skill: name` or `skill: {name, params}`.
#[derive(Debug)]
pub struct SkillSpec {
    /// Skill name.
    pub name: String,
    /// Parameters.
    pub params: BTreeMap<String, serde_json::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SkillMap {
    name: String,
    #[serde(default)]
    params: BTreeMap<String, serde_json::Value>,
}

impl<'de> Deserialize<'de> for SkillSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = SkillSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a skill name, or a mapping with `name` and `params`")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<SkillSpec, E> {
                Ok(SkillSpec {
                    name: s.to_string(),
                    params: BTreeMap::new(),
                })
            }
            fn visit_map<A: MapAccess<'de>>(self, m: A) -> Result<SkillSpec, A::Error> {
                let s = SkillMap::deserialize(de::value::MapAccessDeserializer::new(m))?;
                Ok(SkillSpec {
                    name: s.name,
                    params: s.params,
                })
            }
        }
        d.deserialize_any(V)
    }
}

/// `members: 1`, `members: "2..4"`, `members: "2.."`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MembersSpec {
    /// Fewest members.
    pub min: u32,
    /// Most members (`u32::MAX`: unbounded).
    pub max: u32,
}

impl MembersSpec {
    fn parse(s: &str) -> Result<MembersSpec, String> {
        let t = s.trim();
        let num = |x: &str| -> Result<u32, String> {
            x.trim().parse::<u32>().map_err(|_| {
                format!("expected a member count such as `1`, `2..4` or `2..`, found `{s}`")
            })
        };
        let (min, max) = match t.split_once("..") {
            Some((a, b)) => (
                num(a)?,
                if b.trim().is_empty() {
                    u32::MAX
                } else {
                    num(b.trim_start_matches('='))?
                },
            ),
            None => {
                let n = num(t)?;
                (n, n)
            }
        };
        if min == 0 {
            return Err("a child needs at least one member (`members` minimum is 1)".into());
        }
        if max < min {
            return Err(format!("`members: {s}` has a maximum below its minimum"));
        }
        Ok(MembersSpec { min, max })
    }
}

impl<'de> Deserialize<'de> for MembersSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = MembersSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a member count such as `1`, `2..4` or `2..`")
            }
            fn visit_u64<E: de::Error>(self, n: u64) -> Result<MembersSpec, E> {
                let n = u32::try_from(n).map_err(|_| E::custom("member count too large"))?;
                MembersSpec::parse(&n.to_string()).map_err(E::custom)
            }
            fn visit_i64<E: de::Error>(self, n: i64) -> Result<MembersSpec, E> {
                u64::try_from(n)
                    .map_err(|_| E::custom("member count cannot be negative"))
                    .and_then(|n| self.visit_u64(n))
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<MembersSpec, E> {
                MembersSpec::parse(s).map_err(E::custom)
            }
        }
        d.deserialize_any(V)
    }
}

/// `sync.vote` or `{protocol, point, deadline, retry, params}`.
#[derive(Debug, Default)]
pub struct BindingSpec {
    /// Protocol name (or alias); `None` keeps the default.
    pub protocol: Option<String>,
    /// Point label (`A`), used by configuration files.
    pub point: Option<Spanned<String>>,
    /// Deadline of each instance (`5s`).
    pub deadline: Option<Spanned<DurationText>>,
    /// Retransmission interval (`500ms`).
    pub retry: Option<Spanned<DurationText>>,
    /// Protocol parameters.
    pub params: serde_json::Value,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BindingMap {
    protocol: Option<String>,
    point: Option<Spanned<String>>,
    deadline: Option<Spanned<DurationText>>,
    retry: Option<Spanned<DurationText>>,
    #[serde(default)]
    params: serde_json::Value,
}

impl<'de> Deserialize<'de> for BindingSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = BindingSpec;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a protocol name such as `sync.vote`, or a mapping with `protocol`, `point`, `deadline`, `retry`, `params`",
                )
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<BindingSpec, E> {
                Ok(BindingSpec {
                    protocol: Some(s.to_string()),
                    ..BindingSpec::default()
                })
            }
            fn visit_map<A: MapAccess<'de>>(self, m: A) -> Result<BindingSpec, A::Error> {
                let b = BindingMap::deserialize(de::value::MapAccessDeserializer::new(m))?;
                Ok(BindingSpec {
                    protocol: b.protocol,
                    point: b.point,
                    deadline: b.deadline,
                    retry: b.retry,
                    params: b.params,
                })
            }
        }
        d.deserialize_any(V)
    }
}

/// A configuration file: protocol bindings per named point.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConfigSpec {
    /// Name of the configuration.
    pub config: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// Overrides of the graph-wide defaults.
    #[serde(default)]
    pub defaults: DefaultsSpec,
    /// Point name (label such as `A`, or `behavior.kind`) → binding.
    #[serde(default)]
    pub bindings: Ordered<BindingSpec>,
    /// Overrides of the graph's world-model settings.
    pub world_model: Option<Spanned<WorldModelSpec>>,
}
