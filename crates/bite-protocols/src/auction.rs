//! `alloc.auction` — the market of the paper's Figure 1-c S2, as in
//! TraderBot and MURDOCH: sequential single-item auctions run by the team
//! leader.
//!
//! The items are the children's places (how many members each child gets:
//! minimums first, then shared, as every allocation here). Each round the
//! leader calls for bids on the children that still have places, naming
//! the previous round's winner; every member without a place bids on the
//! child it values most — its `utility` for the child, read from its
//! beliefs when it first bids (0 without one; a cost is a negative
//! utility; the valuation holds for the whole auction) — and the leader
//! awards one place to the highest bid (ties to the lower id, then the
//! earlier child). Rounds go on until every place is awarded or nobody is
//! left; the leader then multicasts the assignment.
//!
//! This is the global greedy assignment, within a factor 2 of the optimal
//! total utility for non-negative utilities (Gerkey & Matarić 2004;
//! `alloc.optimal` reaches the optimum, and the tests check both bounds).
//! Without utilities every bid ties and the auction deals the places by
//! id, as `alloc.by-id` does.
//!
//! Messages, no faults, n members and P ≤ n places: P calls, one bid per
//! member without a place per round (the leader's own bid is free), one
//! assignment: at most P + P(n − 1) + 1, O(n·m); rounds: 2P + 1. A bid
//! lost is called for again on the leader's timer; a member waiting for
//! the assignment asks for it with exponential backoff. A member presumed
//! lost is not waited for and its place goes back on sale; a new leader
//! starts the auction again. At the deadline the leader keeps the awards
//! made and deals the places left by id.

use crate::alloc::{settle, utilities};
use crate::gather::{self, Coord};
use crate::sync::no_params;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{
    ChildSlot, Closed, Cx, Factory, Interaction, Outcome, Params, Protocol, Setup,
};
use bite_core::msg::{Body, Kind};
use bite_core::rules::member_counts;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The protocol (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct Auction;

impl Protocol for Auction {
    fn name(&self) -> &'static str {
        "alloc.auction"
    }
    fn aliases(&self) -> &'static [&'static str] {
        &["S2"]
    }
    fn kind(&self) -> Kind {
        Kind::Allocate
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "S2: sequential single-item auctions: the leader calls, members bid their utility, the best bid wins a place."
    }
    fn configure(
        &self,
        params: &Params,
        _: &mut Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        no_params(self.name(), params)?;
        Ok(Arc::new(|| {
            Box::new(Market::default()) as Box<dyn Interaction>
        }))
    }
    fn late_reply(&self, closed: &Closed, body: &Body) -> Option<Body> {
        gather::late_reply(closed, body)
    }
}

#[derive(Default)]
struct Market {
    // Leader.
    /// The leader's children (what is for sale).
    children: Vec<ChildSlot>,
    /// Child → its index in `children`.
    index: BTreeMap<BehaviorId, usize>,
    /// Places left per child.
    places: Vec<u32>,
    /// Members without a place (live, leader's view).
    awarded: BTreeMap<RobotId, usize>,
    /// Bids of the current round: member → (child index, value).
    bids: BTreeMap<RobotId, (usize, f64)>,
    /// Members without a place when the round was called (or the team
    /// last changed): no award is looked for before this many bids.
    free_count: usize,
    round: u32,
    /// Awards in the order they were made.
    order: Vec<(RobotId, usize)>,
    last_winner: Option<RobotId>,
    leading: bool,
    // Member.
    /// The last call heard.
    call: Option<(Vec<BehaviorId>, u32)>,
    won: bool,
    /// This robot's utility per child, valued when it first bids (a
    /// member's valuation holds for the whole auction, as in TraderBot).
    /// Indexed by behavior id (dense); NaN for a child it cannot take.
    values: Option<Vec<f64>>,
    // Both.
    coord: Coord,
    /// Highest round number seen (a new leader starts above it).
    seen_round: u32,
}

impl Market {
    fn items(&self) -> Vec<BehaviorId> {
        self.children
            .iter()
            .zip(&self.places)
            .filter(|(_, p)| **p > 0)
            .map(|(c, _)| c.behavior)
            .collect()
    }

    fn free(&self, cx: &Cx<'_>) -> Vec<RobotId> {
        cx.members()
            .filter(|m| !self.awarded.contains_key(m))
            .collect()
    }

    /// This robot's best bid among `items`: highest utility, ties to the
    /// earlier item.
    fn best(
        values: &mut Option<Vec<f64>>,
        cx: &Cx<'_>,
        items: &[BehaviorId],
    ) -> Option<(BehaviorId, f64)> {
        let mine = values.get_or_insert_with(|| {
            let u = utilities(cx);
            let len = u.iter().map(|(b, _)| b.index() + 1).max().unwrap_or(0);
            let mut v = vec![f64::NAN; len];
            for (b, x) in u {
                v[b.index()] = x;
            }
            v
        });
        let mut best: Option<(BehaviorId, f64)> = None;
        for it in items {
            // A child not enabled for this robot: the lowest possible bid.
            let u = mine
                .get(it.index())
                .copied()
                .filter(|x| !x.is_nan())
                .unwrap_or(f64::MIN);
            if best.is_none_or(|(_, b)| u > b) {
                best = Some((*it, u));
            }
        }
        best
    }

    /// Start (or, as a new leader, restart) the auction.
    fn lead(&mut self, cx: &mut Cx<'_>) {
        self.leading = true;
        self.children = cx.children().to_vec();
        self.index = (self.children.iter().enumerate())
            .map(|(i, c)| (c.behavior, i))
            .collect();
        let n = cx.team_size();
        self.places = member_counts(n, &self.children);
        self.awarded.clear();
        self.order.clear();
        self.last_winner = None;
        self.round = self.seen_round;
        self.next_round(cx);
    }

    fn next_round(&mut self, cx: &mut Cx<'_>) {
        let items = self.items();
        if items.is_empty() || self.free(cx).is_empty() {
            return self.finish(cx);
        }
        self.round += 1;
        self.seen_round = self.round;
        self.bids.clear();
        self.free_count = self.free(cx).len();
        cx.broadcast(Body::Call {
            items: items.clone(),
            round: self.round,
            winner: self.last_winner,
        });
        if !self.awarded.contains_key(&cx.me())
            && let Some((item, value)) = Self::best(&mut self.values, cx, &items)
            && let Some(i) = self.index_of(item)
        {
            self.bids.insert(cx.me(), (i, value));
        }
        self.maybe_award(cx);
    }

    fn call_body(&self) -> Body {
        Body::Call {
            items: self.items(),
            round: self.round,
            winner: self.last_winner,
        }
    }

    fn index_of(&self, item: BehaviorId) -> Option<usize> {
        self.index.get(&item).copied()
    }

    fn maybe_award(&mut self, cx: &mut Cx<'_>) {
        if self.coord.result.is_some() || cx.is_aborted() {
            return;
        }
        if self.bids.len() < self.free_count {
            return; // bids still to come (checked in O(1) per bid)
        }
        let free = self.free(cx);
        if !free.iter().all(|m| self.bids.contains_key(m)) {
            return;
        }
        // Highest bid; the map iterates in id order, so `>` keeps the lower
        // id on a tie, and each member bid its earliest best child.
        let mut best: Option<(RobotId, usize, f64)> = None;
        for m in &free {
            if let Some((i, v)) = self.bids.get(m).copied()
                && best.is_none_or(|(_, _, b)| v > b)
            {
                best = Some((*m, i, v));
            }
        }
        match best {
            Some((winner, i, _)) => {
                self.awarded.insert(winner, i);
                self.order.push((winner, i));
                self.places[i] -= 1;
                self.last_winner = Some(winner);
                self.coord.progress(cx);
                self.next_round(cx);
            }
            None => self.finish(cx),
        }
    }

    /// Announce the assignment: the awards, and (at a deadline, or after
    /// members were lost) the places left dealt by id to the members left.
    fn finish(&mut self, cx: &mut Cx<'_>) {
        let awards: Vec<(RobotId, usize)> = self.order.clone();
        let o = Outcome::Allocate(settle(cx, &self.children, awards).into());
        self.coord.adopt(cx, o, true);
    }

    fn bid(&mut self, cx: &mut Cx<'_>) {
        if self.won || self.coord.idle(cx) {
            return;
        }
        if let Some((items, round)) = &self.call
            && let Some((item, value)) = Self::best(&mut self.values, cx, items)
        {
            let round = *round;
            cx.send(cx.leader(), Body::Bid { item, value, round });
        }
    }
}

impl Interaction for Market {
    fn start(&mut self, cx: &mut Cx<'_>) {
        self.coord.start(cx);
        if cx.is_leader() {
            self.lead(cx);
        }
        if !cx.is_decided() {
            cx.wake_after_retry();
        }
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let leader = cx.leader();
        match body {
            Body::Call {
                items,
                round,
                winner,
            } if from == leader && !cx.is_leader() => {
                self.seen_round = self.seen_round.max(*round);
                self.coord.progress(cx);
                if *winner == Some(cx.me()) {
                    self.won = true;
                }
                if self.call.as_ref().is_none_or(|(_, r)| *round >= *r) {
                    self.call = Some((items.clone(), *round));
                    self.bid(cx);
                }
            }
            Body::Bid { item, value, round } if cx.is_leader() && self.leading => {
                if self.coord.answer(cx, from) {
                    return;
                }
                if *round != self.round || self.awarded.contains_key(&from) || cx.is_aborted() {
                    return; // stale, or from a member that already won
                }
                let Some(i) = self.index_of(*item).filter(|i| self.places[*i] > 0) else {
                    cx.violation(format!("alloc.auction: {from} bid on an item not for sale"));
                    return;
                };
                if !value.is_finite() && *value != f64::MIN {
                    cx.violation(format!("alloc.auction: {from} bid a non-number"));
                    return;
                }
                self.bids.insert(from, (i, *value));
                self.maybe_award(cx);
            }
            Body::Query if cx.is_leader() => {
                if !self.coord.answer(cx, from)
                    && self.leading
                    && !self.awarded.contains_key(&from)
                    && !self.bids.contains_key(&from)
                {
                    let call = self.call_body();
                    cx.send(from, call);
                }
            }
            _ if self.coord.on_announcement(cx, from, body) => {}
            // Leadership changing, stale rounds: the retries recover.
            Body::Call { .. } | Body::Bid { .. } | Body::Query => {}
            _ if cx.is_aborted() => {}
            other => cx.violation(format!(
                "alloc.auction: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if self.coord.idle(cx) || !self.coord.quiet(cx) {
            return;
        }
        if cx.is_leader() {
            // Call again the members whose bid this round has not come.
            let missing: Vec<RobotId> = self
                .free(cx)
                .into_iter()
                .filter(|m| !self.bids.contains_key(m))
                .collect();
            let call = self.call_body();
            for m in missing {
                cx.send(m, call.clone());
            }
        } else {
            cx.send(cx.leader(), Body::Query);
        }
        self.coord.next_resend(cx);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if self.coord.deadline_passed(cx, self.leading) {
            self.finish(cx);
        }
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        let Some(changed) = self.coord.members_changed(cx) else {
            return;
        };
        if cx.is_leader() {
            if changed || !self.leading {
                // Took over: run the auction again among the survivors.
                self.lead(cx);
            } else {
                // A member was lost: its place goes back on sale, and its
                // bid is no longer waited for.
                let lost: Vec<RobotId> = self
                    .awarded
                    .keys()
                    .copied()
                    .filter(|r| !cx.is_live(*r))
                    .collect();
                for r in lost {
                    if let Some(i) = self.awarded.remove(&r) {
                        self.places[i] += 1;
                        self.order.retain(|(w, _)| *w != r);
                    }
                }
                self.free_count = self.free(cx).len();
                self.maybe_award(cx);
            }
        } else if changed {
            // A new auction under a new leader.
            self.won = false;
            self.call = None;
        }
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader() && self.leading && self.coord.result.is_none() {
            // Leaving: the others go on with the awards made and the rest
            // dealt by id (this robot's own decision is ignored: it left).
            self.finish(cx);
        }
    }
}
