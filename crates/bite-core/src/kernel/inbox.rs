//! The inbox: messages from teammates, validated and routed to their
//! protocol instance, answered for instances already over, or buffered
//! for instances this robot has not reached yet.

use super::{DEDUP_PER_SENDER, Frame, Kernel, Outgoing, Output};
use crate::event::{DropReason, Event};
use crate::ids::{BehaviorId, RobotId, TeamId};
use crate::ids::{InstanceKey, Kind};
use crate::interaction::{Closed, Outcome, Recipients};
use crate::msg::{Body, Envelope, encoded_len};
use crate::time::Time;
use std::collections::BTreeMap;
use std::sync::Arc;

/// A buffered message for an instance not started yet.
pub(super) struct Pending {
    pub(super) at: Time,
    pub(super) from: RobotId,
    pub(super) body: Body,
}

/// Messages buffered per instance not started yet, with their count kept
/// in one place.
#[derive(Default)]
pub(super) struct Inbox {
    queues: BTreeMap<InstanceKey, Vec<Pending>>,
    len: usize,
}

impl Inbox {
    /// Messages buffered, over every instance.
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// Buffer `p` for `key`; false (and nothing kept) when the same
    /// message from the same sender already waits.
    pub(super) fn push(&mut self, key: InstanceKey, p: Pending) -> bool {
        let queue = self.queues.entry(key).or_default();
        if queue.iter().any(|q| q.from == p.from && q.body == p.body) {
            return false;
        }
        queue.push(p);
        self.len += 1;
        true
    }

    /// Take what waits for `key`, in arrival order.
    pub(super) fn take(&mut self, key: InstanceKey) -> Vec<Pending> {
        let v = self.queues.remove(&key).unwrap_or_default();
        self.len -= v.len();
        v
    }

    /// Drop what waits for any instance of one execution.
    pub(super) fn drop_execution(&mut self, team: TeamId, behavior: BehaviorId, epoch: u32) {
        let keys: Vec<InstanceKey> = self
            .queues
            .keys()
            .filter(|k| (k.team, k.behavior, k.epoch) == (team, behavior, epoch))
            .copied()
            .collect();
        for k in keys {
            self.take(k);
        }
    }

    /// Keep only what `keep` accepts; returns how many were dropped.
    pub(super) fn retain(&mut self, mut keep: impl FnMut(&InstanceKey, &Pending) -> bool) -> usize {
        let mut dropped = 0usize;
        self.queues.retain(|k, v| {
            let before = v.len();
            v.retain(|m| keep(k, m));
            dropped += before - v.len();
            !v.is_empty()
        });
        self.len -= dropped;
        dropped
    }
}

impl Kernel {
    pub(super) fn drop_msg(&mut self, from: RobotId, reason: DropReason) {
        *self.stats.dropped.entry(reason).or_insert(0) += 1;
        // Duplicates, stale messages and our own echoes are normal on a
        // lossy, duplicating network: counted, not logged one by one.
        if !matches!(
            reason,
            DropReason::Duplicate | DropReason::Stale | DropReason::OwnMessage
        ) {
            self.emit(Event::Dropped { from, reason });
        }
    }

    /// Validate a message and hand it to its instance, or buffer it for an
    /// instance this robot has not reached yet.
    pub(super) fn route(&mut self, env: Envelope) {
        let from = env.sender;
        if from == self.me {
            return self.drop_msg(from, DropReason::OwnMessage);
        }
        if from.index() >= self.org.roster_len() {
            return self.drop_msg(from, DropReason::UnknownSender);
        }
        let key = env.instance;
        // A point of the running version, or of a newer one this robot
        // holds (a teammate that switched first talks about it; the
        // message waits in the buffer like any early one).
        let point_of = |graph: &crate::graph::BehaviorGraph| {
            graph.get(key.behavior).is_some() && graph.is_point(key.behavior, key.kind)
        };
        let well_formed = key.epoch > 0
            && (point_of(self.mission.graph())
                || self.pending.values().any(|m| point_of(m.graph())));
        if !well_formed {
            return self.drop_msg(from, DropReason::Malformed);
        }
        if !(self.seen).accept(from, env.seq, self.now, DEDUP_PER_SENDER) {
            return self.drop_msg(from, DropReason::Duplicate);
        }
        if self.lost.contains(from) && !self.stirring.contains(&from) {
            self.stirring.push(from);
        }
        if key.kind == Kind::Allocate
            && ((key.round > 0 && !self.instances.contains_key(&key)) || self.left_instance(key))
        {
            let frame = self
                .stack
                .iter()
                .position(|f| (f.team, f.behavior, f.epoch) == (key.team, key.behavior, key.epoch));
            let told: &[RobotId] = match &env.body {
                Body::Reallocate { lost } => lost,
                _ => &[],
            };
            match frame {
                // A teammate re-allocates what this robot runs under: join
                // it (this robot may not have noticed the loss yet) — unless
                // that teammate left this robot out.
                Some(i) if self.stack[i].round < key.round && !told.contains(&self.me) => {
                    let told = told.to_vec();
                    self.reallocate(i, key.round, &told);
                }
                Some(_) => {}
                // This robot has left that behavior: it takes no part. A
                // teammate's own `Done`, or its notice of how it decided,
                // asks for nothing and gets no answer: two robots that had
                // both left it answered each other's `Done` for ever
                // (docs/reliability.md, "Two robots answering each other").
                // So does a first round this robot left undecided (its
                // own reason to end the behavior came first, say, under a
                // termination that waits for every member): its
                // coordinator, not told, waited for it until its deadline
                // (docs/reliability.md, "An allocation left undecided").
                None if self.org.runs(key.team, key.behavior) >= key.epoch
                    && self.org.team(key.team).is_some_and(|t| t.contains(from)) =>
                {
                    self.stats.received += 1;
                    if !matches!(env.body, Body::Done | Body::Missed { .. }) {
                        self.reply(key, from, Body::Done);
                    }
                    return;
                }
                None => {}
            }
        }
        if matches!(env.body, Body::Reallocate { .. }) {
            // The kernel's own notice, handled above.
            self.stats.received += 1;
            return;
        }
        if let Some(inst) = self.instances.get(&key) {
            let team = self.org.team(key.team).unwrap_or(&inst.team);
            if !team.contains(from) {
                return self.drop_msg(from, DropReason::SenderNotMember);
            }
            self.stats.received += 1;
            return self.deliver(key, from, env.body);
        }
        if let Some(closed) = self.tombstones.get(&key).cloned() {
            self.stats.received += 1;
            if matches!(env.body, Body::Missed { .. }) {
                // Decided here already: nothing to apply, nothing to answer.
                return;
            }
            return self.late_reply(key, closed, from, &env.body);
        }
        match self.org.team(key.team) {
            Some(t) if !t.contains(self.me) => return self.drop_msg(from, DropReason::NotMember),
            Some(t) if !t.contains(from) => {
                return self.drop_msg(from, DropReason::SenderNotMember);
            }
            Some(_) => {}
            // A synchronization or an allocation of a team this robot has
            // dissolved (it left the behavior that made the team) and whose
            // instance it never had: it takes no part, and says so to a
            // teammate that asks. That teammate heard its heartbeats only
            // while they shared the team, and would wait for it until the
            // instance's deadline (docs/reliability.md, "An allocation left
            // undecided").
            None if self.org.is_dead(key.team) => {
                if key.kind != Kind::Terminate && env.body.asks() {
                    self.stats.received += 1;
                    return self.reply(key, from, Body::Done);
                }
                return self.drop_msg(from, DropReason::Stale);
            }
            None => {}
        }
        if self
            .closed
            .get(&(key.team, key.behavior, key.kind))
            .is_some_and(|e| key.stamp() <= *e)
        {
            return self.drop_msg(from, DropReason::Stale);
        }
        // A question about the synchronization or the allocation of an
        // execution this robot's count is past and that it does not run
        // (it left before the point: an ancestor ended, or it went on
        // another way; or it converged onto a teammate further on, past
        // the execution), with no instance or tombstone of it here: it will
        // never reach that point, and says so, as for an allocation it
        // left. Kept for later, the question waited for ever, and the
        // teammate that asked for its deadline: a robot a lap ahead had
        // ended more executions since than it remembers (its last
        // [`super::position::RECENT`]), and told neither from the question nor
        // from the teammate's heartbeats that it had left the execution
        // (docs/reliability.md, "A member that found its coordinator gone
        // at the point", seed 2677). A coordinator that converged past an
        // allocation kept its members' questions for ever in the same way
        // ("A coordinator that went past the allocation", seeds 3251 and
        // 3973).
        if matches!(key.kind, Kind::Sync | Kind::Allocate)
            && env.body.asks()
            && self.org.runs(key.team, key.behavior) >= key.epoch
            && !self.runs_execution(key)
        {
            self.stats.received += 1;
            return self.reply(key, from, Body::Done);
        }
        if self.inbox.len() >= self.limits.max_pending {
            return self.drop_msg(from, DropReason::BufferOverflow);
        }
        let waiting = Pending {
            at: self.now,
            from,
            body: env.body,
        };
        if !self.inbox.push(key, waiting) {
            // A retransmission of a message already waiting: one is enough.
            return self.drop_msg(from, DropReason::Duplicate);
        }
        self.stats.received += 1;
        self.stats.buffered += 1;
    }

    /// True when this robot runs the execution of instance `key`: on its
    /// stack, or the one it ended and terminates or chooses a successor
    /// for.
    fn runs_execution(&self, key: InstanceKey) -> bool {
        let id = super::position::FrameId::of(key);
        self.frames().any(|(_, f)| f.id() == id)
    }

    /// True when this robot left instance `key` before it decided (it is
    /// over here, undecided).
    fn left_instance(&self, key: InstanceKey) -> bool {
        match self.instances.get(&key) {
            Some(inst) => inst.closed == Some(Closed::Left),
            None => self.tombstones.get(&key) == Some(&Closed::Left),
        }
    }

    /// Answer a teammate's late message for a forgotten instance, as its
    /// protocol says.
    pub(super) fn late_reply(
        &mut self,
        key: InstanceKey,
        closed: Closed,
        from: RobotId,
        body: &Body,
    ) {
        if let Some(reply) = self
            .mission
            .bound(key.behavior, key.kind)
            .and_then(|b| b.protocol.late_reply(&closed, body))
        {
            self.reply(key, from, reply);
        }
    }

    /// Send `body` to `to` for instance `key`, outside any live instance.
    pub(super) fn reply(&mut self, key: InstanceKey, to: RobotId, body: Body) {
        self.send_outside(key, Recipients::One(to), body);
    }

    /// Send a message of the kernel's own (not of a protocol instance).
    pub(super) fn send_outside(&mut self, key: InstanceKey, to: Recipients, body: Body) {
        let envelope = Envelope {
            instance: key,
            sender: self.me,
            seq: self.next_seq,
            body,
        };
        self.next_seq += 1;
        let bytes = encoded_len(&envelope) as u32;
        self.stats.sent += 1;
        self.stats.bytes_sent += u64::from(bytes);
        self.out.push_back(Output::Send(Outgoing {
            to,
            envelope,
            bytes,
        }));
    }

    pub(super) fn deliver(&mut self, key: InstanceKey, from: RobotId, body: Body) {
        if let Some(i) = self.instances.get_mut(&key) {
            i.received += 1;
        }
        if key.kind != Kind::Terminate && body == Body::Done {
            // "I have left this behavior" (a re-allocation reached a
            // teammate that is done with it): decide without it.
            self.exclude(key, &[from]);
            self.refresh_due();
            return;
        }
        if let Body::Missed {
            choice,
            children,
            members,
        } = body
        {
            // A synchronization that a robot presumed lost (not one that
            // left the behavior) decided without this robot, while this
            // robot decides it with teammates of its own: the two sides of
            // a partition decided apart. This side follows its own
            // protocol: applied by one of its robots while another, not
            // told yet, decided by the protocol, the notice parted them
            // (docs/reliability.md, "Seeds 61 to 180"). So does a member
            // (of a synchronization or an allocation) whose coordinator is
            // a robot of its own side, which may decide apart from the
            // sender (it started the instance before it heard the sender
            // back) while this member, starting it after, would follow the
            // notice (docs/reliability.md, "A member that followed the
            // other side", "A lone robot's allocation"). A coordinator of
            // an allocation applies the notice, and its protocol instance
            // keeps that decision for the members that ask
            // (`Interaction::on_team_decision`; "An instance decided from a
            // notice"). Positions heal the split with the other side
            // (`Kernel::peer`: a synchronization's histories are compared,
            // an allocation is made anew in a next round).
            if matches!(key.kind, Kind::Sync | Kind::Allocate)
                && self.ever_lost.contains(from)
                && !Frame::any_left_by(&self.stack, from)
                && ((key.kind == Kind::Sync
                    && (self.instances.get(&key))
                        .is_some_and(|i| i.decides_apart_from(from, self.me)))
                    || self
                        .coordinator_of(key)
                        .is_some_and(|c| c != self.me && c != from && !self.ever_lost.contains(c)))
            {
                return;
            }
            // The team decided without this robot while it was presumed
            // lost: apply the team's decision, whatever this robot's own
            // protocol instance (it may believe itself the coordinator).
            let outcome = match key.kind {
                Kind::Sync => Some(Outcome::Sync(choice)),
                Kind::Terminate => Some(Outcome::Terminate(choice)),
                Kind::Allocate => Body::Assignment { children, members }
                    .to_assignment(self.org.roster_len())
                    .map(|a| Outcome::Allocate(Arc::new(a))),
            };
            match outcome {
                Some(o) => self.force(key, o),
                None => self.drop_msg(from, DropReason::Malformed),
            }
            return;
        }
        self.call(key, |imp, cx| imp.on_message(cx, from, &body));
        self.refresh_due();
    }

    pub(super) fn drop_pending(&mut self, key: InstanceKey) {
        self.inbox.take(key);
    }
}
