//! The teammates a robot heard lately ([`Peer`]), by robot.
//!
//! Three forms, by how many: two short vectors side by side while they are
//! a handful (a member hears its leaders), a hash map beyond, a table
//! indexed by roster place once they are a large share of the roster (a
//! leader hearing every member of a large team). At 100,000 robots half of
//! all heartbeats go to the root team's leader and half to members with at
//! most eight teammates heard: in a hash map each cost two cache misses
//! (the control bytes, then the entry). The vectors and the table are
//! where the simulator can ask for them ahead of the heartbeat without
//! reading memory ([`Peers::prefetch`]; docs/performance.md, "2026-11-28,
//! night: heartbeats at 100,000 robots").

use super::position::Peer;
use crate::ids::RobotId;
use rustc_hash::FxHashMap;

/// The most teammates heard kept in two short vectors (their ids fill a
/// cache line); a hash map beyond.
const FEW: usize = 16;
/// A hash map goes back to vectors once they are this few.
const FEW_AGAIN: usize = 8;
/// The fewest teammates heard that make a table (below, a hash map of a
/// few hundred entries stays in the cache anyway).
const TABLE_FROM: usize = 1024;
/// A table is made once the teammates heard are this share of the roster
/// (one in four: the table's empty slots cost at most three entries per
/// entry, a hash map's up to one).
const TABLE_SHARE: usize = 4;
/// A table goes back to a hash map once they are fewer than this share
/// (one in sixteen: far below the share that makes one, so a team that
/// hovers around it does not switch back and forth).
const MAP_SHARE: usize = 16;

/// Teammates heard, by robot. Nothing reads them in an order that matters.
#[derive(Clone, Debug)]
pub(super) enum Peers {
    /// A handful: their ids, and what each said at the same place.
    Few { ids: Vec<RobotId>, peers: Vec<Peer> },
    /// More: by hash.
    Map(FxHashMap<RobotId, Peer>),
    /// Many: by roster place, and how many are there.
    Table {
        slots: Vec<Option<Peer>>,
        len: usize,
    },
}

impl Default for Peers {
    fn default() -> Self {
        Peers::Few {
            ids: Vec::new(),
            peers: Vec::new(),
        }
    }
}

impl Peers {
    #[cfg(test)]
    pub fn len(&self) -> usize {
        match self {
            Peers::Few { ids, .. } => ids.len(),
            Peers::Map(m) => m.len(),
            Peers::Table { len, .. } => *len,
        }
    }

    pub fn get(&self, r: &RobotId) -> Option<&Peer> {
        match self {
            Peers::Few { ids, peers } => peers.get(ids.iter().position(|x| x == r)?),
            Peers::Map(m) => m.get(r),
            Peers::Table { slots, .. } => slots.get(r.index())?.as_ref(),
        }
    }

    pub fn get_mut(&mut self, r: &RobotId) -> Option<&mut Peer> {
        match self {
            Peers::Few { ids, peers } => peers.get_mut(ids.iter().position(|x| x == r)?),
            Peers::Map(m) => m.get_mut(r),
            Peers::Table { slots, .. } => slots.get_mut(r.index())?.as_mut(),
        }
    }

    #[cfg(test)]
    pub fn contains_key(&self, r: &RobotId) -> bool {
        self.get(r).is_some()
    }

    /// The entry of `r`, made with `new` if absent; `None` only for a
    /// robot off the roster of `roster_len` robots (which the caller
    /// checks first).
    pub fn get_or_insert_with(
        &mut self,
        r: RobotId,
        roster_len: usize,
        new: impl FnOnce() -> Peer,
    ) -> Option<&mut Peer> {
        if self.get(&r).is_none() {
            self.insert(r, new(), roster_len);
        }
        self.get_mut(&r)
    }

    /// Keep `p` for `r`, on a roster of `roster_len` robots (checked by the
    /// caller: `r.index() < roster_len`).
    pub fn insert(&mut self, r: RobotId, p: Peer, roster_len: usize) {
        if let Some(q) = self.get_mut(&r) {
            *q = p;
            return;
        }
        if let Peers::Few { ids, peers } = self {
            if ids.len() < FEW {
                ids.push(r);
                peers.push(p);
                return;
            }
            let m = ids.drain(..).zip(peers.drain(..)).collect();
            *self = Peers::Map(m);
        }
        if let Peers::Map(m) = self {
            let n = m.len() + 1;
            if n >= TABLE_FROM && n * TABLE_SHARE >= roster_len && r.index() < roster_len {
                let mut slots: Vec<Option<Peer>> = Vec::new();
                slots.resize_with(roster_len, || None);
                let mut len = 0;
                for (q, peer) in m.drain() {
                    if let Some(s) = slots.get_mut(q.index()) {
                        *s = Some(peer);
                        len += 1;
                    }
                }
                *self = Peers::Table { slots, len };
            }
        }
        match self {
            Peers::Few { .. } => {}
            Peers::Map(m) => {
                m.insert(r, p);
            }
            Peers::Table { slots, len } => {
                if let Some(s) = slots.get_mut(r.index()) {
                    *len += usize::from(s.is_none());
                    *s = Some(p);
                }
            }
        }
    }

    /// Each teammate heard and what it said, in no order that matters.
    pub fn iter(&self) -> Box<dyn Iterator<Item = (RobotId, &Peer)> + '_> {
        match self {
            Peers::Few { ids, peers } => Box::new(ids.iter().copied().zip(peers)),
            Peers::Map(m) => Box::new(m.iter().map(|(r, p)| (*r, p))),
            Peers::Table { slots, .. } => Box::new(
                (slots.iter().enumerate())
                    .filter_map(|(i, p)| Some((RobotId(i as u32), p.as_ref()?))),
            ),
        }
    }

    /// Keep only the teammates `keep` says to, then give back room: a
    /// table that became sparse goes back to a hash map (or vectors, if a
    /// handful are left), a hash map of a handful back to vectors, a hash
    /// map or vectors that shrank give back most of their room.
    pub fn retain(&mut self, mut keep: impl FnMut(RobotId, &Peer) -> bool) {
        match self {
            Peers::Few { ids, peers } => {
                let mut i = 0;
                while i < ids.len() {
                    if keep(ids[i], &peers[i]) {
                        i += 1;
                    } else {
                        ids.swap_remove(i);
                        peers.swap_remove(i);
                    }
                }
                if peers.capacity() > 2 * peers.len() + 1 {
                    ids.shrink_to_fit();
                    peers.shrink_to_fit();
                }
            }
            Peers::Map(m) => {
                m.retain(|r, p| keep(*r, p));
                if m.len() <= FEW_AGAIN {
                    let (ids, peers) = m.drain().unzip();
                    *self = Peers::Few { ids, peers };
                } else if m.capacity() > 4 * m.len() + 4 {
                    m.shrink_to_fit();
                }
            }
            Peers::Table { slots, len } => {
                for (i, s) in slots.iter_mut().enumerate() {
                    if s.as_ref().is_some_and(|p| !keep(RobotId(i as u32), p)) {
                        *s = None;
                        *len -= 1;
                    }
                }
                if *len * MAP_SHARE < slots.len() {
                    let left = (slots.iter_mut().enumerate())
                        .filter_map(|(i, s)| Some((RobotId(i as u32), s.take()?)));
                    *self = if *len <= FEW_AGAIN {
                        let (ids, peers) = left.unzip();
                        Peers::Few { ids, peers }
                    } else {
                        Peers::Map(left.collect())
                    };
                }
            }
        }
    }

    /// Ask for `r`'s entry to be brought into the cache ahead of its
    /// heartbeat (a hint): a table's entry, or a handful's ids and the
    /// first two entries (a member mostly hears its one or two leaders,
    /// the first it heard); a hash map's place is known only by reading it.
    pub fn prefetch(&self, r: RobotId) {
        match self {
            Peers::Few { .. } => self.prefetch_handful(),
            Peers::Map(_) => {}
            Peers::Table { slots, .. } => {
                crate::hint::prefetch_lines(slots.as_ptr().wrapping_add(r.index()), 2);
            }
        }
    }

    /// Ask for a handful's ids and first entries to be brought into the
    /// cache (a hint; nothing for more): where a member's leaders are,
    /// which it reads before it sends a heartbeat.
    pub fn prefetch_handful(&self) {
        if let Peers::Few { ids, peers } = self {
            crate::hint::prefetch_slice(ids, 1);
            crate::hint::prefetch_slice(peers, 4);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::Time;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    fn peer(t: u64) -> Peer {
        Peer {
            heard: Time::from_millis(t),
            ..Peer::default()
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// The same answers as a map, whatever the inserts and removals,
        /// across the switches between the three forms (a roster of 1,200:
        /// a table once 1,024 are heard within the last 4,000 steps).
        #[test]
        fn answers_as_a_map(
            ops in proptest::collection::vec((0u32..1200, 0u8..4), 0..8000),
        ) {
            let roster = 1200;
            let mut p = Peers::default();
            let mut map: BTreeMap<u32, u64> = BTreeMap::new();
            for (k, (r, op)) in ops.into_iter().enumerate() {
                let t = k as u64;
                match op {
                    0 | 1 => {
                        p.insert(RobotId(r), peer(t), roster);
                        map.insert(r, t);
                    }
                    2 => {
                        let e = p.get_or_insert_with(RobotId(r), roster, || peer(t));
                        let v = *map.entry(r).or_insert(t);
                        prop_assert_eq!(e.map(|e| e.heard), Some(Time::from_millis(v)));
                    }
                    _ => {
                        // Forget those heard before `t - 4000`.
                        let cut = t.saturating_sub(4000);
                        p.retain(|_, q| q.heard >= Time::from_millis(cut));
                        map.retain(|_, v| *v >= cut);
                    }
                }
                // Each form where its size says, once a retain has looked.
                if op == 3 {
                    let n = map.len();
                    match &p {
                        Peers::Few { .. } => prop_assert!(n <= FEW),
                        Peers::Map(_) => prop_assert!(n > FEW_AGAIN),
                        Peers::Table { .. } => prop_assert!(n * MAP_SHARE >= roster),
                    }
                }
                prop_assert_eq!(p.len(), map.len());
                for r in [0u32, 7, 600, 1199, r] {
                    prop_assert_eq!(
                        p.get(&RobotId(r)).map(|q| q.heard),
                        map.get(&r).map(|t| Time::from_millis(*t))
                    );
                }
                if op != 3 {
                    continue;
                }
                let mut seen: Vec<(u32, Time)> = p.iter().map(|(r, q)| (r.0, q.heard)).collect();
                seen.sort_unstable_by_key(|(r, _)| *r);
                let want: Vec<(u32, Time)> =
                    map.iter().map(|(r, t)| (*r, Time::from_millis(*t))).collect();
                prop_assert_eq!(seen, want);
            }
        }
    }

    /// A leader that hears a quarter of a large roster keeps a table, and
    /// goes back to a map when most of them go quiet, then to vectors.
    #[test]
    fn many_teammates_make_a_table_and_few_a_map_again() {
        let roster = 8 * TABLE_FROM;
        let mut p = Peers::default();
        for r in 0..(roster / TABLE_SHARE) as u32 {
            p.insert(RobotId(r), peer(u64::from(r)), roster);
        }
        assert!(matches!(p, Peers::Table { .. }));
        assert_eq!(p.len(), roster / TABLE_SHARE);
        p.retain(|r, _| r.index() < 100);
        assert!(matches!(p, Peers::Map(_)));
        assert_eq!(p.len(), 100);
        assert_eq!(
            p.get(&RobotId(99)).map(|q| q.heard),
            Some(Time::from_millis(99))
        );
        p.retain(|r, _| r.index() < FEW_AGAIN);
        assert!(matches!(p, Peers::Few { .. }));
        assert_eq!(
            p.get(&RobotId(3)).map(|q| q.heard),
            Some(Time::from_millis(3))
        );
        p.retain(|_, _| false);
        assert_eq!(p.len(), 0);
        // A table whose teammates nearly all went quiet at once: vectors.
        for r in 0..(roster / TABLE_SHARE) as u32 {
            p.insert(RobotId(r), peer(u64::from(r)), roster);
        }
        assert!(matches!(p, Peers::Table { .. }));
        p.retain(|r, _| r.index() < 2);
        assert!(matches!(p, Peers::Few { .. }));
        assert_eq!(p.len(), 2);
        // Out of the roster: not kept by a table (the caller checks first).
        p.prefetch(RobotId(u32::MAX));
    }
}
