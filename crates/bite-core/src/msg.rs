//! Coordination messages between kernels.
//!
//! Every message names the protocol instance it belongs to — team, point
//! behavior, kind and epoch — plus its sender and a per-sender sequence
//! number. Receivers drop duplicates by `(sender, seq)` and stale epochs by
//! instance, so a late message from an old decision can never change a new
//! one, and a duplicated message changes nothing.

use crate::ids::{BehaviorId, RobotId};
pub use crate::ids::{InstanceKey, Kind};
use crate::members::{Assignment, MemberSet};
use serde::{Deserialize, Serialize};

/// One coordination message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    /// The protocol instance it belongs to.
    pub instance: InstanceKey,
    /// Who sent it.
    pub sender: RobotId,
    /// Per-sender sequence number, strictly increasing from 1.
    pub seq: u64,
    /// What it says.
    pub body: Body,
}

/// Message bodies of the interaction library. Protocols outside this crate
/// can use [`Body::Custom`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Body {
    /// Coordinator's call for votes on these candidates (graph order).
    Propose {
        /// The candidate successors.
        candidates: Vec<BehaviorId>,
    },
    /// A member's vote (`None` = abstain: no candidate is enabled for it).
    Vote {
        /// The chosen candidate.
        choice: Option<BehaviorId>,
    },
    /// A member's ranked ballot, best first.
    Ballot {
        /// Candidates in order of preference.
        ranking: Vec<BehaviorId>,
    },
    /// A synchronization decision (`None` = end the execution chain).
    Decision {
        /// The selected successor.
        choice: Option<BehaviorId>,
    },
    /// An allocation decision, compact on the wire (a few bytes per
    /// assigned member, whatever the roster size): the children in order,
    /// and for each assigned member the index of its child.
    Assignment {
        /// The children, in order.
        children: Vec<BehaviorId>,
        /// `(member, index into children)`, in member order.
        members: Vec<(RobotId, u32)>,
    },
    /// An auction round: the coordinator calls for bids on these items
    /// (children with places left) and names the previous round's winner.
    Call {
        /// The items.
        items: Vec<BehaviorId>,
        /// Auction round, from 1 (each round awards one place).
        round: u32,
        /// Who won the previous round (it bids no more).
        winner: Option<RobotId>,
    },
    /// A member's bid in an auction round: its best item and its value.
    Bid {
        /// The item bid on.
        item: BehaviorId,
        /// The bidder's utility for it (higher is better).
        value: f64,
        /// The round.
        round: u32,
    },
    /// A member's utility for each child it can take.
    Costs {
        /// `(child, utility)` pairs; higher is better.
        values: Vec<(BehaviorId, f64)>,
    },
    /// A token for one slot of a child, passed among members.
    Token {
        /// Slot number.
        slot: u32,
        /// The child the slot belongs to.
        item: BehaviorId,
        /// Members it has visited.
        hops: u32,
        /// Utility a member needs to keep it.
        threshold: f64,
    },
    /// "I keep the token of this slot."
    Claim {
        /// Slot number.
        slot: u32,
    },
    /// A number a member announces (a bid, a cost, a value read from beliefs).
    Value {
        /// What the number is about (a child for bids, `None` otherwise).
        about: Option<BehaviorId>,
        /// The number.
        value: f64,
    },
    /// A member's attribute (allocation by attribute).
    Attribute {
        /// Attribute name.
        name: String,
        /// Attribute value.
        value: String,
    },
    /// "I am done with this behavior" (barrier arrival).
    Done,
    /// "Your message was received" (stops the sender's retries).
    Ack,
    /// "The team has ended this behavior" (barrier release, first-wins stop).
    /// `next` optionally names a new behavior to run under the same parent.
    Release {
        /// Optional replacement behavior under the same parent.
        next: Option<BehaviorId>,
    },
    /// "Is this decided?" — answered with the decision if there is one.
    Query,
    /// Sent by the kernel, not by protocols: "teammates were lost, this
    /// team re-allocates at this point" (the round is in the instance key).
    /// Teammates still under the point join; those that left it answer
    /// `Done`. `lost` are the teammates the sender re-allocates without:
    /// every robot that joins leaves them out too, so that rules computed
    /// alone (by-id) agree before each robot's own detector catches up.
    Reallocate {
        /// Members left out of this round.
        lost: Vec<RobotId>,
    },
    /// Sent by the kernel, not by protocols, to a teammate it hears again
    /// after presuming it lost: how an instance it missed was decided
    /// without it. `choice` is the successor (sync) or the next behavior
    /// (termination); `children` and `members` the allocation, in the form
    /// of [`Body::Assignment`].
    Missed {
        /// Sync choice or termination's next behavior.
        choice: Option<BehaviorId>,
        /// Allocation: the children, in order.
        children: Vec<BehaviorId>,
        /// Allocation: `(member, index into children)`.
        members: Vec<(RobotId, u32)>,
    },
    /// A protocol-defined message for protocols outside the library.
    Custom {
        /// Protocol-chosen tag.
        tag: u16,
        /// Protocol-encoded data.
        data: Vec<u8>,
    },
}

impl Body {
    /// The wire form of an allocation.
    pub fn assignment(a: &Assignment) -> Body {
        let mut members: Vec<(RobotId, u32)> =
            a.0.iter()
                .enumerate()
                .flat_map(|(i, (_, m))| m.iter().map(move |r| (r, i as u32)))
                .collect();
        members.sort_unstable();
        Body::Assignment {
            children: a.0.iter().map(|(c, _)| *c).collect(),
            members,
        }
    }

    /// The allocation an `Assignment` message carries, over a roster of
    /// `roster_len`; `None` if it is not one or is malformed (a member
    /// twice, a child index out of range, a robot outside the roster).
    pub fn to_assignment(&self, roster_len: usize) -> Option<Assignment> {
        let Body::Assignment { children, members } = self else {
            return None;
        };
        let mut sets: Vec<(BehaviorId, MemberSet)> = children
            .iter()
            .map(|c| (*c, MemberSet::empty(roster_len)))
            .collect();
        let mut seen = MemberSet::empty(roster_len);
        for (r, i) in members {
            if r.index() >= roster_len || !seen.insert(*r) {
                return None;
            }
            sets.get_mut(*i as usize)?.1.insert(*r);
        }
        Some(Assignment(sets))
    }

    /// True when the message asks something of its recipient (a call, a
    /// vote, a claim, a query...); false for an announcement (a decision,
    /// an assignment, a release), an acknowledgement, a teammate's `Done`
    /// and the kernel's own notices, which ask for nothing. A robot answers
    /// nothing for an instance it has no part in (see `Kernel::route`) and
    /// a forgotten instance answers nothing, unless the message asks:
    /// answering a `Done` drew another, for ever (docs/reliability.md, "A
    /// decision answered to a teammate that left").
    pub fn asks(&self) -> bool {
        !matches!(
            self,
            Body::Decision { .. }
                | Body::Assignment { .. }
                | Body::Release { .. }
                | Body::Done
                | Body::Ack
                | Body::Missed { .. }
                | Body::Reallocate { .. }
        )
    }

    /// A short name for logs and counters.
    pub fn name(&self) -> &'static str {
        match self {
            Body::Propose { .. } => "propose",
            Body::Vote { .. } => "vote",
            Body::Ballot { .. } => "ballot",
            Body::Decision { .. } => "decision",
            Body::Assignment { .. } => "assignment",
            Body::Call { .. } => "call",
            Body::Bid { .. } => "bid",
            Body::Costs { .. } => "costs",
            Body::Token { .. } => "token",
            Body::Claim { .. } => "claim",
            Body::Value { .. } => "value",
            Body::Attribute { .. } => "attribute",
            Body::Done => "done",
            Body::Ack => "ack",
            Body::Release { .. } => "release",
            Body::Query => "query",
            Body::Reallocate { .. } => "reallocate",
            Body::Missed { .. } => "missed",
            Body::Custom { .. } => "custom",
        }
    }
}

/// Wire format version (first byte of every encoded message).
pub const WIRE_VERSION: u8 = 1;
/// Largest encoded message a kernel accepts.
pub const MAX_WIRE_BYTES: usize = 64 * 1024;

/// Why bytes could not be decoded into an [`Envelope`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Empty input.
    #[error("empty message")]
    Empty,
    /// Unknown version byte.
    #[error("unsupported wire version {0} (this build speaks {WIRE_VERSION})")]
    Version(u8),
    /// Over [`MAX_WIRE_BYTES`].
    #[error("message of {0} bytes exceeds the {MAX_WIRE_BYTES}-byte limit")]
    TooLarge(usize),
    /// The payload does not decode.
    #[error("malformed message: {0}")]
    Malformed(String),
}

/// Encode an envelope: one version byte, then postcard.
pub fn encode(env: &Envelope) -> Vec<u8> {
    let out = vec![WIRE_VERSION];
    // Serializing plain data into a Vec cannot fail.
    match postcard::to_extend(env, out) {
        Ok(v) => v,
        Err(_) => vec![WIRE_VERSION],
    }
}

/// Encoded size of an envelope in bytes (what the byte counters report).
pub fn encoded_len(env: &Envelope) -> usize {
    1 + postcard::experimental::serialized_size(env).unwrap_or(0)
}

/// Decode bytes received from the network. Never panics.
pub fn decode(bytes: &[u8]) -> Result<Envelope, WireError> {
    let (&version, rest) = bytes.split_first().ok_or(WireError::Empty)?;
    if bytes.len() > MAX_WIRE_BYTES {
        return Err(WireError::TooLarge(bytes.len()));
    }
    if version != WIRE_VERSION {
        return Err(WireError::Version(version));
    }
    let (env, tail): (Envelope, &[u8]) =
        postcard::take_from_bytes(rest).map_err(|e| WireError::Malformed(e.to_string()))?;
    if !tail.is_empty() {
        return Err(WireError::Malformed(format!(
            "{} trailing bytes",
            tail.len()
        )));
    }
    Ok(env)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::TeamId;

    fn sample() -> Envelope {
        Envelope {
            instance: InstanceKey {
                team: TeamId::ROOT,
                behavior: BehaviorId(4),
                kind: Kind::Sync,
                epoch: 2,
                round: 0,
            },
            sender: RobotId(1),
            seq: 17,
            body: Body::Vote {
                choice: Some(BehaviorId(5)),
            },
        }
    }

    #[test]
    fn roundtrip_and_size() {
        let e = sample();
        let bytes = encode(&e);
        assert_eq!(bytes.len(), encoded_len(&e));
        assert_eq!(decode(&bytes).unwrap(), e);
    }

    #[test]
    fn assignments_roundtrip_compactly() {
        use Assignment;
        let n = 1000;
        let a = Assignment(
            (0..n as u32)
                .map(|c| (BehaviorId(c), MemberSet::from_iter(n, [RobotId(c)])))
                .collect(),
        );
        let body = Body::assignment(&a);
        assert_eq!(body.to_assignment(n), Some(a));
        let env = Envelope { body, ..sample() };
        // A thousand children of a thousand robots: well under the limit.
        assert!(encoded_len(&env) < 8 * 1024, "{}", encoded_len(&env));
        let twice = Body::Assignment {
            children: vec![BehaviorId(1), BehaviorId(2)],
            members: vec![(RobotId(0), 0), (RobotId(0), 1)],
        };
        assert_eq!(twice.to_assignment(4), None);
        let out_of_range = Body::Assignment {
            children: vec![BehaviorId(1)],
            members: vec![(RobotId(0), 3)],
        };
        assert_eq!(out_of_range.to_assignment(4), None);
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert_eq!(decode(&[]), Err(WireError::Empty));
        assert_eq!(decode(&[9, 1, 2]), Err(WireError::Version(9)));
        let mut bytes = encode(&sample());
        bytes.truncate(bytes.len() - 1);
        assert!(matches!(decode(&bytes), Err(WireError::Malformed(_))));
        let mut long = encode(&sample());
        long.push(0);
        assert!(matches!(decode(&long), Err(WireError::Malformed(_))));
    }
}
