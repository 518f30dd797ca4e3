//! A member that leaves an allocating behavior before the team's first
//! allocation of it decided (its own reason to end the behavior came first,
//! under a termination that waits for every member) says so when the
//! coordinator's messages reach it, and the coordinator decides without it
//! at once rather than at its deadline. Found by the property test
//! `no_waiting_across_levels` (seed 7844512826741064117, four robots):
//! `alloc.token`'s leader dealt tokens to such a member until its deadline,
//! then, with the member left out, had more places than members and
//! passed the tokens round until the deadline all the same. With five
//! robots, a member that dissolved its subteam (it ended the behavior
//! above it) dropped a teammate's question at the subteam's next
//! synchronization as stale, and the teammate waited for it until its
//! deadline (docs/reliability.md, "An allocation left undecided").

use bite_core::event::Event;
use bite_core::graph::load_str;
use bite_core::interaction::Recipients;
use bite_core::kernel::Output;
use bite_core::kernel::{Anchor, FrameId, FrameState, PosFrame, Position};
use bite_core::msg::{Body, InstanceKey};
use bite_core::time::Time;
use bite_core::{Kernel, Mission, RobotId, TeamId, Value};
use std::sync::Arc;

mod common;
use common::from;

/// Three robots run `p` until `stop`, its children allocated by tokens.
const GRAPH: &str = "graph: left\nteam: { robots: 3 }\nstart: p\n\
    defaults: { sync: sync.by-rule, allocate: alloc.token, terminate: term.wait-all }\n\
    behaviors:\n  p: { team: true, children: [x, y], allocate: alloc.token, until: stop }\n\
    \x20 x: { team: true, skill: w }\n  y: { team: true, skill: w }\n";

#[derive(Default)]
struct Drained {
    sent: Vec<(Recipients, Body)>,
    started: Vec<InstanceKey>,
    decided: usize,
}

fn drain(k: &mut Kernel) -> Drained {
    let mut d = Drained::default();
    while let Some(o) = k.poll_output() {
        match o {
            Output::Send(s) => d.sent.push((s.to, s.envelope.body)),
            Output::Event(Event::InteractionStarted { instance, .. }) => d.started.push(instance),
            Output::Event(Event::InteractionDecided { .. }) => d.decided += 1,
            Output::Event(_) => {}
        }
    }
    d
}

fn robot(me: u32) -> Kernel {
    let g = load_str(&Arc::from("left.yaml"), GRAPH).expect("the test graph loads");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    Kernel::new(mission, RobotId(me), u64::from(me) + 1)
}

/// Robot `me` of three that run `p` until `stop`, its children allocated
/// by `protocol` (bound as the default).
fn robot_allocating_by(protocol: &str, me: u32) -> Kernel {
    let graph = format!(
        "graph: by\nteam: {{ robots: 3 }}\nstart: p\n\
         defaults: {{ sync: sync.by-rule, allocate: {protocol}, terminate: term.wait-all }}\n\
         behaviors:\n  p: {{ team: true, children: [x, y], until: stop }}\n\
         \x20 x: {{ team: true, skill: w }}\n  y: {{ team: true, skill: w }}\n"
    );
    let g = load_str(&Arc::from("by.yaml"), &graph).expect("the test graph loads");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    Kernel::new(mission, RobotId(me), u64::from(me) + 1)
}

/// The allocation of `p` this robot started on its first tick.
fn start(k: &mut Kernel) -> InstanceKey {
    let stop = k.mission().graph().symbols().get("stop").expect("belief");
    k.tick(Time::ZERO, &[(stop, Value::Bool(false))]);
    let d = drain(k);
    let key = d.started.first().copied().expect("the allocation started");
    assert_eq!(key.kind, bite_core::ids::Kind::Allocate);
    key
}

#[test]
fn a_member_that_left_the_first_round_answers_that_it_is_done() {
    let mut r1 = robot(1);
    let key = start(&mut r1);
    // `p` ends for r1 before the tokens reach it: it waits at the barrier.
    let stop = r1.mission().graph().symbols().get("stop").expect("belief");
    r1.tick(Time::from_millis(100), &[(stop, Value::Bool(true))]);
    drain(&mut r1);
    let x = r1.mission().graph().find("x").expect("x");
    let token = Body::Token {
        slot: 1,
        item: x,
        hops: 0,
        threshold: 0.0,
    };
    r1.message(Time::from_millis(200), from(0, key, 1, token));
    let answered = drain(&mut r1);
    assert_eq!(
        answered.sent,
        [(Recipients::One(RobotId(0)), Body::Done)],
        "r1 tells the leader it is done with `p`"
    );
}

#[test]
fn the_token_leader_decides_once_every_live_member_holds_a_place() {
    let mut r0 = robot(0);
    let key = start(&mut r0);
    // r0 dealt three places: kept one, sent one token to r1 and one to r2.
    r0.message(
        Time::from_millis(100),
        from(1, key, 1, Body::Claim { slot: 1 }),
    );
    assert_eq!(drain(&mut r0).decided, 0, "r2 has not claimed yet");
    // r2 is done with `p`: two members, two places held.
    r0.message(Time::from_millis(200), from(2, key, 1, Body::Done));
    let d = drain(&mut r0);
    assert_eq!(d.decided, 1, "decided at once, not at its deadline");
    assert!(
        d.sent
            .iter()
            .any(|(_, m)| matches!(m, Body::Assignment { .. })),
        "the assignment announced: {:?}",
        d.sent
    );
}

/// Two members claim one place (the leader dealt the places again while
/// the first tokens still travelled): the first claim wins it, and the
/// second claimant, which takes no more tokens once it has claimed, is
/// given the place left over, so the leader decides at once. Found by
/// `no_waiting_across_levels` (RNG seed 20261204, graph seed
/// 10877919030516264622, seven robots): two members lost such races and
/// the leader waited for them until its deadline (docs/reliability.md, "A
/// place claimed twice").
#[test]
fn a_member_that_lost_a_claim_race_is_given_the_place_left_over() {
    every_member_placed_after_claims(1, 1);
}

/// The token leader r0 of three, having dealt three places and kept one,
/// hears r1 claim place `first`, then r2 place `second`: it decides at
/// once, every member placed.
fn every_member_placed_after_claims(first: u32, second: u32) {
    let mut r0 = robot(0);
    let key = start(&mut r0);
    drain(&mut r0);
    r0.message(
        Time::from_millis(100),
        from(1, key, 1, Body::Claim { slot: first }),
    );
    assert_eq!(drain(&mut r0).decided, 0, "r2 has not claimed yet");
    r0.message(
        Time::from_millis(200),
        from(2, key, 1, Body::Claim { slot: second }),
    );
    let d = drain(&mut r0);
    assert_eq!(d.decided, 1, "decided at once, not at its deadline");
    let placed: Vec<RobotId> = (d.sent.iter())
        .find_map(|(_, m)| match m {
            Body::Assignment { members, .. } => Some(members.iter().map(|(r, _)| *r).collect()),
            _ => None,
        })
        .expect("the assignment announced");
    assert_eq!(
        placed,
        [RobotId(0), RobotId(1), RobotId(2)],
        "every member placed"
    );
}

/// A member that reached the point after its token was dealt (it dropped
/// the token: it was not in the instance yet) asks the leader how the
/// allocation stands; the leader deals it its place again at once, as
/// `alloc.auction` sends its call again. Without it the member waited for
/// the leader's next deal, up to 64 retries away, and the leader's
/// deadline came first. Found by `no_waiting_across_levels` (RNG seed
/// 6855, graph seed 8450988898213553314, eight robots; docs/reliability.md,
/// "A member that reached the token's point late").
#[test]
fn a_member_that_asks_is_dealt_its_place_again() {
    let mut r0 = robot(0);
    let key = start(&mut r0);
    drain(&mut r0);
    // r0 dealt three places, kept one, and r1 claimed the second.
    r0.message(
        Time::from_millis(100),
        from(1, key, 1, Body::Claim { slot: 1 }),
    );
    assert_eq!(drain(&mut r0).decided, 0, "r2 has not claimed yet");
    r0.message(Time::from_millis(200), from(2, key, 1, Body::Query));
    let d = drain(&mut r0);
    let y = r0.mission().graph().find("y").expect("y");
    assert!(
        d.sent
            .iter()
            .any(|(to, m)| *to == Recipients::One(RobotId(2))
                && matches!(m, Body::Token { slot: 2, item, .. } if *item == y)),
        "r2 dealt the place left: {:?}",
        d.sent
    );
    // And r1, which holds a place, is dealt nothing when it asks.
    r0.message(Time::from_millis(300), from(1, key, 2, Body::Query));
    assert!(drain(&mut r0).sent.is_empty(), "r1 holds a place");
}

/// A member claims a place the leader never made: a token of an earlier
/// leader's deal (numbered for the team that leader saw), passed on to it
/// by a live teammate before the leadership changed. It takes no more
/// tokens once it has claimed, so the leader gives it a place left, as it
/// does a member that lost a claim race. Found by
/// `no_waiting_across_levels` (RNG seed 7260, graph seed
/// 6026314665237865797, seven robots): the leader took each of the
/// member's claims for a protocol violation and waited for it until its
/// deadline (docs/reliability.md, "A token of an earlier deal").
#[test]
fn a_member_that_claims_a_place_of_an_earlier_deal_is_given_one() {
    // r1 claims a seventh place of three.
    every_member_placed_after_claims(6, 2);
}

/// A member that ended the behavior whose allocation made its subteam
/// (its own `until`) dissolved the subteam; a teammate still in it, which
/// heard its heartbeats only while they shared the subteam, asks it at the
/// subteam's next synchronization: it answers that it is done, instead of
/// dropping the question as stale (the teammate waited until its deadline:
/// the same property test, five robots).
#[test]
fn a_member_that_dissolved_the_team_answers_that_it_is_done() {
    const TEAM: &str = "graph: dead\nteam: { robots: 3 }\nstart: m\n\
        defaults: { sync: sync.elected-leader, allocate: alloc.by-id, terminate: term.local }\n\
        behaviors:\n  m: { team: true, children: [p] }\n\
        \x20 p: { team: true, children: [q, y], allocate: alloc.by-id, until: stop, next: [z] }\n\
        \x20 q: { team: true, skill: w, until: qd, next: [a, b], members: \"2\" }\n\
        \x20 y: { team: true, skill: w, members: \"1\" }\n\
        \x20 a: { team: true, skill: w }\n  b: { team: true, skill: w }\n  z: { team: true, skill: w }\n";
    let g = load_str(&Arc::from("dead.yaml"), TEAM).expect("the test graph loads");
    let q = g.find("q").expect("q");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut r1 = Kernel::new(mission, RobotId(1), 2);
    let stop = r1.mission().graph().symbols().get("stop").expect("belief");
    r1.tick(Time::ZERO, &[(stop, Value::Bool(false))]);
    let mut subteam = None;
    while let Some(o) = r1.poll_output() {
        if let Output::Event(Event::Selected { behavior, team, .. }) = o
            && behavior == q
        {
            subteam = Some(team);
        }
    }
    let team = subteam.expect("r1 runs `q` in the subteam");
    assert_ne!(team, bite_core::ids::TeamId::ROOT, "a subteam of two");
    // `p` ends for r1: the subteam is dissolved here.
    r1.tick(Time::from_millis(100), &[(stop, Value::Bool(true))]);
    drain(&mut r1);
    // r0, still in the subteam, ended `q` and asks at its sync point.
    let key = InstanceKey {
        team,
        behavior: q,
        kind: bite_core::ids::Kind::Sync,
        epoch: 1,
        round: 0,
    };
    r1.message(Time::from_millis(200), from(0, key, 1, Body::Query));
    assert_eq!(
        drain(&mut r1).sent,
        [(Recipients::One(RobotId(0)), Body::Done)],
        "r1 tells r0 it takes no part"
    );
}

/// A robot that takes over an allocation whose rule makes no call
/// (`alloc.optimal`: members send their costs unprompted) asks
/// the members it has no contribution from: one that sent its own to the
/// leader before and left the allocation since will not send it again,
/// and its kernel answers the question that it is done. Found by
/// `no_waiting_across_levels` (RNG seed 13, graph seed
/// 3090137497910363889, seven robots): two members ended the behavior
/// 0.1 s into its allocation, after contributing to leaders that were
/// leaving too; the robot that led next waited for them until its
/// deadline (docs/reliability.md, "A contribution sent to the leader
/// before").
#[test]
fn a_robot_taking_over_an_allocation_without_a_call_asks_who_it_has_not_heard() {
    const VALUE: &str = "graph: value\nteam: { robots: 3 }\nstart: p\n\
        defaults: { sync: sync.by-rule, allocate: alloc.optimal, terminate: term.wait-all }\n\
        behaviors:\n  p: { team: true, children: [x, y], allocate: alloc.optimal, until: stop }\n\
        \x20 x: { team: true, skill: w }\n  y: { team: true, skill: w }\n";
    let g = load_str(&Arc::from("value.yaml"), VALUE).expect("the test graph loads");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut r1 = Kernel::new(mission, RobotId(1), 2);
    let key = start(&mut r1);
    // r0, the leader, is lost: r1 leads and has heard only itself.
    r1.member_lost(Time::from_millis(100), RobotId(0));
    let asked = drain(&mut r1);
    assert!(
        asked
            .sent
            .contains(&(Recipients::One(RobotId(2)), Body::Query)),
        "r1 asks r2: {:?}",
        asked.sent
    );
    assert_eq!(asked.decided, 0);
    // r2 left `p` after sending its contribution to r0: it is done.
    r1.message(Time::from_millis(150), from(2, key, 1, Body::Done));
    assert_eq!(drain(&mut r1).decided, 1, "decided at once");
}

/// A member whose coordinator changed sends its contribution to the new
/// one at once; that one may not know yet that it leads (it has not heard
/// yet that the teammate before it left) and drops it, and the member's
/// next resend has backed off for seconds by then. The new coordinator
/// asks the members it has not heard from (`Query`) when it takes over: a
/// member answers with its contribution again. Found by
/// `no_waiting_across_levels` (RNG seed 244, graph seed
/// 7180224004388772354): the coordinator waited 3.3 s for a contribution
/// it had dropped and decided at its deadline.
#[test]
fn a_member_asked_by_its_coordinator_sends_its_contribution_again() {
    let mut r2 = robot_allocating_by("alloc.optimal", 2);
    let key = start(&mut r2);
    let contributions = |d: &Drained| -> Vec<Body> {
        (d.sent.iter())
            .filter(|(to, m)| *to == Recipients::One(RobotId(0)) && *m != Body::Query)
            .map(|(_, m)| m.clone())
            .collect()
    };
    // Its first tick sent the contribution to r0, the coordinator (drained
    // by `start`); r0 asks for it.
    r2.message(Time::from_millis(50), from(0, key, 1, Body::Query));
    let answered = drain(&mut r2);
    assert_eq!(
        contributions(&answered).len(),
        1,
        "r2 answers the query: {:?}",
        answered.sent
    );
    // A robot that is not its coordinator asks nothing of it.
    r2.message(Time::from_millis(60), from(1, key, 1, Body::Query));
    assert!(drain(&mut r2).sent.is_empty());
}

/// A robot that leads an allocation whose rule makes no call from its
/// start, only because the teammate before it left the behavior above,
/// asks once the members it has not heard: one may have sent its
/// contribution to the teammate that left, and left the allocation since.
/// A robot that leads because the teammate before it is presumed lost
/// asks nothing (every member learns of a loss and sends to it). Found by
/// `no_waiting_across_levels` (RNG seed 461, graph seed
/// 4293902327213708843, seven robots): the member had sent its value to
/// a coordinator that then completed the mission, and left the allocation;
/// the robot that led next waited for it until its deadline
/// (docs/reliability.md, "A contribution sent to a coordinator that
/// left").
#[test]
fn a_robot_leading_after_one_that_left_asks_who_it_has_not_heard() {
    use bite_core::TeamId;
    use bite_core::kernel::{Ended, FrameId, Position};
    const AFTER: &str = "graph: after\nteam: { robots: 3 }\nstart: root\n\
        defaults: { sync: sync.by-rule, allocate: alloc.by-id, terminate: term.local }\n\
        behaviors:\n  root: { team: true, children: [a], until: stop }\n\
        \x20 a: { team: true, skill: w, until: go, next: [p] }\n\
        \x20 p: { team: true, children: [x, y], allocate: alloc.optimal }\n\
        \x20 x: { team: true, skill: w }\n  y: { team: true, skill: w }\n";
    let t = Time::from_secs_f64;
    for r0_left in [true, false] {
        let g = load_str(&Arc::from("after.yaml"), AFTER).expect("the test graph loads");
        let root = g.find("root").expect("behavior");
        let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
        let mut r1 = Kernel::new(mission, RobotId(1), 2);
        let sym = r1.mission().graph().symbols().clone();
        let [go, stop] = ["go", "stop"].map(|n| sym.get(n).expect("belief"));
        r1.tick(
            Time::ZERO,
            &[(go, Value::Bool(false)), (stop, Value::Bool(false))],
        );
        if r0_left {
            // r0 is done with the mission (it left `root`).
            let root_ended = Ended {
                id: FrameId {
                    team: TeamId::ROOT,
                    behavior: root,
                    epoch: 1,
                },
                parent: None,
            };
            let done = Position {
                robot: RobotId(0),
                ended: vec![root_ended],
                ..Position::default()
            };
            r1.peer(t(0.2), RobotId(0), &done);
        } else {
            r1.member_lost(t(0.2), RobotId(0));
        }
        drain(&mut r1);
        r1.tick(t(0.3), &[(go, Value::Bool(true))]);
        let key = (drain(&mut r1).started.into_iter())
            .find(|k| k.kind == bite_core::ids::Kind::Allocate)
            .expect("p's allocation started");
        // Its retry interval later, it has heard no member.
        r1.tick(t(1.5), &[]);
        let asked = drain(&mut r1);
        let queried = (asked.sent.iter())
            .any(|(to, m)| *to == Recipients::One(RobotId(2)) && *m == Body::Query);
        assert_eq!(
            queried, r0_left,
            "r0 left: {r0_left}; sent {:?}",
            asked.sent
        );
        assert_eq!(asked.decided, 0, "it waits for r2");
        if r0_left {
            // Asked once only.
            r1.tick(t(3.5), &[]);
            let again = drain(&mut r1);
            assert!(!(again.sent.iter()).any(|(_, m)| *m == Body::Query));
            // r2 left `p` after sending its contribution to r0: it is done.
            r1.message(t(3.6), from(2, key, 1, Body::Done));
            assert_eq!(drain(&mut r1).decided, 1, "decided at once");
        }
    }
}

/// When the coordinator changes, the resend backoff starts over: a member
/// asks its new coordinator a retry later if no call came, and a robot
/// that takes over calls again, a retry later, the members it has not
/// heard, instead of waiting out the backoff its resends to the old
/// coordinator had reached (seconds by then). A member that had yet to
/// learn of the change dropped the new coordinator's first call, and the
/// coordinator waited for its deadline. Found by `no_waiting_across_levels`
/// (RNG seed 779, graph seed 8753189644158184162, eight robots:
/// `alloc.auction`) (docs/reliability.md, "A call dropped at a takeover").
#[test]
fn a_new_coordinator_and_its_members_talk_a_retry_after_the_change() {
    let t = Time::from_secs_f64;
    let to = |d: &Drained, r: u32, what: fn(&Body) -> bool| {
        (d.sent.iter()).any(|(rcpt, m)| {
            let reaches = match rcpt {
                Recipients::One(x) => *x == RobotId(r),
                Recipients::Team(set) => set.contains(RobotId(r)),
            };
            reaches && what(m)
        })
    };
    for me in [1, 2] {
        let mut k = robot_allocating_by("alloc.auction", me);
        start(&mut k);
        // r0 coordinates and says nothing: the robot's questions to it back
        // off (0.5, 1.5, 3.5 s...).
        for s in [0.5, 1.5, 3.5] {
            k.tick(t(s), &[]);
        }
        drain(&mut k);
        // r0 is lost at 3.6 s: r1 leads. Its call (r1), or the call r2
        // dropped (r2), leaves nothing to do until a retry later.
        k.member_lost(t(3.6), RobotId(0));
        drain(&mut k);
        k.tick(t(4.15), &[]);
        let after = drain(&mut k);
        if me == 1 {
            assert!(
                to(&after, 2, |m| matches!(m, Body::Call { .. })),
                "r1 calls r2 again: {:?}",
                after.sent
            );
        } else {
            assert!(
                to(&after, 1, |m| *m == Body::Query),
                "r2 asks r1: {:?}",
                after.sent
            );
        }
    }
}

/// A member of an `alloc.auction` whose coordinator changes asks the new
/// one for its call at once: the new coordinator's calls made while the
/// member still counted the old one were not its leader's then, and a
/// member that reached the point late, bid to the old one and learnt from
/// its answer that it had left, waited a retry for nothing while the new
/// coordinator's deadline fell. Found by `no_waiting_across_levels` (RNG
/// seed 2648, graph seed 12240106986188585820, seven robots)
/// (docs/reliability.md, "A member that found its coordinator gone at the
/// point").
#[test]
fn an_auction_member_asks_its_new_coordinator_at_once() {
    let t = Time::from_secs_f64;
    let mut k = robot_allocating_by("alloc.auction", 2);
    start(&mut k);
    k.tick(t(0.5), &[]);
    drain(&mut k);
    // r0, its coordinator, is lost: r1 leads, and is asked now.
    k.member_lost(t(0.6), RobotId(0));
    let now = drain(&mut k);
    assert!(
        (now.sent.iter())
            .any(|(rcpt, m)| *rcpt == Recipients::One(RobotId(1)) && *m == Body::Query),
        "r2 asks r1 at once: {:?}",
        now.sent
    );
}

/// Robot `me` of `robots` that run `p` (its children allocated by
/// `alloc.optimal`), then `z`, having started `p`'s allocation; and robot
/// 0's heartbeat from `z`#1, after `p`#1: it went past the allocation.
fn waiting_with_r0_past(me: u32, robots: usize) -> (Kernel, InstanceKey, Position) {
    let graph = format!(
        "graph: past\nteam: {{ robots: {robots} }}\nstart: p\n\
         defaults: {{ sync: sync.by-rule, allocate: alloc.optimal, terminate: term.local }}\n\
         behaviors:\n  p: {{ team: true, children: [x, y], until: stop, next: [z] }}\n\
         \x20 x: {{ team: true, skill: w }}\n  y: {{ team: true, skill: w }}\n\
         \x20 z: {{ team: true, skill: w, until: stop }}\n"
    );
    let g = load_str(&Arc::from("past.yaml"), &graph).expect("the test graph loads");
    let [p, z] = ["p", "z"].map(|n| g.find(n).expect("behavior"));
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut k = Kernel::new(mission, RobotId(me), u64::from(me) + 1);
    let key = start(&mut k);
    let past = Position {
        robot: RobotId(0),
        frames: vec![PosFrame {
            id: FrameId {
                team: TeamId::ROOT,
                behavior: z,
                epoch: 1,
            },
            anchor: Some(Anchor {
                behavior: p,
                epoch: 1,
                first: false,
            }),
            state: FrameState::Running,
            alloc: None,
            departed: None,
        }],
        ..Position::default()
    };
    (k, key, past)
}

/// A member waiting at an allocation asks its coordinator, once heard
/// running the successor of the allocation's execution, how the allocation
/// ended: it decided and left (its decision may have been lost), or it
/// left undecided (its own reason to end the behavior came first), which
/// it answers with `Done`. Only once it has been seen there for a retry:
/// its decision may still be on its way. Found by
/// `no_waiting_across_levels` (RNG seed 950, graph seed
/// 183384660120993347, seven robots): the coordinator reached the
/// allocation, sent its value to the robot it took for the coordinator,
/// and its condition ended the behavior in the next tick; the member
/// waited for its decision until the deadline (docs/reliability.md, "A
/// coordinator that left undecided, unheard").
#[test]
fn a_member_asks_its_coordinator_heard_past_the_allocation() {
    let (mut r1, key, past) = waiting_with_r0_past(1, 2);
    let queries = |d: &Drained| {
        (d.sent.iter())
            .filter(|s| **s == (Recipients::One(RobotId(0)), Body::Query))
            .count()
    };
    // r1 has waited a retry (500 ms) when it first sees r0 there.
    r1.peer(Time::from_millis(600), RobotId(0), &past);
    assert_eq!(queries(&drain(&mut r1)), 0, "first seen past: not yet");
    r1.peer(Time::from_millis(1100), RobotId(0), &past);
    let asked = drain(&mut r1);
    assert_eq!(queries(&asked), 1, "past for a retry: r1 asks r0");
    assert_eq!(asked.decided, 0);
    r1.message(Time::from_millis(1150), from(0, key, 1, Body::Done));
    assert_eq!(drain(&mut r1).decided, 1, "r0 left undecided: r1 decides");
}

/// A robot waiting at a point whose team's leader left the execution the
/// point belongs to sends its heartbeats to the member acting for the
/// leader too (the next by id), as it does while the leader is away from
/// the team: the leader relays nothing of that execution, and the members
/// still in it would not hear each other. In the case above (seed 950) the
/// member heard nothing of its coordinator, at work on its way, and its
/// deadline fell before it came.
#[test]
fn a_robot_waiting_where_its_leader_left_tells_the_member_acting_for_it() {
    let (mut r2, _, past) = waiting_with_r0_past(2, 3);
    let audience = |k: &Kernel| k.beacon_audience().iter().collect::<Vec<_>>();
    assert_eq!(audience(&r2), [RobotId(0)], "r2 tells its leader only");
    r2.peer(Time::from_millis(100), RobotId(0), &past);
    assert_eq!(audience(&r2), [RobotId(0), RobotId(1)], "r0 left `p`#1");
}

/// A member whose allocation's deadline falls while its coordinator is
/// heard out of the execution (here first seen running the successor just
/// before the deadline, too late to have been asked a retry after) asks it
/// how the allocation ended and waits two retries, instead of timing out:
/// the coordinator left, and nothing it sends will come unasked. Its
/// `Done` (it left undecided) lets the member decide without it, with no
/// deadline counted. Found by `no_waiting_across_levels` (RNG seed 343,
/// graph seed 12850264291869646365, seven robots): the coordinator became
/// coordinator when the one before was left out, half a second before the
/// deadline (docs/reliability.md, "A coordinator that left undecided,
/// heard").
#[test]
fn a_member_asks_its_coordinator_heard_out_of_the_allocation_at_the_deadline() {
    let (mut r1, key, past) = waiting_with_r0_past(1, 2);
    let p = r1.mission().graph().find("p").expect("p");
    let bound = r1.mission().bound(p, bite_core::ids::Kind::Allocate);
    let len = bound.expect("the allocation is bound").deadline;
    let deadline = Time(len.as_micros() as u64);
    let queries = |d: &Drained| {
        (d.sent.iter())
            .filter(|s| **s == (Recipients::One(RobotId(0)), Body::Query))
            .count()
    };
    let before = Time(deadline.0 - 200_000);
    r1.peer(before, RobotId(0), &past);
    assert_eq!(queries(&drain(&mut r1)), 0, "first seen past: not yet");
    r1.tick(deadline, &[]);
    let mut timed_out = 0;
    let mut asked = 0;
    while let Some(o) = r1.poll_output() {
        match o {
            Output::Event(Event::InteractionTimedOut { .. }) => timed_out += 1,
            Output::Send(s)
                if s.to == Recipients::One(RobotId(0)) && s.envelope.body == Body::Query =>
            {
                asked += 1
            }
            _ => {}
        }
    }
    assert_eq!(
        (asked, timed_out),
        (1, 0),
        "asked at the deadline, no timeout"
    );
    let answer = Time(deadline.0 + 50_000);
    r1.message(answer, from(0, key, 1, Body::Done));
    assert_eq!(drain(&mut r1).decided, 1, "r0 left undecided: r1 decides");
}

/// A member that applied its coordinator's decision answers a teammate
/// that asks it for the decision (a contribution or a `Query`): the
/// teammate reached the point later, after the coordinator had left, and
/// takes this robot for the coordinator. It got no answer and asked until
/// its deadline (property seed 4167, graph seed 4632419412741304454, four
/// robots: docs/reliability.md, "A member asked for a decision it
/// applied"). A member that has not had the decision keeps quiet, as
/// before: the sender's retries reach the coordinator when it knows it
/// leads.
#[test]
fn a_member_that_applied_the_decision_answers_a_teammate_that_asks_it() {
    let t = Time::from_secs_f64;
    let mut r1 = robot_allocating_by("alloc.optimal", 1);
    let key = start(&mut r1);
    drain(&mut r1);
    // r2 asks r1 before r1 has the decision: nothing to tell.
    r1.message(t(0.1), from(2, key, 1, Body::Query));
    assert_eq!(drain(&mut r1).sent, [], "no decision yet: r1 keeps quiet");
    // r0, the coordinator, decides and tells the team.
    let [x, y] = ["x", "y"].map(|n| r1.mission().graph().find(n).expect("child"));
    let decision = Body::Assignment {
        children: vec![x, y],
        members: vec![(RobotId(0), 0), (RobotId(1), 0), (RobotId(2), 1)],
    };
    r1.message(t(0.2), from(0, key, 1, decision.clone()));
    assert_eq!(drain(&mut r1).decided, 1, "r1 applies r0's decision");
    // r2, which takes r1 for the coordinator, asks again: it is told.
    r1.message(t(0.3), from(2, key, 2, Body::Query));
    assert_eq!(
        drain(&mut r1).sent,
        [(Recipients::One(RobotId(2)), decision)],
        "r1 answers r2 with the team's decision"
    );
}
