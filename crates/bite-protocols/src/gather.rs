//! The shape most communicating protocols share: *gather, decide,
//! announce*. Every member sends its contribution (a vote, a ranked ballot,
//! a value read from its beliefs, an attribute, its utilities) to the team
//! leader; the leader decides from what it gathered and multicasts the
//! decision. What differs between protocols — what a member contributes and
//! how the leader decides — is a [`Rule`]; everything about robustness is
//! here, once:
//!
//! - members send their contribution when they reach the point (or, for a
//!   rule that announces a call first, when the call arrives), and resend
//!   it with exponential backoff (retry, 2, 4… intervals, capped at 64)
//!   until they hear the decision; the leader answers any contribution
//!   after deciding with the decision, so a lost decision costs one resend;
//! - a rule with a call ([`Rule::call`]) has the leader call again, on its
//!   own timer, the members it has not heard from;
//! - the leader decides as soon as every live member has contributed, and
//!   at its deadline from what it has; a member cut off from its leader
//!   decides alone ([`Rule::alone`]) and the kernel reports the timeout;
//! - members presumed lost are not waited for; when the leader is lost the
//!   next lowest live member takes over: members resend their contribution
//!   to it, and a member that already applied the old leader's decision
//!   tells it, so that the survivors apply one decision;
//! - a leader that leaves the point early decides from what it has (the
//!   others go on with that); a member that leaves early sends its
//!   abstention, if the rule has one.
//!
//! Messages per decision, no faults, team of n ≥ 2: n − 1 contributions and
//! one decision (n), plus one call for rules that announce one (n + 1).
//! Rounds: 2 (3 with a call).

use bite_core::ids::RobotId;
use bite_core::interaction::{Cx, Interaction, Outcome};
use bite_core::msg::Body;
use bite_core::rules;
use std::collections::BTreeMap;
use std::sync::Arc;

/// What a gather-decide-announce protocol plugs in.
pub(crate) trait Rule: Send + Sync + 'static {
    /// The protocol's name (for violations).
    fn name(&self) -> &'static str;
    /// The leader's call, multicast before members contribute (`None`:
    /// members contribute as soon as they reach the point).
    fn call(&self, _cx: &Cx<'_>) -> Option<Body> {
        None
    }
    /// Whether the leader waits for contributions at all (`false`: it
    /// decides alone at once and informs the members).
    fn gathers(&self) -> bool {
        true
    }
    /// This robot's contribution.
    fn contribution(&self, cx: &mut Cx<'_>) -> Body;
    /// `Ok` if `body` is a well-formed contribution from `from`; `Err`
    /// says what is wrong (a protocol violation, ignored).
    fn check(&self, cx: &Cx<'_>, from: RobotId, body: &Body) -> Result<(), String>;
    /// True when `body` is the kind of message members contribute.
    fn is_contribution(&self, body: &Body) -> bool;
    /// The decision from the contributions gathered (the leader's own
    /// included; members that did not answer are missing).
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome;
    /// What a member cut off from its leader decides at the deadline.
    fn alone(&self, cx: &mut Cx<'_>) -> Outcome {
        rules::fallback(cx)
    }
    /// What a member leaving before it contributed sends, if anything.
    fn abstain(&self) -> Option<Body> {
        None
    }
}

/// The message that announces a decision.
pub(crate) fn announcement(o: &Outcome) -> Body {
    match o {
        Outcome::Sync(choice) => Body::Decision { choice: *choice },
        Outcome::Allocate(a) => Body::assignment(a),
        Outcome::Terminate(next) => Body::Release { next: *next },
    }
}

/// The decision an announcement carries, if it is one of the kind this
/// instance decides (`None` otherwise, or if malformed).
pub(crate) fn announced(cx: &Cx<'_>, body: &Body) -> Option<Outcome> {
    use bite_core::interaction::PointInput;
    match (cx.input(), body) {
        (PointInput::Sync { .. }, Body::Decision { choice }) => Some(Outcome::Sync(*choice)),
        (PointInput::Allocate { .. }, Body::Assignment { .. }) => body
            .to_assignment(cx.team().members.roster_len())
            .map(|a| Outcome::Allocate(a.into())),
        (PointInput::Terminate, Body::Release { next }) => Some(Outcome::Terminate(*next)),
        _ => None,
    }
}

/// Wait before the next resend: the retry interval, doubling each time
/// (capped at 64 intervals).
pub(crate) fn backoff(cx: &Cx<'_>, resends: u32) -> std::time::Duration {
    cx.retry() * 2u32.pow(resends.min(6))
}

/// How a protocol's announcements are written and read, when not with the
/// library's messages (`Decision`, `Assignment`, `Release`): graph-defined
/// protocols announce with a message of their own.
pub(crate) trait Announce: Send + Sync {
    /// The announcement of `o`.
    fn encode(&self, o: &Outcome) -> Body;
    /// `None`: `body` is not an announcement; `Some(Err)`: it is one but
    /// malformed (or of another kind); `Some(Ok)`: the decision it carries.
    fn decode(&self, cx: &Cx<'_>, body: &Body) -> Option<Result<Outcome, ()>>;
}

/// What every leader-coordinated protocol keeps about its coordination:
/// the decision, who leads, and the resend backoff.
#[derive(Default)]
pub(crate) struct Coord {
    /// How announcements are written (`None`: the library's messages).
    codec: Option<Arc<dyn Announce>>,
    /// The decision, once known (answers retransmissions).
    pub(crate) result: Option<Outcome>,
    /// The leader this robot last dealt with (to notice a new leader).
    known_leader: Option<RobotId>,
    /// This robot became the leader after the instance started (its
    /// leader was lost).
    took_over: bool,
    /// A decision announced by a teammate before this robot's leader that
    /// has left the behavior since (left out here, not presumed lost),
    /// heard while this robot was a member: adopted if this robot comes
    /// to lead (see [`Coord::members_changed`]).
    departed_decision: Option<(RobotId, Outcome)>,
    /// This robot leads after a coordinator that left the behavior, from
    /// the instance's start or since (see [`Coord::after_departed`]).
    heir_of_departed: bool,
    /// This robot led from the start only because teammates before it had
    /// left the behavior, and has yet to ask the members it has not heard
    /// (see [`Coord::ask_after_departed`]).
    ask_missing: bool,
    resends: u32,
    /// When the instance last made progress (see [`Coord::progress`]).
    progress_at: Option<bite_core::time::Time>,
}

impl Coord {
    /// A coordination announcing with `codec`'s messages.
    pub(crate) fn with_codec(codec: Arc<dyn Announce>) -> Self {
        Coord {
            codec: Some(codec),
            ..Coord::default()
        }
    }

    /// The announcement of `o`.
    pub(crate) fn encode(&self, o: &Outcome) -> Body {
        match &self.codec {
            Some(c) => c.encode(o),
            None => announcement(o),
        }
    }

    fn decode(&self, cx: &Cx<'_>, body: &Body) -> Option<Result<Outcome, ()>> {
        if let Some(c) = &self.codec {
            return c.decode(cx, body);
        }
        match announced(cx, body) {
            Some(o) => Some(Ok(o)),
            None if matches!(
                body,
                Body::Decision { .. } | Body::Assignment { .. } | Body::Release { .. }
            ) =>
            {
                Some(Err(()))
            }
            None => None,
        }
    }

    /// The instance made progress (the leader heard a member, a member
    /// heard its leader move on): the deadline, which bounds the time
    /// without progress, starts over, and so does the resend backoff.
    pub(crate) fn progress(&mut self, cx: &mut Cx<'_>) {
        self.progress_at = Some(cx.now());
        self.resends = 0;
        cx.postpone_deadline();
    }

    /// On a timer: true when the instance has been quiet for a whole
    /// backoff period since its last progress (time to resend); otherwise
    /// the check is rescheduled for then.
    pub(crate) fn quiet(&mut self, cx: &mut Cx<'_>) -> bool {
        match self.progress_at {
            Some(t) if cx.now() < t + backoff(cx, self.resends) => {
                let at = t + backoff(cx, self.resends);
                cx.wake_at(at);
                false
            }
            _ => true,
        }
    }

    /// The instance starts: remember the leader. A robot that leads only
    /// because the teammates before it are left out (they left the
    /// behavior, or are presumed lost) takes over from them: a decision
    /// one of them made, which a member applied and tells it, is the
    /// team's (docs/reliability.md, "A decision made before the late
    /// arrivals came").
    pub(crate) fn start(&mut self, cx: &Cx<'_>) {
        self.known_leader = Some(cx.leader());
        self.took_over = cx.is_leader() && cx.team().members.iter().next() != Some(cx.me());
        let me = cx.me();
        let before = || (cx.team().members.iter()).take_while(move |r| *r < me);
        self.ask_missing = self.took_over && before().any(|r| cx.has_left(r));
        // One before it ran the point and left: it may have decided, and
        // left with its decision.
        self.heir_of_departed = self.ask_missing && before().any(|r| cx.left_after_running(r));
    }

    /// True once, for a robot that has led from the start only because
    /// teammates before it left the behavior: a member may have sent its
    /// contribution to one of them and left the point since, and will not
    /// send it again. Asked, its kernel says it left, and the coordinator
    /// decides without it instead of waiting for its deadline
    /// (docs/reliability.md, "A contribution sent to a coordinator that
    /// left"). A robot that took over during the instance asks at once
    /// (`on_members_changed`).
    pub(crate) fn ask_after_departed(&mut self) -> bool {
        std::mem::take(&mut self.ask_missing)
    }

    /// Members changed: did the leader change? (Notes a takeover.) When
    /// it did, the resend backoff starts over, a retry from now: a new
    /// leader calls again the members it has not heard, and a member asks
    /// a new leader it has not heard from, then, not on the schedule their
    /// resends to the old leader had backed off to (seconds by then). A
    /// member that has yet to learn of the change drops the new leader's
    /// first call, and a new leader may itself have left the point: both
    /// cost a deadline (docs/reliability.md, "A call dropped at a
    /// takeover").
    pub(crate) fn leader_changed(&mut self, cx: &mut Cx<'_>) -> bool {
        let leader = cx.leader();
        let before = self.known_leader;
        let changed = before != Some(leader);
        self.known_leader = Some(leader);
        if changed && !self.idle(cx) {
            self.resends = 0;
            cx.wake_after_retry();
        }
        if changed && cx.is_leader() {
            self.took_over = true;
            if before.is_some_and(|b| b != cx.me() && cx.has_left(b)) {
                self.heir_of_departed = true;
            }
        }
        changed
    }

    /// A teammate was lost or left: the bookkeeping every leader-based
    /// protocol shares. `None` when nothing is left to do here (decided —
    /// a new leader is told the decision — or aborted); otherwise whether
    /// the leader changed.
    pub(crate) fn members_changed(&mut self, cx: &mut Cx<'_>) -> Option<bool> {
        let changed = self.leader_changed(cx);
        if self.result.is_some() {
            if changed {
                self.tell_new_leader(cx);
            }
            return None;
        }
        if cx.is_aborted() || self.adopt_departed(cx) {
            return None;
        }
        Some(changed)
    }

    /// True when this robot leads after a coordinator that left the
    /// behavior (left out, not presumed lost), from the instance's start
    /// or since: that coordinator may have decided and left with its
    /// decision, which has yet to reach this robot. Leaving the point
    /// then, it decides nothing: a decision of its own, announced, parted
    /// the members that applied it from those that had the old one
    /// (docs/reliability.md, "A coordinator that took over and left" and
    /// "A coordinator after one that left, from the start"); the members'
    /// next coordinator adopts the old one if it reached it
    /// ([`Coord::on_announcement`]). A robot that leads from the start as
    /// the team's first member, after teammates presumed lost, or after
    /// ones that left without running the point
    /// ([`Cx::left_after_running`]), decides as it leaves: nobody before
    /// it decided, and members that reached the point later would wait
    /// for a coordinator that had gone.
    pub(crate) fn after_departed(&self) -> bool {
        self.heir_of_departed
    }

    /// Leading now, with the decision a teammate before this robot
    /// applied and left with (kept by [`Coord::on_announcement`]): adopt
    /// and announce it, the team's decision. True when it did.
    pub(crate) fn adopt_departed(&mut self, cx: &mut Cx<'_>) -> bool {
        if self.result.is_some() || !cx.is_leader() {
            return false;
        }
        match self.departed_decision.take() {
            Some((_, o)) => {
                self.adopt(cx, o, true);
                true
            }
            None => false,
        }
    }

    /// The deadline passed: true when this robot leads (`leading`) and has
    /// not decided — it decides from what it has; a member cut off from
    /// its leader decides alone by the silent rule.
    pub(crate) fn deadline_passed(&self, cx: &mut Cx<'_>, leading: bool) -> bool {
        if cx.is_leader() && leading {
            return self.result.is_none();
        }
        let o = rules::fallback(cx);
        cx.decide(o);
        false
    }

    /// Apply a decision; a leader also announces it.
    pub(crate) fn adopt(&mut self, cx: &mut Cx<'_>, outcome: Outcome, announce: bool) {
        if announce {
            cx.broadcast(self.encode(&outcome));
        }
        self.result = Some(outcome.clone());
        cx.decide(outcome);
    }

    /// Handle `body` if it announces a decision (true if it was one): a
    /// member applies its leader's; a leader that took over from a lost one
    /// adopts the one a member heard from it, so that all or none apply
    /// it. A decision sent to the original leader is a member's own
    /// decision after its deadline, not the team's: ignored.
    pub(crate) fn on_announcement(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) -> bool {
        let outcome = match self.decode(cx, body) {
            None => return false,
            Some(Err(())) => {
                cx.violation(format!("malformed `{}` from {from}", body.name()));
                return true;
            }
            Some(Ok(o)) => o,
        };
        if self.result.is_some() || cx.is_aborted() {
            return true;
        }
        // From a teammate before this robot that left the behavior (left
        // out, not presumed lost): it coordinated the point, decided,
        // applied its decision and went on, and the message waited while
        // this robot was on its way. A leader adopts (and announces) it;
        // a member keeps it in case it comes to lead, and follows its
        // leader meanwhile: under loss the leader may not have heard it,
        // and members that applied it while their leader decided anew
        // parted from it (docs/reliability.md, "A decision from a leader
        // that left").
        let departed = from < cx.me() && cx.has_left(from);
        if cx.is_leader() {
            if self.took_over || departed {
                self.adopt(cx, outcome, true);
            }
        } else if from == cx.leader() {
            self.adopt(cx, outcome, false);
        } else if departed
            && self
                .departed_decision
                .as_ref()
                .is_none_or(|(r, _)| from < *r)
        {
            self.departed_decision = Some((from, outcome));
        }
        true
    }

    /// The kernel applied the team's decision to this instance (a notice
    /// from a teammate presumed lost): it is this instance's decision now,
    /// which it answers with and tells a new leader, and it decides no
    /// other (see [`Interaction::on_team_decision`]).
    pub(crate) fn team_decided(&mut self, outcome: &Outcome) {
        if self.result.is_none() {
            self.result = Some(outcome.clone());
        }
    }

    /// A leader answers a member with the decision, if there is one.
    pub(crate) fn answer(&self, cx: &mut Cx<'_>, to: RobotId) -> bool {
        match &self.result {
            Some(o) => {
                cx.send(to, self.encode(o));
                true
            }
            None => false,
        }
    }

    /// A member whose leader changed tells it the decision applied here
    /// (true if it did).
    pub(crate) fn tell_new_leader(&self, cx: &mut Cx<'_>) -> bool {
        match &self.result {
            Some(o) if !cx.is_leader() => {
                cx.send(cx.leader(), self.encode(o));
                true
            }
            _ => false,
        }
    }

    /// Nothing left to do on a timer: decided or left.
    pub(crate) fn idle(&self, cx: &Cx<'_>) -> bool {
        self.result.is_some() || cx.is_decided() || cx.is_aborted()
    }

    /// Schedule the next resend with exponential backoff.
    pub(crate) fn next_resend(&mut self, cx: &mut Cx<'_>) {
        self.resends += 1;
        let t = cx.now() + backoff(cx, self.resends);
        cx.wake_at(t);
    }

    /// Start the backoff over (a new leader to talk to).
    pub(crate) fn reset_backoff(&mut self) {
        self.resends = 0;
    }
}

/// One instance of a gather-decide-announce protocol.
pub(crate) struct Gather<R: Rule> {
    rule: Arc<R>,
    /// Leader only: contributions received, its own included.
    got: BTreeMap<RobotId, Body>,
    /// Leader only: whether the call went out.
    called: bool,
    /// Member only: the contribution it sent.
    sent: Option<Body>,
    coord: Coord,
}

impl<R: Rule> Gather<R> {
    pub(crate) fn new(rule: Arc<R>) -> Self {
        Gather {
            rule,
            got: BTreeMap::new(),
            called: false,
            sent: None,
            coord: Coord::default(),
        }
    }

    /// The other members not left out whose contribution the leader has
    /// not had (collected: the caller sends to them).
    fn missing(&self, cx: &Cx<'_>) -> Vec<RobotId> {
        let me = cx.me();
        (cx.members())
            .filter(|m| *m != me && !self.got.contains_key(m))
            .collect()
    }

    fn finish(&mut self, cx: &mut Cx<'_>) {
        let outcome = self.rule.decide(cx, &self.got);
        self.coord.adopt(cx, outcome, true);
    }

    fn maybe_finish(&mut self, cx: &mut Cx<'_>) {
        if self.coord.result.is_some() || cx.is_aborted() {
            return;
        }
        // Contributions of members presumed lost since are not waited for.
        let heard = cx.members().filter(|m| self.got.contains_key(m)).count();
        if !self.rule.gathers() || heard >= cx.team_size() {
            self.finish(cx);
        }
    }

    /// Lead: call (if the rule does), count this robot's own contribution.
    fn lead(&mut self, cx: &mut Cx<'_>) {
        if self.rule.gathers() {
            if !self.called
                && let Some(call) = self.rule.call(cx)
            {
                cx.broadcast(call);
            }
            self.called = true;
            if !self.got.contains_key(&cx.me()) {
                let mine = self.rule.contribution(cx);
                self.got.insert(cx.me(), mine);
            }
        }
        self.maybe_finish(cx);
    }

    fn contribute(&mut self, cx: &mut Cx<'_>) {
        if cx.is_decided() {
            // Decided already (a teammate told it how the team decided
            // without it): a contribution now could only part it from the
            // coordinator's decision.
            return;
        }
        let body = match &self.sent {
            Some(b) => b.clone(),
            None => self.rule.contribution(cx),
        };
        cx.send(cx.leader(), body.clone());
        self.sent = Some(body);
    }
}

impl<R: Rule> Interaction for Gather<R> {
    fn start(&mut self, cx: &mut Cx<'_>) {
        self.coord.start(cx);
        if cx.is_leader() {
            self.lead(cx);
        } else if self.rule.gathers() && self.rule.call(cx).is_none() {
            self.contribute(cx);
        }
        if !cx.is_decided() {
            cx.wake_after_retry();
        }
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        let name = self.rule.name();
        if self.rule.is_contribution(body) {
            if !cx.is_leader() {
                // Sent to a robot that no longer leads, or does not know yet
                // that it does: the sender's retries recover it. One that
                // applied the team's decision answers with it: the sender,
                // which takes it for the coordinator (the one that decided
                // has left, as far as the sender knows), would otherwise ask
                // until its deadline (docs/reliability.md, "A member asked
                // for a decision it applied", property seed 4167).
                self.coord.answer(cx, from);
                return;
            }
            if self.coord.answer(cx, from) || cx.is_aborted() {
                return;
            }
            match self.rule.check(cx, from, body) {
                Ok(()) => {
                    self.coord.progress(cx);
                    self.got.insert(from, body.clone());
                    self.maybe_finish(cx);
                }
                Err(why) => cx.violation(format!("{name}: {from} {why}")),
            }
            return;
        }
        if self.coord.on_announcement(cx, from, body) {
            return;
        }
        match body {
            Body::Query if cx.is_leader() => {
                if !self.coord.answer(cx, from)
                    && !self.got.contains_key(&from)
                    && !cx.is_aborted()
                    && let Some(call) = self.rule.call(cx)
                {
                    cx.send(from, call);
                }
            }
            Body::Query => {
                // A leader that took over asks for what it has not had: the
                // contribution this robot sent it when its own view made it
                // the leader first, dropped because it did not know yet that
                // it led (the resend backs off for seconds by then).
                if from == leader
                    && self.sent.is_some()
                    && self.coord.result.is_none()
                    && !cx.is_aborted()
                {
                    self.contribute(cx);
                } else if from != leader {
                    // A member that takes this robot for its coordinator:
                    // the decision, if the team's was applied here (as for
                    // a contribution, above).
                    self.coord.answer(cx, from);
                }
            }
            _ if self
                .rule
                .call(cx)
                .as_ref()
                .is_some_and(|c| same_kind(c, body)) =>
            {
                // The call: contribute (again, if ours was lost).
                if from == leader
                    && !cx.is_leader()
                    && self.coord.result.is_none()
                    && !cx.is_aborted()
                {
                    self.contribute(cx);
                }
            }
            _ if cx.is_aborted() => {}
            other => cx.violation(format!("{name}: unexpected `{}` from {from}", other.name())),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if self.coord.idle(cx) || !self.coord.quiet(cx) {
            return;
        }
        if cx.is_leader() {
            // Call again those not heard from (rules without a call wait
            // for the members' own resends, but ask once those that may
            // have sent theirs to a coordinator that left).
            if let Some(call) = self.rule.call(cx) {
                for m in self.missing(cx) {
                    cx.send(m, call.clone());
                }
            } else if self.coord.ask_after_departed() {
                for m in self.missing(cx) {
                    cx.send(m, Body::Query);
                }
            }
        } else if self.sent.is_some() {
            self.contribute(cx);
        } else {
            // Waiting for a call or a decision that may have been lost.
            cx.send(cx.leader(), Body::Query);
        }
        self.coord.next_resend(cx);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            if self.coord.result.is_none() {
                self.finish(cx);
            }
        } else {
            let o = self.rule.alone(cx);
            cx.decide(o);
        }
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        let changed = self.coord.leader_changed(cx);
        if cx.is_leader() {
            if !cx.is_aborted() && self.coord.adopt_departed(cx) {
                return;
            }
            if self.coord.result.is_none() && !cx.is_aborted() {
                if changed && self.rule.gathers() && self.rule.call(cx).is_none() {
                    // Taking over a rule without a call: a member that
                    // sent its contribution to the leader before and left
                    // the instance since will not send it again; asked, its
                    // kernel says it left (docs/reliability.md, "A
                    // contribution sent to the leader before").
                    for m in self.missing(cx) {
                        cx.send(m, Body::Query);
                    }
                }
                // Leading now (or still): call if not done, count who is left.
                self.lead(cx);
            }
        } else if changed && !self.coord.tell_new_leader(cx) && self.sent.is_some() {
            // Our contribution again, to the new leader.
            self.coord.reset_backoff();
            self.contribute(cx);
        }
    }

    fn on_team_decision(&mut self, _cx: &mut Cx<'_>, outcome: &Outcome) {
        self.coord.team_decided(outcome);
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            // Leaving: the others go on with what was gathered so far.
            if self.coord.result.is_none() && !self.coord.after_departed() {
                self.finish(cx);
            }
        } else if self.sent.is_none()
            && let Some(body) = self.rule.abstain()
        {
            self.sent = Some(body.clone());
            cx.send(cx.leader(), body);
        }
    }
}

fn same_kind(a: &Body, b: &Body) -> bool {
    std::mem::discriminant(a) == std::mem::discriminant(b)
}

/// The answer of a forgotten instance to a member's late message: the
/// decision this robot applied (nothing if it left before deciding, or if
/// the message asks for nothing: an announcement, an acknowledgement, or
/// a teammate's `Done` — "I have left this behavior", which the kernel
/// sends in answer to a message about a behavior its robot has left; a
/// decision in answer to it drew another `Done`, for ever:
/// docs/reliability.md, "A decision answered to a teammate that left").
pub(crate) fn late_reply(closed: &bite_core::interaction::Closed, body: &Body) -> Option<Body> {
    use bite_core::interaction::Closed;
    if !body.asks() {
        return None;
    }
    match closed {
        Closed::Synced(choice) => Some(Body::Decision { choice: *choice }),
        Closed::Allocated(a) => Some(Body::assignment(a)),
        Closed::Terminated(next) => Some(Body::Release { next: *next }),
        Closed::Left => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bite_core::interaction::Closed;

    #[test]
    fn a_forgotten_instance_answers_only_a_message_that_asks() {
        let synced = Closed::Synced(None);
        let decision = Some(Body::Decision { choice: None });
        assert_eq!(late_reply(&synced, &Body::Vote { choice: None }), decision);
        assert_eq!(late_reply(&synced, &Body::Query), decision);
        // Notices ask for nothing: answering `Done` with the decision drew
        // another `Done` from a robot that had left, for ever.
        for notice in [Body::Done, Body::Ack, Body::Decision { choice: None }] {
            assert_eq!(late_reply(&synced, &notice), None, "{notice:?}");
        }
        assert_eq!(late_reply(&Closed::Left, &Body::Query), None);
    }
}
