//! Healing from teammates' positions (see the `position` module for the
//! rules): departures, splits, allocation splits, burns and catching up.

use super::position::{
    ALLOC_HEALS, Anchor, Ended, FrameId, FrameState, PosFrame, Position, RECENT, Slot, push_recent,
};
use super::{Frame, Kernel, Phase, State};
use crate::event::{EndReason, Event, FrameRef, Via};
use crate::ids::{BehaviorId, RobotId};
use crate::ids::{InstanceKey, Kind};
use crate::org::MemberSet;
use smallvec::SmallVec;

/// How many behaviors `Kernel::leads_back` walks before it gives up (and
/// takes the way for one that leads back).
const LEADS_BACK_WALK: usize = 64;

/// How many executions of a predecessor `Kernel::catch_up` burns at most
/// for one teammate's heartbeat (the latest ones; the count is raised past
/// all of them). A team laps a behavior far fewer times than this between
/// two heartbeats; a larger gap is a teammate's word that cannot be true.
const MAX_CATCH_UP: u32 = 64;

/// Which points of an execution a teammate is left out of
/// (`Kernel::skip_execution`).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Skip {
    /// All of them: it went past the execution without running it
    /// (`Kernel::went_past`).
    Points,
    /// Its allocation: it ended the execution before it was allocated.
    Allocation,
    /// Its allocation, unless it coordinates it here: it converged past
    /// the execution (it may have run it and decided, its end no longer
    /// among those its heartbeat lists).
    AllocationButCoordinator,
}

impl Kernel {
    /// Allocation splits: a teammate under the same execution of an
    /// allocation point holds another allocation of it. The newest round
    /// wins: a robot behind joins the teammate's round; two robots in the
    /// same round with different allocations both allocate again in the
    /// next round, with everyone they hear — the same rule on both sides,
    /// so they meet in one instance. Bounded by [`ALLOC_HEALS`] per
    /// execution. A robot waiting at an allocation below heals too (that
    /// allocation's own frame, at the top, holds none yet): two members
    /// that took a subteam from different views of the allocation above
    /// waited there for a leader a lap behind until a deadline
    /// (docs/reliability.md, "A leader a lap behind"). So does a robot
    /// waiting at a termination below (reallocating ends that wait): a
    /// member that came late and ended its subteam at once waited at its
    /// termination for its leader, and the leader at its own subteam's
    /// termination for it, until a deadline (docs/reliability.md, "Both
    /// sides of a split waiting at a termination"). And a robot waiting at
    /// the synchronization after it, for a leader that came and allocated
    /// from another view (docs/reliability.md, "A split seen from a
    /// synchronization").
    pub(super) fn reconcile_allocation(&mut self, from: RobotId, pos: &Position) {
        let heals = match &self.phase {
            Phase::Run | Phase::Idle { .. } | Phase::Allocating(_) => true,
            // Only for a teammate of the subteam that ends, or that chooses
            // its successor (each side of the split waits for the other):
            // healing on any teammate's other allocation added rounds that
            // robots at work settle.
            Phase::Terminating { frame, .. } | Phase::Selecting { frame, .. } => {
                self.org.team(frame.team).is_some_and(|t| t.contains(from))
            }
            _ => false,
        };
        if !heals || self.lost.contains(from) {
            return;
        }
        let idle_top = matches!(self.phase, Phase::Idle { .. }).then(|| self.stack.len() - 1);
        for i in 0..self.stack.len() {
            let f = &self.stack[i];
            let Some(mine) = f.alloc_print() else {
                // Rejoined under it after a restart, and the team has
                // allocated it since: take part.
                if idle_top == Some(i)
                    && !f.left_behind
                    && let Some((round, _)) = (pos.frames.iter())
                        .find(|g| g.id == f.id() && g.state == FrameState::Running)
                        .and_then(|g| g.alloc)
                    && self.join_allocation(i, round)
                {
                    return;
                }
                continue;
            };
            let id = f.id();
            let Some(theirs) = pos
                .frames
                .iter()
                .find(|g| g.id == id && g.state == FrameState::Running)
                .and_then(|g| g.alloc)
            else {
                continue;
            };
            if theirs == mine
                || theirs.0 < mine.0
                || f.alloc_heals >= ALLOC_HEALS
                || idle_top == Some(i)
                || f.departed.as_ref().is_some_and(|d| d.contains(from))
                || !self.org.team(f.team).is_some_and(|t| t.contains(from))
                // Views still settling (a teammate presumed lost): the
                // round it comes back in decides first.
                || self
                    .org
                    .team(f.team)
                    .is_some_and(|t| t.members.iter().any(|r| self.lost.contains(r)))
            {
                continue;
            }
            let round = if theirs.0 > mine.0 {
                theirs.0
            } else {
                mine.0 + 1
            };
            self.stack[i].alloc_heals += 1;
            self.emit(Event::AllocationSplit {
                behavior: id.behavior,
                team: id.team,
                epoch: id.epoch,
                mine: mine.0,
                theirs: theirs.0,
                member: from,
                round,
            });
            self.reallocate(i, round, &[]);
            return;
        }
    }

    /// Executions a teammate burned are never used here either (unless
    /// this robot runs one now: it converges like its teammates did).
    pub(super) fn apply_burns(&mut self, pos: &Position) {
        for id in &pos.burned {
            let mine = self.stack.iter().any(|f| f.id() == *id)
                || self.popped().is_some_and(|(f, _)| f.id() == *id);
            if !mine && !self.recent_burned.contains(id) {
                self.burn(*id);
            }
        }
    }

    /// Never use execution `id` again: its instances are closed, the
    /// team's count of the behavior is past it, messages buffered for it
    /// are dropped, and teammates are told with the next heartbeats.
    pub(super) fn burn(&mut self, id: FrameId) {
        for kind in Kind::ALL {
            let key = InstanceKey {
                team: id.team,
                behavior: id.behavior,
                kind,
                epoch: id.epoch,
                round: u32::MAX,
            };
            self.mark_closed(key);
        }
        self.org.runs_at_least(id.team, id.behavior, id.epoch);
        self.inbox.drop_execution(id.team, id.behavior, id.epoch);
        push_recent(&mut self.recent_burned, id);
    }

    /// Executions a teammate runs (or ran) under a frame this robot has
    /// ended are executions it will never join: a teammate that goes on
    /// alone below a behavior its team is waiting to end (wait-all waits
    /// for every member's chain) counts executions the others never see.
    /// Count past them, as past an epoch seen on a clock, so that the team
    /// numbers its next executions alike instead of splitting over ids.
    pub(super) fn count_past(&mut self, pos: &Position) {
        // This robot's ended executions, each with its parent: two
        // executions under different parents may share an id (a behavior
        // that both `triangle` and `line` expand to, at the same team
        // count), and a teammate's frame is the one this robot ended only
        // if its parent is too (as in `awaited_at_work`).
        let popped = self.popped().map(|(f, _)| Ended {
            id: f.id(),
            parent: self.stack.last().map(Frame::id),
        });
        if self.recent_ended.is_empty() && popped.is_none() {
            return;
        }
        let gone = |e: &Ended| popped.as_ref() == Some(e) || self.recent_ended.contains_ended(e);
        // The teammate's frames are a chain, root first: frame `k` runs
        // under frame `k - 1`.
        let at = |k: usize| Ended {
            id: pos.frames[k].id,
            parent: k.checked_sub(1).map(|p| pos.frames[p].id),
        };
        let mut never: SmallVec<[Ended; RECENT]> = SmallVec::new();
        for k in 1..pos.frames.len() {
            let up = at(k - 1);
            if gone(&up) || never.contains(&up) {
                never.push(at(k));
            }
        }
        for e in &pos.ended {
            let Some(parent) = e.parent else { continue };
            // The parent as the teammate ran it: in its chain, or among
            // the executions it ended.
            let up = (pos.frames.iter().position(|f| f.id == parent).map(at))
                .or_else(|| pos.ended.iter().find(|x| x.id == parent).copied());
            let past = match up {
                Some(up) => gone(&up) || never.contains(&up),
                // Its parent's place unknown: by the id alone.
                None => {
                    popped.is_some_and(|p| p.id == parent)
                        || self.recent_ended.contains(&parent)
                        || never.iter().any(|n| n.id == parent)
                }
            };
            if past {
                never.push(*e);
            }
        }
        for e in &never {
            self.org.runs_at_least(e.id.team, e.id.behavior, e.id.epoch);
        }
    }

    /// A teammate runs, under the same parent execution and in the same
    /// team, another execution of the individual behavior this robot last
    /// ended and went on from in sequence, after the same step (the same
    /// anchor), numbered higher, and the team burned this robot's: the
    /// two are one step of the mission ([`Anchor`]), which the team
    /// renamed after this robot had left it (teammates still in it
    /// converged on one that a later arrival numbered higher, and burned
    /// the old name). Count past the new name, as the teammates did,
    /// so that this robot numbers its next run of the behavior past it
    /// instead of reusing it for its next lap (docs/reliability.md, "A lap
    /// renamed behind a robot that left it").
    pub(super) fn count_renamed(&mut self, pos: &Position) {
        let Some((k, parent, x, after)) = self.went_on_from else {
            return;
        };
        // Only a name the team gave up (burned): each member numbers its
        // runs of an individual behavior at its own pace, so the same step
        // under another number is no renaming by itself. A team
        // behavior's diverged histories meet instead (the robot may go
        // back into the teammate's execution: `Kernel::meet`).
        if after.first
            || k == 0
            || !self.mission.graph().is_individual(x.behavior)
            || !self.recent_burned.contains(&x)
        {
            return;
        }
        // Still under the parent execution it ran `x` under, and not come
        // to `x`'s behavior again there (wherever it is now).
        let (Some(up), Some(g), Some(gu)) = (
            self.stack.get(k - 1),
            pos.frames.get(k),
            pos.frames.get(k - 1),
        ) else {
            return;
        };
        if up.id() == parent
            && up.runs.latest_epoch(x.behavior) == x.epoch
            && gu.id == parent
            && g.id.team == x.team
            && g.id.behavior == x.behavior
            && g.id.epoch > x.epoch
            && g.anchor == Some(after)
        {
            self.org.runs_at_least(x.team, x.behavior, g.id.epoch);
        }
    }

    /// Histories that diverged and met again: a teammate runs the same
    /// execution as this robot, but after a later execution of the same
    /// predecessor (cut off from the team, it ran that predecessor more
    /// times), or after another predecessor this robot ran fewer times. The
    /// executions between are ones this robot will never join:
    /// burn them, so that the team numbers the predecessor's next execution
    /// alike and nothing sent for the teammate's extra executions (a
    /// termination it tells this robot it missed) ends this robot's next
    /// one.
    pub(super) fn catch_up(&mut self, pos: &Position) {
        let mut skip: Vec<FrameId> = Vec::new();
        let graph = self.mission.graph();
        for (_, id, a) in self.anchored() {
            // An individual behavior (`team: false`) is no team execution:
            // each member numbers its runs of it at its own pace, so a
            // teammate in the same id after a later predecessor ran another
            // lap, not this one (as in `meet`).
            if a.first || graph.is_individual(id.behavior) {
                continue;
            }
            // The same predecessor run more times, or another one this
            // robot ran fewer times than the teammate's count (cut off,
            // the two took different ways to the same execution: the
            // teammate's predecessor, and any run of it before, are
            // behind it for good).
            let Some(b) = pos
                .frames
                .iter()
                .find(|g| g.id == id)
                .and_then(|g| g.anchor)
                .filter(|b| {
                    !b.first
                        && (b.behavior != a.behavior || b.epoch > a.epoch)
                        && self.org.runs(id.team, b.behavior) < b.epoch
                })
            else {
                continue;
            };
            // At most the last `MAX_CATCH_UP` of them: burning the
            // latest raises the count past all, and a teammate's epoch is
            // its word, not a length to trust (a heartbeat claiming epoch
            // 4,294,967,295 asked for 68 GB here and aborted the robot).
            let done = self.org.runs(id.team, b.behavior);
            let from = (done + 1).max(b.epoch.saturating_sub(MAX_CATCH_UP - 1));
            skip.extend((from..=b.epoch).map(|epoch| FrameId {
                team: id.team,
                behavior: b.behavior,
                epoch,
            }));
        }
        for id in skip {
            self.burn(id);
        }
    }

    /// Mark `from` (and whom it reports) departed from the frames of this
    /// robot's stack (and the one it ended) that it has ended.
    pub(super) fn learn_departures(&mut self, from: RobotId, pos: &Position) {
        // The stack's frames, then the one it ended, by index (nothing
        // collected per heartbeat); their number is taken once.
        let popped = self.popped().map(|(f, _)| f.term_key());
        let depth = self.stack.len();
        let mut skipped = None;
        let mut newly_departed = false;
        for k in 0..depth + usize::from(popped.is_some()) {
            let slot = (k < depth).then_some(k);
            let f = match slot {
                Some(i) => &self.stack[i],
                None => match self.popped() {
                    Some((f, _)) => f,
                    None => continue,
                },
            };
            let id = f.id();
            // Its frame of the execution, if it shows one.
            let shown = pos.frames.iter().find(|g| g.id == id);
            let report = shown.and_then(|g| g.departed.as_ref());
            // It ended the execution (or burned it), or runs its successor
            // (it may have gone past it without running it, converging on
            // teammates further on).
            let ended_it = pos.ended.iter().any(|e| e.id == id) || pos.burned.contains(&id);
            let follows = || pos.frames.iter().any(|g| g.follows(id));
            let ran =
                ended_it || shown.is_some_and(|g| g.state != FrameState::Running) || follows();
            // Else the teammate's frame beside it, if it runs one this
            // robot has yet to start (looked up once for the tests below).
            let ahead = if ran {
                None
            } else {
                self.yet_to_start(k, id, pos)
            };
            // Or it went past without running it: it never took part in
            // the execution's allocation either (see below).
            let went_past = ahead.is_some_and(|g| self.went_past(k, id, g));
            // Or it went off another way for good: the team's first member,
            // in an individual behavior that never leads back here, come
            // from an execution this robot ran before this one
            // (`Kernel::went_off`).
            let went_past = went_past || ahead.is_some_and(|g| self.went_off(k, id, g, from));
            // Or it went round past it: it runs a later execution of the
            // behavior this one came after, which leads only here
            // (`Kernel::round_past`; docs/reliability.md, "A teammate gone
            // round past the execution"). Or it went on beyond it, to a
            // behavior only this one leads to (`Kernel::went_beyond`). It may
            // have run it (and decided its allocation), so it stays in that
            // allocation, as a teammate that ran it does. Or it runs a later
            // execution of this one's behavior (`Kernel::lapped`).
            let went_round = !went_past
                && ahead.is_some_and(|g| {
                    self.round_past(k, g.id)
                        || self.went_beyond(k, id, g.id)
                        || self.lapped(k, id, g)
                });
            // One that ended it before any allocation of it (its end, heard
            // with no allocation applied) neither decided one.
            let unallocated = || {
                shown.is_some_and(|g| g.state != FrameState::Running && g.alloc.is_none())
                    && self.graph().is_alloc_point(id.behavior)
            };
            // Or it follows it, converged past it, never having run it (it
            // neither ended it nor runs it): it never started the
            // execution, so it sends nothing to its allocation, where a
            // coordinator would wait for it until its deadline (property
            // seed 7816). It stays there if it leads it here: it may have
            // run it and decided, its end no longer among those its
            // heartbeat lists.
            let converged_past = || {
                slot.is_some()
                    && !ended_it
                    && shown.is_none()
                    && follows()
                    && self.graph().is_alloc_point(id.behavior)
            };
            if went_past {
                skipped = Some((id, Skip::Points));
            } else if slot.is_some() && ran && unallocated() {
                skipped = Some((id, Skip::Allocation));
            } else if ran && converged_past() {
                skipped = Some((id, Skip::AllocationButCoordinator));
            }
            let ended = ran || went_past || went_round;
            // Nothing to learn: the team is not looked up (its split is
            // cold in a large team, and most heartbeats report nothing).
            if report.is_none() && !ended {
                continue;
            }
            let Some(team) = self.org.team(f.team) else {
                continue;
            };
            let known = f.departed.as_ref();
            let news = report.map(|d| d.news(&team.members, known));
            let covers = news.as_ref().is_none_or(|n| n.covers);
            let mut who: Option<MemberSet> = news.and_then(|n| n.fresh);
            // What is new from the report is in the report; the sender
            // (never this robot: see `peer`) may not be.
            debug_assert_ne!(from, self.me);
            let mut adds_sender = false;
            if ended && team.contains(from) && !known.is_some_and(|d| d.contains(from)) {
                who.get_or_insert_with(|| MemberSet::empty(self.org.roster_len()))
                    .insert(from);
                adds_sender = true;
                newly_departed = true;
            }
            let Some(mut who) = who else {
                continue;
            };
            // This robot is never news to itself. It is taken out of `who`
            // below only where `who` is used: taking it out of a shared
            // set copies the roster's bits.
            let mine = who.contains(self.me);
            if who.is_empty() || (mine && who.len() == 1) {
                continue;
            }
            // When what this robot will know is exactly the leader's report
            // (the report holds all it knew, only members of the team, and,
            // for a frame on the stack, not this robot), it keeps the report
            // itself: one set shared by every member instead of a copy of
            // the roster's size each; `depart` below then adds nothing to it.
            // A frame this robot ended may list the robot itself: it has
            // departed from it (nothing below it runs here any more).
            let share = report
                .filter(|d| {
                    (slot.is_none() || !d.contains(self.me))
                        && (!adds_sender || d.contains(from))
                        && covers
                        && d.is_subset(&team.members)
                })
                .cloned();
            let shared = share.is_some();
            if let Some(d) = share {
                match slot {
                    Some(i) => self.stack[i].departed = Some(d),
                    None => {
                        if let Phase::Terminating { frame, .. } | Phase::Selecting { frame, .. } =
                            &mut self.phase
                        {
                            frame.departed = Some(d);
                        }
                    }
                }
            }
            match slot {
                Some(i) => {
                    who.remove(self.me);
                    self.depart(i, &who, who.contains(from).then_some((from, pos)));
                }
                // The frame this robot ended keeps the report, which holds
                // all of `who`: nothing to add.
                None if shared => {}
                None => {
                    if let Some(key) = popped {
                        who.remove(self.me);
                        self.depart_popped(key, &who);
                    }
                }
            }
        }
        // A departed teammate stays in the allocation of the execution it
        // left (it may have led it and decided: `depart`); one that ended it
        // before it was allocated decided none. One that went past it
        // without running it takes part in none of its points: it sends no
        // `Done` to its end either.
        if let Some((id, skip)) = skipped {
            self.skip_execution(id, from, skip);
        }
        if newly_departed {
            self.note_left_ran(from, pos);
        }
    }

    /// Teammate `from`, before this robot in id order (only such a
    /// teammate coordinates ahead of it), is newly known to have left a
    /// behavior of this robot's: keep the executions of points that its
    /// heartbeat lists as ended (of a team this robot is in, and that this
    /// robot has not ended). Coordinating one, it may have decided and
    /// left with its decision, which may not have reached this robot yet:
    /// a robot that comes to lead such a point after it decides nothing as
    /// it leaves the point ([`crate::interaction::Cx::left_after_running`];
    /// docs/reliability.md, "A coordinator after one that left, from the
    /// start" and "A synchronization's coordinator after one that left,
    /// heard while ending").
    fn note_left_ran(&mut self, from: RobotId, pos: &Position) {
        if from > self.me {
            return;
        }
        // An execution whose point is still to come here, or under way:
        // of a live team of this robot's, not older than the latest this
        // robot started, and not ended here — or ended here and waiting
        // for its termination or choosing its successor: a
        // synchronization point's instance starts only once its execution
        // has ended, and reads the entry then.
        let open = |k: &Kernel, id: FrameId| {
            k.org.team(id.team).is_some_and(|t| t.contains(k.me))
                && k.org.runs(id.team, id.behavior) <= id.epoch
                && (!k.recent_ended.contains(&id) || k.popped().is_some_and(|(f, _)| f.id() == id))
        };
        for e in &pos.ended {
            let id = e.id;
            let point = || {
                let g = self.graph();
                g.is_alloc_point(id.behavior) || g.is_point(id.behavior, Kind::Sync)
            };
            let entry = (from, id.team, id.behavior, id.epoch);
            if !point() || self.left_ran.contains(&entry) || !open(self, id) {
                continue;
            }
            // What can no longer matter makes room first.
            let mut kept = std::mem::take(&mut self.left_ran);
            kept.retain(|&(_, team, behavior, epoch)| {
                open(
                    self,
                    FrameId {
                        team,
                        behavior,
                        epoch,
                    },
                )
            });
            self.left_ran = kept;
            if self.left_ran.len() >= super::LEFT_RAN {
                self.left_ran.remove(0);
            }
            self.left_ran.push(entry);
        }
    }

    /// Leave teammate `from` out of the points of execution `id` that
    /// `skip` names.
    fn skip_execution(&mut self, id: FrameId, from: RobotId, skip: Skip) {
        let keys: SmallVec<[InstanceKey; 2]> = (self.instances.iter())
            .filter(|(k, i)| {
                (k.kind == Kind::Allocate || skip == Skip::Points)
                    && (k.team, k.behavior, k.epoch) == (id.team, id.behavior, id.epoch)
                    && matches!(i.state, State::Armed | State::Active)
                    && i.team.contains(from)
                    && !i.excludes(from)
                    && !(skip == Skip::AllocationButCoordinator
                        && self.coordinator(*k, i) == Some(from))
            })
            .map(|(k, _)| k)
            .collect();
        if keys.is_empty() {
            return;
        }
        for k in keys {
            self.exclude(k, &[from]);
        }
        self.refresh_due();
    }

    /// True when a teammate runs, beside this robot's execution `id` at
    /// depth `k` (under the same parent execution, in the same team), `g`,
    /// an execution of one of `id`'s successors that this robot has yet to
    /// start ([`Kernel::yet_to_start`]): it reached the point after `id`
    /// by another way (a precondition that held for it alone chose another
    /// successor before, or it converged on teammates further on) and will
    /// not come to `id` (docs/reliability.md, "Teammates gone another
    /// way").
    fn went_past(&self, k: usize, id: FrameId, g: &PosFrame) -> bool {
        // Not one before it: the execution this robot came from (it may
        // have converged on it without running it) or any it knows of.
        let before = |a: Anchor| !a.first && a.behavior == g.id.behavior && a.epoch >= g.id.epoch;
        // Nor one it reached from an earlier execution of this robot's
        // behavior, by another successor, unless that way never leads back
        // here (its successors' runs are not this robot's to count).
        // An execution the team burned is none of its laps: a teammate
        // that ran it and went on ran this lap's behavior under an id the
        // team gave up, and will number its next run past this one.
        let from_earlier = g.anchor.is_some_and(|a| {
            !a.first
                && a.behavior == id.behavior
                && a.epoch < id.epoch
                && !self.recent_burned.contains(&FrameId {
                    team: id.team,
                    behavior: a.behavior,
                    epoch: a.epoch,
                })
        });
        // Unless it waits at `g`'s end: a termination that needs teammates
        // there (one it could decide alone it would have), and this robot,
        // yet to start `g`, gets there only past `id`. Waiting for it at
        // `id` would be waiting in a circle (property seed 7900). Should
        // other teammates end `g` with it and it come round to `id` after
        // all, it finds `id`'s points decided and follows their outcome,
        // as a departed teammate does.
        let waits_there = g.state == FrameState::Ending;
        g.id.behavior != id.behavior
            && g.id.epoch > self.org.runs(id.team, g.id.behavior)
            && !(self.slot_at(k)).is_some_and(|(_, f)| f.anchor.is_some_and(before))
            && (self.graph().get(id.behavior)).is_some_and(|b| b.next.contains(&g.id.behavior))
            && !(from_earlier && !waits_there && self.leads_back(g.id.behavior, id.behavior))
    }

    /// True when a teammate runs, beside this robot's execution `id` at
    /// depth `k` (under the same parent execution, in the same team), `g`,
    /// a later execution of `id`'s own behavior, which this robot has yet
    /// to start ([`Kernel::yet_to_start`]): a robot numbers its executions
    /// of a team behavior 1, 2, 3… and never runs one again, so the
    /// teammate will not come to `id` (it ran it and went round, or
    /// converged past it from the way before). It may have run it, so it
    /// stays in its allocation, as a teammate that ran it does.
    ///
    /// Not when `g` came after the same execution as `id` (the same
    /// successor counted differently: this robot converges on it,
    /// [`Kernel::reconcile`]), nor for an individual behavior, which each
    /// member numbers at its own pace. Without this, a robot a lap behind
    /// waited at a point below `id` for a teammate that had converged past
    /// it onto the team's next lap, until its deadline (docs/reliability.md,
    /// "A teammate a lap ahead, converged past").
    fn lapped(&self, k: usize, id: FrameId, g: &PosFrame) -> bool {
        g.id.behavior == id.behavior
            && g.id.epoch > id.epoch
            && !self.graph().is_individual(id.behavior)
            && self
                .slot_at(k)
                .is_some_and(|(_, f)| f.anchor.is_some() && f.anchor != g.anchor)
    }

    /// True when a teammate runs, beside this robot's execution `id` at
    /// depth `k` (under the same parent execution, in the same team),
    /// execution `g`, which this robot has yet to start
    /// ([`Kernel::yet_to_start`]), of a behavior that only `id`'s leads to:
    /// `id`'s behavior is on no cycle (it runs once under its parent), and
    /// every way from the parent's chains to `g`'s behavior passes through
    /// it. The teammate ran `id` (it ended it by its own condition, and
    /// went on: `term.local`) and will not come to it again. The end it ran
    /// may be gone from the ends it still reports ([`RECENT`]) by the time
    /// this robot gets there, and a barrier below `id` waited out its
    /// deadline for it (docs/reliability.md, "A teammate gone on beyond the
    /// execution"). It may have decided `id`'s allocation, so it stays in
    /// that allocation, as a teammate that ran it does.
    ///
    /// Not a teammate on a way that does not pass through `id` (another
    /// successor of the point before it, taken by a precondition that held
    /// for it alone): a split that heals by converging, which may bring it
    /// into `id` (property seed 259). The walks are bounded
    /// ([`Kernel::reaches`]): beyond the bound a way is taken to exist, and
    /// nobody is departed.
    fn went_beyond(&self, k: usize, id: FrameId, g: FrameId) -> bool {
        let Some(parent) = k.checked_sub(1).and_then(|i| self.stack.get(i)) else {
            return false;
        };
        let heads = self
            .graph()
            .get(parent.behavior)
            .map_or(&[][..], |b| &b.children[..]);
        g.behavior != id.behavior
            && !self.leads_back(id.behavior, id.behavior)
            && self.leads_back(id.behavior, g.behavior)
            && !self.reaches(heads, g.behavior, Some(id.behavior))
    }

    /// True when teammate `from` runs, beside this robot's execution `id`
    /// at depth `k` (under the same parent execution, in the same team),
    /// `g`, an execution this robot has yet to start
    /// ([`Kernel::yet_to_start`]), and will never come to `id`:
    ///
    /// - `g`'s behavior never leads to `id`'s, and one of the two is
    ///   individual: histories meet only where both are team behaviors
    ///   ([`Kernel::meet`]), so the teammate is never moved into `id`
    ///   (nor, `g` individual, out of `g`; `g` a team behavior, only onto
    ///   a side a lap further on), and its chain from there avoids `id`'s
    ///   behavior (an individual `id` since docs/reliability.md, "A leader
    ///   gone off from an individual behavior");
    /// - `from` is the team's first member, the healing leader on every
    ///   member's view: at a split it follows no other side
    ///   ([`Kernel::reconcile`]), the others converge on it; or `from` runs
    ///   `g` with that member (heard recently), on the side the others
    ///   converge on;
    /// - `g` came after an execution this robot ran before `id` (of the
    ///   same parent and team, so ended before `id` started): the teammate
    ///   went off there, and never ran `id` either.
    ///
    /// It takes part in none of `id`'s points. Without this, a member that
    /// went on from the execution before by the other successor waited for
    /// the leader at `id`'s allocation until its deadline: the leader, its
    /// coordinator, went another way into an individual behavior whose
    /// chain ends the parent's (docs/reliability.md, "A leader gone off
    /// for good").
    fn went_off(&self, k: usize, id: FrameId, g: &PosFrame, from: RobotId) -> bool {
        let (Some(parent), Some(a)) = (k.checked_sub(1).and_then(|i| self.stack.get(i)), g.anchor)
        else {
            return false;
        };
        // `a`: not `id` itself nor a later run of its behavior.
        !a.first
            && parent.runs.latest_epoch(a.behavior) >= a.epoch
            && (a.behavior != id.behavior || a.epoch < id.epoch)
            && g.id.behavior != id.behavior
            && (self.graph().is_individual(g.id.behavior)
                || self.graph().is_individual(id.behavior))
            && !self.leads_back(g.id.behavior, id.behavior)
            && self
                .org
                .team(id.team)
                .and_then(|t| t.members.first())
                .is_some_and(|l| {
                    l == from
                        || (l != self.me
                            && self
                                .fresh_peer(l)
                                .is_some_and(|p| p.frames.get(k).is_some_and(|(f, _)| *f == g.id)))
                })
    }

    /// The teammate's frame at depth `k` of `pos`, if it runs, beside this
    /// robot's execution `id` there (under the same parent execution, in
    /// the same team), an execution this robot has yet to start: its epoch
    /// is past the latest this robot started of its behavior under that
    /// parent.
    fn yet_to_start<'p>(&self, k: usize, id: FrameId, pos: &'p Position) -> Option<&'p PosFrame> {
        let p = k.checked_sub(1).and_then(|i| self.stack.get(i))?;
        let up = k.checked_sub(1).and_then(|i| pos.frames.get(i))?;
        let g = pos.frames.get(k)?;
        (g.id.team == id.team && up.id == p.id() && g.id.epoch > p.runs.latest_epoch(g.id.behavior))
            .then_some(g)
    }

    /// True when behavior `to` may follow `from` along sequential edges
    /// (looked for among the first [`LEADS_BACK_WALK`] behaviors reached;
    /// beyond, taken as yes).
    fn leads_back(&self, from: BehaviorId, to: BehaviorId) -> bool {
        let next = self.graph().get(from).map_or(&[][..], |x| &x.next[..]);
        self.reaches(next, to, None)
    }

    /// True when behavior `to` is one of `starts` or may follow one along
    /// sequential edges without passing `avoid` (looked for among the
    /// first [`LEADS_BACK_WALK`] behaviors reached; beyond, taken as yes).
    fn reaches(&self, starts: &[BehaviorId], to: BehaviorId, avoid: Option<BehaviorId>) -> bool {
        let g = self.graph();
        let mut seen: SmallVec<[BehaviorId; 16]> = SmallVec::new();
        let mut todo: SmallVec<[BehaviorId; 16]> = SmallVec::new();
        let mut edges = starts;
        loop {
            for &n in edges {
                if n == to || seen.len() >= LEADS_BACK_WALK {
                    return true;
                }
                if Some(n) != avoid && !seen.contains(&n) {
                    seen.push(n);
                    todo.push(n);
                }
            }
            let Some(b) = todo.pop() else {
                return false;
            };
            edges = g.get(b).map_or(&[][..], |x| &x.next[..]);
        }
    }

    /// This robot's anchored frames, root first (read in place: a team
    /// leader runs this for every heartbeat of every member).
    pub(super) fn anchored(&self) -> impl Iterator<Item = (Slot, FrameId, Anchor)> + '_ {
        (0..=self.stack.len()).filter_map(|k| self.anchored_at(k))
    }

    /// The `k`-th of [`Kernel::anchored`]'s slots (stack frames, then the
    /// one it ended), if anchored: for loops that change the kernel as
    /// they go.
    fn anchored_at(&self, k: usize) -> Option<(Slot, FrameId, Anchor)> {
        let (slot, f) = self.slot_at(k)?;
        f.anchor.map(|a| (slot, f.id(), a))
    }

    /// The `k`-th frame of this robot's chain, root first: the stack's,
    /// then the one it ended (as its position lists them).
    pub(super) fn slot_at(&self, k: usize) -> Option<(Slot, &Frame)> {
        match self.stack.get(k) {
            Some(f) => Some((Slot::Stack(k), f)),
            None if k == self.stack.len() => Some((Slot::Popped, self.popped()?.0)),
            None => None,
        }
    }

    /// Compare this robot's frames with a teammate's after the same
    /// predecessor; converge on one execution (at most one change per
    /// heartbeat: what lies below a changed frame is gone). True when it
    /// converged. With `through`, the teammate's ended executions are
    /// compared instead of its frames ([`Kernel::ran_another_successor`]).
    pub(super) fn reconcile(&mut self, from: RobotId, pos: &Position, through: bool) -> bool {
        // By index, nothing collected: until it converges (and returns),
        // the loop changes neither the stack nor the frame it ended.
        for k in 0..=self.stack.len() {
            let Some((slot, id, prev)) = self.anchored_at(k) else {
                continue;
            };
            let found = if through {
                self.ran_another_successor(k, id, prev, pos)
            } else {
                pos.frames
                    .iter()
                    .find(|g| g.id.team == id.team && g.anchor == Some(prev))
                    .map(|g| g.id)
            };
            let Some(theirs) = found else {
                continue;
            };
            if theirs == id {
                continue;
            }
            let depth = match slot {
                Slot::Stack(i) => i,
                Slot::Popped => self.stack.len(),
            };
            let leader = self.heal_leader(id.team, depth);
            let follow = if theirs.behavior == id.behavior {
                // The same successor, counted differently (an earlier split
                // burned an epoch on one side): the higher epoch wins.
                theirs.epoch > id.epoch
            } else {
                // The healing leader's choice; when the leader is on
                // neither side (elsewhere, or not heard yet), the lowest-id
                // member's, so that the split still closes — every member
                // computes the same order.
                leader == Some(from) || (leader != Some(self.me) && from < self.me)
            };
            if !follow {
                if leader == Some(self.me) && theirs.behavior != id.behavior {
                    self.split_seen(from, id, theirs, prev);
                }
                continue;
            }
            self.converge(slot, from, pos, id, theirs, prev);
            return true;
        }
        false
    }

    /// The execution a teammate ran and ended after `prev`, the execution
    /// this robot's execution `id` at depth `k` came after, when it is
    /// another successor than `id`'s: the teammate ended `prev` under the
    /// same parent execution, did not run `id`, and ended (without burning
    /// it) the next execution of a successor of `prev`'s behavior, the one
    /// this robot would have started in `id`'s place. The two chose apart
    /// at a point where each decides alone, and the teammate went through
    /// its side before this robot heard it there: its teammates had ended
    /// it already, and their releases let it pass at once. Without this
    /// the split was never seen; this robot waited in `id` for teammates
    /// that had gone on, at every point a deadline
    /// (docs/reliability.md, "A split the other side went through"). Only
    /// when neither a frame after `prev` nor a diverged history
    /// ([`Kernel::meet`]) told the split.
    fn ran_another_successor(
        &self,
        k: usize,
        id: FrameId,
        prev: Anchor,
        pos: &Position,
    ) -> Option<FrameId> {
        if prev.first {
            return None;
        }
        let parent = self.stack.get(k.checked_sub(1)?)?;
        let pid = parent.id();
        let before = FrameId {
            team: id.team,
            behavior: prev.behavior,
            epoch: prev.epoch,
        };
        let ended = |f: FrameId| pos.ended.iter().any(|e| e.id == f && e.parent == Some(pid));
        if !ended(before) || ended(id) || pos.frames.iter().any(|g| g.id == id) {
            return None;
        }
        let next = &self.graph().get(prev.behavior)?.next;
        // Where the teammate ended `prev` in its list (oldest first), and
        // the first successor's execution it ended after it there.
        let at = pos
            .ended
            .iter()
            .rposition(|e| e.id == before && e.parent == Some(pid))?;
        let after = pos.ended[at + 1..]
            .iter()
            .find(|e| {
                e.parent == Some(pid) && e.id.team == id.team && next.contains(&e.id.behavior)
            })
            .map(|e| e.id);
        let g = self.graph();
        pos.ended
            .iter()
            .rev()
            .map(|e| (e.id, e.parent))
            .find(|&(e, p)| {
                p == Some(pid)
                    && e.team == id.team
                    && e.behavior != id.behavior
                    && next.contains(&e.behavior)
                    // The lap this robot would have run in `id`'s place:
                    // a team behavior's epochs count the team's laps; an
                    // individual behavior's are the teammate's own count
                    // (a robot that missed a lap of it is behind), so the
                    // teammate's order tells it instead: the successor it
                    // ended right after `prev` (docs/reliability.md, "A
                    // split onto an individual successor, a lap on").
                    && if g.is_individual(e.behavior) {
                        after == Some(e)
                    } else {
                        parent.runs.latest_epoch(e.behavior).checked_add(1) == Some(e.epoch)
                    }
                    && !pos.burned.contains(&e)
                    && !self.recent_burned.contains(&e)
            })
            .map(|(e, _)| e)
    }

    /// Histories that diverged while the team was cut apart (a partition,
    /// a robot paused) and did not meet again: under the same execution of
    /// a parent, this robot and a teammate run different executions that
    /// came after different predecessors, and neither is on the other's
    /// way (it did not run the other's execution, and the other did not
    /// come from its own; a teammate behind or ahead on the same way is
    /// not diverged). Each side's barrier then waits out its deadline for
    /// teammates that are in another execution, and the next ones may
    /// miss each other again (docs/reliability.md, "Histories that
    /// diverged in a partition"). The team meets on one side, as at a
    /// split: the one further on when both came from the same behavior,
    /// else the healing leader's. A robot that moves leaves its execution
    /// (and burns the ones it ran since the sides parted, so that the team
    /// numbers their behaviors' next executions alike) and joins the
    /// teammate's, after the teammate's predecessor. True when it moved.
    pub(super) fn meet(&mut self, from: RobotId, pos: &Position) -> bool {
        if self.lost.contains(from) {
            return false;
        }
        let ran = |id: FrameId, parent: FrameId| {
            pos.ended
                .iter()
                .any(|e| e.id == id && e.parent == Some(parent))
        };
        // Both chains run root first: only the first depth where they part
        // can hold a diverged execution (above it they agree; below it the
        // parents differ). Read in place: a leader hears every member.
        let at = |i: usize| self.slot_at(i).map(|(_, f)| f.id());
        let Some(k) = (0..=self.stack.len()).find(|&i| match (at(i), pos.frames.get(i)) {
            (Some(a), Some(g)) => a != g.id,
            _ => true,
        }) else {
            return false;
        };
        // Frames of two teams (subteams an allocation made) are not
        // compared: the common case at a leader, which hears every member.
        let (Some(g), Some(here)) = (pos.frames.get(k), at(k)) else {
            return false;
        };
        if k == 0 || g.id.team != here.team {
            return false;
        }
        // An individual behavior (`team: false`) is no team execution: each
        // member ends it on its own and goes on, so a teammate may be in one
        // it ran long ago (the ends it remembers are bounded) without the
        // histories having diverged. A member done with two individual
        // behaviors before its teammates were done with the first took them
        // for another history and led the team back into the first, for
        // ever (docs/reliability.md, "A teammate behind in an individual
        // behavior").
        let graph = self.mission.graph();
        if graph.is_individual(g.id.behavior) || graph.is_individual(here.behavior) {
            return false;
        }
        let Some((slot, id, mine)) = self.anchored_at(k) else {
            return false;
        };
        let parent = self.stack[k - 1].id();
        let Some(theirs) = g.anchor else {
            return false;
        };
        if theirs == mine || g.state == FrameState::Ended {
            return false;
        }
        let came_from =
            |a: Anchor, f: FrameId| !a.first && a.behavior == f.behavior && a.epoch == f.epoch;
        let on_the_way = came_from(theirs, id)
            || came_from(mine, g.id)
            || ran(id, parent)
            || self.passed(k, parent, g.id)
            || self.recent_ended.contains_ended(&Ended {
                id: g.id,
                parent: Some(parent),
            });
        if on_the_way {
            return false;
        }
        // The side further on its way, when both came from the same
        // behavior: the one that ran it more times (the team goes on
        // from there, not back over work done). Else the healing
        // leader's side; a member on it does not move for a lower-id
        // member on the other (every member hears the leader).
        let ahead = |x: Anchor, y: Anchor| {
            !x.first && !y.first && x.behavior == y.behavior && x.epoch > y.epoch
        };
        let follow = ahead(theirs, mine)
            || (!ahead(mine, theirs) && self.heal_leader(id.team, k) == Some(from));
        if !follow {
            return false;
        }
        // What this robot ran under the parent since the sides parted:
        // later than anything of the behavior the teammate tells of.
        let told = |b: BehaviorId| {
            let frames = pos.frames.iter().map(|f| f.id);
            let ended = pos.ended.iter().map(|e| e.id);
            let anchor = (!theirs.first).then_some(FrameId {
                team: id.team,
                behavior: theirs.behavior,
                epoch: theirs.epoch,
            });
            (frames
                .chain(ended)
                .chain(pos.burned.iter().copied())
                .chain(anchor))
            .filter(|f| f.team == id.team && f.behavior == b)
            .map(|f| f.epoch)
            .max()
            .unwrap_or(0)
        };
        let since: SmallVec<[FrameId; RECENT]> = self
            .recent_ended
            .iter()
            .filter(|e| e.parent == Some(parent) && e.id.team == id.team)
            .filter(|e| e.id.epoch > told(e.id.behavior))
            .map(|e| e.id)
            .collect();
        for e in since {
            self.burn(e);
        }
        if !theirs.first {
            self.org
                .runs_at_least(id.team, theirs.behavior, theirs.epoch);
        }
        self.converge(slot, from, pos, id, g.id, theirs);
        true
    }

    /// The healing leader saw a member on another successor: record it
    /// once (the member converges by itself).
    pub(super) fn split_seen(
        &mut self,
        from: RobotId,
        mine: FrameId,
        theirs: FrameId,
        prev: Anchor,
    ) {
        if !self.splits_seen.insert((from, theirs)) {
            return;
        }
        if self.splits_seen.len() > 4 * RECENT {
            self.splits_seen.pop_first();
        }
        self.emit(Event::Split {
            team: mine.team,
            after: FrameRef {
                behavior: prev.behavior,
                epoch: prev.epoch,
            },
            mine: FrameRef {
                behavior: mine.behavior,
                epoch: mine.epoch,
            },
            theirs: FrameRef {
                behavior: theirs.behavior,
                epoch: theirs.epoch,
            },
            member: from,
            follows: false,
        });
    }

    /// Leave execution `mine` (and all below it) for `theirs`, the
    /// successor the team converges on after `prev`, as teammate `from`
    /// (at position `pos`) runs it.
    ///
    /// The teammate's history under the parent execution becomes this
    /// robot's: the executions it tells it ended there in the team are
    /// counted past, so that the two number their next executions of those
    /// behaviors alike. Without it a robot that ran a behavior of the loop
    /// fewer times than the teammate it followed numbered its next
    /// execution of it one lower, and a barrier after it took the teammate
    /// on its way there for one gone round past (docs/reliability.md, "A
    /// follower a lap short in its counts").
    pub(super) fn converge(
        &mut self,
        slot: Slot,
        from: RobotId,
        pos: &Position,
        mine: FrameId,
        theirs: FrameId,
        prev: Anchor,
    ) {
        let team = mine.team;
        match slot {
            Slot::Stack(i) => {
                let old = self.stack[i].step_ref();
                self.emit(self.split_event(mine, theirs, prev, from, old));
                self.retract(i);
            }
            Slot::Popped => {
                let old = FrameRef {
                    behavior: mine.behavior,
                    epoch: mine.epoch,
                };
                self.emit(self.split_event(mine, theirs, prev, from, old));
                // Its termination (or the choice after it) is abandoned
                // without a word: the execution did not happen for the team.
                self.abort_phase_quietly();
            }
        }
        self.burn(mine);
        // The execution the teammate's came after is behind this robot's
        // way now, as one it ran is (`Kernel::passed`): a teammate still
        // in it is on its way to this robot, not elsewhere
        // (docs/reliability.md, "A teammate behind the execution converged
        // past"). Not an individual behavior's: each member numbers its
        // runs of one at its own pace.
        let passed = (!prev.first && !self.mission.graph().is_individual(prev.behavior))
            .then_some((prev.behavior, prev.epoch));
        // The parent's run counts forget the abandoned start.
        let parent_runs = match self.stack.last_mut() {
            Some(p) => &mut p.runs,
            None => &mut self.root_runs,
        };
        parent_runs.unbump(mine.behavior);
        if let Some((b, epoch)) = passed {
            parent_runs.pass(b, epoch);
        }
        self.org
            .runs_at_least(team, theirs.behavior, theirs.epoch.saturating_sub(1));
        let parent = self.stack.last().map(Frame::id);
        // Not `theirs`: the teammate may have ended it and wait at its
        // termination, the execution this robot joins. Nor, when `theirs`
        // is among its ends (this robot follows it through them:
        // `Kernel::ran_another_successor`), any it ended after: those came
        // after `theirs`, on the way this robot now takes, and counted past
        // they would be numbered apart from the team's (property seed
        // 8310). Not an individual behavior's: each member numbers its
        // runs of one at its own pace (`Kernel::meet`).
        let graph = self.mission.graph();
        let before = (pos.ended.iter())
            .rposition(|e| e.id == theirs && e.parent == parent)
            .unwrap_or(pos.ended.len());
        for e in &pos.ended[..before] {
            if e.id.team == team
                && e.parent == parent
                && e.id != theirs
                && !graph.is_individual(e.id.behavior)
            {
                self.org.runs_at_least(team, e.id.behavior, e.id.epoch);
            }
        }
        self.phase = Phase::Run;
        // Exactly the teammate's execution, unless this robot started it
        // (or a later one) itself, or burned it: a robot whose count was
        // past it (it had heard a third teammate in a later one) started
        // the one after it, an epoch above everyone, and "the higher epoch
        // wins" drew the others up after it, for ever (docs/reliability.md,
        // "Property seeds 2,638 to 3,553", seed 3136). A robot's starts of
        // a behavior are numbered upwards (the checker's `epochs`).
        let at = (theirs.epoch > self.org.started(team, theirs.behavior)
            && !self.recent_burned.contains(&theirs))
        .then_some(theirs.epoch);
        self.push_anchored_at(theirs.behavior, team, Via::Converged, Some(prev), at);
    }

    pub(super) fn split_event(
        &self,
        mine: FrameId,
        theirs: FrameId,
        prev: Anchor,
        from: RobotId,
        old: FrameRef,
    ) -> Event {
        Event::Split {
            team: mine.team,
            after: FrameRef {
                behavior: prev.behavior,
                epoch: prev.epoch,
            },
            mine: old,
            theirs: FrameRef {
                behavior: theirs.behavior,
                epoch: theirs.epoch,
            },
            member: from,
            follows: true,
        }
    }

    /// Pop frame `i` and everything above it without a word to the team:
    /// their instances close quietly (the executions are being burned).
    pub(super) fn retract(&mut self, i: usize) {
        self.abort_phase_quietly();
        while self.stack.len() > i {
            if let Some(f) = self.stack.pop() {
                self.abort_quietly(f.term_key());
                self.retire(&f, EndReason::Converged);
            }
        }
    }
}
