//! The silent rules: protocols that decide without a single message, from
//! information every member shares (the graph, the roster, the team).
//!
//! They are built into the kernel because they are also its fallbacks: when
//! a communicating protocol misses its deadline without deciding, the kernel
//! applies the rule of the same kind.

use crate::ids::RobotId;
use crate::interaction::{
    Assignment, ChildSlot, Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol,
};
use crate::msg::{Body, Kind};
use crate::org::MemberSet;
use std::sync::Arc;

/// How many members each child gets when `n` members are dealt to
/// `children` (graph order): every child first gets its minimum, in child
/// order, while members last; the rest are shared as evenly as the
/// children's maximums allow, earlier children taking the remainder.
pub fn member_counts(n: usize, children: &[ChildSlot]) -> Vec<u32> {
    let mut counts = vec![0u32; children.len()];
    let mut left = n as u64;
    for (i, c) in children.iter().enumerate() {
        let want = u64::from(c.min.max(1).min(c.max));
        let take = want.min(left);
        counts[i] = take as u32;
        left -= take;
    }
    while left > 0 {
        let open = children
            .iter()
            .zip(&counts)
            .filter(|(c, n)| **n < c.max)
            .count() as u64;
        if open == 0 {
            break;
        }
        let share = (left / open).max(1);
        for (c, n) in children.iter().zip(counts.iter_mut()) {
            if left == 0 {
                break;
            }
            let add = share.min(u64::from(c.max - *n)).min(left);
            *n += add as u32;
            left -= add;
        }
    }
    counts
}

/// Assign `members` (in the order given: preference order) to `children`
/// (graph order): the first child takes the first `counts[0]` members, the
/// next child the next `counts[1]`, and so on, with [`member_counts`].
/// Members left over get no child.
///
/// With members sorted by id this is the paper's SF2 ("assign based on
/// ID"); protocols that first sort the members by something else (a value,
/// a bid) use it for their assignment step.
pub fn assign_in_order(
    roster_len: usize,
    members: impl IntoIterator<Item = RobotId>,
    children: &[ChildSlot],
) -> Assignment {
    let members: Vec<RobotId> = members.into_iter().collect();
    let counts = member_counts(members.len(), children);
    let mut it = members.into_iter();
    Assignment(
        children
            .iter()
            .zip(&counts)
            .map(|(c, n)| {
                (
                    c.behavior,
                    MemberSet::from_iter(roster_len, it.by_ref().take(*n as usize)),
                )
            })
            .collect(),
    )
}

/// [`assign_in_order`] with the members in id order, a machine word at a
/// time (a 10,000-robot team splits in microseconds).
pub fn assign_by_id(members: &MemberSet, children: &[ChildSlot]) -> Assignment {
    let counts = member_counts(members.len(), children);
    let mut out = Vec::with_capacity(children.len());
    for (c, m) in children.iter().zip(members.split_by_rank(&counts)) {
        out.push((c.behavior, m));
    }
    Assignment(out)
}

/// The outcome the kernel applies when an instance of `kind` cannot decide:
/// the first candidate, the allocation by id, or local termination.
pub fn fallback(cx: &Cx<'_>) -> Outcome {
    match cx.input() {
        PointInput::Sync { candidates, .. } => Outcome::Sync(candidates.first().copied()),
        PointInput::Allocate { children } => Outcome::Allocate(cx.assign_by_id(children)),
        PointInput::Terminate => Outcome::Terminate(None),
    }
}

fn no_params(name: &str, params: &Params) -> Result<(), String> {
    match params {
        Params::Null => Ok(()),
        Params::Object(m) if m.is_empty() => Ok(()),
        _ => Err(format!("`{name}` takes no parameters")),
    }
}

/// A silent instance: decides the fallback outcome as soon as it can.
struct Silent {
    name: &'static str,
}

impl Interaction for Silent {
    fn start(&mut self, cx: &mut Cx<'_>) {
        if !matches!(cx.input(), PointInput::Terminate) {
            let o = fallback(cx);
            cx.decide(o);
        }
    }
    fn local_done(&mut self, cx: &mut Cx<'_>, _why: crate::interaction::LocalEnd) {
        cx.decide(Outcome::Terminate(None));
    }
    fn on_message(&mut self, cx: &mut Cx<'_>, from: crate::ids::RobotId, body: &Body) {
        cx.violation(format!(
            "{} sends no messages, but {from} sent `{}`",
            self.name,
            body.name()
        ));
    }
    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        let o = fallback(cx);
        cx.decide(o);
    }
}

macro_rules! silent_protocol {
    ($ty:ident, $name:literal, $alias:expr, $kind:expr, $summary:literal) => {
        #[doc = $summary]
        #[derive(Debug, Clone, Copy, Default)]
        pub struct $ty;
        impl Protocol for $ty {
            fn name(&self) -> &'static str {
                $name
            }
            fn aliases(&self) -> &'static [&'static str] {
                $alias
            }
            fn kind(&self) -> Kind {
                $kind
            }
            fn communicates(&self) -> bool {
                false
            }
            fn summary(&self) -> &'static str {
                $summary
            }
            fn configure(
                &self,
                params: &Params,
                _: &mut crate::interaction::Setup<'_>,
            ) -> Result<Factory, String> {
                no_params($name, params)?;
                Ok(Arc::new(|| {
                    Box::new(Silent { name: $name }) as Box<dyn Interaction>
                }))
            }
        }
    };
}

silent_protocol!(
    SyncByRule,
    "sync.by-rule",
    &["SF1"],
    Kind::Sync,
    "SF1: every member takes the first enabled successor in graph order; no messages."
);
silent_protocol!(
    AllocById,
    "alloc.by-id",
    &["SF2"],
    Kind::Allocate,
    "SF2: members sorted by id are dealt to children in graph order (minimums first); no messages."
);
silent_protocol!(
    TermLocal,
    "term.local",
    &[],
    Kind::Terminate,
    "Each member ends the behavior on its own; teammates are not told."
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::BehaviorId;

    fn slot(b: u32, min: u32, max: u32) -> ChildSlot {
        ChildSlot {
            behavior: BehaviorId(b),
            min,
            max,
        }
    }
    fn ids(a: &Assignment) -> Vec<Vec<u32>> {
        a.0.iter()
            .map(|(_, m)| m.iter().map(|r| r.0).collect())
            .collect()
    }

    #[test]
    fn minimums_first_then_shared_evenly_in_blocks() {
        let members = (0..6).map(RobotId);
        let a = assign_in_order(
            6,
            members,
            &[slot(1, 1, 1), slot(2, 1, u32::MAX), slot(3, 1, u32::MAX)],
        );
        assert_eq!(ids(&a), vec![vec![0], vec![1, 2, 3], vec![4, 5]]);
        assert_eq!(
            member_counts(10, &[slot(1, 2, 3), slot(2, 1, u32::MAX)]),
            [3, 7]
        );
        assert_eq!(member_counts(1, &[slot(1, 2, 3), slot(2, 1, 9)]), [1, 0]);
    }

    #[test]
    fn by_id_fast_path_matches_the_general_rule() {
        use proptest::prelude::*;
        proptest!(|(bits in proptest::collection::vec(any::<bool>(), 0..300),
                    slots in proptest::collection::vec((1u32..4, 0u32..6), 1..5))| {
            let n = bits.len();
            let members = MemberSet::from_iter(n, bits.iter().enumerate().filter(|(_, b)| **b).map(|(i, _)| RobotId(i as u32)));
            let children: Vec<ChildSlot> = slots
                .iter()
                .enumerate()
                .map(|(i, (min, extra))| slot(i as u32, *min, if *extra == 5 { u32::MAX } else { min + extra }))
                .collect();
            let fast = assign_by_id(&members, &children);
            let slow = assign_in_order(n, members.iter(), &children);
            prop_assert_eq!(fast, slow);
        });
    }

    #[test]
    fn fewer_members_than_children_leaves_later_children_uncovered() {
        let a = assign_in_order(
            2,
            (0..2).map(RobotId),
            &[slot(1, 1, 1), slot(2, 1, 1), slot(3, 1, 1)],
        );
        assert_eq!(ids(&a), vec![vec![0], vec![1], vec![]]);
    }

    #[test]
    fn leftover_members_stay_unassigned_when_children_are_full() {
        let a = assign_in_order(4, (0..4).map(RobotId), &[slot(1, 1, 1), slot(2, 2, 2)]);
        assert_eq!(ids(&a), vec![vec![0], vec![1, 2]]);
        assert_eq!(a.child_of(RobotId(3)), None);
        assert_eq!(a.child_of(RobotId(2)), Some((1, BehaviorId(2))));
    }

    #[test]
    fn preference_order_is_respected() {
        let members = [RobotId(2), RobotId(0), RobotId(1)];
        let a = assign_in_order(3, members, &[slot(7, 1, 1), slot(8, 1, 1), slot(9, 1, 1)]);
        assert_eq!(ids(&a), vec![vec![2], vec![0], vec![1]]);
    }
}
