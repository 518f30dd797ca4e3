use bite_core::msg::Kind;
use bite_sim::probe::{ProbeSpec, probe};
use std::time::Duration;
fn main() {
    let reg = bite_protocols::registry();
    let all = [
        (Kind::Sync, "sync.leader", None),
        (Kind::Sync, "sync.elected-leader", None),
        (Kind::Sync, "sync.vote", None),
        (Kind::Sync, "sync.ranked-vote", None),
        (
            Kind::Allocate,
            "alloc.by-value",
            Some("{ value: 'dist(pos, [0, 0])' }"),
        ),
        (
            Kind::Allocate,
            "alloc.by-attribute",
            Some("{ attribute: colour }"),
        ),
        (Kind::Allocate, "alloc.optimal", None),
        (Kind::Allocate, "alloc.auction", None),
        (Kind::Allocate, "alloc.token", None),
        (Kind::Terminate, "term.wait-all", None),
        (Kind::Terminate, "term.majority", None),
        (Kind::Terminate, "term.first-wins", None),
    ];
    let mut bad = 0;
    let mut total = 0;
    for (k, p, params) in all {
        let start = if k == Kind::Allocate { 0.5 } else { 1.0 };
        for n in [2usize, 3, 6] {
            for victim in 0..n {
                for step in 0..40 {
                    for seed in 0..3u64 {
                        let at = start - 0.1 + step as f64 * 0.008;
                        let mut s = ProbeSpec::new(k, p, n);
                        s.params = params.map(str::to_string);
                        s.utilities = k == Kind::Allocate;
                        s.staggered = p == "term.first-wins";
                        s.jitter = Duration::from_millis(8);
                        s.seed = seed;
                        s.crash = Some((victim, Duration::from_secs_f64(at)));
                        let r = probe(&s, &reg).unwrap();
                        total += 1;
                        let dl = reg.get(p).unwrap().default_deadline().as_secs_f64();
                        if !r.completed
                            || !r.violations.is_empty()
                            || r.max_wait > dl + 0.2
                            || r.protocol_violations > 0
                        {
                            bad += 1;
                            if bad < 15 {
                                println!(
                                    "{p} n={n} victim={victim} at={at:.3} seed={seed}: completed={} wait={:.2} to={} pv={} v={:?}",
                                    r.completed,
                                    r.max_wait,
                                    r.timeouts,
                                    r.protocol_violations,
                                    r.violations
                                );
                            }
                        }
                    }
                }
            }
        }
    }
    println!("{bad} bad of {total}");
}
