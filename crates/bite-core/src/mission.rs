//! A mission: a behavior graph with a protocol resolved and configured at
//! every coordination point. Shared (behind an `Arc`) by all kernels of a
//! team running in one process.

use crate::diag::{Diagnostic, Diagnostics, Loc, did_you_mean};
use crate::event::LogList;
use crate::graph::{BehaviorGraph, Binding};
use crate::ids::Kind;
use crate::ids::{BehaviorId, TeamId};
use crate::interaction::{
    Assignment, ByIdMemo, ChildSlot, Factory, Params, Protocol, Registry, Setup,
};
use crate::org::Split;
use smallvec::SmallVec;
use std::fmt;
use std::sync::Arc;
use std::sync::{Mutex, Weak};
use std::time::Duration;

/// How many deadlines a robot waits for a teammate heard working whose
/// position does not change (see `Kernel::awaited_at_work`).
pub const SLOW_WAITS: u32 = 4;

/// The least a robot waits for a teammate heard working whose position does
/// not change, whatever the deadline.
pub const SLOW_WAIT_MIN: Duration = Duration::from_secs(120);

/// How long a robot waits for a teammate heard working whose position does
/// not change, at a point whose protocol has deadline `deadline`:
/// [`SLOW_WAITS`] deadlines, at least [`SLOW_WAIT_MIN`].
pub fn slow_wait(deadline: Duration) -> Duration {
    (deadline * SLOW_WAITS).max(SLOW_WAIT_MIN)
}

/// Retransmission interval when a binding does not give one.
pub const DEFAULT_RETRY: Duration = Duration::from_millis(500);

/// The protocol bound at one point, configured.
#[derive(Clone)]
pub struct Bound {
    /// Point name (label or `behavior.kind`).
    pub point: String,
    /// The protocol.
    pub protocol: Arc<dyn Protocol>,
    /// Creates instances configured with the binding's parameters.
    pub factory: Factory,
    /// Deadline of each instance.
    pub deadline: Duration,
    /// Retransmission interval.
    pub retry: Duration,
    /// The parameters as written.
    pub params: Params,
}

impl fmt::Debug for Bound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Bound")
            .field("point", &self.point)
            .field("protocol", &self.protocol.name())
            .field("deadline", &self.deadline)
            .field("retry", &self.retry)
            .finish()
    }
}

/// A behavior's successors, shared, and the same list as the run log
/// shows it.
pub type Successors = (Arc<[BehaviorId]>, LogList<BehaviorId>);

/// A graph ready to run.
#[derive(Debug)]
pub struct Mission {
    graph: Arc<BehaviorGraph>,
    bound: Vec<[Option<Bound>; 3]>,
    slots: Vec<Arc<[ChildSlot]>>,
    /// The children of each behavior, as ids (shared by every robot's
    /// record of an allocation that saw them all enabled).
    child_ids: Vec<LogList<BehaviorId>>,
    /// The successors of each behavior that has any, shared by every
    /// synchronization at it, with the same list as the run log shows it.
    next: Vec<Option<Successors>>,
    /// The children of each behavior with their positions, by id.
    child_index: Vec<Vec<(BehaviorId, u32)>>,
    /// Behaviors none of whose children has a precondition.
    unconditional: Vec<bool>,
    /// The allocations applied by the kernels of this process.
    splits: Splits,
    /// Recent allocations by id, by the (shared) team and children they
    /// split.
    by_id: ByIdMemo,
}

/// The subteams made by allocations, shared between the kernels of one
/// process (see [`Mission::split`]): equal allocations of the same
/// execution make one [`Split`], held by every robot that applied it and
/// freed when the last one dissolves it.
#[derive(Debug, Default)]
struct Splits {
    table: Mutex<SplitTable>,
}

type Execution = (TeamId, BehaviorId, (u32, u32));

#[derive(Debug, Default)]
struct SplitTable {
    /// Looked up by execution and swept, never walked in order: a hash
    /// map (a B-tree of a thousand executions was a tenth of a decision).
    /// Nearly always one split per execution (more only where robots of
    /// this process applied different allocations): kept inline, as a
    /// list allocated for every split cost an allocation and a free per
    /// split.
    by_execution: rustc_hash::FxHashMap<Execution, SmallVec<[Weak<Split>; 1]>>,
    /// Entries (weak pointers) in `by_execution`.
    entries: usize,
    /// Entries left by the last sweep of dead ones.
    kept: usize,
}

/// The table is swept of dead splits once it holds twice what the last
/// sweep left, and not below this many entries.
const SPLIT_SWEEP_FROM: usize = 1024;

impl Splits {
    fn lock(&self) -> std::sync::MutexGuard<'_, SplitTable> {
        self.table
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl SplitTable {
    fn find(
        &self,
        parent: TeamId,
        point: BehaviorId,
        stamp: (u32, u32),
        assignment: &Arc<Assignment>,
    ) -> Option<Arc<Split>> {
        let found = self.by_execution.get(&(parent, point, stamp))?;
        let live = || found.iter().filter_map(Weak::upgrade);
        // The same allocation (the silent rule's, shared), else an equal one.
        live()
            .find(|s| Arc::ptr_eq(s.assignment(), assignment))
            .or_else(|| live().find(|s| **s.assignment() == **assignment))
    }

    fn insert(&mut self, split: &Arc<Split>) {
        self.by_execution
            .entry((split.parent(), split.point(), split.stamp()))
            .or_default()
            .push(Arc::downgrade(split));
        self.entries += 1;
        // Forget the splits every robot has dissolved, once there are as
        // many new entries as the last sweep kept (amortized: a sweep costs
        // what was inserted since the last). A dead entry's weak pointer
        // also holds its split's memory.
        if self.entries >= SPLIT_SWEEP_FROM.max(2 * self.kept) {
            self.by_execution.retain(|_, v| {
                v.retain(|w| w.strong_count() > 0);
                !v.is_empty()
            });
            self.entries = self.by_execution.values().map(|v| v.len()).sum();
            self.kept = self.entries;
        }
    }
}

impl Mission {
    /// Resolve every point's binding against `registry`: the protocol must
    /// exist, be of the point's kind, and accept its parameters.
    pub fn new(mut graph: BehaviorGraph, registry: &Registry) -> Result<Mission, Diagnostics> {
        let mut diags = Vec::new();
        // Expressions in protocol parameters may name beliefs no condition
        // of the graph mentions: they join the symbol table.
        let mut symbols = (**graph.symbols()).clone();
        let mut bound: Vec<[Option<Bound>; 3]> = Vec::with_capacity(graph.len());
        for b in graph.behaviors() {
            let mut row: [Option<Bound>; 3] = [None, None, None];
            for kind in Kind::ALL {
                if graph.is_point(b.id, kind) {
                    let mut setup = Setup::new(&graph, &mut symbols, b.id, kind);
                    row[kind.index()] = resolve(registry, &mut setup, &mut diags);
                }
            }
            bound.push(row);
        }
        // Defaults that no point uses are still checked, so that a typo in
        // a configuration is not silently ignored.
        for kind in Kind::ALL {
            if let Some(d) = graph.default_binding(kind)
                && let Some(name) = &d.protocol
            {
                check_protocol(
                    registry,
                    name,
                    kind,
                    &format!("default {kind}"),
                    d,
                    &mut diags,
                );
            }
        }
        if !diags.is_empty() {
            return Err(Diagnostics(diags));
        }
        graph.set_symbols(Arc::new(symbols));
        let slots = graph
            .behaviors()
            .iter()
            .map(|b| {
                b.children
                    .iter()
                    .map(|c| {
                        let b = graph.behavior(*c);
                        ChildSlot {
                            behavior: *c,
                            min: b.members.0,
                            max: b.members.1,
                            critical: b.critical,
                        }
                    })
                    .collect()
            })
            .collect();
        let child_ids = graph
            .behaviors()
            .iter()
            .map(|b| LogList::from(b.children.as_slice()))
            .collect();
        let next = graph
            .behaviors()
            .iter()
            .map(|b| {
                (!b.next.is_empty()).then(|| {
                    (
                        Arc::from(b.next.as_slice()),
                        LogList::from(b.next.as_slice()),
                    )
                })
            })
            .collect();
        let child_index = graph
            .behaviors()
            .iter()
            .map(|b| {
                let mut v: Vec<(BehaviorId, u32)> = (b.children.iter())
                    .enumerate()
                    .map(|(i, c)| (*c, i as u32))
                    .collect();
                v.sort_unstable();
                v
            })
            .collect();
        let unconditional = graph
            .behaviors()
            .iter()
            .map(|b| b.children.iter().all(|c| graph.behavior(*c).pre.is_none()))
            .collect();
        Ok(Mission {
            graph: Arc::new(graph),
            bound,
            slots,
            child_ids,
            next,
            child_index,
            unconditional,
            splits: Splits::default(),
            by_id: ByIdMemo::default(),
        })
    }

    /// The graph.
    pub fn graph(&self) -> &Arc<BehaviorGraph> {
        &self.graph
    }
    /// The protocol bound at point (`b`, `kind`), if `b` is such a point.
    pub fn bound(&self, b: BehaviorId, kind: Kind) -> Option<&Bound> {
        self.bound
            .get(b.index())
            .and_then(|r| r[kind.index()].as_ref())
    }
    /// The children of `b` with their member counts.
    pub fn child_slots(&self, b: BehaviorId) -> &[ChildSlot] {
        self.slots.get(b.index()).map_or(&[], |s| s)
    }
    /// [`Mission::child_slots`], shared.
    pub fn child_slots_shared(&self, b: BehaviorId) -> Option<&Arc<[ChildSlot]>> {
        self.slots.get(b.index())
    }
    /// True when no child of `b` has a precondition: they are all enabled,
    /// whatever a robot believes.
    pub fn children_unconditional(&self, b: BehaviorId) -> bool {
        self.unconditional.get(b.index()).copied().unwrap_or(true)
    }
    /// The children of `b`, shared.
    pub fn child_ids(&self, b: BehaviorId) -> Option<&LogList<BehaviorId>> {
        self.child_ids.get(b.index())
    }
    /// The successors of `b`, shared, and as the run log shows them
    /// (`None` when it has none).
    pub fn next_shared(&self, b: BehaviorId) -> Option<&Successors> {
        self.next.get(b.index())?.as_ref()
    }
    /// The position of `child` among the children of `b`.
    pub fn child_index(&self, b: BehaviorId, child: BehaviorId) -> Option<u32> {
        let v = self.child_index.get(b.index())?;
        v.binary_search_by_key(&child, |(c, _)| *c)
            .ok()
            .map(|k| v[k].1)
    }

    /// The allocations by id this process's robots share (see
    /// [`ByIdMemo`]).
    pub fn by_id_memo(&self) -> &ByIdMemo {
        &self.by_id
    }

    /// The subteams that `assignment` makes of `parent` at execution
    /// `stamp` (epoch, round) of allocation point `point`. Every kernel of
    /// this process that applies an equal allocation of the same execution
    /// gets the same [`Split`] (compared in full, so a different
    /// allocation never shares one): a team of 10,000 robots splitting
    /// among 10,000 children stores the subteams once rather than once per
    /// robot, and later robots only hash and compare the assignment.
    pub fn split(
        &self,
        parent: TeamId,
        point: BehaviorId,
        stamp: (u32, u32),
        assignment: Arc<Assignment>,
    ) -> Arc<Split> {
        let mut table = self.splits.lock();
        if let Some(found) = table.find(parent, point, stamp, &assignment) {
            return found;
        }
        let split = Arc::new(Split::new(parent, point, stamp, assignment, |c| {
            self.child_index(point, c)
        }));
        table.insert(&split);
        split
    }

    /// The split an equal allocation of the same execution already made in
    /// this process, if one is alive (such an allocation was checked when
    /// it was first applied).
    pub fn find_split(
        &self,
        parent: TeamId,
        point: BehaviorId,
        stamp: (u32, u32),
        assignment: &Arc<Assignment>,
    ) -> Option<Arc<Split>> {
        self.splits.lock().find(parent, point, stamp, assignment)
    }
    /// The longest a robot of this mission waits at a point with nothing
    /// to show for it before the point's deadline decides: a teammate
    /// heard working whose position does not change is waited for
    /// ([`slow_wait`]), checked at each deadline, so up to
    /// one deadline more. Zero when no point is bound.
    pub fn longest_wait(&self) -> Duration {
        (self.bound.iter().flatten().flatten())
            .map(|b| slow_wait(b.deadline) + b.deadline)
            .max()
            .unwrap_or(Duration::ZERO)
    }

    /// Every point with its bound protocol, in graph order.
    pub fn points(&self) -> Vec<(crate::graph::Point, &Bound)> {
        self.graph
            .points()
            .into_iter()
            .filter_map(|p| self.bound(p.behavior, p.kind).map(|b| (p, b)))
            .collect()
    }
}

fn check_protocol<'r>(
    registry: &'r Registry,
    name: &str,
    kind: Kind,
    point: &str,
    at: &Binding,
    diags: &mut Vec<Diagnostic>,
) -> Option<&'r Arc<dyn Protocol>> {
    let Some(p) = registry.get(name) else {
        let hint = did_you_mean(name, registry.names()).or_else(|| {
            let names: Vec<&str> = registry
                .iter()
                .filter(|p| p.kind() == kind)
                .map(|p| p.name())
                .collect();
            Some(format!("{} protocols: {}", kind, names.join(", ")))
        });
        let mut d = Diagnostic::error(
            &at.file,
            at.loc,
            "unknown-protocol",
            format!("no protocol called `{name}` (bound at {point})"),
        );
        d.hint = hint;
        diags.push(d);
        return None;
    };
    if p.kind() != kind {
        diags.push(
            Diagnostic::error(
                &at.file,
                at.loc,
                "binding-kind-mismatch",
                format!(
                    "`{}` is {} protocol, but `{point}` is {} point",
                    p.name(),
                    p.kind().a_noun(),
                    kind.a_noun()
                ),
            )
            .with_hint(format!(
                "bind {} protocol here, e.g. `{}`",
                kind.a_noun(),
                Registry::default_for(kind)
            )),
        );
        return None;
    }
    Some(p)
}

fn resolve(
    registry: &Registry,
    setup: &mut Setup<'_>,
    diags: &mut Vec<Diagnostic>,
) -> Option<Bound> {
    let (graph, b, kind) = (setup.graph(), setup.point(), setup.kind());
    let point = graph.point_name(b, kind);
    let own = graph.own_binding(b, kind);
    let def = graph.default_binding(kind);
    let (name, from): (String, Option<&Binding>) = match (
        own.and_then(|o| o.protocol.clone()),
        def.and_then(|d| d.protocol.clone()),
    ) {
        (Some(n), _) => (n, own),
        (None, Some(n)) => (n, def),
        (None, None) => (Registry::default_for(kind).to_string(), None),
    };
    let fallback_at = Binding {
        protocol: None,
        deadline: None,
        retry: None,
        params: Params::Null,
        file: graph.file().clone(),
        loc: graph.behavior(b).loc,
    };
    let at = from.or(own).unwrap_or(&fallback_at);
    let protocol = check_protocol(registry, &name, kind, &point, at, diags)?.clone();
    // Parameters written on the point win; otherwise a protocol that came
    // from the defaults keeps the defaults' parameters.
    let params = match own {
        Some(o) if !o.params.is_null() => o.params.clone(),
        Some(o) if o.protocol.is_some() => Params::Null,
        _ => def.map_or(Params::Null, |d| d.params.clone()),
    };
    let (file, loc) = (at.file.clone(), at.loc);
    let factory = match protocol.configure(&params, setup) {
        Ok(f) => f,
        Err(e) => {
            diags.push(Diagnostic::error(
                &file,
                loc,
                "bad-params",
                format!("parameters of `{}` at {point}: {e}", protocol.name()),
            ));
            return None;
        }
    };
    let pick = |f: fn(&Binding) -> Option<Duration>| own.and_then(f).or_else(|| def.and_then(f));
    let deadline = pick(|x| x.deadline).unwrap_or_else(|| protocol.default_deadline());
    let retry = pick(|x| x.retry).unwrap_or(DEFAULT_RETRY);
    if deadline.is_zero() || retry < Duration::from_millis(1) {
        diags.push(Diagnostic::error(
            &at.file,
            if at.loc.is_known() {
                at.loc
            } else {
                Loc::UNKNOWN
            },
            "bad-duration",
            format!(
                "at {point}: the deadline must be positive and the retry interval at least 1ms"
            ),
        ));
        return None;
    }
    Some(Bound {
        point,
        protocol,
        factory,
        deadline,
        retry,
        params,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::RobotId;
    use crate::members::{Assignment, MemberSet};

    fn mission() -> Mission {
        let g = crate::graph::load_str(
            &Arc::from("g.yaml"),
            "start: top\ndefaults: { terminate: term.local }\nbehaviors:\n  top: { team: true, children: [x, y] }\n  x: {}\n  y: {}\n",
        )
        .unwrap_or_else(|d| panic!("{d}"))
        .with_team_size(2);
        Mission::new(g, &Registry::core()).unwrap_or_else(|d| panic!("{d}"))
    }

    /// Splits dissolved by every robot are forgotten: the table of a
    /// process that runs an allocation point over and over stays bounded
    /// (it grew by an entry and a split's memory per execution).
    #[test]
    fn dissolved_splits_are_forgotten_and_live_ones_kept() {
        let m = mission();
        let g = m.graph();
        let top = g.find("top").expect("top");
        let (x, y) = (g.find("x").expect("x"), g.find("y").expect("y"));
        let one = |i: u32| MemberSet::from_iter(2, [RobotId(i)]);
        let assignment = || Arc::new(Assignment(vec![(x, one(0)), (y, one(1))]));
        // Kept alive throughout, as a robot still in its subteam would.
        let held: Vec<Arc<Split>> = (0..3)
            .map(|e| m.split(TeamId::ROOT, top, (e, 0), assignment()))
            .collect();
        let mut peak = 0;
        for epoch in 3..20_000 {
            let s = m.split(TeamId::ROOT, top, (epoch, 0), assignment());
            // Equal allocations of one execution share their split.
            let again = m.split(TeamId::ROOT, top, (epoch, 0), assignment());
            assert!(Arc::ptr_eq(&s, &again));
            peak = peak.max(m.splits.lock().entries);
        }
        assert!(
            peak <= 2 * SPLIT_SWEEP_FROM,
            "the table grew to {peak} entries"
        );
        for (e, s) in held.iter().enumerate() {
            let found = m.find_split(TeamId::ROOT, top, (e as u32, 0), &assignment());
            assert!(
                found.is_some_and(|f| Arc::ptr_eq(&f, s)),
                "live split {e} forgotten"
            );
        }
    }
}
