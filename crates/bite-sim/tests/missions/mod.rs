//! What the whole-mission tests (timed and physical worlds) share:
//! loading, running with a fixed seed, and failing with the replay command.
#![allow(dead_code)] // each test crate uses its own part

use bite_core::graph::{BehaviorGraph, load_str};
use bite_core::mission::Mission;
use bite_sim::check::check;
use bite_sim::runner::{RunOptions, RunReport};
use bite_sim::{Scenario, prepare, run};
use std::sync::Arc;

pub const FORMATION: &str = include_str!("../../../../examples/formation.yaml");

/// Table II of the paper: configurations 1-7 of the formation graph.
pub const TABLE2: [&str; 7] = [
    include_str!("../../../../examples/configs/1.yaml"),
    include_str!("../../../../examples/configs/2.yaml"),
    include_str!("../../../../examples/configs/3.yaml"),
    include_str!("../../../../examples/configs/4.yaml"),
    include_str!("../../../../examples/configs/5.yaml"),
    include_str!("../../../../examples/configs/6.yaml"),
    include_str!("../../../../examples/configs/7.yaml"),
];

/// The formation graph under each Table II configuration: (row, graph).
pub fn table2() -> impl Iterator<Item = (usize, BehaviorGraph)> {
    TABLE2.iter().enumerate().map(|(i, text)| {
        let row = i + 1;
        let cfg = bite_core::graph::Config::load_str(&Arc::from(format!("{row}.yaml")), text)
            .unwrap_or_else(|d| panic!("{d}"));
        let g = graph("formation.yaml", FORMATION)
            .with_config(&cfg)
            .unwrap_or_else(|d| panic!("{d}"));
        (row, g)
    })
}

pub fn graph(name: &str, text: &str) -> BehaviorGraph {
    load_str(&Arc::from(name), text).unwrap_or_else(|d| panic!("{d}"))
}

pub fn scenario(name: &str, text: &str) -> Scenario {
    Scenario::load_str(&Arc::from(name), text).unwrap_or_else(|d| panic!("{d}"))
}

/// A mission in the command language (`text`, from file `name`) compiled
/// for a team of `robots` in physical scenario `sc` and bound to it, as
/// `bite run` does: the mission's origin from the scenario, its skills,
/// beliefs and targets added to it.
pub fn compiled(name: &str, text: &str, sc: &Scenario, robots: usize) -> (BehaviorGraph, Scenario) {
    let spec = sc.physics.as_ref().expect("a physical scenario");
    let out = bite_rtcl::compile(
        name,
        text,
        &bite_rtcl::Library::builtin(),
        &bite_rtcl::CompileOptions {
            origin: spec.mission_origin().to_array(),
            robots,
        },
    )
    .unwrap_or_else(|d| panic!("{d}\n{text}"));
    let g = graph(&format!("{name} (compiled)"), &out.graph());
    let parts = bite_sim::MissionParts {
        file: Arc::from(name),
        skills: out.skills_json(),
        beliefs: out.beliefs.clone(),
        targets: (out.targets.iter())
            .map(|(k, t)| {
                (
                    k.clone(),
                    bite_agent::spec::TargetSpec {
                        colour: t.colour.clone(),
                        size: t.size.unwrap_or([None; 3]),
                    },
                )
            })
            .collect(),
    };
    let sc = sc.with_mission(&parts).unwrap_or_else(|d| panic!("{d}"));
    (g, sc)
}

pub struct Outcome {
    pub mission: Arc<Mission>,
    pub report: RunReport,
    pub log: Vec<u8>,
}

pub fn simulate(g: &BehaviorGraph, sc: &Scenario, seed: u64) -> Outcome {
    simulate_team(g, sc, seed, None)
}

/// [`simulate`] with a team of `robots` (`bite run --robots`), or the
/// scenario's.
pub fn simulate_team(
    g: &BehaviorGraph,
    sc: &Scenario,
    seed: u64,
    robots: Option<usize>,
) -> Outcome {
    let mission =
        prepare(g, sc, robots, &bite_protocols::registry()).unwrap_or_else(|d| panic!("{d}"));
    let mut log = Vec::new();
    let report = run(
        mission.clone(),
        sc,
        RunOptions {
            seed: Some(seed),
            log: Some(&mut log),
            record: true,
            ..RunOptions::default()
        },
    )
    .unwrap_or_else(|d| panic!("{d}"));
    Outcome {
        mission,
        report,
        log,
    }
}

/// The command that replays a run (for failure messages).
pub fn replay(o: &Outcome) -> String {
    let s = &o.report.summary;
    format!(
        "replay: bite run examples/{}.yaml --scenario examples/scenarios/{}.yaml --seed {}{}",
        s.graph,
        s.scenario,
        s.seed,
        s.config
            .as_ref()
            .map(|c| format!(" (configuration {c})"))
            .unwrap_or_default()
    )
}

/// Fail with the seed and the command that replays the run.
pub fn assert_clean(o: &Outcome, what: &str) {
    let v = check(&o.report, &o.mission);
    let s = &o.report.summary;
    assert!(
        v.is_empty(),
        "{what}: invariants broken ({}):\n{}",
        replay(o),
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert_eq!(
        s.violations,
        0,
        "{what}: protocol violations ({})",
        replay(o)
    );
}
