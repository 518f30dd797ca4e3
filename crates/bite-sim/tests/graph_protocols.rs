//! Graph-defined protocols decide as their Rust twins: the same point, team,
//! beliefs, message delays, losses, duplicates and crashes (one seeded
//! network), and the same decision on every robot. Also: the new protocol
//! (a quorum vote falling back to a leader) keeps the invariants.

mod common;

use bite_core::msg::Kind;
use bite_sim::probe::{ProbeResult, ProbeSpec, probe};
use proptest::prelude::*;
use std::time::Duration;

/// (kind, graph protocol, its params, Rust twin, its params).
type Twin = (
    Kind,
    &'static str,
    Option<&'static str>,
    &'static str,
    Option<&'static str>,
);
const TWINS: &[Twin] = &[
    (Kind::Sync, "graph.vote", None, "sync.vote", None),
    (
        Kind::Allocate,
        "graph.market",
        Some("{ bid: pos.x }"),
        "alloc.by-value",
        Some("{ value: pos.x, order: descending }"),
    ),
    (
        Kind::Terminate,
        "graph.wait-all",
        None,
        "term.wait-all",
        None,
    ),
];

#[derive(Clone, Debug)]
struct Case {
    n: usize,
    loss: f64,
    dup: f64,
    jitter_ms: u64,
    crash: Option<(usize, f64)>,
    seed: u64,
}

fn spec(kind: Kind, protocol: &str, params: Option<&str>, c: &Case) -> ProbeSpec {
    let mut s = ProbeSpec::new(kind, protocol, c.n);
    s.params = params.map(str::to_string);
    s.utilities = kind != Kind::Terminate;
    s.staggered = kind == Kind::Terminate;
    s.loss = c.loss;
    s.duplicate = c.dup;
    s.jitter = Duration::from_millis(c.jitter_ms);
    s.crash = c.crash.map(|(r, t)| (r, Duration::from_secs_f64(t)));
    s.seed = c.seed;
    s
}

fn run(s: &ProbeSpec) -> ProbeResult {
    probe(s, &bite_protocols::registry()).unwrap_or_else(|d| panic!("{}: {d}", s.protocol))
}

/// Run both twins on case `c`; `Err` says how they differ.
fn compare(which: usize, c: &Case) -> Result<(ProbeResult, ProbeResult), String> {
    let (kind, graph, gp, twin, tp) = TWINS[which];
    let g = run(&spec(kind, graph, gp, c));
    let t = run(&spec(kind, twin, tp, c));
    let what = format!("{graph} vs {twin} on {c:?}");
    // The graph protocol keeps the invariants its twin keeps. (Where the
    // twin itself breaks one — seen: `alloc.by-value` with 10 robots, 23 %
    // loss and a crash during the decision, see the issue notes — the twin
    // must break it the same way.)
    if g.violations != t.violations || g.protocol_violations > 0 {
        return Err(format!(
            "{what}: invariants {:?} ({} protocol violations) vs twin {:?}",
            g.violations, g.protocol_violations, t.violations
        ));
    }
    if g.completed != t.completed {
        return Err(format!(
            "{what}: completed {} vs {}",
            g.completed, t.completed
        ));
    }
    let mut gc = g.choices.clone();
    let mut tc = t.choices.clone();
    gc.sort();
    tc.sort();
    if gc != tc {
        return Err(format!("{what}: choices {gc:?} vs {tc:?}"));
    }
    if g.assignment != t.assignment {
        return Err(format!(
            "{what}: assignment {:?} vs {:?}",
            g.assignment, t.assignment
        ));
    }
    Ok((g, t))
}

#[test]
#[allow(clippy::needless_range_loop)] // `compare` takes the index
fn fault_free_twins_decide_alike_with_the_same_messages() {
    for which in 0..TWINS.len() {
        for n in [1usize, 2, 3, 5, 8] {
            for seed in 1..=4u64 {
                let c = Case {
                    n,
                    loss: 0.0,
                    dup: 0.0,
                    jitter_ms: 0,
                    crash: None,
                    seed,
                };
                let (g, t) = compare(which, &c).unwrap_or_else(|e| panic!("{e}"));
                assert!(g.completed);
                assert_eq!(g.timeouts, 0, "{} n={n}", TWINS[which].1);
                // The vote and the market send what their twins send; the
                // barrier goes without acknowledgements.
                if TWINS[which].0 != Kind::Terminate {
                    assert_eq!(
                        g.messages, t.messages,
                        "{} n={n} seed={seed}",
                        TWINS[which].1
                    );
                    assert_eq!(g.rounds, t.rounds, "{} n={n} seed={seed}", TWINS[which].1);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(common::config(40))]

    /// Random teams, preferences, losses, duplicates, reordering and a
    /// crash: the graph protocol decides what its twin decides, on every
    /// robot, and keeps the invariants.
    #[test]
    fn graph_protocols_decide_as_their_twins(
        which in 0..TWINS.len(),
        n in 1usize..=10,
        loss in prop_oneof![Just(0.0), 0.0f64..0.25],
        dup in prop_oneof![Just(0.0), 0.0f64..0.25],
        jitter_ms in 0u64..60,
        crash in prop_oneof![Just(None), (0usize..10, 0.4f64..1.6).prop_map(Some)],
        seed in any::<u64>(),
    ) {
        let crash = crash.filter(|(r, _)| *r < n && n > 1);
        let c = Case { n, loss, dup, jitter_ms, crash, seed };
        if let Err(e) = compare(which, &c) {
            return Err(TestCaseError::fail(e));
        }
    }
}

#[test]
fn the_quorum_vote_decides_without_waiting_for_everyone_and_falls_back() {
    for n in [1usize, 2, 3, 4, 7] {
        for seed in 1..=6u64 {
            for loss in [0.0, 0.2] {
                let c = Case {
                    n,
                    loss,
                    dup: 0.0,
                    jitter_ms: 20,
                    crash: None,
                    seed,
                };
                let s = spec(Kind::Sync, "graph.quorum-vote", None, &c);
                let r = run(&s);
                assert!(r.completed, "n={n} seed={seed} loss={loss}");
                assert!(
                    r.violations.is_empty(),
                    "n={n} seed={seed}: {:?}",
                    r.violations
                );
                assert_eq!(r.protocol_violations, 0);
                let first = r.choices.first().copied();
                if loss == 0.0 {
                    assert_eq!(r.timeouts, 0, "n={n} seed={seed}");
                    assert!(
                        r.choices.iter().all(|c| Some(*c) == first),
                        "split: {:?}",
                        r.choices
                    );
                }
            }
        }
    }
}
