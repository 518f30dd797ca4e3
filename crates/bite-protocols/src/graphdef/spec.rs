//! The YAML shape of a protocol file (see `docs/protocols.md`, "Writing a
//! protocol as a graph"). Locations are kept for diagnostics.

use bite_core::yaml::{DurationText, Ordered};
use serde::Deserialize;
use serde_saphyr::Spanned;

/// A whole protocol file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FileSpec {
    /// The name it is bound by (`graph.vote`).
    pub protocol: Spanned<String>,
    /// `sync`, `allocate` or `terminate`.
    pub kind: Spanned<String>,
    /// One line for `bite protocols`.
    pub summary: Option<String>,
    /// The built-in protocol it mirrors, if any (documentation, tests).
    pub twin: Option<Spanned<String>>,
    /// Deadline used when a binding does not give one.
    pub deadline: Option<Spanned<DurationText>>,
    /// Parameters a binding gives (expressions over the robot's beliefs).
    #[serde(default)]
    pub params: Ordered<ParamSpec>,
    /// The messages the protocol speaks, with what each carries.
    pub messages: Spanned<Ordered<MessageSpec>>,
    /// The message that carries the decision.
    pub announce: Option<Spanned<String>>,
    /// Where the leader and the members start.
    pub start: Spanned<RolesSpec>,
    /// Where each role goes when the deadline passes.
    pub on_deadline: Option<Spanned<RolesSpec>>,
    /// Where each role goes when the robot leaves the instance early.
    pub on_abort: Option<Spanned<RolesSpec>>,
    /// The protocol's own behaviors, in order.
    pub behaviors: Spanned<Ordered<BehaviorSpec>>,
}

/// A parameter.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ParamSpec {
    /// The expression used when the binding gives none (`None`: required).
    pub default: Option<String>,
    /// What it is, for the error when it is missing.
    pub help: Option<String>,
}

/// A message: what it carries and whether it says its sender is done.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MessageSpec {
    /// `none`, `choice`, `ranking`, `number` or `decision`.
    pub carries: Spanned<String>,
    /// Termination: the sender is done with the behavior.
    #[serde(default)]
    pub departs: bool,
}

/// A behavior per role.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RolesSpec {
    /// The leader's (the lowest-id live member).
    pub leader: Option<Spanned<String>>,
    /// Every other member's.
    pub member: Option<Spanned<String>>,
}

/// One behavior of the protocol graph.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct BehaviorSpec {
    /// Free text.
    pub description: Option<String>,
    /// Precondition: a successor is taken only if it holds.
    pub pre: Option<Spanned<String>>,
    /// Skills run, in order, when the behavior starts.
    #[serde(default, rename = "do")]
    pub skills: Vec<Spanned<SkillSpec>>,
    /// Termination condition (none: the behavior ends once its skills ran).
    pub until: Option<Spanned<String>>,
    /// Sequential edges: the first successor whose precondition holds.
    #[serde(default)]
    pub next: Vec<Spanned<String>>,
}

/// One skill. Exactly one of `send`, `keep`, `decide` and `use`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SkillSpec {
    /// Send this message.
    pub send: Option<Spanned<String>>,
    /// Count this robot's own message as received.
    pub keep: Option<Spanned<String>>,
    /// Who a sent message goes to: `leader`, `team`, `missing <message>`.
    pub to: Option<Spanned<String>>,
    /// What it carries.
    pub value: Option<Spanned<String>>,
    /// Take the decision by this rule.
    pub decide: Option<Spanned<String>>,
    /// The message the rule counts.
    pub from: Option<Spanned<String>>,
    /// `sorted`: `ascending` or `descending`.
    pub order: Option<Spanned<String>>,
    /// Run this protocol (nested) to decide.
    #[serde(rename = "use")]
    pub use_: Option<Spanned<String>>,
    /// Parameters of the nested protocol.
    pub params: Option<bite_core::graph::Params>,
}
