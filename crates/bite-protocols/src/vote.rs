//! `sync.vote` — the paper's SF8 and Figure 1-c S1: the leader announces the
//! candidates, every member votes, the leader tallies and announces the
//! winner.
//!
//! Candidates are all sequential successors of the point behavior. Each
//! member votes for its preferred successor among those enabled for it
//! (highest `utility`, then graph order), or abstains if none is enabled.
//! The winner has the most votes; ties go to the earlier successor in graph
//! order; if everyone abstains the execution chain ends. Members resend
//! their vote (or ask for the call with `Query`) every retry interval until
//! the result arrives; the leader answers late votes and queries with the
//! result. At its deadline the leader tallies the votes it has.
//!
//! Messages, no faults: one call, n−1 votes, one result: n + 1. Rounds: 3.

use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol};
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
}

#[derive(Default)]
struct Ballot {
    /// The candidates of the call (members learn them from `Propose`).
    proposal: Option<Vec<BehaviorId>>,
    /// Leader only: votes received, including its own.
    votes: BTreeMap<RobotId, Option<BehaviorId>>,
    /// The result, once known (answers retransmissions).
    result: Option<Option<BehaviorId>>,
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
        if self.result.is_none() && self.votes.len() >= cx.team_size() {
            self.finish(cx);
        }
    }
}

impl Interaction for Ballot {
    fn start(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() {
            let proposal = successors(cx);
            let mine = cx.preferred(&proposal);
            self.votes.insert(cx.me(), mine);
            cx.broadcast(Body::Propose {
                candidates: proposal.clone(),
            });
            self.proposal = Some(proposal);
            self.maybe_tally(cx);
        }
        cx.wake_after_retry();
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        match body {
            Body::Propose { candidates } if from == leader && !cx.is_leader() => {
                if let Some(choice) = self.result {
                    // Already decided: the call is a retransmission.
                    let _ = choice;
                    return;
                }
                let choice = cx.preferred(candidates);
                self.proposal = Some(candidates.clone());
                cx.send(leader, Body::Vote { choice });
            }
            Body::Vote { choice } if cx.is_leader() => {
                if let Some(result) = self.result {
                    cx.send(from, Body::Decision { choice: result });
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
                (None, Some(p)) => cx.send(
                    from,
                    Body::Propose {
                        candidates: p.clone(),
                    },
                ),
                (None, None) => {}
            },
            Body::Decision { choice } if from == leader => {
                self.result = Some(*choice);
                cx.decide(Outcome::Sync(*choice));
            }
            other => cx.violation(format!(
                "sync.vote: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if self.result.is_some() || cx.is_decided() {
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
            match &self.proposal {
                None => cx.send(leader, Body::Query),
                Some(p) => {
                    let choice = cx.preferred(p);
                    cx.send(leader, Body::Vote { choice });
                }
            }
        }
        cx.wake_after_retry();
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
}
