//! Whole missions in the timed-skill world, with fixed seeds: they complete,
//! the behaviors run in the right order, every invariant holds, and runs are
//! reproducible byte for byte.

use bite_core::event::{Event, Via};
use bite_core::graph::Config;
use bite_core::ids::{RobotId, TeamId};
use bite_core::msg::{InstanceKey, Kind};
use bite_sim::Scenario;
use std::collections::BTreeMap;
use std::sync::Arc;

mod missions;
use missions::{FORMATION, Outcome, assert_clean, graph, replay, scenario, simulate, table2};

const FORMATION_SC: &str = include_str!("../../../examples/scenarios/formation.yaml");
const PATROL: &str = include_str!("../../../examples/patrol.yaml");
const PATROL_SC: &str = include_str!("../../../examples/scenarios/patrol.yaml");
const SQUADS: &str = include_str!("../../../examples/squads.yaml");
const SQUADS_SC: &str = include_str!("../../../examples/scenarios/squads.yaml");

/// The behaviors robot `r` selected, in order.
fn selections(o: &Outcome, r: u32) -> Vec<String> {
    let g = o.mission.graph();
    o.report
        .history
        .iter()
        .filter(|rec| rec.robot == RobotId(r))
        .filter_map(|rec| match &rec.event {
            Event::Selected { behavior, .. } => Some(g.name_of(*behavior).to_string()),
            _ => None,
        })
        .collect()
}

#[test]
fn formation_completes_in_the_paper_order() {
    let o = simulate(
        &graph("formation.yaml", FORMATION),
        &scenario("f.yaml", FORMATION_SC),
        1,
    );
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_eq!(s.timeouts, 0, "{s}");
    assert_clean(&o, "formation");
    // Triangle first (search, then walk legs led by robot 0), then line.
    let seq = selections(&o, 0);
    assert_eq!(
        &seq[..5],
        ["formation", "triangle", "search", "walk", "lead"],
        "{seq:?}"
    );
    let line = seq
        .iter()
        .position(|b| b == "line")
        .expect("switches to line");
    assert!(seq[..line].iter().all(|b| b != "linewalk"));
    assert!(seq[line..].iter().any(|b| b == "linewalk"));
    assert!(seq[line..].iter().all(|b| b != "walk"));
    // Roles: robot 0 leads, 1 follows left, 2 follows right (SF2, by id).
    assert!(selections(&o, 1).contains(&"follow_left".to_string()));
    assert!(selections(&o, 2).contains(&"follow_right".to_string()));
    // All walked the 6 m course in about 50 s of walking plus searches.
    assert!((45.0..120.0).contains(&s.task_time), "{}", s.task_time);
}

#[test]
fn the_same_seed_gives_the_same_log_byte_for_byte() {
    let g = graph("formation.yaml", FORMATION);
    let sc = scenario("f.yaml", FORMATION_SC);
    let a = simulate(&g, &sc, 7);
    let b = simulate(&g, &sc, 7);
    assert!(!a.log.is_empty());
    assert!(a.log == b.log, "two runs with seed 7 differ");
    assert_eq!(
        a.report.summary.log_fingerprint,
        b.report.summary.log_fingerprint
    );
    let c = simulate(&g, &sc, 8);
    assert!(a.log != c.log, "another seed gives another run");
}

#[test]
fn a_sequential_cycle_repeats_laps_by_vote() {
    let o = simulate(
        &graph("patrol.yaml", PATROL),
        &scenario("p.yaml", PATROL_SC),
        3,
    );
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_clean(&o, "patrol");
    let seq = selections(&o, 1);
    let laps = seq.iter().filter(|b| *b == "lap").count();
    assert_eq!(laps, 3, "{seq:?}");
    assert!(
        seq.contains(&"investigate".to_string()),
        "the alarm is investigated: {seq:?}"
    );
    assert_eq!(seq.last().map(String::as_str), Some("home"));
    // Every vote: a call, one vote per other member, a result (n + 1).
    let per_instance = sent_per_instance(&o, Kind::Sync);
    assert!(!per_instance.is_empty());
    for (k, n) in per_instance {
        assert_eq!(
            n, 3,
            "sync.vote with 2 robots sends n + 1 = 3 messages ({k})"
        );
    }
}

/// Messages sent per instance of a kind, summed over robots.
fn sent_per_instance(o: &Outcome, kind: Kind) -> BTreeMap<InstanceKey, u32> {
    let mut m = BTreeMap::new();
    for rec in &o.report.history {
        if let Event::InteractionDecided { instance, sent, .. } = &rec.event
            && instance.kind == kind
        {
            *m.entry(*instance).or_insert(0) += *sent;
        }
    }
    m
}

#[test]
fn nested_allocation_splits_a_subteam_again() {
    let o = simulate(
        &graph("squads.yaml", SQUADS),
        &scenario("s.yaml", SQUADS_SC),
        5,
    );
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_clean(&o, "squads");
    let g = o.mission.graph();
    // Every robot reached a leaf two allocations deep, in a team whose parent
    // is a squad, whose parent is the root team.
    let mut leaves = BTreeMap::new();
    for rec in &o.report.history {
        if let Event::Selected {
            behavior,
            team,
            via: Via::Allocation,
            depth: 3,
            ..
        } = &rec.event
        {
            leaves.insert(rec.robot, (g.name_of(*behavior).to_string(), *team));
        }
    }
    assert_eq!(leaves.len(), 6, "{leaves:?}");
    let scouts = leaves
        .values()
        .filter(|(b, _)| b.ends_with("scout"))
        .count();
    assert_eq!(scouts, 2, "one scout per squad: {leaves:?}");
    let (_, t) = &leaves[&RobotId(0)];
    assert_ne!(*t, TeamId::ROOT);
}

#[test]
fn formation_under_vote_and_faults_still_agrees() {
    let g = graph("formation.yaml", FORMATION);
    let cfg = Config::load_str(
        &Arc::from("votes.yaml"),
        "bindings: { A: sync.vote, B: sync.vote, D: sync.vote }",
    )
    .unwrap_or_else(|d| panic!("{d}"));
    let g = g.with_config(&cfg).unwrap_or_else(|d| panic!("{d}"));
    let mut sc = scenario("f.yaml", FORMATION_SC);
    sc.network.loss = 0.15;
    sc.network.duplicate = 0.15;
    sc.network.jitter = std::time::Duration::from_millis(80);
    for seed in 1..=4 {
        let o = simulate(&g, &sc, seed);
        let s = &o.report.summary;
        assert!(s.completed, "seed {seed}: {s}\n{}", replay(&o));
        assert_clean(&o, &format!("formation with votes, 15% loss, seed {seed}"));
        assert!(s.network.lost > 0 && s.network.duplicated > 0);
    }
}

fn partitioned(from: &str, until: &str) -> Scenario {
    let text = FORMATION_SC.replace(
        "network:\n  latency: 5ms\n  jitter: 10ms",
        &format!(
            "network:\n  latency: 5ms\n  jitter: 10ms\n  partitions:\n    - {{ from: {from}, until: {until}, groups: [[r0, r1], [r2]] }}"
        ),
    );
    scenario("partitioned.yaml", &text)
}

#[test]
fn a_partition_delays_but_does_not_break_the_barrier() {
    // Shorter than the failure detector's bound: messages are cut during
    // the second leg's barriers, nobody is presumed lost, the retries
    // carry the barrier through.
    let g = graph("formation.yaml", FORMATION);
    let o = simulate(&g, &partitioned("14s", "15.5s"), 1);
    let s = &o.report.summary;
    assert!(s.network.partitioned > 0, "{s}");
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert!(
        !o.report
            .history
            .iter()
            .any(|r| matches!(r.event, Event::MemberLost { .. })),
        "nobody presumed lost"
    );
    assert_clean(&o, "partition");
}

#[test]
fn a_long_partition_splits_the_team_and_each_side_reallocates() {
    // 8 s without hearing each other: each side presumes the other lost
    // and re-allocates the triangle's roles among itself, then they meet
    // again and finish the course.
    let g = graph("formation.yaml", FORMATION);
    let o = simulate(&g, &partitioned("10s", "18s"), 1);
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    let realloc: BTreeMap<u32, u32> = reallocations(&o).into_iter().collect();
    // r0 and r1 lose r2 (round 1); r2 loses both, one after the other
    // (rounds 1 and 2). When the partition heals, r2's round-2 messages
    // reach r0 and r1, which join that round; members that still hold
    // different allocations of it (one joined while it still presumed r2
    // lost) allocate again with everyone (`allocation_split`), a bounded
    // number of times, until all hold one allocation: every robot ends on
    // the same round.
    let rounds: Vec<u32> = realloc.values().copied().collect();
    assert_eq!(rounds.len(), 3, "{realloc:?}");
    assert!(rounds.iter().all(|r| *r == rounds[0]), "{realloc:?}");
    assert!(
        (2..=2 + u32::from(bite_core::kernel::ALLOC_HEALS)).contains(&rounds[0]),
        "{realloc:?}"
    );
    assert_clean(&o, "long partition");
}

#[test]
fn scenario_errors_name_the_file_and_place() {
    let g = graph("formation.yaml", FORMATION);
    let sc = scenario("bad.yaml", "crashes:\n  - { robot: r9, at: 5s }\n");
    let err = sc.resolve(&g).expect_err("r9 is not in a team of 3");
    assert_eq!(err.0[0].code, "unknown-robot");
    assert_eq!((err.0[0].loc.line, err.0[0].loc.col), (2, 5));
    let err = Scenario::load_str(&Arc::from("bad.yaml"), "network: { loss: 2 }")
        .expect_err("loss is a probability");
    assert!(err.to_string().contains("probability"), "{err}");
    let err = Scenario::load_str(&Arc::from("bad.yaml"), "skills:\n  s: { duration: [3, 1] }")
        .expect_err("bounds out of order");
    assert!(err.to_string().starts_with("bad.yaml:2:"), "{err}");
    // A heartbeat of 0 s never let simulated time pass (the run hung,
    // growing by 450 MB a second); `lost_after` within a heartbeat has
    // every robot presumed lost between two.
    for fd in [
        "{ heartbeat: 0s }",
        "{ heartbeat: 1us }",
        "{ lost_after: 100ms, heartbeat: 250ms }",
    ] {
        let text = format!("scenario: t\nfailure_detector: {fd}\n");
        let err = Scenario::load_str(&Arc::from("hb.yaml"), &text).expect_err(fd);
        assert_eq!(err.0[0].code, "bad-failure-detector", "{err}");
        assert!(err.to_string().starts_with("hb.yaml:2:"), "{err}");
    }
    Scenario::load_str(
        &Arc::from("hb.yaml"),
        "failure_detector: { lost_after: 100ms, heartbeat: 10ms }",
    )
    .expect("the shortest heartbeat");
}

/// A teammate heard working whose position never changes is waited for up
/// to four deadlines (at least 120 s), checked at each deadline, and then
/// decided without. With a 40 s deadline that is 165 s after its last
/// change, and the stall watch's default 120 s called the run stalled
/// first, though the robots still had their timeout and decision to come.
/// The watch now waits at least the mission's longest own wait
/// (`Mission::longest_wait`) and 10 s more.
#[test]
fn a_teammate_stuck_at_work_is_a_timeout_and_a_decision_not_a_stall() {
    let text = |deadline: &str| {
        format!(
            "graph: stuck\nteam: {{ robots: 2 }}\nstart: work\n\
             defaults: {{ terminate: {{ protocol: term.wait-all, deadline: {deadline} }} }}\n\
             behaviors:\n  work: {{ team: true, skill: hold, until: done, next: [after] }}\n  \
             after: {{ team: true, skill: short, until: short_done }}\n"
        )
    };
    let sc = scenario(
        "stuck.yaml",
        "scenario: stuck\nseed: 1\ncontrol_hz: 10\ntime_limit: 600s\nskills:\n  hold: {}\n  \
         short: { duration: [1, 1], done: { short_done: true } }\n\
         events:\n  - { at: 5s, robots: [r0], set: { done: true } }\n",
    );
    for (deadline, waited) in [("30s", 120.0), ("40s", 160.0), ("60s", 240.0)] {
        let g = graph("stuck.yaml", &text(deadline));
        let o = simulate(&g, &sc, 1);
        let s = &o.report.summary;
        assert!(s.completed, "deadline {deadline}: {s}\n{}", replay(&o));
        assert_eq!(s.timeouts, 1, "deadline {deadline}: {s}");
        // r0 arrived at 5 s and waited for r1 (last changed at 0 s) up to
        // its limit, then to the next deadline.
        assert!(
            s.task_time > waited && s.task_time < waited + 15.0,
            "deadline {deadline}: {s}"
        );
    }
}

/// Two robots whose legs end by `term.majority`, one of them crashed: a
/// majority of the whole pair is both, and the survivor alone is a
/// minority, so the first barrier after the crash ends at its deadline
/// (a minority cut off by a partition must not decide sooner). From then
/// on the crashed teammate, silent for a whole deadline, is given up
/// (`Cx::is_given_up`) and out of the whole: the survivor decides each
/// later barrier at once. It paid the 30 s deadline at every barrier
/// before (fresh property seed 1209: 56 deadlines, 2,004 s).
#[test]
fn a_teammate_lost_for_good_costs_a_majority_one_deadline_not_one_per_barrier() {
    let g = graph(
        "pair.yaml",
        "graph: pair\nteam: { robots: 2 }\nstart: mission\n\
         defaults: { sync: sync.leader, terminate: term.majority }\nbehaviors:\n  \
         mission: { team: true, children: [leg] }\n  \
         leg: { team: true, skill: walk, until: walked, next: [leg, home] }\n  \
         home: { team: true, skill: walk, until: walked, pre: 'runs(leg) >= 8' }\n",
    );
    let sc = |extra: &str| {
        scenario(
            "pair-sc.yaml",
            &format!(
                "scenario: pair\nseed: 1\ncontrol_hz: 10\ntime_limit: 900s\nskills:\n  \
                 walk: {{ duration: [2, 4], start: {{ walked: false }}, done: {{ walked: true }} }}\n{extra}"
            ),
        )
    };
    let o = simulate(&g, &sc("crashes:\n  - { robot: r1, at: 5s }\n"), 1);
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_eq!(
        s.timeouts, 1,
        "one deadline, then the survivor decides: {s}"
    );
    let legs = selections(&o, 0).iter().filter(|b| *b == "leg").count();
    assert_eq!(legs, 8, "{:?}", selections(&o, 0));
    assert!(s.task_time < 80.0, "{s}");
    // Said once, in the run log, by the survivor.
    let given: Vec<_> = (o.report.history.iter())
        .filter(|r| matches!(r.event, Event::MemberGivenUp { .. }))
        .map(|r| (r.robot, format!("{:?}", r.event)))
        .collect();
    assert_eq!(
        given,
        [(
            RobotId(0),
            format!("{:?}", Event::MemberGivenUp { member: RobotId(1) })
        )]
    );
    assert_clean(&o, "a pair with a crash");

    // Heard again, the teammate counts again: r1 paused past a deadline
    // and back, the pair's later barriers need both.
    let o = simulate(
        &g,
        &sc("crashes:\n  - { robot: r1, at: 5s, until: 45s }\n"),
        1,
    );
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_clean(&o, "a pair with a pause");
}

#[test]
fn a_crashed_robot_does_not_hang_the_team() {
    let g = graph("formation.yaml", FORMATION);
    // With failure detection (the default): the survivors presume it lost
    // after `lost_after` and their protocols decide without it.
    let text = format!("{FORMATION_SC}\ncrashes:\n  - {{ robot: r2, at: 8s }}\n");
    let o = simulate(&g, &scenario("crash.yaml", &text), 1);
    let s = &o.report.summary;
    assert_eq!(s.crashed_robots, 1);
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert_eq!(s.timeouts, 0, "nobody waited for a deadline: {s}");
    let lost: Vec<_> = o
        .report
        .history
        .iter()
        .filter(|r| matches!(r.event, Event::MemberLost { member: RobotId(2) }))
        .map(|r| (r.robot, r.t))
        .collect();
    assert_eq!(lost.len(), 2, "both survivors noticed: {lost:?}");
    for (_, t) in &lost {
        let after = t.as_secs_f64() - 8.0;
        assert!(
            (2.0..2.3).contains(&after),
            "detected {after:.3} s after the crash"
        );
    }
    assert_clean(&o, "crash");

    // Without it, the barrier's deadline turns the silence into a decision.
    let text = format!(
        "{FORMATION_SC}\nfailure_detector: {{ enabled: false }}\ncrashes:\n  - {{ robot: r2, at: 8s }}\n"
    );
    let o = simulate(&g, &scenario("crash.yaml", &text), 1);
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    assert!(s.timeouts > 0, "the silence was a timeout and a decision");
    assert!(s.task_time > 70.0, "and cost the deadline: {s}");
    assert_clean(&o, "crash without detection");
}

#[test]
fn the_team_carries_on_when_its_leader_crashes() {
    // r0 leads every team protocol; it crashes during the first triangle
    // leg. r1 takes over barriers and votes.
    let g = graph("formation.yaml", FORMATION);
    let cfg = Config::load_str(
        &Arc::from("votes.yaml"),
        "bindings: { A: sync.vote, B: sync.vote, D: sync.vote }",
    )
    .unwrap_or_else(|d| panic!("{d}"));
    for g in [
        g.clone(),
        g.with_config(&cfg).unwrap_or_else(|d| panic!("{d}")),
    ] {
        for at in ["2.1s", "8s", "14.7s", "31s"] {
            let text = format!("{FORMATION_SC}\ncrashes:\n  - {{ robot: r0, at: {at} }}\n");
            let o = simulate(&g, &scenario("leader-crash.yaml", &text), 1);
            let s = &o.report.summary;
            assert!(s.completed, "leader crashed at {at}: {s}\n{}", replay(&o));
            assert_eq!(s.timeouts, 0, "leader crashed at {at}: {s}");
            assert_clean(&o, &format!("leader crash at {at}"));
        }
    }
}

#[test]
fn a_paused_robot_rejoins() {
    // r2 stops for 15 s, long enough to be presumed lost, then resumes with
    // its state: the others went on without it; it catches up.
    let g = graph("formation.yaml", FORMATION);
    let text = format!("{FORMATION_SC}\ncrashes:\n  - {{ robot: r2, at: 5s, until: 20s }}\n");
    let o = simulate(&g, &scenario("pause.yaml", &text), 1);
    let s = &o.report.summary;
    assert!(s.completed, "{s}\n{}", replay(&o));
    let back = o
        .report
        .history
        .iter()
        .filter(|r| matches!(r.event, Event::MemberBack { member: RobotId(2) }))
        .count();
    assert_eq!(back, 2, "both teammates hear r2 again");
    assert_clean(&o, "pause");
}

const TASKS: &str = r#"
graph: tasks
team: { robots: 4 }
start: work
defaults: { terminate: term.wait-all }
behaviors:
  work:
    team: true
    children: [a, b, c]
    allocate: PROTOCOL
  a: { team: true, skill: job, until: job_done, members: 1, utility: '10 - x' }
  b: { team: true, skill: job, until: job_done, members: 1, utility: 'x' }
  c: { team: true, skill: job, until: job_done, members: "1..", utility: '1' }
"#;

#[test]
fn a_lost_members_child_is_reallocated_by_the_points_protocol() {
    for protocol in [
        "alloc.by-id",
        "{ protocol: alloc.by-value, params: { value: x } }",
        "{ protocol: alloc.by-attribute, params: { attribute: colour } }",
        "alloc.optimal",
        "alloc.auction",
        "alloc.token",
    ] {
        let g = graph("tasks.yaml", &TASKS.replace("PROTOCOL", protocol));
        // Robot i believes x = i; every job takes 20 s.
        let mut sc = String::from(
            "scenario: tasks\nseed: 3\nskills:\n  job: { duration: 20, start: { job_done: false }, done: { job_done: true } }\nevents:\n",
        );
        for i in 0..4 {
            sc.push_str(&format!(
                "  - {{ at: 0s, robots: [r{i}], set: {{ x: {i} }} }}\n"
            ));
        }
        // First find who runs `b` (it takes one member), then crash it.
        let o = simulate(&g, &scenario("tasks-sc.yaml", &sc), 3);
        let b = g.find("b").unwrap_or_else(|| panic!("b"));
        let holder = o
            .report
            .history
            .iter()
            .find_map(|r| match &r.event {
                Event::Selected { behavior, .. } if *behavior == b => Some(r.robot),
                _ => None,
            })
            .unwrap_or_else(|| panic!("{protocol}: nobody runs b"));
        sc.push_str(&format!(
            "crashes:\n  - {{ robot: r{}, at: 5s }}\n",
            holder.0
        ));
        let o = simulate(&g, &scenario("tasks-crash.yaml", &sc), 3);
        let s = &o.report.summary;
        assert!(s.completed, "{protocol}: {s}\n{}", replay(&o));
        assert_clean(&o, protocol);
        // Every survivor re-allocated once, and someone else runs b to the end.
        let rounds = reallocations(&o);
        assert_eq!(rounds.len(), 3, "{protocol}: {rounds:?}");
        assert!(rounds.iter().all(|(r, k)| *r != holder.0 && *k == 1));
        let finished_b: Vec<RobotId> = o
            .report
            .history
            .iter()
            .filter_map(|r| match r.event {
                Event::Terminated {
                    behavior,
                    reason: bite_core::event::EndReason::Until,
                    ..
                } if behavior == b => Some(r.robot),
                _ => None,
            })
            .collect();
        assert_eq!(
            finished_b.len(),
            1,
            "{protocol}: b finished by {finished_b:?}"
        );
        assert_ne!(finished_b[0], holder, "{protocol}");
        // Re-allocating cost no deadline: survivors decided as soon as
        // they knew.
        assert_eq!(s.timeouts, 0, "{protocol}: {s}");
    }
}

/// The seven configurations of the paper's Table II, as shipped.

#[test]
fn the_seven_table2_configurations_complete_the_formation() {
    // Row → the protocol each of points A-E must run.
    let rows = [
        [
            "sync.by-rule",
            "sync.by-rule",
            "alloc.by-id",
            "sync.by-rule",
            "alloc.by-id",
        ],
        [
            "sync.by-rule",
            "sync.ranked-vote",
            "alloc.by-id",
            "sync.by-rule",
            "alloc.by-id",
        ],
        [
            "sync.by-rule",
            "sync.ranked-vote",
            "alloc.by-id",
            "sync.by-rule",
            "alloc.by-id",
        ],
        [
            "sync.elected-leader",
            "sync.by-rule",
            "alloc.by-id",
            "sync.by-rule",
            "alloc.by-id",
        ],
        [
            "sync.vote",
            "sync.ranked-vote",
            "alloc.by-value",
            "sync.by-rule",
            "alloc.by-id",
        ],
        [
            "sync.by-rule",
            "sync.round-robin",
            "alloc.by-value",
            "sync.leader",
            "alloc.by-attribute",
        ],
        [
            "sync.elected-leader",
            "sync.by-rule",
            "alloc.by-id",
            "sync.elected-leader",
            "alloc.by-id",
        ],
    ];
    let sc = scenario("formation-sc.yaml", FORMATION_SC);
    for (row, g) in table2() {
        let o = simulate(&g, &sc, row as u64);
        let s = &o.report.summary;
        assert!(s.completed, "row {row}: {s}\n{}", replay(&o));
        assert_clean(&o, &format!("Table II row {row}"));
        for (label, want) in ["A", "B", "C", "D", "E"].iter().zip(rows[row - 1]) {
            let (b, kind) = o
                .mission
                .graph()
                .points()
                .into_iter()
                .find(|p| p.name == *label)
                .map(|p| (p.behavior, p.kind))
                .unwrap_or_else(|| panic!("no point {label}"));
            let bound = o.mission.bound(b, kind).map(|x| x.protocol.name());
            assert_eq!(bound, Some(want), "row {row}, point {label}");
        }
        // Interaction time is accounted per kind; the communicating rows
        // spend some in synchronization or allocation.
        let talk = s.interaction_time.sync + s.interaction_time.allocate;
        assert_eq!(talk > 0.0, row != 1, "row {row}: {s}");
    }
}

const PREEMPT: &str = r#"
graph: preempt
team: { robots: 2 }
start: mission
defaults: { terminate: term.wait-all }
behaviors:
  mission:
    team: true
    children: [work]
  work:
    team: true
    skill: job
    until: job_done
    URGENT
    next: [flee, rest]
    sync: sync.vote
  flee: { team: true, skill: run, until: safe, pre: alarm }
  rest: { team: true, skill: nap, until: rested, pre: not alarm }
"#;

const PREEMPT_SC: &str = r#"
scenario: preempt
seed: 1
time_limit: 300s
skills:
  job: { duration: [60, 60], start: { job_done: false }, done: { job_done: true } }
  run: { duration: [2, 2], start: { safe: false }, done: { safe: true } }
  nap: { duration: [1, 1], start: { rested: false }, done: { rested: true } }
events:
  # r1 works 60 s; r0 is done at 10 s, and sees an alarm at 12 s.
  - { at: 10s, robots: [r0], set: { job_done: true } }
  - { at: 12s, robots: [r0], set: { alarm: true } }
"#;

#[test]
fn an_urgent_condition_preempts_a_slow_termination() {
    let sc = scenario("preempt-sc.yaml", PREEMPT_SC);
    let flee_at = |text: &str| {
        let g = graph("preempt.yaml", text);
        let o = simulate(&g, &sc, 1);
        assert!(o.report.summary.completed, "{}", o.report.summary);
        assert_clean(&o, "preemption");
        let flee = g.find("flee").unwrap_or_else(|| panic!("flee"));
        let work = g.find("work").unwrap_or_else(|| panic!("work"));
        let h = &o.report.history;
        let started = h
            .iter()
            .find(|r| {
                r.robot == RobotId(0)
                    && matches!(r.event, Event::Selected { behavior, .. } if behavior == flee)
            })
            .map(|r| r.t.as_secs_f64());
        // r0 finished `work` at 10 s and waits at its barrier when the
        // alarm goes off: the wait is preempted.
        let urgent = h.iter().any(|r| {
            r.robot == RobotId(0)
                && matches!(r.event, Event::Preempted { behavior, .. } if behavior == work)
        });
        (started, urgent, o.report.summary.task_time)
    };
    // Without `urgent`, r0 is held at the barrier although the alarm went
    // off at 12 s: until r1's 60 s job ends, or here until the barrier's
    // 30 s deadline (from 10 s) lets it go on alone.
    let (slow, urgent, _) = flee_at(&PREEMPT.replace("URGENT", ""));
    assert!(!urgent);
    let slow = slow.unwrap_or(f64::INFINITY);
    assert!(slow >= 40.0, "r0 fled at {slow}");
    // With it, r0 leaves `work` at the next control tick after the alarm and
    // chooses its successor alone; the barrier is told, and r1 finishes.
    let (fast, urgent, _) = flee_at(&PREEMPT.replace("URGENT", "urgent: alarm"));
    assert!(urgent);
    let fast = fast.unwrap_or(f64::INFINITY);
    assert!((12.0..12.5).contains(&fast), "r0 fled at {fast}");
    // An alarm while still working ends the behavior at once, too.
    let g = graph("preempt.yaml", &PREEMPT.replace("URGENT", "urgent: alarm"));
    let early = scenario("early.yaml", &PREEMPT_SC.replace("at: 12s", "at: 5s"));
    let o = simulate(&g, &early, 1);
    assert!(o.report.summary.completed, "{}", o.report.summary);
    assert_clean(&o, "early alarm");
    let work = g.find("work").unwrap_or_else(|| panic!("work"));
    let ended = o.report.history.iter().find_map(|r| match r.event {
        Event::Terminated {
            behavior,
            reason: bite_core::event::EndReason::Urgent,
            ..
        } if behavior == work && r.robot == RobotId(0) => Some(r.t.as_secs_f64()),
        _ => None,
    });
    assert!(ended.is_some_and(|t| (5.0..5.5).contains(&t)), "{ended:?}");
}

/// Every re-allocation in the recorded history: (robot, round), in order.
fn reallocations(o: &Outcome) -> Vec<(u32, u32)> {
    o.report
        .history
        .iter()
        .filter_map(|r| match r.event {
            Event::Reallocating { round, .. } => Some((r.robot.0, round)),
            _ => None,
        })
        .collect()
}

/// One allocation point with K children and K robots: every robot gets
/// one child, the mission completes, and the heartbeats stay linear in
/// the team (each robot beacons its team leaders; the leaders and the
/// finished robots answer whoever beacons them). Before, every finished
/// robot beaconed the whole team: K = 10,000 took 8 minutes and 3 GB.
#[test]
fn one_allocation_point_with_many_children_stays_linear() {
    const K: usize = 600;
    let kids: Vec<String> = (0..K).map(|i| format!("c{i}")).collect();
    let mut g = format!(
        "graph: wide\nstart: mission\nteam: {{ robots: {K} }}\n\
         defaults: {{ sync: sync.by-rule, allocate: alloc.by-id, terminate: term.local }}\n\
         behaviors:\n  mission:\n    team: true\n    children: [{}]\n",
        kids.join(", ")
    );
    for k in &kids {
        g.push_str(&format!("  {k}: {{ skill: work, until: done }}\n"));
    }
    let sc = "scenario: wide\nworld: timed\nseed: 1\ncontrol_hz: 10\ntime_limit: 60s\n\
              skills:\n  work: { duration: [1.0, 2.0], start: { done: false }, done: { done: true } }\n";
    let o = simulate(&graph("wide.yaml", &g), &scenario("wide-sc.yaml", sc), 1);
    let s = &o.report.summary;
    assert!(s.completed, "{s}");
    assert_eq!(s.timeouts, 0, "{s}");
    assert_clean(&o, "wide");
    // Heartbeats every 250 ms: at most a handful per robot and period.
    let periods = (s.task_time / 0.25).ceil() as u64 + 2;
    let bound = 4 * K as u64 * periods;
    assert!(
        s.heartbeats.messages <= bound,
        "{} heartbeats for {K} robots over {periods} periods (bound {bound})",
        s.heartbeats.messages
    );
}

#[test]
fn a_large_team_handles_its_robots_events_side_by_side_and_runs_the_same() {
    // A large team on two threads (here from 64 robots) handles a timed
    // world's events of the robots (messages, heartbeats, timers) side by
    // side for a window
    // shorter than the network's least delay (`Sim::batch`), then carried
    // out in order. With loss, duplicates, skewed clocks, crashes, a
    // restart, forged messages and protocol deadlines, the run must be
    // byte for byte the one that handles one event at a time (one thread).
    use bite_sim::runner::{RunOptions, prepare, run};
    let g = graph("formation.yaml", FORMATION);
    let text = format!(
        "{FORMATION_SC}\nclocks:\n  r5: {{ rate: 1.02, offset: 30ms }}\n  r70: {{ rate: 0.97 }}\n\
         inject: {{ every: 150ms }}\n\
         crashes:\n  - {{ robot: r3, at: 2s, until: 4s, restart: true }}\n  - {{ robot: r0, at: 6s }}\n  - {{ robot: r40, at: 3s, until: 5s }}\n"
    );
    let mut sc = scenario("large.yaml", &text);
    sc.network.loss = 0.05;
    sc.network.duplicate = 0.05;
    // A slow network makes the window long: robots' own timers fall due
    // inside it, between their events, and are handled in their place.
    let mut slow = sc.clone();
    slow.network.latency = std::time::Duration::from_millis(150);
    slow.network.jitter = std::time::Duration::from_millis(40);
    // Protocols that retry every few milliseconds, on the slow network:
    // timers fall due between a robot's events of a window.
    let eager = Config::load_str(
        &Arc::from("eager.yaml"),
        "defaults:\n  sync: { retry: 7ms }\n  terminate: { retry: 7ms }\n  allocate: { retry: 7ms }\n",
    )
    .unwrap_or_else(|d| panic!("{d}"));
    let eager = g.with_config(&eager).unwrap_or_else(|d| panic!("{d}"));
    let on = |g: &bite_core::BehaviorGraph,
              sc: &Scenario,
              threads: usize,
              seed: u64,
              most: Option<usize>| {
        let mission = prepare(g, sc, Some(120), &bite_protocols::registry()).expect("prepares");
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        let mut log = Vec::new();
        let report = run(
            mission,
            sc,
            RunOptions {
                seed: Some(seed),
                log: Some(&mut log),
                time_limit: Some(std::time::Duration::from_secs(15)),
                pool: Some(Arc::new(pool)),
                // Side by side from 64 robots (5,000 by default).
                batch_from: Some(64),
                batch_most: most,
                ..RunOptions::default()
            },
        )
        .expect("runs");
        (log, report)
    };
    for (g, sc, seed) in [
        (&g, &sc, 1),
        (&g, &sc, 2),
        (&g, &slow, 3),
        (&eager, &slow, 4),
    ] {
        let (one, r1) = on(g, sc, 1, seed, None);
        let (two, r2) = on(g, sc, 2, seed, None);
        // Windows cut short at a few events: the rest begin the next.
        let (cut, r3) = on(g, sc, 2, seed, Some(5));
        let s = &r1.summary;
        assert!(
            s.network.lost > 0 && s.network.duplicated > 0,
            "seed {seed}: {s}"
        );
        let text = String::from_utf8_lossy(&one);
        assert!(
            text.contains("\"crashed\"") && text.contains("\"resumed\""),
            "seed {seed}: robots crashed and came back"
        );
        // The second run took the path under test: windows side by side,
        // and (on the slow network with eager retries) robots whose timer
        // could fall due first, and timers handled in between.
        let b = r2.batched;
        assert_eq!(
            r1.batched,
            Default::default(),
            "one thread: one event at a time"
        );
        assert!(b.windows > 0 && b.events > b.windows, "seed {seed}: {b:?}");
        if seed >= 3 {
            assert!(b.pooled > 0, "seed {seed}: {b:?}");
        }
        if seed == 4 {
            assert!(b.later > 0 && b.between > 0, "seed {seed}: {b:?}");
        }
        assert_eq!(b.cut, 0, "seed {seed}: no window reaches the default most");
        assert!(
            r3.batched.cut > 0 && r3.batched.windows > b.windows,
            "seed {seed}: {:?}",
            r3.batched
        );
        assert!(one == two, "seed {seed}: the logs differ on two threads");
        assert!(
            one == cut,
            "seed {seed}: the logs differ with windows cut short"
        );
        assert_eq!(r1.end, r2.end);
        assert_eq!(r1.end, r3.end);
        for r in [&r2, &r3] {
            assert_eq!(
                serde_json::to_string(&r1.summary).expect("json"),
                serde_json::to_string(&r.summary).expect("json")
            );
        }
    }
}
