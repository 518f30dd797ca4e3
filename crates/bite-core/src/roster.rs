//! The team roster: which robots exist, their names and attributes.
//!
//! Robot ids are roster indices, so all processes loading the same roster
//! agree on them.

use crate::ids::RobotId;
use crate::value::Value;
use serde::Serialize;
use std::collections::BTreeMap;

/// Largest team accepted (a graph's roster, a member set read from the
/// network).
pub const MAX_ROBOTS: usize = 1_000_000;

/// One robot of the team.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotInfo {
    /// Human-readable name (unique).
    pub name: String,
    /// Static attributes (colour, capabilities...) used by allocation.
    pub attributes: BTreeMap<String, Value>,
}

/// The whole team.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Roster {
    robots: Vec<RobotInfo>,
}

impl Roster {
    /// `n` robots named `r0..r{n-1}` without attributes.
    pub fn anonymous(n: usize) -> Self {
        Roster {
            robots: (0..n)
                .map(|i| RobotInfo {
                    name: format!("r{i}"),
                    attributes: BTreeMap::new(),
                })
                .collect(),
        }
    }
    /// A roster from explicit entries.
    pub fn new(robots: Vec<RobotInfo>) -> Self {
        Roster { robots }
    }
    /// Number of robots.
    pub fn len(&self) -> usize {
        self.robots.len()
    }
    /// True when there is no robot.
    pub fn is_empty(&self) -> bool {
        self.robots.is_empty()
    }
    /// A robot's entry.
    pub fn get(&self, r: RobotId) -> Option<&RobotInfo> {
        self.robots.get(r.index())
    }
    /// A robot's name (`r<id>` if unknown).
    pub fn name(&self, r: RobotId) -> String {
        self.get(r)
            .map_or_else(|| r.to_string(), |i| i.name.clone())
    }
    /// Look a robot up by name.
    pub fn find(&self, name: &str) -> Option<RobotId> {
        self.robots
            .iter()
            .position(|r| r.name == name)
            .map(|i| RobotId(i as u32))
    }
    /// The robots' names in id order.
    pub fn names(&self) -> Vec<String> {
        self.robots.iter().map(|r| r.name.clone()).collect()
    }
    /// All robots in id order.
    pub fn iter(&self) -> impl Iterator<Item = (RobotId, &RobotInfo)> {
        self.robots
            .iter()
            .enumerate()
            .map(|(i, r)| (RobotId(i as u32), r))
    }
    /// The same roster resized to `n` robots (extra robots are anonymous).
    pub fn resized(&self, n: usize) -> Roster {
        let mut robots: Vec<RobotInfo> = self.robots.iter().take(n).cloned().collect();
        for i in robots.len()..n {
            robots.push(RobotInfo {
                name: format!("r{i}"),
                attributes: BTreeMap::new(),
            });
        }
        Roster { robots }
    }
}
