//! A seeded simulated network: latency, jitter, loss, duplication,
//! reordering (from jitter), symmetric and one-way partitions, and crashed
//! robots. Every draw comes from the network's own seeded generator, so a run
//! is reproducible from its seed.

use bite_core::ids::RobotId;
use bite_core::interaction::Rng;
use bite_core::time::Time;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use std::time::Duration;

pub use bite_agent::netmodel::{Cut, NetModel, Partition};

/// Network counters.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct NetStats {
    /// Copies handed to the network (one per recipient).
    pub attempts: u64,
    /// Copies scheduled for delivery (duplicates included).
    pub delivered: u64,
    /// Copies lost at random.
    pub lost: u64,
    /// Extra copies created by duplication.
    pub duplicated: u64,
    /// Copies dropped by a partition.
    pub partitioned: u64,
    /// Copies dropped because the robots were out of radio range.
    pub out_of_range: u64,
    /// Copies held and delivered in a burst.
    pub held: u64,
}

/// The network of one simulated run.
#[derive(Clone, Debug)]
pub struct SimNet {
    model: NetModel,
    rng: Rng,
    stats: NetStats,
}

impl SimNet {
    /// A network following `model`, seeded with `seed`.
    pub fn new(model: NetModel, seed: u64) -> Self {
        SimNet {
            model,
            rng: Rng::seed_from_u64(seed),
            stats: NetStats::default(),
        }
    }
    /// The model.
    pub fn model(&self) -> &NetModel {
        &self.model
    }
    /// The counters.
    pub fn stats(&self) -> &NetStats {
        &self.stats
    }
    /// Count a copy that could not be sent: the robots are out of radio
    /// range of each other.
    pub fn out_of_range(&mut self) {
        self.stats.attempts += 1;
        self.stats.out_of_range += 1;
    }
    /// True if a partition cuts `from → to` at `now`.
    pub fn cut(&self, now: Time, from: RobotId, to: RobotId) -> bool {
        self.model
            .partitions
            .iter()
            .any(|p| p.from <= now && now < p.until && p.cut.blocks(from, to))
    }
    /// Send one copy from `from` to `to` at `now`: the delivery times of the
    /// copies that arrive (none if lost or cut, two or three if duplicated).
    pub fn transmit(&mut self, now: Time, from: RobotId, to: RobotId, out: &mut Vec<Time>) {
        out.clear();
        self.stats.attempts += 1;
        if self.cut(now, from, to) {
            self.stats.partitioned += 1;
            return;
        }
        let mut copies = 1;
        if self.model.duplicate > 0.0 && self.rng.random_bool(self.model.duplicate.min(1.0)) {
            copies += 1;
            if self.rng.random_bool(self.model.duplicate.min(1.0)) {
                copies += 1;
            }
        }
        self.stats.duplicated += copies - 1;
        for _ in 0..copies {
            if self.model.loss > 0.0 && self.rng.random_bool(self.model.loss.min(1.0)) {
                self.stats.lost += 1;
                continue;
            }
            let jitter = self.model.jitter.as_micros() as u64;
            let extra = if jitter > 0 {
                self.rng.random_range(0..=jitter)
            } else {
                0
            };
            let mut at = now + self.model.latency + Duration::from_micros(extra);
            // Held in a stalled switch: released at the end of the window.
            if let Some((_, until)) = self.model.holds.iter().find(|(f, u)| *f <= now && now < *u) {
                at = at.max(*until + Duration::from_micros(extra));
                self.stats.held += 1;
            }
            out.push(at);
            self.stats.delivered += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproducible_and_counts_add_up() {
        let model = NetModel {
            loss: 0.2,
            duplicate: 0.3,
            ..NetModel::default()
        };
        let mut a = SimNet::new(model.clone(), 9);
        let mut b = SimNet::new(model, 9);
        let (mut ta, mut tb) = (Vec::new(), Vec::new());
        for i in 0..1000 {
            a.transmit(Time(i), RobotId(0), RobotId(1), &mut ta);
            b.transmit(Time(i), RobotId(0), RobotId(1), &mut tb);
            assert_eq!(ta, tb);
            for t in &ta {
                assert!(*t >= Time(i) + Duration::from_millis(2));
                assert!(*t <= Time(i) + Duration::from_millis(5));
            }
        }
        let s = a.stats();
        assert_eq!(s.attempts, 1000);
        assert_eq!(s.attempts + s.duplicated, s.delivered + s.lost);
        assert!(s.lost > 100 && s.lost < 400, "{s:?}");
        assert!(s.duplicated > 200, "{s:?}");
    }

    #[test]
    fn partitions_cut_links_in_their_interval_only() {
        let model = NetModel {
            partitions: vec![
                Partition {
                    from: Time::from_millis(10),
                    until: Time::from_millis(20),
                    cut: Cut::Groups(vec![vec![RobotId(0), RobotId(1)]]),
                },
                Partition {
                    from: Time::from_millis(30),
                    until: Time::from_millis(40),
                    cut: Cut::OneWay {
                        from: vec![RobotId(0)],
                        to: vec![RobotId(2)],
                    },
                },
            ],
            ..NetModel::default()
        };
        let net = SimNet::new(model, 1);
        let (r0, r1, r2) = (RobotId(0), RobotId(1), RobotId(2));
        assert!(!net.cut(Time::from_millis(5), r0, r2));
        assert!(
            net.cut(Time::from_millis(15), r0, r2),
            "r2 is in the unlisted group"
        );
        assert!(net.cut(Time::from_millis(15), r2, r1));
        assert!(!net.cut(Time::from_millis(15), r0, r1));
        assert!(net.cut(Time::from_millis(35), r0, r2));
        assert!(!net.cut(Time::from_millis(35), r2, r0), "one-way");
        assert!(
            !net.cut(Time::from_millis(40), r0, r2),
            "interval is half-open"
        );
    }
}
