//! A compiled mission's graph loads the same whether handed over as data
//! (`Compiled::load_graph`, what `bite run mission.rtcl` does) or written
//! as YAML and parsed (`bite_core::graph::load_str` on `Compiled::graph`,
//! what `bite run` does with an emitted graph): the same behaviors, edges,
//! conditions, bindings, roster, symbols and warnings. Only the source
//! locations differ (none on the direct path), so they are blanked.

use bite_rtcl::{CompileOptions, Library, compile};
use std::path::Path;
use std::sync::Arc;

/// `Debug` of the graph with every `Loc { line: L, col: C }` blanked.
fn without_locations(g: &bite_core::BehaviorGraph) -> String {
    let text = format!("{g:#?}");
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while let Some(i) = rest.find("Loc {") {
        out.push_str(&rest[..i]);
        let Some(end) = rest[i..].find('}') else {
            break;
        };
        out.push_str("Loc");
        rest = &rest[i + end + 1..];
    }
    out.push_str(rest);
    out
}

fn same_both_ways(name: &str, src: &str, opts: &CompileOptions) {
    let out = compile(name, src, &Library::builtin(), opts).unwrap_or_else(|e| panic!("{e}"));
    let file: Arc<str> = Arc::from(format!("{name} (compiled)"));
    let parsed = bite_core::graph::load_str(&file, &out.graph()).unwrap_or_else(|e| panic!("{e}"));
    let direct = out.load_graph(&file).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(parsed.to_string(), direct.to_string(), "{name}");
    assert_eq!(parsed.to_dot(), direct.to_dot(), "{name}");
    assert_eq!(parsed.points(), direct.points(), "{name}");
    let (p, d) = (without_locations(&parsed), without_locations(&direct));
    assert!(
        p.contains("until"),
        "{name}: the comparison sees the behaviors"
    );
    assert!(
        p == d,
        "{name}: the graphs differ:\n--- parsed\n{p}\n--- direct\n{d}"
    );
    // Every direct diagnostic is at no location (the names say where).
    assert!(
        direct.warnings().iter().all(|w| !w.loc.is_known()),
        "{name}"
    );
}

#[test]
fn shipped_missions_load_the_same_both_ways() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).expect("examples") {
        let path = e.expect("entry").path();
        if path.extension().is_some_and(|x| x == "rtcl") {
            let src = std::fs::read_to_string(&path).expect("mission");
            let name = path.file_name().map(|f| f.to_string_lossy().into_owned());
            let name = name.unwrap_or_default();
            for robots in [1, 2, 3, 5] {
                same_both_ways(
                    &name,
                    &src,
                    &CompileOptions {
                        robots,
                        origin: [6.7, -1.5],
                    },
                );
            }
            n += 1;
        }
    }
    assert!(n >= 3, "found the shipped missions");
}

/// Every command of the library, with and without optional parameters:
/// 40 lines (more than `PARALLEL_FROM` commands).
fn every_command() -> String {
    let mut src = String::new();
    for i in 0..40 {
        let line = match i % 10 {
            0 => format!("find:.25:.25:.25:red=>t{i}"),
            1 => format!("move:t{}:{}:-.5", i - 1, i % 7),
            2 => "goto:1.5:2".to_string(),
            3 => "wait:2   # a pause".to_string(),
            4 => "scan:0:0:4:3:0.6".to_string(),
            5 => "formation:triangle:0.6:3:0".to_string(),
            6 => format!("follow:t{}:0.5:10", i - 6),
            7 => "formation:column".to_string(),
            8 => "find::::blue".to_string(),
            _ => String::new(),
        };
        src.push_str(&line);
        src.push('\n');
    }
    src
}

#[test]
fn a_generated_mission_of_every_command_loads_the_same_both_ways() {
    // Odd file names: the graph's name and description come from it.
    let src = every_command();
    for (file, robots) in [("m.rtcl", 2), ("a b\t\"c\".rtcl", 4), ("yes", 1)] {
        same_both_ways(
            file,
            &src,
            &CompileOptions {
                robots,
                ..CompileOptions::default()
            },
        );
    }
}

/// A long mission's commands are generated side by side; the result is the
/// same on one thread as on several.
#[test]
fn a_long_mission_compiles_the_same_on_one_thread_and_on_several() {
    let src = every_command();
    assert!(
        src.lines().filter(|l| !l.trim().is_empty()).count() >= bite_rtcl::codegen::PARALLEL_FROM
    );
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            compile(
                "m.rtcl",
                &src,
                &Library::builtin(),
                &CompileOptions::default(),
            )
            .unwrap_or_else(|e| panic!("{e}"))
        })
    };
    let one = on(1);
    for threads in [2, 3, 8] {
        let several = on(threads);
        assert!(one == several, "{threads} threads");
        assert_eq!(one.graph(), several.graph());
    }
}
