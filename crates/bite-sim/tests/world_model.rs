//! Collaborative world modelling in whole missions: the paper's
//! synchronized-termination example, the Follow Left / Lead example, and
//! focused+helpful against broadcast on the shipped missions (task time
//! within 5 %, at most a fifth of the messages).

use bite_core::graph::Config;
use bite_sim::Scenario;
use std::sync::Arc;

mod missions;
use missions::{FORMATION, Outcome, assert_clean, graph, scenario, simulate};

const FORMATION_SC: &str = include_str!("../../../examples/scenarios/formation.yaml");
const FORMATION_PHYSICS: &str = include_str!("../../../examples/scenarios/formation-physics.yaml");
const COVERAGE: &str = include_str!("../../../examples/coverage.yaml");
const COVERAGE_SC: &str = include_str!("../../../examples/scenarios/coverage-physics.yaml");
const FOLLOW_LEAD: &str = include_str!("../../../examples/follow-lead.yaml");
const FOLLOW_LEAD_SC: &str = include_str!("../../../examples/scenarios/follow-lead.yaml");

fn sharing(policy: &str) -> Config {
    Config::load_str(
        &Arc::from(format!("{policy}.yaml")),
        &format!("config: {policy}\nworld_model: {{ sharing: {policy} }}\n"),
    )
    .unwrap_or_else(|d| panic!("{d}"))
}

fn run(g: &str, gtext: &str, sc: &Scenario, policy: &str) -> Outcome {
    let g = graph(g, gtext)
        .with_config(&sharing(policy))
        .unwrap_or_else(|d| panic!("{d}"));
    let o = simulate(&g, sc, 1);
    assert_clean(&o, policy);
    o
}

fn log_lines(o: &Outcome) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&o.log)
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect()
}

/// When each robot ended `behavior` (first time), from the run log.
fn ended(o: &Outcome, behavior: &str) -> Vec<f64> {
    let lines = log_lines(o);
    ["r0", "r1", "r2"]
        .iter()
        .map(|r| {
            lines
                .iter()
                .find(|x| {
                    x["event"] == "terminated" && x["robot"] == *r && x["behavior"] == behavior
                })
                .and_then(|x| x["t"].as_f64())
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

#[test]
fn the_robot_that_sees_the_narrowing_first_makes_the_others_believe_it() {
    // r0 sees the way narrow at 30 s, the others only at 34 s.
    let text = FORMATION_SC.replace(
        "  - { at: 30s, set: { narrow_ahead: true } }",
        "  - { at: 30s, robots: [r0], set: { narrow_ahead: true } }\n  - { at: 34s, robots: [r1, r2], set: { narrow_ahead: true } }",
    );
    assert_ne!(text, FORMATION_SC, "the scenario's event moved");
    let sc = scenario("formation.yaml", &text);
    // Without sharing, the triangle ends when the last robot sees it.
    let none = run("formation.yaml", FORMATION, &sc, "none");
    let t = ended(&none, "triangle");
    assert!(t[0] < 30.5 && t[1] >= 34.0 && t[2] >= 34.0, "{t:?}");
    // With Algorithm 2, r0 tells its team before its termination protocol
    // asks them: everyone ends the triangle at 30 s.
    let focused = run("formation.yaml", FORMATION, &sc, "focused");
    let t = ended(&focused, "triangle");
    assert!(t.iter().all(|t| (30.0..30.5).contains(t)), "{t:?}");
    let lines = log_lines(&focused);
    let inform = lines
        .iter()
        .position(|x| x["event"] == "inform" && x["robot"] == "r0" && x["about"] == "triangle")
        .expect("r0 informs about the triangle");
    let asks = lines
        .iter()
        .position(|x| {
            x["event"] == "interaction_started"
                && x["robot"] == "r0"
                && x["instance"]["behavior"] == "triangle"
                && x["instance"]["kind"] == "terminate"
        })
        .expect("r0 starts the triangle's termination");
    assert!(inform < asks, "the belief travels before the protocol");
    assert_eq!(lines[inform]["reason"], "obligatory");
    assert_eq!(lines[inform]["to"], serde_json::json!(["r1", "r2"]));
    assert_eq!(
        lines[inform]["beliefs"],
        serde_json::json!(["narrow_ahead"])
    );
}

#[test]
fn only_helpful_information_tells_the_leader_what_the_followers_see() {
    let sc = scenario("follow-lead.yaml", FOLLOW_LEAD_SC);
    let time = |p: &str| {
        let o = run("follow-lead.yaml", FOLLOW_LEAD, &sc, p);
        assert!(o.report.summary.completed, "{p}");
        (o.report.summary.task_time, o)
    };
    let (none, _) = time("none");
    let (focused, _) = time("focused");
    let (helpful, h) = time("helpful");
    let (broadcast, _) = time("broadcast");
    // The leader walks its whole course unless told (83 s at its pace).
    assert!(
        none > 80.0 && focused > 80.0,
        "none {none}, focused {focused}"
    );
    assert!(
        helpful < 26.0 && broadcast < 26.0,
        "helpful {helpful}, broadcast {broadcast}"
    );
    let sharing = h.report.summary.sharing.as_ref().expect("sharing totals");
    assert_eq!(sharing.messages["obligatory"], 0);
    assert!(sharing.messages["helpful"] >= 1);
    // Each helpful message goes to the one robot of the role it is about
    // (roles by id: r0 leads, r1 left, r2 right), from another robot.
    let informs: Vec<serde_json::Value> = log_lines(&h)
        .into_iter()
        .filter(|x| x["event"] == "inform")
        .collect();
    for x in &informs {
        let to = match x["about"].as_str() {
            Some("lead") => "r0",
            Some("follow_left") => "r1",
            Some("follow_right") => "r2",
            other => panic!("helpful message about {other:?}"),
        };
        assert_eq!(x["to"], serde_json::json!([to]), "{x}");
        assert_ne!(x["robot"], to, "{x}");
    }
    assert!(
        informs.iter().any(|x| x["about"] == "lead"),
        "the leader is told"
    );
}

#[test]
fn focused_helpful_matches_broadcast_with_a_fraction_of_its_messages() {
    let formation = scenario("formation.yaml", FORMATION_SC);
    let formation_physics = scenario("formation-physics.yaml", FORMATION_PHYSICS);
    let coverage = scenario("coverage-physics.yaml", COVERAGE_SC);
    let follow = scenario("follow-lead.yaml", FOLLOW_LEAD_SC);
    let cases: [(&str, &str, &Scenario); 4] = [
        ("formation.yaml", FORMATION, &formation),
        ("formation.yaml", FORMATION, &formation_physics),
        ("coverage.yaml", COVERAGE, &coverage),
        ("follow-lead.yaml", FOLLOW_LEAD, &follow),
    ];
    for (g, text, sc) in cases {
        let b = run(g, text, sc, "broadcast");
        let f = run(g, text, sc, "focused+helpful");
        let (bs, fs) = (&b.report.summary, &f.report.summary);
        let what = format!("{g} on {}", sc.name);
        assert!(bs.completed && fs.completed, "{what}");
        assert!(
            fs.task_time <= bs.task_time * 1.05,
            "{what}: task time {} vs broadcast {}",
            fs.task_time,
            bs.task_time
        );
        let (bm, fm) = (
            bs.sharing.as_ref().map_or(0, |s| s.total()),
            fs.sharing.as_ref().map_or(0, |s| s.total()),
        );
        assert!(bm > 0, "{what}: broadcast sent nothing");
        assert!(fm * 5 <= bm, "{what}: {fm} messages vs broadcast {bm}");
    }
}
