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
    decided: Vec<String>,
}

fn drain(k: &mut Kernel) -> Drained {
    let mut d = Drained::default();
    while let Some(o) = k.poll_output() {
        match o {
            Output::Send(s) => d.sent.push((s.to, s.envelope.body)),
            Output::Event(Event::InteractionStarted { instance, .. }) => d.started = Some(instance),
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
