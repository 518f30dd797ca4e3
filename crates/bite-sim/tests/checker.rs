//! The invariant checker must catch broken protocols: run the formation
//! mission with protocols that violate agreement and allocation on purpose.

use bite_core::graph::{Config, load_str};
use bite_core::ids::RobotId;
use bite_core::interaction::{
    Assignment, Cx, Factory, Interaction, Outcome, Params, Protocol, Registry,
};
use bite_core::msg::{Body, Kind};
use bite_core::org::MemberSet;
use bite_sim::check::check;
use bite_sim::runner::RunOptions;
use bite_sim::{Scenario, prepare, run};
use rand::RngExt;
use std::sync::Arc;

/// Each robot picks a random successor on its own: agreement must break.
struct Anarchy;
struct AnarchyInst;
impl Interaction for AnarchyInst {
    fn start(&mut self, cx: &mut Cx<'_>) {
        let succ = match cx.input() {
            bite_core::interaction::PointInput::Sync { successors, .. } => successors.to_vec(),
            _ => Vec::new(),
        };
        let i = cx.rng().random_range(0..succ.len().max(1));
        cx.decide(Outcome::Sync(succ.get(i).copied()));
    }
    fn on_message(&mut self, _: &mut Cx<'_>, _: RobotId, _: &Body) {}
    fn on_deadline(&mut self, _: &mut Cx<'_>) {}
}
impl Protocol for Anarchy {
    fn name(&self) -> &'static str {
        "sync.anarchy"
    }
    fn kind(&self) -> Kind {
        Kind::Sync
    }
    fn communicates(&self) -> bool {
        false
    }
    fn summary(&self) -> &'static str {
        "broken on purpose"
    }
    fn configure(
        &self,
        _: &Params,
        _: &mut bite_core::interaction::Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        Ok(Arc::new(|| Box::new(AnarchyInst) as Box<dyn Interaction>))
    }
}

/// Everyone takes the first child: coverage must break.
struct Crowd;
struct CrowdInst;
impl Interaction for CrowdInst {
    fn start(&mut self, cx: &mut Cx<'_>) {
        let n = cx.team().members.roster_len();
        let children: Vec<_> = cx.children().to_vec();
        let members: Vec<RobotId> = cx.members().collect();
        let a = children
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let set = if i == 0 {
                    MemberSet::from_iter(n, members.iter().copied())
                } else {
                    MemberSet::empty(n)
                };
                (c.behavior, set)
            })
            .collect();
        cx.decide(Outcome::Allocate(Assignment(a).into()));
    }
    fn on_message(&mut self, _: &mut Cx<'_>, _: RobotId, _: &Body) {}
    fn on_deadline(&mut self, _: &mut Cx<'_>) {}
}
impl Protocol for Crowd {
    fn name(&self) -> &'static str {
        "alloc.crowd"
    }
    fn kind(&self) -> Kind {
        Kind::Allocate
    }
    fn communicates(&self) -> bool {
        false
    }
    fn summary(&self) -> &'static str {
        "broken on purpose"
    }
    fn configure(
        &self,
        _: &Params,
        _: &mut bite_core::interaction::Setup<'_>,
    ) -> Result<Factory, bite_core::interaction::ConfigError> {
        Ok(Arc::new(|| Box::new(CrowdInst) as Box<dyn Interaction>))
    }
}

fn run_with(
    config: &str,
) -> (
    bite_sim::runner::RunReport,
    Arc<bite_core::mission::Mission>,
) {
    let g = load_str(
        &Arc::from("formation.yaml"),
        include_str!("../../../examples/formation.yaml"),
    )
    .unwrap_or_else(|d| panic!("{d}"));
    let cfg = Config::load_str(&Arc::from("broken.yaml"), config).unwrap_or_else(|d| panic!("{d}"));
    let g = g.with_config(&cfg).unwrap_or_else(|d| panic!("{d}"));
    let sc = Scenario::load_str(
        &Arc::from("f.yaml"),
        include_str!("../../../examples/scenarios/formation.yaml"),
    )
    .unwrap_or_else(|d| panic!("{d}"));
    let mut reg: Registry = bite_protocols::registry();
    reg.register(Arc::new(Anarchy));
    reg.register(Arc::new(Crowd));
    let mission = prepare(&g, &sc, None, &reg).unwrap_or_else(|d| panic!("{d}"));
    let report = run(
        mission.clone(),
        &sc,
        RunOptions {
            record: true,
            time_limit: Some(std::time::Duration::from_secs(120)),
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|d| panic!("{d}"));
    (report, mission)
}

fn violations_with(config: &str) -> Vec<&'static str> {
    let (report, mission) = run_with(config);
    check(&report, &mission)
        .iter()
        .map(|v| v.invariant)
        .collect()
}

/// The run as a launched team would have logged it: one JSON-lines log
/// per robot.
fn logs_of(
    report: &bite_sim::runner::RunReport,
    mission: &bite_core::mission::Mission,
) -> Vec<(String, Vec<serde_json::Value>)> {
    let namer = bite_sim::log::Namer::new(mission.graph());
    let roster = mission.graph().roster();
    roster
        .iter()
        .map(|(id, info)| {
            let recs = report
                .history
                .iter()
                .filter(|r| r.robot == id)
                .map(|r| namer.record(r.t, r.robot, &r.event))
                .collect();
            (info.name.clone(), recs)
        })
        .collect()
}

#[test]
fn logs_read_back_as_the_events_they_record() {
    let (report, mission) = run_with("bindings: { C: alloc.by-id }");
    let namer = bite_sim::log::Namer::new(mission.graph());
    let mut read = 0;
    for r in &report.history {
        let rec = namer.record(r.t, r.robot, &r.event);
        if let Some((t, robot, e)) = namer.unrecord(&mission, &rec) {
            read += 1;
            assert_eq!(robot, r.robot);
            // Team ids come back as their short names' stand-ins: compare
            // what the log says.
            assert_eq!(namer.record(t, robot, &e), rec);
        }
    }
    assert!(read > 50, "only {read} events read back");
}

#[test]
fn launched_logs_are_checked_like_a_simulated_run() {
    for (config, broken) in [
        (
            "bindings: { A: sync.anarchy, B: sync.anarchy }",
            Some("agreement"),
        ),
        ("bindings: { C: alloc.crowd }", Some("allocation")),
        ("bindings: { A: sync.vote, C: alloc.by-id }", None),
    ] {
        let (report, mission) = run_with(config);
        let (v, n) = bite_sim::check::check_logs(&mission, &logs_of(&report, &mission), &[]);
        assert!(n > 0);
        let names: Vec<_> = v.iter().map(|v| v.invariant).collect();
        match broken {
            Some(inv) => assert!(names.contains(&inv), "{config}: {names:?}"),
            None => assert!(names.is_empty(), "{config}: {names:?}"),
        }
    }
}

#[test]
fn the_checker_catches_disagreement() {
    let v = violations_with("bindings: { A: sync.anarchy, B: sync.anarchy }");
    assert!(v.contains(&"agreement"), "{v:?}");
}

#[test]
fn the_checker_catches_uncovered_children() {
    let v = violations_with("bindings: { C: alloc.crowd }");
    assert!(v.contains(&"allocation"), "{v:?}");
}

#[test]
fn correct_protocols_give_no_violation() {
    let v = violations_with("bindings: { A: sync.vote, C: alloc.by-id }");
    assert!(v.is_empty(), "{v:?}");
}
