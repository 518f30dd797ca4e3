//! `alloc.token` — token passing in the style of Farinelli, Scerri et al.
//! (LA-DCOP), for large teams: no member ever hears from all the others.
//!
//! The leader makes one token per place (the children's places, minimums
//! first as everywhere) and deals token k to the k-th live member. A member
//! holding a token keeps it if it has no place yet and its `utility` for
//! the token's child reaches the token's threshold (parameter `threshold`,
//! default 0; a child without `utility` is worth 0); it then claims the
//! place from the leader. Otherwise it passes the token on to the next live
//! member in id order. A token that has gone round the whole team once is
//! kept by the first member without a place, whatever its utility, so
//! every token settles within two laps. When every place is claimed the
//! leader multicasts the assignment.
//!
//! Messages, no faults, P places, n members: P tokens dealt, H passes, P
//! claims, one assignment: 2P + H + 1 (tokens and claims to or from the
//! leader itself are free). H is 0 when every member takes the first token
//! it is dealt (no utilities, or utilities above the threshold) and at most
//! 2n per token; rounds: 3 + the longest chain of passes. The leader deals
//! unclaimed places again on its timer (a token lost on the way, or still
//! travelling); a place claimed twice goes to the first claim, and the
//! second claimant, which takes no more tokens once it has claimed, is
//! given another unclaimed place (of the same child if there is one), as
//! is a member that claims a place the leader never made (a token of an
//! earlier leader's deal, passed on by a teammate). A member waiting for
//! the assignment asks for it with exponential backoff, and one without a
//! place is dealt its places again when it asks. When a member is
//! presumed lost, its place (claimed or not) is dealt again as a token; a
//! member that becomes leader because the leader was lost deals all places
//! anew, and a token from a teammate a member has left out (its deal
//! numbered the places of another team) is dropped. At its deadline the
//! leader deals the unclaimed places by id among the members without one.

use crate::alloc::settle;
use crate::gather::{self, Coord};
use bite_core::ids::RobotId;
use bite_core::interaction::{
    ChildSlot, Closed, Cx, Factory, Interaction, Outcome, Params, Protocol, Setup, parse_params,
};
use bite_core::msg::{Body, Kind};
use bite_core::rules::member_counts;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The protocol (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct TokenPassing;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct TokenParams {
    #[serde(default)]
    threshold: f64,
}

impl Protocol for TokenPassing {
    fn name(&self) -> &'static str {
        "alloc.token"
    }
    fn kind(&self) -> Kind {
        Kind::Allocate
    }
    fn communicates(&self) -> bool {
        true
    }
    fn summary(&self) -> &'static str {
        "Token passing (Farinelli et al.): one token per place travels until a member with enough utility keeps it."
    }
    fn configure(
        &self,
        params: &Params,
        _: &mut Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        let p: TokenParams = parse_params(self.name(), params)?;
        if !p.threshold.is_finite() {
            return Err(bite_core::interaction::ConfigError::Invalid(
                "`threshold` must be a number".into(),
            ));
        }
        let threshold = p.threshold;
        Ok(Arc::new(move || {
            Box::new(Tokens {
                threshold,
                ..Tokens::default()
            }) as Box<dyn Interaction>
        }))
    }
    fn late_reply(&self, closed: &Closed, body: &Body) -> Option<Body> {
        gather::late_reply(closed, body)
    }
}

#[derive(Default)]
struct Tokens {
    threshold: f64,
    // Leader.
    leading: bool,
    children: Vec<ChildSlot>,
    /// Child index of each place (slot).
    slots: Vec<usize>,
    /// Claimed slots: slot → member.
    claims: BTreeMap<u32, RobotId>,
    // Member.
    /// The slot this robot claimed.
    mine: Option<u32>,
    // Both.
    coord: Coord,
}

impl Tokens {
    fn lead(&mut self, cx: &mut Cx<'_>) {
        self.leading = true;
        self.children = cx.children().to_vec();
        let counts = member_counts(cx.team_size(), &self.children);
        self.slots = counts
            .iter()
            .enumerate()
            .flat_map(|(i, n)| std::iter::repeat_n(i, *n as usize))
            .collect();
        self.claims.clear();
        self.deal(cx);
    }

    /// Deal every unclaimed slot's token, slot k to the k-th live member.
    fn deal(&mut self, cx: &mut Cx<'_>) {
        self.deal_to(cx, None);
    }

    /// Deal the unclaimed slots' tokens, slot k to the k-th live member;
    /// only those of member `only` when given.
    fn deal_to(&mut self, cx: &mut Cx<'_>, only: Option<RobotId>) {
        let members: Vec<RobotId> = cx.members().collect();
        if members.is_empty() {
            return;
        }
        for k in 0..self.slots.len() {
            let to = members[k % members.len()];
            if self.claims.contains_key(&(k as u32)) || only.is_some_and(|r| r != to) {
                continue;
            }
            let token = self.token(k);
            if to == cx.me() {
                self.hold(cx, &token);
            } else {
                cx.send(to, token);
            }
        }
        self.maybe_finish(cx);
    }

    /// A member without a place asks how the allocation stands: it was not
    /// at the point yet when its tokens were dealt (it dropped them), and
    /// the leader's next deal may be a whole backoff away (up to 64
    /// retries). It is dealt its places again now, or, when every place
    /// dealt to it is claimed, the first unclaimed one (a duplicate token
    /// is harmless: the first claim wins). As `alloc.auction` sends its
    /// call again to a member that asks (docs/reliability.md, "A member
    /// that reached the token's point late").
    fn deal_to_asker(&mut self, cx: &mut Cx<'_>, from: RobotId) {
        if !self.leading
            || cx.is_aborted()
            || !cx.is_live(from)
            || self.claims.values().any(|r| *r == from)
        {
            return;
        }
        let members: Vec<RobotId> = cx.members().collect();
        let Some(at) = members.iter().position(|r| *r == from) else {
            return;
        };
        let unclaimed = |k: &usize| !self.claims.contains_key(&(*k as u32));
        let mine = (0..self.slots.len()).any(|k| unclaimed(&k) && k % members.len() == at);
        if mine {
            self.deal_to(cx, Some(from));
        } else if let Some(k) = (0..self.slots.len()).find(unclaimed) {
            cx.send(from, self.token(k));
        }
    }

    /// Slot `k`'s token as the leader deals it.
    fn token(&self, k: usize) -> Body {
        Body::Token {
            slot: k as u32,
            item: self.children[self.slots[k]].behavior,
            hops: 0,
            threshold: self.threshold,
        }
    }

    /// This robot holds a token: keep it, or pass it on.
    fn hold(&mut self, cx: &mut Cx<'_>, token: &Body) {
        let Body::Token {
            slot,
            item,
            hops,
            threshold,
        } = token
        else {
            return;
        };
        if self.mine == Some(*slot) {
            // Our claim was lost and the leader dealt the slot again.
            self.claim(cx, *slot);
            return;
        }
        let n = cx.team_size() as u32;
        let utility = cx.utility(*item).unwrap_or(0.0);
        let keep = self.mine.is_none()
            && self.coord.result.is_none()
            && (utility >= *threshold || *hops >= n.saturating_sub(1));
        if keep {
            self.mine = Some(*slot);
            self.claim(cx, *slot);
            return;
        }
        if *hops >= 2 * n {
            return; // Gone round twice: the leader deals it again later.
        }
        let members: Vec<RobotId> = cx.members().collect();
        let me = cx.me();
        let next = members
            .iter()
            .copied()
            .find(|m| *m > me)
            .or_else(|| members.first().copied());
        let passed = Body::Token {
            slot: *slot,
            item: *item,
            hops: hops + 1,
            threshold: *threshold,
        };
        match next {
            Some(to) if to != me => cx.send(to, passed),
            // Alone: nobody to pass to.
            _ => {}
        }
    }

    fn claim(&mut self, cx: &mut Cx<'_>, slot: u32) {
        if cx.is_leader() {
            self.record(cx, cx.me(), slot);
        } else {
            cx.send(cx.leader(), Body::Claim { slot });
        }
    }

    fn record(&mut self, cx: &mut Cx<'_>, from: RobotId, slot: u32) {
        // One place per member; the first claim of a place wins it. The
        // member that lost the race takes no more tokens (it holds a
        // place, as far as it knows), so it is given another unclaimed
        // place, of the same child if there is one: left without, it held
        // the allocation up until the deadline (docs/reliability.md, "A
        // place claimed twice"). So is a member that claims a place this
        // leader never made: a token of another leader's deal (numbered
        // for the team that leader saw), passed on to it by a live
        // teammate before the leadership changed; it took no more tokens
        // either (docs/reliability.md, "A token of an earlier deal").
        if !self.claims.values().any(|r| *r == from) {
            let free = |s: &u32| !self.claims.contains_key(s);
            let all = 0..self.slots.len() as u32;
            let place = match self.slots.get(slot as usize) {
                Some(&child) => Some(slot).filter(free).or_else(|| {
                    (all.clone().filter(free))
                        .find(|s| self.slots[*s as usize] == child)
                        .or_else(|| all.clone().find(free))
                }),
                None => all.clone().find(free),
            };
            if let Some(s) = place {
                self.claims.insert(s, from);
                self.coord.progress(cx);
            }
        }
        self.maybe_finish(cx);
    }

    /// Finish once every place is claimed, or every live member holds one:
    /// a member left out since the places were made (presumed lost, or
    /// done with the behavior) leaves more places than members, and the
    /// places over stay empty whoever the tokens reach (they went round
    /// until the deadline: docs/reliability.md, "An allocation left
    /// undecided").
    fn maybe_finish(&mut self, cx: &mut Cx<'_>) {
        if self.coord.result.is_some() || cx.is_aborted() {
            return;
        }
        let placed = cx
            .members()
            .filter(|r| self.claims.values().any(|c| c == r))
            .count();
        if self.claims.len() >= self.slots.len() || (placed > 0 && placed >= cx.team_size()) {
            self.finish(cx);
        }
    }

    /// Announce the claims, with unclaimed places dealt by id among the
    /// members without one.
    fn finish(&mut self, cx: &mut Cx<'_>) {
        let awards: Vec<(RobotId, usize)> = self
            .claims
            .iter()
            .map(|(s, r)| (*r, self.slots[*s as usize]))
            .collect();
        let o = Outcome::Allocate(settle(cx, &self.children, awards).into());
        self.coord.adopt(cx, o, true);
    }
}

impl Interaction for Tokens {
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
        match body {
            Body::Token { item, .. } => {
                if self.coord.idle(cx) {
                    return;
                }
                if !cx.is_live(from) {
                    // Dealt or passed by a teammate this robot has left
                    // out (presumed lost, or done with the behavior): its
                    // places were numbered for another team than the one
                    // the leader deals to now, and a claim of one would
                    // name a place the leader never made.
                    return;
                }
                if !cx.is_leader() {
                    // The allocation is alive (the leader counts only
                    // claims as progress, or tokens nobody can take would
                    // keep it from its deadline).
                    self.coord.progress(cx);
                }
                if !cx.children().iter().any(|c| c.behavior == *item) {
                    cx.violation(format!(
                        "alloc.token: {from} passed a token for a non-child"
                    ));
                    return;
                }
                self.hold(cx, body);
            }
            Body::Claim { slot } if cx.is_leader() && self.leading => {
                if !self.coord.answer(cx, from) && !cx.is_aborted() {
                    self.record(cx, from, *slot);
                }
            }
            Body::Query if cx.is_leader() => {
                if !self.coord.answer(cx, from) {
                    self.deal_to_asker(cx, from);
                }
            }
            _ if self.coord.on_announcement(cx, from, body) => {}
            Body::Claim { .. } | Body::Query => {}
            _ if cx.is_aborted() => {}
            other => cx.violation(format!(
                "alloc.token: unexpected `{}` from {from}",
                other.name()
            )),
        }
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        if self.coord.idle(cx) || !self.coord.quiet(cx) {
            return;
        }
        if cx.is_leader() && self.leading {
            // Tokens lost on the way (or still travelling: a duplicate is
            // harmless, the first claim wins).
            self.deal(cx);
        } else if !cx.is_leader() {
            if let Some(slot) = self.mine {
                cx.send(cx.leader(), Body::Claim { slot });
            } else {
                cx.send(cx.leader(), Body::Query);
            }
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
                // Took over from a lost leader: deal every place again
                // (members forget their claims to the old leader).
                self.mine = None;
                self.lead(cx);
            } else {
                // A lost member's place is free again: dealt by id at the
                // end if nobody claims it.
                let lost: Vec<u32> = self
                    .claims
                    .iter()
                    .filter(|(_, r)| !cx.is_live(**r))
                    .map(|(s, _)| *s)
                    .collect();
                for s in lost {
                    self.claims.remove(&s);
                }
                if !self.slots.is_empty() {
                    self.deal(cx);
                }
            }
        } else if changed {
            // The new leader deals the places again: claims made to the
            // old one are void.
            self.mine = None;
        }
    }

    fn on_team_decision(&mut self, _cx: &mut Cx<'_>, outcome: &Outcome) {
        self.coord.team_decided(outcome);
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        if cx.is_leader()
            && self.leading
            && self.coord.result.is_none()
            && !self.coord.after_departed()
        {
            self.finish(cx);
        }
    }
}
