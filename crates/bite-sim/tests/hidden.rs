//! The box-push missions with the box hidden by the seed
//! (`examples/scenarios/*-hidden-physics.yaml`): the box is out of every
//! camera's sight at t = 0, the robots' search finds it, and the outcome is
//! reported as it is — completed with the box delivered, or not — with no
//! invariant broken.

use bite_core::event::Event;
use bite_core::graph::BehaviorGraph;
use bite_sim::Scenario;
use bite_sim::physics::World;

mod missions;
use missions::{assert_clean, compiled, graph, scenario, simulate};

const SEARCH_RESCUE: &str = include_str!("../../../examples/search-rescue.rtcl");
const SEARCH_RESCUE_HIDDEN: &str =
    include_str!("../../../examples/scenarios/search-rescue-hidden-physics.yaml");
const BOX_PUSH: &str = include_str!("../../../examples/box-push.yaml");
const BOX_PUSH_HIDDEN: &str =
    include_str!("../../../examples/scenarios/box-push-hidden-physics.yaml");

/// `search-rescue.rtcl` compiled against `sc` and bound to it, as `bite
/// run` does: the mission's origin and team size from the scenario.
fn search_rescue(sc: &Scenario) -> (BehaviorGraph, Scenario) {
    let robots = sc
        .physics
        .as_ref()
        .expect("a physical scenario")
        .start
        .len();
    compiled("search-rescue.rtcl", SEARCH_RESCUE, sc, robots)
}

/// Run `g` on `sc` with `seed` and check the hidden `object`: nobody saw it
/// at t = 0, the robots searched before they moved it (`moving` is the
/// first behavior after the search), and the summary tells the outcome as
/// it is. True when the mission completed.
fn hidden_run(g: &BehaviorGraph, sc: &Scenario, seed: u64, object: &str, moving: &str) -> bool {
    let what = format!("{} seed {seed}", sc.name);
    // The world the run starts from (the runner and the Zenoh simulator
    // server build it the same way): no camera sees the object.
    let spec = sc.physics.clone().expect("physical");
    let k = (spec.objects.iter())
        .position(|o| o.name.as_deref() == Some(object))
        .expect("the object");
    assert!(
        spec.objects[k]
            .place
            .as_ref()
            .is_some_and(|p| p.out_of_sight)
    );
    let names: Vec<String> = (0..g.roster().len() as u32)
        .map(|r| g.roster().name(bite_core::ids::RobotId(r)).to_string())
        .collect();
    let mut w = World::new(spec, &names, g.symbols(), &sc.file, seed)
        .unwrap_or_else(|d| panic!("{what}: {d}"));
    let at = w.object_pos(k);
    for (i, name) in names.iter().enumerate() {
        let seen = w.observe(i).objects.iter().any(|(o, _)| *o == k);
        assert!(!seen, "{what}: {name} sees the {object} at {at} at t = 0");
    }

    let o = simulate(g, sc, seed);
    assert_clean(&o, &what);
    let s = &o.report.summary;
    // The run put the object where that world did.
    let log = String::from_utf8_lossy(&o.log);
    let first: serde_json::Value = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("a JSON record"))
        .find(|r| r["event"] == "poses")
        .expect("a poses record");
    let logged = &first["objects"][object];
    assert_eq!(first["t"], 0.0, "{what}");
    let (x, y) = (logged[0].as_f64(), logged[1].as_f64());
    assert!(
        x.zip(y)
            .is_some_and(|(x, y)| (x - at.x).abs() < 1e-3 && (y - at.y).abs() < 1e-3),
        "{what}: the run put the {object} at {logged}, the world at {at}"
    );
    // The search: first seen after t = 0, and every robot that moved it
    // searched first.
    let world = s.world.as_ref().expect("a world summary");
    let seen = world.first_seen.get(object).copied();
    assert!(
        seen.is_none_or(|t| t > 0.0),
        "{what}: first seen at {seen:?}"
    );
    let b = g.find(moving).expect("the behavior after the search");
    for rec in &o.report.history {
        if let Event::Selected { behavior, .. } = &rec.event
            && *behavior == b
        {
            assert!(
                seen.is_some_and(|t| t <= rec.t.as_secs_f64()),
                "{what}: r{} started `{moving}` at {} before anyone saw the {object} ({seen:?})",
                rec.robot.0,
                rec.t
            );
        }
    }
    // The outcome, as it is.
    if s.completed {
        let met = world.goal_met_at;
        assert!(
            met.is_some_and(|t| t <= s.task_time + 1e-9),
            "{what}: completed, but the goal was met at {met:?}"
        );
        assert!(
            seen.is_some(),
            "{what}: completed without seeing the {object}"
        );
    } else {
        assert!(
            matches!(
                s.outcome,
                bite_sim::summary::Outcome::Stalled | bite_sim::summary::Outcome::NotCompleted
            ),
            "{what}: not completed, but the outcome is {:?}",
            s.outcome
        );
    }
    s.completed
}

#[test]
fn the_hidden_box_is_searched_for_then_rescued() {
    let (g, sc) = search_rescue(&scenario(
        "search-rescue-hidden-physics.yaml",
        SEARCH_RESCUE_HIDDEN,
    ));
    let done = (1..=5)
        .filter(|&seed| hidden_run(&g, &sc, seed, "yellow_box", "move_2"))
        .count();
    // 38 of seeds 1..40 complete (docs/scenario-format.md).
    assert!(done >= 4, "{done} of 5 completed");
}

#[test]
fn the_hand_written_box_push_searches_for_the_hidden_box() {
    let g = graph("box-push.yaml", BOX_PUSH);
    let sc = scenario("box-push-hidden-physics.yaml", BOX_PUSH_HIDDEN);
    let done = (1..=5)
        .filter(|&seed| hidden_run(&g, &sc, seed, "box", "first_leg"))
        .count();
    assert!(done >= 1, "{done} of 5 completed");
}
