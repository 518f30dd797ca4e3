//! Sets of robots, and allocations of them to behaviors: the vocabulary the
//! organization hierarchy, messages and run-log events share.

use crate::ids::{BehaviorId, Fnv1a, RobotId};
use fixedbitset::FixedBitSet;
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::{OnceLock, Weak};

/// Members kept in place, without a heap allocation.
const INLINE: usize = 4;

/// A set of robots of a roster.
///
/// Small sets are sorted lists (up to four members in place, without an
/// allocation), large ones a bit per robot of the roster (10,000 robots
/// take 1.25 KB): an allocation of 10,000 robots to 10,000 children is
/// 10,000 one-member lists, not 10,000 bit sets of 10,000 bits. Which form
/// a set takes is invisible: equality, fingerprints and the wire form are
/// those of the bit set.
#[derive(Clone, Debug)]
pub struct MemberSet {
    roster: u32,
    repr: Repr,
}

#[derive(Clone, Debug)]
enum Repr {
    /// Up to [`INLINE`] members, sorted.
    Few { n: u8, ids: [u32; INLINE] },
    /// Sorted members.
    List(Vec<u32>),
    /// A bit per robot of the roster, shared between copies until one of
    /// them changes (a set the size of the roster, per holder, made the
    /// simulator's memory grow with the square of the team: every member
    /// of a team of 100,000 held its own copy of who departed).
    Bits(Arc<Bits>),
}

/// A bit set shared between copies of a [`MemberSet`], with the answers to
/// the first questions asked of it (see [`MemberSet::news`]).
#[derive(Debug, Default)]
struct Bits {
    set: FixedBitSet,
    news: OnceLock<Memo>,
    /// [`MemberSet::is_subset`]'s answer for the first superset asked
    /// about (a bit set, named by address as in [`Memo`]).
    subset_of: OnceLock<(Weak<Bits>, bool)>,
    /// Its number of members, once counted.
    len: OnceLock<usize>,
    /// Members before each word, once a rank was asked of a large set.
    ranks: OnceLock<Box<[u32]>>,
}

/// Sets of more words than this keep a table of ranks (see
/// [`Bits::rank`]); smaller ones are counted.
const RANK_TABLE_FROM: usize = 8;

/// [`MemberSet::news`]'s answer for one pair of other sets, named by
/// address (the weak pointers keep the addresses from being reused; a set
/// changed in place while one is held moves to a new address, see
/// [`Bits::make_mut`]).
#[derive(Debug)]
struct Memo {
    within: Weak<Bits>,
    known: Option<Weak<Bits>>,
    news: News,
}

impl Bits {
    fn shared(set: FixedBitSet) -> Arc<Bits> {
        Arc::new(Bits {
            set,
            ..Bits::default()
        })
    }
    /// `a ⊆ b`. The answer for the first superset asked about is kept (a
    /// leader's report, shared by its team's members, each asking whether
    /// it names only the team's members; what is new in it, shared the
    /// same way, each asking whether it knew it already).
    fn subset(a: &Arc<Bits>, b: &Arc<Bits>) -> bool {
        if Arc::ptr_eq(a, b) {
            return true;
        }
        if let Some((of, yes)) = a.subset_of.get() {
            if Weak::as_ptr(of) == Arc::as_ptr(b) {
                return *yes;
            }
            return a.set.is_subset(&b.set);
        }
        let yes = a.set.is_subset(&b.set);
        let _ = a.subset_of.set((Arc::downgrade(b), yes));
        yes
    }
    /// The bits to change: copied when shared, moved to a new address when
    /// a memo names them (so that no memo answers for the changed set),
    /// and without a memo of their own.
    fn make_mut(this: &mut Arc<Bits>) -> &mut FixedBitSet {
        let b = Arc::make_mut(this);
        b.news = OnceLock::new();
        b.subset_of = OnceLock::new();
        b.len = OnceLock::new();
        b.ranks = OnceLock::new();
        &mut b.set
    }
    /// How many members are below `i`. Every robot of a team asks its rank
    /// in the team's (shared) set at every control tick: a large set keeps
    /// the members before each of its words, so that each robot reads two
    /// words rather than the roster's.
    fn rank(&self, i: usize) -> usize {
        const WORD: usize = usize::BITS as usize;
        let words = self.set.as_slice();
        let i = i.min(self.set.len());
        if words.len() <= RANK_TABLE_FROM {
            return self.set.count_ones(..i);
        }
        let table = self.ranks.get_or_init(|| {
            let mut before = 0u32;
            words
                .iter()
                .map(|w| {
                    let at = before;
                    before += w.count_ones();
                    at
                })
                .collect()
        });
        let (w, bit) = (i / WORD, i % WORD);
        match (table.get(w), words.get(w)) {
            (Some(before), Some(word)) => {
                *before as usize + (word & ((1usize << bit) - 1)).count_ones() as usize
            }
            // `i` is the set's length, a whole number of words: every member.
            _ => *self.len.get_or_init(|| self.set.count_ones(..)),
        }
    }
}

/// A copy has no memo.
impl Clone for Bits {
    fn clone(&self) -> Self {
        Bits {
            set: self.set.clone(),
            ..Bits::default()
        }
    }
}

impl std::ops::Deref for Bits {
    type Target = FixedBitSet;
    #[inline]
    fn deref(&self) -> &FixedBitSet {
        &self.set
    }
}

/// What a teammate's report of who departed tells a robot
/// ([`MemberSet::news`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct News {
    /// Members of the report that are in the team and not known yet
    /// (`None`: there are none).
    pub fresh: Option<MemberSet>,
    /// The report holds every robot already known.
    pub covers: bool,
}

/// Members in increasing id order.
pub enum Members<'a> {
    /// Of a list.
    List(std::slice::Iter<'a, u32>),
    /// Of a bit set.
    Bits(fixedbitset::Ones<'a>),
}

impl Iterator for Members<'_> {
    type Item = RobotId;
    #[inline]
    fn next(&mut self) -> Option<RobotId> {
        match self {
            Members::List(it) => it.next().map(|i| RobotId(*i)),
            Members::Bits(it) => it.next().map(|i| RobotId(i as u32)),
        }
    }
}

impl MemberSet {
    /// The empty set over a roster of `roster_len` robots.
    pub fn empty(roster_len: usize) -> Self {
        MemberSet {
            roster: roster_len as u32,
            repr: Repr::Few {
                n: 0,
                ids: [0; INLINE],
            },
        }
    }
    /// Every robot of a roster of `roster_len`.
    pub fn all(roster_len: usize) -> Self {
        if roster_len <= INLINE {
            return Self::from_sorted(roster_len, (0..roster_len as u32).collect());
        }
        let mut s = FixedBitSet::with_capacity(roster_len);
        s.insert_range(..);
        MemberSet {
            roster: roster_len as u32,
            repr: Repr::Bits(Bits::shared(s)),
        }
    }
    /// The set of the given robots (ids beyond `roster_len` are ignored).
    pub fn from_iter(roster_len: usize, robots: impl IntoIterator<Item = RobotId>) -> Self {
        let mut v: Vec<u32> = robots
            .into_iter()
            .filter(|r| r.index() < roster_len)
            .map(|r| r.0)
            .collect();
        v.sort_unstable();
        v.dedup();
        Self::from_sorted(roster_len, v)
    }
    /// True when a set of `n` members of a roster of `roster` is kept as a
    /// bit set: when that takes less room than the list, or once the list
    /// is longer than 64 (a set that grows one member at a time, such as
    /// the teammates done with a behavior, does not shift a long list).
    fn dense(n: usize, roster: usize) -> bool {
        n > INLINE && n > (roster / 32).min(64)
    }
    /// The set of `ids`, sorted, without repeats, all in the roster.
    fn from_sorted(roster_len: usize, ids: Vec<u32>) -> Self {
        let repr = if ids.len() <= INLINE {
            let mut a = [0; INLINE];
            a[..ids.len()].copy_from_slice(&ids);
            Repr::Few {
                n: ids.len() as u8,
                ids: a,
            }
        } else if Self::dense(ids.len(), roster_len) {
            let mut s = FixedBitSet::with_capacity(roster_len);
            for i in ids {
                s.insert(i as usize);
            }
            Repr::Bits(Bits::shared(s))
        } else {
            Repr::List(ids)
        };
        MemberSet {
            roster: roster_len as u32,
            repr,
        }
    }
    /// The sorted members, when the set is a list.
    #[inline]
    fn list(&self) -> Option<&[u32]> {
        match &self.repr {
            Repr::Few { n, ids } => Some(&ids[..*n as usize]),
            Repr::List(v) => Some(v),
            Repr::Bits(_) => None,
        }
    }
    /// The set as a bit set (borrowed when it is one).
    fn bits(&self) -> std::borrow::Cow<'_, FixedBitSet> {
        match &self.repr {
            Repr::Bits(b) => std::borrow::Cow::Borrowed(&b.set),
            _ => {
                let mut b = FixedBitSet::with_capacity(self.roster as usize);
                for r in self.iter() {
                    b.insert(r.index());
                }
                std::borrow::Cow::Owned(b)
            }
        }
    }
    /// Its size in postcard's wire form (see `Serialize` below), counted
    /// without writing it: the bit set's length, then its blocks as bytes.
    /// A set held as a list is not turned into a bit set to be counted (a
    /// leader's heartbeat counted its departed sets once per member).
    pub fn wire_len(&self) -> usize {
        let (length, blocks) = match &self.repr {
            Repr::Bits(b) => (b.set.len(), b.set.as_slice().len()),
            _ => {
                let roster = self.roster as usize;
                (roster, roster.div_ceil(usize::BITS as usize))
            }
        };
        let bytes = blocks * std::mem::size_of::<usize>();
        varint_len(length as u64) + varint_len(bytes as u64) + bytes
    }
    /// Add a robot (ignored if outside the roster). Returns whether it was new.
    pub fn insert(&mut self, r: RobotId) -> bool {
        if r.index() >= self.roster as usize {
            return false;
        }
        let roster = self.roster as usize;
        match &mut self.repr {
            Repr::Bits(b) => {
                if b.contains(r.index()) {
                    return false;
                }
                return !Bits::make_mut(b).put(r.index());
            }
            Repr::Few { n, ids } => {
                let len = *n as usize;
                let Err(at) = ids[..len].binary_search(&r.0) else {
                    return false;
                };
                if len < INLINE {
                    ids.copy_within(at..len, at + 1);
                    ids[at] = r.0;
                    *n += 1;
                    return true;
                }
                let mut v = Vec::with_capacity(2 * INLINE);
                v.extend_from_slice(&ids[..at]);
                v.push(r.0);
                v.extend_from_slice(&ids[at..len]);
                self.repr = Repr::List(v);
            }
            Repr::List(v) => {
                if v.last().is_some_and(|l| *l < r.0) {
                    v.push(r.0);
                } else {
                    let Err(at) = v.binary_search(&r.0) else {
                        return false;
                    };
                    v.insert(at, r.0);
                }
            }
        }
        if let Repr::List(v) = &self.repr
            && Self::dense(v.len(), roster)
        {
            let v = std::mem::take(self.list_mut());
            *self = Self::from_sorted(roster, v);
        }
        true
    }
    fn list_mut(&mut self) -> &mut Vec<u32> {
        match &mut self.repr {
            Repr::List(v) => v,
            _ => unreachable!("only called on lists"),
        }
    }
    /// Remove a robot.
    pub fn remove(&mut self, r: RobotId) {
        match &mut self.repr {
            Repr::Bits(b) => {
                if r.index() < b.len() && b.contains(r.index()) {
                    Bits::make_mut(b).set(r.index(), false);
                }
            }
            Repr::Few { n, ids } => {
                let len = *n as usize;
                if let Ok(at) = ids[..len].binary_search(&r.0) {
                    ids.copy_within(at + 1..len, at);
                    *n -= 1;
                }
            }
            Repr::List(v) => {
                if let Ok(at) = v.binary_search(&r.0) {
                    v.remove(at);
                }
            }
        }
    }
    /// Membership test.
    #[inline]
    pub fn contains(&self, r: RobotId) -> bool {
        match &self.repr {
            Repr::Few { n, ids } => ids[..*n as usize].contains(&r.0),
            Repr::List(v) => v.binary_search(&r.0).is_ok(),
            Repr::Bits(b) => b.contains(r.index()),
        }
    }
    /// Number of members.
    pub fn len(&self) -> usize {
        match &self.repr {
            // Counted once per shared set (every robot of a team of
            // 100,000 counts the same roster).
            Repr::Bits(b) => *b.len.get_or_init(|| b.set.count_ones(..)),
            _ => self.list().map_or(0, <[u32]>::len),
        }
    }
    /// The `i`-th word of the set's bit set (the members in
    /// `[w i, w i + w)`, `w` bits to a word).
    fn word(&self, i: usize) -> usize {
        const WORD: usize = usize::BITS as usize;
        match &self.repr {
            Repr::Bits(b) => b.as_slice().get(i).copied().unwrap_or(0),
            _ => {
                let list = self.list().unwrap_or_default();
                let lo = i * WORD;
                let from = list.partition_point(|x| (*x as usize) < lo);
                let mut word = 0;
                for x in &list[from..] {
                    let at = *x as usize - lo;
                    if at >= WORD {
                        break;
                    }
                    word |= 1 << at;
                }
                word
            }
        }
    }
    /// The first member, in id order, that is `keep` or in none of the
    /// sets `without` yields (called again for every word). Word by word
    /// when this set is a bit set: a team leader is the first member not
    /// departed, and in a large team the first tens of thousands may have
    /// departed.
    pub fn first_not_in<'a, I>(&self, keep: RobotId, without: impl Fn() -> I) -> Option<RobotId>
    where
        I: Iterator<Item = &'a MemberSet>,
    {
        const WORD: usize = usize::BITS as usize;
        let Repr::Bits(b) = &self.repr else {
            return self
                .iter()
                .find(|r| *r == keep || !without().any(|s| s.contains(*r)));
        };
        for (i, &word) in b.as_slice().iter().enumerate() {
            if word == 0 {
                continue;
            }
            let mut m = word;
            for s in without() {
                m &= !s.word(i);
                if m == 0 {
                    break;
                }
            }
            if keep.index() / WORD == i {
                m |= word & (1 << (keep.index() % WORD));
            }
            if m != 0 {
                return Some(RobotId((i * WORD) as u32 + m.trailing_zeros()));
            }
        }
        None
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        match &self.repr {
            Repr::Bits(b) => b.is_clear(),
            _ => self.list().is_none_or(<[u32]>::is_empty),
        }
    }
    /// How many members have a lower id than `r` (its 0-based rank when
    /// it is a member).
    pub fn rank(&self, r: RobotId) -> usize {
        match (&self.repr, self.list()) {
            (Repr::Bits(b), _) => b.rank(r.index()),
            (_, Some(l)) => l.partition_point(|x| *x < r.0),
            _ => 0,
        }
    }
    /// Members in increasing id order.
    pub fn iter(&self) -> Members<'_> {
        match &self.repr {
            Repr::Bits(b) => Members::Bits(b.ones()),
            _ => Members::List(self.list().unwrap_or_default().iter()),
        }
    }
    /// The lowest member.
    pub fn first(&self) -> Option<RobotId> {
        match &self.repr {
            Repr::Bits(b) => b.minimum().map(|i| RobotId(i as u32)),
            _ => self.list().and_then(|l| l.first()).map(|i| RobotId(*i)),
        }
    }
    /// Size of the roster this set ranges over.
    pub fn roster_len(&self) -> usize {
        self.roster as usize
    }
    /// True when every member of `self` is in `other`.
    pub fn is_subset(&self, other: &MemberSet) -> bool {
        match (&self.repr, &other.repr) {
            // One shared set (a leader's report a member kept): no need to
            // read the roster's words.
            (Repr::Bits(a), Repr::Bits(b)) if Arc::ptr_eq(a, b) => true,
            (Repr::Bits(a), Repr::Bits(b)) => Bits::subset(a, b),
            _ => self.iter().all(|r| other.contains(r)),
        }
    }
    /// What this set, a teammate's report of who departed a behavior,
    /// tells a robot that knows `known` departed, in a team of `within`:
    /// who is new, and whether the report holds all the robot knew.
    ///
    /// Word by word when the sets are bit sets (a leader's report in a
    /// large team): O(n / 64), nothing allocated when nothing is new, and
    /// what is new comes as words too, added to what the robot knows the
    /// same way ([`MemberSet::union_with`]). A team's members hear the
    /// same report and mostly know the same (the report before it, kept
    /// as it is): copies of a set share their bits, and the answer for
    /// the first pair of sets asked about is kept with the report, so that
    /// in the simulator a team of n reads a report once, not n times
    /// (n² / 64 words a heartbeat for the team).
    pub fn news(&self, within: &MemberSet, known: Option<&MemberSet>) -> News {
        // What this robot knows is the report itself (it kept the leader's
        // report, and the leader's next heartbeat carries the same one):
        // nothing is new, and the roster's words need not be read.
        if known.is_some_and(|k| k.shares_bits(self)) {
            return News {
                fresh: None,
                covers: true,
            };
        }
        let (Repr::Bits(me), Repr::Bits(w)) = (&self.repr, &within.repr) else {
            return self.read_news(within, known);
        };
        let k = match known.map(|k| &k.repr) {
            None => None,
            Some(Repr::Bits(k)) => Some(k),
            Some(_) => return self.read_news(within, known),
        };
        let asked = |m: &Memo| {
            Weak::as_ptr(&m.within) == Arc::as_ptr(w)
                && match (&m.known, k) {
                    (None, None) => true,
                    (Some(a), Some(b)) => Weak::as_ptr(a) == Arc::as_ptr(b),
                    _ => false,
                }
        };
        if let Some(m) = me.news.get() {
            if asked(m) {
                return m.news.clone();
            }
            return self.read_news(within, known);
        }
        let news = self.read_news(within, known);
        // Another thread may have answered another question first: then
        // this one is not kept.
        let _ = me.news.set(Memo {
            within: Arc::downgrade(w),
            known: k.map(Arc::downgrade),
            news: news.clone(),
        });
        news
    }
    /// [`MemberSet::news`], read from the sets.
    fn read_news(&self, within: &MemberSet, known: Option<&MemberSet>) -> News {
        let known_bits = match known.map(|k| &k.repr) {
            None => Some(None),
            Some(Repr::Bits(k)) => Some(Some(k.as_slice())),
            Some(_) => None,
        };
        if let (Repr::Bits(a), Repr::Bits(w), Some(k)) = (&self.repr, &within.repr, known_bits) {
            let known_at = |i: usize| k.and_then(|k| k.get(i)).copied().unwrap_or(0);
            let fresh = |(i, (x, y)): (usize, (&usize, &usize))| x & y & !known_at(i);
            let words = || a.as_slice().iter().zip(w.as_slice()).enumerate();
            // Counted first, so that a few new members make a short list
            // (a bit set is the whole roster's size).
            let count: usize = words().map(|p| fresh(p).count_ones() as usize).sum();
            let covers = k.is_none_or(|k| {
                let outside =
                    |(i, kw): (usize, &usize)| kw & !a.as_slice().get(i).copied().unwrap_or(0);
                k.iter().enumerate().all(|p| outside(p) == 0)
            });
            if count == 0 {
                return News {
                    fresh: None,
                    covers,
                };
            }
            if !Self::dense(count, self.roster as usize) {
                const WORD: usize = usize::BITS as usize;
                let mut ids = Vec::with_capacity(count);
                for p in words() {
                    let i = p.0;
                    let mut word = fresh(p);
                    while word != 0 {
                        ids.push((i * WORD) as u32 + word.trailing_zeros());
                        word &= word - 1;
                    }
                }
                return News {
                    fresh: Some(MemberSet::from_sorted(self.roster as usize, ids)),
                    covers,
                };
            }
            let mut bits = FixedBitSet::with_capacity(self.roster as usize);
            for (slot, word) in bits.as_mut_slice().iter_mut().zip(words().map(fresh)) {
                *slot = word;
            }
            return News {
                fresh: Some(MemberSet {
                    roster: self.roster,
                    repr: Repr::Bits(Bits::shared(bits)),
                }),
                covers,
            };
        }
        let ids: Vec<u32> = self
            .iter()
            .filter(|r| within.contains(*r) && !known.is_some_and(|k| k.contains(*r)))
            .map(|r| r.0)
            .collect();
        News {
            fresh: (!ids.is_empty()).then(|| MemberSet::from_sorted(self.roster as usize, ids)),
            covers: known.is_none_or(|k| k.is_subset(self)),
        }
    }
    /// Members as a vector.
    pub fn to_vec(&self) -> Vec<RobotId> {
        self.iter().collect()
    }
    /// True when no robot is in both sets.
    pub fn is_disjoint(&self, other: &MemberSet) -> bool {
        match (&self.repr, &other.repr) {
            (Repr::Bits(a), Repr::Bits(b)) => a.is_disjoint(b),
            (Repr::Bits(_), _) => other.iter().all(|r| !self.contains(r)),
            _ => self.iter().all(|r| !other.contains(r)),
        }
    }
    /// How many robots are in both sets (word by word for two bit sets).
    pub fn count_common(&self, other: &MemberSet) -> usize {
        match (&self.repr, &other.repr) {
            (Repr::Bits(a), Repr::Bits(b)) => a.intersection_count(b),
            (Repr::Bits(_), _) => other.iter().filter(|r| self.contains(*r)).count(),
            _ => self.iter().filter(|r| other.contains(*r)).count(),
        }
    }
    /// True when both sets hold the same shared bits (not merely equal
    /// members): what lets a team's members keep one copy of a leader's
    /// report.
    pub fn shares_bits(&self, other: &MemberSet) -> bool {
        match (&self.repr, &other.repr) {
            (Repr::Bits(a), Repr::Bits(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
    /// Add every member of `other`.
    pub fn union_with(&mut self, other: &MemberSet) {
        // A short list stays a list while the union is sparse (a bit set
        // is the whole roster's size, per holder).
        let sparse = !matches!(self.repr, Repr::Bits(_))
            && matches!(other.repr, Repr::Bits(_))
            && !Self::dense(self.len() + other.len(), self.roster as usize);
        if sparse {
            for r in other.iter() {
                self.insert(r);
            }
            return;
        }
        match (&mut self.repr, &other.repr) {
            (Repr::Bits(a), Repr::Bits(b)) => {
                // Shared and already holding all of `other`: nothing to
                // copy.
                if !Bits::subset(b, a) {
                    Bits::make_mut(a).union_with(b);
                }
            }
            (_, Repr::Bits(b)) => {
                let mut bits = FixedBitSet::clone(b);
                bits.grow(self.roster as usize);
                for r in self.iter() {
                    bits.insert(r.index());
                }
                self.repr = Repr::Bits(Bits::shared(bits));
            }
            _ => {
                for r in other.iter() {
                    self.insert(r);
                }
            }
        }
    }
    /// A stable fingerprint of the set (equal sets, equal fingerprints):
    /// FNV-1a over the roster size and the bit set's words, little-endian;
    /// a list is hashed as its bit set would be, skipping the empty words.
    pub fn fingerprint(&self) -> u64 {
        let mut h = Fnv1a::new();
        h.write(&u64::from(self.roster).to_le_bytes());
        match &self.repr {
            Repr::Bits(b) => {
                for block in b.as_slice() {
                    h.write(&(*block as u64).to_le_bytes());
                }
            }
            _ => {
                let words = (self.roster as u64).div_ceil(64);
                let mut at = 0u64;
                let mut members = self.list().unwrap_or_default().iter().peekable();
                while let Some(&first) = members.next() {
                    let w = u64::from(first) / 64;
                    let mut word = 1u64 << (first % 64);
                    while let Some(&&x) = members.peek() {
                        if u64::from(x) / 64 != w {
                            break;
                        }
                        word |= 1u64 << (x % 64);
                        members.next();
                    }
                    h.write_zeros(8 * (w - at));
                    h.write(&word.to_le_bytes());
                    at = w + 1;
                }
                h.write_zeros(8 * (words - at));
            }
        }
        h.finish()
    }
    /// Split the members, in increasing id order, into consecutive groups of
    /// `counts[i]` members each (members beyond the total are left out).
    /// O(members + groups), plus a word per 64 robots of the roster for each
    /// group large enough to be a bit set.
    pub fn split_by_rank(&self, counts: &[u32]) -> Vec<MemberSet> {
        let roster = self.roster as usize;
        let mut out = Vec::with_capacity(counts.len());
        let mut members = self.iter();
        for &c in counts {
            let c = c as usize;
            if Self::dense(c, roster) {
                let mut b = FixedBitSet::with_capacity(roster);
                for r in members.by_ref().take(c) {
                    b.insert(r.index());
                }
                out.push(MemberSet {
                    roster: self.roster,
                    repr: Repr::Bits(Bits::shared(b)),
                });
            } else if c <= INLINE {
                let mut ids = [0; INLINE];
                let mut n = 0;
                for r in members.by_ref().take(c) {
                    ids[n] = r.0;
                    n += 1;
                }
                out.push(MemberSet {
                    roster: self.roster,
                    repr: Repr::Few { n: n as u8, ids },
                });
            } else {
                let v: Vec<u32> = members.by_ref().take(c).map(|r| r.0).collect();
                out.push(MemberSet::from_sorted(roster, v));
            }
        }
        out
    }
}

impl PartialEq for MemberSet {
    fn eq(&self, other: &Self) -> bool {
        if self.roster != other.roster {
            return false;
        }
        match (&self.repr, &other.repr, self.list(), other.list()) {
            (Repr::Few { n: a, ids: x }, Repr::Few { n: b, ids: y }, _, _) => {
                a == b && x[..*a as usize] == y[..*b as usize]
            }
            (_, _, Some(a), Some(b)) => a == b,
            (Repr::Bits(a), Repr::Bits(b), _, _) => a.set == b.set,
            _ => self.len() == other.len() && self.iter().eq(other.iter()),
        }
    }
}

impl Eq for MemberSet {}

impl std::hash::Hash for MemberSet {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.roster.hash(state);
        for r in self.iter() {
            r.hash(state);
        }
    }
}

/// Bytes postcard takes for an unsigned integer (a varint: seven bits a
/// byte), for sizes counted by hand (`Position::encoded_len`,
/// [`MemberSet::wire_len`]). Here, below `msg` in the core's layers,
/// because a set's size on the wire is counted with it.
#[inline]
pub fn varint_len(v: u64) -> usize {
    // Most numbers sent (epochs, behaviors, lengths) take one byte.
    if v < 0x80 {
        return 1;
    }
    (70 - v.leading_zeros() as usize) / 7
}

/// The wire form: the roster's bit set, whatever the set's form in memory.
impl Serialize for MemberSet {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_newtype_struct("MemberSet", &*self.bits())
    }
}

/// Reads the wire form written above (`length`, then the blocks as
/// little-endian bytes) from a binary format and from JSON alike (JSON
/// writes the bytes as a list of numbers), and refuses, instead of
/// allocating, a roster larger than any graph may have
/// ([`crate::roster::MAX_ROBOTS`]) or bytes past the roster's end: a forged
/// message is an error, never a huge allocation.
impl<'de> Deserialize<'de> for MemberSet {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Outer;
        impl<'de> Visitor<'de> for Outer {
            type Value = MemberSet;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a member set")
            }
            fn visit_newtype_struct<D: serde::Deserializer<'de>>(
                self,
                d: D,
            ) -> Result<MemberSet, D::Error> {
                d.deserialize_struct("FixedBitset", &["length", "data"], Fields)
            }
            // Self-describing formats (JSON) may present the newtype's
            // content directly.
            fn visit_map<A: MapAccess<'de>>(self, m: A) -> Result<MemberSet, A::Error> {
                Fields.visit_map(m)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, s: A) -> Result<MemberSet, A::Error> {
                Fields.visit_seq(s)
            }
        }
        d.deserialize_newtype_struct("MemberSet", Outer)
    }
}

/// `length` and `data` of the wire form, in order or by name.
struct Fields;

impl Fields {
    fn build<E: de::Error>(length: u64, data: Vec<u8>) -> Result<MemberSet, E> {
        let roster = usize::try_from(length)
            .ok()
            .filter(|n| *n <= crate::roster::MAX_ROBOTS)
            .ok_or_else(|| {
                E::custom(format!(
                    "a member set of {length} robots (the limit is {})",
                    crate::roster::MAX_ROBOTS
                ))
            })?;
        // No bit past the roster's end.
        let used = roster.div_ceil(8);
        let tail = u8::MAX
            .checked_shl((roster % 8) as u32)
            .filter(|_| roster % 8 != 0);
        if data.iter().skip(used).any(|b| *b != 0)
            || tail.is_some_and(|mask| data.get(used - 1).is_some_and(|b| b & mask != 0))
        {
            return Err(E::custom(format!(
                "a member set names a robot beyond its roster of {roster}"
            )));
        }
        let data = &data[..data.len().min(used)];
        let n: usize = data.iter().map(|b| b.count_ones() as usize).sum();
        if MemberSet::dense(n, roster) {
            let blocks: Vec<usize> = data
                .chunks(std::mem::size_of::<usize>())
                .map(|c| {
                    let mut w = [0u8; std::mem::size_of::<usize>()];
                    w[..c.len()].copy_from_slice(c);
                    usize::from_le_bytes(w)
                })
                .collect();
            return Ok(MemberSet {
                roster: roster as u32,
                repr: Repr::Bits(Bits::shared(FixedBitSet::with_capacity_and_blocks(
                    roster, blocks,
                ))),
            });
        }
        let mut ids = Vec::with_capacity(n);
        for (i, byte) in data.iter().enumerate().filter(|(_, b)| **b != 0) {
            for bit in 0..8 {
                if byte & (1 << bit) != 0 {
                    ids.push((i * 8 + bit) as u32);
                }
            }
        }
        Ok(MemberSet::from_sorted(roster, ids))
    }
}

impl<'de> Visitor<'de> for Fields {
    type Value = MemberSet;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a member set: `length` and `data`")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<MemberSet, A::Error> {
        let length: u64 = s
            .next_element()?
            .ok_or_else(|| de::Error::invalid_length(0, &self))?;
        let Bytes(data) = s
            .next_element()?
            .ok_or_else(|| de::Error::invalid_length(1, &self))?;
        Self::build(length, data)
    }
    fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<MemberSet, A::Error> {
        let (mut length, mut data) = (None, None);
        while let Some(key) = m.next_key::<std::borrow::Cow<'de, str>>()? {
            match &*key {
                "length" if length.is_none() => length = Some(m.next_value::<u64>()?),
                "data" if data.is_none() => data = Some(m.next_value::<Bytes>()?.0),
                "length" | "data" => return Err(de::Error::duplicate_field("length or data")),
                other => return Err(de::Error::unknown_field(other, &["length", "data"])),
            }
        }
        let length = length.ok_or_else(|| de::Error::missing_field("length"))?;
        let data = data.ok_or_else(|| de::Error::missing_field("data"))?;
        Self::build(length, data)
    }
}

/// Bytes, written as bytes (binary formats) or as a list of numbers (JSON).
struct Bytes(Vec<u8>);

impl<'de> Deserialize<'de> for Bytes {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Bytes;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("bytes")
            }
            fn visit_bytes<E: de::Error>(self, b: &[u8]) -> Result<Bytes, E> {
                Ok(Bytes(b.to_vec()))
            }
            fn visit_byte_buf<E: de::Error>(self, b: Vec<u8>) -> Result<Bytes, E> {
                Ok(Bytes(b))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Bytes, A::Error> {
                // Bounded by the largest roster, whatever the sender claims.
                let cap = crate::roster::MAX_ROBOTS / 8 + 8;
                let mut v = Vec::with_capacity(s.size_hint().unwrap_or(0).min(cap));
                while let Some(b) = s.next_element::<u8>()? {
                    if v.len() >= cap {
                        return Err(de::Error::invalid_length(v.len() + 1, &self));
                    }
                    v.push(b);
                }
                Ok(Bytes(v))
            }
        }
        d.deserialize_bytes(V)
    }
}

/// An allocation: each child with the members assigned to it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Assignment(pub Vec<(BehaviorId, MemberSet)>);

impl Assignment {
    /// The child assigned to `r`, if any.
    pub fn child_of(&self, r: RobotId) -> Option<(usize, BehaviorId)> {
        self.0
            .iter()
            .enumerate()
            .find(|(_, (_, m))| m.contains(r))
            .map(|(i, (b, _))| (i, *b))
    }
}

/// A child of an allocation point and how many members it wants.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChildSlot {
    /// The child behavior (head of an execution chain).
    pub behavior: BehaviorId,
    /// Fewest members that make it worth running (at least 1).
    pub min: u32,
    /// Most members it can use.
    pub max: u32,
    /// Given its minimum before the children that are not critical, when
    /// the members are too few for every minimum (`critical: true`).
    pub critical: bool,
}

/// How many members each child gets when `n` members are dealt to
/// `children` (graph order): every child first gets its minimum while
/// members last, the critical children first and then the others, each in
/// child order; the rest are shared as evenly as the children's maximums
/// allow, earlier children taking the remainder.
pub fn member_counts(n: usize, children: &[ChildSlot]) -> Vec<u32> {
    let mut counts = vec![0u32; children.len()];
    let mut left = n as u64;
    for critical in [true, false] {
        for (i, c) in children.iter().enumerate() {
            if c.critical != critical {
                continue;
            }
            let want = u64::from(c.min.max(1).min(c.max));
            let take = want.min(left);
            counts[i] = take as u32;
            left -= take;
        }
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

/// How many allocations by id are remembered.
const BY_ID_REMEMBERED: usize = 64;

/// An allocation by id, and what it was computed from.
#[derive(Debug)]
struct ById {
    members: Weak<MemberSet>,
    children: Weak<[ChildSlot]>,
    assignment: Weak<Assignment>,
}

/// Recent allocations by id, by the (shared) team and children they split:
/// kept by a mission for the robots of one process, so that 10,000 robots
/// splitting among 10,000 children compute the split once.
#[derive(Debug, Default)]
pub struct ByIdMemo(std::sync::Mutex<Vec<ById>>);

impl ByIdMemo {
    /// [`assign_by_id`] of `members` to `children`, computed once for the
    /// robots of this process that pass the same (shared) sets: the
    /// assignment depends on nothing else.
    pub fn assign_by_id(
        &self,
        members: &Arc<MemberSet>,
        children: &Arc<[ChildSlot]>,
    ) -> Arc<Assignment> {
        let mut memo = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        // A weak pointer that still upgrades points at the live value, so
        // equal addresses mean the same sets.
        let same = |e: &ById| {
            std::ptr::eq(e.members.as_ptr(), Arc::as_ptr(members))
                && std::ptr::eq(e.children.as_ptr(), Arc::as_ptr(children))
                && e.members.strong_count() > 0
                && e.children.strong_count() > 0
        };
        if let Some(a) = memo
            .iter()
            .filter(|e| same(e))
            .find_map(|e| e.assignment.upgrade())
        {
            return a;
        }
        let a = Arc::new(assign_by_id(members, children));
        memo.retain(|e| {
            !same(e) && e.assignment.strong_count() > 0 && e.members.strong_count() > 0
        });
        if memo.len() >= BY_ID_REMEMBERED {
            memo.remove(0);
        }
        memo.push(ById {
            members: Arc::downgrade(members),
            children: Arc::downgrade(children),
            assignment: Arc::downgrade(&a),
        });
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varint_len_is_postcards_length_at_every_boundary() {
        let mut values = vec![0u64, u64::MAX];
        for bits in 1..64 {
            values.extend([(1u64 << bits) - 1, 1u64 << bits, (1u64 << bits) + 1]);
        }
        for v in values {
            let sent = postcard::to_allocvec(&v).unwrap_or_default().len();
            assert_eq!(varint_len(v), sent, "{v}");
        }
    }

    fn set(roster: usize, ids: &[u32]) -> MemberSet {
        MemberSet::from_iter(roster, ids.iter().map(|i| RobotId(*i)))
    }

    #[test]
    fn every_form_round_trips_through_the_wire_and_json() {
        let cases = [
            set(3, &[2]),
            set(3, &[]),
            set(70, &[0, 63, 64, 69]),
            set(1000, &(0..40).map(|i| i * 7).collect::<Vec<_>>()),
            set(130, &(0..130).collect::<Vec<_>>()),
            set(64, &(0..64).step_by(2).collect::<Vec<_>>()),
        ];
        for m in cases {
            let wire = postcard::to_allocvec(&m).expect("encodes");
            let back: MemberSet = postcard::from_bytes(&wire).expect("decodes");
            assert_eq!(back, m);
            assert_eq!(back.roster, m.roster);
            let json = serde_json::to_string(&m).expect("encodes");
            let back: MemberSet = serde_json::from_str(&json).expect("decodes from JSON");
            assert_eq!(back, m, "{json}");
        }
    }

    #[test]
    fn common_members_are_counted_in_every_form() {
        let forms = [
            set(200, &[1, 5, 64, 150]),
            set(200, &(0..200).step_by(3).collect::<Vec<_>>()),
            set(200, &(0..30).map(|i| i * 5).collect::<Vec<_>>()),
            set(200, &[]),
        ];
        for a in &forms {
            for b in &forms {
                let brute = a.iter().filter(|r| b.contains(*r)).count();
                assert_eq!(a.count_common(b), brute);
            }
        }
    }

    /// Brute-force [`MemberSet::news`].
    fn brute_news(a: &MemberSet, w: &MemberSet, k: Option<&MemberSet>) -> (Vec<RobotId>, bool) {
        let fresh = a
            .iter()
            .filter(|r| w.contains(*r) && !k.is_some_and(|k| k.contains(*r)))
            .collect();
        let covers = k.is_none_or(|k| k.iter().all(|r| a.contains(r)));
        (fresh, covers)
    }

    fn news_of(a: &MemberSet, w: &MemberSet, k: Option<&MemberSet>) -> (Vec<RobotId>, bool) {
        let n = a.news(w, k);
        assert!(
            n.fresh.as_ref().is_none_or(|f| !f.is_empty()),
            "no empty news"
        );
        (n.fresh.map(|f| f.to_vec()).unwrap_or_default(), n.covers)
    }

    #[test]
    fn news_is_read_right_in_every_form_and_asked_twice() {
        let forms = [
            set(200, &[1, 5, 64, 150]),
            set(200, &(0..200).step_by(3).collect::<Vec<_>>()),
            set(200, &(0..200).step_by(2).collect::<Vec<_>>()),
            set(200, &(0..30).map(|i| i * 5).collect::<Vec<_>>()),
            set(200, &(0..200).collect::<Vec<_>>()),
            set(200, &[]),
        ];
        for a in &forms {
            for w in &forms {
                for k in forms.iter().map(Some).chain([None]) {
                    let brute = brute_news(a, w, k);
                    // The first answer may be kept with `a`: every other
                    // pair asked after it must still be read.
                    assert_eq!(news_of(a, w, k), brute);
                    assert_eq!(news_of(a, w, k), brute, "asked again");
                    assert_eq!(news_of(&a.clone(), w, k), brute, "a copy");
                }
            }
        }
    }

    /// The answer kept with a report never outlives a change of the
    /// report, the team or what the robot knew, whoever holds them.
    #[test]
    fn news_kept_with_a_report_follows_every_change() {
        let agrees = |report: &MemberSet, team: &MemberSet, known: &MemberSet| {
            let brute = brute_news(report, team, Some(known));
            assert_eq!(news_of(report, team, Some(known)), brute);
        };
        let n = 1000;
        let team = set(n, &(0..600).collect::<Vec<_>>());
        let mut report = set(n, &(0..300).collect::<Vec<_>>());
        let mut known = set(n, &(0..200).collect::<Vec<_>>());
        agrees(&report, &team, &known);
        // What the robot knew changes in place (it holds the only copy).
        known.insert(RobotId(250));
        agrees(&report, &team, &known);
        known.remove(RobotId(0));
        agrees(&report, &team, &known);
        // The report changes in place.
        report.insert(RobotId(400));
        agrees(&report, &team, &known);
        // The team changes in place.
        let mut team2 = team.clone();
        agrees(&report, &team2, &known);
        team2.remove(RobotId(299));
        agrees(&report, &team2, &known);
        // A robot that kept the report itself learns nothing from it.
        let kept = report.clone();
        assert_eq!(news_of(&report, &team, Some(&kept)), (vec![], true));
        // Inclusion, kept the same way.
        assert!(!report.is_subset(&team2));
        let mut small = report.clone();
        small.remove(RobotId(400));
        assert!(small.is_subset(&team));
        assert!(small.is_subset(&team), "asked again");
        small.insert(RobotId(700));
        assert!(!small.is_subset(&team), "changed since");
        let mut big = team.clone();
        assert!(small.clone().is_subset(&big) == small.iter().all(|r| big.contains(r)));
        big.insert(RobotId(700));
        assert!(small.is_subset(&big), "the superset changed since");
        // Counts follow changes too.
        let before = report.len();
        report.insert(RobotId(999));
        assert_eq!(report.len(), before + 1);
    }

    #[test]
    fn the_first_member_not_departed_is_found_in_every_form() {
        let forms = [
            set(300, &[1, 5, 64, 150]),
            set(300, &(0..300).step_by(3).collect::<Vec<_>>()),
            set(300, &(0..130).collect::<Vec<_>>()),
            set(300, &(64..300).collect::<Vec<_>>()),
            set(300, &(0..300).collect::<Vec<_>>()),
            set(300, &[]),
        ];
        for team in &forms {
            for x in &forms {
                for y in &forms {
                    for keep in [0, 5, 63, 64, 129, 299] {
                        let keep = RobotId(keep);
                        let brute = team
                            .iter()
                            .find(|r| *r == keep || !(x.contains(*r) || y.contains(*r)));
                        let got = team.first_not_in(keep, || [x, y].into_iter());
                        assert_eq!(got, brute, "{team:?} {x:?} {y:?} {keep:?}");
                    }
                }
            }
        }
    }

    /// Ranks against a count, in every form and size (a large set answers
    /// from its table of ranks), and after a shared set is changed in one
    /// copy (the table follows the change; the other copy keeps its own).
    #[test]
    fn ranks_are_counted_right_in_every_form_and_after_a_change() {
        let brute = |s: &MemberSet, r: u32| s.iter().filter(|m| m.0 < r).count();
        let check = |s: &MemberSet| {
            for r in (0..=s.roster_len() as u32 + 1)
                .step_by(7)
                .chain([63, 64, 65, 511, 512])
            {
                assert_eq!(s.rank(RobotId(r)), brute(s, r), "rank {r} in {s:?}");
            }
        };
        for roster in [3, 300, 1024, 2000] {
            let forms = [
                set(roster, &[]),
                set(roster, &[1, 2]),
                set(roster, &(0..roster as u32).step_by(3).collect::<Vec<_>>()),
                set(roster, &(0..roster as u32).collect::<Vec<_>>()),
                set(
                    roster,
                    &(roster as u32 / 2..roster as u32).collect::<Vec<_>>(),
                ),
            ];
            for s in &forms {
                check(s);
                check(s); // asked again: from the table, if it has one
                let mut changed = s.clone();
                changed.insert(RobotId(0));
                changed.remove(RobotId(roster as u32 - 1));
                check(&changed);
                check(s);
                // Changed in place, not shared, after its ranks were read.
                changed.insert(RobotId(roster as u32 / 2 + 1));
                changed.remove(RobotId(1));
                check(&changed);
            }
        }
    }

    #[test]
    fn forged_sets_are_refused_without_allocating() {
        let e = serde_json::from_str::<MemberSet>(r#"{"length":1099511627776,"data":[1]}"#)
            .expect_err("roster too large");
        assert!(e.to_string().contains("limit"), "{e}");
        let e = serde_json::from_str::<MemberSet>(r#"{"length":3,"data":[8]}"#)
            .expect_err("robot 3 of 3");
        assert!(e.to_string().contains("beyond"), "{e}");
        let e = serde_json::from_str::<MemberSet>(r#"{"length":8,"data":[0,1]}"#)
            .expect_err("a byte past the end");
        assert!(e.to_string().contains("beyond"), "{e}");
        // Trailing zero bytes (a whole block) are harmless.
        let m: MemberSet =
            serde_json::from_str(r#"{"length":3,"data":[4,0,0,0,0,0,0,0]}"#).expect("decodes");
        assert_eq!(m, set(3, &[2]));
        // A forged binary length is refused the same way.
        let mut wire = postcard::to_allocvec(&set(3, &[1])).expect("encodes");
        wire[0] = 0xff;
        wire.splice(1..1, [0xff, 0xff, 0xff, 0x0f]);
        assert!(postcard::from_bytes::<MemberSet>(&wire).is_err());
    }
}
