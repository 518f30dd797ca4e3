//! The organization hierarchy (team hierarchy): a DAG whose vertices are
//! subteams, from the root team of all robots down to singletons, with
//! bidirectional links between behaviors and the subteams executing them.
//!
//! Each robot keeps its own copy. Subteams are created by allocations and
//! their ids are derived from the allocation ([`TeamId::derive`]), so every
//! member that applies the same allocation builds the same hierarchy.
//! Singletons are implicit leaves: `{r}` is a child of the smallest stored
//! team that contains `r`.

use crate::ids::{BehaviorId, RobotId, TeamId};
use fixedbitset::FixedBitSet;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

/// A set of robots, as a bitset over roster indices (10,000 robots take
/// 1.25 KB). Cheap to test, iterate in id order, and share.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct MemberSet(FixedBitSet);

impl MemberSet {
    /// The empty set over a roster of `roster_len` robots.
    pub fn empty(roster_len: usize) -> Self {
        MemberSet(FixedBitSet::with_capacity(roster_len))
    }
    /// Every robot of a roster of `roster_len`.
    pub fn all(roster_len: usize) -> Self {
        let mut s = FixedBitSet::with_capacity(roster_len);
        s.insert_range(..);
        MemberSet(s)
    }
    /// The set of the given robots (ids beyond `roster_len` are ignored).
    pub fn from_iter(roster_len: usize, robots: impl IntoIterator<Item = RobotId>) -> Self {
        let mut s = Self::empty(roster_len);
        for r in robots {
            s.insert(r);
        }
        s
    }
    /// Add a robot (ignored if outside the roster). Returns whether it was new.
    pub fn insert(&mut self, r: RobotId) -> bool {
        if r.index() >= self.0.len() {
            return false;
        }
        !self.0.put(r.index())
    }
    /// Remove a robot.
    pub fn remove(&mut self, r: RobotId) {
        if r.index() < self.0.len() {
            self.0.set(r.index(), false);
        }
    }
    /// Membership test.
    #[inline]
    pub fn contains(&self, r: RobotId) -> bool {
        self.0.contains(r.index())
    }
    /// Number of members.
    pub fn len(&self) -> usize {
        self.0.count_ones(..)
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_clear()
    }
    /// How many members have a lower id than `r` (its 0-based rank when
    /// it is a member).
    pub fn rank(&self, r: RobotId) -> usize {
        self.0.count_ones(..r.index().min(self.0.len()))
    }
    /// Members in increasing id order.
    pub fn iter(&self) -> impl Iterator<Item = RobotId> + '_ {
        self.0.ones().map(|i| RobotId(i as u32))
    }
    /// The lowest member.
    pub fn first(&self) -> Option<RobotId> {
        self.0.minimum().map(|i| RobotId(i as u32))
    }
    /// Size of the roster this set ranges over.
    pub fn roster_len(&self) -> usize {
        self.0.len()
    }
    /// True when every member of `self` is in `other`.
    pub fn is_subset(&self, other: &MemberSet) -> bool {
        self.0.is_subset(&other.0)
    }
    /// Members as a vector.
    pub fn to_vec(&self) -> Vec<RobotId> {
        self.iter().collect()
    }
    /// True when no robot is in both sets.
    pub fn is_disjoint(&self, other: &MemberSet) -> bool {
        self.0.is_disjoint(&other.0)
    }
    /// Add every member of `other`.
    pub fn union_with(&mut self, other: &MemberSet) {
        self.0.union_with(&other.0);
    }
    /// A stable fingerprint of the set (equal sets, equal fingerprints).
    pub fn fingerprint(&self) -> u64 {
        let mut h = crate::ids::Fnv1a::new();
        h.write(&(self.0.len() as u64).to_le_bytes());
        for block in self.0.as_slice() {
            h.write(&(*block as u64).to_le_bytes());
        }
        h.finish()
    }
    /// Split the members, in increasing id order, into consecutive groups of
    /// `counts[i]` members each (members beyond the total are left out).
    /// Works a machine word at a time: O(roster / 64 + groups · 64).
    pub fn split_by_rank(&self, counts: &[u32]) -> Vec<MemberSet> {
        let len = self.0.len();
        let mut out: Vec<FixedBitSet> = counts
            .iter()
            .map(|_| FixedBitSet::with_capacity(len))
            .collect();
        let mut group = 0;
        let mut left = counts.first().copied().unwrap_or(0) as usize;
        'blocks: for (w, &block) in self.0.as_slice().iter().enumerate() {
            let mut rest = block;
            while rest != 0 {
                while left == 0 {
                    group += 1;
                    match counts.get(group) {
                        Some(c) => left = *c as usize,
                        None => break 'blocks,
                    }
                }
                let ones = rest.count_ones() as usize;
                let dst = out[group].as_mut_slice();
                if ones <= left {
                    dst[w] |= rest;
                    left -= ones;
                    rest = 0;
                } else {
                    // Take the lowest `left` members of this word.
                    let mut take = 0usize;
                    let mut r = rest;
                    for _ in 0..left {
                        let low = r & r.wrapping_neg();
                        take |= low;
                        r &= !low;
                    }
                    dst[w] |= take;
                    rest &= !take;
                    left = 0;
                }
            }
        }
        out.into_iter().map(MemberSet).collect()
    }
}

/// A vertex of the hierarchy.
#[derive(Clone, Debug)]
pub struct Team {
    /// Its id.
    pub id: TeamId,
    /// Its members.
    pub members: Arc<MemberSet>,
    /// Number of members (cached).
    pub size: u32,
    /// The team it was split from (`None` for the root).
    pub parent: Option<TeamId>,
    /// The allocation that created it: point, epoch, child index.
    pub origin: Option<(BehaviorId, u32, u32)>,
    /// Subteams split from it that are still alive.
    pub children: Vec<TeamId>,
}

impl Team {
    /// The lowest-id member: the default coordinator of team protocols.
    pub fn leader(&self) -> Option<RobotId> {
        self.members.first()
    }
    /// Membership test.
    #[inline]
    pub fn contains(&self, r: RobotId) -> bool {
        self.members.contains(r)
    }
}

/// How many dissolved team ids a robot remembers, to recognise late
/// messages addressed to them.
const DEAD_TEAMS_REMEMBERED: usize = 4096;

/// One robot's copy of the organization hierarchy.
#[derive(Clone, Debug)]
pub struct Organization {
    roster_len: usize,
    teams: BTreeMap<TeamId, Team>,
    /// behavior → subteams linked to it (who runs b?).
    by_behavior: BTreeMap<BehaviorId, BTreeSet<TeamId>>,
    /// subteam → behaviors linked to it (what does t run?).
    by_team: BTreeMap<TeamId, BTreeSet<BehaviorId>>,
    /// Execution counts: how many times team t has started behavior b.
    runs: BTreeMap<(TeamId, BehaviorId), u32>,
    dead: VecDeque<TeamId>,
    dead_set: BTreeSet<TeamId>,
}

impl Organization {
    /// The hierarchy of a roster of `roster_len` robots: just the root team.
    pub fn new(roster_len: usize) -> Self {
        Self::with_root(Arc::new(MemberSet::all(roster_len)))
    }

    /// The hierarchy whose root team has these members (shared, so that a
    /// simulator running 10,000 kernels stores the root set once).
    pub fn with_root(root: Arc<MemberSet>) -> Self {
        let roster_len = root.roster_len();
        let size = root.len() as u32;
        let mut teams = BTreeMap::new();
        teams.insert(
            TeamId::ROOT,
            Team {
                id: TeamId::ROOT,
                members: root,
                size,
                parent: None,
                origin: None,
                children: Vec::new(),
            },
        );
        Organization {
            roster_len,
            teams,
            by_behavior: BTreeMap::new(),
            by_team: BTreeMap::new(),
            runs: BTreeMap::new(),
            dead: VecDeque::new(),
            dead_set: BTreeSet::new(),
        }
    }

    /// Size of the roster.
    pub fn roster_len(&self) -> usize {
        self.roster_len
    }
    /// A team, if alive.
    pub fn team(&self, id: TeamId) -> Option<&Team> {
        self.teams.get(&id)
    }
    /// The root team.
    pub fn root(&self) -> &Team {
        // The root is inserted at construction and never removed.
        &self.teams[&TeamId::ROOT]
    }
    /// Every live team, in id order.
    pub fn teams(&self) -> impl Iterator<Item = &Team> {
        self.teams.values()
    }
    /// True when `id` was a team that has since been dissolved.
    pub fn is_dead(&self, id: TeamId) -> bool {
        self.dead_set.contains(&id)
    }

    /// Record a subteam split from `parent` by an allocation. Re-adding an
    /// existing team (same derived id) is a no-op.
    pub fn add_subteam(
        &mut self,
        parent: TeamId,
        id: TeamId,
        members: Arc<MemberSet>,
        origin: (BehaviorId, u32, u32),
    ) {
        if self.teams.contains_key(&id) {
            return;
        }
        let size = members.len() as u32;
        self.teams.insert(
            id,
            Team {
                id,
                members,
                size,
                parent: Some(parent),
                origin: Some(origin),
                children: Vec::new(),
            },
        );
        if let Some(p) = self.teams.get_mut(&parent) {
            p.children.push(id);
        }
    }

    /// Dissolve every subteam below `id` (not `id` itself): used when the
    /// behavior whose allocation created them terminates.
    pub fn dissolve_children(&mut self, id: TeamId) {
        let kids = match self.teams.get_mut(&id) {
            Some(t) => std::mem::take(&mut t.children),
            None => return,
        };
        for k in kids {
            self.dissolve(k);
        }
    }

    /// Dissolve `id` and everything below it.
    pub fn dissolve(&mut self, id: TeamId) {
        if id == TeamId::ROOT {
            return;
        }
        let Some(team) = self.teams.remove(&id) else {
            return;
        };
        if let Some(p) = team.parent.and_then(|p| self.teams.get_mut(&p)) {
            p.children.retain(|c| *c != id);
        }
        for k in team.children {
            self.dissolve(k);
        }
        if let Some(bs) = self.by_team.remove(&id) {
            for b in bs {
                if let Some(ts) = self.by_behavior.get_mut(&b) {
                    ts.remove(&id);
                    if ts.is_empty() {
                        self.by_behavior.remove(&b);
                    }
                }
            }
        }
        self.runs.retain(|(t, _), _| *t != id);
        if self.dead_set.insert(id) {
            self.dead.push_back(id);
            if self.dead.len() > DEAD_TEAMS_REMEMBERED
                && let Some(old) = self.dead.pop_front()
            {
                self.dead_set.remove(&old);
            }
        }
    }

    /// Link behavior `b` and team `t` both ways (t executes b).
    pub fn link(&mut self, b: BehaviorId, t: TeamId) {
        self.by_behavior.entry(b).or_default().insert(t);
        self.by_team.entry(t).or_default().insert(b);
    }
    /// Remove the link between `b` and `t`.
    pub fn unlink(&mut self, b: BehaviorId, t: TeamId) {
        if let Some(ts) = self.by_behavior.get_mut(&b) {
            ts.remove(&t);
            if ts.is_empty() {
                self.by_behavior.remove(&b);
            }
        }
        if let Some(bs) = self.by_team.get_mut(&t) {
            bs.remove(&b);
            if bs.is_empty() {
                self.by_team.remove(&t);
            }
        }
    }
    /// Who runs behavior `b`? The teams linked to it.
    pub fn teams_running(&self, b: BehaviorId) -> impl Iterator<Item = TeamId> + '_ {
        self.by_behavior.get(&b).into_iter().flatten().copied()
    }
    /// What does team `t` run? The behaviors linked to it.
    pub fn behaviors_of(&self, t: TeamId) -> impl Iterator<Item = BehaviorId> + '_ {
        self.by_team.get(&t).into_iter().flatten().copied()
    }

    /// Count one more execution of `b` by `t`; returns the new count (the
    /// epoch of that execution, from 1).
    pub fn start_run(&mut self, t: TeamId, b: BehaviorId) -> u32 {
        let n = self.runs.entry((t, b)).or_insert(0);
        *n = n.saturating_add(1);
        *n
    }
    /// Make the count of `t`'s executions of `b` at least `n` (an execution
    /// burned or adopted to converge with teammates is never started again).
    pub fn runs_at_least(&mut self, t: TeamId, b: BehaviorId, n: u32) {
        let c = self.runs.entry((t, b)).or_insert(0);
        *c = (*c).max(n);
    }
    /// How many times `t` has started `b`.
    pub fn runs(&self, t: TeamId, b: BehaviorId) -> u32 {
        self.runs.get(&(t, b)).copied().unwrap_or(0)
    }

    /// The smallest live teams containing `r` (its parents in the DAG, as a
    /// singleton leaf).
    pub fn teams_of(&self, r: RobotId) -> Vec<TeamId> {
        self.teams
            .values()
            .filter(|t| t.contains(r))
            .filter(|t| {
                !t.children
                    .iter()
                    .any(|c| self.teams.get(c).is_some_and(|c| c.contains(r)))
            })
            .map(|t| t.id)
            .collect()
    }

    /// Check the hierarchy's structural invariants: every subteam is a
    /// subset of its parent, children lists match parent links, and every
    /// link points at a live team. Returns the first violation.
    pub fn check_invariants(&self) -> Result<(), String> {
        for t in self.teams.values() {
            if let Some(p) = t.parent {
                let Some(pt) = self.teams.get(&p) else {
                    return Err(format!("team {} has dissolved parent {}", t.id, p));
                };
                if !t.members.is_subset(&pt.members) {
                    return Err(format!("team {} is not a subset of its parent {}", t.id, p));
                }
                if !pt.children.contains(&t.id) {
                    return Err(format!("parent {} does not list child {}", p, t.id));
                }
            } else if t.id != TeamId::ROOT {
                return Err(format!("team {} has no parent", t.id));
            }
        }
        for (b, ts) in &self.by_behavior {
            for t in ts {
                if !self.teams.contains_key(t) {
                    return Err(format!("behavior b{} linked to dissolved team {}", b.0, t));
                }
                if !self.by_team.get(t).is_some_and(|bs| bs.contains(b)) {
                    return Err(format!("link b{} -> {} has no inverse", b.0, t));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hierarchy_links_both_ways_and_dissolves() {
        let mut org = Organization::new(4);
        assert_eq!(org.root().size, 4);
        let walk = BehaviorId(1);
        let lead = BehaviorId(2);
        let follow = BehaviorId(3);
        org.link(walk, TeamId::ROOT);
        let t1 = TeamId::derive(TeamId::ROOT, walk, (1, 0), 0, 1);
        let t2 = TeamId::derive(TeamId::ROOT, walk, (1, 0), 1, 2);
        org.add_subteam(
            TeamId::ROOT,
            t1,
            Arc::new(MemberSet::from_iter(4, [RobotId(0)])),
            (walk, 1, 0),
        );
        org.add_subteam(
            TeamId::ROOT,
            t2,
            Arc::new(MemberSet::from_iter(
                4,
                [RobotId(1), RobotId(2), RobotId(3)],
            )),
            (walk, 1, 1),
        );
        org.link(lead, t1);
        org.link(follow, t2);
        assert_eq!(org.teams_running(follow).collect::<Vec<_>>(), vec![t2]);
        assert_eq!(org.behaviors_of(t1).collect::<Vec<_>>(), vec![lead]);
        assert_eq!(org.teams_of(RobotId(2)), vec![t2]);
        org.check_invariants().unwrap();
        assert_eq!(org.start_run(t2, follow), 1);
        assert_eq!(org.start_run(t2, follow), 2);
        org.dissolve_children(TeamId::ROOT);
        assert!(org.team(t1).is_none() && org.is_dead(t1));
        assert_eq!(org.teams_running(follow).count(), 0);
        assert_eq!(org.runs(t2, follow), 0);
        assert_eq!(org.teams_of(RobotId(2)), vec![TeamId::ROOT]);
        org.check_invariants().unwrap();
    }

    #[test]
    fn member_sets() {
        let mut s = MemberSet::empty(10);
        assert!(s.insert(RobotId(3)));
        assert!(!s.insert(RobotId(3)));
        assert!(!s.insert(RobotId(42)), "outside the roster is ignored");
        s.insert(RobotId(1));
        assert_eq!(s.to_vec(), vec![RobotId(1), RobotId(3)]);
        assert_eq!(s.first(), Some(RobotId(1)));
        assert_eq!(MemberSet::all(3).len(), 3);
    }
}
