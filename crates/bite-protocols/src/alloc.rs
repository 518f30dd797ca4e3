//! Allocation protocols that gather and decide in one step (SF3, SF6 and
//! the optimal assignment). The market and token protocols, which take
//! several rounds, are in [`crate::auction`] and [`crate::token`].
//!
//! How many members each child gets is the same everywhere: every child
//! first gets its minimum, in graph order, while members last; the rest is
//! shared as evenly as the children's maximums allow
//! ([`bite_core::rules::member_counts`]). The protocols differ in *which*
//! members go where:
//!
//! - `alloc.by-value` (SF3): each member sends a number read from its
//!   beliefs — parameter `value`, an expression such as `head_angle` or
//!   `dist(pos, goal)` — and the leader deals the members, sorted by value
//!   (`order: ascending`, the default, or `descending`; ties and unknown
//!   values by id, unknown last), to the children in graph order.
//! - `alloc.by-attribute` (SF6): roles ask for an attribute — parameter
//!   `attribute` (e.g. `colour`) and `wants`, a map from child to the value
//!   it asks for — and each member sends its own: the belief of that name
//!   if it has one (a capability can change), else its roster attribute.
//!   The leader first gives each child members that match what it wants,
//!   in id order, then fills the places still open with anyone (a role is
//!   better taken by a robot of the wrong colour than left empty).
//! - `alloc.optimal`: each member sends its `utility` for every child
//!   enabled for it (the child's `utility` expression; 0 without one), and
//!   the leader solves the assignment of members to the children's places
//!   exactly (Jonker-Volgenant, [`crate::lap`]), maximizing total utility.
//!   A child not enabled for a member is taken by it only if nothing else
//!   is possible.
//!
//! All three: n messages per decision (n − 1 contributions and the
//! assignment), 2 rounds; robustness as in [`crate::gather`].

use crate::gather::Rule;
use crate::lap;
use crate::sync::{gather_protocol, no_params};
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{Assignment, ChildSlot, ConfigError, Cx, Outcome, parse_params};
use bite_core::msg::{Body, Kind};
use bite_core::org::MemberSet;
use bite_core::rules::{assign_in_order, member_counts};
use bite_core::value::Value;
use serde::Deserialize;
use std::collections::{BTreeMap, BTreeSet};

/// The live members of the instance, in id order.
fn live(cx: &Cx<'_>) -> Vec<RobotId> {
    cx.members().collect()
}

/// An assignment from `(member, child index)` pairs.
pub(crate) fn assignment_of(
    cx: &Cx<'_>,
    children: &[ChildSlot],
    pairs: impl IntoIterator<Item = (RobotId, usize)>,
) -> Assignment {
    let n = cx.team().members.roster_len();
    let mut sets: Vec<(BehaviorId, MemberSet)> = children
        .iter()
        .map(|c| (c.behavior, MemberSet::empty(n)))
        .collect();
    for (r, i) in pairs {
        if let Some((_, s)) = sets.get_mut(i) {
            s.insert(r);
        }
    }
    Assignment(sets)
}

/// The final allocation of a protocol that awards places one at a time
/// (auction, token), after members may have been lost: `awards` (member,
/// child index), in the order they were made, are kept while they are live
/// and their child has room for the live team's size; the places still
/// open go to the live members without one, in id order, children in graph
/// order. So the result has the shape every allocation has — minimums
/// first, no child empty while another has more than its minimum.
pub(crate) fn settle(
    cx: &Cx<'_>,
    children: &[ChildSlot],
    awards: impl IntoIterator<Item = (RobotId, usize)>,
) -> Assignment {
    let members = live(cx);
    let mut open = member_counts(members.len(), children);
    let mut pairs: Vec<(RobotId, usize)> = Vec::new();
    let mut placed = BTreeSet::new();
    for (r, i) in awards {
        if cx.is_live(r) && open.get(i).is_some_and(|n| *n > 0) && !placed.contains(&r) {
            open[i] -= 1;
            pairs.push((r, i));
            placed.insert(r);
        }
    }
    let mut free = members.into_iter().filter(|m| !placed.contains(m));
    let mut fill = Vec::new();
    for (i, left) in open.iter().enumerate() {
        for _ in 0..*left {
            if let Some(r) = free.next() {
                fill.push((r, i));
            }
        }
    }
    pairs.extend(fill);
    assignment_of(cx, children, pairs)
}

// ----- alloc.by-value ------------------------------------------------------

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum Order {
    #[default]
    Ascending,
    Descending,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ByValueParams {
    value: Option<String>,
    #[serde(default)]
    order: Order,
}

gather_protocol!(
    ByValue,
    "alloc.by-value",
    &["SF3"],
    Kind::Allocate,
    "SF3: members send a value read from their beliefs (e.g. head angle); sorted, they are dealt to the children.",
    |params, setup| {
        let p = parse_params::<ByValueParams>("alloc.by-value", params)?;
        let src = p.value.ok_or_else(|| ConfigError::Missing {
            protocol: "alloc.by-value".into(),
            param: "value".into(),
            what: "the number each member sends, e.g. `value: head_angle`".into(),
        })?;
        setup.expr(&src, Some("number")).map(|value| Sorted {
            value,
            order: p.order,
        })
    }
);

pub(crate) struct Sorted {
    value: bite_core::cond::Expr,
    order: Order,
}

impl Rule for Sorted {
    fn name(&self) -> &'static str {
        "alloc.by-value"
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        let value = cx
            .eval(&self.value)
            .and_then(|v| v.as_num())
            .filter(|x| x.is_finite())
            .unwrap_or(f64::NAN);
        Body::Value { about: None, value }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Value { .. })
    }
    fn check(&self, _: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        match body {
            Body::Value { about: None, .. } => Ok(()),
            _ => Err("sent a value about a behavior".into()),
        }
    }
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        let value = |r: RobotId| match got.get(&r) {
            Some(Body::Value { value, .. }) => Some(*value),
            _ => None,
        };
        deal_by_value(cx, value, self.order == Order::Descending)
    }
}

/// SF3's deal: the live members sorted by the value they sent (ascending,
/// or `descending`; unknown and non-finite values last, ties by id) are
/// dealt to the children in graph order. `alloc.by-value` and the
/// graph-defined market deal with it.
pub(crate) fn deal_by_value(
    cx: &Cx<'_>,
    value: impl Fn(RobotId) -> Option<f64>,
    descending: bool,
) -> Outcome {
    let mut members: Vec<(Option<f64>, RobotId)> = live(cx)
        .into_iter()
        .map(|r| (value(r).filter(|v| v.is_finite()), r))
        .collect();
    members.sort_by(|(a, ra), (b, rb)| {
        let by_value = match (a, b) {
            (Some(x), Some(y)) if descending => y.total_cmp(x),
            (Some(x), Some(y)) => x.total_cmp(y),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => std::cmp::Ordering::Equal,
        };
        by_value.then(ra.cmp(rb))
    });
    let roster = cx.team().members.roster_len();
    Outcome::Allocate(
        assign_in_order(roster, members.into_iter().map(|(_, r)| r), cx.children()).into(),
    )
}

// ----- alloc.by-attribute --------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ByAttributeParams {
    attribute: Option<String>,
    #[serde(default)]
    wants: BTreeMap<String, serde_json::Value>,
}

gather_protocol!(
    ByAttribute,
    "alloc.by-attribute",
    &["SF6"],
    Kind::Allocate,
    "SF6: roles ask for an attribute (e.g. colour); members announce theirs; matching members first.",
    |params, setup| {
        let p = parse_params::<ByAttributeParams>("alloc.by-attribute", params)?;
        let attribute = p.attribute.ok_or_else(|| ConfigError::Missing {
            protocol: "alloc.by-attribute".into(),
            param: "attribute".into(),
            what: "the attribute roles ask for, e.g. `attribute: colour`".into(),
        })?;
        let mut wants = BTreeMap::new();
        for (child, v) in &p.wants {
            let b = setup.child(child)?;
            let text = match v {
                serde_json::Value::String(s) => s.clone(),
                serde_json::Value::Bool(_) | serde_json::Value::Number(_) => v.to_string(),
                _ => {
                    return Err(ConfigError::Invalid(format!(
                        "`wants.{child}` must be a text, number or bool"
                    )));
                }
            };
            wants.insert(b, text);
        }
        Ok::<_, ConfigError>(Matching { attribute, wants })
    }
);

pub(crate) struct Matching {
    attribute: String,
    wants: BTreeMap<BehaviorId, String>,
}

fn text_of(v: &Value) -> String {
    match v {
        Value::Text(t) => t.to_string(),
        other => other.to_string(),
    }
}

impl Rule for Matching {
    fn name(&self) -> &'static str {
        "alloc.by-attribute"
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        let value = cx
            .beliefs()
            .get_named(&self.attribute)
            .map(|b| text_of(&b.value))
            .or_else(|| {
                cx.roster()
                    .get(cx.me())
                    .and_then(|i| i.attributes.get(&self.attribute))
                    .map(text_of)
            })
            .unwrap_or_default();
        Body::Attribute {
            name: self.attribute.clone(),
            value,
        }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Attribute { .. })
    }
    fn check(&self, _: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        match body {
            Body::Attribute { name, .. } if *name == self.attribute => Ok(()),
            Body::Attribute { name, .. } => Err(format!(
                "announced `{name}`, but this point asks for `{}`",
                self.attribute
            )),
            _ => Err("sent something else than an attribute".into()),
        }
    }
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        let members = live(cx);
        let children = cx.children().to_vec();
        let counts = member_counts(members.len(), &children);
        let attr = |r: &RobotId| match got.get(r) {
            Some(Body::Attribute { value, .. }) => Some(value.as_str()),
            _ => None,
        };
        let mut open: Vec<u32> = counts.clone();
        let mut taken: BTreeMap<RobotId, usize> = BTreeMap::new();
        // Matching members first, child by child in graph order.
        for (i, c) in children.iter().enumerate() {
            let Some(want) = self.wants.get(&c.behavior) else {
                continue;
            };
            for r in &members {
                if open[i] == 0 {
                    break;
                }
                if !taken.contains_key(r) && attr(r) == Some(want.as_str()) {
                    taken.insert(*r, i);
                    open[i] -= 1;
                }
            }
        }
        // Then anyone for the places left, members in id order.
        let mut rest = members.iter().filter(|r| !taken.contains_key(r));
        let mut fill = Vec::new();
        for (i, left) in open.iter().enumerate() {
            for _ in 0..*left {
                if let Some(r) = rest.next() {
                    fill.push((*r, i));
                }
            }
        }
        taken.extend(fill);
        Outcome::Allocate(assignment_of(cx, &children, taken).into())
    }
}

// ----- alloc.optimal -------------------------------------------------------

gather_protocol!(
    Optimal,
    "alloc.optimal",
    &[],
    Kind::Allocate,
    "The leader gathers every member's utilities and solves the assignment exactly (Jonker-Volgenant).",
    |params, setup| no_params("alloc.optimal", params).map(|()| Exact)
);

pub(crate) struct Exact;

/// This robot's utility for each child enabled for it (0 without a
/// `utility` expression).
pub(crate) fn utilities(cx: &Cx<'_>) -> Vec<(BehaviorId, f64)> {
    cx.children()
        .iter()
        .map(|c| (c.behavior, cx.utility(c.behavior).unwrap_or(0.0)))
        .collect()
}

impl Rule for Exact {
    fn name(&self) -> &'static str {
        "alloc.optimal"
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        Body::Costs {
            values: utilities(cx),
        }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Costs { .. })
    }
    fn check(&self, _: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        match body {
            Body::Costs { values } if values.iter().all(|(_, v)| v.is_finite()) => Ok(()),
            Body::Costs { .. } => Err("sent a utility that is not a number".into()),
            _ => Err("sent something else than utilities".into()),
        }
    }
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        let members = live(cx);
        let children = cx.children().to_vec();
        let counts = member_counts(members.len(), &children);
        // One column per place.
        let cols: Vec<usize> = counts
            .iter()
            .enumerate()
            .flat_map(|(i, n)| std::iter::repeat_n(i, *n as usize))
            .collect();
        let mut cost = vec![0.0; members.len() * cols.len()];
        for (row, r) in members.iter().enumerate() {
            let values: BTreeMap<BehaviorId, f64> = match got.get(r) {
                Some(Body::Costs { values }) => {
                    let mut m = BTreeMap::new();
                    for (c, u) in values {
                        m.entry(*c).or_insert(*u); // the first one counts
                    }
                    m
                }
                // Not heard from: indifferent.
                _ => BTreeMap::new(),
            };
            for (k, i) in cols.iter().enumerate() {
                let b = children[*i].behavior;
                cost[row * cols.len() + k] = if !got.contains_key(r) {
                    0.0
                } else {
                    // Maximize utility; a child the member cannot take
                    // only as a last resort.
                    values.get(&b).map_or(f64::INFINITY, |u| -u)
                };
            }
        }
        let sol = lap::solve(members.len(), cols.len(), &cost);
        let pairs = members
            .iter()
            .zip(&sol.row_to_col)
            .filter_map(|(r, k)| k.map(|k| (*r, cols[k])));
        Outcome::Allocate(assignment_of(cx, &children, pairs).into())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn params_are_typed() {
        use super::*;
        let e: Result<ByValueParams, _> = parse_params(
            "alloc.by-value",
            &serde_json::json!({"value": "x", "sort": 1}),
        );
        let e = e.unwrap_err();
        assert!(
            matches!(&e, ConfigError::BadParams { protocol, detail }
                if protocol == "alloc.by-value" && detail.contains("unknown field `sort`")),
            "{e}"
        );
        let o: Result<ByValueParams, _> = parse_params(
            "alloc.by-value",
            &serde_json::json!({"value": "x", "order": "sideways"}),
        );
        assert!(o.unwrap_err().to_string().contains("ascending"));
    }
}
