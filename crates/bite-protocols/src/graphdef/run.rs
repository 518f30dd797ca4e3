//! The interpreter: one instance of a graph protocol on one robot.
//!
//! The robot stands on one behavior of the protocol graph at a time. On
//! every input (start, message, timer, members changed, deadline, the
//! robot's own end of a team behavior) the interpreter updates what has
//! been received and then *advances*: while the current behavior's `until`
//! holds (or it has none), it moves to the first successor whose `pre`
//! holds, running that behavior's skills as it starts. A behavior whose
//! `until` does not hold yet, or whose successors are all disabled, waits
//! for the next input; one without successors ends the robot's chain (it
//! waits for the decision). At most [`MAX_STEPS`] behaviors per input.

use super::{
    Codec, FIXED_VARS, LEADER, MEMBER, Payload, Program, Rule, Skill, Source, To, VAR_DONE,
    VAR_GOAL, VAR_LEADER, VAR_LIVE, VAR_TEAM, VAR_TOOK_OVER, nested_body, unnest,
};
use crate::gather::Coord;
use bite_core::cond::{Env, Expr};
use bite_core::ids::{BehaviorId, BeliefId, RobotId};
use bite_core::interaction::{Cx, Effects, Interaction, LocalEnd, Outcome, Recipients};
use bite_core::msg::Body;
use bite_core::rules;
use bite_core::time::Time;
use bite_core::value::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// Most behaviors entered on one input.
const MAX_STEPS: usize = 64;
/// Most messages of a nested instance kept before it starts.
const MAX_EARLY: usize = 64;

/// A nested protocol instance (a `use` skill).
struct Sub {
    slot: u16,
    inst: Box<dyn Interaction>,
    decided: bool,
}

/// One instance of a graph protocol.
pub(crate) struct GraphRun {
    p: Arc<Program>,
    /// The behavior this robot stands on (`None`: its chain ended).
    at: Option<usize>,
    entered: Time,
    runs: Vec<u32>,
    /// Per message: what each teammate (and, kept, this robot) sent last.
    heard: Vec<BTreeMap<RobotId, Payload>>,
    /// Leader: the members it has heard anything from.
    heard_any: BTreeSet<RobotId>,
    /// Messages sent to the leader, resent until the decision is heard.
    to_leader: Vec<(usize, Payload)>,
    /// The last message sent to the team (repeated to those not heard from).
    broadcast: Option<(usize, Payload)>,
    coord: Coord,
    done: bool,
    goal: bool,
    took_over: bool,
    sub: Option<Sub>,
    early: Vec<(RobotId, u16, Body)>,
}

struct Vars<'a> {
    vals: &'a [Option<Value>],
    elapsed: f64,
    runs: u32,
}

impl Env for Vars<'_> {
    fn belief(&self, id: BeliefId) -> Option<&Value> {
        self.vals.get(id.index())?.as_ref()
    }
    fn belief_age(&self, _: BeliefId) -> Option<f64> {
        None
    }
    fn elapsed(&self) -> f64 {
        self.elapsed
    }
    fn runs(&self, _: Option<BehaviorId>) -> u32 {
        self.runs
    }
}

impl GraphRun {
    pub(crate) fn new(p: Arc<Program>) -> Self {
        let n = p.def.messages.len();
        let b = p.def.behaviors.len();
        let codec = p.codec.clone();
        GraphRun {
            p,
            at: None,
            entered: Time::ZERO,
            runs: vec![0; b],
            heard: vec![BTreeMap::new(); n],
            heard_any: BTreeSet::new(),
            to_leader: Vec::new(),
            broadcast: None,
            coord: Coord::with_codec(codec),
            done: false,
            goal: false,
            took_over: false,
            sub: None,
            early: Vec::new(),
        }
    }

    fn role(cx: &Cx<'_>) -> usize {
        if cx.is_leader() { LEADER } else { MEMBER }
    }

    /// The values of the protocol's variables now.
    fn values(&self, cx: &Cx<'_>) -> Vec<Option<Value>> {
        let mut v = vec![None; FIXED_VARS + 3 * self.heard.len()];
        let live = cx.team_size();
        v[VAR_LIVE] = Some(Value::Num(live as f64));
        v[VAR_TEAM] = Some(Value::Num(cx.team().size as f64));
        v[VAR_LEADER] = Some(Value::Bool(cx.is_leader()));
        v[VAR_TOOK_OVER] = Some(Value::Bool(self.took_over));
        v[VAR_DONE] = Some(Value::Bool(self.done));
        v[VAR_GOAL] = Some(Value::Bool(self.goal));
        for (i, h) in self.heard.iter().enumerate() {
            let heard = cx.members().filter(|m| h.contains_key(m)).count();
            let mut counts: BTreeMap<BehaviorId, usize> = BTreeMap::new();
            for p in h.values() {
                if let Payload::Choice(Some(c)) = p {
                    *counts.entry(*c).or_insert(0) += 1;
                }
            }
            let top = counts.values().copied().max().unwrap_or(0);
            v[FIXED_VARS + 3 * i] = Some(Value::Num(heard as f64));
            v[FIXED_VARS + 3 * i + 1] = Some(Value::Num(live.saturating_sub(heard) as f64));
            v[FIXED_VARS + 3 * i + 2] = Some(Value::Num(top as f64));
        }
        v
    }

    fn holds(&self, cx: &Cx<'_>, vals: &[Option<Value>], e: &Expr, b: usize, since: Time) -> bool {
        e.eval(&Vars {
            vals,
            elapsed: cx.now().saturating_since(since).as_secs_f64(),
            runs: self.runs[b],
        })
    }

    fn finished(&self, cx: &Cx<'_>) -> bool {
        cx.is_decided() || cx.is_aborted()
    }

    /// Move along the graph as far as conditions allow.
    fn advance(&mut self, cx: &mut Cx<'_>) {
        for _ in 0..MAX_STEPS {
            if self.finished(cx) {
                return;
            }
            let Some(b) = self.at else { return };
            let def = &self.p.def.behaviors[b];
            if self.sub.as_ref().is_some_and(|s| !s.decided)
                && def.skills.iter().any(|s| matches!(s, Skill::Use { .. }))
            {
                return; // the nested instance decides
            }
            let vals = self.values(cx);
            if let Some(u) = &def.until
                && !self.holds(cx, &vals, u, b, self.entered)
            {
                return;
            }
            if def.next.is_empty() {
                self.at = None;
                return;
            }
            let next = def.next.iter().copied().find(|n| {
                self.p.def.behaviors[*n]
                    .pre
                    .as_ref()
                    .is_none_or(|p| self.holds(cx, &vals, p, *n, cx.now()))
            });
            match next {
                Some(n) => self.enter(cx, n),
                None => return, // wait until a successor is enabled
            }
        }
    }

    /// Start behavior `b`: run its skills in order.
    fn enter(&mut self, cx: &mut Cx<'_>, b: usize) {
        self.at = Some(b);
        self.entered = cx.now();
        self.runs[b] = self.runs[b].saturating_add(1);
        let p = self.p.clone();
        for sk in &p.def.behaviors[b].skills {
            if cx.is_decided() {
                return;
            }
            match sk {
                Skill::Send { msg, to, value } => {
                    let payload = self.payload(cx, *msg, value);
                    self.send(cx, *msg, *to, payload);
                }
                Skill::Keep { msg, value } => {
                    let payload = self.payload(cx, *msg, value);
                    self.heard[*msg].entry(cx.me()).or_insert(payload);
                }
                Skill::Decide(rule) => {
                    let o = self.decide(cx, *rule);
                    self.adopt(cx, o);
                }
                Skill::Use { slot } => self.start_sub(cx, *slot),
            }
        }
    }

    fn payload(&self, cx: &mut Cx<'_>, msg: usize, src: &Source) -> Payload {
        use super::Carries;
        let carries = self.p.def.messages[msg].carries;
        match src {
            Source::Nothing => match carries {
                Carries::Choice => Payload::Choice(None),
                Carries::Ranking => Payload::Ranking(Vec::new()),
                _ => Payload::Nothing,
            },
            Source::Preferred => {
                let all = crate::sync::successors(cx);
                Payload::Choice(cx.preferred(&all))
            }
            Source::First => Payload::Choice(cx.candidates().first().copied()),
            Source::Ranking => {
                let all = crate::sync::successors(cx);
                Payload::Ranking(cx.ranking(&all))
            }
            Source::Decision => match &self.coord.result {
                Some(o) => Codec::payload(o),
                None => Payload::Pick(None),
            },
            Source::Expr(i) => Payload::Number(
                cx.eval(&self.p.exprs[*i])
                    .and_then(|v| v.as_num())
                    .filter(|x| x.is_finite())
                    .unwrap_or(f64::NAN),
            ),
        }
    }

    fn send(&mut self, cx: &mut Cx<'_>, msg: usize, to: To, payload: Payload) {
        let body = self.p.def.message_body(msg, &payload);
        match to {
            To::Leader => {
                if cx.is_leader() {
                    // The leader's own contribution counts as received.
                    self.heard[msg].insert(cx.me(), payload);
                    return;
                }
                cx.send(cx.leader(), body);
                self.to_leader.retain(|(m, _)| *m != msg);
                self.to_leader.push((msg, payload));
            }
            To::Team => {
                cx.broadcast(body);
                self.broadcast = Some((msg, payload));
            }
            To::Missing(of) => {
                let me = cx.me();
                let missing: Vec<RobotId> = cx
                    .members()
                    .filter(|m| *m != me && !self.heard[of].contains_key(m))
                    .collect();
                if missing.len() + 1 >= cx.team_size() {
                    cx.broadcast(body);
                } else {
                    for m in missing {
                        cx.send(m, body.clone());
                    }
                }
                self.broadcast = Some((msg, payload));
            }
        }
    }

    fn decide(&self, cx: &mut Cx<'_>, rule: Rule) -> Outcome {
        match rule {
            Rule::Plurality(m) => {
                let votes = self.heard[m].values().map(|p| match p {
                    Payload::Choice(c) => *c,
                    _ => None,
                });
                Outcome::Sync(
                    crate::sync::plurality(&crate::sync::successors(cx), votes).map(|(c, _)| c),
                )
            }
            Rule::Borda(m) => {
                let ballots = self.heard[m].values().filter_map(|p| match p {
                    Payload::Ranking(r) => Some(r.as_slice()),
                    _ => None,
                });
                Outcome::Sync(crate::sync::borda(&crate::sync::successors(cx), ballots))
            }
            Rule::Sorted { msg, descending } => {
                let h = &self.heard[msg];
                let value = |r: RobotId| match h.get(&r) {
                    Some(Payload::Number(x)) => Some(*x),
                    _ => None,
                };
                crate::alloc::deal_by_value(cx, value, descending)
            }
            Rule::Own => match cx.input() {
                bite_core::interaction::PointInput::Sync { .. } => crate::sync::own_choice(cx),
                bite_core::interaction::PointInput::Allocate { children } => {
                    let c = children.clone();
                    Outcome::Allocate(cx.assign_by_id(&c))
                }
                bite_core::interaction::PointInput::Terminate => Outcome::Terminate(None),
            },
            Rule::Silent => rules::fallback(cx),
        }
    }

    /// Take a decision: a leader announces it to the team and answers with
    /// it from then on; a member decides for itself.
    fn adopt(&mut self, cx: &mut Cx<'_>, o: Outcome) {
        if cx.is_leader() {
            self.coord.adopt(cx, o, true);
        } else {
            cx.decide(o);
        }
    }

    // ----- nested protocols --------------------------------------------

    fn start_sub(&mut self, cx: &mut Cx<'_>, slot: u16) {
        let Some(f) = self.p.subs.get(slot as usize) else {
            return;
        };
        self.sub = Some(Sub {
            slot,
            inst: f(),
            decided: false,
        });
        self.with_sub(cx, |i, c| i.start(c));
        let early: Vec<(RobotId, u16, Body)> = std::mem::take(&mut self.early);
        for (from, s, body) in early {
            if s == slot {
                self.with_sub(cx, |i, c| i.on_message(c, from, &body));
            } else {
                self.early.push((from, s, body));
            }
        }
    }

    /// Call the nested instance and carry its effects out: its messages
    /// wrapped in this protocol's, its decision taken as this one's.
    fn with_sub(&mut self, cx: &mut Cx<'_>, f: impl FnOnce(&mut dyn Interaction, &mut Cx<'_>)) {
        let Some(sub) = self.sub.as_mut() else { return };
        let mut fx = Effects::default();
        {
            let mut scx = cx.nested(&mut fx, sub.decided);
            f(&mut *sub.inst, &mut scx);
        }
        let slot = sub.slot;
        for (to, body) in fx.sends {
            let wrapped = nested_body(slot, &body);
            match to {
                Recipients::One(r) => cx.send(r, wrapped),
                Recipients::Team(_) => cx.broadcast(wrapped),
            }
        }
        if let Some(t) = fx.wake {
            cx.wake_at(t);
        }
        for v in fx.violations {
            cx.violation(v);
        }
        if fx.postpone {
            cx.postpone_deadline();
        }
        for r in fx.departed {
            cx.member_done(r);
        }
        if let Some(o) = fx.outcome {
            sub.decided = true;
            if !self.finished(cx) {
                self.adopt(cx, o);
            }
        }
    }

    /// Resend what this robot owes its leader (after a quiet period, or to
    /// a new leader).
    fn resend_to_leader(&self, cx: &mut Cx<'_>) {
        for (m, p) in &self.to_leader {
            let body = self.p.def.message_body(*m, p);
            cx.send(cx.leader(), body);
        }
    }

    fn time_dependent(&self) -> bool {
        self.at.is_some_and(|b| {
            let d = &self.p.def.behaviors[b];
            d.until.as_ref().is_some_and(Expr::depends_on_time)
                || d.next.iter().any(|n| {
                    self.p.def.behaviors[*n]
                        .pre
                        .as_ref()
                        .is_some_and(Expr::depends_on_time)
                })
        })
    }
}

impl Interaction for GraphRun {
    fn start(&mut self, cx: &mut Cx<'_>) {
        self.coord.start(cx);
        let b = self.p.def.start[Self::role(cx)];
        self.enter(cx, b);
        self.advance(cx);
        if !cx.is_decided() {
            cx.wake_after_retry();
        }
    }

    fn local_done(&mut self, cx: &mut Cx<'_>, why: LocalEnd) {
        self.done = true;
        self.goal = why == LocalEnd::Condition;
        self.with_sub(cx, |i, c| i.local_done(c, why));
        self.advance(cx);
    }

    fn on_message(&mut self, cx: &mut Cx<'_>, from: RobotId, body: &Body) {
        let name = self.p.def.name;
        if let Body::Query = body {
            if cx.is_leader()
                && !self.coord.answer(cx, from)
                && !self.heard_any.contains(&from)
                && !cx.is_aborted()
                && let Some((m, p)) = &self.broadcast
            {
                let b = self.p.def.message_body(*m, p);
                cx.send(from, b);
            }
            return;
        }
        if let Some(n) = unnest(body) {
            match n {
                Ok((slot, inner)) => match &self.sub {
                    Some(s) if s.slot == slot => {
                        self.with_sub(cx, |i, c| i.on_message(c, from, &inner))
                    }
                    _ if self.early.len() < MAX_EARLY => self.early.push((from, slot, inner)),
                    _ => {}
                },
                Err(e) => cx.violation(format!("{name}: {from} sent {e}")),
            }
            return;
        }
        let (msg, payload) = match self.p.def.decode(body) {
            None => {
                if !cx.is_aborted() {
                    cx.violation(format!("{name}: unexpected `{}` from {from}", body.name()));
                }
                return;
            }
            Some(Err(e)) => {
                cx.violation(format!("{name}: {from} sent {e}"));
                return;
            }
            Some(Ok(x)) => x,
        };
        if Some(msg) == self.p.def.announce {
            self.coord.on_announcement(cx, from, body);
            return;
        }
        if let Err(e) = check(cx, &payload) {
            cx.violation(format!("{name}: {from} {e}"));
            return;
        }
        if cx.is_leader() && (self.coord.answer(cx, from) || cx.is_aborted()) {
            return;
        }
        // A message from the leader of a kind this robot already handled
        // (a call repeated, or a new leader's call): what it owes the
        // leader may have been lost, or gone to the old one.
        let repeated = !self.heard[msg].is_empty();
        if self.p.def.messages[msg].departs {
            cx.member_done(from);
        }
        self.heard[msg].insert(from, payload);
        self.heard_any.insert(from);
        if cx.is_leader() {
            self.coord.progress(cx);
        } else if repeated && from == cx.leader() && self.coord.result.is_none() {
            self.resend_to_leader(cx);
        }
        self.advance(cx);
    }

    fn on_timer(&mut self, cx: &mut Cx<'_>) {
        self.with_sub(cx, |i, c| i.on_timer(c));
        if self.coord.idle(cx) {
            return;
        }
        self.advance(cx);
        if self.finished(cx) {
            return;
        }
        if self.time_dependent() {
            cx.wake_after_retry();
        }
        if !self.coord.quiet(cx) {
            return;
        }
        if cx.is_leader() {
            if let Some((m, p)) = &self.broadcast {
                let body = self.p.def.message_body(*m, p);
                let me = cx.me();
                let missing: Vec<RobotId> = cx
                    .members()
                    .filter(|r| *r != me && !self.heard_any.contains(r))
                    .collect();
                for r in missing {
                    cx.send(r, body.clone());
                }
            }
        } else if !self.to_leader.is_empty() {
            self.resend_to_leader(cx);
        } else {
            cx.send(cx.leader(), Body::Query);
        }
        self.coord.next_resend(cx);
    }

    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        if self.sub.as_ref().is_some_and(|s| !s.decided) {
            self.with_sub(cx, |i, c| i.on_deadline(c));
            if cx.is_decided() {
                return;
            }
        }
        match self.p.def.on_deadline[Self::role(cx)] {
            Some(b) => {
                self.enter(cx, b);
                self.advance(cx);
            }
            None => {
                let o = rules::fallback(cx);
                self.adopt(cx, o);
            }
        }
    }

    fn on_members_changed(&mut self, cx: &mut Cx<'_>) {
        self.with_sub(cx, |i, c| i.on_members_changed(c));
        let changed = self.coord.leader_changed(cx);
        if self.coord.result.is_some() {
            if changed {
                self.coord.tell_new_leader(cx);
            }
            return;
        }
        if cx.is_aborted() || cx.is_decided() {
            return;
        }
        if cx.is_leader() {
            if changed {
                // Taking over: start again as the leader, with what we have.
                self.took_over = true;
                self.enter(cx, self.p.def.start[LEADER]);
            }
        } else if changed && !self.to_leader.is_empty() {
            self.coord.reset_backoff();
            self.resend_to_leader(cx);
        }
        self.advance(cx);
    }

    fn on_member_waiting(&mut self, cx: &mut Cx<'_>, from: RobotId) {
        // As the built-in barriers do: a member whose heartbeats have shown
        // it waiting at the point counts as having sent its report of
        // that, the protocol's message marked `departs` that carries
        // nothing, when the report itself has not come (lost on the way).
        if !cx.is_leader() || self.coord.idle(cx) {
            return;
        }
        let Some(msg) = (self.p.def.messages.iter())
            .position(|m| m.departs && matches!(m.carries, super::Carries::Nothing))
        else {
            return;
        };
        if self.heard[msg].contains_key(&from) {
            return;
        }
        cx.member_done(from);
        self.heard[msg].insert(from, Payload::Nothing);
        self.heard_any.insert(from);
        self.coord.progress(cx);
        self.advance(cx);
    }

    fn on_team_decision(&mut self, _cx: &mut Cx<'_>, outcome: &Outcome) {
        self.coord.team_decided(outcome);
    }

    fn on_abort(&mut self, cx: &mut Cx<'_>) {
        self.with_sub(cx, |i, c| i.on_abort(c));
        if self.coord.result.is_some() {
            return;
        }
        if let Some(b) = self.p.def.on_abort[Self::role(cx)] {
            // `cx` refuses decisions now, but a leader still announces
            // what it decides, and a member still sends (an abstention).
            self.enter(cx, b);
        }
    }
}

/// A received choice or ranking must name successors of the point.
fn check(cx: &Cx<'_>, p: &Payload) -> Result<(), String> {
    match p {
        Payload::Choice(c) => crate::sync::check_choice(cx, *c),
        Payload::Ranking(r) => crate::sync::check_ranking(cx, r),
        _ => Ok(()),
    }
}
