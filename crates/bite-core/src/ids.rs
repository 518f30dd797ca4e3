//! Identifiers shared by every part of the engine.
//!
//! All identifiers are small copyable integers. Robots are numbered by their
//! position in the team roster, so every robot process that loads the same
//! roster agrees on every id without talking.

use serde::{Deserialize, Serialize};
use std::fmt;

/// A robot: its index in the team roster (`0..n`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RobotId(pub u32);

impl RobotId {
    /// The roster index as a `usize`.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl fmt::Display for RobotId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "r{}", self.0)
    }
}

/// A behavior of the task behavior graph (index into `BehaviorGraph::behaviors`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct BehaviorId(pub u32);

impl BehaviorId {
    /// The index as a `usize`.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A belief name, interned (index into the graph's [`crate::belief::Symbols`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct BeliefId(pub u32);

impl BeliefId {
    /// The index as a `usize`.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A vertex of the organization hierarchy (a subteam).
///
/// Team ids are *derived*, never assigned: the root team has a fixed id and a
/// subteam created by an allocation gets `TeamId::derive(parent, point, epoch,
/// child)`. Every robot that applies the same allocation computes the same id,
/// so ids can address messages without a naming service.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct TeamId(pub u64);

impl TeamId {
    /// The whole team (the root of the organization hierarchy).
    pub const ROOT: TeamId = TeamId(0x5eed_0000_0000_0001);

    /// The id of the subteam that executes child number `child` of allocation
    /// point `point`, allocated by `parent` during its `epoch`-th execution of
    /// the point (re-allocation `round`, 0 for the first), with members
    /// whose [`MemberSet::fingerprint`] is `members`.
    /// Stable across processes, platforms and compiler versions (FNV-1a over
    /// little-endian bytes).
    ///
    /// The members are part of the identity: robots whose views of an
    /// allocation diverged (one timed out and applied its own) are in
    /// *different* teams, and never mistake each other's messages for their
    /// own team's.
    ///
    /// [`MemberSet::fingerprint`]: crate::org::MemberSet::fingerprint
    pub fn derive(
        parent: TeamId,
        point: BehaviorId,
        (epoch, round): (u32, u32),
        child: u32,
        members: u64,
    ) -> TeamId {
        let mut h = Fnv1a::new();
        h.write(&parent.0.to_le_bytes());
        h.write(&point.0.to_le_bytes());
        h.write(&epoch.to_le_bytes());
        h.write(&round.to_le_bytes());
        h.write(&child.to_le_bytes());
        h.write(&members.to_le_bytes());
        TeamId(h.finish())
    }
}

impl fmt::Display for TeamId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if *self == TeamId::ROOT {
            f.write_str("root")
        } else {
            write!(f, "t{:08x}", (self.0 >> 32) as u32 ^ self.0 as u32)
        }
    }
}

/// 64-bit FNV-1a: a tiny, stable, well-known hash used for ids and run-log
/// fingerprints. Not for adversarial input (use a MAC for that).
#[derive(Clone, Copy, Debug)]
pub struct Fnv1a(u64);

impl Fnv1a {
    /// A fresh hasher.
    pub const fn new() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
    /// Feed bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    /// Feed `n` zero bytes, in O(log n): a zero byte only multiplies the
    /// state by the FNV prime, so `n` of them multiply it by its `n`-th
    /// power (a sparse bit set hashes as its dense form would, without
    /// walking its empty words).
    pub fn write_zeros(&mut self, n: u64) {
        let (mut p, mut k, mut acc) = (0x0000_0100_0000_01b3u64, n, 1u64);
        while k > 0 {
            if k & 1 == 1 {
                acc = acc.wrapping_mul(p);
            }
            p = p.wrapping_mul(p);
            k >>= 1;
        }
        self.0 = self.0.wrapping_mul(acc);
    }
    /// The hash so far.
    pub const fn finish(&self) -> u64 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

/// The three kinds of social interaction behavior (the paper's three links
/// between task behaviors and interaction behaviors).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// Synchronized selection among sequential successors (`Decide`).
    Sync,
    /// Allocation of children to subteams (`Allocate`).
    Allocate,
    /// Synchronized termination (`Terminate`).
    Terminate,
}

impl Kind {
    /// All kinds, in a fixed order (also the index order of per-kind arrays).
    pub const ALL: [Kind; 3] = [Kind::Sync, Kind::Allocate, Kind::Terminate];
    /// Index for per-kind arrays.
    #[inline]
    pub const fn index(self) -> usize {
        match self {
            Kind::Sync => 0,
            Kind::Allocate => 1,
            Kind::Terminate => 2,
        }
    }
    /// The word used in files and point names.
    pub const fn as_str(self) -> &'static str {
        match self {
            Kind::Sync => "sync",
            Kind::Allocate => "allocate",
            Kind::Terminate => "terminate",
        }
    }
    /// The noun used in messages: "synchronization", "allocation", "termination".
    pub const fn noun(self) -> &'static str {
        match self {
            Kind::Sync => "synchronization",
            Kind::Allocate => "allocation",
            Kind::Terminate => "termination",
        }
    }
    /// The noun with its article: "a synchronization", "an allocation".
    pub const fn a_noun(self) -> &'static str {
        match self {
            Kind::Sync => "a synchronization",
            Kind::Allocate => "an allocation",
            Kind::Terminate => "a termination",
        }
    }
    /// Parse the word used in files.
    pub fn parse(s: &str) -> Option<Kind> {
        match s {
            "sync" => Some(Kind::Sync),
            "allocate" | "alloc" => Some(Kind::Allocate),
            "terminate" | "term" => Some(Kind::Terminate),
            _ => None,
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Identity of one protocol instance: the interaction of kind `kind` that
/// team `team` runs at behavior `behavior` during its `epoch`-th execution of
/// it (epochs count from 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct InstanceKey {
    /// The subteam running the interaction.
    pub team: TeamId,
    /// The point behavior (the behavior terminated, decided after, or allocated).
    pub behavior: BehaviorId,
    /// Which interaction.
    pub kind: Kind,
    /// The team's execution count of `behavior` when the instance started.
    pub epoch: u32,
    /// Allocation only: 0 for the allocation made when the team reached
    /// the point, 1, 2… for re-allocations after teammates were lost.
    pub round: u32,
}

impl InstanceKey {
    /// `(epoch, round)`: the order of instances at one point.
    pub fn stamp(&self) -> (u32, u32) {
        (self.epoch, self.round)
    }
}

impl fmt::Display for InstanceKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}/b{}/{}#{}",
            self.team, self.behavior.0, self.kind, self.epoch
        )?;
        if self.round > 0 {
            write!(f, ".{}", self.round)?;
        }
        Ok(())
    }
}

/// The hash a name (a behavior's, a belief's) is found by in the tables
/// that index names by it: one function, so that a hash made by one part
/// (a loader's worker, the compiler) is the one another looks up with.
pub fn name_hash(name: &str) -> u64 {
    use std::hash::BuildHasher as _;
    rustc_hash::FxBuildHasher.hash_one(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PINNED: u64 = 0x4b99_aba0_8fe6_2e7a;

    #[test]
    fn derived_team_ids_are_stable_and_distinct() {
        let a = TeamId::derive(TeamId::ROOT, BehaviorId(3), (1, 0), 0, 7);
        let b = TeamId::derive(TeamId::ROOT, BehaviorId(3), (1, 0), 1, 7);
        let c = TeamId::derive(TeamId::ROOT, BehaviorId(3), (2, 0), 0, 7);
        let d = TeamId::derive(TeamId::ROOT, BehaviorId(3), (1, 0), 0, 8);
        let e = TeamId::derive(TeamId::ROOT, BehaviorId(3), (1, 1), 0, 7);
        assert_ne!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d, "other members, another team");
        assert_ne!(a, e, "a re-allocation makes new teams");
        // Pinned value: a change here breaks interoperability between
        // robot processes built from different versions.
        assert_eq!(a, TeamId(PINNED));
        assert_eq!(Fnv1a::new().finish(), 0xcbf2_9ce4_8422_2325);
        let mut h = Fnv1a::new();
        h.write(b"a");
        assert_eq!(h.finish(), 0xaf63_dc4c_8601_ec8c);
    }
}
