//! The organization hierarchy (team hierarchy): a DAG whose vertices are
//! subteams, from the root team of all robots down to singletons, with
//! bidirectional links between behaviors and the subteams executing them.
//!
//! Each robot keeps its own copy. Subteams are created by allocations and
//! their ids are derived from the allocation ([`TeamId::derive`]), so every
//! member that applies the same allocation builds the same hierarchy.
//! Singletons are implicit leaves: `{r}` is a child of the smallest stored
//! team that contains `r`.

use crate::ids::{BehaviorId, Fnv1a, RobotId, TeamId};
pub use crate::members::{Assignment, MemberSet, Members};
use litemap::LiteMap;
use smallvec::SmallVec;
use std::collections::VecDeque;
use std::sync::{Arc, OnceLock};

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

/// Splits with more subteams than this index their members by robot.
const INDEXED_SPLIT: usize = 16;

/// Splits of at most this many subteams find one by reading their ids in
/// order, not by binary search through `by_id`.
const FEW_SUBTEAMS: usize = 8;

/// The subteams one allocation made, one per child given members, each
/// linked to its child. Immutable, and shared (behind an `Arc`) by every
/// robot of a process that applied the same allocation: a simulator
/// running 10,000 kernels that split 10,000 robots among 10,000 children
/// stores those 10,000 subteams once, not 10⁸ times (see
/// [`crate::mission::Mission::split`]).
#[derive(Debug)]
pub struct Split {
    parent: TeamId,
    point: BehaviorId,
    stamp: (u32, u32),
    assignment: Arc<Assignment>,
    /// The subteams with the child each was made for, in the
    /// assignment's order.
    teams: Vec<(BehaviorId, Team)>,
    /// Indices of `teams`, by team id, for splits of more than
    /// [`FEW_SUBTEAMS`] (empty otherwise).
    by_id: SmallVec<[u32; 8]>,
    /// Indices of `teams`, by child.
    by_head: SmallVec<[u32; 8]>,
    /// For each robot of the roster, 1 + the index of its subteam (0:
    /// none); only for splits with many subteams.
    member_of: Vec<u32>,
    /// FNV-1a over the subteam ids in order.
    print: u64,
    /// The assignment as the run log shows it (made once, when asked).
    log: OnceLock<crate::event::LogList<(BehaviorId, crate::event::MembersLog)>>,
}

impl Split {
    /// The subteams of `parent` that `assignment` makes at execution
    /// `stamp` (epoch, round) of allocation point `point`: one per child
    /// with members, its id derived from all of that ([`TeamId::derive`]);
    /// `index` gives a child's position among the point's children.
    pub fn new(
        parent: TeamId,
        point: BehaviorId,
        stamp: (u32, u32),
        assignment: Arc<Assignment>,
        index: impl Fn(BehaviorId) -> Option<u32>,
    ) -> Split {
        let mut teams = Vec::with_capacity(assignment.0.len());
        let mut h = Fnv1a::new();
        for (child, members) in &assignment.0 {
            if members.is_empty() {
                continue;
            }
            let Some(idx) = index(*child) else {
                continue;
            };
            let id = TeamId::derive(parent, point, stamp, idx, members.fingerprint());
            h.write(&id.0.to_le_bytes());
            let team = Team {
                id,
                members: Arc::new(members.clone()),
                size: members.len() as u32,
                parent: Some(parent),
                origin: Some((point, stamp.0, idx)),
            };
            teams.push((*child, team));
        }
        // A few subteams are found without it (see `Split::index`).
        let mut by_id: SmallVec<[u32; 8]> = SmallVec::new();
        if teams.len() > FEW_SUBTEAMS {
            by_id.extend(0..teams.len() as u32);
            by_id.sort_by_key(|i| teams[*i as usize].1.id);
        }
        let mut by_head: SmallVec<[u32; 8]> = (0..teams.len() as u32).collect();
        by_head.sort_by_key(|i| teams[*i as usize].0);
        let mut member_of = Vec::new();
        if teams.len() > INDEXED_SPLIT {
            let roster = teams.first().map_or(0, |(_, t)| t.members.roster_len());
            member_of = vec![0; roster];
            for (i, (_, t)) in teams.iter().enumerate() {
                for r in t.members.iter() {
                    if member_of[r.index()] == 0 {
                        member_of[r.index()] = i as u32 + 1;
                    }
                }
            }
        }
        Split {
            parent,
            point,
            stamp,
            assignment,
            teams,
            by_id,
            by_head,
            member_of,
            print: h.finish(),
            log: OnceLock::new(),
        }
    }
    /// The team that was split.
    pub fn parent(&self) -> TeamId {
        self.parent
    }
    /// The allocation point.
    pub fn point(&self) -> BehaviorId {
        self.point
    }
    /// The execution of the point: (epoch, round).
    pub fn stamp(&self) -> (u32, u32) {
        self.stamp
    }
    /// The allocation applied.
    pub fn assignment(&self) -> &Arc<Assignment> {
        &self.assignment
    }
    /// The subteams, with the child each runs, in the assignment's order.
    pub fn subteams(&self) -> impl Iterator<Item = (BehaviorId, &Team)> {
        self.teams.iter().map(|(b, t)| (*b, t))
    }
    /// Number of subteams.
    pub fn len(&self) -> usize {
        self.teams.len()
    }
    /// True when the allocation gave no child any member.
    pub fn is_empty(&self) -> bool {
        self.teams.is_empty()
    }
    /// The position of subteam `id` in the assignment's order.
    #[inline]
    fn index(&self, id: TeamId) -> Option<usize> {
        // A few subteams (nearly every split): read their ids in a row;
        // asked of every link and count when the split dissolves.
        if self.teams.len() <= FEW_SUBTEAMS {
            return self.teams.iter().position(|(_, t)| t.id == id);
        }
        self.by_id
            .binary_search_by_key(&id, |i| self.teams[*i as usize].1.id)
            .ok()
            .map(|k| self.by_id[k] as usize)
    }
    /// A subteam of this split.
    pub fn team(&self, id: TeamId) -> Option<&Team> {
        self.index(id).map(|i| &self.teams[i].1)
    }
    /// True when `id` is one of its subteams.
    pub fn contains(&self, id: TeamId) -> bool {
        self.team(id).is_some()
    }
    /// The subteam made for child `b`.
    fn of_head(&self, b: BehaviorId) -> Option<&Team> {
        self.by_head
            .binary_search_by_key(&b, |i| self.teams[*i as usize].0)
            .ok()
            .map(|k| &self.teams[self.by_head[k] as usize].1)
    }
    /// The child robot `r` was given, and its subteam.
    pub fn subteam_of(&self, r: RobotId) -> Option<(BehaviorId, &Team)> {
        let i = if self.member_of.is_empty() {
            self.teams.iter().position(|(_, t)| t.contains(r))?
        } else {
            (*self.member_of.get(r.index())? as usize).checked_sub(1)?
        };
        let (b, t) = &self.teams[i];
        Some((*b, t))
    }
    /// FNV-1a over the subteam ids in order: equal for robots that applied
    /// the same allocation (what positions carry to compare allocations).
    pub fn print(&self) -> u64 {
        self.print
    }
    /// The assignment as the run log shows it: the list of members for
    /// subteams up to [`crate::event::LOG_MEMBERS_LIMIT`], a count and a
    /// fingerprint for larger ones. Made once and shared.
    pub fn log(&self) -> &crate::event::LogList<(BehaviorId, crate::event::MembersLog)> {
        self.log
            .get_or_init(|| crate::event::OutcomeLog::members_log(&self.assignment))
    }
}

/// How many dissolved team ids a robot remembers, to recognise late
/// messages addressed to them.
const DEAD_TEAMS_REMEMBERED: usize = 4096;
/// How many of the newest dissolved teams `is_dead` reads in place before
/// asking the set (one cache line of ids).
const NEWEST_DEAD: usize = 8;
/// Splits of more subteams than this are remembered whole when dissolved
/// (shared, so they cost a robot a pointer), the last few of them.
const DEAD_SPLIT_SIZE: usize = 64;
const DEAD_SPLITS_REMEMBERED: usize = 8;

/// The keys of a set from `lo` on, in order.
fn from_key<A: Ord + Copy, B: Ord + Copy>(
    set: &LiteMap<(A, B), ()>,
    lo: (A, B),
) -> impl Iterator<Item = (A, B)> + '_ {
    let at = set.find_index(&lo).unwrap_or_else(|i| i);
    set.as_slice()[at..].iter().map(|(k, _)| *k)
}

/// A team's count of its executions of a behavior (the epoch of the
/// latest, from 1), and the highest of them this robot started itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct RunCount {
    count: u32,
    started: u32,
}

/// One robot's copy of the organization hierarchy.
///
/// The root team, and the [`Split`]s of the allocations this robot applied
/// that are still alive (few: one per allocating behavior on its stack).
/// Links between behaviors and subteams are those the splits made, minus
/// the ones removed since, plus the ones added since.
#[derive(Clone, Debug)]
pub struct Organization {
    roster_len: usize,
    root: Team,
    splits: Vec<Arc<Split>>,
    /// Links beyond those the splits made: behavior → team, team → behavior.
    /// These and the counts are sorted vectors (`LiteMap`): a robot keeps
    /// a handful of each (fewer than 16 links and 32 counts in every
    /// shipped run), changes them at every decision and reads the counts
    /// at every heartbeat; B-trees spent a tenth of a decision step
    /// rebalancing and cost a cache miss per node at 100,000 robots.
    links: LiteMap<(BehaviorId, TeamId), ()>,
    links_by_team: LiteMap<(TeamId, BehaviorId), ()>,
    /// Links a split made that were removed since.
    unlinked: LiteMap<(BehaviorId, TeamId), ()>,
    /// Execution counts: how many times team t has started behavior b,
    /// and the highest of those executions this robot started itself.
    runs: LiteMap<(TeamId, BehaviorId), RunCount>,
    /// Dissolved teams, oldest first, and the same as a set (looked up for
    /// every message, changed at every dissolution, never walked: a hash
    /// set; a B-tree of 4,096 ids was a tenth of a decision step).
    dead: VecDeque<TeamId>,
    dead_set: rustc_hash::FxHashSet<TeamId>,
    dead_splits: VecDeque<Arc<Split>>,
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
        Organization {
            roster_len,
            root: Team {
                id: TeamId::ROOT,
                members: root,
                size,
                parent: None,
                origin: None,
            },
            splits: Vec::new(),
            links: LiteMap::new(),
            links_by_team: LiteMap::new(),
            unlinked: LiteMap::new(),
            runs: LiteMap::new(),
            dead: VecDeque::new(),
            dead_set: rustc_hash::FxHashSet::default(),
            dead_splits: VecDeque::new(),
        }
    }

    /// Size of the roster.
    pub fn roster_len(&self) -> usize {
        self.roster_len
    }
    /// A team, if alive.
    pub fn team(&self, id: TeamId) -> Option<&Team> {
        if id == TeamId::ROOT {
            return Some(&self.root);
        }
        self.splits.iter().rev().find_map(|s| s.team(id))
    }
    /// The split that made team `id`, if alive.
    fn split_of(&self, id: TeamId) -> Option<&Arc<Split>> {
        self.splits.iter().rev().find(|s| s.contains(id))
    }
    /// The root team.
    pub fn root(&self) -> &Team {
        &self.root
    }
    /// Every live team: the root, then each allocation's subteams.
    pub fn teams(&self) -> impl Iterator<Item = &Team> {
        std::iter::once(&self.root).chain(
            self.splits
                .iter()
                .flat_map(|s| s.teams.iter().map(|(_, t)| t)),
        )
    }
    /// The live splits, oldest first.
    pub fn splits(&self) -> &[Arc<Split>] {
        &self.splits
    }
    /// The live subteams split from `id`.
    pub fn subteams_of(&self, id: TeamId) -> impl Iterator<Item = &Team> {
        self.splits
            .iter()
            .filter(move |s| s.parent == id)
            .flat_map(|s| s.teams.iter().map(|(_, t)| t))
    }
    /// True when `id` was a team that has since been dissolved.
    pub fn is_dead(&self, id: TeamId) -> bool {
        // The newest first, read in place: a teammate's heartbeat reports
        // executions of teams dissolved moments ago, again and again, and
        // at 100,000 robots the hash set's cache misses were half of
        // counting executions (`runs_at_least`).
        self.dead.iter().rev().take(NEWEST_DEAD).any(|t| *t == id)
            || self.dead_set.contains(&id)
            || self.dead_splits.iter().any(|s| s.contains(id))
    }

    /// Record the subteams of an allocation (linked to their children).
    /// Adding a split already recorded (same parent, point and stamp) is a
    /// no-op.
    pub fn add_split(&mut self, split: Arc<Split>) {
        if self.splits.iter().any(|s| {
            Arc::ptr_eq(s, &split)
                || (s.parent, s.point, s.stamp) == (split.parent, split.point, split.stamp)
        }) {
            return;
        }
        self.splits.push(split);
    }

    /// Dissolve every subteam below `id` (not `id` itself): used when the
    /// behavior whose allocation created them terminates.
    pub fn dissolve_children(&mut self, id: TeamId) {
        let below: Vec<Arc<Split>> = self
            .splits
            .iter()
            .filter(|s| s.parent == id)
            .cloned()
            .collect();
        for s in below {
            self.dissolve_split(&s);
        }
    }

    /// Dissolve `id` with the other subteams of the allocation that made
    /// it (they live and end together), and everything below them.
    pub fn dissolve(&mut self, id: TeamId) {
        if let Some(s) = self.split_of(id).cloned() {
            self.dissolve_split(&s);
        }
    }

    /// Dissolve the subteams of a split, and everything below them.
    pub fn dissolve_split(&mut self, split: &Arc<Split>) {
        let Some(at) = self.splits.iter().position(|s| Arc::ptr_eq(s, split)) else {
            return;
        };
        let split = self.splits.remove(at);
        let below: Vec<Arc<Split>> = self
            .splits
            .iter()
            .filter(|s| split.contains(s.parent))
            .cloned()
            .collect();
        for s in below {
            self.dissolve_split(&s);
        }
        let gone = |t: &TeamId| split.contains(*t);
        self.links.retain(|(_, t), _| !gone(t));
        self.links_by_team.retain(|(t, _), _| !gone(t));
        self.unlinked.retain(|(_, t), _| !gone(t));
        self.runs.retain(|(t, _), _| !gone(t));
        if split.len() > DEAD_SPLIT_SIZE {
            self.dead_splits.push_back(split);
            if self.dead_splits.len() > DEAD_SPLITS_REMEMBERED {
                self.dead_splits.pop_front();
            }
            return;
        }
        for (_, t) in &split.teams {
            if self.dead_set.insert(t.id) {
                self.dead.push_back(t.id);
                if self.dead.len() > DEAD_TEAMS_REMEMBERED
                    && let Some(old) = self.dead.pop_front()
                {
                    self.dead_set.remove(&old);
                }
            }
        }
    }

    /// True when a split made the link `b` ↔ `t` (`t` made for child `b`).
    fn split_link(&self, b: BehaviorId, t: TeamId) -> bool {
        self.split_of(t)
            .and_then(|s| s.of_head(b))
            .is_some_and(|x| x.id == t)
    }

    /// Link behavior `b` and team `t` both ways (t executes b).
    pub fn link(&mut self, b: BehaviorId, t: TeamId) {
        if self.split_link(b, t) {
            self.unlinked.remove(&(b, t));
        } else {
            self.links.insert((b, t), ());
            self.links_by_team.insert((t, b), ());
        }
    }
    /// Remove the link between `b` and `t`.
    pub fn unlink(&mut self, b: BehaviorId, t: TeamId) {
        if self.split_link(b, t) {
            self.unlinked.insert((b, t), ());
        } else {
            self.links.remove(&(b, t));
            self.links_by_team.remove(&(t, b));
        }
    }
    /// Who runs behavior `b`? The teams linked to it, in id order.
    pub fn teams_running(&self, b: BehaviorId) -> impl Iterator<Item = TeamId> + '_ {
        let mut ts: Vec<TeamId> = from_key(&self.links, (b, TeamId(0)))
            .take_while(|(x, _)| *x == b)
            .map(|(_, t)| t)
            .collect();
        for s in &self.splits {
            if let Some(t) = s.of_head(b)
                && !self.unlinked.contains_key(&(b, t.id))
            {
                ts.push(t.id);
            }
        }
        ts.sort_unstable();
        ts.dedup();
        ts.into_iter()
    }
    /// What does team `t` run? The behaviors linked to it, in id order.
    pub fn behaviors_of(&self, t: TeamId) -> impl Iterator<Item = BehaviorId> + '_ {
        let mut bs: Vec<BehaviorId> = from_key(&self.links_by_team, (t, BehaviorId(0)))
            .take_while(|(x, _)| *x == t)
            .map(|(_, b)| b)
            .collect();
        if let Some(s) = self.split_of(t)
            && let Some(b) = s.index(t).map(|i| s.teams[i].0)
            && !self.unlinked.contains_key(&(b, t))
        {
            bs.push(b);
        }
        bs.sort_unstable();
        bs.dedup();
        bs.into_iter()
    }

    /// Count one more execution of `b` by `t`; returns the new count (the
    /// epoch of that execution, from 1).
    pub fn start_run(&mut self, t: TeamId, b: BehaviorId) -> u32 {
        let n = self.runs.entry((t, b)).or_default();
        n.count = n.count.saturating_add(1);
        n.started = n.count;
        n.count
    }
    /// Start execution `epoch` of `b` by `t`, a teammate's (to converge
    /// with it), whatever the count: the count is raised to it, never
    /// lowered. Returns `epoch`.
    pub fn start_run_at(&mut self, t: TeamId, b: BehaviorId, epoch: u32) -> u32 {
        let n = self.runs.entry((t, b)).or_default();
        n.count = n.count.max(epoch);
        n.started = n.started.max(epoch);
        epoch
    }
    /// The highest execution of `b` by `t` this robot started itself (0:
    /// none): a count raised by teammates' word is not a start.
    pub fn started(&self, t: TeamId, b: BehaviorId) -> u32 {
        self.runs.get(&(t, b)).map_or(0, |n| n.started)
    }
    /// Make the count of `t`'s executions of `b` at least `n` (an execution
    /// burned or adopted to converge with teammates is never started again).
    /// A team dissolved here never runs again: its count is not kept (a
    /// teammate's word on it would otherwise linger for good).
    pub fn runs_at_least(&mut self, t: TeamId, b: BehaviorId, n: u32) {
        // A count kept is of a live team (dissolving a team drops its
        // counts), so the dead teams are only asked about a new one: a
        // teammate's heartbeat mostly repeats counts already kept, and at
        // 100,000 robots asking cost a cache miss each time.
        if let Some(c) = self.runs.get_mut(&(t, b)) {
            c.count = c.count.max(n);
        } else if !self.is_dead(t) {
            self.runs.insert(
                (t, b),
                RunCount {
                    count: n,
                    started: 0,
                },
            );
        }
    }
    /// Ask for the execution counts (read at every teammate's heartbeat)
    /// to be brought into the cache; see [`crate::kernel::Kernel::prefetch`].
    pub fn prefetch(&self) {
        crate::hint::prefetch_slice(self.runs.as_slice(), 2);
        let (older, newer) = self.dead.as_slices();
        let newest = if newer.is_empty() { older } else { newer };
        crate::hint::prefetch_slice(&newest[newest.len().saturating_sub(NEWEST_DEAD)..], 2);
    }
    /// How many times `t` has started `b`.
    pub fn runs(&self, t: TeamId, b: BehaviorId) -> u32 {
        self.runs.get(&(t, b)).map_or(0, |n| n.count)
    }

    /// The smallest live teams containing `r` (its parents in the DAG, as a
    /// singleton leaf).
    pub fn teams_of(&self, r: RobotId) -> Vec<TeamId> {
        self.teams()
            .filter(|t| t.contains(r))
            .filter(|t| !self.subteams_of(t.id).any(|c| c.contains(r)))
            .map(|t| t.id)
            .collect()
    }

    /// Check the hierarchy's structural invariants: every subteam is a
    /// subset of its parent, and every link points at a live team. Returns
    /// the first violation.
    pub fn check_invariants(&self) -> Result<(), String> {
        for s in &self.splits {
            let Some(pt) = self.team(s.parent) else {
                return Err(format!("the subteams of {} outlive their parent", s.parent));
            };
            for (_, t) in &s.teams {
                if t.parent != Some(s.parent) {
                    return Err(format!(
                        "team {} does not name its parent {}",
                        t.id, s.parent
                    ));
                }
                if !t.members.is_subset(&pt.members) {
                    return Err(format!(
                        "team {} is not a subset of its parent {}",
                        t.id, s.parent
                    ));
                }
            }
        }
        for (b, t) in self.links.keys() {
            if self.team(*t).is_none() {
                return Err(format!("behavior b{} linked to dissolved team {}", b.0, t));
            }
            if !self.links_by_team.contains_key(&(*t, *b)) {
                return Err(format!("link b{} -> {} has no inverse", b.0, t));
            }
        }
        if self.links.len() != self.links_by_team.len() {
            return Err("links and their inverses differ".into());
        }
        // Counts are kept for teams not formed here yet (a teammate's word
        // on them), never for dissolved ones.
        if let Some((t, b)) = (self.runs.keys()).find(|(t, _)| self.is_dead(*t)) {
            return Err(format!("runs of b{} kept for dissolved team {}", b.0, t));
        }
        if let Some((b, t)) = (self.unlinked.keys()).find(|(_, t)| self.team(*t).is_none()) {
            return Err(format!(
                "behavior b{} unlinked from dissolved team {}",
                b.0, t
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fixedbitset::FixedBitSet;
    use serde::Serialize;

    fn set(n: usize, ids: &[u32]) -> MemberSet {
        MemberSet::from_iter(n, ids.iter().map(|i| RobotId(*i)))
    }

    #[test]
    fn hierarchy_links_both_ways_and_dissolves() {
        let mut org = Organization::new(4);
        assert_eq!(org.root().size, 4);
        let walk = BehaviorId(1);
        let lead = BehaviorId(2);
        let follow = BehaviorId(3);
        let inner = BehaviorId(4);
        org.link(walk, TeamId::ROOT);
        let asg = Assignment(vec![(lead, set(4, &[0])), (follow, set(4, &[1, 2, 3]))]);
        let index = |b: BehaviorId| Some(b.0 - 2);
        let split = Arc::new(Split::new(TeamId::ROOT, walk, (1, 0), Arc::new(asg), index));
        let t1 = TeamId::derive(TeamId::ROOT, walk, (1, 0), 0, set(4, &[0]).fingerprint());
        let t2 = TeamId::derive(
            TeamId::ROOT,
            walk,
            (1, 0),
            1,
            set(4, &[1, 2, 3]).fingerprint(),
        );
        assert_eq!(
            split.subteam_of(RobotId(2)).map(|(b, t)| (b, t.id)),
            Some((follow, t2))
        );
        org.add_split(split.clone());
        org.add_split(split.clone());
        assert_eq!(org.splits().len(), 1, "added once");
        assert_eq!(org.teams_running(follow).collect::<Vec<_>>(), vec![t2]);
        assert_eq!(org.behaviors_of(t1).collect::<Vec<_>>(), vec![lead]);
        assert_eq!(org.teams_of(RobotId(2)), vec![t2]);
        assert_eq!(org.team(t1).map(|t| t.origin), Some(Some((walk, 1, 0))));
        // Links move as the robots' chains go on.
        org.unlink(follow, t2);
        org.link(inner, t2);
        assert_eq!(org.behaviors_of(t2).collect::<Vec<_>>(), vec![inner]);
        assert_eq!(org.teams_running(follow).count(), 0);
        org.link(follow, t2);
        assert_eq!(
            org.behaviors_of(t2).collect::<Vec<_>>(),
            vec![follow, inner]
        );
        org.check_invariants().unwrap();
        assert_eq!(org.start_run(t2, follow), 1);
        assert_eq!(org.start_run(t2, follow), 2);
        // A split of t2, below it: dissolved with it.
        let sub = Assignment(vec![(inner, set(4, &[1]))]);
        let sub = Arc::new(Split::new(t2, follow, (2, 0), Arc::new(sub), |_| Some(0)));
        org.add_split(sub.clone());
        let t3 = sub.subteams().next().map(|(_, t)| t.id).unwrap();
        assert_eq!(org.teams_of(RobotId(1)), vec![t3]);
        assert_eq!(org.subteams_of(t2).count(), 1);
        org.check_invariants().unwrap();
        org.dissolve_children(TeamId::ROOT);
        assert!(org.team(t1).is_none() && org.is_dead(t1) && org.is_dead(t3));
        assert_eq!(org.teams_running(follow).count(), 0);
        assert_eq!(org.behaviors_of(t2).count(), 0);
        assert_eq!(org.runs(t2, follow), 0);
        assert_eq!(org.teams_of(RobotId(2)), vec![TeamId::ROOT]);
        assert_eq!(org.teams().count(), 1);
        org.check_invariants().unwrap();
        // A teammate's word on a dissolved team's runs is not kept; on a
        // team not formed here yet, it is.
        org.runs_at_least(t2, follow, 5);
        assert_eq!(org.runs(t2, follow), 0);
        org.runs_at_least(TeamId(77), follow, 5);
        assert_eq!(org.runs(TeamId(77), follow), 5);
        org.check_invariants().unwrap();
        // A count raised by a teammate's word is not a start of this
        // robot's; a start, or a teammate's execution joined, is.
        assert_eq!(org.started(TeamId(77), follow), 0);
        assert_eq!(org.start_run_at(TeamId(77), follow, 3), 3);
        assert_eq!(org.runs(TeamId(77), follow), 5, "never lowered");
        assert_eq!(org.started(TeamId(77), follow), 3);
        assert_eq!(org.start_run(TeamId(77), follow), 6);
        assert_eq!(org.started(TeamId(77), follow), 6);
    }

    /// Every dissolved team is dead, the newest (read in place) and the
    /// older ones (only in the set) alike; a count is kept for a live team
    /// and raised, never lowered.
    #[test]
    fn dissolved_teams_are_dead_past_the_newest_few() {
        let (walk, lead) = (BehaviorId(1), BehaviorId(2));
        let mut org = Organization::new(4);
        let mut gone = Vec::new();
        for k in 1..=(3 * NEWEST_DEAD as u32) {
            let a = Assignment(vec![(lead, set(4, &[0, 1]))]);
            let s = Arc::new(Split::new(TeamId::ROOT, walk, (k, 0), Arc::new(a), |_| {
                Some(0)
            }));
            org.add_split(s.clone());
            let t = s.subteams().next().map(|(_, t)| t.id).unwrap();
            org.runs_at_least(t, lead, 2);
            org.runs_at_least(t, lead, 1);
            assert_eq!(org.runs(t, lead), 2, "raised, never lowered");
            org.dissolve_children(TeamId::ROOT);
            gone.push(t);
        }
        for t in &gone {
            assert!(org.is_dead(*t) && org.team(*t).is_none());
            org.runs_at_least(*t, lead, 9);
            assert_eq!(org.runs(*t, lead), 0, "no count for a dissolved team");
        }
        assert!(!org.is_dead(TeamId::ROOT));
        org.check_invariants().unwrap();
    }

    /// A subteam is found by id, and a stranger is not, in a split of a
    /// few subteams (ids read in a row) as in a larger one (by binary
    /// search), each robot in the subteam of its child.
    #[test]
    fn splits_find_their_subteams_whatever_their_number() {
        let walk = BehaviorId(1);
        for k in [1u32, 3, FEW_SUBTEAMS as u32, FEW_SUBTEAMS as u32 + 1, 40] {
            let n = k as usize;
            let a = Assignment((0..k).map(|i| (BehaviorId(10 + i), set(n, &[i]))).collect());
            let s = Split::new(TeamId::ROOT, walk, (1, 0), Arc::new(a), |b| Some(b.0 - 10));
            assert_eq!(s.len(), n);
            for (child, t) in s.subteams() {
                assert_eq!(s.team(t.id).map(|x| x.id), Some(t.id), "{k} subteams");
                assert_eq!(s.of_head(child).map(|x| x.id), Some(t.id));
                let r = RobotId(child.0 - 10);
                assert_eq!(s.subteam_of(r).map(|(b, x)| (b, x.id)), Some((child, t.id)));
            }
            assert!(!s.contains(TeamId::ROOT) && !s.contains(TeamId(77)));
        }
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

    /// The old form: a bit set, always.
    fn dense(s: &MemberSet) -> FixedBitSet {
        let mut b = FixedBitSet::with_capacity(s.roster_len());
        for r in s.iter() {
            b.insert(r.index());
        }
        b
    }

    fn dense_fingerprint(b: &FixedBitSet) -> u64 {
        let mut h = Fnv1a::new();
        h.write(&(b.len() as u64).to_le_bytes());
        for block in b.as_slice() {
            h.write(&(*block as u64).to_le_bytes());
        }
        h.finish()
    }

    #[test]
    fn every_form_of_a_set_behaves_as_its_bit_set() {
        for n in [0usize, 3, 5, 64, 65, 200, 1000, 10_000] {
            let mut s = MemberSet::empty(n);
            let mut shadow = FixedBitSet::with_capacity(n);
            // Grows through every form: in place, list, bit set.
            let mut x = 7u64;
            for k in 0..(n / 8 + 6) {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let r = RobotId(((x >> 33) % (n.max(1) as u64)) as u32);
                let new = s.insert(r);
                assert_eq!(new, n > 0 && !shadow.put(r.index()), "n={n} k={k}");
                if k % 5 == 4 && n > 0 {
                    s.remove(r);
                    shadow.set(r.index(), false);
                }
                assert_eq!(dense(&s), shadow, "n={n} k={k}");
                assert_eq!(s.len(), shadow.count_ones(..));
                assert_eq!(s.fingerprint(), dense_fingerprint(&shadow), "n={n} k={k}");
                let again = MemberSet::from_iter(n, s.iter());
                assert_eq!(again, s);
                assert_eq!(again.fingerprint(), s.fingerprint());
                if let Some(r) = s.first() {
                    assert_eq!(s.rank(r), 0);
                    assert!(s.is_subset(&MemberSet::all(n)));
                }
                // The wire form is the bit set's, whatever the form.
                let bytes = postcard::to_allocvec(&s).unwrap();
                #[derive(Serialize)]
                struct Old<'a>(&'a FixedBitSet);
                assert_eq!(bytes, postcard::to_allocvec(&Old(&shadow)).unwrap());
                let back: MemberSet = postcard::from_bytes(&bytes).unwrap();
                assert_eq!(back, s);
            }
        }
    }

    #[test]
    fn splitting_by_rank_keeps_small_groups_small() {
        let all = MemberSet::all(10_000);
        let counts: Vec<u32> = (0..10_000)
            .map(|i| u32::from(i < 9_990))
            .chain([3])
            .collect();
        let parts = all.split_by_rank(&counts);
        assert_eq!(parts.len(), 10_001);
        assert_eq!(parts[0].to_vec(), vec![RobotId(0)]);
        assert_eq!(parts[9_989].to_vec(), vec![RobotId(9_989)]);
        assert!(parts[9_990].is_empty());
        assert_eq!(
            parts[10_000].to_vec(),
            vec![RobotId(9_990), RobotId(9_991), RobotId(9_992)]
        );
        let halves = all.split_by_rank(&[5_000, 5_000]);
        assert_eq!(halves[1].first(), Some(RobotId(5_000)));
        assert_eq!(halves[1].len(), 5_000);
        assert!(halves[0].is_disjoint(&halves[1]));
        let mut u = halves[0].clone();
        u.union_with(&halves[1]);
        assert_eq!(u, all);
        let mut few = set(10_000, &[1, 2]);
        few.union_with(&halves[1]);
        assert_eq!(few.len(), 5_002);
        assert!(!set(10_000, &[1, 9_999]).is_disjoint(&halves[1]));
        assert!(set(10_000, &[1, 2]).is_disjoint(&halves[1]));
    }
}
