//! A sliding anti-replay window per sender, as IPsec uses: accepts each
//! sequence number at most once, tolerates reordering within the window,
//! and rejects anything older than the window.

/// Width of the window in sequence numbers.
pub const WINDOW: u64 = 256;

/// The window of one sender.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ReplayWindow {
    top: u64,
    bits: [u64; (WINDOW / 64) as usize],
}

impl ReplayWindow {
    /// A window that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }
    /// Highest sequence number accepted so far.
    pub fn top(&self) -> u64 {
        self.top
    }
    /// Would `seq` be accepted? (Does not record it.)
    pub fn check(&self, seq: u64) -> bool {
        if seq == 0 {
            return false;
        }
        if seq > self.top {
            return true;
        }
        let age = self.top - seq;
        age < WINDOW && !self.bit(age)
    }
    /// Accept `seq` if it is new and recent; returns whether it was accepted.
    pub fn accept(&mut self, seq: u64) -> bool {
        if !self.check(seq) {
            return false;
        }
        if seq > self.top {
            self.shift(seq - self.top);
            self.top = seq;
            self.set(0);
        } else {
            self.set(self.top - seq);
        }
        true
    }
    fn bit(&self, age: u64) -> bool {
        self.bits[(age / 64) as usize] & (1 << (age % 64)) != 0
    }
    fn set(&mut self, age: u64) {
        self.bits[(age / 64) as usize] |= 1 << (age % 64);
    }
    /// Age every recorded bit by `by` positions.
    fn shift(&mut self, by: u64) {
        if by >= WINDOW {
            self.bits = Default::default();
            return;
        }
        let words = (by / 64) as usize;
        let bits = (by % 64) as u32;
        let n = self.bits.len();
        for i in (0..n).rev() {
            let src = i.checked_sub(words);
            let lo = src.map_or(0, |s| self.bits[s]);
            let carry = src
                .and_then(|s| s.checked_sub(1))
                .map_or(0, |s| self.bits[s]);
            self.bits[i] = if bits == 0 {
                lo
            } else {
                (lo << bits) | (carry >> (64 - bits))
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn accepts_once_tolerates_reordering_rejects_old() {
        let mut w = ReplayWindow::new();
        assert!(!w.accept(0));
        assert!(w.accept(5));
        assert!(!w.accept(5));
        assert!(w.accept(3));
        assert!(w.accept(4));
        assert!(!w.accept(3));
        assert!(w.accept(300));
        assert!(!w.accept(5), "older than the window");
        assert!(w.accept(299));
        assert!(w.accept(300 - WINDOW + 1));
        assert!(!w.accept(300 - WINDOW));
    }

    proptest! {
        /// Against a model that remembers everything: the window accepts
        /// exactly the first copy of each number not older than the window.
        #[test]
        fn matches_a_model(seqs in proptest::collection::vec(1u64..700, 0..400)) {
            let mut w = ReplayWindow::new();
            let mut seen = std::collections::BTreeSet::new();
            let mut top = 0u64;
            for s in seqs {
                let expect = !seen.contains(&s) && (s > top || top - s < WINDOW);
                prop_assert_eq!(w.accept(s), expect, "seq {}", s);
                if expect {
                    seen.insert(s);
                    top = top.max(s);
                }
            }
        }
    }
}
