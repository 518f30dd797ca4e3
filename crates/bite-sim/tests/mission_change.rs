//! Changing a running mission: the formation's course changes mid-way
//! (`examples/formation-change.yaml` → `formation-change-v2.yaml`), at
//! many times, over many seeds, under loss, partitions, crashes and
//! restarts around the change. Every member of a team switches at the
//! same safe point, the team never splits over a version, nobody stalls.

mod missions;

use bite_core::event::Event;
use bite_sim::fault::{Fault, apply_all};
use bite_sim::runner::{Change, RunOptions, prepare_change};
use bite_sim::summary::Outcome;
use bite_sim::{prepare, run};
use missions::{graph, scenario};
use std::time::Duration;

const V1: &str = include_str!("../../../examples/formation-change.yaml");
const V2: &str = include_str!("../../../examples/formation-change-v2.yaml");
const SCENARIO: &str = include_str!("../../../examples/scenarios/formation-change.yaml");

struct Run {
    summary: bite_sim::summary::Summary,
    violations: Vec<String>,
    /// (robot, version, after behavior) of every switch.
    switched: Vec<(u32, u32, String)>,
    /// Live robots' versions at the end.
    versions: Vec<u32>,
    /// Members that stopped waiting for their leader's decision at a safe
    /// point.
    fence_timeouts: usize,
    v2: std::sync::Arc<bite_core::mission::Mission>,
}

/// The same run without a change: on the first version, or (`second`)
/// on the second from the start.
fn run_alone(second: bool, seed: u64, faults: &[Fault]) -> Outcome {
    let g = if second {
        graph("formation-change-v2.yaml", V2)
    } else {
        graph("formation-change.yaml", V1)
    };
    let mut sc = scenario("formation-change.yaml", SCENARIO);
    sc.mission_changes.clear();
    missions::simulate(&g, &apply_all(&sc, faults), seed)
        .report
        .summary
        .outcome
}

fn run_change(at: f64, seed: u64, faults: &[Fault]) -> Run {
    run_changes(&[at], seed, faults)
}

/// Version 3: the course shortened again to 7 m.
fn v3_text() -> String {
    V2.replace("distance_walked >= 8", "distance_walked >= 7")
}

/// Hand versions 2, 3, ... at the times `at` (the second and later ones
/// from `v3_text`, each aligned to the one before).
fn run_changes(at: &[f64], seed: u64, faults: &[Fault]) -> Run {
    let g = graph("formation-change.yaml", V1);
    let mut sc = scenario("formation-change.yaml", SCENARIO);
    // The test hands the change itself, at `at`.
    sc.mission_changes.clear();
    let sc = apply_all(&sc, faults);
    let reg = bite_protocols::registry();
    let v1 = prepare(&g, &sc, None, &reg).unwrap_or_else(|d| panic!("{d}"));
    let v2 = prepare_change(&v1, &graph("formation-change-v2.yaml", V2), &reg)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut changes = Vec::new();
    let mut base = v1.clone();
    for (i, t) in at.iter().enumerate() {
        let m = if i == 0 {
            v2.clone()
        } else {
            prepare_change(&base, &graph("v3.yaml", &v3_text()), &reg)
                .unwrap_or_else(|e| panic!("{e}"))
        };
        changes.push(Change {
            at: bite_core::time::Time::ZERO + Duration::from_secs_f64(*t),
            version: i as u32 + 1,
            mission: m.clone(),
            source: format!("version {}", i + 1),
        });
        base = m;
    }
    let report = run(
        v1,
        &sc,
        RunOptions {
            seed: Some(seed),
            record: true,
            changes,
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|d| panic!("{d}"));
    let switched = report
        .history
        .iter()
        .filter_map(|r| match &r.event {
            Event::MissionChanged { version, after, .. } => Some((
                r.robot.0,
                *version,
                after.map_or("(rejoining)".to_string(), |a| {
                    v2.graph().name_of(a.behavior).to_string()
                }),
            )),
            _ => None,
        })
        .collect();
    let versions = (report.finals.iter())
        .filter(|f| !f.crashed)
        .map(|f| f.version)
        .collect();
    let fence_timeouts = (report.history.iter())
        .filter(|r| {
            matches!(
                r.event,
                Event::MissionChangeDeferred {
                    timed_out: true,
                    ..
                }
            )
        })
        .count();
    Run {
        fence_timeouts,
        violations: report.violations.iter().map(ToString::to_string).collect(),
        summary: report.summary,
        switched,
        versions,
        v2,
    }
}

/// What run `what` broke: an invariant, or it stalled or ran out of time.
fn broken(what: &str, r: &Run) -> Vec<String> {
    let mut out = Vec::new();
    if !r.violations.is_empty() {
        out.push(format!("{what}: {:?}", r.violations));
    }
    if !matches!(
        r.summary.outcome,
        Outcome::Completed | Outcome::CompletedWithTimeouts
    ) {
        out.push(format!("{what}: {}", r.summary));
    }
    out
}

/// Run `what` broke nothing and ended with its three robots on the second
/// version.
fn assert_whole_on_version_2(what: &str, r: &Run) {
    let broke = broken(what, r);
    assert!(broke.is_empty(), "{broke:?}");
    assert_eq!(r.versions, [1, 1, 1], "{what}: {}", r.summary);
}

/// The behaviors after which robots of run `r` switched versions.
fn safe_points(r: &Run) -> std::collections::BTreeSet<&str> {
    r.switched.iter().map(|s| s.2.as_str()).collect()
}

fn faults(spec: &str) -> Vec<Fault> {
    Fault::parse_all(spec).unwrap_or_else(|e| panic!("{spec}: {e}"))
}

#[test]
fn the_example_changes_course_mid_way_and_completes_with_everyone_switching_together() {
    let g = graph("formation-change.yaml", V1);
    let sc = scenario("formation-change.yaml", SCENARIO);
    assert_eq!(
        sc.mission_changes.len(),
        1,
        "the example scenario changes the mission"
    );
    let r = run_change(sc.mission_changes[0].at.as_secs_f64(), sc.seed, &[]);
    assert_eq!(r.summary.outcome, Outcome::Completed, "{}", r.summary);
    assert!(r.violations.is_empty(), "{:?}", r.violations);
    assert_eq!(
        r.switched.len(),
        3,
        "every robot switches: {:?}",
        r.switched
    );
    let after = safe_points(&r);
    assert_eq!(
        after.len(),
        1,
        "all at the same safe point: {:?}",
        r.switched
    );
    assert_eq!(r.versions, [1, 1, 1]);
    // The new version ran: the column (new) instead of the line (retired).
    let line = r.v2.graph().find("line").expect("line is kept, retired");
    assert!(r.v2.graph().is_retired(line));
    assert!(g.find("column").is_none());
    let ran = |name: &str| r.summary.points.iter().any(|p| p.point.starts_with(name));
    assert!(ran("column"), "{}", r.summary);
}

#[test]
fn a_change_that_cannot_be_applied_safely_is_refused_with_the_reason() {
    let g = graph("formation-change.yaml", V1);
    let sc = scenario("formation-change.yaml", SCENARIO);
    let reg = bite_protocols::registry();
    let v1 = prepare(&g, &sc, None, &reg).unwrap_or_else(|d| panic!("{d}"));
    // `walk` loses its children: robots inside it could not end it.
    let bad = V2.replace(
        "    children: [lead, follow_left, follow_right]\n",
        "    skill: walk_lead\n",
    );
    let bad = bad.replace("    allocate: { point: C }\n", "");
    let e = prepare_change(&v1, &graph("bad.yaml", &bad), &reg).unwrap_err();
    assert!(e.contains("`walk` has children"), "{e}");
    // Another team.
    let e = prepare_change(
        &v1,
        &graph("bad.yaml", &V2.replace("{ name: r2,", "{ name: r9,")),
        &reg,
    )
    .unwrap_err();
    assert!(e.contains("team differs"), "{e}");
}

/// The change at many times (so that it meets every kind of safe point:
/// after a search, a leg, the narrow passage), over seeds and fault
/// classes: loss, a partition across the change, the leader crashing at
/// the change, a restart during it.
#[test]
fn hot_change_under_loss_and_crashes_never_splits_or_stalls() {
    let classes: [(&str, &str); 6] = [
        ("fault-free", ""),
        ("loss", "loss=0.15"),
        ("heavy-loss", "loss=0.3;dup=0.05;jitter=30ms"),
        ("partition", "partition=r0|r1,r2@{p}+4s"),
        ("leader-crash", "crash=r0@{c}"),
        ("restart", "restart=r1@{c}+3s"),
    ];
    let mut failures = Vec::new();
    let mut runs = 0;
    let mut switched_runs = 0;
    let mut with_deadlines = Vec::new();
    let mut base_deadlines = Vec::new();
    for (class, spec) in classes {
        for seed in 1..=25u64 {
            let at = 8.0 + (seed as f64 * 9.7) % 45.0;
            let spec = spec
                .replace("{p}", &format!("{:.1}s", at - 1.0))
                .replace("{c}", &format!("{:.1}s", at + 0.5 + seed as f64));
            let r = run_change(at, seed, &faults(&spec));
            runs += 1;
            let what = format!("{class} seed {seed} change at {at:.1}s [{spec}]");
            // Under heavy loss a barrier may need its deadline, with or
            // without a change (the same seed runs into it on either version
            // alone); the change itself never leaves a member waiting for
            // its leader's decision.
            failures.extend(broken(&what, &r));
            if r.summary.outcome == Outcome::CompletedWithTimeouts {
                with_deadlines.push(what.clone());
            }
            if [false, true]
                .iter()
                .any(|v2| run_alone(*v2, seed, &faults(&spec)) == Outcome::CompletedWithTimeouts)
            {
                base_deadlines.push(what.clone());
            }
            if r.fence_timeouts > 0 && !class.contains("crash") {
                failures.push(format!(
                    "{what}: {} members gave up waiting for their leader's decision",
                    r.fence_timeouts
                ));
            }
            // A live team ends on one version (nobody left behind on a
            // version its team left).
            let vs: std::collections::BTreeSet<u32> = r.versions.iter().copied().collect();
            if vs.len() > 1 {
                failures.push(format!("{what}: versions at the end {:?}", r.versions));
            }
            if vs.contains(&1) {
                switched_runs += 1;
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {runs} runs:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // Protocol deadlines (a barrier under loss) are about as frequent as
    // in the same runs without a change (on either version alone).
    eprintln!(
        "runs needing a protocol deadline: {} with the change, {} without, of {runs}",
        with_deadlines.len(),
        base_deadlines.len()
    );
    assert!(
        with_deadlines.len() <= base_deadlines.len() + runs / 20,
        "with the change: {with_deadlines:?}\nwithout: {base_deadlines:?}"
    );
    assert!(
        switched_runs * 10 >= runs * 9,
        "the change was applied in only {switched_runs} of {runs} runs"
    );
}

/// Found on unseen seeds (`bite sweep --graph examples/formation-change.yaml
/// --seeds 321..400`, partition seed 325): r0 is cut from r1 and r2 at
/// 12.9 s, ends `walk` #1 alone and goes on in the running version; the
/// change comes at 20 s; the partition heals at 21.3 s. Two defects:
///
/// - r1, its side's leader while r0 was presumed lost, switched after
///   `walk` #1 on r0's notice of how the walk ended, before r0's heartbeats
///   said r0 had gone on in the running version there; r2, reaching the
///   same boundary after r0 was back, followed r0. The team chose in two
///   versions. A leader now holds for a member presumed lost but heard
///   from since.
/// - r0 and r2 had both left `walk` #1 and answered each other's `Done` for
///   r2's re-allocation of it, a hundred messages a second until the end
///   of the mission (6,348 in all). A `Done` or a notice now gets no answer.
#[test]
fn a_change_after_a_partition_waits_for_the_teammate_that_went_on_alone() {
    let r = run_change(20.0, 325, &faults("partition=r0|r1,r2@12.904s+8.391s"));
    assert_whole_on_version_2("seed 325", &r);
    let after = safe_points(&r);
    assert_eq!(
        after.len(),
        1,
        "all at the same safe point: {:?}",
        r.switched
    );
    let sent = r.summary.messages.total();
    assert!(sent < 300, "{sent} messages: robots answering each other");
}

/// Found on unseen seeds (`bite sweep --graph examples/formation-change.yaml
/// --classes pause --seeds 481..1280`, seed 1041), which never finished: a
/// member holding at a safe point for its leader waits longer while the
/// leader is heard, but its timer was due after the shorter wait, so from
/// then on it was woken at the same instant, again and again, and the
/// simulated clock stood still. The run completes now.
#[test]
fn a_member_holding_for_its_leader_is_woken_when_its_wait_is_over() {
    let r = run_change(20.0, 1041, &faults("pause=r1@29.552s+7.128s"));
    assert_whole_on_version_2("seed 1041", &r);
}

/// Found on unseen seeds (`bite sweep --graph examples/formation-change.yaml
/// --seeds 481..1280`): a robot that reaches a safe point late read the
/// version a teammate runs *now* as the version it chose in there. In
/// pause seed 1222, r0 and r1 end `walk` #1 without r2 (paused) and with
/// no change pending; the change comes at 20 s and they switch after
/// `search` #2. r2, back at 23 s, reached the boundary after `walk` #1 and
/// switched there, its leader and its teammate being on the new version:
/// the team chose in two versions after `walk` #1. A teammate that
/// switched at a later boundary (its fences and the order of its ends say
/// so) went on in an older version at the earlier one. One-way seeds 965
/// and 1011 broke the same invariant and pass with the same change.
#[test]
fn a_late_member_does_not_take_a_later_switch_for_one_at_its_boundary() {
    for (seed, spec) in [
        (1222, "pause=r2@16.032s+6.914s"),
        (965, "oneway=r1>r0,r2@2.549s+21.493s"),
        (1011, "oneway=r2>r0,r1@16.474s+13.202s"),
    ] {
        let r = run_change(20.0, seed, &faults(spec));
        assert_whole_on_version_2(&format!("seed {seed}"), &r);
        if seed == 1222 {
            // Everyone switched at the same safe point, r2 as it caught up.
            let after = safe_points(&r);
            assert_eq!(after, ["search"].into(), "{:?}", r.switched);
        }
    }
}

/// Found on unseen seeds (`bite sweep --graph examples/formation-change.yaml
/// --seeds 1281..1680`, pause seed 1451): r1 reaches the safe point after
/// `search` #2 with the change pending and holds for its leader's
/// decision; it is paused at 20.3 s for 6.8 s. r0 and r2 switch there
/// meanwhile. Back at 27.1 s, r1 found its 5 s hold over before it heard a
/// heartbeat and went on in the running version: the team chose in two
/// versions. Time asleep no longer counts toward the hold: r1 hears its
/// teammates' decision and switches there too.
#[test]
fn a_hold_at_a_safe_point_does_not_run_out_while_its_robot_is_paused() {
    let r = run_change(20.0, 1451, &faults("pause=r1@20.275s+6.82s"));
    assert_whole_on_version_2("seed 1451", &r);
    let after = safe_points(&r);
    assert_eq!(after, ["search"].into(), "{:?}", r.switched);
    assert_eq!(r.fence_timeouts, 0, "{}", r.summary);
}

/// Two versions in quick succession (the second while the first is still
/// pending on some robots, or just applied on others): no split between
/// versions, and the team ends on the newest.
#[test]
fn two_changes_in_quick_succession_leave_one_team_on_the_newest_version() {
    let mut failures = Vec::new();
    let mut runs = 0;
    for (class, spec) in [
        ("fault-free", ""),
        ("loss", "loss=0.15"),
        ("partition", "partition=r0|r1,r2@{p}+4s"),
        ("restart", "restart=r1@{p}+3s"),
    ] {
        for seed in 1..=15u64 {
            let at = 8.0 + (seed as f64 * 9.7) % 45.0;
            let gap = 0.2 + (seed as f64 * 0.37) % 3.0;
            let spec = spec.replace("{p}", &format!("{:.1}s", at - 0.5));
            let r = run_changes(&[at, at + gap], seed, &faults(&spec));
            runs += 1;
            let what = format!(
                "{class} seed {seed} changes at {at:.1}s and {:.1}s [{spec}]",
                at + gap
            );
            failures.extend(broken(&what, &r));
            if r.versions.iter().any(|v| *v != 2) {
                failures.push(format!("{what}: versions at the end {:?}", r.versions));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {runs} runs:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
