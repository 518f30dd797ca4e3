//! Synchronization protocols: choose the next behavior of the execution
//! chain together (the paper's SF4, SF5, SF7, SF8, SF9).
//!
//! - `sync.vote` (SF8, Figure 1-c S1): the leader announces the candidates
//!   (all sequential successors), every member votes for its preferred
//!   successor among those enabled for it (highest `utility`, then graph
//!   order) or abstains if none is, the leader tallies — plurality, ties to
//!   the earlier successor in graph order, the chain ends if everyone
//!   abstains — and announces the winner. n + 1 messages, 3 rounds.
//! - `sync.ranked-vote` (SF9): the same, with ranked ballots (each member
//!   ranks the successors enabled for it, best first) counted by Borda: with
//!   m successors a ballot gives m − 1 points to its first choice, m − 2 to
//!   its second…; unranked successors get nothing. Most points wins, ties to
//!   graph order; only successors someone ranked can win. n + 1 messages.
//! - `sync.leader` (SF4): the leader decides alone and informs the members.
//!   Parameter `choose`: `round-robin` (default: the k-th execution of the
//!   point behavior picks successor k, counting round the list, skipping
//!   successors not enabled for the leader — the paper's "decision based on
//!   the number of times this behavior is executed"), `first` (first enabled
//!   successor), `preferred` (the leader's preference by `utility`) or
//!   `random` (seeded). One multicast: 1 message, 1 round.
//! - `sync.elected-leader` (SF5): the members elect a leader at random —
//!   each draws a random ballot from its seeded generator and sends it with
//!   its preferred successor; the coordinator elects the highest ballot
//!   (ties to the lower id) and announces the elected leader's choice. The
//!   choice travels with the ballot, which saves the round in which the
//!   elected leader would announce it. n messages, 2 rounds.
//! - `sync.round-robin` (SF7): silent; every member picks, as `sync.leader`
//!   with `round-robin` does, successor k at the k-th execution. 0 messages.
//!
//! All communicating ones share the gather-decide-announce machinery of
//! [`crate::gather`] (retries, deadlines, lost leaders); a member cut off
//! from its leader at the deadline follows its own preference (or, for the
//! leader rules, applies the leader's rule itself).

use crate::gather::Rule;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{
    Cx, Factory, Interaction, Outcome, Params, PointInput, Protocol, Setup, parse_params,
};
use bite_core::msg::{Body, Kind};
use rand::RngExt;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::sync::Arc;

pub(crate) use bite_core::interaction::no_params;

pub(crate) fn successors(cx: &Cx<'_>) -> Vec<BehaviorId> {
    match cx.input() {
        PointInput::Sync { successors, .. } => successors.to_vec(),
        _ => Vec::new(),
    }
}

/// Successor `epoch` counting round the list from the first (epochs start
/// at 1); if it is not enabled, the next enabled one round the list.
pub(crate) fn rotation(cx: &Cx<'_>) -> Option<BehaviorId> {
    let all = successors(cx);
    if all.is_empty() {
        return None;
    }
    let start = (cx.key().epoch.saturating_sub(1) as usize) % all.len();
    (0..all.len())
        .map(|i| all[(start + i) % all.len()])
        .find(|b| cx.candidates().contains(b))
}

pub(crate) fn check_choice(cx: &Cx<'_>, choice: Option<BehaviorId>) -> Result<(), String> {
    match choice {
        Some(c) if !successors(cx).contains(&c) => {
            Err(format!("chose `b{}`, not a successor", c.0))
        }
        _ => Ok(()),
    }
}

fn propose(cx: &Cx<'_>) -> Option<Body> {
    Some(Body::Propose {
        candidates: successors(cx),
    })
}

/// `Ok` if `ranking` names successors of the point, each once.
pub(crate) fn check_ranking(cx: &Cx<'_>, ranking: &[BehaviorId]) -> Result<(), String> {
    for (i, c) in ranking.iter().enumerate() {
        check_choice(cx, Some(*c))?;
        if ranking[..i].contains(c) {
            return Err(format!("ranked `b{}` twice", c.0));
        }
    }
    Ok(())
}

pub(crate) fn own_choice(cx: &mut Cx<'_>) -> Outcome {
    let all = successors(cx);
    Outcome::Sync(cx.preferred(&all))
}

/// The plurality winner among `successors` and its number of votes: the
/// successor with the most votes, ties broken by graph order; `None` when
/// nobody voted for any (abstentions and votes for non-successors count
/// for nothing). `sync.vote` and the graph-defined votes count with it.
pub(crate) fn plurality(
    successors: &[BehaviorId],
    votes: impl Iterator<Item = Option<BehaviorId>>,
) -> Option<(BehaviorId, usize)> {
    let mut counts: BTreeMap<BehaviorId, usize> = BTreeMap::new();
    for c in votes.flatten() {
        *counts.entry(c).or_insert(0) += 1;
    }
    let mut best: Option<(BehaviorId, usize)> = None;
    for c in successors {
        if let Some(n) = counts.get(c).copied()
            && best.is_none_or(|(_, m)| n > m)
        {
            best = Some((*c, n));
        }
    }
    best
}

/// The Borda winner among `successors` (m − 1 points for a first choice,
/// m − 2 for a second…; ties broken by graph order), `None` when no ballot
/// ranks any.
pub(crate) fn borda<'a>(
    successors: &[BehaviorId],
    ballots: impl Iterator<Item = &'a [BehaviorId]>,
) -> Option<BehaviorId> {
    let m = successors.len() as u64;
    let mut points: BTreeMap<BehaviorId, u64> = BTreeMap::new();
    for ranking in ballots {
        for (i, c) in ranking.iter().enumerate() {
            *points.entry(*c).or_insert(0) += m.saturating_sub(1 + i as u64);
        }
    }
    // Graph order breaks ties: the first successor with the most points.
    let mut best: Option<(u64, BehaviorId)> = None;
    for c in successors {
        if let Some(p) = points.get(c).copied()
            && best.is_none_or(|(q, _)| p > q)
        {
            best = Some((p, *c));
        }
    }
    best.map(|(_, c)| c)
}

/// Generate the [`Protocol`] impl of a gather-based protocol.
macro_rules! gather_protocol {
    ($ty:ident, $name:literal, $aliases:expr, $kind:expr, $summary:literal,
     |$params:ident, $setup:ident| $make:expr) => {
        #[doc = $summary]
        #[derive(Debug, Clone, Copy, Default)]
        pub struct $ty;
        impl bite_core::interaction::Protocol for $ty {
            fn name(&self) -> &'static str {
                $name
            }
            fn aliases(&self) -> &'static [&'static str] {
                $aliases
            }
            fn kind(&self) -> bite_core::msg::Kind {
                $kind
            }
            fn communicates(&self) -> bool {
                true
            }
            fn summary(&self) -> &'static str {
                $summary
            }
            #[allow(unused_variables)]
            fn configure(
                &self,
                $params: &bite_core::interaction::Params,
                $setup: &mut bite_core::interaction::Setup<'_>,
            ) -> Result<bite_core::interaction::Factory, bite_core::interaction::ConfigError> {
                let rule = std::sync::Arc::new($make?);
                Ok(std::sync::Arc::new(move || {
                    Box::new($crate::gather::Gather::new(rule.clone()))
                        as Box<dyn bite_core::interaction::Interaction>
                }))
            }
            fn late_reply(
                &self,
                closed: &bite_core::interaction::Closed,
                body: &bite_core::msg::Body,
            ) -> Option<bite_core::msg::Body> {
                $crate::gather::late_reply(closed, body)
            }
        }
    };
}
pub(crate) use gather_protocol;

// ----- sync.vote ----------------------------------------------------------

gather_protocol!(
    Vote,
    "sync.vote",
    &["SF8"],
    Kind::Sync,
    "SF8: the leader calls a vote among the successors, tallies (plurality, ties by graph order) and announces.",
    |params, setup| no_params("sync.vote", params).map(|()| Plurality)
);

pub(crate) struct Plurality;

impl Rule for Plurality {
    fn name(&self) -> &'static str {
        "sync.vote"
    }
    fn call(&self, cx: &Cx<'_>) -> Option<Body> {
        propose(cx)
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        let all = successors(cx);
        Body::Vote {
            choice: cx.preferred(&all),
        }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Vote { .. })
    }
    fn check(&self, cx: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        match body {
            Body::Vote { choice } => check_choice(cx, *choice),
            _ => Err("sent something else than a vote".into()),
        }
    }
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        let votes = got.values().map(|v| match v {
            Body::Vote { choice } => *choice,
            _ => None,
        });
        Outcome::Sync(plurality(&successors(cx), votes).map(|(c, _)| c))
    }
    fn alone(&self, cx: &mut Cx<'_>) -> Outcome {
        own_choice(cx)
    }
    fn abstain(&self) -> Option<Body> {
        Some(Body::Vote { choice: None })
    }
}

// ----- sync.ranked-vote ---------------------------------------------------

gather_protocol!(
    RankedVote,
    "sync.ranked-vote",
    &["SF9"],
    Kind::Sync,
    "SF9: ranked ballots counted by Borda (m-1 points for a first choice...), ties by graph order.",
    |params, setup| no_params("sync.ranked-vote", params).map(|()| Borda)
);

pub(crate) struct Borda;

impl Rule for Borda {
    fn name(&self) -> &'static str {
        "sync.ranked-vote"
    }
    fn call(&self, cx: &Cx<'_>) -> Option<Body> {
        propose(cx)
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        let all = successors(cx);
        Body::Ballot {
            ranking: cx.ranking(&all),
        }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Ballot { .. })
    }
    fn check(&self, cx: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        let Body::Ballot { ranking } = body else {
            return Err("sent something else than a ballot".into());
        };
        check_ranking(cx, ranking)
    }
    fn decide(&self, cx: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        let ballots = got.values().filter_map(|b| match b {
            Body::Ballot { ranking } => Some(ranking.as_slice()),
            _ => None,
        });
        Outcome::Sync(borda(&successors(cx), ballots))
    }
    fn alone(&self, cx: &mut Cx<'_>) -> Outcome {
        own_choice(cx)
    }
    fn abstain(&self) -> Option<Body> {
        Some(Body::Ballot {
            ranking: Vec::new(),
        })
    }
}

// ----- sync.leader --------------------------------------------------------

/// How `sync.leader`'s leader chooses.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum Choose {
    /// The k-th execution picks successor k (round the list).
    #[default]
    RoundRobin,
    /// The first enabled successor.
    First,
    /// The leader's preference by utility.
    Preferred,
    /// A seeded random enabled successor.
    Random,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct LeaderParams {
    #[serde(default)]
    choose: Choose,
}

gather_protocol!(
    Leader,
    "sync.leader",
    &["SF4"],
    Kind::Sync,
    "SF4: the leader decides (by default by the execution count) and informs the members.",
    |params, setup| parse_params::<LeaderParams>("sync.leader", params)
        .map(|p| LeaderDecides(p.choose))
);

pub(crate) struct LeaderDecides(Choose);

impl LeaderDecides {
    fn choose(&self, cx: &mut Cx<'_>) -> Outcome {
        let all = successors(cx);
        Outcome::Sync(match self.0 {
            Choose::RoundRobin => rotation(cx),
            Choose::First => cx.candidates().first().copied(),
            Choose::Preferred => cx.preferred(&all),
            Choose::Random => {
                let c = cx.candidates().to_vec();
                if c.is_empty() {
                    None
                } else {
                    let i = cx.rng().random_range(0..c.len());
                    Some(c[i])
                }
            }
        })
    }
}

impl Rule for LeaderDecides {
    fn name(&self) -> &'static str {
        "sync.leader"
    }
    fn gathers(&self) -> bool {
        false
    }
    fn contribution(&self, _: &mut Cx<'_>) -> Body {
        Body::Query
    }
    fn is_contribution(&self, _: &Body) -> bool {
        false
    }
    fn check(&self, _: &Cx<'_>, _: RobotId, _: &Body) -> Result<(), String> {
        Err("contributed to a leader's decision".into())
    }
    fn decide(&self, cx: &mut Cx<'_>, _: &BTreeMap<RobotId, Body>) -> Outcome {
        self.choose(cx)
    }
    fn alone(&self, cx: &mut Cx<'_>) -> Outcome {
        // Apply the leader's rule oneself (the same result for the
        // deterministic rules when the candidates agree).
        self.choose(cx)
    }
}

// ----- sync.elected-leader ------------------------------------------------

gather_protocol!(
    ElectedLeader,
    "sync.elected-leader",
    &["SF5"],
    Kind::Sync,
    "SF5: members draw random ballots; the highest is elected leader and its choice applies.",
    |params, setup| no_params("sync.elected-leader", params).map(|()| Election)
);

pub(crate) struct Election;

impl Rule for Election {
    fn name(&self) -> &'static str {
        "sync.elected-leader"
    }
    fn contribution(&self, cx: &mut Cx<'_>) -> Body {
        let all = successors(cx);
        let about = cx.preferred(&all);
        // 2^53 ballots: ties are practically impossible, and broken by id.
        let value = (cx.rng().random::<u64>() >> 11) as f64;
        Body::Value { about, value }
    }
    fn is_contribution(&self, body: &Body) -> bool {
        matches!(body, Body::Value { .. })
    }
    fn check(&self, cx: &Cx<'_>, _: RobotId, body: &Body) -> Result<(), String> {
        match body {
            Body::Value { about, value } if value.is_finite() => check_choice(cx, *about),
            Body::Value { .. } => Err("sent a ballot that is not a number".into()),
            _ => Err("sent something else than a ballot".into()),
        }
    }
    fn decide(&self, _: &mut Cx<'_>, got: &BTreeMap<RobotId, Body>) -> Outcome {
        // The map iterates in id order: `>` keeps the lower id on a tie.
        let mut elected: Option<(f64, Option<BehaviorId>)> = None;
        for b in got.values() {
            if let Body::Value { about, value } = b
                && elected.is_none_or(|(v, _)| *value > v)
            {
                elected = Some((*value, *about));
            }
        }
        Outcome::Sync(elected.and_then(|(_, c)| c))
    }
    fn alone(&self, cx: &mut Cx<'_>) -> Outcome {
        own_choice(cx)
    }
}

// ----- sync.round-robin ---------------------------------------------------

/// SF7: every member picks successor k at the k-th execution of the point
/// behavior (round the list, skipping successors not enabled for it).
#[derive(Debug, Clone, Copy, Default)]
pub struct RoundRobin;

impl Protocol for RoundRobin {
    fn name(&self) -> &'static str {
        "sync.round-robin"
    }
    fn aliases(&self) -> &'static [&'static str] {
        &["SF7"]
    }
    fn kind(&self) -> Kind {
        Kind::Sync
    }
    fn communicates(&self) -> bool {
        false
    }
    fn summary(&self) -> &'static str {
        "SF7: every member picks the next successor in turn by the execution count; no messages."
    }
    fn configure(
        &self,
        params: &Params,
        _: &mut Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        no_params(self.name(), params)?;
        Ok(Arc::new(|| Box::new(Turn) as Box<dyn Interaction>))
    }
}

struct Turn;

impl Interaction for Turn {
    fn start(&mut self, cx: &mut Cx<'_>) {
        cx.decide(Outcome::Sync(rotation(cx)));
    }
    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        cx.violation(format!(
            "sync.round-robin sends no messages, but {from} sent `{}`",
            body.name()
        ));
    }
    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        cx.decide(Outcome::Sync(rotation(cx)));
    }
}
