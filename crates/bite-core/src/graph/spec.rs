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
    pub sharing: Option<Spanned<String>>,
    /// Decisions per second.
    pub hz: Option<Spanned<f64>>,
    /// Messages per second per robot (one per recipient).
    pub budget: Option<Spanned<f64>>,
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
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
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
    /// Precondition. (The conditions and the skill are boxed as the
    /// bindings are: a text with its locations is 80 bytes, most behaviors
    /// have one condition or none, and a large graph's specs are all made
    /// before it is built.)
    pub pre: Option<Box<Spanned<String>>>,
    /// Termination condition.
    pub until: Option<Box<Spanned<String>>>,
    /// Emergency termination condition: ends the behavior on this robot at
    /// once, without waiting for its termination protocol.
    pub urgent: Option<Box<Spanned<String>>>,
    /// Preference used by deciding protocols (a number; higher is better).
    pub utility: Option<Box<Spanned<String>>>,
    /// Skill of an atomic behavior.
    pub skill: Option<Box<Spanned<SkillSpec>>>,
    /// How many members it takes when allocated (`1`, `2..4`, `2..`).
    pub members: Option<Spanned<MembersSpec>>,
    /// A child of an allocation point that is given its minimum before
    /// the children that are not, when the team is too small for every
    /// minimum (`critical: true`).
    pub critical: Option<Spanned<bool>>,
    /// Binding of its synchronization point (boxed, as the other two: a
    /// binding with its locations is ~400 bytes, and most behaviors have
    /// none; a graph of 100,000 behaviors holds all their specs at once).
    pub sync: Option<Box<Spanned<BindingSpec>>>,
    /// Binding of its allocation point.
    pub allocate: Option<Box<Spanned<BindingSpec>>>,
    /// Binding of its termination point.
    pub terminate: Option<Box<Spanned<BindingSpec>>>,
}

/// `skill: name` or `skill: {name, params}`.
#[derive(Clone, Debug, PartialEq)]
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
#[derive(Clone, Debug, Default, PartialEq)]
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

/// Graph specs from the fast YAML subset ([`crate::yaml::fast`]): the
/// common keys and plain values only; `None` for anything else, and the
/// caller parses the text with the YAML library instead.
pub(crate) mod fast {
    use super::{
        BehaviorSpec, BindingSpec, DefaultsSpec, GraphSpec, MembersSpec, Ordered, RobotsSpec,
        SkillSpec, TeamSpec,
    };
    use crate::yaml::fast::{Node, Scalar, location};
    use serde_saphyr::Spanned;
    use std::collections::BTreeMap;

    fn at<T>(value: T, (line, col): (u32, u32)) -> Spanned<T> {
        let l = location(line, col);
        Spanned::new(value, l, l)
    }

    fn scalar<'n, 'a>(n: &'n Node<'a>) -> Option<&'n Scalar<'a>> {
        match n {
            Node::Scalar(s) => Some(s),
            _ => None,
        }
    }

    /// Text, where the YAML library would read text: quoted, or plain and
    /// neither a number nor a word it might read as something else.
    fn text(n: &Node<'_>) -> Option<String> {
        let s = scalar(n)?;
        if s.quoted {
            return Some(s.text.to_string());
        }
        let t: &str = &s.text;
        let first = t.bytes().next()?;
        if !(first.is_ascii_alphabetic() || first == b'_') {
            return None;
        }
        if t.len() <= 5
            && matches!(
                t.to_ascii_lowercase().as_str(),
                "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "y" | "n"
            )
        {
            return None;
        }
        Some(t.to_string())
    }

    fn spanned_text(n: &Node<'_>) -> Option<Spanned<String>> {
        Some(at(text(n)?, n.loc()))
    }

    /// A plain decimal count (no sign, no leading zero).
    fn count(n: &Node<'_>) -> Option<u64> {
        let s = scalar(n)?;
        let t: &str = &s.text;
        if s.quoted || t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        if t.len() > 1 && t.starts_with('0') {
            return None;
        }
        t.parse().ok()
    }

    fn names(n: &Node<'_>) -> Option<Vec<Spanned<String>>> {
        match n {
            Node::Seq(items, ..) => items.iter().map(spanned_text).collect(),
            _ => None,
        }
    }

    fn binding(n: &Node<'_>) -> Option<Spanned<BindingSpec>> {
        let protocol = text(n)?;
        Some(at(
            BindingSpec {
                protocol: Some(protocol),
                ..BindingSpec::default()
            },
            n.loc(),
        ))
    }

    fn entries<'n, 'a>(n: &'n Node<'a>) -> Option<&'n [(Scalar<'a>, Node<'a>)]> {
        match n {
            Node::Map(e, ..) => Some(e),
            _ => None,
        }
    }

    fn behavior(n: &Node<'_>) -> Option<BehaviorSpec> {
        let mut b = BehaviorSpec::default();
        for (k, v) in entries(n)? {
            match k.text.as_ref() {
                "description" => b.description = Some(text(v)?),
                "team" => {
                    let s = scalar(v)?;
                    b.team = match (s.quoted, s.text.as_ref()) {
                        (false, "true") => true,
                        (false, "false") => false,
                        _ => return None,
                    };
                }
                "children" => b.children = names(v)?,
                "next" => b.next = names(v)?,
                "pre" => b.pre = Some(Box::new(spanned_text(v)?)),
                "until" => b.until = Some(Box::new(spanned_text(v)?)),
                "urgent" => b.urgent = Some(Box::new(spanned_text(v)?)),
                "utility" => b.utility = Some(Box::new(spanned_text(v)?)),
                "skill" => {
                    let name = text(v)?;
                    let params = BTreeMap::new();
                    b.skill = Some(Box::new(at(SkillSpec { name, params }, v.loc())));
                }
                "members" => {
                    let s = scalar(v)?;
                    let m = if s.quoted {
                        MembersSpec::parse(&s.text).ok()?
                    } else {
                        let n = u32::try_from(count(v)?).ok()?;
                        MembersSpec::parse(&n.to_string()).ok()?
                    };
                    b.members = Some(at(m, v.loc()));
                }
                "critical" => {
                    let s = scalar(v)?;
                    let c = match (s.quoted, s.text.as_ref()) {
                        (false, "true") => true,
                        (false, "false") => false,
                        _ => return None,
                    };
                    b.critical = Some(at(c, v.loc()));
                }
                "sync" => b.sync = Some(Box::new(binding(v)?)),
                "allocate" => b.allocate = Some(Box::new(binding(v)?)),
                "terminate" => b.terminate = Some(Box::new(binding(v)?)),
                _ => return None,
            }
        }
        Some(b)
    }

    /// The graph spec of a fast-parsed file, or `None`.
    pub(crate) fn graph(root: &Node<'_>) -> Option<GraphSpec> {
        let mut g = GraphSpec {
            graph: None,
            description: None,
            team: None,
            start: None,
            defaults: DefaultsSpec::default(),
            beliefs: Ordered::default(),
            world_model: None,
            behaviors: None,
        };
        for (k, v) in entries(root)? {
            match k.text.as_ref() {
                "graph" => g.graph = Some(text(v)?),
                "description" => g.description = Some(text(v)?),
                "start" => g.start = Some(spanned_text(v)?),
                "team" => {
                    let [(rk, rv)] = entries(v)? else {
                        return None;
                    };
                    if rk.text != "robots" {
                        return None;
                    }
                    g.team = Some(TeamSpec {
                        robots: at(RobotsSpec::Count(count(rv)?), rv.loc()),
                    });
                }
                "defaults" => {
                    for (dk, dv) in entries(v)? {
                        let b = Some(binding(dv)?);
                        match dk.text.as_ref() {
                            "sync" => g.defaults.sync = b,
                            "allocate" => g.defaults.allocate = b,
                            "terminate" => g.defaults.terminate = b,
                            _ => return None,
                        }
                    }
                }
                "behaviors" => {
                    let list = entries(v)?;
                    let mut out = Vec::with_capacity(list.len());
                    for (name, body) in list {
                        let key = Node::Scalar(Scalar {
                            text: name.text.clone(),
                            quoted: false,
                            line: name.line,
                            col: name.col,
                        });
                        // A name the library might read as a number or a
                        // boolean is left to it.
                        let key = spanned_text(&key)?;
                        out.push((key, at(behavior(body)?, body.loc())));
                    }
                    g.behaviors = Some(at(Ordered(out), v.loc()));
                }
                _ => return None,
            }
        }
        Some(g)
    }
}
