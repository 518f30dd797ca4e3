//! `sync.vote` — the paper's SF8 and Figure 1-c S1: the leader announces the
//! candidates, every member votes, the leader tallies and announces the
//! winner.
//!
//! Candidates are all sequential successors of the point behavior. Each
//! member votes for its preferred successor among those enabled for it
//! (highest `utility`, then graph order), or abstains if none is enabled.
//! The winner has the most votes; ties go to the earlier successor in graph
//! order; if everyone abstains the execution chain ends. A member without
//! the result asks for it (`Query`) with exponential backoff; the leader
//! answers with the result, or calls a member again whose vote it has not
//! received, and calls missing voters again on its own timer. At its
//! deadline the leader tallies the votes it has. A leader that leaves early
//! announces the tally so far; a member that leaves before voting abstains.
//!
//! Messages, no faults, members reaching the point together: one call, n−1
//! votes, one result: n + 1. Rounds: 3. Members that arrive late cost one
//! query each per backoff period they wait (0.5, 1, 2… s by default).

use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{
    Closed, Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol,
};
use bite_core::msg::{Body, Kind};
use std::collections::BTreeMap;
use std::sync::Arc;

/// The protocol (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct Vote;

pub(crate) fn no_params(name: &str, params: &Params) -> Result<(), String> {
    match params {
        Params::Null => Ok(()),
        Params::Object(m) if m.is_empty() => Ok(()),
        _ => Err(format!("`{name}` takes no parameters")),
    }
}

impl Protocol for Vote {
    fn name(&self) -> &'static str {
        "sync.vote"
    }
    fn aliases(&self) -> &'static [&'static str] {
        &["SF8"]
    }
    fn kind(&self) -> Kind {
        Kind::Sync
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "SF8: the leader calls a vote among the successors, tallies (plurality, ties by graph order) and announces."
    }
    fn configure(&self, params: &Params) -> Result<Factory, String> {
        no_params(self.name(), params)?;
        Ok(Arc::new(|| {
            Box::new(Ballot::default()) as Box<dyn Interaction>
        }))
    }
    fn late_reply(&self, closed: Closed, body: &Body) -> Option<Body> {
        // A late vote or question gets the result this robot applied.
        match (closed, body) {
            (Closed::Synced(choice), Body::Vote { .. } | Body::Query) => {
                Some(Body::Decision { choice })
            }
            _ => None,
        }
    }
}

#[derive(Default)]
struct Ballot {
    /// The candidates of the call (members learn them from `Propose`).
    proposal: Option<Vec<BehaviorId>>,
    /// Leader only: votes received, including its own.
    votes: BTreeMap<RobotId, Option<BehaviorId>>,
    /// Member only: the vote it sent.
    voted: Option<Option<BehaviorId>>,
    /// The result, once known (answers retransmissions).
    result: Option<Option<BehaviorId>>,
    /// Timer firings so far (for the exponential backoff).
    resends: u32,
    /// The leader this robot last dealt with (to notice a new leader).
    known_leader: Option<RobotId>,
}

fn successors(cx: &Cx<'_>) -> Vec<BehaviorId> {
    match cx.input() {
        PointInput::Sync { successors, .. } => successors.clone(),
        _ => Vec::new(),
    }
}

impl Ballot {
    fn tally(&self) -> Option<BehaviorId> {
        let proposal = self.proposal.as_deref().unwrap_or(&[]);
        let mut best: Option<(usize, BehaviorId)> = None;
        for c in proposal {
            let n = self.votes.values().filter(|v| **v == Some(*c)).count();
            if n > 0 && best.is_none_or(|(m, _)| n > m) {
                best = Some((n, *c));
            }
        }
        best.map(|(_, c)| c)
    }

    fn finish(&mut self, cx: &mut Cx<'_>) {
        let choice = self.tally();
        self.result = Some(choice);
        cx.broadcast(Body::Decision { choice });
        cx.decide(Outcome::Sync(choice));
    }

    fn maybe_tally(&mut self, cx: &mut Cx<'_>) {
        // Votes of members presumed lost since are not waited for.
        let live_votes = cx.members().filter(|m| self.votes.contains_key(m)).count();
        if self.result.is_none() && live_votes >= cx.team_size() {
            self.finish(cx);
        }
    }

    fn vote(&mut self, cx: &mut Cx<'_>, candidates: &[BehaviorId]) {
        let choice = cx.preferred(candidates);
        self.voted = Some(choice);
        cx.send(cx.leader(), Body::Vote { choice });
    }

    /// Lead the vote: call it, with this robot's own vote.
    fn call(&mut self, cx: &mut Cx<'_>) {
        let proposal = successors(cx);
        let mine = cx.preferred(&proposal);
        self.votes.insert(cx.me(), mine);
        cx.broadcast(Body::Propose {
            candidates: proposal.clone(),
        });
        self.proposal = Some(proposal);
        self.maybe_tally(cx);
    }
}

impl Interaction for Ballot {
    fn start(&mut self, cx: &mut Cx<'_>) {
        self.known_leader = Some(cx.leader());
        if cx.is_leader() {
            self.call(cx);
        }
        cx.wake_after_retry();
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        match body {
            Body::Propose { candidates } if from == leader && !cx.is_leader() => {
                if self.result.is_some() || cx.is_aborted() {
                    return;
                }
                // A first call, or the leader calling again because our
                // vote was lost: (re)send it.
                self.proposal = Some(candidates.clone());
                self.vote(cx, candidates);
            }
            Body::Vote { choice } if cx.is_leader() => {
                if let Some(result) = self.result {
                    cx.send(from, Body::Decision { choice: result });
                    return;
                }
                if cx.is_aborted() {
                    return;
                }
                let proposal = self.proposal.as_deref().unwrap_or(&[]);
                if choice.is_some_and(|c| !proposal.contains(&c)) {
                    cx.violation(format!("sync.vote: {from} voted for a non-candidate"));
                    return;
                }
                self.votes.insert(from, *choice);
                self.maybe_tally(cx);
            }
            Body::Query if cx.is_leader() => match (self.result, &self.proposal) {
                (Some(choice), _) => cx.send(from, Body::Decision { choice }),
                // Not voted yet (the call was lost): call it again.
                (None, Some(p)) if !self.votes.contains_key(&from) && !cx.is_aborted() => cx.send(
                    from,
                    Body::Propose {
                        candidates: p.clone(),
                    },
                ),
                _ => {}
            },
            Body::Decision { choice } if cx.is_leader() && self.result.is_none() => {
                // A member heard the result from the previous leader, now
                // lost: adopt it, so that all or none apply it.
                self.result = Some(*choice);
                cx.broadcast(Body::Decision { choice: *choice });
                cx.decide(Outcome::Sync(*choice));
            }
            Body::Decision { choice } if from == leader => {
                self.result = Some(*choice);
                cx.decide(Outcome::Sync(*choice));
            }
            // Leadership changing under a lost leader: a message can reach a
            // robot that does not know yet that it leads, or no longer does.
            // The sender's retries recover it.
            Body::Vote { .. } | Body::Query | Body::Propose { .. } | Body::Decision { .. } => {}
            _ if cx.is_aborted() => {}
            other => cx.violation(format!(
                "sync.vote: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if self.result.is_some() || cx.is_decided() || cx.is_aborted() {
            return;
        }
        let leader = cx.leader();
        if cx.is_leader() {
            // Call again those who have not voted.
            let missing: Vec<RobotId> = cx
                .members()
                .filter(|m| !self.votes.contains_key(m))
                .collect();
            let candidates = self.proposal.clone().unwrap_or_default();
            for m in missing {
                cx.send(
                    m,
                    Body::Propose {
                        candidates: candidates.clone(),
                    },
                );
            }
        } else {
            // No result yet: ask (the leader calls again if our vote was
            // lost, or answers with the result if it was the result that was).
            cx.send(leader, Body::Query);
        }
        self.resends += 1;
        let t = cx.now() + cx.retry() * 2u32.pow(self.resends.min(6));
        cx.wake_at(t);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            if self.result.is_none() {
                self.finish(cx);
            }
        } else {
            // Cut off from the leader: follow our own preference (the kernel
            // reports the timeout).
            let choice = cx.preferred(&successors(cx));
            cx.decide(Outcome::Sync(choice));
        }
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        let leader = cx.leader();
        let changed = self.known_leader != Some(leader);
        self.known_leader = Some(leader);
        if cx.is_leader() {
            if self.result.is_some() || cx.is_aborted() {
                return;
            }
            if changed && self.proposal.is_none() {
                // Took over from a lost leader: call the vote again.
                self.call(cx);
            } else {
                self.maybe_tally(cx);
            }
        } else if changed {
            match (self.result, self.voted) {
                // Tell the new leader the result we already applied.
                (Some(choice), _) => cx.send(leader, Body::Decision { choice }),
                // Or our vote again.
                (None, Some(choice)) => cx.send(leader, Body::Vote { choice }),
                (None, None) => {}
            }
        }
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            // Leaving: let the others go on with the votes cast so far.
            if self.result.is_none() {
                let choice = self.tally();
                self.result = Some(choice);
                cx.broadcast(Body::Decision { choice });
            }
        } else if self.voted.is_none() {
            // Leaving before voting: abstain, so the leader need not wait.
            self.voted = Some(None);
            cx.send(cx.leader(), Body::Vote { choice: None });
        }
    }
}
