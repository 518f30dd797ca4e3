//! The instance table: protocol instances started at the points Algorithm 1
//! reaches (`Allocate`, `Terminate`, `Decide`), their effects and timers,
//! and what is remembered of them once over.

use super::*;

impl Kernel {
    /// An ancestor ended while an interaction was in flight: abandon it.
    pub(super) fn abort_phase(&mut self) {
        self.abort_phase_with(true);
    }

    /// Abandon the interaction in flight without telling the team (its
    /// execution is being burned).
    pub(super) fn abort_phase_quietly(&mut self) {
        self.abort_phase_with(false);
    }

    pub(super) fn abort_phase_with(&mut self, tell: bool) {
        match std::mem::replace(&mut self.phase, Phase::Run) {
            Phase::Allocating(k) => self.abort_with(k, tell),
            Phase::Terminating { key: Some(k), .. } | Phase::Selecting { key: Some(k), .. } => {
                self.abort_with(k, tell)
            }
            _ => {}
        }
    }

    pub(super) fn abort(&mut self, key: InstanceKey) {
        self.abort_with(key, true);
    }

    pub(super) fn abort_quietly(&mut self, key: InstanceKey) {
        self.abort_with(key, false);
    }

    /// Leave instance `key` before it decided; `tell`: let the protocol tell
    /// the teammates what they need to go on without this robot.
    pub(super) fn abort_with(&mut self, key: InstanceKey, tell: bool) {
        let Some(inst) = self.instances.get_mut(&key) else {
            return;
        };
        match inst.state {
            State::Decided => {
                // Keep it lingering to answer teammates, but let it be collected.
                inst.outcome = None;
                return;
            }
            State::Aborted => return,
            State::Armed | State::Active => {}
        }
        let protocol = inst.protocol;
        let announced = inst.state == State::Active;
        // Let the protocol tell its teammates, then keep it lingering so
        // that it can answer them (a barrier leader that leaves releases
        // whoever arrives later).
        if tell {
            self.call(key, |imp, cx| imp.on_abort(cx));
        }
        if let Some(inst) = self.instances.get_mut(&key) {
            if inst.state == State::Decided {
                // The protocol decided as this robot left (a coordinator
                // that leaves decides from what it has and announces it):
                // the decision stands for the team, and teammates that
                // missed the announcement are answered with it. This robot
                // does not apply it.
                inst.outcome = None;
            } else {
                inst.state = State::Aborted;
                inst.wake = None;
                inst.outcome = None;
                inst.closed = Some(Closed::Left);
            }
        }
        self.close(key);
        if announced {
            self.emit(Event::InteractionAborted {
                instance: key,
                protocol,
            });
        }
    }

    pub(super) fn close(&mut self, key: InstanceKey) {
        self.mark_closed(key);
        self.drop_pending(key);
    }

    /// Remember that `key` and every earlier instance at its point are over.
    pub(super) fn mark_closed(&mut self, key: InstanceKey) {
        let e = self
            .closed
            .entry((key.team, key.behavior, key.kind))
            .or_insert((0, 0));
        *e = (*e).max(key.stamp());
    }

    pub(super) fn start_instance(&mut self, key: InstanceKey, input: PointInput, told: &[RobotId]) {
        let Some(bound) = self.mission.bound(key.behavior, key.kind) else {
            return;
        };
        let armed = key.kind == Kind::Terminate;
        let Some(team) = self.org.team(key.team).cloned() else {
            return;
        };
        // Lost teammates are left out of every instance (every robot learns
        // of them within a heartbeat), and so are teammates that left an
        // ancestor: every member learns that from the same heartbeats (the
        // leaver's, relayed by the team's leader), so silent rules leave
        // them out alike — an allocation does not give a role to a teammate
        // that is done with the behavior.
        let mut gone = self.lost.clone();
        for r in told {
            gone.insert(*r);
        }
        // An allocation at the top frame is not below it: teammates idle
        // under it take part in a re-allocation (those that left it answer
        // `Done`).
        let below = match key.kind {
            Kind::Allocate => self.stack.len().saturating_sub(1),
            _ => self.stack.len(),
        };
        for f in &self.stack[..below] {
            if let Some(d) = &f.departed {
                gone.union_with(d);
            }
        }
        let excluded = (!gone.is_empty() && !team.members.is_disjoint(&gone)).then_some(gone);
        let inst = Box::new(Instance {
            excluded,
            protocol: bound.protocol.name(),
            team,
            closed: None,
            split: None,
            imp: (bound.factory)(),
            input,
            retry: bound.retry.into(),
            deadline_len: bound.deadline.into(),
            state: if armed { State::Armed } else { State::Active },
            waiting_since: if armed { None } else { Some(self.now) },
            past_seen: None,
            deadline: if armed {
                Time::MAX
            } else {
                self.now + bound.deadline
            },
            wake: None,
            outcome: None,
            timed_out: false,
            called: false,
            asked: None,
            sent: 0,
            bytes: 0,
            received: 0,
        });
        let protocol = inst.protocol;
        if !armed {
            self.waits_from(inst.retry_due());
            let excluded = inst.excluded_members();
            let options: LogList<BehaviorId> = match &inst.input {
                PointInput::Sync { candidates, .. } => match self.mission.next_shared(key.behavior)
                {
                    // Every successor: the mission's list, shared.
                    Some((all, ids)) if Arc::ptr_eq(all, candidates) => ids.clone(),
                    _ => candidates.as_ref().into(),
                },
                PointInput::Allocate { children } => {
                    match (self.mission.child_slots_shared(key.behavior))
                        .zip(self.mission.child_ids(key.behavior))
                    {
                        // Every child: the mission's list, shared.
                        Some((all, ids)) if Arc::ptr_eq(all, children) => ids.clone(),
                        _ => children.iter().map(|c| c.behavior).collect(),
                    }
                }
                PointInput::Terminate => LogList::default(),
            };
            self.emit(Event::InteractionStarted {
                instance: key,
                protocol,
                excluded,
                options,
            });
        }
        let mut waiting = self.inbox.take(key);
        match self.decided_by_departed(key, &inst, &waiting) {
            // The team decided before this robot came: it applies that
            // decision, and its protocol instance, never started, answers
            // teammates with it.
            Some(o) => {
                self.instances.insert(key, inst);
                self.force(key, o);
            }
            // Started before it is put in the table: absent meanwhile, as
            // an instance is during every call into it.
            None => self.call_with(key, inst, |imp, cx| imp.start(cx)),
        }
        self.refresh_due();
        // A teammate's word on how the instance was decided without this
        // robot (`Missed`) comes before the protocol's messages that
        // waited with it: answering the coordinator's call first would
        // hand it a contribution (a vote, a bid) from a robot that then
        // applies the other decision, and the two would part.
        waiting.sort_by_key(|m| !matches!(m.body, Body::Missed { .. }));
        for m in waiting {
            self.deliver(key, m.from, m.body);
        }
    }

    /// The decision of a synchronization or an allocation that a teammate
    /// coordinating it before this robot announced, applied, and left the
    /// behavior with (so it is left out here, not presumed lost), found
    /// among the messages that waited for the instance while this robot
    /// was on its way; `None` unless this robot now coordinates it. Without
    /// this, the new coordinator decided anew, and the team applied two
    /// decisions with no faults (docs/reliability.md, "A decision from a
    /// leader that left"). A member follows its coordinator instead: under
    /// loss the coordinator may not have heard the decision, and members
    /// that applied it while their coordinator decided anew parted from it.
    /// Only the library's announcements are read (`Decision`,
    /// `Assignment`); a graph-defined protocol's are its own.
    fn decided_by_departed(
        &self,
        key: InstanceKey,
        inst: &Instance,
        waiting: &[inbox::Pending],
    ) -> Option<Outcome> {
        if waiting.is_empty() || self.coordinator(key, inst) != Some(self.me) {
            return None;
        }
        let departed = |r: RobotId| {
            r < self.me
                && inst.team.contains(r)
                && inst.excludes(r)
                && !self.lost.contains(r)
                && !self.ever_lost.contains(r)
        };
        let m = waiting
            .iter()
            .filter(|m| departed(m.from))
            .filter(|m| match (&inst.input, &m.body) {
                (PointInput::Sync { successors, .. }, Body::Decision { choice }) => {
                    choice.is_none_or(|c| successors.contains(&c))
                }
                (PointInput::Allocate { .. }, Body::Assignment { .. }) => true,
                _ => false,
            })
            .min_by_key(|m| m.from)?;
        match (&inst.input, &m.body) {
            (PointInput::Sync { .. }, Body::Decision { choice }) => {
                Some(Outcome::Sync(choice.to_owned()))
            }
            (PointInput::Allocate { .. }, b) => b
                .to_assignment(self.org.roster_len())
                .map(|a| Outcome::Allocate(Arc::new(a))),
            _ => None,
        }
    }

    /// This robot's own reason to end the behavior of `key` happened.
    pub(super) fn term_local_done(&mut self, key: InstanceKey, why: LocalEnd) {
        let now = self.now;
        let Some(inst) = self.instances.get_mut(&key) else {
            return;
        };
        if inst.state != State::Armed {
            return;
        }
        inst.state = State::Active;
        inst.waiting_since = Some(now);
        inst.deadline = now + inst.deadline_len.get();
        let protocol = inst.protocol;
        let excluded = inst.excluded_members();
        let ready = inst.retry_due();
        self.waits_from(ready);
        self.emit(Event::InteractionStarted {
            instance: key,
            protocol,
            excluded,
            options: LogList::default(),
        });
        self.call(key, |imp, cx| imp.local_done(cx, why));
        self.refresh_due();
    }

    pub(super) fn take_outcome(&mut self, key: InstanceKey) -> Option<Outcome> {
        self.instances.get_mut(&key).and_then(|i| i.outcome.take())
    }

    /// Call into an instance with a fresh context, then apply its effects.
    pub(super) fn call(
        &mut self,
        key: InstanceKey,
        f: impl FnOnce(&mut dyn Interaction, &mut Cx<'_>),
    ) {
        let Some(inst) = self.instances.take(&key) else {
            return;
        };
        self.call_with(key, inst, f);
    }

    /// [`Kernel::call`] with the instance out of the table; it is put
    /// (back) under `key` after its effects.
    fn call_with(
        &mut self,
        key: InstanceKey,
        mut inst: Box<Instance>,
        f: impl FnOnce(&mut dyn Interaction, &mut Cx<'_>),
    ) {
        let mut fx = Effects::default();
        {
            let mut cx = Cx::new(CxParts {
                now: self.now,
                me: self.me,
                key,
                team: self.org.team(key.team).unwrap_or(&inst.team),
                excluded: inst.excluded.as_ref(),
                lost: Some(&self.lost),
                given_up: Some(&self.given_up),
                left_ran: &self.left_ran,
                org: &self.org,
                runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
                graph: self.mission.graph(),
                memo: Some(self.mission.by_id_memo()),
                roster: self.mission.graph().roster(),
                beliefs: &self.beliefs,
                rng: &mut self.rng,
                input: &inst.input,
                retry: inst.retry.get(),
                deadline: inst.deadline,
                decided: inst.state == State::Decided,
                aborted: inst.state == State::Aborted,
                fx: &mut fx,
            });
            f(&mut *inst.imp, &mut cx);
        }
        let departed = std::mem::take(&mut fx.departed);
        self.apply_effects(key, &mut inst, fx);
        self.instances.insert(key, inst);
        if !departed.is_empty() {
            self.departures(key, &departed);
        }
    }

    pub(super) fn apply_effects(&mut self, key: InstanceKey, inst: &mut Instance, fx: Effects) {
        for (to, body) in fx.sends {
            let envelope = Envelope {
                instance: key,
                sender: self.me,
                seq: self.next_seq,
                body,
            };
            self.next_seq += 1;
            let bytes = encoded_len(&envelope) as u32;
            inst.sent += 1;
            inst.bytes += u64::from(bytes);
            self.stats.sent += 1;
            self.stats.bytes_sent += u64::from(bytes);
            self.out.push_back(Output::Send(Outgoing {
                to,
                envelope,
                bytes,
            }));
        }
        if let Some(w) = fx.wake
            && inst.state != State::Aborted
        {
            inst.wake = Some(inst.wake.map_or(w, |x| x.min(w)));
            self.next_due = Some(self.next_due.map_or(w, |x| x.min(w)));
        }
        if fx.postpone && inst.state == State::Active {
            inst.deadline = self.now + inst.deadline_len.get();
        }
        for what in fx.violations {
            self.emit(Event::ProtocolViolation {
                instance: key,
                what,
            });
        }
        let mut tell = Vec::new();
        if let Some(outcome) = fx.outcome
            && matches!(inst.state, State::Armed | State::Active)
        {
            // An allocation a teammate of this process already applied
            // (checked then) is shared as it is; any other is checked.
            let (team, point, stamp) = (key.team, key.behavior, key.stamp());
            let shared = match &outcome {
                Outcome::Allocate(a) => self.mission.find_split(team, point, stamp, a),
                _ => None,
            };
            let mut outcome = match shared {
                Some(_) => outcome,
                None => self.validate(key, inst, outcome),
            };
            inst.state = State::Decided;
            if let Outcome::Allocate(a) = &mut outcome {
                // The subteams it makes, shared with the teammates of this
                // process that decided the same (the assignment moves
                // into them; what the kernel applies is `inst.split`).
                let a = std::mem::take(a);
                inst.split = Some(match shared {
                    Some(s) => s,
                    None => self.mission.split(team, point, stamp, a),
                });
            }
            let waited = inst.waiting_since.map_or(Duration::ZERO, |t| self.now - t);
            self.emit(Event::InteractionDecided {
                instance: key,
                protocol: inst.protocol,
                outcome: match (&outcome, &inst.split) {
                    (Outcome::Sync(c), _) => OutcomeLog::Sync { choice: *c },
                    (Outcome::Allocate(_), Some(s)) => OutcomeLog::Allocate {
                        assignment: s.log().clone(),
                    },
                    (Outcome::Allocate(a), None) => OutcomeLog::allocation(a),
                    (Outcome::Terminate(n), _) => OutcomeLog::Terminate { next: *n },
                },
                waited_us: waited.as_micros() as u64,
                sent: inst.sent,
                bytes: inst.bytes,
                received: inst.received,
                timed_out: inst.timed_out,
            });
            inst.closed = Some(match (&outcome, &inst.split) {
                (Outcome::Sync(c), _) => Closed::Synced(*c),
                (Outcome::Allocate(_), Some(s)) => Closed::Allocated(s.assignment().clone()),
                (Outcome::Allocate(a), None) => Closed::Allocated(a.clone()),
                (Outcome::Terminate(n), _) => Closed::Terminated(*n),
            });
            inst.outcome = Some(outcome);
            // Teammates presumed lost that this decision left out: told
            // now if they are back, else when they are.
            if let Some(ex) = &inst.excluded {
                for r in ex
                    .iter()
                    .filter(|r| inst.team.contains(*r) && self.ever_lost.contains(*r))
                {
                    if self.lost.contains(r) {
                        let missed = self.missed.entry(r).or_default();
                        if missed.len() >= MISSED_REMEMBERED {
                            missed.pop_front();
                        }
                        missed.push_back(key);
                    } else if let Some(body) = inst.closed.as_ref().and_then(missed_body) {
                        tell.push((r, body));
                    }
                }
            }
            self.mark_closed(key);
            // A termination decided while its behavior is still on the stack
            // (the team ended it, or this robot idles under it) ends it here.
            if key.kind == Kind::Terminate
                && let Some(f) = self.stack.iter_mut().find(|f| f.term_key() == key)
            {
                f.team_ended = true;
            }
        }
        for (r, body) in tell {
            self.reply(key, r, body);
        }
    }

    /// Check a decision against what the instance was asked; a protocol bug
    /// or a forged message must not corrupt the kernel, so an invalid
    /// decision is replaced by the silent rule of its kind.
    pub(super) fn validate(
        &mut self,
        key: InstanceKey,
        inst: &Instance,
        outcome: Outcome,
    ) -> Outcome {
        let graph = self.mission.graph().clone();
        let outcome = match outcome {
            Outcome::Allocate(a) if matches!(inst.input, PointInput::Allocate { .. }) => {
                match self.sanitize_allocation(key, a) {
                    Ok(clean) => return Outcome::Allocate(clean),
                    Err(a) => Outcome::Allocate(a),
                }
            }
            o => o,
        };
        let ok = match (&outcome, &inst.input) {
            (Outcome::Sync(None), PointInput::Sync { .. }) => true,
            (Outcome::Sync(Some(s)), PointInput::Sync { successors, .. }) => successors.contains(s),
            (Outcome::Terminate(n), PointInput::Terminate) => {
                n.is_none_or(|n| graph.get(n).is_some())
            }
            _ => false,
        };
        if ok {
            return outcome;
        }
        self.emit(Event::ProtocolViolation {
            instance: key,
            what: format!("{} decided an invalid outcome {outcome:?}", inst.protocol),
        });
        match &inst.input {
            PointInput::Sync { candidates, .. } => Outcome::Sync(candidates.first().copied()),
            PointInput::Allocate { children } => match self.org.team(key.team) {
                Some(t) => Outcome::Allocate(Arc::new(rules::assign_by_id(&t.members, children))),
                None => Outcome::Allocate(Arc::default()),
            },
            PointInput::Terminate => Outcome::Terminate(None),
        }
    }

    /// An allocation as this robot can apply it: its children must be
    /// children of the point; members this robot does not know in the team
    /// are left out (a leader whose view of the team diverged after a
    /// timeout decides for the members it knows; those both know agree), and
    /// a member listed twice keeps its first child. `Err` (the allocation
    /// back) if a child is not a child of the point. Linear in the size of
    /// the allocation; one that needs no change is returned as it is.
    pub(super) fn sanitize_allocation(
        &self,
        key: InstanceKey,
        a: Arc<Assignment>,
    ) -> Result<Arc<Assignment>, Arc<Assignment>> {
        let Some(team) = self.org.team(key.team) else {
            return Err(a);
        };
        let n = self.org.roster_len();
        if a.0.iter().any(|(c, m)| {
            self.mission.child_index(key.behavior, *c).is_none() || m.roster_len() != n
        }) {
            return Err(a);
        }
        let mut seen = fixedbitset::FixedBitSet::with_capacity(n);
        if a.0.iter().all(|(_, m)| {
            m.iter()
                .all(|r| team.members.contains(r) && !seen.put(r.index()))
        }) {
            return Ok(a);
        }
        let mut seen = MemberSet::empty(n);
        let mut out = Vec::with_capacity(a.0.len());
        for (c, m) in &a.0 {
            let mut mine = MemberSet::empty(n);
            for r in m.iter() {
                if team.members.contains(r) && seen.insert(r) {
                    mine.insert(r);
                }
            }
            out.push((*c, mine));
        }
        Ok(Arc::new(Assignment(out)))
    }

    pub(super) fn fire_timers(&mut self) {
        let now = self.now;
        let due: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| i.wake.is_some_and(|w| w <= now))
            .map(|(k, _)| k)
            .collect();
        for k in due {
            if let Some(i) = self.instances.get_mut(&k) {
                i.wake = None;
            }
            self.call(k, |imp, cx| imp.on_timer(cx));
        }
        let expired: Vec<InstanceKey> = self
            .instances
            .iter()
            .filter(|(_, i)| i.state == State::Active && i.deadline <= now)
            .map(|(k, _)| k)
            .collect();
        for k in expired {
            if self.awaited_at_work(k) {
                // A teammate this instance waits for is heard working on
                // the behavior: not silent, only slower. Wait on.
                if let Some(i) = self.instances.get_mut(&k) {
                    i.deadline = now + i.deadline_len.get();
                }
                self.stats.deadlines_rearmed += 1;
                continue;
            }
            if self.call_unheard(k) || self.ask_coordinator_out(k) {
                self.stats.deadlines_rearmed += 1;
                continue;
            }
            if self.heard_at_the_barrier(k) {
                continue;
            }
            if let Some(i) = self.instances.get_mut(&k) {
                i.timed_out = true;
                // The teammates presumed lost that it decides without (see
                // `Cx::is_given_up`).
                if !self.lost.is_empty() {
                    let given: smallvec::SmallVec<[RobotId; 2]> = (i.team.members.iter())
                        .filter(|r| self.lost.contains(*r) && !self.given_up.contains(*r))
                        .collect();
                    for r in given {
                        self.given_up.insert(r);
                        self.emit(Event::MemberGivenUp { member: r });
                    }
                }
            }
            self.stats.timeouts += 1;
            self.call(k, |imp, cx| imp.on_deadline(cx));
            let protocol_decided = self
                .instances
                .get(&k)
                .is_some_and(|i| i.state == State::Decided);
            if !protocol_decided {
                self.call(k, |_, cx| {
                    let o = rules::fallback(cx);
                    cx.decide(o);
                });
            }
            let protocol = self.instances.get(&k).map_or("?", |i| i.protocol);
            self.emit(Event::InteractionTimedOut {
                instance: k,
                protocol,
                protocol_decided,
            });
        }
        self.refresh_due();
    }

    /// The deadline of instance `k` fell, and teammates it counts have
    /// never been heard (within [`position::FRESH`]): their heartbeats go
    /// to a leader elsewhere (one that left the execution, and that they
    /// do not know left), so this robot cannot tell one on its way from one
    /// gone or silent. Once per instance it sends them its own heartbeats
    /// for two retries and waits that long: one on its way answers
    /// (`Kernel::answer_strangers`) and is waited for at the next deadline
    /// if heard at work (`Kernel::awaited_at_work`), one that went past is
    /// left out (`Kernel::learn_departures`), and a silent one is decided
    /// without then. True when it called.
    pub(super) fn call_unheard(&mut self, k: InstanceKey) -> bool {
        let Some(inst) = self.instances.get(&k) else {
            return false;
        };
        if inst.called {
            return false;
        }
        let mut unheard: Option<MemberSet> = None;
        for r in inst.team.members.iter() {
            if r != self.me && self.counted(inst, r) && self.fresh_peer(r).is_none() {
                (unheard.get_or_insert_with(|| MemberSet::empty(self.org.roster_len()))).insert(r);
            }
        }
        let now = self.now;
        let (Some(unheard), Some(inst)) = (unheard, self.instances.get_mut(&k)) else {
            return false;
        };
        inst.called = true;
        let until = now + inst.retry.get() * 2;
        inst.deadline = until;
        match self.calling.as_deref_mut() {
            Some((set, t)) if *t > now => {
                set.union_with(&unheard);
                *t = (*t).max(until);
            }
            _ => self.calling = Some(Box::new((unheard, until))),
        }
        true
    }

    /// The deadline of allocation `k` fell at a member whose coordinator
    /// is heard (within [`position::FRESH`]) out of the execution: it left
    /// it, having decided (its decision lost or still on its way) or
    /// undecided (its own reason to end the behavior came first), and
    /// nothing it sends will come unasked. Once per coordinator this robot
    /// asks it (`Query`) and waits two retries: one that left answers with
    /// its decision, or with `Done` when it left undecided (`inbox.rs`),
    /// and this robot decides with the team, or without it, rather than at
    /// a deadline (docs/reliability.md, "A coordinator that left
    /// undecided, heard"). True when it asked.
    fn ask_coordinator_out(&mut self, k: InstanceKey) -> bool {
        if k.kind != Kind::Allocate {
            return false;
        }
        let Some(inst) = self.instances.get(&k) else {
            return false;
        };
        let Some(c) = self.coordinator(k, inst) else {
            return false;
        };
        if c == self.me || inst.asked == Some(c) {
            return false;
        }
        let id = FrameId::of(k);
        // Not heard, or heard in the execution: nothing to ask.
        if (self.fresh_peer(c)).is_none_or(|p| p.frames.iter().any(|(f, _)| *f == id)) {
            return false;
        }
        let now = self.now;
        let Some(inst) = self.instances.get_mut(&k) else {
            return false;
        };
        inst.asked = Some(c);
        inst.deadline = now + inst.retry.get() * 2;
        self.reply(k, c, crate::msg::Body::Query);
        true
    }

    /// The deadline of termination `k`, which this robot coordinates,
    /// fell while teammates it counts were last heard waiting at the
    /// barrier (their last frame is its execution, ended): they are not
    /// silent, they have arrived, whether their reports came or not. A
    /// member's heartbeats count it arrived once they have shown it
    /// waiting for a retry (`Kernel::heard_waiting`), so that a run
    /// without faults reads its report first; at the deadline there is
    /// nothing to wait for. A member that came to the point a moment
    /// before, and sent its report to a leader it did not know had left,
    /// was decided without: the barrier timed out 30 ms before the member
    /// found this robot (docs/reliability.md, "Heard at the barrier when
    /// the deadline fell"). True when the barrier then decided.
    fn heard_at_the_barrier(&mut self, k: InstanceKey) -> bool {
        if k.kind != Kind::Terminate {
            return false;
        }
        let Some(inst) = self.instances.get(&k) else {
            return false;
        };
        if self.coordinator(k, inst) != Some(self.me) {
            return false;
        }
        let id = FrameId::of(k);
        let waiting: Vec<RobotId> = (inst.team.members.iter())
            .filter(|r| *r != self.me && self.counted(inst, *r))
            .filter(|r| {
                self.fresh_peer(*r)
                    .and_then(|p| p.frames.last())
                    .is_some_and(|(f, s)| *f == id && *s == FrameState::Ending)
            })
            .collect();
        for r in waiting {
            self.call(k, |imp, cx| imp.on_member_waiting(cx, r));
        }
        self.instances
            .get(&k)
            .is_some_and(|i| i.state == State::Decided)
    }

    /// An instance starts waiting, and will have waited a retry at
    /// `ready` (see `Kernel::asks_from`).
    fn waits_from(&mut self, ready: Option<Time>) {
        if let Some(ready) = ready {
            self.asks_from = Some(self.asks_from.map_or(ready, |t| t.min(ready)));
        }
    }

    pub(super) fn refresh_due(&mut self) {
        // A plain loop: this runs after every call into an instance.
        let mut due = self.fence_wait.map(|(_, _, until)| until);
        let mut earlier = |t: Time| due = Some(due.map_or(t, |d| d.min(t)));
        for i in self.instances.values() {
            if let Some(w) = i.wake {
                earlier(w);
            }
            if i.state == State::Active {
                earlier(i.deadline);
            }
        }
        self.next_due = due;
    }

    // ----- messages ------------------------------------------------------

    pub(super) fn bury(&mut self, key: InstanceKey, closed: Closed) {
        self.tombstones.bury(key, closed, TOMBSTONES);
    }

    /// Decide instance `key` with `outcome`, outside its protocol.
    pub(super) fn force(&mut self, key: InstanceKey, outcome: Outcome) {
        let Some(mut inst) = self.instances.take(&key) else {
            return;
        };
        let open = matches!(inst.state, State::Armed | State::Active);
        let fx = Effects {
            outcome: Some(outcome),
            ..Effects::default()
        };
        self.apply_effects(key, &mut inst, fx);
        // The protocol learns what was applied (as checked), so that it
        // answers with it and never announces a decision of its own.
        match inst
            .closed
            .as_ref()
            .filter(|_| open)
            .and_then(Closed::outcome)
        {
            Some(o) => self.call_with(key, inst, |imp, cx| imp.on_team_decision(cx, &o)),
            None => {
                self.instances.insert(key, inst);
            }
        }
        self.refresh_due();
    }

    /// Forget instances that stopped lingering and buffered messages that
    /// can no longer be used.
    pub(super) fn gc(&mut self) {
        let now = self.now;
        // A finished instance (decided or left) stays while it still has
        // work (a timer: e.g. telling stragglers of a release); then only
        // its outcome is kept, to answer late teammates.
        let done = self.instances.remove_where(|i| {
            matches!(i.state, State::Decided | State::Aborted)
                && i.outcome.is_none()
                && i.wake.is_none()
                && i.closed.is_some()
        });
        for (k, i) in done {
            if let Some(c) = i.closed {
                self.bury(k, c);
            }
        }
        self.seen.forget_older(now, DEDUP_MEMORY);
        self.quiet_peers();
        let ttl = self.limits.pending_ttl;
        let closed = &self.closed;
        let org = &self.org;
        // Messages for an execution now over, or a team now dissolved, are
        // stale; the others dropped waited past their time to live.
        let mut stale = 0u64;
        let dropped = self.inbox.retain(|k, m| {
            let over = closed
                .get(&(k.team, k.behavior, k.kind))
                .is_some_and(|e| k.stamp() <= *e)
                || org.is_dead(k.team);
            stale += u64::from(over);
            !over && now - m.at < ttl
        });
        let expired = dropped as u64 - stale;
        for (reason, n) in [
            (DropReason::Stale, stale),
            (DropReason::BufferOverflow, expired),
        ] {
            if n > 0 {
                *self.stats.dropped.entry(reason).or_insert(0) += n;
            }
        }
        self.refresh_due();
    }
}
