//! The heartbeat failure detector, sans-IO: told when each teammate was
//! heard and what time it is, it says who is presumed lost and who is back.
//!
//! A teammate silent for `lost_after` is presumed lost; heard again, it is
//! back. A teammate that said it finished (its last heartbeat) is never
//! presumed lost: its silence is expected. Silence is counted from the
//! start of the mission ([`Detector::start`]), not from the process start,
//! so a teammate never heard at all is presumed lost `lost_after` into the
//! mission. Times are microseconds on whatever clock the runtime uses (a
//! robot process: the wall clock of arrival); the detector reads none.
//!
//! The robot runtime (`bite-zenoh`) feeds its verdicts to the
//! [`Agent`](crate::agent::Agent) as `Input::Lost` / `Input::Back`. The
//! simulator feeds the same inputs from its model of this detector (the
//! moment a crash or a partition outlasts `lost_after`, plus a drawn
//! detection delay within one heartbeat period), which costs nothing per
//! heartbeat and so scales to teams of thousands.

/// What the detector concluded at a [`Detector::poll`] or a
/// [`Detector::heard`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Teammate (roster index) presumed lost.
    Lost(u32),
    /// Teammate heard again after being presumed lost.
    Back(u32),
}

/// One robot's view of which teammates are alive.
#[derive(Clone, Debug)]
pub struct Detector {
    me: u32,
    lost_after_us: u64,
    /// When each teammate was last heard (`None`: never).
    heard: Vec<Option<u64>>,
    suspected: Vec<bool>,
    finished: Vec<bool>,
    started: bool,
}

impl Detector {
    /// Robot `me` of a team of `n`, presuming a teammate lost after
    /// `lost_after_us` of silence.
    pub fn new(n: usize, me: u32, lost_after_us: u64) -> Detector {
        Detector {
            me,
            lost_after_us,
            heard: vec![None; n],
            suspected: vec![false; n],
            finished: vec![false; n],
            started: false,
        }
    }

    /// Teammate `from` was heard at `at_us`. Returns [`Verdict::Back`] when
    /// it was presumed lost (and the mission has started). A time earlier
    /// than one already seen does not move its last-heard time back.
    pub fn heard(&mut self, from: u32, at_us: u64) -> Option<Verdict> {
        let i = from as usize;
        let h = self.heard.get_mut(i)?;
        *h = Some(at_us.max(h.unwrap_or(0)));
        if self.suspected[i] && self.started {
            self.suspected[i] = false;
            return Some(Verdict::Back(from));
        }
        None
    }

    /// Teammate `who` said (its last heartbeat) whether it finished the
    /// mission: if so, its silence from now on is expected.
    pub fn finished(&mut self, who: u32, finished: bool) {
        if let Some(f) = self.finished.get_mut(who as usize) {
            *f = finished;
        }
    }

    /// The mission starts at `origin_us`: silence counts from here (a
    /// teammate heard earlier, or never, counts as heard now).
    pub fn start(&mut self, origin_us: u64) {
        self.started = true;
        for h in &mut self.heard {
            *h = Some(h.unwrap_or(origin_us).max(origin_us));
        }
    }

    /// True once [`Detector::start`] was called.
    pub fn started(&self) -> bool {
        self.started
    }

    /// True when every teammate has been heard at least once.
    pub fn everyone_heard(&self) -> bool {
        (self.heard.iter().enumerate()).all(|(i, h)| i == self.me as usize || h.is_some())
    }

    /// Teammates never heard (roster indices).
    pub fn never_heard(&self) -> impl Iterator<Item = u32> + '_ {
        (self.heard.iter().enumerate())
            .filter(|(i, h)| *i != self.me as usize && h.is_none())
            .map(|(i, _)| i as u32)
    }

    /// True when teammate `r` has been heard at least once.
    pub fn has_heard(&self, r: u32) -> bool {
        self.heard.get(r as usize).is_some_and(Option::is_some)
    }

    /// True when teammate `r` is presumed lost.
    pub fn is_suspected(&self, r: u32) -> bool {
        self.suspected.get(r as usize).copied().unwrap_or(false)
    }

    /// True when teammate `r` said it finished.
    pub fn is_finished(&self, r: u32) -> bool {
        self.finished.get(r as usize).copied().unwrap_or(false)
    }

    /// Teammates presumed lost now, in roster order.
    pub fn suspected(&self) -> impl Iterator<Item = u32> + '_ {
        (self.suspected.iter().enumerate())
            .filter(|(_, s)| **s)
            .map(|(i, _)| i as u32)
    }

    /// At `now_us`: the teammates newly presumed lost (appended to `out`),
    /// and when to poll next (`None`: nothing to wait for). Nothing is
    /// presumed before the mission starts.
    pub fn poll(&mut self, now_us: u64, out: &mut Vec<Verdict>) -> Option<u64> {
        if !self.started {
            return None;
        }
        let mut next: Option<u64> = None;
        for (i, h) in self.heard.iter().enumerate() {
            if i == self.me as usize || self.suspected[i] || self.finished[i] {
                continue;
            }
            let Some(h) = h else { continue };
            let due = h.saturating_add(self.lost_after_us);
            if now_us >= due {
                self.suspected[i] = true;
                out.push(Verdict::Lost(i as u32));
            } else {
                next = Some(next.map_or(due, |n: u64| n.min(due)));
            }
        }
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000;

    fn poll(d: &mut Detector, now: u64) -> (Vec<Verdict>, Option<u64>) {
        let mut v = Vec::new();
        let next = d.poll(now, &mut v);
        (v, next)
    }

    #[test]
    fn silence_from_the_start_is_a_loss_and_a_heartbeat_brings_it_back() {
        let mut d = Detector::new(3, 0, 2 * S);
        d.heard(1, 5 * S);
        assert!(!d.everyone_heard());
        assert_eq!(d.never_heard().collect::<Vec<_>>(), vec![2]);
        // Nothing before the start.
        assert_eq!(poll(&mut d, 100 * S), (vec![], None));
        d.start(10 * S);
        assert!(d.everyone_heard());
        assert_eq!(poll(&mut d, 11 * S), (vec![], Some(12 * S)));
        d.heard(1, 11 * S + 500_000);
        assert_eq!(
            poll(&mut d, 12 * S),
            (vec![Verdict::Lost(2)], Some(13 * S + 500_000))
        );
        assert!(d.is_suspected(2));
        // Presumed once, not at every poll.
        assert_eq!(poll(&mut d, 12 * S + 1).0, vec![]);
        assert_eq!(d.heard(2, 13 * S), Some(Verdict::Back(2)));
        assert_eq!(d.suspected().count(), 0);
        assert_eq!(d.heard(2, 13 * S + 1), None);
    }

    #[test]
    fn a_finished_teammate_is_never_presumed_lost() {
        let mut d = Detector::new(2, 1, S);
        d.start(0);
        d.finished(0, true);
        assert_eq!(poll(&mut d, 100 * S), (vec![], None));
    }

    #[test]
    fn late_arrivals_do_not_move_the_last_heard_time_back() {
        let mut d = Detector::new(2, 0, S);
        d.start(0);
        d.heard(1, 5 * S);
        d.heard(1, 2 * S);
        assert_eq!(poll(&mut d, 5 * S + 999_999), (vec![], Some(6 * S)));
        // Out-of-roster senders are ignored, not a panic.
        assert_eq!(d.heard(7, S), None);
    }
}
