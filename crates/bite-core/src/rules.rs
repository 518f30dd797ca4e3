//! The silent rules: protocols that decide without a single message, from
//! information every member shares (the graph, the roster, the team).
//!
//! They are built into the kernel because they are also its fallbacks: when
//! a communicating protocol misses its deadline without deciding, the kernel
//! applies the rule of the same kind.

use crate::ids::Kind;
use crate::interaction::{
    ConfigError, Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol, Registry,
    no_params,
};
use crate::msg::Body;
use std::sync::Arc;

pub use crate::members::{assign_by_id, assign_in_order, member_counts};

impl Registry {
    /// The silent rules built into the kernel: `sync.by-rule`,
    /// `alloc.by-id`, `term.local`.
    pub fn core() -> Self {
        let mut r = Self::new();
        r.register(Arc::new(crate::rules::SyncByRule));
        r.register(Arc::new(crate::rules::AllocById));
        r.register(Arc::new(crate::rules::TermLocal));
        r
    }
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

/// A silent instance of protocol `P`: decides the fallback outcome as soon
/// as it can. Zero-sized, so that starting one allocates nothing (a robot
/// starts several at every decision).
struct Silent<P>(std::marker::PhantomData<P>);

impl<P: Protocol + Default + Send + 'static> Interaction for Silent<P> {
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
            P::default().name(),
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
            ) -> Result<Factory, ConfigError> {
                no_params($name, params)?;
                Ok(Arc::new(|| {
                    Box::new(Silent::<$ty>(std::marker::PhantomData)) as Box<dyn Interaction>
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
    use crate::ids::RobotId;
    use crate::members::{Assignment, ChildSlot, MemberSet};

    fn slot(b: u32, min: u32, max: u32) -> ChildSlot {
        ChildSlot {
            behavior: BehaviorId(b),
            min,
            max,
            critical: false,
        }
    }
    fn critical(b: u32, min: u32, max: u32) -> ChildSlot {
        ChildSlot {
            critical: true,
            ..slot(b, min, max)
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
                    slots in proptest::collection::vec((1u32..4, 0u32..6, any::<bool>()), 1..5))| {
            let n = bits.len();
            let members = MemberSet::from_iter(n, bits.iter().enumerate().filter(|(_, b)| **b).map(|(i, _)| RobotId(i as u32)));
            let children: Vec<ChildSlot> = slots
                .iter()
                .enumerate()
                .map(|(i, (min, extra, c))| ChildSlot {
                    critical: *c,
                    ..slot(i as u32, *min, if *extra == 5 { u32::MAX } else { min + extra })
                })
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
    fn critical_children_take_their_minimums_first_when_members_are_few() {
        // The relay's last leg: step aside, then finish the push. Two
        // robots: one each, dealt in graph order. One robot: the push.
        let leg = [slot(1, 1, u32::MAX), critical(2, 1, 1)];
        let a = assign_in_order(2, (0..2).map(RobotId), &leg);
        assert_eq!(ids(&a), vec![vec![0], vec![1]]);
        let a = assign_in_order(1, (0..1).map(RobotId), &leg);
        assert_eq!(ids(&a), vec![vec![], vec![0]]);
        // Several critical children: in graph order among themselves; the
        // rest is shared as before.
        let c = [
            slot(1, 1, 9),
            critical(2, 2, 9),
            slot(3, 1, 9),
            critical(4, 1, 9),
        ];
        assert_eq!(member_counts(2, &c), [0, 2, 0, 0]);
        assert_eq!(member_counts(3, &c), [0, 2, 0, 1]);
        assert_eq!(member_counts(4, &c), [1, 2, 0, 1]);
        assert_eq!(member_counts(9, &c), [2, 3, 2, 2]);
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
