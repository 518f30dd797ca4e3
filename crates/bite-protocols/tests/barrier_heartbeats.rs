//! A barrier's leader and a member whose reports are all lost: the
//! member's heartbeats, which say it waits at the barrier, count as its
//! arrival once they have said so for a retry interval.

use bite_core::event::Event;
use bite_core::graph::load_str;
use bite_core::interaction::Recipients;
use bite_core::kernel::Output;
use bite_core::msg::Body;
use bite_core::time::Time;
use bite_core::{Kernel, Mission, RobotId, Value};
use std::sync::Arc;

/// Two robots work until each is done; the team ends the work together.
fn graph(terminate: &str) -> String {
    format!(
        "graph: barrier-heartbeats\nteam: {{ robots: 2 }}\nstart: work\n\
         defaults: {{ sync: sync.by-rule, allocate: alloc.by-id, terminate: {terminate} }}\n\
         behaviors:\n  work: {{ team: true, skill: work, until: done }}\n"
    )
}

fn robot(terminate: &str, me: u32) -> Kernel {
    let g = load_str(&Arc::from("barrier-heartbeats.yaml"), &graph(terminate))
        .expect("the test graph loads");
    let mission = Mission::new(g, &bite_protocols::registry()).expect("binds");
    let mut k = Kernel::new(Arc::new(mission), RobotId(me), u64::from(me) + 1);
    k.tick(Time::ZERO, &[]);
    k
}

fn done(k: &Kernel, v: bool) -> Vec<(bite_core::BeliefId, Value)> {
    let id = k.mission().graph().symbols().get("done").expect("belief");
    vec![(id, Value::Bool(v))]
}

/// What `k` sent and decided since the last call: (acks to robot 1, the
/// barrier decided, and whether by its deadline).
fn drain(k: &mut Kernel) -> (usize, Option<bool>) {
    let (mut acks, mut decided) = (0, None);
    while let Some(o) = k.poll_output() {
        match o {
            Output::Send(s)
                if s.envelope.body == Body::Ack && s.to == Recipients::One(RobotId(1)) =>
            {
                acks += 1
            }
            Output::Event(Event::InteractionDecided { timed_out, .. }) => decided = Some(timed_out),
            _ => {}
        }
    }
    (acks, decided)
}

/// The leader (robot 0) is done at 1 s; robot 1 at 1.5 s. None of robot
/// 1's messages reach the leader, its heartbeats do (four a second, from
/// `from`), saying what it runs: the leader releases the team once they
/// have said for a retry interval (0.5 s) that robot 1 waits at the
/// barrier, as if its report had come, and acknowledges it; heartbeats
/// that say robot 1 still works release no one.
fn leader_hearing(terminate: &str, member_done: bool) -> Option<(f64, bool, usize)> {
    let (mut leader, mut member) = (robot(terminate, 0), robot(terminate, 1));
    let mut acks = 0;
    for j in 1..=200 {
        let t = f64::from(j) * 0.05;
        let now = Time::from_secs_f64(t);
        if j % 2 == 0 {
            leader.tick(now, &done(&leader, t >= 1.0));
            member.tick(now, &done(&member, member_done && t >= 1.5));
            // Robot 1's messages are all lost.
            while member.poll_output().is_some() {}
        }
        if j % 5 == 0 {
            leader.peer(now, RobotId(1), &member.position());
        }
        let (a, decided) = drain(&mut leader);
        acks += a;
        if let Some(timed_out) = decided {
            return Some((t, timed_out, acks));
        }
    }
    None
}

#[test]
fn a_barrier_counts_a_member_its_heartbeats_show_waiting() {
    // (`term.first-wins` does not wait here: both robots end `work` by its
    // condition, and the first to see it releases the team itself.)
    for terminate in ["term.wait-all", "term.majority", "graph.wait-all"] {
        let (at, timed_out, acks) = leader_hearing(terminate, true)
            .unwrap_or_else(|| panic!("{terminate}: the leader never released the team"));
        assert!(!timed_out, "{terminate}: released by its deadline");
        // Robot 1 began to wait at 1.5 s; its heartbeats said so from the
        // next one (1.75 s), and for a retry interval from 2.25 s.
        assert!((2.0..=2.6).contains(&at), "{terminate}: released at {at} s");
        // (The graph-written barrier has no acknowledgement: its members
        // resend their report until released.)
        let expected = if terminate.starts_with("graph.") {
            0
        } else {
            1
        };
        assert_eq!(acks, expected, "{terminate}: acknowledged once");
        // Heartbeats of a member that still works: no release before the
        // deadline (30 s, past the 10 s this test runs).
        assert_eq!(leader_hearing(terminate, false), None, "{terminate}");
    }
}
