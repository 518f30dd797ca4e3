//! The belief store: what one robot believes, each belief with its time and
//! source.
//!
//! Belief names are interned once (when the behavior graph is loaded) into
//! [`BeliefId`]s, so evaluating a condition is an array lookup. A store
//! counts its changes in [`BeliefStore::version`]; the kernel skips
//! re-evaluating conditions when nothing they could read has changed.

use crate::ids::{BeliefId, RobotId};
use crate::time::Time;
use crate::value::Value;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Interned belief names. Shared (behind an `Arc`) by a graph and every
/// store created for it.
#[derive(Clone, Debug, Default)]
pub struct Symbols {
    names: Vec<Arc<str>>,
    /// Hashed ([`crate::ids::name_hash`]): a graph's conditions look up every name
    /// they read when it is loaded (a B-tree's string comparisons were most
    /// of that). A table of ids, so that the loader can intern names its
    /// workers hashed ([`Symbols::intern_hashed`]).
    index: hashbrown::HashTable<BeliefId>,
}

impl Symbols {
    /// An empty table.
    pub fn new() -> Self {
        Self::default()
    }
    /// An empty table with room for `n` names.
    pub fn with_capacity(n: usize) -> Self {
        Symbols {
            names: Vec::with_capacity(n),
            index: hashbrown::HashTable::with_capacity(n),
        }
    }
    /// The id of `name`, adding it if it is new.
    pub fn intern(&mut self, name: &str) -> BeliefId {
        self.intern_hashed(crate::ids::name_hash(name), name)
    }
    /// The id of `name`, whose [`crate::ids::name_hash`] is `hash`, adding it if it
    /// is new.
    pub fn intern_hashed(&mut self, hash: u64, name: &str) -> BeliefId {
        let names = &self.names;
        match self.index.entry(
            hash,
            |id| *names[id.index()] == *name,
            |id| crate::ids::name_hash(&names[id.index()]),
        ) {
            hashbrown::hash_table::Entry::Occupied(e) => *e.get(),
            hashbrown::hash_table::Entry::Vacant(v) => {
                let id = BeliefId(self.names.len() as u32);
                v.insert(id);
                self.names.push(Arc::from(name));
                id
            }
        }
    }
    /// The id of `name`, if it is known.
    pub fn get(&self, name: &str) -> Option<BeliefId> {
        (self.index)
            .find(crate::ids::name_hash(name), |id| {
                *self.names[id.index()] == *name
            })
            .copied()
    }
    /// The name of `id`.
    pub fn name(&self, id: BeliefId) -> &str {
        self.names.get(id.index()).map_or("?", |n| n)
    }
    /// The name of `id`, shared (copying it copies a pointer).
    pub fn name_shared(&self, id: BeliefId) -> Arc<str> {
        self.names
            .get(id.index())
            .cloned()
            .unwrap_or_else(|| Arc::from("?"))
    }
    /// Number of interned names.
    pub fn len(&self) -> usize {
        self.names.len()
    }
    /// True when no name is interned.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }
    /// All names with their ids, in id order.
    pub fn iter(&self) -> impl Iterator<Item = (BeliefId, &str)> {
        self.names
            .iter()
            .enumerate()
            .map(|(i, n)| (BeliefId(i as u32), &**n))
    }
}

/// Where a belief came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "robot")]
pub enum Source {
    /// The robot's own sensors or skills.
    Percept,
    /// A teammate told us.
    Teammate(RobotId),
    /// Set by the engine itself (initial beliefs, configuration).
    Given,
}

/// One belief: a value, when it was last set, and by whom.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Belief {
    /// The value.
    pub value: Value,
    /// When it was set.
    pub time: Time,
    /// Who set it.
    pub source: Source,
}

/// What one robot believes.
#[derive(Clone, Debug)]
pub struct BeliefStore {
    symbols: Arc<Symbols>,
    slots: Vec<Option<Belief>>,
    /// Beliefs whose names no condition of the graph mentions (kept so that
    /// they can be shown and shared, never read by the kernel).
    extra: BTreeMap<Arc<str>, Belief>,
    version: u64,
}

impl BeliefStore {
    /// Ask for the first belief slots to be brought into the cache
    /// (see [`crate::kernel::Kernel::prefetch`]).
    pub fn prefetch(&self) {
        crate::hint::prefetch_slice(&self.slots, 4);
    }

    /// An empty store over the graph's symbol table.
    pub fn new(symbols: Arc<Symbols>) -> Self {
        let slots = vec![None; symbols.len()];
        BeliefStore {
            symbols,
            slots,
            extra: BTreeMap::new(),
            version: 0,
        }
    }
    /// Take a larger symbol table that starts with this one (a new version
    /// of the mission): beliefs kept by name that no condition read before
    /// move into their slots.
    pub fn extend_symbols(&mut self, symbols: Arc<Symbols>) {
        debug_assert!(
            self.symbols
                .iter()
                .all(|(id, n)| symbols.get(n) == Some(id))
        );
        self.slots.resize(symbols.len(), None);
        let moved: Vec<Arc<str>> = self
            .extra
            .keys()
            .filter(|n| symbols.get(n).is_some())
            .cloned()
            .collect();
        for n in moved {
            if let (Some(b), Some(id)) = (self.extra.remove(&n), symbols.get(&n)) {
                self.slots[id.index()] = Some(b);
            }
        }
        self.symbols = symbols;
        self.version += 1;
    }
    /// The symbol table.
    pub fn symbols(&self) -> &Arc<Symbols> {
        &self.symbols
    }
    /// Incremented by every change; unchanged sets do not count.
    #[inline]
    pub fn version(&self) -> u64 {
        self.version
    }
    /// The belief `id`, if set.
    #[inline]
    pub fn get(&self, id: BeliefId) -> Option<&Belief> {
        self.slots.get(id.index()).and_then(Option::as_ref)
    }
    /// The value of belief `id`, if set.
    #[inline]
    pub fn value(&self, id: BeliefId) -> Option<&Value> {
        self.get(id).map(|b| &b.value)
    }
    /// The belief called `name`, if set.
    pub fn get_named(&self, name: &str) -> Option<&Belief> {
        match self.symbols.get(name) {
            Some(id) => self.get(id),
            None => self.extra.get(name),
        }
    }
    /// Set belief `id`. Returns whether the value changed (a re-set to the
    /// same value only refreshes the time and source).
    pub fn set(&mut self, id: BeliefId, value: Value, time: Time, source: Source) -> bool {
        let Some(slot) = self.slots.get_mut(id.index()) else {
            return false;
        };
        let changed = !matches!(slot, Some(b) if b.value.same_as(&value));
        *slot = Some(Belief {
            value,
            time,
            source,
        });
        self.version += u64::from(changed);
        changed
    }
    /// Set the belief called `name` (interned or not). Returns whether the
    /// value changed.
    pub fn set_named(&mut self, name: &str, value: Value, time: Time, source: Source) -> bool {
        if let Some(id) = self.symbols.get(name) {
            return self.set(id, value, time, source);
        }
        let belief = Belief {
            value,
            time,
            source,
        };
        let old = self.extra.insert(Arc::from(name), belief.clone());
        let changed = !matches!(old, Some(b) if b.value.same_as(&belief.value));
        self.version += u64::from(changed);
        changed
    }
    /// Forget belief `id`. Returns whether it was set.
    pub fn clear(&mut self, id: BeliefId) -> bool {
        match self.slots.get_mut(id.index()) {
            Some(slot @ Some(_)) => {
                *slot = None;
                self.version += 1;
                true
            }
            _ => false,
        }
    }
    /// Every set belief with its name, interned ones first (in id order),
    /// then the others by name.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Belief)> {
        let interned = self.slots.iter().enumerate().filter_map(|(i, b)| {
            b.as_ref()
                .map(|b| (self.symbols.name(BeliefId(i as u32)), b))
        });
        interned.chain(self.extra.iter().map(|(n, b)| (&**n, b)))
    }
}

/// How many times each behavior was started directly under one execution
/// of its parent (what `runs` reads in conditions), and the epoch of its
/// latest start there: a few entries, sorted by behavior, kept in place.
///
/// Every frame on a robot's stack holds one: a B-tree allocated a node at
/// the first start under each frame, an allocation per decision and a
/// node per frame of every robot of a large team.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RunCounts(smallvec::SmallVec<[(crate::ids::BehaviorId, u32, u32); 2]>);

impl RunCounts {
    /// No behavior started yet.
    pub fn new() -> RunCounts {
        RunCounts::default()
    }
    /// How many times `b` was started (0 when never).
    #[inline]
    pub fn get(&self, b: crate::ids::BehaviorId) -> u32 {
        self.0
            .iter()
            .find(|(x, _, _)| *x == b)
            .map_or(0, |(_, n, _)| *n)
    }
    /// Count one more start of `b`, its execution numbered `epoch`.
    pub fn bump(&mut self, b: crate::ids::BehaviorId, epoch: u32) {
        match self.0.binary_search_by_key(&b, |(x, _, _)| *x) {
            Ok(i) => {
                self.0[i].1 += 1;
                self.0[i].2 = self.0[i].2.max(epoch);
            }
            Err(i) => self.0.insert(i, (b, 1, epoch)),
        }
    }
    /// Forget one start of `b` (a start abandoned); never below zero. The
    /// latest epoch stays: the abandoned execution is numbered all the same.
    pub fn unbump(&mut self, b: crate::ids::BehaviorId) {
        if let Ok(i) = self.0.binary_search_by_key(&b, |(x, _, _)| *x) {
            self.0[i].1 = self.0[i].1.saturating_sub(1);
        }
    }
    /// Note that execution `epoch` of `b` is behind this robot's way here
    /// though it never started it: it converged onto a teammate's
    /// successor of it. The latest epoch is raised (never lowered), the
    /// count of starts is not.
    pub fn pass(&mut self, b: crate::ids::BehaviorId, epoch: u32) {
        match self.0.binary_search_by_key(&b, |(x, _, _)| *x) {
            Ok(i) => self.0[i].2 = self.0[i].2.max(epoch),
            Err(i) => self.0.insert(i, (b, 0, epoch)),
        }
    }
    /// The highest epoch at which `b` was started here (0 when never), or
    /// passed ([`RunCounts::pass`]).
    /// Epochs count a team's executions of a behavior, so an execution of
    /// `b` by the same team under the same parent execution with an epoch
    /// up to this one came no later than this start.
    pub fn latest_epoch(&self, b: crate::ids::BehaviorId) -> u32 {
        self.0
            .iter()
            .find(|(x, _, _)| *x == b)
            .map_or(0, |(_, _, e)| *e)
    }
    /// Every behavior started, with its count, in behavior order.
    pub fn iter(&self) -> impl Iterator<Item = (crate::ids::BehaviorId, u32)> + '_ {
        self.0.iter().map(|&(b, n, _)| (b, n))
    }
}

/// What a condition reads when evaluated for a behavior `own`: the robot's
/// beliefs, the run counts of `own`'s parent execution, and time.
///
/// The one environment the kernel (for `pre` and `until`) and protocols
/// (for `utility`) evaluate conditions in.
pub struct BeliefEnv<'a> {
    /// The robot's beliefs.
    pub beliefs: &'a BeliefStore,
    /// Starts of each behavior in the current execution of `own`'s parent.
    pub runs: &'a RunCounts,
    /// Now.
    pub now: Time,
    /// When `own` started (now, for a behavior not started yet).
    pub started: Time,
    /// The behavior whose condition is evaluated.
    pub own: crate::ids::BehaviorId,
}

impl crate::cond::Env for BeliefEnv<'_> {
    #[inline]
    fn belief(&self, id: BeliefId) -> Option<&Value> {
        self.beliefs.value(id)
    }
    fn belief_age(&self, id: BeliefId) -> Option<f64> {
        self.beliefs
            .get(id)
            .map(|b| (self.now - b.time).as_secs_f64())
    }
    fn elapsed(&self) -> f64 {
        (self.now - self.started).as_secs_f64()
    }
    fn runs(&self, b: Option<crate::ids::BehaviorId>) -> u32 {
        self.runs.get(b.unwrap_or(self.own))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_reports_changes_and_bumps_version() {
        let mut sym = Symbols::new();
        let a = sym.intern("a");
        assert_eq!(sym.intern("a"), a);
        let mut store = BeliefStore::new(Arc::new(sym));
        assert!(store.set(a, Value::Num(1.0), Time(5), Source::Percept));
        let v = store.version();
        assert!(!store.set(a, Value::Num(1.0), Time(6), Source::Percept));
        assert_eq!(store.version(), v, "an unchanged value is not a change");
        assert_eq!(store.get(a).unwrap().time, Time(6), "but time is refreshed");
        assert!(store.set_named("other", Value::Bool(true), Time(7), Source::Given));
        assert_eq!(store.get_named("other").unwrap().value, Value::Bool(true));
        assert_eq!(store.iter().count(), 2);
        assert!(store.clear(a));
        assert!(store.value(a).is_none());
    }

    proptest::proptest! {
        /// The same counts as the B-tree it replaces, whatever the starts,
        /// abandoned starts and executions passed, past the few kept in
        /// place; and the highest epoch started or passed of each behavior.
        #[test]
        fn run_counts_count_as_a_map(ops in proptest::collection::vec((0u32..6, 0u8..3, 1u32..50), 0..60)) {
            use crate::ids::BehaviorId;
            let mut counts = RunCounts::new();
            let mut map: BTreeMap<BehaviorId, u32> = BTreeMap::new();
            let mut latest: BTreeMap<BehaviorId, u32> = BTreeMap::new();
            for (b, op, epoch) in ops {
                let b = BehaviorId(b);
                match op {
                    0 => {
                        counts.bump(b, epoch);
                        *map.entry(b).or_insert(0) += 1;
                        let e = latest.entry(b).or_insert(0);
                        *e = (*e).max(epoch);
                    }
                    1 => {
                        counts.unbump(b);
                        if let Some(n) = map.get_mut(&b) {
                            *n = n.saturating_sub(1);
                        }
                    }
                    _ => {
                        counts.pass(b, epoch);
                        map.entry(b).or_insert(0);
                        let e = latest.entry(b).or_insert(0);
                        *e = (*e).max(epoch);
                    }
                }
                for x in 0..6 {
                    let x = BehaviorId(x);
                    proptest::prop_assert_eq!(counts.get(x), map.get(&x).copied().unwrap_or(0));
                    proptest::prop_assert_eq!(counts.latest_epoch(x), latest.get(&x).copied().unwrap_or(0));
                }
                let listed: Vec<(BehaviorId, u32)> = counts.iter().collect();
                let expected: Vec<(BehaviorId, u32)> = map.iter().map(|(b, n)| (*b, *n)).collect();
                proptest::prop_assert_eq!(&listed, &expected);
            }
        }
    }
}
