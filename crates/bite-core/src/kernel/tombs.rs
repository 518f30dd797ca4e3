//! Outcomes of forgotten instances, kept to answer late teammates: the
//! newest [`TOMBSTONES`](super::TOMBSTONES) in the order they were buried,
//! looked up by key.
//!
//! One ring of (key, outcome) in burial order and a table of positions in
//! it: the hash map of outcomes beside a queue of keys stored every key
//! twice, a sixth of a robot's memory of finished work at 100,000 robots
//! (docs/performance.md, "2026-11-28, late").

use crate::ids::InstanceKey;
use crate::interaction::Closed;
use std::collections::VecDeque;
use std::hash::BuildHasher;

/// Buried instances' outcomes, oldest first.
#[derive(Clone, Debug, Default)]
pub(super) struct Tombstones {
    /// (key, outcome) in burial order.
    ring: VecDeque<(InstanceKey, Closed)>,
    /// Each key's burial number (its place in `ring` is that minus
    /// `first`, wrapping).
    index: hashbrown::HashTable<u32>,
    /// The burial number of `ring[0]`.
    first: u32,
}

fn hash(key: &InstanceKey) -> u64 {
    rustc_hash::FxBuildHasher.hash_one(key)
}

impl Tombstones {
    fn place(&self, n: u32) -> usize {
        n.wrapping_sub(self.first) as usize
    }

    /// The outcome buried under `key`.
    pub fn get(&self, key: &InstanceKey) -> Option<&Closed> {
        let n = self
            .index
            .find(hash(key), |&n| self.ring[self.place(n)].0 == *key)?;
        Some(&self.ring[self.place(*n)].1)
    }

    /// Bury `key` with `closed` (a key buried again keeps its place and
    /// takes the new outcome); the oldest go beyond `most`.
    pub fn bury(&mut self, key: InstanceKey, closed: Closed, most: usize) {
        let h = hash(&key);
        let (ring, first) = (&mut self.ring, self.first);
        if let Some(&n) = self
            .index
            .find(h, |&n| ring[n.wrapping_sub(first) as usize].0 == key)
        {
            ring[n.wrapping_sub(first) as usize].1 = closed;
        } else {
            let n = first.wrapping_add(ring.len() as u32);
            ring.push_back((key, closed));
            let ring = &self.ring;
            self.index
                .insert_unique(h, n, |&m| hash(&ring[m.wrapping_sub(first) as usize].0));
        }
        while self.ring.len() > most {
            let Some((old, _)) = self.ring.pop_front() else {
                break;
            };
            let first = self.first;
            if let Ok(e) = self.index.find_entry(hash(&old), |&n| n == first) {
                e.remove();
            }
            self.first = first.wrapping_add(1);
        }
    }

    /// How many are kept.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.ring.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::{BehaviorId, Kind, TeamId};
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    fn key(i: u32) -> InstanceKey {
        InstanceKey {
            team: TeamId(u64::from(i % 3)),
            behavior: BehaviorId(i),
            kind: Kind::Sync,
            epoch: 1,
            round: 0,
        }
    }

    proptest! {
        /// The same answers as a map of outcomes beside a queue of keys
        /// (what it replaces), whatever the burials, repeats included.
        #[test]
        fn answers_as_a_map_beside_a_queue(
            burials in proptest::collection::vec((0u32..40, proptest::option::of(0u32..5)), 0..300),
            most in 1usize..20,
        ) {
            let mut t = Tombstones::default();
            let mut map: BTreeMap<InstanceKey, Closed> = BTreeMap::new();
            let mut order: VecDeque<InstanceKey> = VecDeque::new();
            for (k, choice) in burials {
                let closed = Closed::Synced(choice.map(BehaviorId));
                t.bury(key(k), closed.clone(), most);
                if map.insert(key(k), closed).is_none() {
                    order.push_back(key(k));
                }
                while order.len() > most {
                    if let Some(old) = order.pop_front() {
                        map.remove(&old);
                    }
                }
                prop_assert_eq!(t.len(), map.len());
                for i in 0..40 {
                    prop_assert_eq!(t.get(&key(i)), map.get(&key(i)));
                }
            }
        }
    }
}
