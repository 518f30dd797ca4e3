//! A robot whose kernel applied the team's decision from a teammate's
//! notice (`Missed`: the team decided without this robot while it presumed
//! the sender lost) holds that decision in its protocol instance too: when
//! it then leads the instance, it answers teammates with the decision it
//! applied and never decides, or announces, another.

use bite_core::event::Event;
use bite_core::graph::load_str;
use bite_core::interaction::Recipients;
use bite_core::kernel::Output;
use bite_core::msg::{Body, InstanceKey};
use bite_core::time::Time;
use bite_core::{BehaviorId, Kernel, Mission, RobotId, Value};
use std::sync::Arc;

mod common;
use common::from;

/// Three robots run `a` until `go`, then vote between `b` and `c`.
const GRAPH: &str = "graph: notice\nteam: { robots: 3 }\nstart: a\n\
    defaults: { sync: sync.vote, allocate: alloc.by-id, terminate: term.local }\n\
    behaviors:\n  a: { team: true, skill: w, until: go, next: [b, c] }\n\
    \x20 b: { team: true, skill: w }\n  c: { team: true, skill: w }\n";

/// What the kernel sent (to whom, what) and the sync points it started and
/// decided since the last call.
#[derive(Default)]
struct Drained {
    sent: Vec<(Recipients, Body)>,
    started: Option<InstanceKey>,
    /// Who the last instance started left out.
    left_out: Vec<RobotId>,
    decided: Vec<String>,
}

fn drain(k: &mut Kernel) -> Drained {
    let mut d = Drained::default();
    while let Some(o) = k.poll_output() {
        match o {
            Output::Send(s) => d.sent.push((s.to, s.envelope.body)),
            Output::Event(Event::InteractionStarted {
                instance, excluded, ..
            }) => {
                d.started = Some(instance);
                d.left_out = excluded;
            }
            Output::Event(e @ Event::InteractionDecided { .. }) => d.decided.push(format!("{e:?}")),
            Output::Event(_) => {}
        }
    }
    d
}

/// r1's kernel on `GRAPH`, ticked once in `a`: the kernel, the belief
/// `go`, and the behaviors `b` and `c`.
fn r1_of_three() -> (Kernel, bite_core::BeliefId, BehaviorId, BehaviorId) {
    let g = load_str(&Arc::from("notice.yaml"), GRAPH).expect("the test graph loads");
    let (b, c): (BehaviorId, BehaviorId) = (g.find("b").expect("b"), g.find("c").expect("c"));
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut r1 = Kernel::new(mission, RobotId(1), 2);
    let go = r1.mission().graph().symbols().get("go").expect("belief");
    r1.tick(Time::ZERO, &[(go, Value::Bool(false))]);
    (r1, go, b, c)
}

#[test]
fn a_robot_that_applied_the_teams_decision_leads_with_it() {
    let (mut r1, go, b, c) = r1_of_three();
    let t = Time::from_secs_f64;
    // r0 presumed lost a while, then heard again.
    r1.member_lost(t(0.1), RobotId(0));
    r1.member_back(t(0.2), RobotId(0));
    drain(&mut r1);
    // `a` ends: the vote starts, r0 leads it and calls; r1 votes.
    r1.tick(t(0.3), &[(go, Value::Bool(true))]);
    let key = drain(&mut r1).started.expect("the vote started");
    let propose = Body::Propose {
        candidates: vec![b, c],
    };
    r1.message(t(0.31), from(0, key, 1, propose));
    let voted = drain(&mut r1);
    assert!(
        voted
            .sent
            .iter()
            .any(|(to, m)| *to == Recipients::One(RobotId(0)) && matches!(m, Body::Vote { .. })),
        "r1 votes: {:?}",
        voted.sent
    );
    // r0's notice: the team (r0 and r2, while r0 presumed r1 lost) chose
    // `c`. r1's kernel applies it.
    let missed = Body::Missed {
        choice: Some(c),
        children: Vec::new(),
        members: Vec::new(),
    };
    r1.message(t(0.32), from(0, key, 2, missed));
    let applied = drain(&mut r1);
    assert_eq!(applied.decided.len(), 1, "{:?}", applied.decided);
    // r0 is presumed lost again: r1 leads the vote now. r2 votes `b`.
    r1.member_lost(t(0.33), RobotId(0));
    let led = drain(&mut r1);
    r1.message(t(0.34), from(2, key, 1, Body::Vote { choice: Some(b) }));
    let answered = drain(&mut r1);
    let decisions: Vec<&(Recipients, Body)> = (led.sent.iter())
        .chain(&answered.sent)
        .filter(|(_, m)| matches!(m, Body::Decision { .. }))
        .collect();
    assert!(
        decisions
            .iter()
            .all(|(_, m)| *m == Body::Decision { choice: Some(c) }),
        "r1 announced a decision it did not apply: {decisions:?}"
    );
    assert!(
        (answered.sent.iter()).any(|(to, m)| *to == Recipients::One(RobotId(2))
            && *m == Body::Decision { choice: Some(c) }),
        "r1 answers r2 with the decision it applied: {:?}",
        answered.sent
    );
    assert!(
        led.decided.is_empty() && answered.decided.is_empty(),
        "decided once: {:?} {:?}",
        led.decided,
        answered.decided
    );
}

/// A leader waiting at a `term.wait-all` barrier hears that the team
/// ended the behavior without it (a notice from a teammate it presumed
/// lost, which led the others meanwhile and released them at its
/// deadline). Its members still working take releases only from the
/// leader they follow — this robot — so it tells them, and keeps telling
/// them until they confirm. Found at 12 robots (configuration 6, a
/// partition, seed 2): half the team stayed in `triangle` for good while
/// the rest went on to `line` (docs/reliability.md, "A release no member
/// heard").
#[test]
fn a_leader_that_applied_the_teams_end_releases_its_members_still_working() {
    const WAIT: &str = "graph: released\nteam: { robots: 3 }\nstart: a\n\
        defaults: { sync: sync.by-rule, allocate: alloc.by-id, terminate: term.wait-all }\n\
        behaviors:\n  a: { team: true, skill: w, until: go, next: [b] }\n\
        \x20 b: { team: true, skill: w }\n";
    let g = load_str(&Arc::from("released.yaml"), WAIT).expect("the test graph loads");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut r0 = Kernel::new(mission, RobotId(0), 3);
    let go = r0.mission().graph().symbols().get("go").expect("belief");
    let t = Time::from_secs_f64;
    r0.tick(t(0.0), &[(go, Value::Bool(false))]);
    // r1 presumed lost a while (it led r2 meanwhile), then heard again.
    r0.member_lost(t(0.1), RobotId(1));
    r0.member_back(t(0.2), RobotId(1));
    drain(&mut r0);
    // r0 ends `a` and waits at the barrier it leads; r2 still works.
    r0.tick(t(0.3), &[(go, Value::Bool(true))]);
    let key = drain(&mut r0).started.expect("the barrier started");
    // r1's notice: the team ended `a` without r0.
    let missed = Body::Missed {
        choice: None,
        children: Vec::new(),
        members: Vec::new(),
    };
    r0.message(t(0.4), from(1, key, 1, missed));
    let told = drain(&mut r0);
    assert_eq!(told.decided.len(), 1, "{:?}", told.decided);
    let released = |sent: &[(Recipients, Body)]| {
        sent.iter().any(|(to, m)| {
            *m == Body::Release { next: None }
                && match to {
                    Recipients::One(r) => *r == RobotId(2),
                    Recipients::Team(s) => s.contains(RobotId(2)),
                }
        })
    };
    assert!(released(&told.sent), "r2 is released: {:?}", told.sent);
    // Told again until it confirms.
    r0.tick(t(2.0), &[(go, Value::Bool(true))]);
    assert!(released(&drain(&mut r0).sent), "r2 is told again");
}

/// A robot that leads an instance from its start only because the
/// teammate before it is left out (here presumed lost; in the case found,
/// it had left the behavior after deciding its allocation) takes over from
/// it: the decision a member applied, and tells it (a late reply to its
/// call), is the team's. It adopts and announces it. Found with eight
/// robots (graph seed 15936183023725379530): four robots a lap behind
/// started an auction the leader had decided before leaving; the new
/// leader heard the decision from the two teammates that applied it,
/// ignored it, and waited them out until its deadline
/// (docs/reliability.md, "A decision made before the late arrivals
/// came").
#[test]
fn a_robot_leading_because_its_leader_left_adopts_the_decision_a_member_applied() {
    let (mut r1, go, _, c) = r1_of_three();
    let t = Time::from_secs_f64;
    r1.member_lost(t(0.1), RobotId(0));
    drain(&mut r1);
    // `a` ends: the vote starts with r0 left out, so r1 leads it.
    r1.tick(t(0.3), &[(go, Value::Bool(true))]);
    let started = drain(&mut r1);
    let key = started.started.expect("the vote started");
    let syncs = |d: &Drained| -> Vec<String> {
        (d.decided.iter())
            .filter(|e| e.contains("kind: Sync"))
            .cloned()
            .collect()
    };
    assert!(syncs(&started).is_empty(), "{:?}", started.decided);
    // r2 answers the call with the decision it applied (r0's).
    r1.message(t(0.31), from(2, key, 1, Body::Decision { choice: Some(c) }));
    let adopted = drain(&mut r1);
    let decided = syncs(&adopted);
    assert_eq!(decided.len(), 1, "r1 decides: {:?}", adopted.sent);
    assert!(
        decided[0].contains(&format!("choice: Some({c:?})")),
        "r1 adopts r2's decision: {:?}",
        adopted.decided
    );
    assert!(
        (adopted.sent.iter()).any(|(_, m)| *m == Body::Decision { choice: Some(c) }),
        "r1 announces it: {:?}",
        adopted.sent
    );
}

/// [`GRAPH`] under a root behavior: the vote after `a` runs under `root`.
const UNDER_ROOT: &str = "graph: left\nteam: { robots: 3 }\nstart: root\n\
    defaults: { sync: sync.vote, allocate: alloc.by-id, terminate: term.local }\n\
    behaviors:\n  root: { team: true, children: [a] }\n\
    \x20 a: { team: true, skill: w, until: go, next: [b, c] }\n\
    \x20 b: { team: true, skill: w }\n  c: { team: true, skill: w }\n";

/// Robot `me` of [`UNDER_ROOT`]'s three, ticked once in `a`, that then
/// heard its teammate r0 decide the vote after `a` for `c` (the message
/// waits: the vote has not started here) and then finish the mission (so
/// r0 left `root`: it is left out of the vote here, not presumed lost).
/// Returns the kernel, the belief `go`, `c`, and the vote's key.
fn after_r0_decided_and_left(me: u32) -> (Kernel, bite_core::BeliefId, BehaviorId, InstanceKey) {
    let (mut k, go, c, key, done) = after_r0_left(UNDER_ROOT, me, true);
    k.peer(Time::from_secs_f64(0.2), RobotId(0), &done);
    drain(&mut k);
    (k, go, c, key)
}

/// As [`after_r0_decided_and_left`], on `graph` (which has [`UNDER_ROOT`]'s
/// behaviors), the decision heard only if `told`, and r0's heartbeat
/// that shows it done with the mission returned, not heard yet.
fn after_r0_left(
    graph: &str,
    me: u32,
    told: bool,
) -> (
    Kernel,
    bite_core::BeliefId,
    BehaviorId,
    InstanceKey,
    bite_core::kernel::Position,
) {
    use bite_core::TeamId;
    use bite_core::msg::Kind;
    let g = load_str(&Arc::from("left.yaml"), graph).expect("the test graph loads");
    let [root, a, c] = ["root", "a", "c"].map(|n| g.find(n).expect("behavior"));
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut k = Kernel::new(mission, RobotId(me), u64::from(me) + 1);
    let go = k.mission().graph().symbols().get("go").expect("belief");
    let t = Time::from_secs_f64;
    k.tick(Time::ZERO, &[(go, Value::Bool(false))]);
    let key = InstanceKey {
        team: TeamId::ROOT,
        behavior: a,
        kind: Kind::Sync,
        epoch: 1,
        round: 0,
    };
    if told {
        k.message(t(0.1), from(0, key, 1, Body::Decision { choice: Some(c) }));
    }
    let done = finished(root, c);
    drain(&mut k);
    (k, go, c, key, done)
}

/// r0's heartbeat once it ended `last` (the first execution of a behavior
/// under the root) and then `root`: it finished the mission, so it left
/// every behavior.
fn finished(root: BehaviorId, last: BehaviorId) -> bite_core::kernel::Position {
    use bite_core::TeamId;
    use bite_core::kernel::{Ended, FrameId, Position};
    let id = |behavior| FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch: 1,
    };
    Position {
        robot: RobotId(0),
        ended: vec![
            Ended {
                id: id(last),
                parent: Some(id(root)),
            },
            Ended {
                id: id(root),
                parent: None,
            },
        ],
        ..Position::default()
    }
}

/// The vote `key` started with r0 left out (it left: this robot's
/// instance does not count it), and the synchronizations decided with it.
fn started_without_r0(d: &mut Drained, key: InstanceKey) {
    assert_eq!(d.started, Some(key), "the vote started");
    assert_eq!(d.left_out, [RobotId(0)], "r0 left: it is left out");
    d.decided.retain(|e| e.contains("kind: Sync"));
}

/// A robot that reaches a point its coordinator decided before leaving the
/// behavior, and coordinates it now (the one before it left), applies the
/// decision that waited for it instead of deciding anew. Found by
/// `no_waiting_across_levels` (RNG seed 169, graph seed
/// 15129041871835573196, eight robots, no faults): the new coordinator
/// chose to end the chain while the members the old one had told went to
/// its successor (docs/reliability.md, "A decision from a leader that
/// left").
#[test]
fn a_coordinator_applies_the_decision_its_predecessor_made_and_left_with() {
    let (mut r1, go, c, key) = after_r0_decided_and_left(1);
    r1.tick(Time::from_secs_f64(0.3), &[(go, Value::Bool(true))]);
    let mut d = drain(&mut r1);
    started_without_r0(&mut d, key);
    assert_eq!(d.decided.len(), 1, "decided at once: {:?}", d.sent);
    assert!(
        d.decided[0].contains(&format!("choice: Some({c:?})")),
        "r1 applies r0's decision: {:?}",
        d.decided
    );
    assert!(
        d.sent.iter().all(|(_, m)| match m {
            Body::Propose { .. } => false,
            Body::Decision { choice } => *choice == Some(c),
            _ => true,
        }),
        "no vote of its own: {:?}",
        d.sent
    );
}

/// A member that heard the decision of a teammate before its coordinator,
/// which left the behavior with it, follows its coordinator; if it comes
/// to coordinate (the coordinator presumed lost), it adopts and announces
/// that decision instead of deciding anew. Found by
/// `no_waiting_across_levels` (RNG seed 75, graph seed
/// 10533492770770632144, seven robots, no faults). A member does not adopt
/// it while it has a coordinator: under loss that coordinator may not have
/// heard it, and decided anew (seed 113, 27 % loss).
#[test]
fn a_member_adopts_the_decision_of_a_leader_that_left_once_it_leads() {
    let (mut r2, go, c, key) = after_r0_decided_and_left(2);
    let t = Time::from_secs_f64;
    r2.tick(t(0.3), &[(go, Value::Bool(true))]);
    let mut d = drain(&mut r2);
    started_without_r0(&mut d, key);
    assert!(d.decided.is_empty(), "r1 coordinates: {:?}", d.decided);
    r2.member_lost(t(0.4), RobotId(1));
    let led = drain(&mut r2);
    assert_eq!(led.decided.len(), 1, "r2 decides: {:?}", led.sent);
    assert!(
        led.decided[0].contains(&format!("choice: Some({c:?})")),
        "r2 adopts r0's decision: {:?}",
        led.decided
    );
    assert!(
        (led.sent.iter()).any(|(_, m)| *m == Body::Decision { choice: Some(c) }),
        "and announces it: {:?}",
        led.sent
    );
}

/// A robot that leads a point after the teammate before it left the
/// behavior, that teammate having run the point's execution, leaves the
/// point itself (its `root` ends) without deciding if it has not heard
/// that teammate's decision: a decision of its own, announced as it left,
/// parted the members that applied it from those that had the old one.
/// Found by `random_teams_survive_network_faults` (RNG seed 196, graph
/// seed 12199998743731976875, five robots, 2.5 % loss, 126 ms jitter) for
/// a robot that took the lead once the point had started: the old
/// coordinator's heartbeat overtook its announcement (docs/reliability.md,
/// "A coordinator that took over and left"); and again (RNG seeds 686, 718
/// and 748) for a robot that led from the start, the teammate before it
/// having left after running the point, with its announcement still on
/// the way (docs/reliability.md, "A coordinator after one that left, from
/// the start"). A robot that leads because the teammate before it is
/// presumed lost, or left without running the point, decides as it
/// leaves: nobody before it decided, and members that came later waited
/// for a coordinator that had gone (RNG seed 76).
#[test]
fn a_coordinator_after_one_that_left_leaves_without_deciding() {
    use bite_core::kernel::{Ended, FrameId};
    const ROOT_ENDS: &str = "graph: left\nteam: { robots: 3 }\nstart: root\n\
        defaults: { sync: sync.vote, allocate: alloc.by-id, terminate: term.local }\n\
        behaviors:\n  root: { team: true, children: [a], until: stop }\n\
        \x20 a: { team: true, skill: w, until: go, next: [b, c] }\n\
        \x20 b: { team: true, skill: w }\n  c: { team: true, skill: w }\n";
    let t = Time::from_secs_f64;
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum R0 {
        /// Ran `a` (and decided its vote), then left: heard before the
        /// vote starts here (r1 leads from the start) or after (r1 takes
        /// over).
        LeftBefore,
        LeftAfter,
        /// Ran `a` and left, heard after r1 ended `a` but before the vote
        /// starts (r1 waits for the team's end of `a`, under
        /// `term.wait-all`): the vote starts only once `a` has ended here.
        LeftWhileEnding,
        /// Left without running `a` (its heartbeat lists only `root`).
        LeftWithoutRunning,
        LostBefore,
    }
    let waiting_end = ROOT_ENDS.replace("until: go,", "until: go, terminate: term.wait-all,");
    for r0 in [
        R0::LeftBefore,
        R0::LeftAfter,
        R0::LeftWhileEnding,
        R0::LeftWithoutRunning,
        R0::LostBefore,
    ] {
        let graph = match r0 {
            R0::LeftWhileEnding => waiting_end.as_str(),
            _ => ROOT_ENDS,
        };
        let (mut r1, go, _, key, mut done) = after_r0_left(graph, 1, false);
        let stop = r1.mission().graph().symbols().get("stop").expect("belief");
        let ran_a = Ended {
            id: FrameId::of(key),
            parent: done.ended.last().map(|e| e.id),
        };
        match r0 {
            R0::LeftWithoutRunning => done.ended.retain(|e| e.parent.is_none()),
            _ => done.ended.insert(0, ran_a),
        }
        match r0 {
            R0::LeftBefore | R0::LeftWithoutRunning => r1.peer(t(0.2), RobotId(0), &done),
            R0::LostBefore => r1.member_lost(t(0.2), RobotId(0)),
            R0::LeftAfter | R0::LeftWhileEnding => {}
        }
        let go_on = [(go, Value::Bool(true)), (stop, Value::Bool(false))];
        r1.tick(t(0.3), &go_on);
        let mut d = drain(&mut r1);
        if r0 == R0::LeftWhileEnding {
            let end = InstanceKey {
                kind: bite_core::msg::Kind::Terminate,
                ..key
            };
            assert_eq!(d.started, Some(end), "r1 waits for the team to end `a`");
            r1.peer(t(0.32), RobotId(0), &done);
            r1.message(t(0.34), from(2, end, 1, Body::Done));
            d = drain(&mut r1);
        }
        assert_eq!(d.started, Some(key), "the vote started");
        if r0 == R0::LeftAfter {
            r1.peer(t(0.35), RobotId(0), &done);
            d.decided.extend(drain(&mut r1).decided);
        }
        d.decided.retain(|e| e.contains("kind: Sync"));
        assert!(
            d.decided.is_empty(),
            "r1 waits for r2's vote: {:?}",
            d.decided
        );
        // `root` ends for r1: it leaves the vote.
        r1.tick(t(0.4), &[(stop, Value::Bool(true))]);
        let left = drain(&mut r1);
        let announced = (left.sent.iter()).any(|(_, m)| matches!(m, Body::Decision { .. }));
        assert_eq!(
            announced,
            matches!(r0, R0::LostBefore | R0::LeftWithoutRunning),
            "r0 {r0:?}; r1 sent {:?}",
            left.sent
        );
    }
}

/// A member that counts out a teammate that left the behavior (here it
/// finished the mission) takes that teammate's release of the behavior's
/// end, and confirms it: the teammate led the end in its view and the team
/// went on with it, while this robot's leader at the point is another.
/// Found by `no_waiting_across_levels` (RNG seed 1008, graph seed
/// 16345115294303735707, eight robots, no faults): r5 came to `b3`#3 0.8 s
/// after r1 released the team (`term.majority`), counted r1 out, ignored
/// its release 40 times and ran `b3`#3 85 s after its team had ended it
/// (docs/reliability.md, "A release from a teammate that left").
/// Robot `me`'s kernel on a team of `robots` that runs `a` under `root`
/// until `go`, `a` ended by `terminate`, ticked once with `go` false: the
/// kernel, the belief `go`, and the behaviors `root` and `a`.
fn one_barrier(
    robots: usize,
    terminate: &str,
    me: u32,
) -> (Kernel, bite_core::BeliefId, BehaviorId, BehaviorId) {
    let text = format!(
        "graph: barrier\nteam: {{ robots: {robots} }}\nstart: root\n\
        defaults: {{ sync: sync.vote, allocate: alloc.by-id, terminate: term.local }}\n\
        behaviors:\n  root: {{ team: true, children: [a] }}\n\
        \x20 a: {{ team: true, skill: w, until: go, terminate: {terminate} }}\n"
    );
    let g = load_str(&Arc::from("barrier.yaml"), &text).expect("the test graph loads");
    let [root, a] = ["root", "a"].map(|n| g.find(n).expect("behavior"));
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut k = Kernel::new(mission, RobotId(me), u64::from(me) + 1);
    let go = k.mission().graph().symbols().get("go").expect("belief");
    k.tick(Time::ZERO, &[(go, Value::Bool(false))]);
    drain(&mut k);
    (k, go, root, a)
}

/// The termination of behavior `a`'s first execution by the root team.
fn end_of(a: BehaviorId) -> InstanceKey {
    InstanceKey {
        team: bite_core::TeamId::ROOT,
        behavior: a,
        kind: bite_core::msg::Kind::Terminate,
        epoch: 1,
        round: 0,
    }
}

#[test]
fn a_member_takes_the_release_of_a_teammate_that_left() {
    let (mut r2, _, root, a) = one_barrier(3, "term.majority", 2);
    let t = Time::from_secs_f64;
    // r0 ended `a` with the team and finished the mission: it left.
    r2.peer(t(0.1), RobotId(0), &finished(root, a));
    drain(&mut r2);
    let key = end_of(a);
    r2.message(t(0.2), from(0, key, 1, Body::Release { next: None }));
    let d = drain(&mut r2);
    assert!(
        (d.decided.iter()).any(|e| e.contains("term.majority") && e.contains("Terminate")),
        "r2 ends `a`: {:?}",
        d.decided
    );
    assert!(
        d.sent
            .iter()
            .any(|(to, m)| *m == Body::Ack && *to == Recipients::One(RobotId(0))),
        "and confirms to r0: {:?}",
        d.sent
    );
}

/// A barrier's leader whose deadline falls while a member it counts was
/// last heard waiting at the barrier counts it arrived and releases the
/// team: the member is not silent, its report went elsewhere (to a leader
/// it did not know had left) or was lost. Before, the barrier timed out
/// (found by `no_waiting_across_levels`, RNG seed 1016, graph seed
/// 10985443681506886131: the deadline fell 30 ms before the member found
/// its leader). Heard waiting for less than a retry, the member is not
/// counted before the deadline: its report, not its heartbeat, is read
/// first in a run without faults.
#[test]
fn a_member_heard_waiting_at_the_barrier_when_the_deadline_falls_has_arrived() {
    use bite_core::TeamId;
    use bite_core::kernel::{FrameId, FrameState, PosFrame, Position};
    let (mut r0, go, root, a) = one_barrier(2, "term.wait-all", 0);
    let t = Time::from_secs_f64;
    r0.tick(t(0.1), &[(go, Value::Bool(true))]);
    let d = drain(&mut r0);
    let key = end_of(a);
    assert_eq!(d.started, Some(key), "r0 waits at `a`'s barrier");
    // `term.wait-all`'s deadline: 30 s from the start.
    let deadline = t(30.1);
    // r1 is heard once, just before the deadline, waiting at the barrier.
    let id = |behavior| FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch: 1,
    };
    let frame = |behavior, state, anchor| PosFrame {
        id: id(behavior),
        anchor,
        state,
        alloc: None,
        departed: None,
    };
    let waiting = Position {
        robot: RobotId(1),
        frames: vec![
            frame(root, FrameState::Running, None),
            frame(
                a,
                FrameState::Ending,
                Some(bite_core::kernel::Anchor {
                    behavior: root,
                    epoch: 1,
                    first: true,
                }),
            ),
        ],
        ..Position::default()
    };
    r0.peer(t(30.0), RobotId(1), &waiting);
    assert!(
        drain(&mut r0).decided.is_empty(),
        "not counted before the deadline"
    );
    r0.timer(deadline);
    let d = drain(&mut r0);
    assert!(
        (d.decided.iter()).any(|e| e.contains("term.wait-all") && e.contains("timed_out: false")),
        "r0 releases the team without a timeout: {:?}",
        d.decided
    );
}

/// Two robots loop through `a`, whose ends are decided by `term.majority`;
/// r0's kernel alone, with r1 presumed lost. A majority of the pair is
/// both, so the first barrier waits for its deadline. That deadline
/// decided without r1, which is then given up (`Cx::is_given_up`): the
/// next barrier is a majority of the one robot not given up, decided at
/// once. Heard again, r1 counts again and the barrier after waits for it.
#[test]
fn a_teammate_a_deadline_decided_without_is_out_of_the_majority_until_heard_again() {
    let text = "graph: pair\nteam: { robots: 2 }\nstart: root\n\
        defaults: { sync: sync.leader, allocate: alloc.by-id, terminate: term.majority }\n\
        behaviors:\n  root: { team: true, children: [a] }\n\
        \x20 a: { team: true, skill: w, until: go, next: [a] }\n";
    let g = load_str(&Arc::from("pair.yaml"), text).expect("the test graph loads");
    let mission = Arc::new(Mission::new(g, &bite_protocols::registry()).expect("binds"));
    let mut r0 = Kernel::new(mission, RobotId(0), 1);
    let go = r0.mission().graph().symbols().get("go").expect("belief");
    let t = Time::from_secs_f64;
    // Events since the last call: terminations decided, deadlines fallen.
    let ends = |k: &mut Kernel| {
        let (mut decided, mut timed_out) = (0, 0);
        while let Some(o) = k.poll_output() {
            match o {
                Output::Event(Event::InteractionDecided { instance, .. })
                    if instance.kind == bite_core::msg::Kind::Terminate =>
                {
                    decided += 1
                }
                Output::Event(Event::InteractionTimedOut { .. }) => timed_out += 1,
                _ => {}
            }
        }
        (decided, timed_out)
    };
    // One lap: `a` runs, then its end.
    let lap = |k: &mut Kernel, at: f64| {
        k.tick(t(at), &[(go, Value::Bool(false))]);
        k.tick(t(at + 1.0), &[(go, Value::Bool(true))]);
    };
    r0.tick(t(0.0), &[(go, Value::Bool(false))]);
    r0.member_lost(t(0.5), RobotId(1));
    ends(&mut r0);
    lap(&mut r0, 1.0);
    assert_eq!(ends(&mut r0), (0, 0), "a minority of the pair waits");
    r0.timer(t(40.0));
    assert_eq!(ends(&mut r0), (1, 1), "its deadline decides");
    lap(&mut r0, 41.0);
    assert_eq!(ends(&mut r0), (1, 0), "r1 given up: decided at once");
    r0.member_back(t(45.0), RobotId(1));
    lap(&mut r0, 46.0);
    assert_eq!(ends(&mut r0), (0, 0), "r1 heard again: waited for");
}
