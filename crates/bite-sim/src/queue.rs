//! The simulator's event queue: what happens next, in the order of time
//! and, at equal times, of scheduling.
//!
//! A single binary heap of every message in flight was a tenth of a large
//! team's run (`perf`, 10,000 robots: a leader's heartbeat puts 10,000
//! deliveries in flight, and each pop walked a heap of tens of thousands
//! of entries scattered in memory). Here events are kept in buckets of
//! [`BUCKET`] of simulated time: those of later buckets are only appended
//! to their bucket's list; the bucket being drained is sorted once (it is
//! mostly appended in order already) and read front to back, and what is
//! scheduled into it while it drains goes to a small heap. An event is
//! pushed in O(1) (plus a lookup among the few buckets in flight).
//!
//! The order is exactly the single heap's: the drained bucket and the
//! small heap hold every event of the buckets up to the current one, every
//! later bucket events strictly later than all of them, so the lesser of
//! their two fronts is the least of all (a property test below compares
//! the two).

use bite_core::time::Time;
use std::cmp::{Ordering, Reverse};
use std::collections::{BTreeMap, BinaryHeap, VecDeque};

/// Width of a bucket, in microseconds of simulated time (1 ms).
pub const BUCKET: u64 = 1_000;

struct Keyed<T> {
    at: Time,
    seq: u64,
    item: T,
}

impl<T> PartialEq for Keyed<T> {
    fn eq(&self, o: &Self) -> bool {
        (self.at, self.seq) == (o.at, o.seq)
    }
}
impl<T> Eq for Keyed<T> {}
impl<T> PartialOrd for Keyed<T> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl<T> Ord for Keyed<T> {
    fn cmp(&self, o: &Self) -> Ordering {
        (self.at, self.seq).cmp(&(o.at, o.seq))
    }
}

/// The most events an emptied list may have room for to be kept for a
/// later bucket. A bucket holding a leader's heartbeat to a large team
/// has room for tens of thousands; kept, every list would in time have
/// that much room, one per bucket ahead: at 100,000 robots, hundreds of
/// megabytes that grew with the length of the run (docs/performance.md,
/// "2026-11-28, late"). Such a bucket grows its own list again (a few
/// reallocations every heartbeat period).
const SPARE_ROOM: usize = 4096;
/// The most emptied lists kept: timers scheduled seconds ahead keep
/// hundreds of buckets open at once, and a spare for each, at up to
/// [`SPARE_ROOM`] events, held tens of megabytes no bucket needed.
const SPARES: usize = 32;

/// Events in order of `(time, order of scheduling)`.
pub(crate) struct EventQueue<T> {
    /// What is left of the bucket being drained, sorted.
    sorted: VecDeque<Keyed<T>>,
    /// Events scheduled into the buckets up to `cur` while it drains.
    current: BinaryHeap<Reverse<Keyed<T>>>,
    /// The bucket being drained.
    cur: u64,
    /// Events of later buckets, unordered within a bucket.
    later: BTreeMap<u64, Vec<Keyed<T>>>,
    /// Emptied lists, kept for later buckets.
    spare: Vec<Vec<Keyed<T>>>,
    seq: u64,
    len: usize,
}

impl<T> Default for EventQueue<T> {
    fn default() -> Self {
        EventQueue {
            sorted: VecDeque::new(),
            current: BinaryHeap::new(),
            cur: 0,
            later: BTreeMap::new(),
            spare: Vec::new(),
            seq: 0,
            len: 0,
        }
    }
}

impl<T> EventQueue<T> {
    /// Schedule `item` at `at` (after everything already scheduled at
    /// `at`).
    pub fn push(&mut self, at: Time, item: T) {
        self.seq += 1;
        self.len += 1;
        let k = Keyed {
            at,
            seq: self.seq,
            item,
        };
        let b = at.0 / BUCKET;
        if b <= self.cur {
            self.current.push(Reverse(k));
        } else {
            let spare = &mut self.spare;
            self.later
                .entry(b)
                .or_insert_with(|| spare.pop().unwrap_or_default())
                .push(k);
        }
    }

    /// The next event and its time.
    #[cfg(test)]
    pub fn pop(&mut self) -> Option<(Time, T)> {
        self.pop_keyed().map(|(at, _, item)| (at, item))
    }

    /// The next event, its time and its place among the events scheduled
    /// at that time (the order of scheduling).
    pub fn pop_keyed(&mut self) -> Option<(Time, u64, T)> {
        let from_heap = self.next_from_heap()?;
        let k = if from_heap {
            self.current.pop()?.0
        } else {
            self.sorted.pop_front()?
        };
        self.len -= 1;
        Some((k.at, k.seq, k.item))
    }

    /// The event `k` places after the next one in the bucket being drained,
    /// if there is one: a hint for fetching ahead (an event scheduled
    /// meanwhile may come first; events of later buckets are not seen).
    pub fn ahead(&self, k: usize) -> Option<&T> {
        self.sorted.get(k + 1).map(|e| &e.item)
    }

    /// The time and place of the next event, and the event, without
    /// taking it.
    pub fn peek(&mut self) -> Option<(Time, u64, &T)> {
        let k = if self.next_from_heap()? {
            &self.current.peek()?.0
        } else {
            self.sorted.front()?
        };
        Some((k.at, k.seq, &k.item))
    }

    /// Whether the next event is on the heap (`false`: at the front of the
    /// sorted bucket); `None` when nothing is scheduled.
    fn next_from_heap(&mut self) -> Option<bool> {
        if self.sorted.is_empty() && self.current.is_empty() {
            let (b, mut list) = self.later.pop_first()?;
            self.cur = b;
            // A bucket is mostly appended in order (a leader's heartbeat
            // to its team, a control tick): sorting it finds the runs and
            // reads memory in order, where a heap would hop.
            list.sort_unstable();
            // Both conversions keep the storage (no copy: the emptied
            // deque has nothing to move).
            let old = std::mem::replace(&mut self.sorted, VecDeque::from(list));
            if old.capacity() <= SPARE_ROOM && self.spare.len() < SPARES {
                self.spare.push(Vec::from(old));
            }
        }
        Some(match (self.sorted.front(), self.current.peek()) {
            (Some(a), Some(Reverse(b))) => b < a,
            (None, _) => true,
            (Some(_), None) => false,
        })
    }

    /// How many events are scheduled.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Pushes and pops interleaved as a run does (never scheduling
        /// before the last event popped) come out exactly as from one
        /// binary heap ordered by time, then order of scheduling.
        #[test]
        fn pops_in_the_order_of_one_heap(
            ops in proptest::collection::vec((0u64..5_000_000, 0u8..4), 1..400)
        ) {
            let mut q = EventQueue::default();
            let mut reference = BinaryHeap::new();
            let mut now = 0u64;
            let mut seq = 0u64;
            for (i, (delay, pops)) in ops.iter().enumerate() {
                // Some delays fall in the current bucket, some far ahead,
                // some at the same instant.
                let at = now + if i % 5 == 0 { 0 } else { *delay };
                seq += 1;
                q.push(Time(at), i);
                reference.push(Reverse((at, seq, i)));
                for _ in 0..*pops {
                    let head = reference.peek().map(|Reverse((at, _, i))| (Time(*at), *i));
                    prop_assert_eq!(q.peek().map(|(at, _, i)| (at, *i)), head);
                    let want = reference.pop().map(|Reverse((at, _, i))| (Time(at), i));
                    let got = q.pop();
                    prop_assert_eq!(got, want);
                    if let Some((t, _)) = got {
                        now = t.0;
                    }
                }
                prop_assert_eq!(q.len(), reference.len());
            }
            while let Some(Reverse((at, _, i))) = reference.pop() {
                prop_assert_eq!(q.pop(), Some((Time(at), i)));
            }
            prop_assert_eq!(q.pop(), None);
        }
    }

    /// Looking ahead names the events after the next one in the bucket
    /// being drained, in order, and nothing past its end (nor what was
    /// scheduled into the bucket while it drains).
    #[test]
    fn ahead_names_the_events_after_the_next() {
        let mut q = EventQueue::default();
        let at = |i: u32| Time(2 * BUCKET + u64::from(i));
        for i in 0..5u32 {
            q.push(at(i), i);
        }
        q.push(Time(10 * BUCKET), 99);
        assert_eq!(q.peek().map(|(_, _, i)| *i), Some(0));
        assert_eq!(
            (q.ahead(0), q.ahead(2), q.ahead(3)),
            (Some(&1), Some(&3), Some(&4))
        );
        assert_eq!(q.ahead(4), None, "a later bucket is not seen");
        assert_eq!(q.pop(), Some((at(0), 0)));
        assert_eq!(q.ahead(0), Some(&2));
        q.push(at(1), 7);
        assert_eq!(q.peek().map(|(_, _, i)| *i), Some(1));
        assert_eq!(
            q.ahead(0),
            Some(&2),
            "a hint: what was scheduled meanwhile is not seen"
        );
    }
}
