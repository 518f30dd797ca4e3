use bite_core::msg::Kind;
use bite_sim::probe::{ProbeSpec, probe};
fn main() {
    let reg = bite_protocols::registry();
    let list: &[(Kind, &str, Option<&str>)] = &[
        (Kind::Sync, "sync.by-rule", None),
        (Kind::Sync, "sync.leader", None),
        (Kind::Sync, "sync.elected-leader", None),
        (Kind::Sync, "sync.round-robin", None),
        (Kind::Sync, "sync.vote", None),
        (Kind::Sync, "sync.ranked-vote", None),
        (Kind::Allocate, "alloc.by-id", None),
        (Kind::Allocate, "alloc.by-value", Some("{ value: x }")),
        (
            Kind::Allocate,
            "alloc.by-attribute",
            Some("{ attribute: colour }"),
        ),
        (Kind::Allocate, "alloc.optimal", None),
        (Kind::Allocate, "alloc.auction", None),
        (Kind::Allocate, "alloc.token", None),
        (Kind::Terminate, "term.local", None),
        (Kind::Terminate, "term.wait-all", None),
        (Kind::Terminate, "term.majority", None),
        (Kind::Terminate, "term.first-wins", None),
    ];
    for (k, p, params) in list {
        for n in [1, 2, 3, 10, 100] {
            let mut s = ProbeSpec::new(*k, p, n);
            s.params = params.map(str::to_string);
            s.staggered = *p == "term.first-wins";
            let r = probe(&s, &reg).unwrap();
            println!(
                "{p:22} n={n:4} msgs={:6} rounds={:6.2} inst={} to={} ok={} v={} pv={}",
                r.messages,
                r.rounds,
                r.instances,
                r.timeouts,
                r.completed,
                r.violations.len(),
                r.protocol_violations
            );
        }
    }
}
