//! A robot's interaction instances, by key, in key order.
//!
//! A robot runs a handful of instances at a time (one per point on its
//! stack, and the few that linger to answer late teammates), started and
//! ended at every decision. A sorted vector of boxed instances finds one
//! by binary search over keys held side by side and walks them in key order
//! without chasing tree nodes; a B-tree did the same with an allocation
//! and a rebalancing per change (a tenth of a decision step).

use super::Instance;
use crate::ids::{BehaviorId, InstanceKey, Kind, TeamId};

/// Instances by key.
pub(super) type Instances = Slots<Box<Instance>>;

/// An instance key as three words whose order is `InstanceKey`'s (team,
/// behavior, kind, epoch, round): a binary search step compares at most
/// three integers instead of walking five fields through `Ordering`s.
/// Packed once when a key is looked up, not at every comparison.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Packed {
    team: u64,
    /// Behavior in the high half, the kind's index in the low.
    point: u64,
    /// Epoch in the high half, round in the low.
    stamp: u64,
}

impl Packed {
    #[inline]
    fn new(k: &InstanceKey) -> Packed {
        Packed {
            team: k.team.0,
            point: (u64::from(k.behavior.0) << 32) | k.kind.index() as u64,
            stamp: (u64::from(k.epoch) << 32) | u64::from(k.round),
        }
    }

    #[inline]
    fn key(self) -> InstanceKey {
        InstanceKey {
            team: TeamId(self.team),
            behavior: BehaviorId((self.point >> 32) as u32),
            kind: Kind::ALL[(self.point & 3) as usize],
            epoch: (self.stamp >> 32) as u32,
            round: self.stamp as u32,
        }
    }
}

/// Values by instance key, in key order: the part of `BTreeMap`'s
/// interface the kernel uses, with the same answers (tested against it),
/// and [`Slots::take`]: a value lent out and put back where it was.
pub(super) struct Slots<V> {
    /// Sorted by key, keys unique. `None`: a value taken out to be put
    /// back ([`Slots::take`]), absent to every query meanwhile.
    slots: Vec<(Packed, Option<V>)>,
    /// How many are `Some`.
    live: usize,
    /// The slot last found by a change (`get_mut`, `take`, `insert`),
    /// tried before a search: a call into an instance looks it up, lends
    /// it out and puts it back, three finds of the same key in a row.
    /// Only a hint: checked against the key, so a stale one costs one
    /// comparison.
    last: usize,
}

impl<V> Default for Slots<V> {
    fn default() -> Self {
        Slots {
            slots: Vec::new(),
            live: 0,
            last: 0,
        }
    }
}

impl<V> Slots<V> {
    #[inline]
    fn find(&self, key: &InstanceKey) -> Result<usize, usize> {
        let key = Packed::new(key);
        if self.slots.get(self.last).is_some_and(|(k, _)| *k == key) {
            return Ok(self.last);
        }
        self.slots.binary_search_by(|(k, _)| k.cmp(&key))
    }

    /// [`Slots::find`], remembering the slot for the next.
    #[inline]
    fn find_mut(&mut self, key: &InstanceKey) -> Result<usize, usize> {
        let found = self.find(key);
        if let Ok(i) = found {
            self.last = i;
        }
        found
    }

    /// See [`super::Kernel::prefetch`].
    pub(super) fn prefetch(&self) {
        crate::hint::prefetch_slice(&self.slots, 2);
    }

    pub(super) fn len(&self) -> usize {
        self.live
    }

    pub(super) fn contains_key(&self, key: &InstanceKey) -> bool {
        self.get(key).is_some()
    }

    pub(super) fn get(&self, key: &InstanceKey) -> Option<&V> {
        self.find(key).ok().and_then(|i| self.slots[i].1.as_ref())
    }

    pub(super) fn get_mut(&mut self, key: &InstanceKey) -> Option<&mut V> {
        match self.find_mut(key) {
            Ok(i) => self.slots[i].1.as_mut(),
            Err(_) => None,
        }
    }

    /// Put `value` under `key`, returning the value it replaces.
    pub(super) fn insert(&mut self, key: InstanceKey, value: V) -> Option<V> {
        match self.find_mut(&key) {
            Ok(i) => {
                let old = self.slots[i].1.replace(value);
                if old.is_none() {
                    self.live += 1;
                }
                old
            }
            Err(i) => {
                self.slots.insert(i, (Packed::new(&key), Some(value)));
                self.live += 1;
                self.last = i;
                None
            }
        }
    }

    /// Take the value under `key` out to be put back with
    /// [`Slots::insert`]: absent meanwhile, as if removed, but its slot
    /// stays, so that neither moves the values after it.
    pub(super) fn take(&mut self, key: &InstanceKey) -> Option<V> {
        let i = self.find_mut(key).ok()?;
        let old = self.slots[i].1.take();
        if old.is_some() {
            self.live -= 1;
        }
        old
    }

    /// Remove every value `pred` accepts, in one pass: the removed, with
    /// their keys, in key order. Empty slots go too (a value taken and
    /// put back later gets a new one).
    pub(super) fn remove_where(
        &mut self,
        mut pred: impl FnMut(&V) -> bool,
    ) -> Vec<(InstanceKey, V)> {
        let out: Vec<(InstanceKey, V)> = self
            .slots
            .extract_if(.., |(_, v)| v.as_ref().is_none_or(&mut pred))
            .filter_map(|(k, v)| v.map(|v| (k.key(), v)))
            .collect();
        self.live -= out.len();
        out
    }

    /// Every value with its key, in key order.
    pub(super) fn iter(&self) -> impl Iterator<Item = (InstanceKey, &V)> {
        self.slots
            .iter()
            .filter_map(|(k, v)| v.as_ref().map(|v| (k.key(), v)))
    }

    pub(super) fn keys(&self) -> impl Iterator<Item = InstanceKey> + '_ {
        self.iter().map(|(k, _)| k)
    }

    pub(super) fn values(&self) -> impl Iterator<Item = &V> {
        self.slots.iter().filter_map(|(_, v)| v.as_ref())
    }

    pub(super) fn values_mut(&mut self) -> impl Iterator<Item = &mut V> {
        self.slots.iter_mut().filter_map(|(_, v)| v.as_mut())
    }
}

impl<V> std::ops::Index<&InstanceKey> for Slots<V> {
    type Output = V;

    fn index(&self, key: &InstanceKey) -> &V {
        match self.get(key) {
            Some(v) => v,
            None => panic!("no instance {key:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::{BehaviorId, Kind, TeamId};
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    #[derive(Debug, Clone)]
    enum Op {
        Insert(InstanceKey, u32),
        Remove(InstanceKey),
        Bump(InstanceKey),
        /// Taken out and put back later (after `ops` more operations).
        Lend(InstanceKey, u8),
        /// Every value with this remainder modulo 3 removed.
        RemoveWhere(u32),
    }

    fn key() -> impl Strategy<Value = InstanceKey> {
        // Few distinct values per field, so that keys collide and differ
        // in every field.
        (0..3u64, 0..3u32, 0..3u8, 0..3u32, 0..2u32).prop_map(|(t, b, k, e, r)| InstanceKey {
            team: TeamId(t),
            behavior: BehaviorId(b),
            kind: [Kind::Sync, Kind::Allocate, Kind::Terminate][usize::from(k)],
            epoch: e,
            round: r,
        })
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            (key(), any::<u32>()).prop_map(|(k, v)| Op::Insert(k, v)),
            key().prop_map(Op::Remove),
            key().prop_map(Op::Bump),
            (key(), 0..4u8).prop_map(|(k, n)| Op::Lend(k, n)),
            (0..3u32).prop_map(Op::RemoveWhere),
        ]
    }

    proptest! {
        /// Every operation answers as `BTreeMap`'s does, and the walk is
        /// the map's, in its order.
        #[test]
        fn slots_answer_as_a_b_tree_map_does(ops in proptest::collection::vec(op(), 0..200)) {
            let mut slots = Slots::default();
            let mut map = BTreeMap::new();
            // Values lent out: put back once their count reaches zero.
            let mut lent: Vec<(InstanceKey, u32, u8)> = Vec::new();
            for op in ops {
                for l in &mut lent {
                    l.2 = l.2.saturating_sub(1);
                }
                for (k, v, _) in lent.extract_if(.., |l| l.2 == 0) {
                    prop_assert_eq!(slots.insert(k, v), map.insert(k, v));
                }
                match op {
                    Op::RemoveWhere(r) => {
                        let removed = slots.remove_where(|v| v % 3 == r);
                        let expected: Vec<_> = map.extract_if(.., |_, v| *v % 3 == r).collect();
                        prop_assert_eq!(removed, expected);
                    }
                    Op::Lend(k, n) => {
                        let (a, b) = (slots.take(&k), map.remove(&k));
                        prop_assert_eq!(a, b);
                        if let Some(v) = a {
                            lent.push((k, v, n));
                        }
                    }
                    Op::Insert(k, v) => prop_assert_eq!(slots.insert(k, v), map.insert(k, v)),
                    Op::Remove(k) => {
                        prop_assert_eq!(slots.contains_key(&k), map.contains_key(&k));
                        prop_assert_eq!(slots.get(&k), map.get(&k));
                        // Taken and never put back: removed, to every query.
                        prop_assert_eq!(slots.take(&k), map.remove(&k));
                    }
                    Op::Bump(k) => {
                        if let (Some(a), Some(b)) = (slots.get_mut(&k), map.get_mut(&k)) {
                            *a += 1;
                            *b += 1;
                        }
                        for v in slots.values_mut() {
                            *v = v.wrapping_mul(3);
                        }
                        for v in map.values_mut() {
                            *v = v.wrapping_mul(3);
                        }
                    }
                }
                prop_assert_eq!(slots.len(), map.len());
                let walked: Vec<_> = slots.iter().map(|(k, v)| (k, *v)).collect();
                let expected: Vec<_> = map.iter().map(|(k, v)| (*k, *v)).collect();
                prop_assert_eq!(walked, expected);
                prop_assert!(slots.keys().eq(map.keys().copied()));
                prop_assert!(slots.values().eq(map.values()));
                for (k, v) in &map {
                    prop_assert!(slots.contains_key(k));
                    prop_assert_eq!(slots.get(k), Some(v));
                    prop_assert_eq!(&slots[k], v);
                }
            }
        }
    }
}
