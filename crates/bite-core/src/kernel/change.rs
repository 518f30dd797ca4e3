//! Changing a running mission: a new version is held *pending* and each
//! subteam switches to it at a safe point, all its members at the same one.
//!
//! A safe point is a behavior boundary: the moment a team has ended an
//! execution `X` and is about to choose what follows it (Algorithm 1, line
//! 8), before any synchronization instance of that choice starts. Nothing
//! is ever switched inside a behavior or inside a protocol instance, so
//! every instance runs to its end under the version it started in.
//!
//! **Agreement.** At `X` with a version `v` pending, a robot:
//!
//! 1. follows what a teammate already did at `X` for `v` (its heartbeat
//!    lists the recent [`Fence`]s it applied: switched, or went on in the
//!    running version);
//! 2. if it is the team's leader (the lowest-id member neither lost nor
//!    departed, as for healing splits), decides: it switches when every
//!    other such member is heard (recently) holding `v`, and goes on in
//!    the running version otherwise (the next boundary tries again); its
//!    decision travels with its heartbeats;
//! 3. otherwise holds at `X` until it hears the decision (at most
//!    [`FENCE_WAIT`]; then it goes on in the running version and says so).
//!
//! Only the leader decides and every member follows it, so a team never
//! splits over a version; teams the change does not reach keep running and
//! switch at their own next boundary. The new version is numbered like the
//! running one ([`crate::graph::BehaviorGraph::aligned_to`]): instance keys,
//! positions and team ids mean the same in both, so teams on either side of
//! a change still end their common ancestors together.

use super::*;
use crate::graph::Refused;
use crate::kernel::position::{FRESH, FrameId, RECENT};
use serde::Deserialize;

/// How long a member holds at a boundary for its leader's decision (four
/// times as long while its leader is heard, short of the boundary).
pub const FENCE_WAIT: Duration = Duration::from_secs(5);

/// A gap between two inputs of a kernel longer than this: the robot was
/// not running (its process paused or descheduled; a running one has a
/// control tick every period). What it waits for at a safe point, news
/// from its teammates, could not reach it meanwhile: the gap does not
/// count toward [`FENCE_WAIT`].
pub const ASLEEP: Duration = Duration::from_secs(1);

/// How many pending versions a robot holds (the newest).
const HELD: usize = 4;

/// What a robot did at one boundary while a version was pending.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Fence {
    /// The version that was pending.
    pub version: u32,
    /// The execution whose successor was being chosen.
    pub after: FrameId,
    /// True: switched to `version` there; false: went on in the running one.
    pub switched: bool,
}

/// What a teammate's heartbeat said about versions.
#[derive(Clone, Debug, Default)]
pub(super) struct PeerVersion {
    pub(super) heard: Time,
    pub(super) version: u32,
    pub(super) pending: u32,
    pub(super) fences: Vec<Fence>,
    /// The executions its frames follow (it has chosen their successors).
    pub(super) past: Vec<FrameId>,
    /// Executions it ended before the boundary where it switched to
    /// `version` (as far as its recent ends show): it chose their
    /// successors in an older version.
    pub(super) older: Vec<FrameId>,
}

impl PeerVersion {
    /// The version it chose the successor of `after` in, if it has, as
    /// far as this robot can tell: its version, unless it switched to it
    /// at a later boundary (then one before it: a version at most this
    /// old).
    fn chose_at(&self, after: FrameId) -> Option<u32> {
        if !self.past.contains(&after) {
            return None;
        }
        Some(match self.older.contains(&after) {
            true => self.version.saturating_sub(1),
            false => self.version,
        })
    }
}

impl Kernel {
    /// The version of the mission this robot runs (0: the first).
    pub fn version(&self) -> u32 {
        self.version
    }

    /// The newest version it holds pending, if any.
    pub fn pending_version(&self) -> Option<u32> {
        self.pending.keys().next_back().copied()
    }

    /// The newest version of the mission it runs or holds: what a newer
    /// one must be numbered like.
    pub fn newest_mission(&self) -> &Arc<Mission> {
        self.pending.values().next_back().unwrap_or(&self.mission)
    }

    /// Offer version `version` of the mission (its graph aligned to the
    /// newest one this robot runs or holds, see
    /// [`crate::graph::BehaviorGraph::aligned_to`]). It is applied at this
    /// robot's team's next safe point; older versions still held are kept
    /// (a teammate may have switched to one of them already). Refused when
    /// it is not newer than what this robot runs or holds, or not aligned.
    pub fn offer_change(
        &mut self,
        now: Time,
        version: u32,
        mission: Arc<Mission>,
    ) -> Result<(), Refused> {
        self.set_now(now);
        let refuse = |me: &mut Kernel, why: String| {
            me.emit(Event::MissionChangeRefused {
                version,
                reason: why.clone(),
            });
            Err(Refused(why))
        };
        let newest = self.pending_version().unwrap_or(self.version);
        if version <= newest {
            return refuse(
                self,
                format!("version {version} is not newer than version {newest}, held here"),
            );
        }
        let (old, new) = (self.newest_mission().graph(), mission.graph());
        let aligned = new.len() >= old.len()
            && new.roster().names() == old.roster().names()
            && old
                .symbols()
                .iter()
                .all(|(id, n)| new.symbols().get(n) == Some(id))
            && old
                .behaviors()
                .iter()
                .all(|b| new.get(b.id).is_some_and(|c| c.name == b.name));
        if !aligned {
            return refuse(
                self,
                format!(
                    "version {version} is not numbered like version {newest} (align it to the newest version first)"
                ),
            );
        }
        self.pending.insert(version, mission);
        while self.pending.len() > HELD {
            self.pending.pop_first();
        }
        self.emit(Event::MissionChangeOffered { version });
        self.step();
        Ok(())
    }

    /// Line 8 with a version pending: may this robot choose the successor
    /// of `after` now? Switches first if its team does. False: hold.
    pub(super) fn fence_passed(&mut self, after: FrameId) -> bool {
        let Some(v) = self.pending_version() else {
            return true;
        };
        if self.fences.iter().any(|f| f.after == after) {
            return true;
        }
        let me = self.version;
        let held = |w: u32| w <= me || self.pending.contains_key(&w);
        // 1. A teammate already applied a decision here: switched to a
        // version this robot holds (or runs), or went on without switching.
        let here: Vec<Fence> = (self.peer_versions.values())
            .flat_map(|p| p.fences.iter().filter(|f| f.after == after).copied())
            .collect();
        let followed: Option<Option<u32>> = here
            .iter()
            .find(|f| f.switched && held(f.version))
            .map(|f| Some(f.version))
            .or_else(|| here.iter().any(|f| !f.switched).then_some(None));
        let team = self.org.team(after.team).map(|t| t.members.clone());
        let depth = self.stack.len();
        let leader = self.heal_leader(after.team, depth);
        let in_team = |r: RobotId| team.as_ref().is_some_and(|t| t.contains(r));
        // A teammate heard past `after`: in this robot's version (the team
        // went on without switching there), or in a newer one it holds (it
        // switched there). The version it chose in there is the one it
        // runs now, unless it switched to that at a later boundary: then it
        // went on there, in an older one (docs/reliability.md, "A version
        // read from a teammate that switched later").
        let past: Vec<u32> = (self.peer_versions.iter())
            .filter(|(r, _)| in_team(**r))
            .filter_map(|(_, p)| p.chose_at(after))
            .collect();
        let passed_new = past.iter().copied().find(|w| *w > me && held(*w));
        let passed_old = past.iter().any(|w| *w <= me);
        // The team's leader runs a newer version this robot holds (it
        // switched on its side of a partition, or this robot is a
        // restarted or late one): catch up.
        let leader_ahead = leader
            .filter(|l| *l != self.me)
            .and_then(|l| self.peer_versions.get(&l))
            .filter(|p| self.now - p.heard <= FRESH && p.version > me)
            .filter(|p| !p.older.contains(&after))
            .map(|p| p.version)
            .filter(|w| held(*w));
        // The leader's view of its members: each fresh, holding `v` or not.
        let above = &self.stack[..depth];
        let members: Vec<RobotId> = team
            .as_ref()
            .map(|t| {
                t.iter()
                    .filter(|r| {
                        *r != self.me && !self.lost.contains(*r) && !Frame::any_left_by(above, *r)
                    })
                    .collect()
            })
            .unwrap_or_default();
        let fresh = |r: &RobotId| {
            self.peer_versions
                .get(r)
                .filter(|p| self.now - p.heard <= FRESH)
        };
        let all_fresh = members.iter().all(|r| fresh(r).is_some());
        // A member presumed lost but heard from since (its heartbeats are
        // on their way) may have passed `after` on its own side, in the
        // running version: the leader does not decide without it, but
        // holds for its heartbeat (docs/reliability.md, "A change decided
        // beside a teammate that had gone on").
        let stirring =
            (self.stirring.iter()).any(|r| in_team(*r) && !Frame::any_left_by(above, *r));
        let all_hold = members
            .iter()
            .all(|r| fresh(r).is_some_and(|p| p.pending >= v || p.version >= v));
        let leads = leader == Some(self.me);
        let leader_decides = all_hold.then_some(v);
        // Some(Some(w)): switch to w; Some(None): go on; None: undecided.
        let decided = match followed {
            Some(s) => Some(s),
            None if leader_ahead.or(passed_new).is_some() => Some(leader_ahead.or(passed_new)),
            None if passed_old => Some(None),
            // 2. The leader decides, on what it heard recently from every
            // member (back from a pause, it first hears them again).
            None if leads && all_fresh && !stirring => Some(leader_decides),
            // 3. Hold for the decision (a member), or for fresh news (the
            // leader), for a while.
            None => None,
        };
        let switch = match decided {
            Some(s) => s,
            None => {
                let since = match self.fence_wait {
                    Some((f, t, _)) if f == after => t,
                    _ => self.now,
                };
                // A member whose leader is heard, still short of the
                // boundary, waits for it longer (bounded).
                let leader_coming = !leads
                    && leader
                        .and_then(|l| self.peer_versions.get(&l))
                        .is_some_and(|p| self.now - p.heard <= FRESH);
                let wait = if leader_coming {
                    FENCE_WAIT * 4
                } else {
                    FENCE_WAIT
                };
                // The timer is due when the wait is over: at the wait
                // of the moment (it used to be due after the shorter wait
                // whatever the member waited for, and a member whose
                // leader was heard was woken at the same instant for ever:
                // docs/reliability.md, "A member woken for ever at a safe
                // point").
                let until = since + wait;
                if self.now < until {
                    if self.fence_wait != Some((after, since, until)) {
                        self.fence_wait = Some((after, since, until));
                        self.refresh_due();
                    }
                    return false;
                }
                if leads {
                    leader_decides
                } else {
                    self.emit(Event::MissionChangeDeferred {
                        version: v,
                        team: after.team,
                        after: FrameRef {
                            behavior: after.behavior,
                            epoch: after.epoch,
                        },
                        timed_out: true,
                    });
                    self.record_fence(Fence {
                        version: v,
                        after,
                        switched: false,
                    });
                    return true;
                }
            }
        };
        let switch = switch.filter(|w| *w > me);
        self.record_fence(Fence {
            version: switch.unwrap_or(v),
            after,
            switched: switch.is_some(),
        });
        match switch {
            Some(w) => self.switch_version(w, Some(after)),
            None => self.emit(Event::MissionChangeDeferred {
                version: v,
                team: after.team,
                after: FrameRef {
                    behavior: after.behavior,
                    epoch: after.epoch,
                },
                timed_out: false,
            }),
        }
        true
    }

    /// The robot was asleep for `gap` (see [`ASLEEP`]): a hold at a safe
    /// point resumes where it was (docs/reliability.md, "A hold that ran
    /// out while its robot was paused").
    pub(super) fn slept(&mut self, gap: Duration) {
        if let Some((f, since, until)) = self.fence_wait {
            self.fence_wait = Some((f, since + gap, until + gap));
            self.refresh_due();
        }
    }

    fn record_fence(&mut self, f: Fence) {
        self.fences.push_back(f);
        while self.fences.len() > RECENT {
            self.fences.pop_front();
        }
        if self.fence_wait.is_some() {
            self.fence_wait = None;
            self.refresh_due();
        }
    }

    /// A restarted robot rejoining its team (a fresh mind, in nothing yet)
    /// holds a version its teammate already runs: it takes it before it
    /// joins the team where the team is.
    pub(super) fn rejoin_version(&mut self, pos: &Position) {
        if pos.version > self.version && self.pending.contains_key(&pos.version) {
            self.switch_version(pos.version, None);
        }
    }

    /// Run held version `version` from now on (older ones held are
    /// dropped): at the boundary after `after`, or (`None`) as a restarted
    /// robot rejoins.
    fn switch_version(&mut self, version: u32, after: Option<FrameId>) {
        let Some(mission) = self.pending.remove(&version) else {
            return;
        };
        self.pending.retain(|w, _| *w > version);
        let old = self.mission.clone();
        let changed = mission.graph().changed_since(old.graph());
        self.beliefs
            .extend_symbols(mission.graph().symbols().clone());
        for (name, value) in mission.graph().initial_beliefs() {
            if old.graph().symbols().get(name).is_none() {
                self.beliefs
                    .set_named(name, value.clone(), self.now, Source::Given);
            }
        }
        self.mission = mission;
        self.version = version;
        self.stack_version += 1;
        self.emit(Event::MissionChanged {
            version,
            team: after.map_or(TeamId::ROOT, |a| a.team),
            after: after.map(|a| FrameRef {
                behavior: a.behavior,
                epoch: a.epoch,
            }),
            changed,
        });
    }

    /// What a teammate's heartbeat says about versions (before the rest of
    /// it is read: it may name behaviors of a version this robot does not
    /// run yet).
    pub(super) fn peer_version(&mut self, from: RobotId, pos: &Position) {
        if pos.version == 0 && pos.pending == 0 && pos.fences.is_empty() && self.pending.is_empty()
        {
            self.peer_versions.remove(&from);
            return;
        }
        // What it has chosen successors of: what its frames follow, and
        // what it ended recently and is not choosing a successor of now.
        let choosing: Vec<FrameId> = (pos.frames.iter())
            .filter(|f| f.state != crate::kernel::FrameState::Running)
            .map(|f| f.id)
            .collect();
        let past = (pos.frames.iter())
            .filter_map(|f| {
                f.anchor.filter(|a| !a.first).map(|a| FrameId {
                    team: f.id.team,
                    behavior: a.behavior,
                    epoch: a.epoch,
                })
            })
            .chain(
                pos.ended
                    .iter()
                    .map(|e| e.id)
                    .filter(|id| !choosing.contains(id)),
            )
            .collect();
        // What it ended before the boundary where it switched to the
        // version it runs (the first of its recent ends with a fence that
        // says it switched to it there).
        let switched_at = (pos.ended.iter()).position(|e| {
            (pos.fences.iter()).any(|f| f.switched && f.version == pos.version && f.after == e.id)
        });
        let older =
            switched_at.map_or_else(Vec::new, |i| pos.ended[..i].iter().map(|e| e.id).collect());
        // Pass on what teammates did at safe points of this robot's teams.
        for f in &pos.fences {
            let mine = self
                .org
                .team(f.after.team)
                .is_some_and(|t| t.contains(self.me));
            if mine && !self.relayed.contains(f) && !self.fences.contains(f) {
                self.relayed.push_back(*f);
                while self.relayed.len() > RECENT {
                    self.relayed.pop_front();
                }
            }
        }
        self.peer_versions.insert(
            from,
            PeerVersion {
                heard: self.now,
                version: pos.version,
                pending: pos.pending,
                fences: pos.fences.clone(),
                past,
                older,
            },
        );
    }

    /// The part of a teammate's position this robot can read: frames of
    /// behaviors its running version does not have (the teammate switched
    /// already) are left out, with everything below them.
    pub(super) fn readable(&self, pos: &Position) -> Option<Position> {
        let n = self.graph().len();
        let known = |id: &FrameId| id.behavior.index() < n;
        let all_known = pos
            .frames
            .iter()
            .all(|f| known(&f.id) && f.anchor.is_none_or(|a| a.behavior.index() < n))
            && pos.ended.iter().all(|e| known(&e.id))
            && pos.burned.iter().all(known);
        if all_known {
            return None;
        }
        let mut p = pos.clone();
        let cut = p
            .frames
            .iter()
            .position(|f| !known(&f.id) || f.anchor.is_some_and(|a| a.behavior.index() >= n))
            .unwrap_or(p.frames.len());
        p.frames.truncate(cut);
        p.ended
            .retain(|e| known(&e.id) && e.parent.as_ref().is_none_or(known));
        p.burned.retain(known);
        p.fences.retain(|f| known(&f.after));
        Some(p)
    }
}
