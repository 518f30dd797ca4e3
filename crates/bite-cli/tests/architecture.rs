//! Architecture invariants (ARCHITECTURE.md, "What each crate must never
//! know"), checked against what cargo actually links and what the sources
//! actually import, so that a dependency added in passing fails here rather
//! than in a review.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The packages `package` links in normal builds (itself included), as
/// `cargo tree` resolves them; `extra` are further `cargo tree` flags.
fn links(package: &str, extra: &[&str]) -> BTreeSet<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(root())
        .args(["tree", "--offline", "-e", "normal", "--prefix", "none"])
        .args(["--format", "{p}", "-p", package])
        .args(extra)
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(String::from))
        .collect()
}

/// `package` (built with `extra` flags) links none of `never`.
fn never(package: &str, extra: &[&str], never: &[&str], why: &str) {
    let got = links(package, extra);
    assert!(
        got.contains(package),
        "{package}: not in its own tree: {got:?}"
    );
    let bad: Vec<&&str> = never.iter().filter(|n| got.contains(**n)).collect();
    assert!(
        bad.is_empty(),
        "{package} {}: links {bad:?}, but {why}",
        extra.join(" ")
    );
}

const PHYSICS: &str = "rapier2d";
const TRANSPORT: &str = "zenoh";
/// The operating system's random source: a crate that links it could draw
/// randomness that no seed reproduces.
const OS_RANDOM: &str = "getrandom";

#[test]
fn the_core_knows_no_clock_socket_random_source_or_runtime() {
    never(
        "bite-core",
        &[],
        &[
            PHYSICS,
            TRANSPORT,
            OS_RANDOM,
            "bite-agent",
            "bite-protocols",
            "bite-sim",
            "bite-zenoh",
            "tokio",
        ],
        "the core is sans-IO: pure state machines every runtime drives the same way",
    );
}

#[test]
fn protocols_and_the_compiler_build_on_the_core_alone() {
    for p in ["bite-protocols", "bite-rtcl"] {
        never(
            p,
            &[],
            &[
                PHYSICS,
                TRANSPORT,
                OS_RANDOM,
                "bite-agent",
                "bite-sim",
                "bite-zenoh",
            ],
            "protocols and the command-language compiler need only the core",
        );
    }
}

#[test]
fn the_mind_links_no_physics_engine_and_no_transport() {
    never(
        "bite-agent",
        &[],
        &[
            PHYSICS,
            TRANSPORT,
            OS_RANDOM,
            "bite-sim",
            "bite-zenoh",
            "tokio",
        ],
        "the mind runs the same in the simulator and in a robot process",
    );
}

#[test]
fn the_simulator_links_no_transport() {
    never(
        "bite-sim",
        &[],
        &[TRANSPORT, OS_RANDOM, "bite-zenoh", "tokio", "foxglove"],
        "a simulated run is deterministic: its network is simulated, its randomness seeded",
    );
}

#[test]
fn the_foxglove_formats_read_records_not_the_engine() {
    never(
        "bite-foxglove",
        &[],
        &[
            "bite-core",
            "bite-agent",
            "bite-sim",
            "bite-zenoh",
            PHYSICS,
            TRANSPORT,
        ],
        "MCAP files and the live view are made from run-log records alone, whichever runtime wrote them",
    );
}

#[test]
fn the_robot_runtime_without_the_sim_server_links_no_physics_engine() {
    never(
        "bite-zenoh",
        &["--no-default-features"],
        &[PHYSICS, "bite-sim"],
        "a robot process has a real body (or talks to a simulated one over Zenoh)",
    );
    // And with it, it does: the test above would pass vacuously otherwise.
    assert!(links("bite-zenoh", &[]).contains(PHYSICS));
}

/// Modules of `bite-core` in layer order: a module may use (`crate::x`)
/// only modules listed before it, or itself. Doc comments do not count.
const CORE_LAYERS: &[&str] = &[
    "hint",
    "time",
    "value",
    "diag",
    "ids",
    "cond",
    "belief",
    "roster",
    "yaml",
    "members",
    "event",
    "org",
    "msg",
    "graph",
    "interaction",
    "rules",
    "mission",
    "kernel",
    "wm",
];

/// The `crate::x` modules each source file of `bite-core` uses, outside
/// comments, by the top module the file belongs to.
fn core_imports() -> BTreeMap<String, BTreeSet<String>> {
    let src = root().join("crates/bite-core/src");
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut stack = vec![src.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("src dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            if p.extension().is_none_or(|x| x != "rs") {
                continue;
            }
            let rel = p.strip_prefix(&src).expect("under src");
            let top = rel
                .components()
                .next()
                .and_then(|c| c.as_os_str().to_str())
                .map(|s| s.trim_end_matches(".rs").to_string())
                .expect("name");
            let name = rel.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if top == "lib" || name.contains("tests") {
                continue;
            }
            let text = std::fs::read_to_string(&p).expect("source");
            // Unit tests may reach anywhere.
            let code = text.split("#[cfg(test)]").next().unwrap_or("");
            let used = out.entry(top.clone()).or_default();
            for line in code.lines() {
                let line = line.split("//").next().unwrap_or("");
                for (i, _) in line.match_indices("crate::") {
                    let m: String = line[i + 7..]
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if !m.is_empty() && m != top {
                        used.insert(m);
                    }
                }
            }
        }
    }
    out
}

#[test]
fn the_core_is_a_straight_chain_of_layers() {
    let imports = core_imports();
    let rank = |m: &str| CORE_LAYERS.iter().position(|x| *x == m);
    let mut bad = Vec::new();
    for (module, uses) in &imports {
        let Some(me) = rank(module) else {
            bad.push(format!("module `{module}` is not in CORE_LAYERS"));
            continue;
        };
        for u in uses {
            match rank(u) {
                Some(r) if r < me => {}
                _ => bad.push(format!("`{module}` uses `{u}`")),
            }
        }
    }
    assert!(
        bad.is_empty(),
        "bite-core's layers are, bottom first, {CORE_LAYERS:?}; a module may use only those \
         below it:\n  {}",
        bad.join("\n  ")
    );
}
