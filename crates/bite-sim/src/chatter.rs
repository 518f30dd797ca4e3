//! Chatter: a robot sending kernel messages far faster than any protocol
//! needs. Two kernels that answer each other's answers send for ever
//! without breaking an invariant (the checker works from events, and a
//! run's events need not change): a run of Table II sent 14,684 messages
//! where 97 do (docs/reliability.md, "Two robots answering each other").
//! The simulator counts what each robot sends in fixed windows of
//! [`WINDOW`]; more than [`limit`] in one window is reported in the
//! summary, and a sweep lists the run among its failures.

use bite_core::ids::RobotId;
use bite_core::time::Time;
use std::time::Duration;

/// The window messages are counted in.
pub const WINDOW: Duration = Duration::from_secs(10);

/// The most kernel messages one robot of a team of `robots` may send in
/// one [`WINDOW`] (a multicast counts once): a protocol sends a few per
/// instance and member, and resends back off. Over the Table II and other
/// shipped missions' sweeps on seeds 1 to 60 (18,400 runs, heavy loss
/// included), no robot sent more than 43 in a window, an eighth of the
/// limit for three robots (350); the loop it is there for sent 888.
pub fn limit(robots: usize) -> u32 {
    200 + 50 * robots as u32
}

/// A robot that sent more than [`limit`] in one window.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chatter {
    /// The robot.
    pub robot: RobotId,
    /// Where the window began.
    pub from: Time,
    /// What it sent in it.
    pub sent: u32,
    /// The limit it passed.
    pub limit: u32,
}

impl std::fmt::Display for Chatter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} sent {} kernel messages within {} s from {} (more than {}): \
             robots answering each other?",
            self.robot,
            self.sent,
            WINDOW.as_secs(),
            self.from,
            self.limit
        )
    }
}

/// Counts what every robot sends, window by window.
pub struct ChatterWatch {
    limit: u32,
    /// Per robot: the window it last sent in, and how many then.
    counts: Vec<(u64, u32)>,
    /// The first robot found over the limit (the count goes on to the
    /// window's end).
    found: Option<Chatter>,
}

impl ChatterWatch {
    /// A watch over a team of `robots`.
    pub fn new(robots: usize) -> Self {
        ChatterWatch {
            limit: limit(robots),
            counts: vec![(0, 0); robots],
            found: None,
        }
    }

    /// Robot `r` sent a kernel message at `now`.
    pub fn sent(&mut self, now: Time, r: RobotId) {
        let window = WINDOW.as_micros() as u64;
        let w = now.0 / window;
        let Some(c) = self.counts.get_mut(r.index()) else {
            return;
        };
        if c.0 != w {
            *c = (w, 0);
        }
        c.1 += 1;
        let from = Time(w * window);
        match &mut self.found {
            None if c.1 > self.limit => {
                self.found = Some(Chatter {
                    robot: r,
                    from,
                    sent: c.1,
                    limit: self.limit,
                });
            }
            Some(f) if f.robot == r && f.from == from => f.sent = c.1,
            _ => {}
        }
    }

    /// The first robot found chattering, if any.
    pub fn found(&self) -> Option<&Chatter> {
        self.found.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Time {
        Time(ms * 1000)
    }

    /// A robot sending at a protocol's pace is not chatter; the first that
    /// sends more than the limit within one window is, with the whole
    /// window's count.
    #[test]
    fn only_more_than_the_limit_within_one_window_is_chatter() {
        let mut w = ChatterWatch::new(3);
        let lim = limit(3);
        assert_eq!(lim, 350);
        // At the limit in every window for a minute: not chatter.
        for k in 0..60 * lim as u64 / 10 {
            w.sent(at(k * 10_000 / lim as u64), RobotId(1));
        }
        assert_eq!(w.found(), None);
        // Two robots answering each other: 100 a second each.
        for k in 0..2000u64 {
            w.sent(at(70_000 + k * 10), RobotId((k % 2) as u32));
            w.sent(at(70_000 + k * 10), RobotId(2));
        }
        let c = w.found().expect("chatter").clone();
        assert_eq!(c.robot, RobotId(2));
        assert_eq!(c.from, at(70_000));
        assert_eq!(c.sent, 1000);
        assert!(
            c.to_string()
                .starts_with("r2 sent 1000 kernel messages within 10 s"),
            "{c}"
        );
    }
}
