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
use bite_core::interaction::{Cx, Factory, Interaction, Outcome, Params, Protocol};
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
}

#[derive(Default)]
struct Barrier {
    /// Leader only: members that arrived.
    arrived: Option<MemberSet>,
    me_done: bool,
    acked: bool,
    /// Queries sent since the leader acknowledged (for backoff).
    queries: u32,
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
        if self.arrived(cx).len() >= size {
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

    fn local_done(&mut self, cx: &mut Cx<'_>) {
        self.me_done = true;
        if cx.is_leader() {
            let me = cx.me();
            self.arrived(cx).insert(me);
            self.try_release(cx);
        } else {
            cx.send(cx.leader(), Body::Done);
            cx.wake_after_retry();
        }
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        match body {
            Body::Done if cx.is_leader() => {
                if cx.is_decided() {
                    // A member missed the release: tell it again.
                    cx.send(from, Body::Release { next: None });
                    return;
                }
                self.arrived(cx).insert(from);
                cx.send(from, Body::Ack);
                self.try_release(cx);
            }
            Body::Ack if from == leader => self.acked = true,
            Body::Release { next } if from == leader => {
                cx.decide(Outcome::Terminate(*next));
            }
            other => cx.violation(format!(
                "term.wait-all: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if cx.is_decided() || cx.is_leader() || !self.me_done {
            return;
        }
        // Until acknowledged, resend at the binding's interval. Once the
        // leader knows we are here we only guard against a lost release:
        // ask again after 4, 8, 16… intervals.
        if !self.acked {
            cx.send(cx.leader(), Body::Done);
            cx.wake_after_retry();
            return;
        }
        if self.queries > 0 {
            cx.send(cx.leader(), Body::Done);
        }
        self.queries = self.queries.saturating_add(1);
        let t = cx.now() + cx.retry() * 2u32.saturating_pow(self.queries.min(10) + 1);
        cx.wake_at(t);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            cx.broadcast(Body::Release { next: None });
        }
        cx.decide(Outcome::Terminate(None));
    }
}
