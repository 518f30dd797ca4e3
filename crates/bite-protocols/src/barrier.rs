//! Synchronized termination: the team ends a behavior together.
//!
//! - `term.wait-all` (the paper's S3): a robot that has finished its part
//!   waits until every member of the subteam has finished too, then all go
//!   on together.
//! - `term.majority`: the behavior ends for everyone once more than half of
//!   the members of the subteam have finished (a majority that believes the
//!   goal reached, or is done); the others are stopped. The majority is of
//!   the whole subteam: teammates presumed lost count as not arrived, so a
//!   minority cut off by a partition (an isolated leader: a "majority of
//!   one") never decides; it ends the behavior only at its deadline, and the
//!   kernel reports the timeout. A teammate presumed lost that a deadline of
//!   this robot has already decided without is given up
//!   (`Cx::is_given_up`): out of the whole until heard again, so a survivor
//!   of a crash pays one deadline, not one at every barrier. Teammates that left the behavior by ending
//!   an ancestor (the kernel learns it from their heartbeats) are done with
//!   it and count as arrived.
//! - `term.first-wins`: the first member whose termination condition holds
//!   (it sees the goal: the target found, the box delivered) ends the
//!   behavior for everyone at once. A member whose part merely ran out
//!   waits, as at a barrier, so the behavior also ends when every member is
//!   done without anyone seeing the goal.
//!
//! The leader (lowest-id live member) keeps the barrier. A member that
//! finishes sends `Done` to the leader, which acknowledges it; once enough
//! members have arrived (all, counting the leader, or a majority) the
//! leader multicasts `Release`. A member resends `Done` after 1, 2, 4…
//! retry intervals (at most 64) until acknowledged, then every 4, 8, 16…
//! intervals until released. A lost `Release` is recovered because the
//! leader answers a late `Done` with `Release`; so it answers the `Query`
//! a member's kernel sends as soon as a heartbeat shows the leader past
//! the barrier, which under heavy loss comes long before the next
//! backed-off `Done`. A lost `Done` is recovered the same way the other
//! way round: a member whose heartbeats have shown it waiting at the
//! barrier for a retry interval has arrived, whether its `Done` came or
//! not (`on_member_waiting`; under heavy loss all of a member's reports,
//! ever further apart, may be lost, and the leader waited out its
//! deadline; without loss its `Done` arrives first). Members
//! released while still working
//! (majority, first-wins, or the leader's deadline) are told until they
//! acknowledge, every 1, 2, 4, 4, 4… retry intervals, at most 40 times (a
//! member at work waits for nothing, so nothing else would tell it; a
//! steady interval keeps heavy loss from delaying the news by minutes). A
//! leader that leaves the barrier before everyone arrived releases no one:
//! the members learn from its heartbeats that it left and report to the
//! next leader. In first-wins the member
//! that sees the goal multicasts `Release` itself, decides at once, and
//! retransmits to those that have not acknowledged.
//!
//! At its deadline the leader releases whoever has arrived; a member whose
//! deadline passes goes on alone (the kernel reports the timeout). A member
//! presumed lost is not waited for; when the leader is lost the next live
//! member takes over and members resend `Done` to it.
//!
//! Messages, no faults, team of n ≥ 2:
//! - wait-all: `Done` and `Ack` from each of the n−1 members and one
//!   `Release`: 2n − 1, plus, for a member that waits long for a slower
//!   leader, one more `Done`/`Ack` pair per backoff period (logarithmic in
//!   the wait). Rounds: 2 after the last arrival.
//! - majority: `Done`/`Ack` from the members that arrive before the
//!   release, the `Release`, and an `Ack` from each member stopped:
//!   about 2⌊n/2⌋ + 1 + ⌈n/2⌉ − 1.
//! - first-wins: one `Release` and n − 1 acknowledgements: n. Rounds: 1.

use crate::gather::backoff;
use crate::sync::no_params;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{
    Closed, Cx, Factory, Interaction, LocalEnd, Outcome, Params, Protocol, Setup,
};
use bite_core::msg::{Body, Kind};
use bite_core::org::MemberSet;
use std::sync::Arc;
use std::time::Duration;

/// When the team's part is over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Every member has finished.
    All,
    /// More than half of the members have finished.
    Majority,
    /// Every member has finished, or one saw the goal.
    FirstWins,
}

macro_rules! barrier_protocol {
    ($ty:ident, $name:literal, $aliases:expr, $mode:expr, $summary:literal) => {
        #[doc = $summary]
        #[derive(Debug, Clone, Copy, Default)]
        pub struct $ty;
        impl Protocol for $ty {
            fn name(&self) -> &'static str {
                $name
            }
            fn aliases(&self) -> &'static [&'static str] {
                $aliases
            }
            fn kind(&self) -> Kind {
                Kind::Terminate
            }
            fn communicates(&self) -> bool {
                true
            }
            fn summary(&self) -> &'static str {
                $summary
            }
            fn default_deadline(&self) -> Duration {
                Duration::from_secs(30)
            }
            fn configure(
                &self,
                params: &Params,
                _: &mut Setup<'_>,
            ) -> Result<Factory, bite_core::interaction::ConfigError> {
                no_params(self.name(), params)?;
                Ok(Arc::new(|| {
                    Box::new(Barrier::new($mode)) as Box<dyn Interaction>
                }))
            }
            fn late_reply(&self, closed: &Closed, body: &Body) -> Option<Body> {
                late_reply(closed, body)
            }
        }
    };
}

barrier_protocol!(
    WaitAll,
    "term.wait-all",
    &["S3"],
    Mode::All,
    "S3: the leader holds a barrier; everyone goes on when every member has finished."
);
barrier_protocol!(
    Majority,
    "term.majority",
    &[],
    Mode::Majority,
    "The behavior ends for everyone once more than half of the members have finished."
);
barrier_protocol!(
    FirstWins,
    "term.first-wins",
    &[],
    Mode::FirstWins,
    "The first member to see the goal ends the behavior for all; otherwise it ends when all are done."
);

fn late_reply(closed: &Closed, body: &Body) -> Option<Body> {
    match (closed, body) {
        // Whoever arrives at a barrier that is over may go on. A barrier
        // this robot left before it decided says nothing: the member learns
        // from the heartbeats that this robot left, and reports to the next
        // leader.
        // So does one that asks (its kernel heard this robot's heartbeat
        // past the barrier while it still waits).
        (Closed::Terminated(_), Body::Done | Body::Query) => Some(Body::Release { next: None }),
        // A release repeated to a robot that already ended the behavior:
        // confirm, so that its sender stops.
        (Closed::Terminated(_), Body::Release { .. }) => Some(Body::Ack),
        _ => None,
    }
}

struct Barrier {
    mode: Mode,
    /// Leader only: members that arrived.
    arrived: Option<MemberSet>,
    /// How many robots `arrived` holds (counted as they arrive, so that a
    /// leader of n members does not count n members at each of n arrivals).
    arrived_n: usize,
    me_done: bool,
    acked: bool,
    /// Resends so far (for the exponential backoff).
    resends: u32,
    /// After releasing members that had not arrived (the leader at a
    /// majority or its deadline, a first-wins member that saw the goal):
    /// those that have not acknowledged the release yet.
    stragglers: Vec<RobotId>,
    /// The leader this robot last reported to (to notice a new leader).
    reported_to: Option<RobotId>,
    /// This leader left with every member arrived, and released them.
    released_on_leave: bool,
    /// What the release names to run next (told to stragglers again).
    next: Option<BehaviorId>,
}

/// How many times a release is repeated to a member still working (it is
/// not waiting for anything, so nothing else will tell it).
const STRAGGLER_TRIES: u32 = 40;
/// The longest pause between two releases to a member still working, in
/// retry intervals: a short, steady interval, so that heavy loss delays the
/// news by seconds, not minutes.
const STRAGGLER_CAP: u32 = 4;

impl Barrier {
    fn new(mode: Mode) -> Self {
        Barrier {
            mode,
            arrived: None,
            arrived_n: 0,
            me_done: false,
            acked: false,
            resends: 0,
            stragglers: Vec::new(),
            reported_to: None,
            released_on_leave: false,
            next: None,
        }
    }

    fn arrived(&mut self, cx: &Cx<'_>) -> &mut MemberSet {
        self.arrived
            .get_or_insert_with(|| MemberSet::empty(cx.team().members.roster_len()))
    }

    /// `r` arrived (leader only).
    fn arrive(&mut self, cx: &Cx<'_>, r: RobotId) {
        if self.arrived(cx).insert(r) {
            self.arrived_n += 1;
        }
    }

    /// Member `from` reported that its part is over (leader only).
    fn arrival(&mut self, cx: &mut Cx<'_>, from: RobotId) {
        self.arrive(cx, from);
        // It is done here: whatever this robot still runs below
        // this behavior will not wait for it.
        cx.member_done(from);
        cx.send(from, Body::Ack);
        self.try_release(cx);
    }

    fn try_release(&mut self, cx: &mut Cx<'_>) {
        if cx.is_decided() || cx.is_aborted() {
            return;
        }
        let size = cx.team_size();
        // Fewer arrivals than live members: not all of them arrived, and
        // the count below can wait.
        if matches!(self.mode, Mode::All | Mode::FirstWins)
            && (!self.me_done || self.arrived_n < size)
        {
            return;
        }
        let arrived = self.arrived(cx).clone();
        // Members presumed lost are not waited for.
        let live_arrived = cx.members().filter(|m| arrived.contains(*m)).count();
        let release = match self.mode {
            Mode::All | Mode::FirstWins => self.me_done && live_arrived >= size,
            // A majority of the whole subteam: teammates presumed lost count
            // as not arrived, so a robot cut off from the others (or left
            // with too few survivors) is never a majority of one. It ends
            // the behavior at its deadline, reported as a timeout.
            // Teammates that left it by ending an ancestor are done with
            // it: they count as arrived.
            // Teammates given up (a deadline of this robot already decided
            // without them: crashed, most likely) are out of the whole.
            Mode::Majority => {
                let (mut whole, mut all_arrived) = (0, 0);
                for m in cx.team().members.iter() {
                    if cx.is_given_up(m) {
                        continue;
                    }
                    whole += 1;
                    if arrived.contains(m) || cx.has_left(m) {
                        all_arrived += 1;
                    }
                }
                all_arrived > whole / 2
            }
        };
        if release {
            self.release(cx, &arrived);
        }
    }

    /// Release everyone; tell those still working until they confirm.
    fn release(&mut self, cx: &mut Cx<'_>, arrived: &MemberSet) {
        self.announce(cx, arrived, None);
        cx.decide(Outcome::Terminate(None));
    }

    /// Tell every member the behavior ends (`next`: its replacement), and
    /// keep telling those that had not arrived (`arrived`) until they
    /// confirm: they are working, not waiting for anything.
    fn announce(&mut self, cx: &mut Cx<'_>, arrived: &MemberSet, next: Option<BehaviorId>) {
        cx.broadcast(Body::Release { next });
        self.next = next;
        let me = cx.me();
        self.stragglers = cx
            .members()
            .filter(|m| *m != me && !arrived.contains(*m))
            .collect();
        if !self.stragglers.is_empty() {
            self.resends = 0;
            cx.wake_after_retry();
        }
    }
}

impl Interaction for Barrier {
    fn start(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            self.arrived(cx);
        }
    }

    fn local_done(&mut self, cx: &mut Cx<'_>, why: LocalEnd) {
        self.me_done = true;
        if self.mode == Mode::FirstWins && why == LocalEnd::Condition {
            // This robot sees the goal: it ends the behavior for everyone.
            let nobody = MemberSet::empty(cx.team().members.roster_len());
            self.release(cx, &nobody);
            return;
        }
        if cx.is_leader() {
            let me = cx.me();
            self.arrive(cx, me);
            self.try_release(cx);
        } else {
            let leader = cx.leader();
            self.reported_to = Some(leader);
            cx.send(leader, Body::Done);
            cx.wake_after_retry();
        }
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        match body {
            // A member missed the release (it resends `Done`, or its kernel
            // asks, having heard this robot's heartbeat past the barrier):
            // it may go on (and, done, it needs no more telling). A leader
            // that left before everyone arrived stays silent: the member
            // will report to the next leader.
            Body::Done | Body::Query if cx.is_leader() && (cx.is_decided() || cx.is_aborted()) => {
                self.stragglers.retain(|r| *r != from);
                if cx.is_decided() || self.released_on_leave {
                    cx.send(from, Body::Release { next: None });
                }
            }
            Body::Done if cx.is_leader() => self.arrival(cx, from),
            Body::Ack if cx.is_decided() && self.stragglers.contains(&from) => {
                // A member released while working confirms.
                self.stragglers.retain(|r| *r != from);
            }
            Body::Ack if from == leader && !cx.is_leader() => {
                self.acked = true;
                // The leader is alive and knows we are here: keep waiting.
                cx.postpone_deadline();
            }
            // A member also takes one from a teammate that left the
            // behavior (left out, not presumed lost): it led the end in its
            // view and released the team, which went on with it; this robot
            // came to the point late and counts it out, so its leader here
            // is another (docs/reliability.md, "A release from a teammate
            // that left"). A leader adopts it below, and tells its members.
            Body::Release { next }
                if self.mode == Mode::FirstWins
                    || from == leader
                    || (!cx.is_leader() && cx.has_left(from)) =>
            {
                if self.mode == Mode::FirstWins || !self.me_done {
                    // Released while still working (first-wins, majority,
                    // the leader's deadline): confirm, or the releaser
                    // keeps telling us.
                    cx.send(from, Body::Ack);
                }
                cx.decide(Outcome::Terminate(*next));
            }
            Body::Release { next } if cx.is_leader() && !cx.is_decided() && !cx.is_aborted() => {
                // A member heard the release from the previous leader, now
                // lost: adopt it, so that all or none apply it.
                cx.broadcast(Body::Release { next: *next });
                cx.decide(Outcome::Terminate(*next));
            }
            _ if cx.is_aborted() || cx.is_decided() => {}
            // Leadership changing under a lost leader: see `crate::gather`.
            // So is a query from a member whose kernel heard the previous
            // leader past the barrier.
            Body::Done | Body::Ack | Body::Release { .. } | Body::Query => {}
            other => cx.violation(format!(
                "term barrier: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if cx.is_decided() && !self.stragglers.is_empty() {
            // Members released while still working are not waiting for
            // anything: tell them again until they confirm, at most
            // STRAGGLER_TRIES times; after that a straggler learns it when
            // it arrives, from the leader's late reply.
            for r in self.stragglers.clone() {
                cx.send(r, Body::Release { next: self.next });
            }
            self.resends += 1;
            if self.resends < STRAGGLER_TRIES {
                let t = cx.now() + cx.retry() * (1u32 << self.resends.min(2)).min(STRAGGLER_CAP);
                cx.wake_at(t);
            } else {
                self.stragglers.clear();
            }
            return;
        }
        if cx.is_decided() || cx.is_aborted() || cx.is_leader() || !self.me_done {
            return;
        }
        // Until acknowledged, resend with exponential backoff. Once the
        // leader knows we are here we only guard against a lost release,
        // asking again after 4, 8, 16... intervals.
        if self.acked && self.resends == 0 {
            self.resends = 2;
        } else {
            cx.send(cx.leader(), Body::Done);
            self.resends += 1;
        }
        let t = cx.now() + backoff(cx, self.resends);
        cx.wake_at(t);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            // Release everyone, stragglers included, and make sure the
            // stragglers hear it (they are working, not waiting).
            let arrived = self.arrived(cx).clone();
            self.release(cx, &arrived);
        }
        cx.decide(Outcome::Terminate(None));
    }

    /// Its heartbeats show `from` waiting here, and its `Done` has not
    /// arrived (lost: under heavy loss a member backs off and may not be
    /// heard before the deadline): it arrived.
    fn on_member_waiting(&mut self, cx: &mut Cx<'_>, from: RobotId) {
        if !cx.is_leader() || cx.is_decided() || cx.is_aborted() {
            return;
        }
        if self.arrived(cx).contains(from) {
            return;
        }
        self.arrival(cx, from);
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        let leader = cx.leader();
        if cx.is_leader() {
            // Leading now (or still): count who is left.
            if self.me_done {
                let me = cx.me();
                self.arrive(cx, me);
            }
            self.try_release(cx);
        } else if self.reported_to.is_some_and(|r| r != leader)
            || (self.me_done && self.reported_to.is_none())
        {
            // A new leader: tell it what it needs.
            self.reported_to = Some(leader);
            if cx.is_decided() {
                cx.send(leader, Body::Release { next: None });
            } else if self.me_done {
                self.acked = false;
                self.resends = 0;
                cx.send(leader, Body::Done);
                cx.wake_after_retry();
            }
        }
    }

    /// The team ended the behavior while this robot was presumed lost
    /// (a teammate's notice, `Body::Missed`). A leader whose members are
    /// still working tells them, as at its deadline: they are not waiting
    /// for anything, and the releases of the leader that decided without
    /// this robot are not from the leader they follow. A side that had
    /// not arrived stayed in the behavior for good while the rest of the
    /// team went on (docs/reliability.md, "A release no member heard").
    fn on_team_decision(&mut self, cx: &mut Cx<'_>, outcome: &Outcome) {
        let Outcome::Terminate(next) = outcome else {
            return;
        };
        if !cx.is_leader() {
            return;
        }
        let arrived = self.arrived(cx).clone();
        let me = cx.me();
        if cx.members().any(|m| m != me && !arrived.contains(m)) {
            self.announce(cx, &arrived, *next);
        }
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            // This leader leaves (an ancestor ended here): it is done with
            // the behavior. If everyone else has arrived, the barrier is
            // complete: release them. Otherwise the members still working
            // are waited for by the next leader — the members learn from
            // this robot's heartbeats that it left, leave it out, and report
            // to the next lowest member.
            self.me_done = true;
            let me = cx.me();
            self.arrive(cx, me);
            let arrived = self.arrived(cx).clone();
            if cx.members().all(|m| arrived.contains(m)) {
                self.released_on_leave = true;
                for r in arrived.iter().filter(|r| *r != me) {
                    cx.send(r, Body::Release { next: None });
                }
            }
        } else if !self.me_done {
            // This member leaves the behavior: it will not arrive later, so
            // count it as arrived.
            self.me_done = true;
            cx.send(cx.leader(), Body::Done);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A barrier that is over answers a late arrival, and a member's
    /// kernel asking because it heard the leader past it, with its
    /// release; one this robot left says nothing.
    #[test]
    fn a_closed_barrier_releases_whoever_arrives_or_asks() {
        let over = Closed::Terminated(None);
        let release = Some(Body::Release { next: None });
        assert_eq!(late_reply(&over, &Body::Done), release);
        assert_eq!(late_reply(&over, &Body::Query), release);
        assert_eq!(late_reply(&Closed::Left, &Body::Query), None);
        assert_eq!(late_reply(&Closed::Left, &Body::Done), None);
    }
}
