//! How a scenario says its network behaves: latency, jitter, loss,
//! duplication, partitions and holds. The simulator's network
//! (`bite_sim::net::SimNet`) carries messages by this model; a robot process
//! reads it with the rest of the scenario and ignores it (its network is real).

use bite_core::ids::RobotId;
use bite_core::time::Time;
use std::time::Duration;

/// How messages travel.
#[derive(Clone, Debug, PartialEq)]
pub struct NetModel {
    /// Fixed one-way latency.
    pub latency: Duration,
    /// Extra latency drawn uniformly from `0..=jitter` per copy (this is
    /// what reorders messages).
    pub jitter: Duration,
    /// Probability that a copy is lost.
    pub loss: f64,
    /// Probability that a message is delivered twice (and `duplicate²` that
    /// it is delivered three times).
    pub duplicate: f64,
    /// Partitions in force during given intervals.
    pub partitions: Vec<Partition>,
    /// Windows `[from, until)` in which every message sent is held, then
    /// delivered as a burst when the window closes (a stalled switch).
    pub holds: Vec<(Time, Time)>,
}

impl Default for NetModel {
    fn default() -> Self {
        NetModel {
            latency: Duration::from_millis(2),
            jitter: Duration::from_millis(3),
            loss: 0.0,
            duplicate: 0.0,
            partitions: Vec::new(),
            holds: Vec::new(),
        }
    }
}

/// A partition of the network during `[from, until)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Partition {
    /// Start.
    pub from: Time,
    /// End.
    pub until: Time,
    /// Which links are cut.
    pub cut: Cut,
}

/// Which links a partition cuts.
#[derive(Clone, Debug, PartialEq)]
pub enum Cut {
    /// Symmetric: robots in different groups cannot talk. Robots not listed
    /// form one more group together.
    Groups(Vec<Vec<RobotId>>),
    /// One-way: messages from any of `from` to any of `to` are dropped.
    OneWay {
        /// Senders cut off.
        from: Vec<RobotId>,
        /// Receivers they cannot reach.
        to: Vec<RobotId>,
    },
}

impl Cut {
    /// True when this cut drops messages from `from` to `to`.
    pub fn blocks(&self, from: RobotId, to: RobotId) -> bool {
        match self {
            Cut::Groups(groups) => {
                let g = |r: RobotId| groups.iter().position(|g| g.contains(&r));
                g(from) != g(to)
            }
            Cut::OneWay { from: f, to: t } => f.contains(&from) && t.contains(&to),
        }
    }
}
