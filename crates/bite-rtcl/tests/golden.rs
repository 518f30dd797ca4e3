//! Golden tests: every shipped mission (`examples/*.rtcl`) compiles to the
//! graph checked in under `tests/golden/<name>.yaml` (and the skills,
//! beliefs and targets under `tests/golden/<name>.world.yaml`), and the
//! graph loads, validates and resolves its protocols without a warning.
//!
//! Regenerate the golden files after an intended change with
//! `BLESS=1 cargo test -p bite-rtcl --test golden`.

use bite_rtcl::{CompileOptions, Library, compile};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The options each shipped mission is compiled with: the team its
/// scenario has; the default origin.
fn options(name: &str) -> CompileOptions {
    let robots = match name {
        "formation-walk" => 3,
        "coverage-sweep" => 5,
        _ => 2,
    };
    CompileOptions {
        robots,
        ..CompileOptions::default()
    }
}

fn missions() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("examples"))
        .expect("examples/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "rtcl"))
        .collect();
    v.sort();
    v
}

fn check_golden(path: &Path, actual: &str, failures: &mut Vec<String>) {
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(path, actual).expect("write golden file");
        return;
    }
    match std::fs::read_to_string(path) {
        Ok(expected) if expected == actual => {}
        Ok(expected) => {
            let line = expected
                .lines()
                .zip(actual.lines())
                .position(|(a, b)| a != b)
                .unwrap_or_else(|| expected.lines().count().min(actual.lines().count()));
            failures.push(format!(
                "{} differs from the compiler's output at line {}:\n  golden: {:?}\n  actual: {:?}\n(run with BLESS=1 to accept)",
                path.display(),
                line + 1,
                expected.lines().nth(line).unwrap_or("<end>"),
                actual.lines().nth(line).unwrap_or("<end>")
            ));
        }
        Err(_) => failures.push(format!(
            "{} is missing (run with BLESS=1 to create it)",
            path.display()
        )),
    }
}

#[test]
fn shipped_missions_match_their_golden_graphs() {
    let lib = Library::builtin();
    let registry = bite_protocols::registry();
    let missions = missions();
    assert!(
        missions.len() >= 4,
        "expected the shipped missions in examples/, found {missions:?}"
    );
    let mut failures = Vec::new();
    for m in &missions {
        let name = m.file_stem().and_then(|s| s.to_str()).expect("name");
        let text = std::fs::read_to_string(m).expect("read mission");
        let file = format!("examples/{name}.rtcl");
        let out = compile(&file, &text, &lib, &options(name))
            .unwrap_or_else(|e| panic!("{file} does not compile:\n{e}"));
        assert!(out.warnings.is_empty(), "{file}: {:?}", out.warnings);
        // The graph loads and validates, with no warning, and every
        // protocol it binds exists.
        let graph = bite_core::graph::load_str(&Arc::from(format!("{name}.yaml")), &out.graph())
            .unwrap_or_else(|e| {
                panic!(
                    "{file}: the generated graph does not load:\n{e}\n{}",
                    out.graph()
                )
            });
        assert!(
            graph.warnings().is_empty(),
            "{file}: {:?}",
            graph.warnings()
        );
        bite_core::Mission::new(graph, &registry)
            .unwrap_or_else(|e| panic!("{file}: the graph's protocols do not resolve:\n{e}"));
        // Every skill the graph names has schemas; every belief it reads
        // is defined.
        for s in out.steps.iter().flat_map(|s| &s.behaviors) {
            if out.graph().contains(&format!("    skill: {s}\n")) {
                assert!(
                    out.skills.get(s).is_some_and(|v| !v.is_empty()),
                    "{file}: skill {s}"
                );
            }
        }
        let golden = root().join("crates/bite-rtcl/tests/golden");
        check_golden(
            &golden.join(format!("{name}.yaml")),
            &out.graph(),
            &mut failures,
        );
        check_golden(
            &golden.join(format!("{name}.world.yaml")),
            &out.world_yaml(),
            &mut failures,
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The search-and-rescue mission has the shape of the hand-written
/// `examples/box-push.yaml`: a root team behavior, the search, a first leg
/// with push/watch, a last leg with step_aside/finish_push.
#[test]
fn search_rescue_has_the_shape_of_the_hand_written_box_push() {
    let text =
        std::fs::read_to_string(root().join("examples/search-rescue.rtcl")).expect("mission");
    let out = compile(
        "search-rescue.rtcl",
        &text,
        &Library::builtin(),
        &CompileOptions {
            origin: [6.7, 1.5],
            robots: 2,
        },
    )
    .expect("compiles");
    let g = bite_core::graph::load_str(&Arc::from("sr.yaml"), &out.graph()).expect("loads");
    let names = |b: &str| -> Vec<String> {
        let beh = g.find(b).unwrap_or_else(|| panic!("no behavior {b}"));
        g.behavior(beh)
            .children
            .iter()
            .map(|c| g.name_of(*c).to_string())
            .collect()
    };
    assert_eq!(names("mission"), ["find_1"]);
    assert_eq!(names("move_2"), ["move_2_first_leg"]);
    assert_eq!(names("move_2_first_leg"), ["move_2_push", "move_2_watch"]);
    assert_eq!(
        names("move_2_last_leg"),
        ["move_2_step_aside", "move_2_finish_push"]
    );
    // The goal, moved by the origin, is the box-push goal between the chairs.
    assert_eq!(
        out.beliefs["move_2_delivered"],
        "dist(box_pos, [6.2, 2]) < 0.3"
    );
    assert_eq!(out.beliefs["find_1_found"], "known(box_pos)");
    assert_eq!(
        out.skills["move_2_push_drive"][0],
        serde_json::json!({"schema": "push", "object": "box", "goal": [6.2, 2], "offset": 0.4, "speed": 0.2, "layer": 2})
    );
    // The paper's priority change: avoidance is layer 3 while finding,
    // below the push (1) while moving.
    let layer = |skill: &str, schema: &str| {
        out.skills[skill]
            .iter()
            .map(bite_rtcl::Json::to_json)
            .find(|s| s["schema"] == schema)
            .and_then(|s| s["layer"].as_u64())
    };
    assert_eq!(layer("find_1", "avoid-obstacle"), Some(3));
    assert_eq!(layer("move_2_push_drive", "avoid-obstacle"), Some(1));
    assert_eq!(layer("move_2_push_drive", "push"), Some(2));
    // Getting to the object, avoidance overrides again.
    assert_eq!(layer("move_2_push", "avoid-obstacle"), Some(3));
    // The pusher's chain: approach, then push.
    let push = g.find("move_2_push").expect("push");
    let next: Vec<&str> = g
        .behavior(push)
        .next
        .iter()
        .map(|b| g.name_of(*b))
        .collect();
    assert_eq!(next, ["move_2_push_drive"]);
    assert_eq!(out.targets["box"].colour.as_deref(), Some("yellow"));
    assert_eq!(out.targets["box"].size, None);
    assert_eq!(
        out.steps
            .iter()
            .map(|s| (s.command.as_str(), s.behavior.as_str(), s.line))
            .collect::<Vec<_>>(),
        [("find", "find_1", 7), ("move", "move_2", 8)]
    );
}

#[test]
fn red_cube_designates_a_red_quarter_metre_cube() {
    let text = std::fs::read_to_string(root().join("examples/red-cube.rtcl")).expect("mission");
    let out = compile(
        "red-cube.rtcl",
        &text,
        &Library::builtin(),
        &CompileOptions {
            origin: [0.5, 1.0],
            robots: 2,
        },
    )
    .expect("compiles");
    let t = &out.targets["cube"];
    assert_eq!(t.colour.as_deref(), Some("red"));
    assert_eq!(t.size, Some([Some(0.25), Some(0.25), Some(0.25)]));
    // Back to where the robots started: the origin itself.
    assert_eq!(
        out.beliefs["move_2_delivered"],
        "dist(cube_pos, [0.5, 1]) < 0.3"
    );
}

/// docs/rtcl.md shows what `examples/search-rescue.rtcl` compiles to: the
/// golden graph, verbatim (`BLESS=1` writes it there too).
#[test]
fn the_language_guide_shows_the_golden_graph() {
    let doc_path = root().join("docs/rtcl.md");
    let doc = std::fs::read_to_string(&doc_path).expect("docs/rtcl.md");
    let golden =
        std::fs::read_to_string(root().join("crates/bite-rtcl/tests/golden/search-rescue.yaml"))
            .expect("golden search-rescue.yaml");
    let start_mark = "```yaml\n# Generated by bite-rtcl from examples/search-rescue.rtcl";
    let start = doc
        .find(start_mark)
        .expect("docs/rtcl.md shows the compiled search-rescue.rtcl")
        + "```yaml\n".len();
    let end = start + doc[start..].find("```").expect("the block ends");
    if std::env::var_os("BLESS").is_some() {
        let mut fixed = doc.clone();
        fixed.replace_range(start..end, &golden);
        std::fs::write(&doc_path, fixed).expect("write docs/rtcl.md");
        return;
    }
    assert!(
        doc[start..end] == golden,
        "docs/rtcl.md's compiled search-rescue.rtcl differs from tests/golden/search-rescue.yaml (run with BLESS=1 to write it there)"
    );
}
