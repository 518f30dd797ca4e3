//! Membership: teammates presumed lost and back, and teammates that left
//! a behavior (departed): protocols decide without them.

use super::*;

impl Kernel {
    /// The runtime presumes teammate `r` lost (no heartbeat for longer than
    /// its bound). Running protocol instances decide without it from now on.
    pub fn member_lost(&mut self, now: Time, r: RobotId) {
        self.set_now(now);
        if r == self.me || !self.lost.insert(r) {
            return;
        }
        self.stirring.retain(|x| *x != r);
        self.ever_lost.insert(r);
        self.emit(Event::MemberLost { member: r });
        let affected: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| {
                i.team.contains(r)
                    && (matches!(i.state, State::Armed | State::Active) || i.wake.is_some())
            })
            .map(|(k, _)| k)
            .collect();
        for k in affected {
            self.exclude(k, &[r]);
        }
        // Children left without enough live members are re-allocated.
        if !matches!(self.phase, Phase::NotStarted | Phase::Finished)
            && let Some(i) = self.orphaned_frame()
        {
            let round = self.stack[i].round + 1;
            self.reallocate(i, round, &[]);
        }
        self.refresh_due();
        self.step();
    }

    /// The runtime hears teammate `r` again. It takes part again from the
    /// next protocol instance on (running ones go on without it).
    pub fn member_back(&mut self, now: Time, r: RobotId) {
        self.set_now(now);
        if self.lost.contains(r) {
            self.lost.remove(r);
            self.given_up.remove(r);
            self.stirring.retain(|x| *x != r);
            self.emit(Event::MemberBack { member: r });
            // Tell it how what it missed was decided: it may be waiting in
            // one of those instances, or running below a behavior its team
            // ended meanwhile, or lead a protocol its team has moved past.
            for key in self.missed.remove(&r).unwrap_or_default() {
                let closed = self
                    .instances
                    .get(&key)
                    .and_then(|i| i.closed.clone())
                    .or_else(|| self.tombstones.get(&key).cloned());
                if let Some(body) = closed.as_ref().and_then(missed_body) {
                    self.reply(key, r, body);
                }
            }
            // Barriers armed but not started take part it again (a member
            // lost once is not left out of its ancestors' terminations for
            // the rest of the mission).
            let departed = Frame::any_left_by(&self.stack, r);
            for inst in self.instances.values_mut() {
                if inst.state == State::Armed
                    && !departed
                    && let Some(x) = &mut inst.excluded
                {
                    x.remove(r);
                }
            }
        }
        self.step();
    }

    /// Instance `k` decides without `who` from now on.
    ///
    /// An instance whose coordinator this changes does not reach its
    /// deadline within a retry from now: the new coordinator has had no
    /// time to gather the team (a member waited out a leader that was
    /// still at work, and its deadline fell 0.01 s after that leader left
    /// and the next one took over: docs/reliability.md, "A deadline just
    /// after the leader changed").
    pub(super) fn exclude(&mut self, k: InstanceKey, who: &[RobotId]) {
        let n = self.org.roster_len();
        let mut new = Vec::new();
        let before = self.coordinator_of(k);
        if let Some(inst) = self.instances.get_mut(&k) {
            let ex = inst.excluded.get_or_insert_with(|| MemberSet::empty(n));
            for r in who {
                if inst.team.contains(*r) && ex.insert(*r) {
                    new.push(*r);
                }
            }
            if !new.is_empty() && inst.state == State::Active {
                self.out.push_back(Output::Event(Event::LeftOut {
                    instance: k,
                    members: new,
                }));
            }
        }
        if self.coordinator_of(k) != before
            && let Some(inst) = self.instances.get_mut(&k)
            && inst.state == State::Active
        {
            inst.deadline = inst.deadline.max(self.now + inst.retry.get());
        }
        self.call(k, |imp, cx| imp.on_members_changed(cx));
    }

    /// Teammates done with the behavior of termination instance `key`:
    /// leave them out of every instance below that behavior.
    pub(super) fn departures(&mut self, key: InstanceKey, who: &[RobotId]) {
        let who = MemberSet::from_iter(self.org.roster_len(), who.iter().copied());
        let who = &who;
        if let Some(i) = self.stack.iter().position(|f| f.term_key() == key) {
            self.depart(i, who, None);
        } else {
            self.depart_popped(key, who);
        }
    }

    /// Teammates done with the behavior this robot ended and waits to
    /// terminate: nothing of it runs here any more, but a leader relays
    /// who is done with its heartbeats.
    pub(super) fn depart_popped(&mut self, key: InstanceKey, who: &MemberSet) {
        let n = self.org.roster_len();
        if let Phase::Terminating { frame, .. } | Phase::Selecting { frame, .. } = &mut self.phase
            && frame.term_key() == key
        {
            frame
                .departed
                .get_or_insert_with(|| MemberSet::empty(n))
                .union_with(who);
        }
    }

    /// The coordinator of running instance `key` as its protocol sees it:
    /// the first member this robot does not leave out.
    pub(super) fn coordinator_of(&self, key: InstanceKey) -> Option<RobotId> {
        self.coordinator(key, self.instances.get(&key)?)
    }

    /// [`Kernel::coordinator_of`], for an instance already in hand.
    pub(super) fn coordinator(&self, key: InstanceKey, inst: &Instance) -> Option<RobotId> {
        let team = self.org.team(key.team).unwrap_or(&inst.team);
        team.members.iter().find(|r| !inst.excludes(*r))
    }

    /// True when instance `inst` still counts teammate `r`: neither
    /// presumed lost nor left out of it. The members a coordinator waits
    /// for, calls, or counts as arrived.
    pub(super) fn counted(&self, inst: &Instance, r: RobotId) -> bool {
        !self.lost.contains(r) && !inst.excludes(r)
    }

    /// Teammates done with the behavior of stack frame `i` (they arrived at
    /// its termination, or left it): leave them out of every instance below
    /// it, as if presumed lost. `told` is the teammate whose heartbeat
    /// said so, with what it said: it stays in an allocation below that it
    /// went through (it ran a child of that execution, or applied an
    /// allocation there): if it led the allocation it decided it, and a
    /// member that missed the decision must hear it from it rather than
    /// take the lead and allocate anew, apart from what the team applied.
    pub(super) fn depart(
        &mut self,
        i: usize,
        who: &MemberSet,
        told: Option<(RobotId, &position::Position)>,
    ) {
        let n = self.org.roster_len();
        self.stack[i]
            .departed
            .get_or_insert_with(|| MemberSet::empty(n))
            .union_with(who);
        // The termination instances of the frames down to this one are not
        // below it, nor is a re-allocation at it (teammates idle under it
        // take part); every other running instance is.
        let here = &self.stack[i];
        let (team, behavior, epoch) = (here.team, here.behavior, here.epoch);
        let mut above: Vec<InstanceKey> = self.stack[..=i].iter().map(Frame::term_key).collect();
        above.extend(self.instances.keys().filter(|k| {
            k.kind == Kind::Allocate && (k.team, k.behavior, k.epoch) == (team, behavior, epoch)
        }));
        let below: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(k, inst)| {
                !above.contains(k)
                    && matches!(inst.state, State::Armed | State::Active)
                    && !who.is_disjoint(&inst.team.members)
                    && self
                        .mission
                        .bound(k.behavior, k.kind)
                        .is_some_and(|b| b.protocol.communicates())
            })
            .map(|(k, _)| k)
            .collect();
        if !below.is_empty() {
            let who = who.to_vec();
            for k in below {
                match told {
                    Some((r, pos)) if k.kind == Kind::Allocate && pos.went_through(k) => {
                        let others: Vec<RobotId> =
                            who.iter().copied().filter(|x| *x != r).collect();
                        if !others.is_empty() {
                            self.exclude(k, &others);
                        }
                        // If it coordinates the allocation here, it decided
                        // it: ask it now rather than at the next resend
                        // (spaced further apart after every loss), so that
                        // a member that missed the decision does not wait
                        // for its deadline.
                        if self.coordinator_of(k) == Some(r) {
                            self.reply(k, r, Body::Query);
                        }
                    }
                    _ => self.exclude(k, &who),
                }
            }
        }
        self.refresh_due();
    }
}
