//! Compiling a 10,000-line mission (goal: well under a second).
//!
//! - `compile`: the whole pipeline (lex, parse, check, generate the graph,
//!   skills and beliefs);
//! - `lex`, `parse`, `check`: the front-end stages alone;
//! - `load_generated_graph`: `bite_core::graph::load_str` on the generated
//!   graph's YAML (what `bite run graph.yaml` does with an emitted graph);
//! - `load_compiled_graph`: `Compiled::load_graph`, the same graph handed
//!   over as data (what `bite run mission.rtcl` does after compiling);
//! - `compile_and_load_10k_lines`: both, what `bite run mission.rtcl` needs
//!   before the run starts (goal: under 50 ms).

use bite_rtcl::{CompileOptions, Library, compile};
use std::sync::{Arc, LazyLock};

// The allocator the `bite` binary runs with, so that the figures are its.
#[global_allocator]
static ALLOC: bite_alloc::MiMalloc = bite_alloc::MiMalloc;

fn main() {
    divan::main();
}

const LINES: usize = 10_000;

/// A mission of `LINES` lines cycling through every command, with a few
/// comments and blank lines.
fn mission() -> String {
    let mut s = String::with_capacity(LINES * 24);
    let mut last = String::new();
    for i in 0..LINES {
        let line = match i % 10 {
            0 => {
                last = format!("t{i}");
                format!("find:.25:.25:.25:red=>{last}")
            }
            1 => format!("move:{last}:{}:-.5", i % 7),
            2 => "goto:1.5:2".to_string(),
            3 => "wait:2   # a pause".to_string(),
            4 => "scan:0:0:4:3:0.6".to_string(),
            5 => "formation:triangle:0.6:3:0".to_string(),
            6 => format!("follow:{last}:0.5:10"),
            7 => "formation:column".to_string(),
            8 => "# a comment line".to_string(),
            _ => String::new(),
        };
        s.push_str(&line);
        s.push('\n');
    }
    s
}

static MISSION: LazyLock<String> = LazyLock::new(mission);
static LIB: LazyLock<Library> = LazyLock::new(Library::builtin);

#[divan::bench]
fn compile_10k_lines(b: divan::Bencher) {
    let opts = CompileOptions::default();
    b.bench(|| compile("bench.rtcl", divan::black_box(&MISSION), &LIB, &opts).expect("compiles"));
}

#[divan::bench]
fn lex_10k_lines(b: divan::Bencher) {
    b.bench(|| bite_rtcl::lex(divan::black_box(&MISSION)));
}

#[divan::bench]
fn parse_10k_lines(b: divan::Bencher) {
    b.bench(|| bite_rtcl::parse("bench.rtcl", divan::black_box(&MISSION)));
}

#[divan::bench]
fn check_10k_lines(b: divan::Bencher) {
    let (m, _) = bite_rtcl::parse("bench.rtcl", &MISSION);
    b.bench(|| bite_rtcl::check("bench.rtcl", &MISSION, divan::black_box(&m), &LIB));
}

#[divan::bench(sample_count = 10)]
fn load_generated_graph(b: divan::Bencher) {
    let out = compile("bench.rtcl", &MISSION, &LIB, &CompileOptions::default()).expect("compiles");
    let file: Arc<str> = Arc::from("bench.yaml");
    b.bench(|| bite_core::graph::load_str(&file, divan::black_box(&out.graph())).expect("loads"));
}

#[divan::bench(sample_count = 20)]
fn load_compiled_graph(b: divan::Bencher) {
    let out = compile("bench.rtcl", &MISSION, &LIB, &CompileOptions::default()).expect("compiles");
    let file: Arc<str> = Arc::from("bench.rtcl (compiled)");
    b.bench(|| divan::black_box(&out).load_graph(&file).expect("loads"));
}

#[divan::bench(sample_count = 20)]
fn compile_and_load_10k_lines(b: divan::Bencher) {
    let opts = CompileOptions::default();
    let file: Arc<str> = Arc::from("bench.rtcl (compiled)");
    b.bench(|| {
        let out = compile("bench.rtcl", divan::black_box(&MISSION), &LIB, &opts).expect("compiles");
        let graph = out.load_graph(&file).expect("loads");
        // Both dropped after the measurement, as `compile_10k_lines`'s output.
        (out, graph)
    });
}
