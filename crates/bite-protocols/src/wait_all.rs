//! `term.wait-all` — the paper's S3 synchronized termination: a robot that
//! has finished its part waits until every member of the subteam has
//! finished too, then all go on together.
//!
//! The leader (lowest-id member) keeps the barrier. A member that finishes
//! sends `Done` to the leader, which acknowledges it; once the leader itself
//! has finished and every member has arrived, it multicasts `Release`. A
//! member resends `Done` every retry interval until acknowledged, then every
//! 4, 8, 16… intervals until released (a lost `Release` is recovered because
//! the leader answers a late `Done` with `Release`). At its deadline the leader
//! releases whoever has arrived; a member whose deadline passes goes on
//! alone (the kernel reports the timeout).
//!
//! Messages, no faults: `Done` and `Ack` from each of the n−1 members and
//! one `Release`: 2n − 1, plus, for a member that waits long for a slower
//! leader, one more `Done`/`Ack` pair per backoff period (logarithmic in the
//! wait). Rounds: 2 after the last arrival.

use bite_core::ids::RobotId;
use bite_core::interaction::{
    Closed, Cx, Factory, Interaction, LocalEnd, Outcome, Params, Protocol,
};
use bite_core::msg::{Body, Kind};
use bite_core::org::MemberSet;
use std::sync::Arc;
use std::time::Duration;

/// The protocol (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct WaitAll;

impl Protocol for WaitAll {
    fn name(&self) -> &'static str {
        "term.wait-all"
    }
    fn aliases(&self) -> &'static [&'static str] {
        &["S3"]
    }
    fn kind(&self) -> Kind {
        Kind::Terminate
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "S3: the leader holds a barrier; everyone goes on when every member has finished."
    }
    fn default_deadline(&self) -> Duration {
        Duration::from_secs(30)
    }
    fn configure(&self, params: &Params) -> Result<Factory, String> {
        crate::vote::no_params(self.name(), params)?;
        Ok(Arc::new(|| {
            Box::new(Barrier::default()) as Box<dyn Interaction>
        }))
    }
    fn late_reply(&self, closed: Closed, body: &Body) -> Option<Body> {
        // Whoever arrives at a barrier that is over (released, or left by
        // this robot) may go on.
        match (closed, body) {
            (Closed::Terminated(_) | Closed::Left, Body::Done) => {
                Some(Body::Release { next: None })
            }
            _ => None,
        }
    }
}

#[derive(Default)]
struct Barrier {
    /// Leader only: members that arrived.
    arrived: Option<MemberSet>,
    me_done: bool,
    acked: bool,
    /// Resends so far (for the exponential backoff).
    resends: u32,
    /// Leader only, after a release at the deadline: members that had not
    /// arrived and have not acknowledged the release yet.
    stragglers: Vec<RobotId>,
    /// The leader this robot last reported to (to notice a new leader).
    reported_to: Option<RobotId>,
}

/// How many times a leader repeats a deadline release to a straggler.
const STRAGGLER_TRIES: u32 = 8;

/// Wait before the next resend: the retry interval, doubling each time
/// (capped at 64 intervals).
fn backoff(cx: &Cx<'_>, resends: u32) -> std::time::Duration {
    cx.retry() * 2u32.pow(resends.min(6))
}

impl Barrier {
    fn arrived(&mut self, cx: &Cx<'_>) -> &mut MemberSet {
        self.arrived
            .get_or_insert_with(|| MemberSet::empty(cx.team().members.roster_len()))
    }

    fn try_release(&mut self, cx: &mut Cx<'_>) {
        if cx.is_decided() || !self.me_done {
            return;
        }
        let size = cx.team_size();
        let arrived = self.arrived(cx).clone();
        // Members presumed lost are not waited for.
        let live_arrived = cx.members().filter(|m| arrived.contains(*m)).count();
        if live_arrived >= size {
            cx.broadcast(Body::Release { next: None });
            cx.decide(Outcome::Terminate(None));
        }
    }
}

impl Interaction for Barrier {
    fn start(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            self.arrived(cx);
        }
    }

    fn local_done(&mut self, cx: &mut Cx<'_>, _why: LocalEnd) {
        self.me_done = true;
        if cx.is_leader() {
            let me = cx.me();
            self.arrived(cx).insert(me);
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
            Body::Done if cx.is_leader() => {
                if cx.is_decided() || cx.is_aborted() {
                    // A member missed the release, or this leader has left
                    // the behavior: it may go on.
                    cx.send(from, Body::Release { next: None });
                    return;
                }
                self.arrived(cx).insert(from);
                // It is done here: whatever this robot still runs below
                // this behavior will not wait for it.
                cx.member_done(from);
                cx.send(from, Body::Ack);
                self.try_release(cx);
            }
            Body::Ack if cx.is_leader() => {
                // A straggler confirms the release.
                self.stragglers.retain(|r| *r != from);
            }
            Body::Ack if from == leader => {
                self.acked = true;
                // The leader is alive and knows we are here: keep waiting.
                cx.postpone_deadline();
            }
            Body::Release { next } if cx.is_leader() && !cx.is_decided() => {
                // A member heard the release from the previous leader, now
                // lost: adopt it, so that all or none apply it.
                cx.broadcast(Body::Release { next: *next });
                cx.decide(Outcome::Terminate(*next));
            }
            Body::Release { next } if from == leader => {
                if !self.me_done {
                    // Released while still working (the leader's deadline):
                    // confirm, or the leader keeps telling us.
                    cx.send(leader, Body::Ack);
                }
                cx.decide(Outcome::Terminate(*next));
            }
            _ if cx.is_aborted() || cx.is_decided() => {}
            // Leadership changing under a lost leader: see sync.vote.
            Body::Done | Body::Ack | Body::Release { .. } => {}
            other => cx.violation(format!(
                "term.wait-all: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() && cx.is_decided() && !self.stragglers.is_empty() {
            // Members released at the deadline while still working are not
            // waiting for anything: tell them again until they confirm.
            // At most STRAGGLER_TRIES times; after that a straggler learns
            // it when it arrives, from this robot's late reply.
            for r in self.stragglers.clone() {
                cx.send(r, Body::Release { next: None });
            }
            self.resends += 1;
            if self.resends < STRAGGLER_TRIES {
                let t = cx.now() + backoff(cx, self.resends);
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
            cx.broadcast(Body::Release { next: None });
            let arrived = self.arrived(cx).clone();
            self.stragglers = cx.members().filter(|m| !arrived.contains(*m)).collect();
            if !self.stragglers.is_empty() {
                self.resends = 0;
                cx.wake_after_retry();
            }
        }
        cx.decide(Outcome::Terminate(None));
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        let leader = cx.leader();
        if cx.is_leader() {
            // Leading now (or still): count who is left.
            if self.me_done {
                let me = cx.me();
                self.arrived(cx).insert(me);
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

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            // Whoever already arrived waits only for this leader: release them.
            let waiting: Vec<RobotId> = self
                .arrived
                .as_ref()
                .map(|a| a.iter().filter(|r| *r != cx.me()).collect())
                .unwrap_or_default();
            for r in waiting {
                cx.send(r, Body::Release { next: None });
            }
        } else if !self.me_done {
            // This member leaves the behavior: it will not arrive later, so
            // count it as arrived.
            self.me_done = true;
            cx.send(cx.leader(), Body::Done);
        }
    }
}
