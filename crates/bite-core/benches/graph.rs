//! Loading behavior graphs (goal: 100,000 behaviors in under 0.5 s).
//!
//! - `load_wide`: `graph::load_str` on the graph of `docs/performance.md`
//!   ("one team behavior with K single-robot children"), K children each
//!   running a skill until a condition holds: YAML parsing with locations,
//!   then validation, for K = 1,000, 10,000 and 100,000 - 1.
//! - `parse_wide`: the YAML parsing alone (the `GraphSpec`).

use bite_core::graph::load_str;
use bite_core::graph::spec::GraphSpec;
use std::sync::Arc;

// The allocator the `bite` binary runs with, so that the figures are its.
#[global_allocator]
static ALLOC: bite_alloc::MiMalloc = bite_alloc::MiMalloc;

fn main() {
    divan::main();
}

/// The wide graph with `k` children (`k + 1` behaviors).
fn wide(k: usize) -> String {
    let kids = (0..k)
        .map(|i| format!("c{i}"))
        .collect::<Vec<_>>()
        .join(", ");
    let mut g = format!(
        "graph: wide\nstart: mission\nteam: {{ robots: {k} }}\n\
         defaults: {{ sync: sync.by-rule, allocate: alloc.by-id, terminate: term.local }}\n\
         behaviors:\n  mission:\n    team: true\n    children: [{kids}]\n"
    );
    for i in 0..k {
        g.push_str(&format!("  c{i}: {{ skill: work, until: done }}\n"));
    }
    g
}

const SIZES: [usize; 3] = [1_000, 10_000, 99_999];

#[divan::bench(args = SIZES, sample_count = 10)]
fn load_wide(b: divan::Bencher, k: usize) {
    let text = wide(k);
    let file: Arc<str> = Arc::from("wide.yaml");
    b.bench(|| load_str(&file, divan::black_box(&text)).expect("loads"));
}

#[divan::bench(args = SIZES, sample_count = 10)]
fn parse_wide(b: divan::Bencher, k: usize) {
    let text = wide(k);
    let file: Arc<str> = Arc::from("wide.yaml");
    b.bench(|| {
        bite_core::yaml::parse::<GraphSpec>(&file, divan::black_box(&text)).expect("parses")
    });
}
