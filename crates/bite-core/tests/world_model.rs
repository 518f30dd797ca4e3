//! The collaborative world model (Algorithms 2 and 3) on hand-built
//! situations: one robot's kernel driven to a known stack, then who its
//! world model informs, about what, and who it does not.

use bite_core::belief::Source;
use bite_core::graph::load_str;
use bite_core::interaction::Registry;
use bite_core::time::Time;
use bite_core::wm::{Inform, Outgoing, Policy, Reason, Report, Sharing, WorldModel};
use bite_core::{BeliefId, Kernel, Mission, RobotId, Value};
use std::sync::Arc;

/// Three robots in a triangle (lead / follow_left / follow_right); the
/// formation ends at the obstacle (`triangle.until`, on every stack), the
/// leader's own leg ends at `gap` (a condition of the lead subteam only),
/// and `regroup` may follow when `clear`.
const GRAPH: &str = r#"
graph: wm-test
team: { robots: 3 }
start: escort
defaults: { sync: sync.by-rule, allocate: alloc.by-id, terminate: term.local }
behaviors:
  escort: { team: true, children: [triangle] }
  triangle:
    team: true
    children: [lead, follow_left, follow_right]
    until: obstacle
    next: [regroup]
  regroup: { team: true, skill: regroup, pre: clear }
  lead: { skill: walk, members: 1, until: gap }
  follow_left: { skill: keep_slot, members: 1, until: left_done }
  follow_right: { skill: keep_slot, members: 1, until: right_done }
"#;

struct Robot {
    kernel: Kernel,
    wm: WorldModel,
}

fn id(k: &Kernel, name: &str) -> BeliefId {
    k.mission()
        .graph()
        .symbols()
        .get(name)
        .expect("a belief of the graph")
}

/// Robot `me` of the test graph, its kernel ticked once (alloc.by-id puts
/// r0 on `lead`, r1 on `follow_left`, r2 on `follow_right`), with a world
/// model of the given policy; `private` names beliefs about itself.
fn robot(me: u32, policy: Policy, budget: Option<f64>, private: &[&str]) -> Robot {
    let g = load_str(&Arc::from("wm-test.yaml"), GRAPH).expect("the test graph loads");
    let n = g.symbols().len();
    let mission = Arc::new(Mission::new(g, &Registry::core()).expect("binds"));
    let mut kernel = Kernel::new(mission, RobotId(me), 1);
    kernel.tick(Time::ZERO, &[]);
    let mut p = vec![false; n];
    for name in private {
        p[id(&kernel, name).index()] = true;
    }
    let sharing = Sharing {
        policy,
        hz: 10.0,
        budget,
    };
    Robot {
        wm: WorldModel::new(RobotId(me), n, sharing, Arc::from(p)),
        kernel,
    }
}

impl Robot {
    /// Percepts at `t` seconds through the world model into the kernel,
    /// then the world model decides what to share (before the kernel acts).
    fn sense(&mut self, t: f64, percepts: &[(&str, Value)]) -> Vec<Outgoing> {
        let now = Time::from_secs_f64(t);
        let ps: Vec<(BeliefId, Value)> = percepts
            .iter()
            .map(|(n, v)| (id(&self.kernel, n), v.clone()))
            .collect();
        let (mut own, mut told) = (Vec::new(), Vec::new());
        self.wm.perceive(now, &ps, &mut own, &mut told);
        for (b, v, s) in told {
            self.kernel.set_belief(b, v, s);
        }
        self.kernel.observe(now, &own);
        if self.wm.due(now) {
            self.wm.share(now, &self.kernel);
        }
        let mut out = Vec::new();
        while let Some(o) = self.wm.poll(now) {
            out.push(o);
        }
        out
    }

    fn leaf(&self) -> String {
        let k = &self.kernel;
        k.leaf()
            .map(|f| k.mission().graph().name_of(f.behavior).to_string())
            .unwrap_or_default()
    }

    fn names(&self, o: &Outgoing) -> Vec<String> {
        let g = self.kernel.mission().graph();
        bite_core::wm::belief_names(g, &o.msg)
    }
}

fn robots(o: &Outgoing) -> Vec<u32> {
    o.to.iter().map(|r| r.0).collect()
}

#[test]
fn the_allocation_puts_each_robot_on_its_role() {
    for (me, role) in [(0, "lead"), (1, "follow_left"), (2, "follow_right")] {
        assert_eq!(robot(me, Policy::None, None, &[]).leaf(), role);
    }
}

#[test]
fn focused_informs_the_subteam_of_a_behavior_on_the_stack_once() {
    let mut r1 = robot(1, Policy::Focused, None, &[]);
    assert!(
        r1.sense(0.1, &[("obstacle", Value::Bool(false))])
            .is_empty()
    );
    // `triangle` is on r1's stack; its termination condition holds: the
    // whole team running it (r0, r2) is told `obstacle`, and only that.
    let out = r1.sense(0.2, &[("obstacle", Value::Bool(true))]);
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(out[0].msg.reason, Reason::Obligatory);
    assert_eq!(robots(&out[0]), vec![0, 2]);
    assert_eq!(r1.names(&out[0]), vec!["obstacle"]);
    // Not again while it holds; again after it stopped and came back.
    assert!(r1.sense(0.3, &[("obstacle", Value::Bool(true))]).is_empty());
    assert!(
        r1.sense(0.4, &[("obstacle", Value::Bool(false))])
            .is_empty()
    );
    assert_eq!(r1.sense(0.5, &[("obstacle", Value::Bool(true))]).len(), 1);
}

#[test]
fn focused_informs_about_a_successors_precondition() {
    let mut r2 = robot(2, Policy::Focused, None, &[]);
    // `regroup` follows `triangle` (on the stack) when `clear` holds.
    let out = r2.sense(0.1, &[("clear", Value::Bool(true))]);
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(robots(&out[0]), vec![0, 1]);
    assert_eq!(r2.names(&out[0]), vec!["clear"]);
}

#[test]
fn focused_alone_does_not_help_another_subteam() {
    // `gap` ends `lead`, which r1 does not run: Algorithm 2 is silent, and
    // a condition of r1's own single-robot subteam informs nobody.
    let mut r1 = robot(1, Policy::Focused, None, &[]);
    let out = r1.sense(
        0.1,
        &[("gap", Value::Bool(true)), ("left_done", Value::Bool(true))],
    );
    assert!(out.is_empty(), "{out:?}");
}

#[test]
fn helpful_informs_the_subteam_whose_behavior_it_is_and_nobody_else() {
    let mut r1 = robot(1, Policy::Helpful, None, &[]);
    let out = r1.sense(0.1, &[("gap", Value::Bool(true))]);
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(out[0].msg.reason, Reason::Helpful);
    // Only the lead subteam: r0.
    assert_eq!(robots(&out[0]), vec![0]);
    assert_eq!(r1.names(&out[0]), vec!["gap"]);
    // `right_done` ends r2's role: r2 alone is told.
    let out = r1.sense(0.2, &[("right_done", Value::Bool(true))]);
    assert_eq!(out.len(), 1);
    assert_eq!(robots(&out[0]), vec![2]);
    // Helpful does not cover r1's own stack (that is Algorithm 2's).
    assert!(r1.sense(0.3, &[("obstacle", Value::Bool(true))]).is_empty());
}

#[test]
fn a_belief_a_teammate_told_is_not_echoed() {
    let mut r1 = robot(1, Policy::FocusedHelpful, None, &[]);
    let (mut own, mut told) = (Vec::new(), Vec::new());
    let obstacle = id(&r1.kernel, "obstacle");
    let msg = Inform {
        reason: Reason::Obligatory,
        about: None,
        beliefs: vec![Report {
            belief: obstacle,
            value: Value::Bool(true),
            age_us: 10_000,
            confidence: 1.0,
        }],
    };
    let at = Time::from_secs_f64(0.06);
    r1.wm.receive(at, RobotId(0), &msg, &mut own, &mut told);
    assert_eq!(
        told,
        vec![(obstacle, Value::Bool(true), Source::Teammate(RobotId(0)))]
    );
    for (b, v, s) in told {
        r1.kernel.set_belief(b, v, s);
    }
    assert!(r1.sense(0.1, &[]).is_empty(), "r0 has told whom it had to");
}

#[test]
fn broadcast_sends_every_change_of_every_belief_to_everyone() {
    let mut r0 = robot(0, Policy::Broadcast, None, &["left_done"]);
    let out = r0.sense(
        0.1,
        &[
            ("left_done", Value::Bool(false)),
            ("clear", Value::Bool(false)),
        ],
    );
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].msg.reason, Reason::Broadcast);
    assert_eq!(robots(&out[0]), vec![1, 2]);
    // Private beliefs too: that is the baseline's cost.
    assert_eq!(r0.names(&out[0]), vec!["clear", "left_done"]);
    // Unchanged: nothing; changed: again.
    assert!(r0.sense(0.2, &[("clear", Value::Bool(false))]).is_empty());
    assert_eq!(r0.sense(0.3, &[("clear", Value::Bool(true))]).len(), 1);
    assert_eq!(r0.wm.stats().messages[Reason::Broadcast.index()], 4);
}

#[test]
fn private_beliefs_are_neither_reported_nor_adopted() {
    // `gap` private to r1 (say, computed from its own odometry): helpful
    // has nothing to say about it.
    let mut r1 = robot(1, Policy::Helpful, None, &["gap"]);
    assert!(r1.sense(0.1, &[("gap", Value::Bool(true))]).is_empty());
    let gap = id(&r1.kernel, "gap");
    let (mut own, mut told) = (Vec::new(), Vec::new());
    let msg = Inform {
        reason: Reason::Broadcast,
        about: None,
        beliefs: vec![Report {
            belief: gap,
            value: Value::Bool(false),
            age_us: 0,
            confidence: 1.0,
        }],
    };
    let at = Time::from_secs_f64(5.0);
    r1.wm.receive(at, RobotId(0), &msg, &mut own, &mut told);
    assert!(own.is_empty() && told.is_empty());
    assert_eq!(r1.wm.stats().ignored, 1);
}

#[test]
fn latest_change_wins_and_positions_are_fused_by_confidence() {
    let mut wm = WorldModel::new(
        RobotId(1),
        2,
        Sharing::default(),
        Arc::from(vec![false, false]),
    );
    let (flag, pos) = (BeliefId(0), BeliefId(1));
    let t = Time::from_secs_f64;
    let (mut own, mut told) = (Vec::new(), Vec::new());
    // Own: false since 0 s.
    wm.perceive(t(0.0), &[(flag, Value::Bool(false))], &mut own, &mut told);
    assert_eq!(own, vec![(flag, Value::Bool(false))]);
    // The robot's own reading reaches the kernel at every tick, changed or
    // not (so `age(b)` means what it means without a world model).
    own.clear();
    wm.perceive(t(0.1), &[(flag, Value::Bool(false))], &mut own, &mut told);
    assert_eq!(own, vec![(flag, Value::Bool(false))]);
    // A teammate saw it true at 2 s: newer than our last change, it wins...
    // (`report(b, v, changed, now)`: read at `now`, changed at `changed`.)
    let report = |b, v, changed: f64, now: f64| Inform {
        reason: Reason::Obligatory,
        about: None,
        beliefs: vec![Report::new(b, v, t(changed), t(now), 0.5)],
    };
    own.clear();
    wm.receive(
        t(2.0),
        RobotId(0),
        &report(flag, Value::Bool(true), 2.0, 2.0),
        &mut own,
        &mut told,
    );
    assert_eq!(
        told,
        vec![(flag, Value::Bool(true), Source::Teammate(RobotId(0)))]
    );
    // ...and keeps winning while our own perception does not change...
    told.clear();
    wm.perceive(t(3.0), &[(flag, Value::Bool(false))], &mut own, &mut told);
    assert!(own.is_empty() && told.is_empty());
    // ...until it does.
    wm.perceive(t(4.0), &[(flag, Value::Bool(true))], &mut own, &mut told);
    wm.perceive(t(5.0), &[(flag, Value::Bool(false))], &mut own, &mut told);
    assert_eq!(own.last(), Some(&(flag, Value::Bool(false))));
    // An older report than the last change is ignored.
    own.clear();
    told.clear();
    wm.receive(
        t(5.0),
        RobotId(2),
        &report(flag, Value::Bool(true), 4.5, 5.0),
        &mut own,
        &mut told,
    );
    assert!(told.is_empty());
    // Positions within a second of each other: weighted by confidence
    // (own 1.0, teammate 0.5).
    wm.perceive(
        t(6.0),
        &[(pos, Value::Vec2([0.0, 0.0]))],
        &mut own,
        &mut told,
    );
    own.clear();
    wm.receive(
        t(6.5),
        RobotId(0),
        &report(pos, Value::Vec2([3.0, 3.0]), 6.5, 6.5),
        &mut own,
        &mut told,
    );
    assert_eq!(own, vec![(pos, Value::Vec2([1.0, 1.0]))]);
}

#[test]
fn reports_are_ordered_by_age_whatever_the_clocks_say() {
    // The receiver's clock runs 2.6 s ahead of the sender's. It read the
    // flag false at 3.0 s of its clock (0.4 s of the sender's); the sender
    // saw it true at 1.8 s of its own clock (4.4 s of the receiver's),
    // later in fact. By the sender's time (1.8 s < 3.0 s) the report would
    // look older than the receiver's reading and never be adopted; by its
    // age (0.05 s on arrival at 4.45 s) it is newer, and wins.
    let mut wm = WorldModel::new(RobotId(1), 1, Sharing::default(), Arc::from(vec![false]));
    let flag = BeliefId(0);
    let t = Time::from_secs_f64;
    let (mut own, mut told) = (Vec::new(), Vec::new());
    wm.perceive(t(2.9), &[(flag, Value::Bool(true))], &mut own, &mut told);
    wm.perceive(t(3.0), &[(flag, Value::Bool(false))], &mut own, &mut told);
    own.clear();
    let sent = Report::new(flag, Value::Bool(true), t(1.8), t(1.85), 1.0);
    assert_eq!(sent.age_us, 50_000);
    assert_eq!(sent.changed_at(t(4.45)), t(4.4));
    let msg = Inform {
        reason: Reason::Obligatory,
        about: None,
        beliefs: vec![sent],
    };
    wm.receive(t(4.45), RobotId(0), &msg, &mut own, &mut told);
    assert_eq!(
        told,
        vec![(flag, Value::Bool(true), Source::Teammate(RobotId(0)))]
    );
    // A report older than the reading (age 1.5 s: changed at 2.95 s of the
    // receiver's clock) is not, whatever the sender's clock read.
    let mut wm2 = WorldModel::new(RobotId(1), 1, Sharing::default(), Arc::from(vec![false]));
    let (mut own, mut told) = (Vec::new(), Vec::new());
    wm2.perceive(t(3.0), &[(flag, Value::Bool(false))], &mut own, &mut told);
    own.clear();
    let stale = Inform {
        beliefs: vec![Report::new(flag, Value::Bool(true), t(9.0), t(10.5), 1.0)],
        ..msg
    };
    wm2.receive(t(4.45), RobotId(0), &stale, &mut own, &mut told);
    assert!(own.is_empty() && told.is_empty(), "{own:?} {told:?}");
}

#[test]
fn a_report_dated_like_the_robots_own_reading_wins_the_tie() {
    // The receiver's clock is held at 0 until the mission starts on it (it
    // runs behind): its own reading and a teammate's report of a change
    // made meanwhile are both dated 0. The teammate tells of a change the
    // robot did not see, so it wins; a report of the same value does not
    // displace the robot's own reading.
    let mut wm = WorldModel::new(RobotId(0), 1, Sharing::default(), Arc::from(vec![false]));
    let found = BeliefId(0);
    let (mut own, mut told) = (Vec::new(), Vec::new());
    wm.perceive(
        Time::ZERO,
        &[(found, Value::Bool(false))],
        &mut own,
        &mut told,
    );
    let report = |v| Inform {
        reason: Reason::Obligatory,
        about: None,
        beliefs: vec![Report {
            belief: found,
            value: v,
            age_us: 20_000,
            confidence: 1.0,
        }],
    };
    own.clear();
    wm.receive(
        Time::ZERO,
        RobotId(1),
        &report(Value::Bool(false)),
        &mut own,
        &mut told,
    );
    assert!(own.is_empty() && told.is_empty(), "{own:?} {told:?}");
    wm.receive(
        Time::ZERO,
        RobotId(1),
        &report(Value::Bool(true)),
        &mut own,
        &mut told,
    );
    assert_eq!(
        told,
        vec![(found, Value::Bool(true), Source::Teammate(RobotId(1)))]
    );
    // Its own reading, unchanged, does not take it back.
    told.clear();
    wm.perceive(
        Time::from_millis(100),
        &[(found, Value::Bool(false))],
        &mut own,
        &mut told,
    );
    assert!(own.is_empty() && told.is_empty(), "{own:?} {told:?}");
}

#[test]
fn a_budget_that_starves_helpful_messages_still_sends_every_obligatory_one() {
    // One message a second; each condition informs two robots (obligatory,
    // about `triangle`/`regroup`) or one (helpful, about the others' roles).
    let mut r1 = robot(1, Policy::FocusedHelpful, Some(1.0), &[]);
    let mut sent: Vec<Outgoing> = Vec::new();
    // When each message left.
    let mut left: Vec<Time> = Vec::new();
    // Everything becomes true at once: obligatory `obstacle` and `clear`,
    // helpful `gap` and `right_done`.
    for k in 1..=60 {
        let now = k as f64 * 0.1;
        let percepts: &[(&str, Value)] = if k == 1 {
            &[
                ("gap", Value::Bool(true)),
                ("right_done", Value::Bool(true)),
                ("obstacle", Value::Bool(true)),
                ("clear", Value::Bool(true)),
            ]
        } else {
            &[]
        };
        let out = r1.sense(now, percepts);
        left.extend(out.iter().map(|_| Time::from_secs_f64(now)));
        sent.extend(out);
    }
    // A message that waited for budget reports its beliefs as old as they
    // are when it leaves, not when it was queued: all changed at 0.1 s.
    assert!(
        left.iter().any(|t| *t > Time::from_secs_f64(0.1)),
        "{left:?}"
    );
    for (o, at) in sent.iter().zip(&left) {
        for r in &o.msg.beliefs {
            let age = at.as_micros() - Time::from_secs_f64(0.1).as_micros();
            assert_eq!(r.age_us, age, "{o:?} left at {at}");
        }
    }
    let obligatory: Vec<&Outgoing> = sent
        .iter()
        .filter(|o| o.msg.reason == Reason::Obligatory)
        .collect();
    let helpful = sent
        .iter()
        .filter(|o| o.msg.reason == Reason::Helpful)
        .count();
    assert_eq!(
        obligatory.len(),
        2,
        "both obligatory messages went out: {sent:?}"
    );
    // They went first.
    assert!(sent[..2].iter().all(|o| o.msg.reason == Reason::Obligatory));
    // The helpful ones waited past their time to live and were dropped.
    assert_eq!(helpful, 0, "{sent:?}");
    assert_eq!(r1.wm.stats().dropped, 2);
    assert_eq!(r1.wm.stats().messages[Reason::Obligatory.index()], 4);
    // Without a budget, all four go.
    let mut free = robot(1, Policy::FocusedHelpful, None, &[]);
    let all = free.sense(
        0.1,
        &[
            ("gap", Value::Bool(true)),
            ("right_done", Value::Bool(true)),
            ("obstacle", Value::Bool(true)),
            ("clear", Value::Bool(true)),
        ],
    );
    assert_eq!(all.len(), 4);
}

#[test]
fn a_mistyped_policy_is_an_error_at_its_line_with_a_hint() {
    let text = "config: x\nworld_model:\n  sharing: focussed+helpful\n";
    let err = bite_core::Config::load_str(&Arc::from("x.yaml"), text).expect_err("rejected");
    let d = &err.0[0];
    assert_eq!(d.code, "bad-sharing");
    // At the value, not the section.
    assert_eq!((d.loc.line, d.loc.col), (3, 12), "{d}");
    assert!(
        d.hint
            .as_deref()
            .is_some_and(|h| h.contains("focused+helpful")),
        "{d}"
    );
    let g = GRAPH.replace(
        "defaults:",
        "world_model: { sharing: broadcast, hz: 0 }\ndefaults:",
    );
    let err = load_str(&Arc::from("g.yaml"), &g).expect_err("hz 0 rejected");
    assert!(err.has("bad-value"), "{err}");
    let d = &err.0[0];
    let line = g
        .lines()
        .position(|l| l.starts_with("world_model:"))
        .expect("there")
        + 1;
    let col = g
        .lines()
        .nth(line - 1)
        .and_then(|l| l.find("hz: 0"))
        .expect("there")
        + 5;
    assert_eq!(
        (d.loc.line as usize, d.loc.col as usize),
        (line, col),
        "{err}"
    );
    // A configuration replaces the graph's settings.
    let g = load_str(&Arc::from("g.yaml"), GRAPH).expect("loads");
    assert_eq!(g.sharing().policy, Policy::None);
    let cfg = bite_core::Config::load_str(
        &Arc::from("c.yaml"),
        "config: c\nworld_model: { sharing: helpful, budget: 5 }\n",
    )
    .expect("loads");
    let g = g.with_config(&cfg).expect("applies");
    assert_eq!(g.sharing().policy, Policy::Helpful);
    assert_eq!(g.sharing().budget, Some(5.0));
}
