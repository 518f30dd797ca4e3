//! The duplicate filter: the `(sender, seq)` pairs a robot accepted
//! recently, so that a message is acted upon at most once whatever the
//! order it arrives in.
//!
//! Every robot keeps one, and at 100,000 robots its shape is most of its
//! cost: a B-tree per sender (a 192-byte node for two or three numbers)
//! was a sixth of a large team's memory (docs/performance.md, "2026-11-28, late").
//! A sender's accepted numbers are now a short sorted vector: its messages
//! mostly arrive in the order it sent them, so an insert is nearly always
//! a push.

use crate::ids::RobotId;
use crate::time::Time;
use rustc_hash::FxHashMap;
use std::time::Duration;

/// Accepted sequence numbers per sender, with when each was accepted.
#[derive(Clone, Debug, Default)]
pub(super) struct Accepted {
    /// Per sender, its accepted numbers in increasing order (never empty).
    by_sender: FxHashMap<RobotId, Vec<(u64, Time)>>,
}

impl Accepted {
    /// Accept message `seq` of `from` at `now`: false when it is a
    /// duplicate (already accepted, or numbered 0, which no sender uses).
    /// A sender holding `per_sender` numbers forgets its lowest first.
    pub fn accept(&mut self, from: RobotId, seq: u64, now: Time, per_sender: usize) -> bool {
        if seq == 0 {
            return false;
        }
        let seqs = self.by_sender.entry(from).or_default();
        let Err(mut at) = seqs.binary_search_by_key(&seq, |&(s, _)| s) else {
            return false;
        };
        if seqs.len() >= per_sender && !seqs.is_empty() {
            seqs.remove(0);
            at = at.saturating_sub(1);
        }
        if seqs.capacity() == 0 {
            // Most senders are heard a few times: no room for four yet.
            seqs.reserve_exact(1);
        }
        seqs.insert(at, (seq, now));
        true
    }

    /// Forget what was accepted `memory` or longer before `now`.
    pub fn forget_older(&mut self, now: Time, memory: Duration) {
        self.by_sender.retain(|_, seqs| {
            seqs.retain(|&(_, t)| now - t < memory);
            !seqs.is_empty()
        });
    }

    /// Pairs remembered.
    pub fn len(&self) -> usize {
        self.by_sender.values().map(Vec::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: u64) -> Time {
        Time(s * 1_000_000)
    }

    #[test]
    fn a_pair_is_accepted_once_in_any_order() {
        let mut a = Accepted::default();
        let (r1, r2) = (RobotId(1), RobotId(2));
        assert!(a.accept(r1, 5, t(0), 8));
        assert!(a.accept(r1, 3, t(0), 8));
        assert!(a.accept(r2, 5, t(0), 8));
        assert!(!a.accept(r1, 5, t(1), 8));
        assert!(!a.accept(r1, 3, t(1), 8));
        assert!(a.accept(r1, 4, t(1), 8));
        assert!(!a.accept(r1, 0, t(1), 8));
        assert_eq!(a.len(), 4);
    }

    #[test]
    fn a_full_sender_forgets_its_lowest_number() {
        let mut a = Accepted::default();
        let r = RobotId(7);
        for seq in [10, 30, 20] {
            assert!(a.accept(r, seq, t(0), 3));
        }
        // Full: 10 goes, 5 comes in below the rest.
        assert!(a.accept(r, 5, t(0), 3));
        assert_eq!(a.len(), 3);
        assert!(
            a.accept(r, 10, t(0), 3),
            "the forgotten number is new again"
        );
        assert!(!a.accept(r, 30, t(0), 3));
    }

    #[test]
    fn old_pairs_are_forgotten_and_empty_senders_go() {
        let mut a = Accepted::default();
        a.accept(RobotId(1), 1, t(0), 8);
        a.accept(RobotId(1), 2, t(50), 8);
        a.accept(RobotId(2), 1, t(10), 8);
        a.forget_older(t(120), Duration::from_secs(120));
        assert_eq!(a.len(), 2);
        assert!(a.accept(RobotId(1), 1, t(120), 8));
        a.forget_older(t(200), Duration::from_secs(60));
        assert_eq!(a.len(), 0);
        assert!(a.by_sender.is_empty());
    }
}
