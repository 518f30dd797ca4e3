//! Algorithm 1 (CONTROL): expand the stack, monitor every frame's
//! conditions, pop what ended, terminate and choose what follows.

use super::*;

impl Kernel {
    /// Lines 1–2: push b0 for the whole team.
    pub(super) fn begin(&mut self) {
        let graph = self.mission.graph().clone();
        for (name, v) in graph.initial_beliefs() {
            self.beliefs
                .set_named(name, v.clone(), self.now, Source::Given);
        }
        self.push(graph.start(), TeamId::ROOT, Via::Start, None);
    }

    pub(super) fn versions(&self) -> (u64, u64) {
        (self.beliefs.version(), self.stack_version)
    }

    /// Run transitions until the kernel must wait for an input.
    pub(super) fn advance(&mut self) {
        for _ in 0..self.limits.max_transitions {
            if !matches!(self.phase, Phase::NotStarted | Phase::Finished)
                && let Some((i, reason)) = self.ended_frame()
            {
                self.end_frame(i, reason);
                continue;
            }
            let progressed = match &self.phase {
                Phase::NotStarted if self.awaiting_rejoin() => false,
                Phase::NotStarted => {
                    self.begin();
                    true
                }
                Phase::Finished | Phase::Run => false,
                Phase::Idle { since, silent } => {
                    // With a silent termination protocol nobody will tell
                    // this robot when the others are done: its empty part is
                    // over, and it ends it at its next tick (never within the
                    // same tick, so a cycle back here cannot spin).
                    if *silent && self.in_tick && self.ticks > *since {
                        let i = self.stack.len() - 1;
                        self.phase = Phase::Run;
                        self.end_frame(i, EndReason::ChainEnded);
                        true
                    } else {
                        false
                    }
                }
                Phase::Expand => self.expand(),
                Phase::WaitChild { seen } => {
                    if *seen == self.versions() && !self.children_pre_timed() {
                        false
                    } else if self.enabled_children().is_empty() {
                        self.phase = Phase::WaitChild {
                            seen: self.versions(),
                        };
                        false
                    } else {
                        self.phase = Phase::Expand;
                        true
                    }
                }
                Phase::Allocating(key) => {
                    let key = *key;
                    self.finish_allocation(key)
                }
                Phase::Terminating { .. } => self.finish_termination(),
                Phase::Selecting { .. } => self.select(),
            };
            if !progressed {
                return;
            }
        }
        self.emit(Event::TransitionLimit);
    }

    /// Line 4: the root-most frame that must end — its termination
    /// condition holds, or its team ended it.
    pub(super) fn ended_frame(&mut self) -> Option<(usize, EndReason)> {
        let vers = self.versions();
        let graph = self.mission.graph();
        for i in 0..self.stack.len() {
            let f = &self.stack[i];
            if f.team_ended {
                return Some((i, EndReason::Team));
            }
            // Termination conditions are about the world: they are
            // monitored on control ticks (Algorithm 1's execution loop), and
            // a behavior's condition is first checked at the tick after it
            // started, once the runtime has started its skill and reported
            // fresh percepts. Team decisions (above) act on any input.
            if !self.in_tick || f.born == self.ticks {
                continue;
            }
            let beh = graph.behavior(f.behavior);
            if beh.until.is_none() && beh.urgent.is_none() {
                continue;
            }
            let conds = || beh.until.iter().chain(&beh.urgent);
            // Found false at this belief version, and at this stack
            // version or (`u64::MAX`) at any: see `until_false_at`.
            if let Some((b, s)) = f.until_false_at
                && b == vers.0
                && (s == vers.1 || s == u64::MAX)
                && !conds().any(|e| e.depends_on_time())
            {
                continue;
            }
            let runs = match i {
                0 => &self.root_runs,
                _ => &self.stack[i - 1].runs,
            };
            let env = BeliefEnv {
                beliefs: &self.beliefs,
                runs,
                now: self.now,
                started: f.started,
                own: f.behavior,
            };
            if let Some(urgent) = &beh.urgent
                && urgent.eval(&env)
            {
                let e = self.condition_event(f.behavior, "urgent", urgent);
                self.out.push_back(Output::Event(e));
                return Some((i, EndReason::Urgent));
            }
            if let Some(until) = &beh.until
                && until.eval(&env)
            {
                let e = self.condition_event(f.behavior, "until", until);
                self.out.push_back(Output::Event(e));
                return Some((i, EndReason::Until));
            }
            let stack = match conds().any(|e| e.depends_on_runs()) {
                true => vers.1,
                false => u64::MAX,
            };
            self.stack[i].until_false_at = Some((vers.0, stack));
        }
        None
    }

    pub(super) fn condition_event(
        &self,
        behavior: BehaviorId,
        field: &'static str,
        e: &Expr,
    ) -> Event {
        let sym = self.beliefs.symbols();
        Event::ConditionHeld {
            behavior,
            field,
            beliefs: e
                .beliefs()
                .iter()
                .map(|id| (sym.name_shared(*id), self.beliefs.value(*id).cloned()))
                .collect(),
        }
    }

    /// Lines 4b–6: pop the descendants of frame `i` and `i` itself, and
    /// start its synchronized termination.
    pub(super) fn end_frame(&mut self, i: usize, reason: EndReason) {
        self.abort_phase();
        let ended = self.stack[i].behavior;
        // Subteams below an end this robot makes alone (an individual
        // behavior, or one whose termination is silent: each member ends
        // it on its own) are left while their teammates go on in them:
        // it answers those that still send it heartbeats for a while
        // (`Kernel::answer_strangers`). A team that ends together learns
        // who ended from its termination protocol.
        if self.stack[i..].iter().any(|f| f.subteams.is_some()) {
            let b = self.graph().behavior(ended);
            let together = b.team
                && (self.mission.bound(ended, Kind::Terminate))
                    .is_some_and(|x| x.protocol.communicates());
            if !together {
                self.left_at = Some(self.now);
            }
        }
        while self.stack.len() > i + 1 {
            if let Some(f) = self.stack.pop() {
                self.abort(f.term_key());
                self.retire(&f, EndReason::Ancestor(ended));
            }
        }
        let Some(frame) = self.stack.pop() else {
            return;
        };
        self.retire(&frame, reason);
        let key = frame.term_key();
        let why = match reason {
            EndReason::Until | EndReason::Urgent => LocalEnd::Condition,
            _ => LocalEnd::ChainEnded,
        };
        let key = if self.instances.contains_key(&key) {
            self.term_local_done(key, why);
            Some(key)
        } else {
            None
        };
        if reason == EndReason::Urgent {
            // Preemption: the termination protocol has been told (it goes on
            // answering teammates), but this robot does not wait for it,
            // nor for its team to choose the successor.
            let mut frame = frame;
            frame.urgent = true;
            self.phase = Phase::Selecting {
                frame: Box::new(frame),
                key: None,
            };
            return;
        }
        self.phase = Phase::Terminating {
            frame: Box::new(frame),
            key,
        };
    }

    /// Bookkeeping for a popped frame: links, subteams, event.
    pub(super) fn retire(&mut self, f: &Frame, reason: EndReason) {
        self.stack_version += 1;
        if reason != EndReason::Converged {
            let parent = self.stack.last().map(Frame::id);
            self.note_ended(f.id(), parent);
        }
        self.org.unlink(f.behavior, f.team);
        self.dissolve(f.subteams.as_ref());
        self.emit(Event::Terminated {
            behavior: f.behavior,
            team: f.team,
            epoch: f.epoch,
            reason,
        });
    }

    /// Dissolve subteams an allocation created.
    pub(super) fn dissolve(&mut self, gone: Option<&Arc<Split>>) {
        let Some(gone) = gone else {
            return;
        };
        self.org.dissolve_split(gone);
        // Late messages for dissolved teams are recognised by the
        // organization's memory of dead teams; the per-instance records can
        // go (a repeated allocation would otherwise grow them forever).
        self.closed.retain(|(t, _, _), _| !gone.contains(*t));
    }

    /// A child of the allocation at a frame on the stack that lost
    /// teammates and has fewer live members than it needs: the frame.
    pub(super) fn orphaned_frame(&self) -> Option<usize> {
        let graph = self.mission.graph();
        // A lost teammate that had already finished the behavior (arrived at
        // its barrier or an ancestor's) leaves nothing to re-allocate.
        let mut done: Option<MemberSet> = None;
        self.stack.iter().position(|f| {
            if let Some(d) = &f.departed {
                done.get_or_insert_with(|| MemberSet::empty(d.roster_len()))
                    .union_with(d);
            }
            let done = done.as_ref();
            let Some(split) = &f.subteams else {
                return false;
            };
            split.subteams().any(|(child, team)| {
                let live = team
                    .members
                    .iter()
                    .filter(|r| !self.lost.contains(*r) || done.is_some_and(|d| d.contains(*r)))
                    .count();
                let min = graph.behavior(child).members.0.max(1) as usize;
                live < team.size as usize && live < min
            })
        })
    }

    /// Re-allocate the children of frame `i` among the teammates still
    /// under it (its allocation protocol decides, in a new round): what
    /// runs below it ends, its subteams dissolve, and it expands again.
    /// `told` are the teammates the robot that started the round left out
    /// (this robot leaves them out too, presumed lost or not).
    pub(super) fn reallocate(&mut self, i: usize, round: u32, told: &[RobotId]) {
        self.abort_phase();
        let b = self.stack[i].behavior;
        while self.stack.len() > i + 1 {
            if let Some(f) = self.stack.pop() {
                self.abort(f.term_key());
                self.retire(&f, EndReason::Reallocation(b));
            }
        }
        let gone = self.stack[i].subteams.take();
        self.dissolve(gone.as_ref());
        let f = &mut self.stack[i];
        f.round = round;
        let (team, epoch) = (f.team, f.epoch);
        let children = f.allotted.clone();
        self.stack_version += 1;
        self.emit(Event::Reallocating {
            behavior: b,
            team,
            epoch,
            round,
        });
        let key = self.start_allocation((team, b, epoch, round), children, told);
        // Tell the team, so that teammates that have not noticed the loss
        // join, and those that left the point say so at once.
        if let Some(inst) = self.instances.get(&key)
            && inst.team.size > 1
        {
            let lost = inst.excluded_members();
            let to = Recipients::Team(inst.team.members.clone());
            self.send_outside(key, to, Body::Reallocate { lost });
        }
    }

    /// Push `b` for `team`, arming its termination protocol if it is a team
    /// behavior.
    /// `after`: the execution before it in its chain (`None`: the first
    /// of a chain under the top frame).
    pub(super) fn push(
        &mut self,
        b: BehaviorId,
        team: TeamId,
        via: Via,
        after: Option<(BehaviorId, u32)>,
    ) {
        let anchor = match after {
            Some((behavior, epoch)) => Some(Anchor {
                behavior,
                epoch,
                first: false,
            }),
            None => self.stack.last().map(|p| Anchor {
                behavior: p.behavior,
                epoch: p.epoch,
                first: true,
            }),
        };
        self.push_anchored(b, team, via, anchor);
    }

    pub(super) fn push_anchored(
        &mut self,
        b: BehaviorId,
        team: TeamId,
        via: Via,
        anchor: Option<Anchor>,
    ) {
        self.push_anchored_at(b, team, via, anchor, None);
    }

    /// [`Kernel::push_anchored`]; `at`: the execution to join, a
    /// teammate's (`Kernel::converge`), instead of the team's next one by
    /// this robot's count.
    pub(super) fn push_anchored_at(
        &mut self,
        b: BehaviorId,
        team: TeamId,
        via: Via,
        anchor: Option<Anchor>,
        at: Option<u32>,
    ) {
        let parent_runs = match self.stack.last_mut() {
            Some(p) => &mut p.runs,
            None => &mut self.root_runs,
        };
        let epoch = match at {
            Some(e) => self.org.start_run_at(team, b, e),
            None => self.org.start_run(team, b),
        };
        parent_runs.bump(b, epoch);
        self.org.link(b, team);
        let depth = self.stack.len() as u32;
        self.stack.push(Frame {
            behavior: b,
            team,
            epoch,
            started: self.now,
            subteams: None,
            round: 0,
            allotted: Arc::default(),
            team_ended: false,
            urgent: false,
            until_false_at: None,
            born: self.ticks,
            runs: crate::belief::RunCounts::new(),
            departed: None,
            anchor,
            alloc_heals: 0,
            left_behind: false,
        });
        self.stack_version += 1;
        self.stats.selections += 1;
        let after = anchor.filter(|a| !a.first).map(|a| FrameRef {
            behavior: a.behavior,
            epoch: a.epoch,
        });
        self.emit(Event::Selected {
            behavior: b,
            team,
            epoch,
            depth,
            via,
            after,
        });
        if self.graph().is_term_point(b) {
            let key = InstanceKey {
                team,
                behavior: b,
                kind: Kind::Terminate,
                epoch,
                round: 0,
            };
            self.start_instance(key, PointInput::Terminate, &[]);
        }
        self.phase = Phase::Expand;
    }

    /// True when a precondition of the top frame's children can change
    /// with time alone (`elapsed`, `age`): re-check on every input.
    pub(super) fn children_pre_timed(&self) -> bool {
        let Some(top) = self.stack.last() else {
            return false;
        };
        let graph = self.mission.graph();
        graph.behavior(top.behavior).children.iter().any(|c| {
            graph
                .behavior(*c)
                .pre
                .as_ref()
                .is_some_and(|p| p.depends_on_time())
        })
    }

    /// The children of the top frame whose preconditions hold, in graph
    /// order (shared with the mission when they all do).
    pub(super) fn enabled_children(&self) -> Arc<[ChildSlot]> {
        let Some(top) = self.stack.last() else {
            return Arc::default();
        };
        let graph = self.mission.graph();
        let Some(all) = self.mission.child_slots_shared(top.behavior) else {
            return Arc::default();
        };
        if self.mission.children_unconditional(top.behavior) {
            return all.clone();
        }
        self.enabled_of(graph, all, |c| c.behavior)
    }

    /// The entries of `all` whose behavior's precondition holds: `all`
    /// itself, shared, when every one does.
    fn enabled_of<T: Copy>(
        &self,
        graph: &BehaviorGraph,
        all: &Arc<[T]>,
        behavior: impl Fn(&T) -> BehaviorId,
    ) -> Arc<[T]> {
        match all.iter().position(|c| !self.pre_holds(graph, behavior(c))) {
            None => all.clone(),
            Some(first) => all[..first]
                .iter()
                .chain(
                    all[first + 1..]
                        .iter()
                        .filter(|c| self.pre_holds(graph, behavior(c))),
                )
                .copied()
                .collect(),
        }
    }

    /// Precondition of `b`, a candidate to run directly under the current
    /// top of the stack.
    pub(super) fn pre_holds(&self, graph: &BehaviorGraph, b: BehaviorId) -> bool {
        graph.behavior(b).pre.as_ref().is_none_or(|pre| {
            pre.eval(&BeliefEnv {
                beliefs: &self.beliefs,
                runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
                now: self.now,
                started: self.now,
                own: b,
            })
        })
    }

    /// Line 3: expand the top frame.
    pub(super) fn expand(&mut self) -> bool {
        let Some(top) = self.stack.last() else {
            self.phase = Phase::Finished;
            return false;
        };
        let (b, team, epoch, round) = (top.behavior, top.team, top.epoch, top.round);
        if self.graph().behavior(b).is_atomic() {
            self.phase = Phase::Run;
            return false;
        }
        let enabled = self.enabled_children();
        if enabled.is_empty() {
            self.emit(Event::WaitingForChild { behavior: b });
            self.phase = Phase::WaitChild {
                seen: self.versions(),
            };
            return false;
        }
        if self.graph().is_alloc_point(b) {
            if let Some(top) = self.stack.last_mut() {
                top.allotted = enabled.clone();
            }
            self.start_allocation((team, b, epoch, round), enabled, &[]);
            return true;
        }
        self.push(enabled[0].behavior, team, Via::Expansion, None);
        true
    }

    /// Line 3c: allocate the children of the top frame (`team`, `b`,
    /// `epoch`), in allocation round `round`, leaving `told` out.
    pub(super) fn start_allocation(
        &mut self,
        (team, b, epoch, round): (TeamId, BehaviorId, u32, u32),
        children: Arc<[ChildSlot]>,
        told: &[RobotId],
    ) -> InstanceKey {
        let key = InstanceKey {
            team,
            behavior: b,
            kind: Kind::Allocate,
            epoch,
            round,
        };
        self.phase = Phase::Allocating(key);
        self.start_instance(key, PointInput::Allocate { children }, told);
        key
    }

    /// Line 3c continued: apply the allocation once decided.
    pub(super) fn finish_allocation(&mut self, key: InstanceKey) -> bool {
        let Some(outcome) = self.take_outcome(key) else {
            return false;
        };
        let Outcome::Allocate(asg) = outcome else {
            return false;
        };
        let (b, team) = (key.behavior, key.team);
        // The subteams, shared with every teammate of this process that
        // applied the same allocation (made when it was decided).
        let split = match self.instances.get(&key).and_then(|i| i.split.clone()) {
            Some(s) => s,
            None => self.mission.split(team, b, key.stamp(), asg),
        };
        self.org.add_split(split.clone());
        let mine = split.subteam_of(self.me).map(|(child, t)| (child, t.id));
        if let Some(top) = self.stack.last_mut() {
            top.subteams = Some(split);
        }
        match mine {
            Some((child, tid)) => self.push(child, tid, Via::Allocation, None),
            None => {
                // No place for this robot: its part of the allocating
                // behavior is empty. It idles under it until the behavior
                // ends — by its own condition, or by its team (a
                // communicating termination protocol is told at once that
                // this robot's part is over, so barriers do not wait for
                // it). With a silent protocol it ends its part at its next
                // tick (see `Phase::Idle`).
                self.emit(Event::Unassigned { behavior: b });
                self.idle_under_top();
            }
        }
        true
    }

    /// This robot has no part in the top frame's children: it idles under
    /// it until it ends — by its own condition, or by its team (a
    /// communicating termination protocol is told at once that this
    /// robot's part is over, so barriers do not wait for it). With a
    /// silent protocol it ends its part at its next tick (see
    /// `Phase::Idle`).
    pub(super) fn idle_under_top(&mut self) {
        let Some(top) = self.stack.last() else {
            return;
        };
        let key = top.term_key();
        let communicates = self
            .mission
            .bound(top.behavior, Kind::Terminate)
            .is_some_and(|x| x.protocol.communicates());
        self.phase = Phase::Idle {
            since: self.ticks,
            silent: !communicates,
        };
        if communicates {
            self.term_local_done(key, LocalEnd::Idle);
        }
    }

    /// Lines 6–7: once the termination protocol decided, run its
    /// replacement behavior or go on to select a successor.
    pub(super) fn finish_termination(&mut self) -> bool {
        let Phase::Terminating { key, .. } = &self.phase else {
            return false;
        };
        let outcome = match *key {
            None => Outcome::Terminate(None),
            Some(k) => match self.take_outcome(k) {
                Some(o) => o,
                None => return self.preempt_termination(),
            },
        };
        let Phase::Terminating { frame, key } = std::mem::replace(&mut self.phase, Phase::Run)
        else {
            return false;
        };
        // A replacement must be a child of the parent frame: anything else
        // would let a message push an arbitrary behavior (even an ancestor).
        let parent_children = self
            .stack
            .last()
            .map(|p| self.graph().behavior(p.behavior).children.clone())
            .unwrap_or_default();
        match outcome {
            Outcome::Terminate(Some(next)) if parent_children.contains(&next) => {
                let prev = Some((frame.behavior, frame.epoch));
                self.push(next, frame.team, Via::Replacement, prev);
            }
            Outcome::Terminate(Some(next)) => {
                if let Some(k) = key {
                    self.emit(Event::ProtocolViolation {
                        instance: k,
                        what: format!(
                            "replacement `{}` is not a child of the parent behavior; ignored",
                            self.graph().name_of(next)
                        ),
                    });
                }
                self.phase = Phase::Selecting { frame, key: None };
            }
            _ => self.phase = Phase::Selecting { frame, key: None },
        }
        true
    }

    /// Waiting for a termination protocol: if the behavior's `urgent`
    /// condition holds (checked on control ticks), stop waiting. The
    /// protocol, already told that this robot is done, goes on without it.
    pub(super) fn preempt_termination(&mut self) -> bool {
        let Phase::Terminating { frame, .. } = &self.phase else {
            return false;
        };
        if !self.in_tick {
            return false;
        }
        let graph = self.mission.graph().clone();
        let Some(urgent) = &graph.behavior(frame.behavior).urgent else {
            return false;
        };
        let env = BeliefEnv {
            beliefs: &self.beliefs,
            runs: self.stack.last().map_or(&self.root_runs, |p| &p.runs),
            now: self.now,
            started: frame.started,
            own: frame.behavior,
        };
        if !urgent.eval(&env) {
            return false;
        }
        let e = self.condition_event(frame.behavior, "urgent", urgent);
        self.out.push_back(Output::Event(e));
        let Phase::Terminating { mut frame, .. } = std::mem::replace(&mut self.phase, Phase::Run)
        else {
            return false;
        };
        frame.urgent = true;
        self.emit(Event::Preempted {
            behavior: frame.behavior,
            team: frame.team,
            epoch: frame.epoch,
        });
        self.phase = Phase::Selecting { frame, key: None };
        true
    }

    /// Line 8: choose the next behavior of the execution chain.
    pub(super) fn select(&mut self) -> bool {
        let Phase::Selecting { frame, key } = &self.phase else {
            return false;
        };
        let (b, team, epoch) = (frame.behavior, frame.team, frame.epoch);
        // An urgent end picks the successor alone: no fence there.
        if key.is_none() && !self.pending.is_empty() && !frame.urgent {
            let after = FrameId {
                team,
                behavior: b,
                epoch,
            };
            if !self.fence_passed(after) {
                return false;
            }
        }
        let Phase::Selecting { frame, key } = &self.phase else {
            return false;
        };
        let graph = self.mission.graph().clone();
        match *key {
            None => {
                let beh = graph.behavior(b);
                if beh.next.is_empty() {
                    return self.chain_end();
                }
                if graph.is_sync_point(b) && !frame.urgent {
                    // The team decides jointly even when this robot sees
                    // fewer than two enabled successors: its teammates may
                    // see more. Silent rules reduce to lines 8b–8d exactly.
                    let key = InstanceKey {
                        team,
                        behavior: b,
                        kind: Kind::Sync,
                        epoch,
                        round: 0,
                    };
                    if let Phase::Selecting { key: k, .. } = &mut self.phase {
                        *k = Some(key);
                    }
                    // The mission's list, shared, and the same list again
                    // for the candidates when every successor is enabled.
                    let successors: Arc<[BehaviorId]> = match self.mission.next_shared(b) {
                        Some((all, _)) => all.clone(),
                        None => beh.next.as_slice().into(),
                    };
                    let candidates = self.enabled_of(&graph, &successors, |s| *s);
                    self.start_instance(
                        key,
                        PointInput::Sync {
                            candidates,
                            successors,
                        },
                        &[],
                    );
                    return true;
                }
                match beh
                    .next
                    .iter()
                    .copied()
                    .find(|s| self.pre_holds(&graph, *s))
                {
                    Some(s) => {
                        if let Some(pre) = &graph.behavior(s).pre {
                            let e = self.condition_event(s, "pre", pre);
                            self.emit(e);
                        }
                        self.note_went_on();
                        self.phase = Phase::Run;
                        self.push(s, team, Via::Sequence, Some((b, epoch)));
                        true
                    }
                    None => self.chain_end(),
                }
            }
            Some(k) => {
                let Some(outcome) = self.take_outcome(k) else {
                    return false;
                };
                match outcome {
                    Outcome::Sync(Some(s)) => {
                        self.note_went_on();
                        self.phase = Phase::Run;
                        self.push(s, team, Via::Decision, Some((b, epoch)));
                        true
                    }
                    _ => self.chain_end(),
                }
            }
        }
    }

    /// Going on in sequence from the execution just ended (the popped
    /// frame): keep it, with what it followed and its depth
    /// (`Kernel::count_renamed`).
    fn note_went_on(&mut self) {
        let depth = self.stack.len();
        let parent = self.stack.last().map(Frame::id);
        self.went_on_from = self
            .popped()
            .and_then(|(f, _)| Some((depth, parent?, f.id(), f.anchor?)));
    }

    /// Line 8b: the execution chain is over, so its parent terminates.
    pub(super) fn chain_end(&mut self) -> bool {
        self.phase = Phase::Run;
        if self.stack.is_empty() {
            self.phase = Phase::Finished;
            self.emit(Event::MissionCompleted);
            return false;
        }
        let i = self.stack.len() - 1;
        self.end_frame(i, EndReason::ChainEnded);
        true
    }

    // ----- protocol instances -------------------------------------------
}
