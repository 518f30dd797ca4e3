//! A robot's interaction instances, by key, in key order.
//!
//! A robot runs a handful of instances at a time (one per point on its
//! stack, and the few that linger to answer late teammates), started and
//! ended at every decision. A sorted vector of boxed instances finds one
//! by binary search over keys held side by side and walks them in key order
//! without chasing tree nodes; a B-tree did the same with an allocation
//! and a rebalancing per change (a tenth of a decision step).

use super::Instance;
use crate::ids::InstanceKey;

/// Instances by key.
pub(super) type Instances = Slots<Box<Instance>>;

/// Values by instance key, in key order: the part of `BTreeMap`'s
/// interface the kernel uses, with the same answers (tested against it).
pub(super) struct Slots<V> {
    /// Sorted by key, keys unique.
    slots: Vec<(InstanceKey, V)>,
}

impl<V> Default for Slots<V> {
    fn default() -> Self {
        Slots { slots: Vec::new() }
    }
}

impl<V> Slots<V> {
    fn find(&self, key: &InstanceKey) -> Result<usize, usize> {
        self.slots.binary_search_by(|(k, _)| k.cmp(key))
    }

    /// See [`super::Kernel::prefetch`].
    pub(super) fn prefetch(&self) {
        crate::hint::prefetch_slice(&self.slots, 2);
    }

    pub(super) fn len(&self) -> usize {
        self.slots.len()
    }

    pub(super) fn contains_key(&self, key: &InstanceKey) -> bool {
        self.find(key).is_ok()
    }

    pub(super) fn get(&self, key: &InstanceKey) -> Option<&V> {
        self.find(key).ok().map(|i| &self.slots[i].1)
    }

    pub(super) fn get_mut(&mut self, key: &InstanceKey) -> Option<&mut V> {
        match self.find(key) {
            Ok(i) => Some(&mut self.slots[i].1),
            Err(_) => None,
        }
    }

    /// Put `value` under `key`, returning the value it replaces.
    pub(super) fn insert(&mut self, key: InstanceKey, value: V) -> Option<V> {
        match self.find(&key) {
            Ok(i) => Some(std::mem::replace(&mut self.slots[i].1, value)),
            Err(i) => {
                self.slots.insert(i, (key, value));
                None
            }
        }
    }

    pub(super) fn remove(&mut self, key: &InstanceKey) -> Option<V> {
        self.find(key).ok().map(|i| self.slots.remove(i).1)
    }

    /// Every value with its key, in key order.
    pub(super) fn iter(&self) -> impl Iterator<Item = (&InstanceKey, &V)> {
        self.slots.iter().map(|(k, v)| (k, v))
    }

    pub(super) fn keys(&self) -> impl Iterator<Item = &InstanceKey> {
        self.slots.iter().map(|(k, _)| k)
    }

    pub(super) fn values(&self) -> impl Iterator<Item = &V> {
        self.slots.iter().map(|(_, v)| v)
    }

    pub(super) fn values_mut(&mut self) -> impl Iterator<Item = &mut V> {
        self.slots.iter_mut().map(|(_, v)| v)
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
        ]
    }

    proptest! {
        /// Every operation answers as `BTreeMap`'s does, and the walk is
        /// the map's, in its order.
        #[test]
        fn slots_answer_as_a_b_tree_map_does(ops in proptest::collection::vec(op(), 0..200)) {
            let mut slots = Slots::default();
            let mut map = BTreeMap::new();
            for op in ops {
                match op {
                    Op::Insert(k, v) => prop_assert_eq!(slots.insert(k, v), map.insert(k, v)),
                    Op::Remove(k) => {
                        prop_assert_eq!(slots.contains_key(&k), map.contains_key(&k));
                        prop_assert_eq!(slots.get(&k), map.get(&k));
                        prop_assert_eq!(slots.remove(&k), map.remove(&k));
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
                let walked: Vec<_> = slots.iter().map(|(k, v)| (*k, *v)).collect();
                let expected: Vec<_> = map.iter().map(|(k, v)| (*k, *v)).collect();
                prop_assert_eq!(walked, expected);
                prop_assert!(slots.keys().eq(map.keys()));
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
